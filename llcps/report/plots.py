"""Plots of an experiment, each written as PNG and SVG.

Figures are built on :class:`matplotlib.figure.Figure` with the Agg canvas directly,
never through pyplot, so plotting works headless and never changes a global
backend. SVGs carry a fixed hash salt and no date, so the same results give the same
files.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable, Sequence

import matplotlib
import matplotlib.lines
import matplotlib.patches
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

from llcps.cps.candidates import candidate_space_size
from llcps.analysis.cumulative import CumulativePoint
from llcps.analysis.figure2 import Figure2Row
from llcps.analysis.paper import FIGURE2_SCENARIOS, PAPER_FIGURE2
from llcps.analysis.results import ResultsTable
from llcps.analysis.stats import ALPHA
from llcps.analysis.generalization import FamilyResult, group_label, row_group, shows_ordering
from llcps.analysis.survival import SurvivalCurve
from llcps.experiments.design import cell_title, condition_rank, scenario_rank
from llcps.experiments.presets import measure_rank, model_rank
from llcps.outputs import written_atomically
from llcps.report.formatting import format_pct

#: What the stars of Figure 2 mean, printed under the heatmap.
STAR_NOTE = (
    f"* p < {ALPHA} (paired Wilcoxon over seeds, uncorrected)   ** also after Holm's correction   "
    "red: less exploration with updates, blue: more"
)
#: Colours of the two conditions, used by every plot.
CONDITION_COLORS = {"update": "#1f77b4", "reset": "#ff7f0e", "others": "#2ca02c"}
#: Heatmap colours span update/reset ratios from 1/8 to 8 (log2 from -3 to 3).
LOG2_RATIO_LIMIT = 3.0
FORMATS: tuple[str, ...] = ("png", "svg")
# Matplotlib 3.10 replaced boxplot's ``vert`` with ``orientation``.
_HORIZONTAL: dict[str, object] = (
    {"orientation": "horizontal"}
    if tuple(int(p) for p in matplotlib.__version__.split(".")[:2]) >= (3, 10)
    else {"vert": False}
)


def save(fig: Figure, stem: str | Path) -> tuple[Path, ...]:
    """Write ``fig`` as ``stem.png`` and ``stem.svg``; returns the paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    paths = []
    with matplotlib.rc_context({"svg.hashsalt": "llcps", "svg.fonttype": "none"}):
        for fmt in FORMATS:
            path = stem.with_suffix(f".{fmt}")
            metadata = {"Date": None} if fmt == "svg" else {"Software": None}
            with written_atomically(path, what="plot") as target:
                fig.savefig(target, format=fmt, dpi=120, bbox_inches="tight", metadata=metadata)
            paths.append(path)
    return tuple(paths)


def _log2_ratio(pct: float | None) -> float:
    # Colour by log2(update / reset) so halving and doubling are equally strong.
    if pct is None or math.isnan(pct):
        return math.nan
    ratio = 1.0 + pct / 100.0
    if ratio <= 0:
        return -LOG2_RATIO_LIMIT
    return float(np.clip(math.log2(ratio), -LOG2_RATIO_LIMIT, LOG2_RATIO_LIMIT))


def _heatmap_panel(
    fig: Figure,
    ax: object,
    values: np.ndarray,
    labels: list[list[str]],
    row_names: list[str],
    col_names: list[str],
    title: str,
) -> object:
    cmap = matplotlib.colormaps["RdBu"].with_extremes(bad="#dddddd")
    image = ax.imshow(  # type: ignore[attr-defined]
        np.ma.masked_invalid(values),
        cmap=cmap,
        norm=Normalize(-LOG2_RATIO_LIMIT, LOG2_RATIO_LIMIT),
        aspect="auto",
    )
    for i, row in enumerate(labels):
        for j, text in enumerate(row):
            strong = not math.isnan(values[i, j]) and abs(values[i, j]) > 0.6 * LOG2_RATIO_LIMIT
            ax.text(j, i, text, ha="center", va="center", fontsize=8, color="white" if strong else "black")  # type: ignore[attr-defined]
    ax.set_xticks(range(len(col_names)), col_names, fontsize=8)  # type: ignore[attr-defined]
    ax.set_yticks(range(len(row_names)), row_names, fontsize=8)  # type: ignore[attr-defined]
    ax.set_title(title, fontsize=10)  # type: ignore[attr-defined]
    return image


