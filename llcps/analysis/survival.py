"""Trials to resolution as survival data: an unsolved episode is censored at its budget.

An episode that exhausts its exploration budget did not take "budget" trials to
resolve the novelty; it took more, by an unknown amount. Treating the budget as the
value (a *capped mean*) biases every mean and percent change toward zero change.
Here each cell's episodes are a right-censored sample of trials-to-resolution:

- :func:`kaplan_meier` estimates the survival curve S(t) = P(not resolved after t
  exploration trials) with pointwise 95% intervals (``scipy.stats.ecdf`` on
  ``scipy.stats.CensoredData``), and its median where S falls to 1/2;
- :func:`restricted_mean` is the restricted mean (RMST): the area under S up to the
  budget tau, i.e. the expected ``min(T, tau)``;
- :func:`survival_table` compares ``update`` with ``reset`` per model x measure x
  pretraining size x scenario: a log-rank test (``scipy.stats.logrank``), and the
  difference of restricted means with a 95% interval from a bootstrap over seeds
  resampled as pairs (``scipy.stats.bootstrap``, ``paired=True``).

Every p-value the report makes is corrected together (:func:`llcps.analysis.stats.adjust`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np
from scipy import stats as sps

from llcps.analysis.figure2 import figure2_order
from llcps.analysis.results import ResultsTable, group_rows
from llcps.analysis.stats import DEFAULT_RESAMPLES, cell_rng, pct_change
from llcps.experiments.design import condition_rank
from llcps.experiments.presets import PRESETS, WHOLE_SPACE
from llcps.experiments.rows import ResultRow, check_metric

#: The time scale of survival: exploration trials until the novelty was resolved.
SURVIVAL_METRIC = "exploration_trials"


@dataclass(frozen=True)
class KaplanMeier:
    """The Kaplan–Meier estimate of one sample of episodes.

    Attributes:
        times: the distinct times at which an episode was resolved or censored.
        survival: S just after each of ``times``.
        ci_low, ci_high: pointwise 95% interval of S (Greenwood, log-log).
        n: episodes; ``events`` of them resolved.
        median: trials by which half are resolved (None when S never falls to 1/2).
        tau: the horizon of the restricted mean (the budget).
        rmst: restricted mean trials to resolution up to ``tau``.
    """

    times: tuple[float, ...]
    survival: tuple[float, ...]
    ci_low: tuple[float, ...]
    ci_high: tuple[float, ...]
    n: int
    events: int
    median: float | None
    tau: float
    rmst: float


def _censored(times: np.ndarray, solved: np.ndarray) -> sps.CensoredData:
    return sps.CensoredData(uncensored=times[solved], right=times[~solved])


def _step_area(times: np.ndarray, survival: np.ndarray, tau: float) -> float:
    """Area under the step function S (1 before ``times[0]``, ``survival[i]`` from ``times[i]``) on [0, tau]."""
    edges = np.concatenate(([0.0], np.minimum(times, tau), [tau]))
    levels = np.concatenate(([1.0], survival))
    return float(np.sum(levels * np.diff(edges)))


def restricted_mean(times: Sequence[float], solved: Sequence[bool], tau: float) -> float:
    """Restricted mean trials to resolution: the area under the Kaplan–Meier curve up to ``tau``.

    With censoring only at the budget and ``tau`` the budget this is the capped mean;
    unlike the capped mean it stays unbiased for the restricted quantity when
    episodes are censored earlier (a lower budget, an interrupted run).
    """
    t = np.asarray(times, dtype=float)
    s = np.asarray(solved, dtype=bool)
    if t.size == 0:
        return math.nan
    if not s.any():  # no episode resolved: S is 1 as far as anything was seen
        return float(tau)
    sf = sps.ecdf(_censored(t, s)).sf
    return _step_area(np.asarray(sf.quantiles), np.asarray(sf.probabilities), tau)


def kaplan_meier(times: Sequence[float], solved: Sequence[bool], *, tau: float) -> KaplanMeier:
    """The Kaplan–Meier estimate of trials to resolution (unsolved episodes censored)."""
    t = np.asarray(times, dtype=float)
    s = np.asarray(solved, dtype=bool)
    if t.size == 0:
        raise ValueError("a Kaplan–Meier estimate needs at least one episode")
    if not s.any():
        grid = np.unique(t)
        ones = (1.0,) * grid.size
        return KaplanMeier(tuple(grid), ones, ones, ones, int(t.size), 0, None, float(tau), restricted_mean(t, s, tau))
    sf = sps.ecdf(_censored(t, s)).sf
    quantiles, probabilities = np.asarray(sf.quantiles, dtype=float), np.asarray(sf.probabilities, dtype=float)
    with warnings.catch_warnings():  # an interval is undefined where S is 0 or 1: NaN there
        warnings.simplefilter("ignore")
        ci = sf.confidence_interval(0.95, method="log-log")
    # Where it is undefined the band closes on the estimate: once every episode has
    # resolved (S = 0) nothing is left to be uncertain about, not everything.
    low, high = np.asarray(ci.low.probabilities), np.asarray(ci.high.probabilities)
    low, high = np.where(np.isnan(low), probabilities, low), np.where(np.isnan(high), probabilities, high)
    below = np.nonzero(probabilities <= 0.5)[0]
    return KaplanMeier(
        times=tuple(quantiles.tolist()),
        survival=tuple(probabilities.tolist()),
        ci_low=tuple(np.minimum(low, probabilities).tolist()),
        ci_high=tuple(np.maximum(high, probabilities).tolist()),
        n=int(t.size),
        events=int(s.sum()),
        median=float(quantiles[below[0]]) if below.size else None,
        tau=float(tau),
        rmst=_step_area(quantiles, probabilities, tau),
    )


def budget(rows: Iterable[ResultRow]) -> float:
    """The horizon tau of some rows: their preset's budget, else the largest count observed.

    A preset whose budget is the whole candidate space (:data:`WHOLE_SPACE`) ends an
    unsolved episode when its candidates run out, far below that number: its horizon is
    the largest count observed.
    """
    rows = list(rows)
    budgets = {PRESETS[r.preset].exploration_budget() for r in rows if r.preset in PRESETS}
    observed = max((r.exploration_trials for r in rows), default=0)
    if len(budgets) == 1 and observed <= max(budgets) < WHOLE_SPACE:
        return float(max(budgets))
    return float(observed)


@dataclass(frozen=True)
class SurvivalCurve:
    """The Kaplan–Meier curve of one cell and scenario."""

    model: str
    measure: str
    pretrain_size: int
    condition: str
    scenario: str
    estimate: KaplanMeier


def survival_curves(table: ResultsTable) -> tuple[SurvivalCurve, ...]:
    """One Kaplan–Meier curve per (model, measure, pretraining size, condition, scenario)."""
    out = []
    groups = group_rows(table, lambda r: (r.model, r.measure, r.pretrain_size, r.condition, r.scenario))
    for (model, measure, size, condition, scenario), part in sorted(
        groups.items(), key=lambda kv: (*figure2_order(*kv[0][:3], kv[0][4]), condition_rank(kv[0][3]))
    ):
        times = [r.exploration_trials for r in part]
        solved = [r.solved for r in part]
        out.append(SurvivalCurve(model, measure, size, condition, scenario, kaplan_meier(times, solved, tau=budget(part))))
    return tuple(out)


@dataclass(frozen=True)
class SurvivalComparison:
    """Update vs reset of one (model, measure, pretraining size, scenario), censoring-aware.

    ``rmst_*`` are restricted means up to ``tau`` over the paired seeds;
    ``rmst_diff_ci_*`` a paired-bootstrap interval of ``rmst_update - rmst_reset``;
    ``pct_change_rmst`` the paper's percent change computed on restricted means.
    ``p_value`` is the log-rank test's; ``p_adjusted`` is filled by the report's correction.
    """

    model: str
    measure: str
    pretrain_size: int
    scenario: str
    n_seeds: int
    tau: float
    solved_update: int
    solved_reset: int
    median_update: float | None
    median_reset: float | None
    rmst_update: float
    rmst_reset: float
    rmst_diff: float
    rmst_diff_ci_low: float
    rmst_diff_ci_high: float
    pct_change_rmst: float
    p_value: float
    p_reason: str
    p_adjusted: float = math.nan


def logrank(a_t: np.ndarray, a_s: np.ndarray, b_t: np.ndarray, b_s: np.ndarray) -> tuple[float, str]:
    """Two-sided log-rank p-value of two censored samples (times, resolved), with a reason when missing."""
    a_s, b_s = np.asarray(a_s, dtype=bool), np.asarray(b_s, dtype=bool)
    a_t, b_t = np.asarray(a_t, dtype=float), np.asarray(b_t, dtype=float)
    if not (a_s.any() or b_s.any()):
        return (math.nan, "no episode resolved in either sample")
    if np.array_equal(a_t, b_t) and np.array_equal(a_s, b_s):
        return (math.nan, "both samples identical")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = sps.logrank(_censored(a_t, a_s), _censored(b_t, b_s))
    p = float(result.pvalue)
    return (p, "") if math.isfinite(p) else (math.nan, "the log-rank statistic is undefined here")


def _logrank(u_t: np.ndarray, u_s: np.ndarray, r_t: np.ndarray, r_s: np.ndarray) -> tuple[float, str]:
    """:func:`logrank` of update against reset, its reasons in those terms."""
    p, reason = logrank(u_t, u_s, r_t, r_s)
    words = {
        "no episode resolved in either sample": "no episode resolved under either condition",
        "both samples identical": "both conditions identical seed by seed",
    }
    return p, words.get(reason, reason)


def paired_rmst_ci(
    u_t: np.ndarray, u_s: np.ndarray, r_t: np.ndarray, r_s: np.ndarray, *, tau: float, rng: np.random.Generator, resamples: int
) -> tuple[float, float]:
    """95% percentile interval of RMST(update) - RMST(reset), seeds resampled as pairs (``scipy.stats.bootstrap``)."""
    if u_t.size < 2 or (np.array_equal(u_t, r_t) and np.array_equal(u_s, r_s)):
        return (math.nan, math.nan)

    def diff(ut: np.ndarray, us: np.ndarray, rt: np.ndarray, rs: np.ndarray) -> float:
        return restricted_mean(ut, us.astype(bool), tau) - restricted_mean(rt, rs.astype(bool), tau)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a degenerate resample distribution gives NaN bounds, said as such
        result = sps.bootstrap(
            (u_t, u_s.astype(float), r_t, r_s.astype(float)),
            diff,
            paired=True,
            vectorized=False,
            n_resamples=resamples,
            method="percentile",
            rng=rng,
        )
    return (float(result.confidence_interval.low), float(result.confidence_interval.high))


def survival_table(
    table: ResultsTable, *, resamples: int = DEFAULT_RESAMPLES // 5, seed: int = 0
) -> tuple[SurvivalComparison, ...]:
    """Update vs reset per (model, measure, pretraining size, scenario), unsolved episodes censored.

    Only seeds run under both conditions are used, as for Figure 2. The bootstrap of
    a restricted mean refits two Kaplan–Meier curves per resample, so it defaults to
    a fifth of the Figure-2 intervals' resamples.
    """
    check_metric(SURVIVAL_METRIC)
    out: list[SurvivalComparison] = []
    groups = group_rows(table, lambda r: (r.model, r.measure, r.pretrain_size, r.scenario))
    for (model, measure, size, scenario), part in sorted(groups.items(), key=lambda kv: figure2_order(*kv[0])):
        upd = {r.seed: r for r in part if r.condition == "update"}
        res = {r.seed: r for r in part if r.condition == "reset"}
        seeds = sorted(set(upd) & set(res))
        if not seeds:
            continue
        tau = budget(part)
        u_t = np.array([upd[s].exploration_trials for s in seeds], dtype=float)
        u_s = np.array([upd[s].solved for s in seeds], dtype=bool)
        r_t = np.array([res[s].exploration_trials for s in seeds], dtype=float)
        r_s = np.array([res[s].solved for s in seeds], dtype=bool)
        ku, kr = kaplan_meier(u_t, u_s, tau=tau), kaplan_meier(r_t, r_s, tau=tau)
        p, reason = _logrank(u_t, u_s, r_t, r_s)
        low, high = paired_rmst_ci(
            u_t, u_s, r_t, r_s, tau=tau, rng=cell_rng(seed, model, measure, size, scenario, "rmst"), resamples=resamples
        )
        out.append(
            SurvivalComparison(
                model=model,
                measure=measure,
                pretrain_size=size,
                scenario=scenario,
                n_seeds=len(seeds),
                tau=tau,
                solved_update=ku.events,
                solved_reset=kr.events,
                median_update=ku.median,
                median_reset=kr.median,
                rmst_update=ku.rmst,
                rmst_reset=kr.rmst,
                rmst_diff=ku.rmst - kr.rmst,
                rmst_diff_ci_low=low,
                rmst_diff_ci_high=high,
                pct_change_rmst=float(pct_change(ku.rmst, kr.rmst)),
                p_value=p,
                p_reason=reason,
            )
        )
    return tuple(out)


__all__ = [
    "KaplanMeier",
    "SurvivalComparison",
    "SurvivalCurve",
    "budget",
    "kaplan_meier",
    "logrank",
    "paired_rmst_ci",
    "restricted_mean",
    "survival_curves",
    "survival_table",
]
