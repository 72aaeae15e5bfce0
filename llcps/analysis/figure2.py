"""Figure 2 over many seeds: update against reset per (model, measure, pretraining size,
scenario), and how often updating reduced exploration (the caption's 50% / 81%).

Each cell's percent change comes with a bootstrap 95% confidence interval (seeds
resampled as update/reset pairs) and a paired Wilcoxon signed-rank p-value over seeds,
because the ``update`` and ``reset`` sequences of one seed start from the same
pretraining set and scenario seeds. The paper's value stands beside each cell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from llcps.analysis.paper import FIGURE2_SCENARIOS, PAPER_FIGURE2
from llcps.analysis.results import ResultsTable, by_seed, group_rows
from llcps.analysis.stats import ALPHA, DEFAULT_RESAMPLES, bootstrap_pct_change_ci, cell_rng, paired_wilcoxon, pct_change
from llcps.experiments.design import scenario_rank
from llcps.experiments.presets import measure_rank, model_rank
from llcps.experiments.rows import check_metric


def figure2_order(model: str, measure: str, pretrain_size: int, scenario: str) -> tuple:
    """Display order: larger pretraining first, then models and measures in grid order."""
    return (-pretrain_size, model_rank(model), measure_rank(measure), scenario_rank(scenario))


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
    check_metric(metric)
    rows: list[Figure2Row] = []
    groups = group_rows(table, lambda r: (r.model, r.measure, r.pretrain_size, r.scenario))
    for (model, measure, size, scenario), part in sorted(groups.items(), key=lambda kv: figure2_order(*kv[0])):
        upd_rows = [row for row in part if row.condition == "update"]
        res_rows = [row for row in part if row.condition == "reset"]
        upd, res = by_seed(upd_rows, metric), by_seed(res_rows, metric)
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


__all__ = ["Figure2Row", "Reduction", "figure2_order", "figure2_table", "our_cells", "reduction_summary"]