def figure2_heatmap(rows: Iterable[Figure2Row], stem: str | Path, *, with_paper: bool = True) -> tuple[Path, ...]:
    """Figure 2 as a heatmap: model x measure against scenario x pretraining size.

    Red is less exploration with updates (as in the paper), blue more; the colour is
    log2(update / reset). ``*`` marks p < 0.05 (Wilcoxon, uncorrected), ``**`` also
    after Holm's correction. With ``with_paper``, the paper's numbers for the same
    cells are drawn beside ours.
    """
    shown = [r for r in rows if r.in_figure2]
    pairs = sorted({(r.model, r.measure) for r in shown}, key=lambda k: (model_rank(k[0]), measure_rank(k[1])))
    cols = sorted({(r.pretrain_size, r.scenario) for r in shown}, key=lambda k: (-k[0], scenario_rank(k[1])))
    if not pairs:
        pairs, cols = [("-", "-")], [(0, FIGURE2_SCENARIOS[0])]
    index = {(r.model, r.measure, r.pretrain_size, r.scenario): r for r in shown}
    ours = np.full((len(pairs), len(cols)), math.nan)
    ours_text = [["n/a"] * len(cols) for _ in pairs]
    paper = np.full_like(ours, math.nan)
    paper_text = [[""] * len(cols) for _ in pairs]
    for i, (model, measure) in enumerate(pairs):
        for j, (size, scenario) in enumerate(cols):
            row = index.get((model, measure, size, scenario))
            if row is not None:
                ours[i, j] = _log2_ratio(row.pct_change)
                stars = "**" if row.p_holm < ALPHA else "*" if row.significant else ""
                ours_text[i][j] = f"{format_pct(row.pct_change)}{stars}"
            published = PAPER_FIGURE2.get((model, measure, size, scenario))
            paper[i, j] = _log2_ratio(published)
            paper_text[i][j] = format_pct(published) if published is not None else ""
    show_paper = with_paper and not np.all(np.isnan(paper))
    row_names = [f"{m} / {me}" for m, me in pairs]
    col_names = [f"{s.replace('scenario', 'S')}\np{size}" for size, s in cols]
    width = 1.6 + 0.9 * len(cols)
    # At least 2.6 in tall: with one or two rows the colour bar's labels need the room.
    fig = Figure(figsize=(width * (2 if show_paper else 1) + 1.5, max(2.6, 1.2 + 0.42 * len(pairs))), layout="constrained")
    axes = fig.subplots(1, 2 if show_paper else 1, squeeze=False)[0]
    n = max((r.n_seeds for r in shown), default=0)
    image = _heatmap_panel(fig, axes[0], ours, ours_text, row_names, col_names, f"ours (n <= {n} seeds per cell)")
    if show_paper:
        _heatmap_panel(fig, axes[1], paper, paper_text, row_names, col_names, "paper (4 runs per cell)")
        axes[1].set_yticks([])
    bar = fig.colorbar(image, ax=list(axes), shrink=0.8)
    ticks = np.arange(-LOG2_RATIO_LIMIT, LOG2_RATIO_LIMIT + 1)
    bar.set_ticks(ticks, labels=[format_pct(100 * (2.0**t - 1)) for t in ticks])
    bar.set_label("exploration % change with updates", fontsize=8)
    fig.suptitle("% change in exploration with model updates vs reset (Figure 2)", fontsize=11)
    fig.text(0.01, 0.0, STAR_NOTE, fontsize=7, ha="left", va="top")
    return save(fig, stem)


def _cell_order(keys: Iterable[tuple[str, str, int]]) -> list[tuple[str, str, int]]:
    return sorted(set(keys), key=lambda k: (model_rank(k[0]), measure_rank(k[1]), -k[2]))


