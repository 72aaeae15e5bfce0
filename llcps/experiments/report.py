"""The experiment report: tables, CSV/JSON, plots and a markdown page from a results table.

:func:`build_report` needs only a :class:`~llcps.experiments.results.ResultsTable`, so a
report can be rebuilt from a saved ``results.csv`` or from the store at any time
without re-running anything. The markdown puts our Figure 2 beside the paper's and
ends with a plain-words summary generated from the numbers; the interpretation of
why we agree or differ is written by hand in ``docs/results.md``.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from llcps.errors import LlcpsError
from llcps.tabular import csv_value
from llcps.experiments import plots
from llcps.experiments.grid import SCENARIO_SEQUENCE, condition_rank, measure_rank, model_rank
from llcps.experiments.results import METRICS, ResultsTable
from llcps.experiments.stats import (
    ALPHA,
    BASELINE_MODEL,
    DEFAULT_RESAMPLES,
    FIGURE2_SCENARIOS,
    PAPER_CAPTION_FRACTION_REDUCED,
    PAPER_FIGURE2,
    PAPER_RUNS_PER_CELL,
    CumulativePoint,
    Figure2Row,
    RandomComparison,
    best_versus_random,
    Reduction,
    cumulative_exploration,
    figure2_table,
    our_cells,
    paper_cells,
    random_comparison,
    reduction_summary,
    adjust,
)
from llcps.experiments.survival import SurvivalComparison, SurvivalCurve, survival_curves, survival_table

format_pct = plots.format_pct

#: The summary names at most this many cells in one sentence; the tables have them all.
SUMMARY_LIST_LIMIT = 8
#: How the paper names its two pretraining sizes.
PRETRAIN_NAMES = {200: "Apriori Training", 4: "No Apriori Training"}


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
    for scenario in [s for s in SCENARIO_SEQUENCE if s in table.unique("scenario")]:
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


@dataclass(frozen=True)
class ReportPaths:
    """Where :func:`build_report` wrote each file."""

    out_dir: Path
    results_csv: Path
    figure2_csv: Path
    figure2_json: Path
    random_csv: Path | None
    report_md: Path
    plots: Mapping[str, tuple[Path, ...]]
    survival_csv: Path | None = None
    report_html: Path | None = None
    films: Mapping[str, Path] = field(default_factory=dict)

    def all(self) -> tuple[Path, ...]:
        """Every file written, for listing or checking."""
        files = [self.results_csv, self.figure2_csv, self.figure2_json, self.report_md]
        if self.random_csv is not None:
            files.append(self.random_csv)
        if self.survival_csv is not None:
            files.append(self.survival_csv)
        if self.report_html is not None:
            files.append(self.report_html)
        files.extend(self.films.values())
        for paths in self.plots.values():
            files.extend(paths)
        return tuple(files)


def _overview(table: ResultsTable) -> dict[str, Any]:
    complete = table.complete_sequences()
    sequences = {r.sequence for r in table}
    unsolved = [r for r in table if not r.solved]
    seeds = sorted(table.unique("seed"))
    variants = sorted(table.unique("variant"))
    return {
        "variants": variants,
        "rows": len(table),
        "presets": list(table.unique("preset")),
        "models": sorted(table.unique("model"), key=model_rank),
        "measures": sorted(table.unique("measure"), key=measure_rank),
        "pretrain_sizes": sorted(table.unique("pretrain_size"), reverse=True),
        "conditions": sorted(table.unique("condition"), key=condition_rank),
        "seeds": len(seeds),
        "seed_range": [seeds[0], seeds[-1]] if seeds else None,
        "cells": len({r.cell for r in table}),
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
    """Run every statistic of :mod:`llcps.experiments.stats` on ``table``."""
    if metric not in METRICS:
        raise LlcpsError(f"unknown metric {metric!r}", hint=f"choose one of: {', '.join(METRICS)}")
    if resamples < 100:
        raise LlcpsError(f"{resamples} bootstrap resamples are too few for a 95% interval", hint="use 1000 or more")
    if len(table) == 0:
        raise LlcpsError("the results table is empty: nothing to report", hint="run `llcps experiment run` first")
    rows, survival, random = adjust(
        [
            figure2_table(table, metric=metric, resamples=resamples, seed=seed),
            survival_table(table, resamples=max(resamples // 5, 100), seed=seed),
            random_comparison(table, metric=metric),
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
        cumulative=cumulative_exploration(table, metric=metric, resamples=resamples, seed=seed),
        overview=_overview(table),
        survival=survival,
        curves=survival_curves(table),
        per_variant=per_variant(table, metric),
    )


# --------------------------------------------------------------------------------------
# Data out: JSON and CSV
# --------------------------------------------------------------------------------------
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
    """The analysis as plain, strict JSON data (NaN and infinity become null)."""
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


def _write_rows_csv(path: Path, rows: Iterable[Any], columns: Iterable[str]) -> Path:
    columns = list(columns)
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            record = asdict(row)
            writer.writerow({k: csv_value(record[k]) for k in columns})
    return path


# --------------------------------------------------------------------------------------
# Markdown
# --------------------------------------------------------------------------------------
def _num(value: float, digits: int = 1) -> str:
    return "n/a" if value is None or math.isnan(value) else f"{value:.{digits}f}"


def format_p(value: float, reason: str = "") -> str:
    """A p-value for a table: three decimals, ``<0.001``, or ``n/a`` with the reason."""
    if value is None or math.isnan(value):
        return f"n/a ({reason})" if reason else "n/a"
    return "<0.001" if value < 0.001 else f"{value:.3f}"


def format_ci(low: float, high: float) -> str:
    if math.isnan(low) or math.isnan(high):
        return "n/a"
    return f"[{format_pct(low)}, {format_pct(high)}]"


def _stars(row: Figure2Row) -> str:
    return "**" if row.p_holm < ALPHA else "*" if row.significant else ""


def _table(header: list[str], body: Iterable[Iterable[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines.extend("| " + " | ".join(cells) + " |" for cells in body)
    return lines


def _pretrain_title(size: int) -> str:
    name = PRETRAIN_NAMES.get(size)
    return f"{size} pretraining points" + (f' (the paper\'s "{name}")' if name else "")


@dataclass(frozen=True)
class TableBlock:
    """A titled table as text cells, rendered alike to markdown and to HTML."""

    title: str
    header: tuple[str, ...]
    body: tuple[tuple[str, ...], ...]


def figure2_blocks(rows: tuple[Figure2Row, ...]) -> list[TableBlock]:
    """The paper's layout: one block per pretraining size, ours next to the paper's."""
    out: list[TableBlock] = []
    shown = [r for r in rows if r.in_figure2]
    for size in sorted({r.pretrain_size for r in shown}, reverse=True):
        block = [r for r in shown if r.pretrain_size == size]
        scenarios = [s for s in FIGURE2_SCENARIOS if any(r.scenario == s for r in block)]
        header = ["model", "measure"]
        for s in scenarios:
            header += [f"{s} ours", "95% CI", "p", f"{s} paper"]
        index = {(r.model, r.measure, r.scenario): r for r in block}
        body = []
        for model, measure in dict.fromkeys((r.model, r.measure) for r in block):
            cells = [model, measure]
            for s in scenarios:
                r = index.get((model, measure, s))
                if r is None:
                    cells += ["", "", "", format_pct(PAPER_FIGURE2.get((model, measure, size, s)))]
                    continue
                paper = "" if r.paper_pct_change is None else format_pct(r.paper_pct_change)
                cells += [
                    f"{format_pct(r.pct_change)}{_stars(r)}",
                    format_ci(r.ci_low, r.ci_high),
                    format_p(r.p_value),
                    paper,
                ]
            body.append(cells)
        out.append(TableBlock(_pretrain_title(size), tuple(header), tuple(tuple(c) for c in body)))
    return out


def _figure2_side_by_side(rows: tuple[Figure2Row, ...]) -> list[str]:
    out: list[str] = []
    for block in figure2_blocks(rows):
        out += [f"### {block.title}", "", *_table(list(block.header), block.body), ""]
    return out


def _figure2_long(rows: tuple[Figure2Row, ...]) -> list[str]:
    header = [
        "model", "measure", "pretraining", "scenario", "n", "mean update", "mean reset",
        "% change", "95% CI", "Wilcoxon p", "Holm p", "solved update", "solved reset",
    ]  # fmt: skip
    body = [
        [
            r.model,
            r.measure,
            str(r.pretrain_size),
            r.scenario,
            str(r.n_seeds),
            _num(r.mean_update),
            _num(r.mean_reset),
            format_pct(r.pct_change),
            format_ci(r.ci_low, r.ci_high),
            format_p(r.p_value, r.p_reason),
            format_p(r.p_holm),
            f"{r.solved_update:.0%}",
            f"{r.solved_reset:.0%}",
        ]  # fmt: skip
        for r in rows
    ]
    return _table(header, body)


def _reduction_table(analysis: Analysis) -> list[str]:
    paper = {(r.pretrain_size, r.model): r for r in analysis.paper_reduction}
    header = [
        "pretraining", "model", "cells", "reduced (ours)", "reduced or unchanged (ours)",
        "reduced (paper table)", "reduced or unchanged (paper table)", "paper caption",
    ]  # fmt: skip
    body = []
    for r in analysis.ours_reduction:
        p = paper.get((r.pretrain_size, r.model))
        caption = PAPER_CAPTION_FRACTION_REDUCED.get(r.pretrain_size) if r.model is None else None
        body.append(
            [
                str(r.pretrain_size),
                r.model or "all",
                str(r.n_cells),
                f"{r.n_reduced}/{r.n_cells} ({r.fraction_reduced:.0%})",
                f"{r.n_reduced + r.n_unchanged}/{r.n_cells} ({r.fraction_not_increased:.0%})",
                f"{p.n_reduced}/{p.n_cells} ({p.fraction_reduced:.0%})" if p else "",
                f"{p.n_reduced + p.n_unchanged}/{p.n_cells} ({p.fraction_not_increased:.0%})" if p else "",
                f"{caption:.0%}" if caption is not None else "",
            ]  # fmt: skip
        )
    return _table(header, body)


def _random_table(comparisons: tuple[RandomComparison, ...]) -> list[str]:
    header = [
        "model", "measure", "pretraining", "condition", "scenario", "n", f"n {BASELINE_MODEL}",
        "median", f"median {BASELINE_MODEL}", "% change of median", "test", "p", "Holm p",
    ]  # fmt: skip
    body = [
        [
            c.model,
            c.measure,
            str(c.pretrain_size),
            c.condition,
            c.scenario,
            str(c.n_model),
            str(c.n_random),
            _num(c.median_model),
            _num(c.median_random),
            format_pct(c.pct_change_median),
            c.test,
            format_p(c.p_value, c.p_reason),
            format_p(c.p_holm),
        ]  # fmt: skip
        for c in comparisons
    ]
    return _table(header, body)


def _median(value: float | None, tau: float) -> str:
    return f">{tau:g}" if value is None else f"{value:g}"


def _survival_table(rows: tuple[SurvivalComparison, ...]) -> list[str]:
    header = [
        "model", "measure", "pretraining", "scenario", "n", "tau", "solved update", "solved reset",
        "median update", "median reset", "RMST update", "RMST reset", "% change of RMST", "difference 95% CI",
        "log-rank p", "Holm p",
    ]  # fmt: skip
    body = [
        [
            r.model, r.measure, str(r.pretrain_size), r.scenario, str(r.n_seeds), f"{r.tau:g}",
            f"{r.solved_update}/{r.n_seeds}", f"{r.solved_reset}/{r.n_seeds}",
            _median(r.median_update, r.tau), _median(r.median_reset, r.tau),
            _num(r.rmst_update), _num(r.rmst_reset), format_pct(r.pct_change_rmst),
            "n/a" if math.isnan(r.rmst_diff_ci_low) else f"[{r.rmst_diff_ci_low:+.1f}, {r.rmst_diff_ci_high:+.1f}]",
            format_p(r.p_value, r.p_reason), format_p(r.p_adjusted),
        ]  # fmt: skip
        for r in rows
    ]
    return _table(header, body)


def _sign(value: float) -> int:
    return 0 if value == 0 else (1 if value > 0 else -1)


def summary_lines(analysis: Analysis) -> list[str]:
    """Plain-words findings generated from the numbers (no interpretation of causes)."""
    lines: list[str] = []
    rows = analysis.figure2
    fig2 = [r for r in rows if r.in_figure2]
    paper = {(r.pretrain_size, r.model): r for r in analysis.paper_reduction}
    for r in analysis.ours_reduction:
        if r.model is not None:
            continue
        p = paper.get((r.pretrain_size, None))
        caption = PAPER_CAPTION_FRACTION_REDUCED.get(r.pretrain_size)
        text = (
            f"With {r.pretrain_size} pretraining points, updating the world model reduced mean exploration in "
            f"{r.n_reduced} of {r.n_cells} Figure-2 cells ({r.fraction_reduced:.0%})"
        )
        if p is not None:
            text += (
                f"; the paper's table shows {p.n_reduced} of {p.n_cells} ({p.fraction_reduced:.0%}; "
                f"{p.fraction_not_increased:.0%} counting its 0% cells)"
            )
            if caption is not None:
                text += f" and its caption states {caption:.0%}"
        lines.append(text + ".")
    if fig2:
        sig = [r for r in fig2 if r.significant]
        holm = [r for r in fig2 if r.p_holm < ALPHA]
        text = (
            f"{len(sig)} of {len(fig2)} Figure-2 cells differ between update and reset at p < {ALPHA} "
            f"(paired Wilcoxon over seeds, uncorrected); {len(holm)} {'remains' if len(holm) == 1 else 'remain'} after Holm's correction"
        )
        if holm:
            named = [f"{r.model}/{r.measure}/p{r.pretrain_size}/{r.scenario} {format_pct(r.pct_change)}" for r in holm]
            more = len(named) - SUMMARY_LIST_LIMIT
            text += ": " + "; ".join(named[:SUMMARY_LIST_LIMIT]) + (f"; and {more} more" if more > 0 else "")
        lines.append(text + ".")
    compared = [r for r in fig2 if r.paper_pct_change is not None]
    if compared:
        nonzero = [r for r in compared if r.paper_pct_change != 0]
        same = [r for r in nonzero if _sign(r.pct_change) == _sign(r.paper_pct_change)]
        outside = [
            r for r in compared
            if not math.isnan(r.ci_low) and not (r.ci_low <= r.paper_pct_change <= r.ci_high)
        ]  # fmt: skip
        lines.append(
            f"Where the paper reports a change, our estimate points the same way in {len(same)} of {len(nonzero)} "
            f"cells; the paper's value lies outside our 95% interval in {len(outside)} of {len(compared)} cells "
            f"(the paper averaged {PAPER_RUNS_PER_CELL} runs per cell, without intervals)."
        )
    control = [r for r in rows if r.scenario == SCENARIO_SEQUENCE[0]]
    if control:
        identical = [r for r in control if r.identical]
        sig = [r for r in control if r.significant]
        worst = max(control, key=lambda r: abs(r.pct_change) if not math.isnan(r.pct_change) else -1.0)
        lines.append(
            f"Control: in {SCENARIO_SEQUENCE[0]} both conditions start from the pretraining set, so they should agree. "
            f"{len(identical)} of {len(control)} cells are identical seed by seed, {len(sig)} {'shows' if len(sig) == 1 else 'show'} a difference at p < {ALPHA}, "
            f"the largest change is {format_pct(worst.pct_change)} ({worst.model}/{worst.measure}/p{worst.pretrain_size})."
        )
    if analysis.random:
        better = [c for c in analysis.random if c.pct_change_median < 0 and c.p_holm < ALPHA]
        worse = [c for c in analysis.random if c.pct_change_median > 0 and c.p_holm < ALPHA]
        lines.append(
            f"Against the {BASELINE_MODEL} order, {len(better)} of {len(analysis.random)} model x measure x "
            f"condition x scenario cells explore significantly less and {len(worse)} significantly more "
            f"(Holm-corrected p < {ALPHA})."
        )
    if analysis.survival:
        tested = [r for r in analysis.survival if not math.isnan(r.p_value)]
        sig = [r for r in tested if r.p_adjusted < ALPHA]
        censored = sum((r.n_seeds - r.solved_update) + (r.n_seeds - r.solved_reset) for r in analysis.survival)
        lines.append(
            f"Censoring-aware (unsolved episodes censored at the budget, {censored} of them in the paired cells): "
            f"{len(sig)} of {len(tested)} tested cells differ between update and reset by the log-rank test "
            f"after Holm's correction"
            + (
                f" ({untested} more have no test; the table says why, e.g. both conditions identical seed by seed)."
                if (untested := len(analysis.survival) - len(tested))
                else "."
            )
        )
    unsolved = analysis.overview.get("unsolved_episodes", 0)
    if unsolved:
        lines.append(
            f"{unsolved} episode(s) ended without solving their scenario; their exploration counts are the budget "
            f"spent, a lower bound on what solving would have taken."
        )
    return lines


def scenes_text(variants: Sequence[int]) -> str:
    """Which scenes a report covers, from the variants its episodes ran in."""
    if not variants or list(variants) == [0]:
        return "Scenes: the canonical scene of each scenario (variant 0)."
    contiguous = list(variants) == list(range(variants[0], variants[-1] + 1))
    span = f"{variants[0]}-{variants[-1]}" if contiguous else ", ".join(str(v) for v in variants)
    return f"Scenes: variants {span} of each scenario, paired with the seeds (seed N solves variant N; variant 0 is the canonical scene)."


def overview_text(analysis: Analysis) -> str:
    """The report's first paragraph: what the results hold."""
    o = analysis.overview
    seed_range = f" (seeds {o['seed_range'][0]}-{o['seed_range'][1]})" if o.get("seed_range") else ""
    return (
        f"Preset(s) {', '.join(o['presets'])}: {o['cells']} cells, {o['seeds']} seeds{seed_range}, "
        f"{o['sequences']} sequences ({o['complete_sequences']} complete), {o['rows']} episodes, "
        f"{o['unsolved_episodes']} unsolved. Simulated {o['sim_seconds']:.0f} s in {o['wall_seconds']:.0f} s of wall time. "
        + scenes_text(o.get("variants", [0]))
    )


