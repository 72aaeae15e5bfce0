"""Statistics of an experiment: the paper's Figure 2 over many seeds, and beyond.

Figure 2 of the paper reports, per world model x measure and scenarios 2 and 3, the
percent change of exploration with model updates against without ("reset"), averaged
over four runs, for 200 and for 4 pretraining points. Here each number comes with a
bootstrap 95% confidence interval (seeds resampled as update/reset pairs) and a
paired Wilcoxon signed-rank p-value over seeds, because the ``update`` and ``reset``
sequences of one seed start from the same pretraining set and scenario seeds.

Every function reads a :class:`~llcps.experiments.results.ResultsTable`; randomness
comes from an explicit seed, and each cell draws from its own stream derived from
its key, so a cell's interval does not depend on which other cells are in the table.
"""

from __future__ import annotations

import math
import warnings
import zlib
from dataclasses import dataclass, replace
from typing import Any, Callable, Iterable, TypeVar

import numpy as np
from scipy import stats as sps

from llcps.errors import LlcpsError
from llcps.experiments.grid import (
    PAPER_MEASURES,
    PAPER_MODELS,
    RANDOM_ORDER_MODEL,
    SCENARIO_SEQUENCE,
    condition_rank,
    measure_rank,
    model_rank,
    scenario_rank,
)
from llcps.experiments.results import METRICS, ResultRow, ResultsTable

K = TypeVar("K")

#: Scenarios the paper's Figure 2 reports (scenario 1 starts from the pretraining set
#: under both conditions, so there it serves as a control: its change should be ~0).
FIGURE2_SCENARIOS: tuple[str, ...] = ("scenario2", "scenario3")
DEFAULT_RESAMPLES = 10_000
ALPHA = 0.05
#: The model whose order every other model is compared against.
BASELINE_MODEL = RANDOM_ORDER_MODEL


# --------------------------------------------------------------------------------------
# The paper's own numbers (Figure 2), for side-by-side comparison.
# --------------------------------------------------------------------------------------
def _paper_block(
    pretrain: int, rows: dict[str, tuple[float, float, float, float]]
) -> dict[tuple[str, str, int, str], float]:
    out: dict[tuple[str, str, int, str], float] = {}
    for measure, (nn2, nn3, nb2, nb3) in rows.items():
        out[("nn", measure, pretrain, "scenario2")] = nn2
        out[("nn", measure, pretrain, "scenario3")] = nn3
        out[("nb", measure, pretrain, "scenario2")] = nb2
        out[("nb", measure, pretrain, "scenario3")] = nb3
    return out


#: ``(model, measure, pretrain_size, scenario) -> % change with updates``, transcribed
#: from Figure 2: "Apriori Training" is 200 pretraining points, "No Apriori Training" 4.
#: Columns per measure: NN scenario 2, NN scenario 3, NB scenario 2, NB scenario 3.
PAPER_FIGURE2: dict[tuple[str, str, int, str], float] = {
    **_paper_block(
        200,
        {
            "least-destructive": (182.0, -10.0, 0.0, 18.0),
            "most-positive-changes": (133.0, 0.0, -1.0, -43.0),
            "least-negative-changes": (121.0, 12.0, -21.0, 0.0),
            "most-changes": (-29.0, 550.0, 553.0, -59.0),
        },
    ),
    **_paper_block(
        4,
        {
            "least-destructive": (-40.0, -1.0, 0.0, -60.0),
            "most-positive-changes": (-3.0, -60.0, 0.0, -87.0),
            "least-negative-changes": (-61.0, -43.0, -46.0, 3.0),
            "most-changes": (109.0, 0.0, 640.0, -1.0),
        },
    ),
}
#: The caption's claims: the fraction of model x measure combinations where updating
#: decreased exploration time. Recomputing them from the table gives other numbers
#: (see :func:`reduction_summary` on :func:`paper_cells`); the report shows both.
PAPER_CAPTION_FRACTION_REDUCED: dict[int, float] = {200: 0.50, 4: 0.81}
#: The paper averaged four runs per cell.
PAPER_RUNS_PER_CELL = 4

