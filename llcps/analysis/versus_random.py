"""Model-guided exploration against the random order: does a world model explore less
than no model at all?

Every model x measure is compared with the random model's exploration in the same
scenario: paired by seed (Wilcoxon) when the random order ran beside it, otherwise
against the pooled random sequences (Mann-Whitney U).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from llcps.analysis.figure2 import figure2_order
from llcps.analysis.results import ResultsTable, by_seed, group_rows
from llcps.analysis.stats import mann_whitney, paired_wilcoxon, pct_change
from llcps.experiments.design import RANDOM_ORDER_MODEL, condition_rank, scenario_rank
from llcps.experiments.rows import ResultRow, check_metric

#: The model whose order every other model is compared against.
BASELINE_MODEL = RANDOM_ORDER_MODEL


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
    check_metric(metric)
    base = group_rows(
        (r for r in table if r.model == baseline), lambda r: (r.measure, r.pretrain_size, r.condition, r.scenario)
    )
    if not base:
        return ()
    pooled = group_rows(
        (row for rows in base.values() for row in rows), lambda r: (r.pretrain_size, r.condition, r.scenario)
    )
    per_scenario = group_rows((row for rows in base.values() for row in rows), lambda r: r.scenario)
    out: list[RandomComparison] = []
    groups = group_rows(
        (r for r in table if r.model != baseline),
        lambda r: (r.model, r.measure, r.pretrain_size, r.condition, r.scenario),
    )

    def order(item: tuple[tuple[str, str, int, str, str], list[ResultRow]]) -> tuple:
        model, measure, size, condition, scenario = item[0]
        return (*figure2_order(model, measure, size, scenario), condition_rank(condition))

    for (model, measure, size, condition, scenario), part in sorted(groups.items(), key=order):
        mine = by_seed(part, metric)
        same = base.get((measure, size, condition, scenario))
        if same:
            theirs = by_seed(same, metric)
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


__all__ = ["BASELINE_MODEL", "RandomComparison", "best_versus_random", "random_comparison"]