def exploration_distribution(
    table: ResultsTable, stem: str | Path, *, metric: str = "exploration_trials", budget: int | None = None
) -> tuple[Path, ...]:
    """Box plot plus every seed's value, per cell and condition, one panel per scenario.

    The panels share the value axis, so scenarios compare at a glance; with ``budget``
    (exploration trials only) a dashed line marks the cap an unsolved episode stops at.
    """
    cells = _cell_order((r.model, r.measure, r.pretrain_size) for r in table)
    scenarios = sorted(table.unique("scenario"), key=scenario_rank) or ["-"]
    conditions = sorted({r.condition for r in table}, key=condition_rank) or ["update"]
    values: dict[tuple[str, str, int, str, str], list[float]] = {}
    for r in table:
        values.setdefault((r.model, r.measure, r.pretrain_size, r.condition, r.scenario), []).append(r.metric(metric))
    show_budget = budget is not None and metric == "exploration_trials"
    cap_label = f"budget cap ({budget} trials)"
    if show_budget and budget is not None and budget >= candidate_space_size():
        # A whole-space budget: an episode stops where the candidates end, not at the number.
        budget = candidate_space_size()
        cap_label = f"whole candidate space ({budget} trials)"
    # Tall enough to read with one cell; the legend gets a row of its own beneath.
    height = max(3.0, 1.4 + 0.5 * max(len(cells), 1) * max(1, len(conditions)) ** 0.5)
    fig = Figure(figsize=(3.4 * len(scenarios) + 2.4, height))
    axes = fig.subplots(1, len(scenarios), sharey=True, sharex=True, squeeze=False)[0]
    fig.subplots_adjust(wspace=0.08, top=1 - 0.55 / height, bottom=1.05 / height)
    jitter = np.random.default_rng(0)
    offsets = np.linspace(-0.2, 0.2, len(conditions)) if len(conditions) > 1 else np.zeros(1)
    for ax, scenario in zip(axes, scenarios):
        for k, condition in enumerate(conditions):
            color = CONDITION_COLORS.get(condition, "grey")
            data = [values.get((*cell, condition, scenario), []) for cell in cells]
            positions = [i + offsets[k] for i in range(len(cells))]
            present = [(p, d) for p, d in zip(positions, data) if d]
            if present:
                ax.boxplot(
                    [d for _, d in present],
                    positions=[p for p, _ in present],
                    **_HORIZONTAL,
                    widths=0.3 if len(conditions) > 1 else 0.5,
                    showfliers=False,
                    patch_artist=True,
                    boxprops={"facecolor": color, "alpha": 0.35},
                    medianprops={"color": "black"},
                    manage_ticks=False,
                )
            for p, d in present:
                ax.scatter(d, p + jitter.uniform(-0.08, 0.08, len(d)), s=9, color=color, zorder=3)
        if show_budget:
            ax.axvline(budget, color="#555555", linestyle="--", linewidth=1)
        ax.set_title(scenario, fontsize=10)
        ax.set_xlabel(metric.replace("_", " "), fontsize=8)
        ax.grid(axis="x", alpha=0.3)
        ax.set_xlim(left=0)
    axes[0].set_yticks(range(len(cells)), [cell_title(*cell) for cell in cells], fontsize=8)
    axes[0].set_ylim(len(cells) - 0.5, -0.5)
    handles = [
        matplotlib.patches.Patch(facecolor=CONDITION_COLORS.get(c, "grey"), alpha=0.5, label=f"{c}: box = quartiles, line = median")
        for c in conditions
    ]
    handles.append(matplotlib.lines.Line2D([], [], marker="o", linestyle="", markersize=4, color="#444444", label="one seed"))
    if show_budget:
        handles.append(matplotlib.lines.Line2D([], [], color="#555555", linestyle="--", label=cap_label))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    fig.suptitle(f"{metric.replace('_', ' ')} per cell, one panel per scenario", fontsize=11, y=1 - 0.12 / height)
    return save(fig, stem)


