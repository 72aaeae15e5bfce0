"""Every statistic of one results table at once, and the same as strict JSON data.

:func:`analyse` runs Figure 2 with intervals and p-values, the reductions beside the
paper's, the censoring-aware comparison, the comparison with the random order and the
cumulative exploration, and corrects every p-value together (Holm). A table of several
orderings (results of several stores, merged) is compared ordering by ordering in the
leave-one-family-out analysis; every other statistic covers one of them
(:func:`~llcps.analysis.selection.one_ordering`). The report's
tables, plots and pages are drawn from one :class:`Analysis` (:mod:`llcps.report`);
``figure2.json`` and ``--json`` are :func:`analysis_json` of it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Mapping

from llcps.analysis.cumulative import CumulativePoint, cumulative_exploration
from llcps.analysis.generalization import (
    HEADLINE_RATIO,
    FamilyResult,
    GeneralizationSummary,
    family_results,
    generalization_summary,
    group_label,
    shows_ordering,
)
from llcps.analysis.figure2 import Figure2Row, Reduction, figure2_table, our_cells, reduction_summary
from llcps.analysis.paper import PAPER_CAPTION_FRACTION_REDUCED, paper_cells
from llcps.analysis.results import ResultsTable, group_rows
from llcps.analysis.selection import one_ordering, orderings
from llcps.analysis.stats import ALPHA, DEFAULT_RESAMPLES, adjust
from llcps.analysis.survival import SurvivalComparison, SurvivalCurve, survival_curves, survival_table
from llcps.analysis.versus_random import RandomComparison, best_versus_random, random_comparison
from llcps.errors import LlcpsError
from llcps.experiments.design import condition_rank, scenario_rank
from llcps.experiments.presets import measure_rank, model_rank
from llcps.experiments.rows import check_metric


@dataclass(frozen=True)
class VariantResult:
    """One scenario in one scene variant: each cell's exploration (None: not run).

    ``results`` maps a cell label (``model / measure / pN / condition``) to the metric's
    value and whether the episode solved.
    """

    scenario: str
    variant: int
    seed: int
    results: Mapping[str, tuple[float, bool] | None]


@dataclass(frozen=True)
class Analysis:
    """Every statistic of one results table, computed once for the files and the page."""

    metric: str
    resamples: int
    seed: int
    figure2: tuple[Figure2Row, ...]
    ours_reduction: tuple[Reduction, ...]
    paper_reduction: tuple[Reduction, ...]
    random: tuple[RandomComparison, ...]
    cumulative: tuple[CumulativePoint, ...]
    overview: Mapping[str, Any]
    #: Update vs reset with unsolved episodes censored at the budget (log-rank, restricted means).
    survival: tuple[SurvivalComparison, ...] = ()
    #: Kaplan–Meier curve per cell, condition and scenario.
    curves: tuple[SurvivalCurve, ...] = ()
    #: Per scene variant and scenario, each cell's result (only when the table spans variants).
    per_variant: tuple[VariantResult, ...] = ()
    #: Leave one family out: each ordering against the random order per held-out family
    #: (Holm across each ordering's families, apart from the correction above).
    generalization: tuple[FamilyResult, ...] = ()
    #: Per ordering over every family: geometric mean of the median ratios, families > 1.
    generalization_overall: tuple[GeneralizationSummary, ...] = ()

    @property
    def comparisons(self) -> int:
        """How many p-values the report corrects together."""
        return sum(not math.isnan(r.p_value) for rows in (self.figure2, self.survival, self.random) for r in rows)


def per_variant(table: ResultsTable, metric: str) -> tuple[VariantResult, ...]:
    """The table scenario by scenario and variant by variant, when it spans several variants."""
    variants = sorted(table.unique("variant"))
    if len(variants) < 2:
        return ()
    cells = sorted(
        {r.cell for r in table},
        key=lambda c: (model_rank(c.model), measure_rank(c.measure), -c.pretrain_size, condition_rank(c.condition)),
    )
    by_key = {(r.scenario, r.variant, r.cell): r for r in table}
    out = []
    for scenario in sorted(table.unique("scenario"), key=scenario_rank):
        for variant in variants:
            rows = [by_key.get((scenario, variant, c)) for c in cells]
            seed = next((r.seed for r in rows if r is not None), None)
            if seed is None:
                continue
            out.append(
                VariantResult(
                    scenario,
                    variant,
                    seed,
                    {c.label: None if r is None else (r.metric(metric), r.solved) for c, r in zip(cells, rows)},
                )
            )
    return tuple(out)



def solve_order(table: ResultsTable) -> list[str]:
    """The table's scenarios in the order its sequences solved them.

    Under ``update`` one branch holds a sequence's episodes in order (episode ids grow);
    the order most sequences show wins. Without update rows (or episode ids), the
    paper's scenarios first, then the rest by name.
    """
    ranked = sorted(table.unique("scenario"), key=scenario_rank)
    orders: dict[tuple[str, ...], int] = {}
    for rows in group_rows((r for r in table if r.condition == "update" and r.episode_id is not None), lambda r: r.sequence).values():
        key = tuple(r.scenario for r in sorted(rows, key=lambda r: r.episode_id or 0))
        orders[key] = orders.get(key, 0) + 1
    if orders:
        best = max(orders.items(), key=lambda kv: (kv[1], len(kv[0])))[0]
        return list(best) + [s for s in ranked if s not in best]
    return ranked


def _overview(table: ResultsTable, cells: tuple[str, ResultsTable]) -> dict[str, Any]:
    """What the table holds; ``cells``: the ordering the per-cell sections cover, and its rows."""
    complete = table.complete_runs()
    sequences = {(r.sequence, r.ordering) for r in table}
    unsolved = [r for r in table if not r.solved]
    seeds = sorted(table.unique("seed"))
    variants = sorted(table.unique("variant"))
    return {
        "variants": variants,
        "scenarios": list(dict.fromkeys([*solve_order(cells[1]), *sorted(table.unique("scenario"), key=scenario_rank)])),
        "rows": len(table),
        "presets": list(table.unique("preset")),
        "models": sorted(table.unique("model"), key=model_rank),
        "measures": sorted(table.unique("measure"), key=measure_rank),
        "pretrain_sizes": sorted(table.unique("pretrain_size"), reverse=True),
        "conditions": sorted(table.unique("condition"), key=condition_rank),
        "orderings": list(orderings(table)),
        "cell_ordering": cells[0],
        "seeds": len(seeds),
        "seed_range": [seeds[0], seeds[-1]] if seeds else None,
        "cells": len({(r.cell, r.ordering) for r in table}),
        "sequences": len(sequences),
        "complete_sequences": len(complete & sequences),
        "unsolved_episodes": len(unsolved),
        "solved_fraction": (1.0 - len(unsolved) / len(table)) if len(table) else None,
        "sim_seconds": sum(r.sim_seconds for r in table),
        "wall_seconds": sum(r.wall_seconds for r in table),
    }


def analyse(
    table: ResultsTable, *, metric: str = "exploration_trials", resamples: int = DEFAULT_RESAMPLES, seed: int = 0
) -> Analysis:
    """Run every statistic of :mod:`llcps.analysis` on ``table``, with one Holm correction over all."""
    check_metric(metric)
    if resamples < 100:
        raise LlcpsError(f"{resamples} bootstrap resamples are too few for a 95% interval", hint="use 1000 or more")
    if len(table) == 0:
        raise LlcpsError("the results table is empty: nothing to report", hint="run `llcps experiment run` first")
    families = family_results(table, metric=metric)
    ordering, cells = one_ordering(table)
    rows, survival, random = adjust(
        [
            figure2_table(cells, metric=metric, resamples=resamples, seed=seed),
            survival_table(cells, resamples=max(resamples // 5, 100), seed=seed),
            random_comparison(cells, metric=metric),
        ]
    )
    return Analysis(
        metric=metric,
        resamples=resamples,
        seed=seed,
        figure2=rows,
        ours_reduction=reduction_summary(our_cells(rows)),
        paper_reduction=reduction_summary(paper_cells()),
        random=random,
        cumulative=cumulative_exploration(cells, metric=metric, resamples=resamples, seed=seed),
        overview=_overview(table, (ordering, cells)),
        survival=survival,
        curves=survival_curves(cells),
        per_variant=per_variant(cells, metric),
        generalization=families,
        generalization_overall=generalization_summary(families),
    )


def _clean(value: Any) -> Any:
    """JSON has no NaN or infinity: write them as null (CSV keeps ``nan``/``inf``)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def _reduction_json(r: Reduction) -> dict[str, Any]:
    return {**asdict(r), "fraction_reduced": r.fraction_reduced, "fraction_not_increased": r.fraction_not_increased}


