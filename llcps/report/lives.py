"""The report of a life run: episodes.csv, the metrics table, the learning curves and a
per-family panel, as report.md and a self-contained report.html.

Files written into the report directory:

- ``episodes.csv``: one row per (life, condition, episode) (:data:`~llcps.analysis.lives.COLUMNS`);
- ``after.csv``: the re-solves after each life (forgetting), same columns, ``episode`` -1;
- ``metrics.csv`` / ``metrics.json``: per condition AUC_life, its difference to reset,
  FT on first encounters and recurrences, the curve ratio, NRP and forgetting, with
  95% intervals over lives; ``families.csv``: per condition and family against reset;
- ``learning_curve.png/svg``, ``families.png/svg``; ``report.md`` (and ``report.html``).
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

from llcps.analysis.lives import COLUMNS, ConditionMetrics, Estimate, LifeMetrics, LifeRow, row_as_csv
from llcps.outputs import check_output_dir, replaced_atomically, write_text
from llcps.report.formatting import format_p
from llcps.report.tables import TableBlock, block_lines

#: Colours of the life conditions in every plot.
LIFE_COLORS = {"update": "#1f77b4", "reset": "#ff7f0e", "scratch": "#2ca02c", "random": "#7f7f7f"}
_MORE = ("#9467bd", "#8c564b", "#e377c2", "#17becf")


@dataclass(frozen=True)
class LifeReportPaths:
    directory: Path
    episodes: Path
    after: Path
    metrics: Path
    metrics_json: Path
    families: Path
    markdown: Path
    html: Path | None
    plots: tuple[Path, ...]


def _color(condition: str, order: Sequence[str]) -> str:
    return LIFE_COLORS.get(condition) or _MORE[order.index(condition) % len(_MORE)]


def _est(e: Estimate, digits: int = 3) -> str:
    if e.value is None or not math.isfinite(e.value):
        return "-"
    text = f"{e.value:.{digits}f}"
    if math.isfinite(e.low) and math.isfinite(e.high):
        text += f" [{e.low:.{digits}f}, {e.high:.{digits}f}]"
    return text


def metrics_block(metrics: LifeMetrics) -> TableBlock:
    """The FT / forgetting / NRP table: one row per condition."""
    header = (
        "condition", "lives", "AUC_life", "AUC_life - reset", "Wilcoxon p", "log-rank p (by episode)", "FT first encounters",
        "FT recurrences", "curve ratio (last/first quarter, over reset's)", f"NRP (last {metrics.last})", "forgetting",
        "originals kept after the life",
    )  # fmt: skip
    body = []
    for c in metrics.conditions:
        body.append(
            (
                c.condition, str(c.lives), _est(c.auc_life), _est(c.auc_difference), format_p(c.wilcoxon_p),
                format_p(c.logrank_p), _est(c.ft_first), _est(c.ft_recurrence), _est(c.curve_ratio, 2), _est(c.nrp),
                _est(c.forgetting), f"{c.originals_kept} of {c.originals}" if c.originals else "-",
            )
        )  # fmt: skip
    return TableBlock("Transfer, forgetting and novelty reaction (95% bootstrap intervals over lives)", header, tuple(body))


def family_block(metrics: LifeMetrics) -> TableBlock:
    header = ("condition", "family", "lives", "AUC", "AUC reset", "difference", "Wilcoxon p", "Holm p", "forgetting")
    body = tuple(
        (f.condition, f.family, str(f.lives), f"{f.auc:.3f}", f"{f.auc_reset:.3f}", _est(f.difference), format_p(f.p), format_p(f.p_holm),
         _est(f.forgetting))
        for f in metrics.families
    )  # fmt: skip
    return TableBlock("Per family, against reset on the same episodes", header, body)


def curve_block(metrics: LifeMetrics) -> TableBlock:
    conditions = list(dict.fromkeys(p.condition for p in metrics.curve))
    header = ("episode", *[f"{c}: mean [95% CI] (KM median)" for c in conditions])
    by = {(p.condition, p.episode): p for p in metrics.curve}
    body = []
    for k in range(metrics.episodes):
        cells = [str(k)]
        for c in conditions:
            p = by.get((c, k))
            if p is None:
                cells.append("-")
                continue
            band = f" [{p.low:.1f}, {p.high:.1f}]" if math.isfinite(p.low) and math.isfinite(p.high) else ""
            median = "-" if p.km_median is None else f"{p.km_median:g}"
            cells.append(f"{p.mean:.1f}{band} ({median})")
        body.append(tuple(cells))
    return TableBlock("Learning curve: exploration trials per episode (censored episodes count as tau)", header, tuple(body))


def learning_curve_plot(metrics: LifeMetrics, stem: Path) -> tuple[Path, ...]:
    from matplotlib.figure import Figure

    from llcps.report.plots import save

    conditions = list(dict.fromkeys(p.condition for p in metrics.curve))
    fig = Figure(figsize=(8.0, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    markers = "osD^vP*X"
    for j, c in enumerate(conditions):
        points = [p for p in metrics.curve if p.condition == c]
        xs = [p.episode for p in points]
        color = _color(c, conditions)
        # Markers of their own, so a condition's line hidden under another's still shows.
        ax.plot(xs, [p.mean for p in points], color=color, label=f"{c}: mean", linewidth=1.6, marker=markers[j % len(markers)],
                markersize=7 - j, alpha=0.85)  # fmt: skip
        lows = [p.low if math.isfinite(p.low) else p.mean for p in points]
        highs = [p.high if math.isfinite(p.high) else p.mean for p in points]
        ax.fill_between(xs, lows, highs, color=color, alpha=0.15, linewidth=0)
        medians = [math.nan if p.km_median is None else p.km_median for p in points]
        ax.plot(xs, medians, color=color, linestyle="--", linewidth=1.0, label=f"{c}: KM median")
    ax.set_xlabel("episode of the life")
    ax.set_ylabel("exploration trials")
    ax.set_yscale("symlog", linthresh=1.0)
    lives = len(metrics.lives)
    ax.set_title(f"Learning curves over {lives} {'life' if lives == 1 else 'lives'} (band: 95% bootstrap over lives)")
    ax.legend(fontsize=7, ncol=2)
    return save(fig, stem)


def family_plot(metrics: LifeMetrics, stem: Path) -> tuple[Path, ...]:
    from matplotlib.figure import Figure

    from llcps.report.plots import save

    conditions = list(dict.fromkeys(f.condition for f in metrics.families))
    families = sorted({f.family for f in metrics.families})
    fig = Figure(figsize=(max(5.0, 1.2 * len(families) + 2), 3.8))
    ax = fig.add_subplot(1, 1, 1)
    width = 0.8 / max(1, len(conditions))
    for j, c in enumerate(conditions):
        rows = {f.family: f for f in metrics.families if f.condition == c}
        xs, ys, errs = [], [], [[], []]
        for i, family in enumerate(families):
            f = rows.get(family)
            if f is None or not math.isfinite(f.difference.value):
                continue
            xs.append(i + (j - (len(conditions) - 1) / 2) * width)
            ys.append(f.difference.value)
            low = f.difference.low if math.isfinite(f.difference.low) else f.difference.value
            high = f.difference.high if math.isfinite(f.difference.high) else f.difference.value
            errs[0].append(f.difference.value - low)
            errs[1].append(high - f.difference.value)
        ax.bar(xs, ys, width=width, color=_color(c, conditions), label=c, yerr=errs, capsize=2)
    ax.axhline(0.0, color="black", linewidth=0.6)
    ax.set_xticks(range(len(families)), families, rotation=20, fontsize=8)
    ax.set_ylabel("AUC minus reset's (per life, mean)")
    ax.set_title("Per family: more than 0 is less exploration than from the pretraining point")
    if conditions:
        ax.legend(fontsize=7)
    return save(fig, stem)


def _write_csv(path: Path, rows: Iterable[LifeRow]) -> Path:
    with replaced_atomically(path, what="life report") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(COLUMNS), lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow(row_as_csv(row))
    return path


def _metrics_csv(path: Path, conditions: Sequence[ConditionMetrics]) -> Path:
    names = ["auc_life", "auc_difference", "ft_first", "ft_recurrence", "curve_ratio", "nrp", "forgetting"]
    with replaced_atomically(path, what="life report") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        header = ["condition", "lives"]
        for n in names:
            header += [n, f"{n}_low", f"{n}_high"]
        writer.writerow(header + ["wilcoxon_p", "logrank_p", "originals_kept", "originals"])
        for c in conditions:
            cells: list[Any] = [c.condition, c.lives]
            for n in names:
                e = getattr(c, n)
                cells += [_num(e.value), _num(e.low), _num(e.high)]
            writer.writerow(cells + [_num(c.wilcoxon_p), _num(c.logrank_p), c.originals_kept, c.originals])
    return path


def _families_csv(path: Path, metrics: LifeMetrics) -> Path:
    with replaced_atomically(path, what="life report") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(["condition", "family", "lives", "auc", "auc_reset", "difference", "difference_low", "difference_high", "p", "p_holm",
                         "forgetting", "forgetting_low", "forgetting_high"])  # fmt: skip
        for f in metrics.families:
            d, g = f.difference, f.forgetting
            writer.writerow([f.condition, f.family, f.lives, _num(f.auc), _num(f.auc_reset), _num(d.value), _num(d.low), _num(d.high), _num(f.p),
                             _num(f.p_holm), _num(g.value), _num(g.low), _num(g.high)])  # fmt: skip
    return path


def _num(value: float) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.6g}"


def overview(life: str, metrics: LifeMetrics, description: str) -> str:
    return (
        f"Life `{life}` ({description}): {len(metrics.lives)} {'life' if len(metrics.lives) == 1 else 'lives'} of {metrics.episodes} episodes, conditions "
        f"{', '.join(c.condition for c in metrics.conditions)}; tau = {metrics.tau} exploration trials."
    )


METHOD = (
    "N_k: exploration trials of episode k (an unsolved episode is censored and counts as tau). "
    "AUC_k = (tau - min(N_k, tau) + 1)/(tau + 1); AUC_life: a life's mean. FT = (AUC - AUC_reset)/(1 - AUC_reset) over "
    "first encounters and over recurrences. Forgetting: AUC of a family's first recurrence minus AUC of its re-solve "
    "(fresh variant) after the life. NRP: mean AUC of the last m episodes over reset's. Intervals: percentile bootstrap "
    "over lives; p: paired Wilcoxon over lives, log-rank stratified by episode index, Holm across families. "
    "See docs/experiments.md."
)


def write_life_report(
    rows: Sequence[LifeRow], metrics: LifeMetrics, out_dir: str | Path, *, life: str, description: str = "", html: bool = False
) -> LifeReportPaths:
    """Write every file of a life report into ``out_dir`` (created; old report files overwritten)."""
    out = check_output_dir(out_dir, what="life report directory")
    out.mkdir(parents=True, exist_ok=True)
    episodes = _write_csv(out / "episodes.csv", [r for r in rows if r.phase == "life"])
    after = _write_csv(out / "after.csv", [r for r in rows if r.phase != "life"])
    metrics_csv = _metrics_csv(out / "metrics.csv", metrics.conditions)
    families_csv = _families_csv(out / "families.csv", metrics)
    metrics_json = out / "metrics.json"
    write_text(metrics_json, json.dumps({"life": life, **metrics.as_json()}, indent=2, default=_json_default) + "\n", what="life report")
    plots: list[Path] = []
    curve_png = family_png = None
    if metrics.curve:
        curve_png = learning_curve_plot(metrics, out / "learning_curve")[0]
        plots.append(curve_png)
    if metrics.families:
        family_png = family_plot(metrics, out / "families")[0]
        plots.append(family_png)
    blocks = [metrics_block(metrics), curve_block(metrics), family_block(metrics)]
    text = overview(life, metrics, description)
    lines = [f"# Life report: {life}", "", text, "", METHOD, ""]
    for block in blocks[:1]:
        lines += block_lines(block) + [""]
    if curve_png is not None:
        lines += ["![Learning curves](learning_curve.png)", ""]
    lines += block_lines(blocks[1]) + [""]
    if family_png is not None:
        lines += ["![Per family](families.png)", ""]
    lines += block_lines(blocks[2]) + [""]
    markdown = out / "report.md"
    write_text(markdown, "\n".join(lines), what="life report")
    page = None
    if html:
        page = out / "report.html"
        write_text(page, render_life_html(life, text, blocks, curve_png, family_png), what="life report")
    return LifeReportPaths(out, episodes, after, metrics_csv, metrics_json, families_csv, markdown, page, tuple(plots))


def _json_default(value: Any) -> Any:
    if isinstance(value, float):
        return None
    raise TypeError(type(value).__name__)


def render_life_html(life: str, text: str, blocks: Sequence[TableBlock], curve: Path | None, families: Path | None) -> str:
    from llcps.report.html import STYLE, escape, figure_html, table_html

    parts = [
        "<!doctype html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>llcps life report: {escape(life)}</title><style>{STYLE}</style></head><body>",
        f"<h1>Life report: {escape(life)}</h1>",
        f"<p>{escape(text)}</p>",
        f'<p class="note">{escape(METHOD)}</p>',
        '<section id="metrics"><h2>Metrics</h2>',
        table_html(blocks[0], table_id="life-metrics"),
        "</section>",
        '<section id="curves"><h2>Learning curves per condition</h2>',
    ]
    if curve is not None:
        parts.append(figure_html(curve, "exploration trials against episode index: mean with a 95% band over lives, KM median dashed", "learning curves"))
    parts += [table_html(blocks[1], table_id="life-curve"), "</section>", '<section id="families"><h2>Per family</h2>']
    if families is not None:
        parts.append(figure_html(families, "per family: AUC minus reset's on the same episodes, 95% interval over lives", "per family"))
    parts += [table_html(blocks[2], table_id="life-families"), "</section>", "</body></html>"]
    return "\n".join(parts) + "\n"


__all__ = ["LifeReportPaths", "family_plot", "learning_curve_plot", "metrics_block", "render_life_html", "write_life_report"]