def cumulative_plot(
    points: Sequence[CumulativePoint], stem: str | Path, *, metric: str = "exploration_trials"
) -> tuple[Path, ...]:
    """Mean cumulative exploration along the scenario sequence, update vs reset, with 95% CI bands.

    One panel per model x measure (rows) and pretraining size (columns).
    """
    pairs = sorted({(p.model, p.measure) for p in points}, key=lambda k: (model_rank(k[0]), measure_rank(k[1])))
    sizes = sorted({p.pretrain_size for p in points}, reverse=True)
    pairs, sizes = pairs or [("-", "-")], sizes or [0]
    # Fixed spacing instead of constrained layout: with dozens of panels (the full
    # grid) the layout solver costs far more than drawing.
    height = 0.6 + 1.7 * len(pairs)
    fig = Figure(figsize=(3.2 * len(sizes) + 0.8, height))
    axes = fig.subplots(len(pairs), len(sizes), sharex=True, sharey=True, squeeze=False)  # one scale: panels compare
    fig.subplots_adjust(hspace=0.45, wspace=0.25, top=1 - 0.45 / height, bottom=0.35 / height)
    order = sorted({p.scenario for p in points}, key=scenario_rank)
    x = np.arange(len(order))
    lines: dict[tuple[str, str, int, str], dict[str, CumulativePoint]] = {}
    for p in points:
        lines.setdefault((p.model, p.measure, p.pretrain_size, p.condition), {})[p.scenario] = p
    for i, (model, measure) in enumerate(pairs):
        for j, size in enumerate(sizes):
            ax = axes[i, j]
            for condition in sorted({k[3] for k in lines}, key=condition_rank):
                line = lines.get((model, measure, size, condition))
                if not line:
                    continue
                pts = [line.get(s) for s in order]
                mean = np.array([p.mean if p else math.nan for p in pts])
                low = np.array([p.ci_low if p else math.nan for p in pts])
                high = np.array([p.ci_high if p else math.nan for p in pts])
                color = CONDITION_COLORS.get(condition, "grey")
                ax.plot(x, mean, marker="o", ms=3, color=color, label=condition)
                ax.fill_between(x, low, high, color=color, alpha=0.2, linewidth=0)
            ax.set_title(f"{model} / {measure} / p{size}", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
            if (i, j) == (0, 0) and ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7, loc="upper left")
    for ax in axes[-1]:
        ax.set_xticks(x, [s.replace("scenario", "S") for s in order])
    for ax in axes[:, 0]:
        ax.set_ylabel(f"cumulative\n{metric.replace('_', ' ')}", fontsize=7)
    fig.suptitle(
        "cumulative exploration over the scenario sequence (mean, 95% bootstrap CI)", fontsize=10, y=1 - 0.1 / height
    )
    return save(fig, stem)


def survival_plot(curves: Sequence[SurvivalCurve], stem: str | Path, *, scenario: str) -> tuple[Path, ...]:
    """Kaplan–Meier curves of trials to resolution in one scenario: one panel per condition,
    one step line per model x measure x pretraining size, with 95% bands.

    An unsolved episode is censored at its budget (a tick on its line), so a curve that
    ends above 0 says how many episodes the budget did not resolve.
    """
    mine = [c for c in curves if c.scenario == scenario]
    conditions = sorted({c.condition for c in mine}, key=condition_rank) or ["update"]
    cells = _cell_order((c.model, c.measure, c.pretrain_size) for c in mine)
    colors = matplotlib.colormaps["tab20"].resampled(max(len(cells), 1))
    fig = Figure(figsize=(4.2 * len(conditions) + 1.6, 3.6))
    axes = fig.subplots(1, len(conditions), sharey=True, squeeze=False)[0]
    fig.subplots_adjust(wspace=0.08, right=0.72 if cells else 0.95)
    for ax, condition in zip(axes, conditions):
        for k, cell in enumerate(cells):
            curve = next((c for c in mine if (c.model, c.measure, c.pretrain_size, c.condition) == (*cell, condition)), None)
            if curve is None:
                continue
            km = curve.estimate
            x = np.concatenate(([0.0], km.times, [km.tau])) if km.times else np.array([0.0, km.tau])
            y = np.concatenate(([1.0], km.survival, [km.survival[-1] if km.survival else 1.0]))
            low = np.concatenate(([1.0], km.ci_low, [km.ci_low[-1] if km.ci_low else 1.0]))
            high = np.concatenate(([1.0], km.ci_high, [km.ci_high[-1] if km.ci_high else 1.0]))
            color = colors(k)
            label = cell_title(*cell)
            ax.step(x, y, where="post", color=color, linewidth=1.2, label=label)
            ax.fill_between(x, low, high, step="post", color=color, alpha=0.12, linewidth=0)
            if km.events < km.n:  # censored at the budget
                ax.plot([km.tau], [km.survival[-1] if km.survival else 1.0], marker="|", ms=9, color=color)
        ax.set_title(f"{scenario}, {condition}", fontsize=10)
        ax.set_xlabel("exploration trials", fontsize=8)
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    axes[0].set_ylabel("P(not yet resolved)", fontsize=8)
    if cells:
        axes[-1].legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False)
    fig.suptitle("Kaplan–Meier estimate of trials to resolution (95% band; | censored at the budget)", fontsize=10)
    return save(fig, stem)


