"""The report's tables: Figure 2 beside the paper's, every cell, the reductions, the
censoring-aware comparison, the random order and the scene variants, as markdown lines
(and Figure 2 as :class:`TableBlock` for the HTML page too)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

from llcps.analysis.analyse import Analysis, VariantResult
from llcps.analysis.figure2 import Figure2Row
from llcps.analysis.generalization import HEADLINE_RATIO, FamilyResult, GeneralizationSummary, group_label, shows_ordering
from llcps.analysis.paper import FIGURE2_SCENARIOS, PAPER_CAPTION_FRACTION_REDUCED, PAPER_FIGURE2, PRETRAIN_NAMES
from llcps.analysis.survival import SurvivalComparison
from llcps.analysis.versus_random import BASELINE_MODEL, RandomComparison
from llcps.report.formatting import format_ci, format_median, format_num, format_p, format_pct, model_side_share, stars


def markdown_table(header: list[str], body: Iterable[Iterable[str]]) -> list[str]:
    """A markdown table's lines."""
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
                    f"{format_pct(r.pct_change)}{stars(r)}",
                    format_ci(r.ci_low, r.ci_high),
                    format_p(r.p_value),
                    paper,
                ]
            body.append(cells)
        out.append(TableBlock(_pretrain_title(size), tuple(header), tuple(tuple(c) for c in body)))
    return out


def figure2_lines(rows: tuple[Figure2Row, ...]) -> list[str]:
    out: list[str] = []
    for block in figure2_blocks(rows):
        out += [f"### {block.title}", "", *markdown_table(list(block.header), block.body), ""]
    return out


def figure2_long_lines(rows: tuple[Figure2Row, ...]) -> list[str]:
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
            format_num(r.mean_update),
            format_num(r.mean_reset),
            format_pct(r.pct_change),
            format_ci(r.ci_low, r.ci_high),
            format_p(r.p_value, r.p_reason),
            format_p(r.p_holm),
            f"{r.solved_update:.0%}",
            f"{r.solved_reset:.0%}",
        ]  # fmt: skip
        for r in rows
    ]
    return markdown_table(header, body)


def reduction_lines(analysis: Analysis) -> list[str]:
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
    return markdown_table(header, body)


def random_lines(comparisons: tuple[RandomComparison, ...]) -> list[str]:
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
            format_num(c.median_model),
            format_num(c.median_random),
            format_pct(c.pct_change_median),
            c.test,
            format_p(c.p_value, c.p_reason),
            format_p(c.p_holm),
        ]  # fmt: skip
        for c in comparisons
    ]
    return markdown_table(header, body)


def survival_lines(rows: tuple[SurvivalComparison, ...]) -> list[str]:
    header = [
        "model", "measure", "pretraining", "scenario", "n", "tau", "solved update", "solved reset",
        "median update", "median reset", "RMST update", "RMST reset", "% change of RMST", "difference 95% CI",
        "log-rank p", "Holm p",
    ]  # fmt: skip
    body = [
        [
            r.model, r.measure, str(r.pretrain_size), r.scenario, str(r.n_seeds), f"{r.tau:g}",
            f"{r.solved_update}/{r.n_seeds}", f"{r.solved_reset}/{r.n_seeds}",
            format_median(r.median_update, r.tau), format_median(r.median_reset, r.tau),
            format_num(r.rmst_update), format_num(r.rmst_reset), format_pct(r.pct_change_rmst),
            "n/a" if math.isnan(r.rmst_diff_ci_low) else f"[{r.rmst_diff_ci_low:+.1f}, {r.rmst_diff_ci_high:+.1f}]",
            format_p(r.p_value, r.p_reason), format_p(r.p_adjusted),
        ]  # fmt: skip
        for r in rows
    ]
    return markdown_table(header, body)


def _ratio(value: float) -> str:
    return "n/a" if math.isnan(value) else ("inf" if math.isinf(value) else f"{value:.2f}")