def _variant_table(rows: tuple[VariantResult, ...], metric: str) -> list[str]:
    labels = list(rows[0].results) if rows else []
    body = [
        [
            v.scenario,
            str(v.variant),
            *(
                "-" if v.results[label] is None
                else _num(v.results[label][0], 0 if metric == "exploration_trials" else 1) + ("" if v.results[label][1] else " (unsolved)")
                for label in labels
            ),
        ]
        for v in rows
    ]
    return _table(["scenario", "variant", *labels], body)


def method_text(analysis: Analysis) -> str:
    """How the numbers are computed (one paragraph, markdown emphasis only on the metric)."""
    metric = analysis.metric.replace("_", " ")
    return (
        f"Measure of exploration: **{metric}**. % change with updates = 100 x (mean update - mean reset) / mean reset "
        f"over seeds run under both conditions (0% when both are 0). These are **capped means**: an unsolved "
        f"episode counts the budget it spent, a lower bound on what solving would have taken; the censoring-aware "
        f"comparison below treats it as censored instead. 95% intervals: percentile bootstrap over seeds "
        f"resampled as update/reset pairs (`scipy.stats.bootstrap`, {analysis.resamples} resamples, seed {analysis.seed}). "
        f"p: two-sided paired Wilcoxon signed-rank over seeds. Holm's correction (statsmodels) over every p-value "
        f"of this report together ({analysis.comparisons}: update vs reset, log-rank, against {BASELINE_MODEL} order). "
        f"`*` p < {ALPHA}, `**` also after Holm."
    )


