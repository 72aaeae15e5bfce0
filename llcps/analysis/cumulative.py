"""Cumulative exploration over the scenario sequence: what lifelong learning saves in
total, per cell, with bootstrap intervals of the mean."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from llcps.analysis.figure2 import figure2_order
from llcps.analysis.results import ResultsTable
from llcps.analysis.stats import DEFAULT_RESAMPLES, bootstrap_mean_ci, cell_rng
from llcps.experiments.design import condition_rank, scenario_rank
from llcps.experiments.rows import check_metric


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
    check_metric(metric)
    complete = table.complete_sequences()
    per_cell: dict[tuple[str, str, int, str], dict[int, np.ndarray]] = {}
    order = sorted(table.unique("scenario"), key=scenario_rank)  # the paper's first, then by name
    position = {s: i for i, s in enumerate(order)}
    for row in table:
        if row.sequence not in complete:
            continue
        key = (row.model, row.measure, row.pretrain_size, row.condition)
        values = per_cell.setdefault(key, {}).setdefault(row.seed, np.zeros(len(order)))
        values[position[row.scenario]] = row.metric(metric)
    out: list[CumulativePoint] = []
    for key, seeds in sorted(
        per_cell.items(), key=lambda kv: (*figure2_order(*kv[0][:3], ""), condition_rank(kv[0][3]))
    ):
        matrix = np.cumsum(np.array([seeds[s] for s in sorted(seeds)]), axis=1)
        for j, scenario in enumerate(order):
            column = matrix[:, j]
            low, high = bootstrap_mean_ci(
                column, rng=cell_rng(seed, *key, scenario, metric, "cum"), resamples=resamples
            )
            out.append(CumulativePoint(*key, scenario, int(column.size), float(column.mean()), low, high))
    return tuple(out)


__all__ = ["CumulativePoint", "cumulative_exploration"]
