"""The report's prose: what the results hold, how the numbers are computed, and a
plain-words summary generated from the numbers (no interpretation of causes; that is
written by hand in docs/results.md)."""

from __future__ import annotations

import math
from typing import Sequence

from llcps.analysis.analyse import Analysis
from llcps.analysis.paper import PAPER_CAPTION_FRACTION_REDUCED, PAPER_RUNS_PER_CELL
from llcps.analysis.stats import ALPHA
from llcps.analysis.versus_random import BASELINE_MODEL
from llcps.report.formatting import format_pct

#: The summary names at most this many cells in one sentence; the tables have them all.
SUMMARY_LIST_LIMIT = 8


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
    first = (analysis.overview.get("scenarios") or [""])[0]  # solved first: update and reset start it alike
    control = [r for r in rows if r.scenario == first]
    if control:
        identical = [r for r in control if r.identical]
        sig = [r for r in control if r.significant]
        worst = max(control, key=lambda r: abs(r.pct_change) if not math.isnan(r.pct_change) else -1.0)
        lines.append(
            f"Control: in {first} both conditions start from the pretraining set, so they should agree. "
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
        + orderings_text(o.get("orderings") or [], o.get("cell_ordering"))
    )


def orderings_text(orderings: Sequence[str], cell_ordering: str | None) -> str:
    """Which orderings a report of several covers where (nothing for a report of one)."""
    if len(orderings) < 2:
        return ""
    return (
        f" Orderings: {', '.join(orderings)}; leave one family out compares each with the random order, "
        f"every other section covers the {cell_ordering} ordering (and the random order)."
    )


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
        "generalization": "per held-out family: trials of each ordering over the random order's (log axis)",
    }
    if name.startswith("survival_"):
        return f"Kaplan–Meier curves of trials to resolution, {name.removeprefix('survival_')}"
    return captions.get(name, name.replace("_", " "))


__all__ = ["SUMMARY_LIST_LIMIT", "method_text", "orderings_text", "overview_text", "plot_caption", "scenes_text", "summary_lines"]