def plot_caption(name: str, metric: str) -> str:
    """The caption of a plot the report drew, by its name in ``ReportPaths.plots``."""
    metric = metric.replace("_", " ")
    captions = {
        "figure2": "Figure 2 as a heatmap, ours beside the paper's",
        "distribution": f"{metric} per cell and condition",
        "cumulative": "cumulative exploration over the scenario sequence",
    }
    if name.startswith("survival_"):
        return f"Kaplan–Meier curves of trials to resolution, {name.removeprefix('survival_')}"
    return captions.get(name, name.replace("_", " "))


def table_budget(table: ResultsTable) -> int | None:
    """The exploration budget of the table's episodes, when its presets share one."""
    from llcps.experiments.grid import PRESETS

    budgets = {PRESETS[p].exploration_budget() if p in PRESETS else None for p in table.unique("preset")}
    return budgets.pop() if len(budgets) == 1 else None


def render_markdown(
    analysis: Analysis,
    plot_paths: Mapping[str, tuple[Path, ...]],
    out_dir: Path,
    *,
    provenance: Sequence[str] = (),
    films: Mapping[str, Path] | None = None,
) -> str:
    """The report page; plots and films are linked relative to ``out_dir``."""
    metric = analysis.metric.replace("_", " ")
    lines = [
        "# Experiment report",
        "",
        overview_text(analysis),
        "",
        method_text(analysis),
        "",
    ]
    if provenance:
        lines += ["## Where it ran", "", *[f"- {line}" for line in provenance], ""]
    lines += [
        "## Summary (generated from the numbers)",
        "",
        *[f"- {line}" for line in summary_lines(analysis)],
        "",
    ]
    if analysis.figure2:
        lines += [
            "## Figure 2: % change in exploration with model updates (capped means), ours beside the paper's",
            "",
            *_figure2_side_by_side(analysis.figure2),
        ]
        if "figure2" in plot_paths:
            lines += [f"![Figure 2 heatmap]({_rel(plot_paths['figure2'][0], out_dir)})", ""]
        lines += [
            "## How often updating reduced exploration",
            "",
            *_reduction_table(analysis),
            "",
            "## Every cell, every scenario",
            "",
            f"{SCENARIO_SEQUENCE[0]} is a control: both conditions start it from the pretraining set.",
            "",
            *_figure2_long(analysis.figure2),
            "",
        ]
    else:
        lines += [
            "These results pair no `update` sequence with a `reset` one (the preset runs one condition), "
            "so there is no Figure 2; the comparisons below are what they hold.",
            "",
        ]
    if analysis.survival:
        lines += [
            "## Censoring-aware: trials to resolution, unsolved episodes censored at the budget",
            "",
            "Kaplan–Meier medians (`>tau` when fewer than half resolved), restricted means up to the budget tau "
            "(the area under the Kaplan–Meier curve) with a 95% interval of their difference from a bootstrap over "
            "seeds resampled as pairs, and the log-rank test.",
            "",
            *_survival_table(analysis.survival),
            "",
        ]
    if analysis.random:
        lines += [f"## Model-guided vs {BASELINE_MODEL} order", "", *_random_table(analysis.random), ""]
        best = best_versus_random(analysis.random)
        if best:
            lines += [
                f"### The best model x measure per scenario (condition reset) against the {BASELINE_MODEL} order",
                "",
                "The cell with the lowest median per pretraining size and scenario; picking the best of "
                "several favours it, so read its p-value as descriptive.",
                "",
                *_random_table(best),
                "",
            ]
    if analysis.per_variant:
        lines += [
            "## Per scene variant",
            "",
            f"{metric.capitalize()} of each episode, scenario by scenario and variant by variant (one seed per variant).",
            "",
            *_variant_table(analysis.per_variant, analysis.metric),
            "",
        ]
    lines += ["## Plots", ""]
    captions = {
        "distribution": f"{metric} per cell and condition",
        "cumulative": "cumulative exploration over the scenario sequence",
    }
    for name in sorted(plot_paths):
        if name.startswith("survival_"):
            captions[name] = f"Kaplan–Meier curves of trials to resolution, {name.removeprefix('survival_')}"
    for name, caption in captions.items():
        if name in plot_paths:
            lines += [f"### {caption[0].upper() + caption[1:]}", "", f"![{caption}]({_rel(plot_paths[name][0], out_dir)})", ""]
    if films:
        lines += ["## A resolving trial per scenario", ""]
        lines += [f"![{scenario}]({_rel(path, out_dir)})" for scenario, path in films.items()]
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def _rel(path: Path, base: Path) -> str:
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return path.as_posix()