def _km(value: float | None, unsolved: int) -> str:
    return "-" if unsolved == 0 and value is None else ("not reached" if value is None else format_num(value))


def _group_header(named: bool) -> str:
    return "model / measure / ordering / pretraining / condition" if named else "model / measure / pretraining / condition"


def _group_name(r: FamilyResult | GeneralizationSummary, named: bool) -> str:
    return group_label(r, ordering=named) + (" (default)" if r.default else "")


def generalization_block(rows: tuple[FamilyResult, ...]) -> TableBlock:
    """Per held-out family and row group: medians, both ratios, Wilcoxon and log-rank.

    The random order's figure per variant is the mean of its draws ("draws": how many).

    The row groups name their ordering when not all are of the paper's (:func:`shows_ordering`).
    """
    named = shows_ordering(rows)
    header = (
        "family", _group_header(named), "n", f"{BASELINE_MODEL} draws", "median trials", f"median {BASELINE_MODEL}", "median of ratios", "ratio of medians",
        "Wilcoxon p", "Holm p", "unsolved", f"unsolved {BASELINE_MODEL}", "KM median", f"KM median {BASELINE_MODEL}", "log-rank p",
        "resolved by the model side",
    )  # fmt: skip
    body = tuple(
        (
            r.family,
            _group_name(r, named),
            str(r.n),
            str(r.random_draws),
            format_num(r.median_model),
            format_num(r.median_random),
            _ratio(r.median_ratio),
            _ratio(r.ratio_of_medians),
            format_p(r.p_value, r.p_reason),
            format_p(r.p_holm),
            str(r.unsolved_model),
            str(r.unsolved_random),
            _km(r.km_median_model, r.unsolved_model + r.unsolved_random),
            _km(r.km_median_random, r.unsolved_model + r.unsolved_random),
            "-" if r.logrank_p is None and r.unsolved_model + r.unsolved_random == 0 else format_p(
                math.nan if r.logrank_p is None else r.logrank_p, r.logrank_reason
            ),
            model_side_share(r.resolved_by_model, r.resolved_with_pick),
        )
        for r in rows
    )
    return TableBlock(f"Leave one family out: each ordering against the {BASELINE_MODEL} order", header, body)


def generalization_overall_block(rows: tuple[GeneralizationSummary, ...]) -> TableBlock:
    """Per row group: the geometric mean of the per-family median ratios and the families above 1."""
    named = shows_ordering(rows)
    header = (_group_header(named), "families", f"geometric mean of the {HEADLINE_RATIO}", f"families worse than {BASELINE_MODEL} (ratio > 1)")
    body = tuple(
        (
            _group_name(r, named),
            str(r.families),
            _ratio(r.geomean_ratio),
            f"{r.worse_than_random} of {r.families}",
        )
        for r in rows
    )
    return TableBlock("Over every family", header, body)


def block_lines(block: TableBlock) -> list[str]:
    """A :class:`TableBlock` as markdown lines (without its title)."""
    return markdown_table(list(block.header), block.body)


def variant_lines(rows: tuple[VariantResult, ...], metric: str) -> list[str]:
    labels = list(rows[0].results) if rows else []
    body = [
        [
            v.scenario,
            str(v.variant),
            *(
                "-" if v.results[label] is None
                else format_num(v.results[label][0], 0 if metric == "exploration_trials" else 1) + ("" if v.results[label][1] else " (unsolved)")
                for label in labels
            ),
        ]
        for v in rows
    ]
    return markdown_table(["scenario", "variant", *labels], body)


__all__ = [
    "TableBlock",
    "block_lines",
    "generalization_block",
    "generalization_overall_block",
    "figure2_blocks",
    "figure2_lines",
    "figure2_long_lines",
    "markdown_table",
    "random_lines",
    "reduction_lines",
    "survival_lines",
    "variant_lines",
]