def survival_plots(curves: Sequence[SurvivalCurve], directory: str | Path) -> dict[str, tuple[Path, ...]]:
    """:func:`survival_plot` for every scenario of ``curves``, as ``survival_<scenario>`` in ``directory``."""
    scenarios = sorted({c.scenario for c in curves}, key=scenario_rank)
    return {s: survival_plot(curves, Path(directory) / f"survival_{s}", scenario=s) for s in scenarios}


def generalization_plot(rows: Sequence[FamilyResult], stem: str | Path) -> tuple[Path, ...]:
    """Per held-out family, each row group's ratio to the random order on a log axis: one
    series, in its own colour, per model x measure x ordering x pretraining size x condition.

    A filled marker is the median of the per-variant ratios, a hollow one the ratio of
    the medians; left of the line at 1 the row group explored less than random. Infinite
    or zero ratios are drawn at the axis' edge.
    """
    families = sorted({r.family for r in rows}, key=scenario_rank)
    groups = list(dict.fromkeys(row_group(r) for r in rows))
    named = shows_ordering(rows)
    height = 1.2 + 0.45 * max(len(families), 1) * max(len(groups), 1) ** 0.5
    fig = Figure(figsize=(6.4, height))
    ax = fig.subplots()
    finite = [v for r in rows for v in (r.median_ratio, r.ratio_of_medians) if math.isfinite(v) and v > 0]
    low, high = (min(finite + [0.5]) / 1.5, max(finite + [2.0]) * 1.5)
    step = 0.8 / max(len(groups), 1)
    colors = matplotlib.colormaps["tab10"]
    for k, key in enumerate(groups):
        mine = {r.family: r for r in rows if row_group(r) == key}
        ys = [i - 0.4 + step * (k + 0.5) for i, f in enumerate(families) if f in mine]
        shown = [mine[f] for f in families if f in mine]

        def clip(v: float) -> float:
            return high if v == math.inf or math.isnan(v) else (low if v <= 0 else min(max(v, low), high))

        label = group_label(shown[0], ordering=named)
        ax.scatter([clip(r.median_ratio) for r in shown], ys, color=colors(k % 10), label=f"{label}: median of ratios", zorder=3)
        ax.scatter(
            [clip(r.ratio_of_medians) for r in shown], ys, facecolors="none", edgecolors=colors(k % 10), label=f"{label}: ratio of medians", zorder=3
        )
    ax.axvline(1.0, color="black", linewidth=0.8)
    ax.set_xscale("log")
    ax.set_xlim(low, high)
    # Plain ratios at 1-2-5 steps: within a decade a log axis labels its minor ticks too, over each other.
    ax.xaxis.set_major_locator(FixedLocator([v for v in (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100) if low <= v <= high]))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_yticks(range(len(families)), families, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("exploration trials / random order's (log scale; < 1: fewer than random)", fontsize=8)
    ax.grid(alpha=0.3, axis="x")
    # Beside the axes, as the survival plots': every family's row has markers, so inside,
    # the legend would hide some.
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False)
    ax.set_title("leave one family out: each held-out family against the random order", fontsize=10)
    return save(fig, stem)