# --------------------------------------------------------------------------------------
# Everything at once
# --------------------------------------------------------------------------------------
def build_report(
    table: ResultsTable,
    out_dir: str | Path,
    *,
    metric: str = "exploration_trials",
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
    provenance: Sequence[Mapping[str, Any]] | None = None,
    films: Mapping[str, Path] | None = None,
    html: bool = False,
) -> ReportPaths:
    """Write results.csv, figure2.csv/json, random_comparison.csv, survival.csv, the plots and
    report.md (and report.html).

    Args:
        table: the results to report on.
        out_dir: directory for every file (created; existing report files are overwritten).
        metric: which of :data:`~llcps.experiments.results.METRICS` counts as exploration.
        resamples: bootstrap resamples per interval.
        seed: seed of the bootstrap streams; same table and seed give identical files.
        provenance: where the runs ran (:func:`~llcps.experiments.artifacts.table_provenance`);
            written to provenance.json. None: what ``out_dir`` already holds, if anything.
        films: scenario -> GIF of a resolving trial. None: the films ``out_dir`` already holds.
        html: also write the self-contained report.html.
    """
    from llcps.experiments import artifacts

    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LlcpsError(f"cannot create report directory {out}: {exc.strerror}") from None
    analysis = analyse(table, metric=metric, resamples=resamples, seed=seed)
    results_csv = table.write_csv(out / "results.csv")
    figure2_csv = _write_rows_csv(out / "figure2.csv", analysis.figure2, (f.name for f in fields(Figure2Row)))
    figure2_json = out / "figure2.json"
    figure2_json.write_text(json.dumps(analysis_json(analysis), indent=1, allow_nan=False) + "\n", encoding="utf-8")
    random_csv = None
    if analysis.random:
        random_csv = _write_rows_csv(
            out / "random_comparison.csv", analysis.random, (f.name for f in fields(RandomComparison))
        )
    if provenance is not None:
        artifacts.write_provenance(out, provenance)
    environments = [artifacts.provenance_line(p) for p in (provenance if provenance is not None else artifacts.read_provenance(out))]
    film_paths = dict(films) if films is not None else artifacts.existing_films(out)
    plot_dir = out / "plots"
    plot_paths = {
        "distribution": plots.exploration_distribution(table, plot_dir / "distribution", metric=metric, budget=table_budget(table)),
        "cumulative": plots.cumulative_plot(analysis.cumulative, plot_dir / "cumulative", metric=metric),
    }
    if analysis.figure2:  # a preset of one condition has no Figure 2 to draw
        plot_paths = {"figure2": plots.figure2_heatmap(analysis.figure2, plot_dir / "figure2"), **plot_paths}
    plot_paths.update({f"survival_{s}": paths for s, paths in plots.survival_plots(analysis.curves, plot_dir).items()})
    survival_csv = None
    if analysis.survival:
        survival_csv = _write_rows_csv(out / "survival.csv", analysis.survival, (f.name for f in fields(SurvivalComparison)))
    report_md = out / "report.md"
    report_md.write_text(
        render_markdown(analysis, plot_paths, out, provenance=environments, films=film_paths), encoding="utf-8"
    )
    report_html = None
    if html:
        from llcps.experiments.html import render_html

        report_html = out / "report.html"
        pngs = {
            name: (plot_caption(name, metric), next(p for p in paths if p.suffix == ".png"))
            for name, paths in plot_paths.items()
            if any(p.suffix == ".png" for p in paths)
        }
        report_html.write_text(
            render_html(
                analysis,
                overview=overview_text(analysis),
                method=method_text(analysis).replace("**", "").replace("`", ""),
                summary=summary_lines(analysis),
                figure2=figure2_blocks(analysis.figure2),
                plots=pngs,
                films=film_paths,
                provenance=environments,
                unfilmed=[s for s in SCENARIO_SEQUENCE if s in table.unique("scenario") and s not in film_paths],
            ),
            encoding="utf-8",
        )
    return ReportPaths(
        out, results_csv, figure2_csv, figure2_json, random_csv, report_md, plot_paths, survival_csv, report_html, film_paths
    )