assert len(PAPER_FIGURE2) == len(PAPER_MODELS) * len(PAPER_MEASURES) * 2 * len(FIGURE2_SCENARIOS)


# --------------------------------------------------------------------------------------
# Building blocks
# --------------------------------------------------------------------------------------
def pct_change(update: float | np.ndarray, reset: float | np.ndarray) -> float | np.ndarray:
    """The paper's "% change with updates": ``100 * (update - reset) / reset``.

    Zero denominator: if both are 0 the change is 0 (neither needed exploration);
    if only ``reset`` is 0 the change is +inf (or -inf for a negative ``update``),
    an unbounded increase rather than a missing value.
    """
    u = np.asarray(update, dtype=float)
    r = np.asarray(reset, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 100.0 * (u - r) / r
    zero = r == 0
    out = np.where(zero & (u == 0), 0.0, out)
    out = np.where(zero & (u != 0), np.copysign(np.inf, u), out)
    return float(out) if out.ndim == 0 else out


def cell_rng(seed: int, *key: object) -> np.random.Generator:
    """A generator for one cell: the run seed plus a stable hash of the cell's key."""
    digest = zlib.crc32("|".join(map(str, key)).encode("utf-8"))
    return np.random.default_rng([int(seed), digest])


def _percentile_bootstrap(
    data: tuple[np.ndarray, ...], statistic: Callable[..., Any], *, paired: bool, rng: np.random.Generator, resamples: int, level: float
) -> tuple[float, float]:
    """A percentile interval from ``scipy.stats.bootstrap`` (NaN bounds when the resamples are degenerate)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # degenerate or infinite resamples: the bounds say so themselves
        result = sps.bootstrap(
            data,
            statistic,
            paired=paired,
            vectorized=True,
            n_resamples=resamples,
            confidence_level=level,
            method="percentile",
            rng=rng,
        )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def bootstrap_pct_change_ci(
    update: np.ndarray,
    reset: np.ndarray,
    *,
    rng: np.random.Generator,
    resamples: int = DEFAULT_RESAMPLES,
    level: float = 0.95,
) -> tuple[float, float]:
    """Percentile bootstrap interval of :func:`pct_change` of the means, resampling seeds as pairs.

    Pairs are kept together because update and reset of one seed share their start;
    resampling them independently would ignore that and widen the interval.
    Returns ``(nan, nan)`` for fewer than two pairs (no spread to resample).
    """
    u = np.asarray(update, dtype=float)
    r = np.asarray(reset, dtype=float)
    if u.shape != r.shape or u.ndim != 1:
        raise ValueError("update and reset must be 1-d arrays of equal length (one value per seed)")
    if u.size < 2:
        return (math.nan, math.nan)
    if np.all(u == u[0]) and np.all(r == r[0]):  # every resample is the estimate itself
        value = float(pct_change(u[0], r[0]))
        return (value, value)

    def change(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.asarray(pct_change(a.mean(axis=axis), b.mean(axis=axis)))

    return _percentile_bootstrap((u, r), change, paired=True, rng=rng, resamples=resamples, level=level)


def bootstrap_mean_ci(
    values: np.ndarray, *, rng: np.random.Generator, resamples: int = DEFAULT_RESAMPLES, level: float = 0.95
) -> tuple[float, float]:
    """Percentile bootstrap interval of a mean; ``(nan, nan)`` for fewer than two values."""
    v = np.asarray(values, dtype=float)
    if v.size < 2:
        return (math.nan, math.nan)
    if np.all(v == v[0]):
        return (float(v[0]), float(v[0]))
    return _percentile_bootstrap((v,), np.mean, paired=False, rng=rng, resamples=resamples, level=level)


def paired_wilcoxon(update: np.ndarray, reset: np.ndarray) -> tuple[float, str]:
    """Two-sided Wilcoxon signed-rank p-value over seeds, and why it is missing when it is.

    Zero differences are dropped (Wilcoxon's convention). Returns ``(nan, reason)``
    for fewer than two pairs or when every difference is zero (no test possible).
    """
    u = np.asarray(update, dtype=float)
    r = np.asarray(reset, dtype=float)
    if u.size < 2:
        return (math.nan, f"fewer than 2 paired seeds (n={u.size})")
    diff = u - r
    if np.all(diff == 0):
        return (math.nan, "all paired differences are zero")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = sps.wilcoxon(u, r, zero_method="wilcox", alternative="two-sided")
    return (float(result.pvalue), "")


def mann_whitney(a: np.ndarray, b: np.ndarray) -> tuple[float, str]:
    """Two-sided Mann-Whitney U p-value for unpaired samples, with a reason when missing."""
    x = np.asarray(a, dtype=float)
    y = np.asarray(b, dtype=float)
    if x.size < 2 or y.size < 2:
        return (math.nan, f"fewer than 2 values on a side (n={x.size} vs {y.size})")
    if np.all(x == x[0]) and np.all(y == x[0]):
        return (math.nan, "all values are equal")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = sps.mannwhitneyu(x, y, alternative="two-sided")
    return (float(result.pvalue), "")


def holm(p_values: Iterable[float]) -> list[float]:
    """Holm-adjusted p-values (``statsmodels``); NaN stays NaN and is not counted in the family."""
    from statsmodels.stats.multitest import multipletests

    p = [float(v) for v in p_values]
    finite = [i for i, v in enumerate(p) if not math.isnan(v)]
    out = [math.nan] * len(p)
    if finite:
        adjusted = multipletests([p[i] for i in finite], alpha=ALPHA, method="holm")[1]
        for i, value in zip(finite, adjusted):
            out[i] = float(value)
    return out


def _by_seed(rows: Iterable[ResultRow], metric: str) -> dict[int, float]:
    return {row.seed: row.metric(metric) for row in rows}


def _group(rows: Iterable[ResultRow], key: Callable[[ResultRow], K]) -> dict[K, list[ResultRow]]:
    groups: dict[K, list[ResultRow]] = {}
    for row in rows:
        groups.setdefault(key(row), []).append(row)
    return groups


def figure2_order(model: str, measure: str, pretrain_size: int, scenario: str) -> tuple:
    """Display order: larger pretraining first, then models and measures in grid order."""
    return (-pretrain_size, model_rank(model), measure_rank(measure), scenario_rank(scenario))


def _check_metric(metric: str) -> None:
    if metric not in METRICS:
        raise LlcpsError(f"unknown metric {metric!r}", hint=f"choose one of: {', '.join(METRICS)}")


# --------------------------------------------------------------------------------------
# Figure 2: update vs reset
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Figure2Row:
    """Update vs reset for one (model, measure, pretraining size, scenario), over paired seeds."""

    model: str
    measure: str
    pretrain_size: int
    scenario: str
    metric: str
    n_seeds: int
    mean_update: float
    mean_reset: float
    median_update: float
    median_reset: float
    pct_change: float
    ci_low: float
    ci_high: float
    p_value: float
    p_reason: str
    #: Holm-adjusted over every comparison of the report (:func:`adjust`); NaN until then.
    p_holm: float
    #: Every paired seed has the same value under both conditions.
    identical: bool
    solved_update: float
    solved_reset: float
    paper_pct_change: float | None

    @property
    def significant(self) -> bool:
        """Uncorrected Wilcoxon p below :data:`ALPHA`."""
        return not math.isnan(self.p_value) and self.p_value < ALPHA

    @property
    def in_figure2(self) -> bool:
        return self.scenario in FIGURE2_SCENARIOS


def figure2_table(
    table: ResultsTable,
    *,
    metric: str = "exploration_trials",
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
) -> tuple[Figure2Row, ...]:
    """One :class:`Figure2Row` per (model, measure, pretraining size, scenario) with both conditions.

    Only seeds present under both conditions are used (pairs); a cell with no pair
    at all is left out. Every scenario of the table is included; scenario 1 is the
    control (both conditions start from the pretraining set there).
    """
    _check_metric(metric)
    rows: list[Figure2Row] = []
    groups = _group(table, lambda r: (r.model, r.measure, r.pretrain_size, r.scenario))
    for (model, measure, size, scenario), part in sorted(groups.items(), key=lambda kv: figure2_order(*kv[0])):
        upd_rows = [row for row in part if row.condition == "update"]
        res_rows = [row for row in part if row.condition == "reset"]
        upd, res = _by_seed(upd_rows, metric), _by_seed(res_rows, metric)
        seeds = sorted(set(upd) & set(res))
        if not seeds:
            continue
        u = np.array([upd[s] for s in seeds])
        r = np.array([res[s] for s in seeds])
        solved_u = {row.seed: row.solved for row in upd_rows}
        solved_r = {row.seed: row.solved for row in res_rows}
        ci = bootstrap_pct_change_ci(
            u, r, rng=cell_rng(seed, model, measure, size, scenario, metric), resamples=resamples
        )
        p, reason = paired_wilcoxon(u, r)
        rows.append(
            Figure2Row(
                model=model,
                measure=measure,
                pretrain_size=size,
                scenario=scenario,
                metric=metric,
                n_seeds=len(seeds),
                mean_update=float(u.mean()),
                mean_reset=float(r.mean()),
                median_update=float(np.median(u)),
                median_reset=float(np.median(r)),
                pct_change=float(pct_change(u.mean(), r.mean())),
                ci_low=ci[0],
                ci_high=ci[1],
                p_value=p,
                p_reason=reason,
                p_holm=math.nan,
                identical=bool(np.array_equal(u, r)),
                solved_update=float(np.mean([solved_u[s] for s in seeds])),
                solved_reset=float(np.mean([solved_r[s] for s in seeds])),
                paper_pct_change=PAPER_FIGURE2.get((model, measure, size, scenario)),
            )
        )
    return tuple(rows)


# --------------------------------------------------------------------------------------
# How often updating reduced exploration (the caption's 50% / 81%)
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Reduction:
    """Among ``n_cells`` Figure-2 cells of one group, how many changed in which direction."""

    pretrain_size: int
    model: str | None  # None: all models together
    n_cells: int
    n_reduced: int  # % change < 0
    n_unchanged: int  # % change == 0
    n_increased: int  # % change > 0

    @property
    def fraction_reduced(self) -> float:
        return self.n_reduced / self.n_cells if self.n_cells else math.nan

    @property
    def fraction_not_increased(self) -> float:
        """Reduced or unchanged; the paper's 81% matches this reading of its own table."""
        return (self.n_reduced + self.n_unchanged) / self.n_cells if self.n_cells else math.nan


def reduction_summary(cells: Iterable[tuple[str, int, float]]) -> tuple[Reduction, ...]:
    """Count directions per pretraining size, overall and per model.

    Args:
        cells: ``(model, pretrain_size, pct_change)`` of each Figure-2 cell; NaN ignored.
    """
    counts: dict[tuple[int, str | None], list[int]] = {}
    for model, size, pct in cells:
        if math.isnan(pct):
            continue
        which = 0 if pct < 0 else 1 if pct == 0 else 2
        for key in ((size, None), (size, model)):
            counts.setdefault(key, [0, 0, 0])[which] += 1
    order = sorted(counts, key=lambda k: (-k[0], k[1] is not None, model_rank(k[1] or "")))
    return tuple(
        Reduction(size, model, sum(c), c[0], c[1], c[2]) for (size, model), c in ((k, counts[k]) for k in order)
    )


def our_cells(rows: Iterable[Figure2Row]) -> list[tuple[str, int, float]]:
    """The Figure-2 cells of our table, as :func:`reduction_summary` input."""
    return [(r.model, r.pretrain_size, r.pct_change) for r in rows if r.in_figure2]


def paper_cells() -> list[tuple[str, int, float]]:
    """The paper's Figure-2 cells, as :func:`reduction_summary` input."""
    return [(model, size, pct) for (model, _measure, size, _scenario), pct in PAPER_FIGURE2.items()]


# --------------------------------------------------------------------------------------
# Model-guided vs random order
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RandomComparison:
    """One model x measure against the random model in one (pretraining size, condition, scenario)."""

    model: str
    measure: str
    pretrain_size: int
    condition: str
    scenario: str
    metric: str
    n_model: int
    n_random: int
    median_model: float
    median_random: float
    #: % change of the median against random: negative means less exploration than random.
    pct_change_median: float
    test: str  # "wilcoxon" (paired by seed) or "mann-whitney"
    p_value: float
    p_reason: str
    #: Holm-adjusted over every comparison of the report (:func:`adjust`); NaN until then.
    p_holm: float = math.nan


def random_comparison(
    table: ResultsTable, *, metric: str = "exploration_trials", baseline: str = BASELINE_MODEL
) -> tuple[RandomComparison, ...]:
    """Compare every model x measure with the ``baseline`` model's exploration.

    The baseline is the random model under the same measure, pretraining size,
    condition and scenario when the table has it; then the test is a paired Wilcoxon
    over common seeds (if at least two). Otherwise every random sequence of that
    (pretraining size, condition, scenario) is pooled, or failing that every random
    sequence of the scenario (the random order uses no training data, so neither the
    pretraining size nor the condition changes it), and the test is Mann-Whitney U.
    Empty when the table has no baseline rows.
    """
    _check_metric(metric)
    base = _group(
        (r for r in table if r.model == baseline), lambda r: (r.measure, r.pretrain_size, r.condition, r.scenario)
    )
    if not base:
        return ()
    pooled = _group(
        (row for rows in base.values() for row in rows), lambda r: (r.pretrain_size, r.condition, r.scenario)
    )
    per_scenario = _group((row for rows in base.values() for row in rows), lambda r: r.scenario)
    out: list[RandomComparison] = []
    groups = _group(
        (r for r in table if r.model != baseline),
        lambda r: (r.model, r.measure, r.pretrain_size, r.condition, r.scenario),
    )

    def order(item: tuple[tuple[str, str, int, str, str], list[ResultRow]]) -> tuple:
        model, measure, size, condition, scenario = item[0]
        return (*figure2_order(model, measure, size, scenario), condition_rank(condition))

    for (model, measure, size, condition, scenario), part in sorted(groups.items(), key=order):
        mine = _by_seed(part, metric)
        same = base.get((measure, size, condition, scenario))
        if same:
            theirs = _by_seed(same, metric)
            common = sorted(set(mine) & set(theirs))
            baseline_values = np.array(list(theirs.values()))
        else:
            theirs, common = {}, []
            rows = pooled.get((size, condition, scenario)) or per_scenario.get(scenario, [])
            baseline_values = np.array([row.metric(metric) for row in rows])
            if baseline_values.size == 0:
                continue
        if len(common) >= 2:
            a = np.array([mine[s] for s in common])
            b = np.array([theirs[s] for s in common])
            p, reason = paired_wilcoxon(a, b)
            test = "wilcoxon"
        else:
            a, b = np.array(list(mine.values())), baseline_values
            p, reason = mann_whitney(a, b)
            test = "mann-whitney"
        med_a, med_b = float(np.median(a)), float(np.median(b))
        out.append(
            RandomComparison(
                model=model,
                measure=measure,
                pretrain_size=size,
                condition=condition,
                scenario=scenario,
                metric=metric,
                n_model=int(a.size),
                n_random=int(b.size),
                median_model=med_a,
                median_random=med_b,
                pct_change_median=float(pct_change(med_a, med_b)),
                test=test,
                p_value=p,
                p_reason=reason,
            )
        )
    return tuple(out)


def best_versus_random(
    comparisons: Iterable[RandomComparison], *, condition: str = "reset"
) -> tuple[RandomComparison, ...]:
    """Per (pretraining size, scenario), the model x measure with the lowest median, against random.

    ``reset`` by default: every episode then starts from the pretraining set, as in the
    paper's question of which measure explores best. Ties go to the first in Figure 2's
    order. Choosing the best of several cells favours it: read the p-value as descriptive.
    """
    best: dict[tuple[int, str], RandomComparison] = {}
    for c in comparisons:
        if c.condition != condition:
            continue
        key = (c.pretrain_size, c.scenario)
        if key not in best or c.median_model < best[key].median_model:
            best[key] = c
    return tuple(
        best[k] for k in sorted(best, key=lambda k: (-k[0], scenario_rank(k[1])))
    )


# --------------------------------------------------------------------------------------
# One correction over every comparison a report makes
# --------------------------------------------------------------------------------------
def adjust(families: Iterable[tuple[Any, ...]]) -> list[tuple[Any, ...]]:
    """Holm's correction over every p-value of several tuples of rows at once.

    A report that tests many cells must correct over all of them together (update vs
    reset, censoring-aware comparisons, model vs random order), or its significant
    findings are mostly luck. Each row needs ``p_value`` and ``p_adjusted`` or ``p_holm``.

    Returns:
        The tuples in the same order, each row with its adjusted p-value set.
    """
    groups = [tuple(g) for g in families]
    adjusted = iter(holm(row.p_value for g in groups for row in g))
    return [
        tuple(replace(row, **{"p_adjusted" if hasattr(row, "p_adjusted") else "p_holm": next(adjusted)}) for row in g)
        for g in groups
    ]


# --------------------------------------------------------------------------------------
# Cumulative exploration over the scenario sequence
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CumulativePoint:
    """Mean cumulative exploration after ``scenario`` over the complete sequences of a cell."""

    model: str
    measure: str
    pretrain_size: int
    condition: str
    scenario: str
    n_seeds: int
    mean: float
    ci_low: float
    ci_high: float


def cumulative_exploration(
    table: ResultsTable,
    *,
    metric: str = "exploration_trials",
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
) -> tuple[CumulativePoint, ...]:
    """Exploration summed along the scenario sequence, per cell, with bootstrap CIs of the mean.

    Only complete sequences count, so every point of a line averages the same seeds.
    """
    _check_metric(metric)
    complete = table.complete_sequences()
    per_cell: dict[tuple[str, str, int, str], dict[int, np.ndarray]] = {}
    position = {s: i for i, s in enumerate(SCENARIO_SEQUENCE)}
    for row in table:
        if row.sequence not in complete:
            continue
        key = (row.model, row.measure, row.pretrain_size, row.condition)
        values = per_cell.setdefault(key, {}).setdefault(row.seed, np.zeros(len(SCENARIO_SEQUENCE)))
        values[position[row.scenario]] = row.metric(metric)
    out: list[CumulativePoint] = []
    for key, seeds in sorted(
        per_cell.items(), key=lambda kv: (*figure2_order(*kv[0][:3], ""), condition_rank(kv[0][3]))
    ):
        matrix = np.cumsum(np.array([seeds[s] for s in sorted(seeds)]), axis=1)
        for j, scenario in enumerate(SCENARIO_SEQUENCE):
            column = matrix[:, j]
            low, high = bootstrap_mean_ci(
                column, rng=cell_rng(seed, *key, scenario, metric, "cum"), resamples=resamples
            )
            out.append(CumulativePoint(*key, scenario, int(column.size), float(column.mean()), low, high))
    return tuple(out)
