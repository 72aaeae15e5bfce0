"""``report.md``: the report page in markdown, plots and films linked relative to it."""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

from llcps.analysis.analyse import Analysis
from llcps.analysis.versus_random import BASELINE_MODEL, best_versus_random
from llcps.analysis.generalization import HEADLINE_RATIO
from llcps.report.tables import (
    block_lines,
    figure2_lines,
    generalization_block,
    generalization_overall_block,
    figure2_long_lines,
    random_lines,
    reduction_lines,
    survival_lines,
    variant_lines,
)
from llcps.report.text import method_text, overview_text, summary_lines


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
            *figure2_lines(analysis.figure2),
        ]
        if "figure2" in plot_paths:
            lines += [f"![Figure 2 heatmap]({_rel(plot_paths['figure2'][0], out_dir)})", ""]
        lines += [
            "## How often updating reduced exploration",
            "",
            *reduction_lines(analysis),
            "",
            "## Every cell, every scenario",
            "",
            f"{(analysis.overview.get('scenarios') or ['the first scenario'])[0]} is a control: both conditions start it from the pretraining set.",
            "",
            *figure2_long_lines(analysis.figure2),
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
            *survival_lines(analysis.survival),
            "",
        ]
    if analysis.random:
        lines += [f"## Model-guided vs {BASELINE_MODEL} order", "", *random_lines(analysis.random), ""]
        best = best_versus_random(analysis.random)
        if best:
            lines += [
                f"### The best model x measure per scenario (condition reset) against the {BASELINE_MODEL} order",
                "",
                "The cell with the lowest median per pretraining size and scenario; picking the best of "
                "several favours it, so read its p-value as descriptive.",
                "",
                *random_lines(best),
                "",
            ]
    if analysis.generalization:
        lines += [
            "## Leave one family out: held-out novelty families against the random order",
            "",
            "Each scenario is a novelty family the pretraining never saw (it draws random layouts from the "
            "sampler's catalog); each row group (a model x measure explored in one ordering) solves it on the "
            "same scene variants as the random order, each episode on its own branch, and every ordering is "
            "compared with the same random-order rows. Ratios are trials(row group) / trials(random): above 1, "
            f"the row group explored more. The overall figure is the geometric mean of the families' {HEADLINE_RATIO} "
            "(per-variant ratios, paired). Wilcoxon: two-sided, paired by variant, Holm across each row group's "
            "families; Kaplan–Meier medians and the log-rank test only where an episode ended unsolved.",
            "",
            *block_lines(generalization_overall_block(analysis.generalization_overall)),
            "",
            *block_lines(generalization_block(analysis.generalization)),
            "",
        ]
        if "generalization" in plot_paths:
            lines += [f"![per-family ratios]({_rel(plot_paths['generalization'][0], out_dir)})", ""]
    if analysis.per_variant:
        lines += [
            "## Per scene variant",
            "",
            f"{metric.capitalize()} of each episode, scenario by scenario and variant by variant (one seed per variant).",
            "",
            *variant_lines(analysis.per_variant, analysis.metric),
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


__all__ = ["render_markdown"]