def analysis_json(analysis: Analysis) -> dict[str, Any]:
    """The analysis as plain, strict JSON data (NaN and infinity become null).

    Each leave-one-family-out entry carries its row group's ``label`` as the report prints it.
    """
    named = shows_ordering(analysis.generalization)
    return _clean(
        {
            "metric": analysis.metric,
            "bootstrap": {
                "resamples": analysis.resamples,
                "seed": analysis.seed,
                "level": 0.95,
                "method": "percentile",
            },
            "alpha": ALPHA,
            "correction": {"method": "holm", "comparisons": analysis.comparisons},
            "overview": dict(analysis.overview),
            "figure2": [asdict(r) for r in analysis.figure2],
            "reduction": {
                "ours": [_reduction_json(r) for r in analysis.ours_reduction],
                "paper_table": [_reduction_json(r) for r in analysis.paper_reduction],
                "paper_caption": {str(k): v for k, v in PAPER_CAPTION_FRACTION_REDUCED.items()},
            },
            "random_comparison": [asdict(r) for r in analysis.random],
            "best_versus_random": [asdict(r) for r in best_versus_random(analysis.random)],
            "survival": [asdict(r) for r in analysis.survival],
            "kaplan_meier": [asdict(c) for c in analysis.curves],
            "generalization": {
                "headline_ratio": HEADLINE_RATIO,
                "correction": "holm across the families of each row group (model, measure, ordering, pretraining size, condition)",
                "families": [{**asdict(r), "label": group_label(r, ordering=named)} for r in analysis.generalization],
                "overall": [{**asdict(r), "label": group_label(r, ordering=named)} for r in analysis.generalization_overall],
            },
            "per_variant": [
                {**asdict(v), "results": {k: None if r is None else {"value": r[0], "solved": r[1]} for k, r in v.results.items()}}
                for v in analysis.per_variant
            ],
        }
    )


def report_json(
    table: ResultsTable, *, metric: str = "exploration_trials", resamples: int = DEFAULT_RESAMPLES, seed: int = 0
) -> dict[str, Any]:
    """The Figure-2 table and its companions as data, for ``--json``."""
    return analysis_json(analyse(table, metric=metric, resamples=resamples, seed=seed))


__all__ = ["Analysis", "VariantResult", "analyse", "analysis_json", "per_variant", "report_json", "solve_order"]
