"""The experiment report as one self-contained HTML page (``report.html``).

Everything is inside the file: styles inline, plots and films as data URIs, so the
page can be mailed, attached or opened offline. It holds the overview, where the
runs ran, the generated summary, our Figure 2 beside the paper's, every plot the
report made (whatever :func:`~llcps.report.build.build_report` drew, survival
curves included when the statistics offer them) and a film of a resolving trial
per scenario.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path
from typing import Any, Mapping, Sequence

from llcps.analysis.analyse import Analysis
from llcps.inputs import read_user_file
from llcps.limits import MAX_EMBEDDED_BYTES
from llcps.report.tables import TableBlock

_MIME = {".png": "image/png", ".gif": "image/gif", ".svg": "image/svg+xml", ".jpg": "image/jpeg"}

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2rem auto; max-width: 78rem;
       padding: 0 1rem; color: #1d1d1f; line-height: 1.45; }
h1 { font-size: 1.7rem; margin-bottom: .2rem; } h2 { margin-top: 2.2rem; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: .6rem 0 1.2rem; font-size: .85rem; }
th, td { border: 1px solid #d0d0d0; padding: .25rem .5rem; text-align: right; }
th { background: #f3f3f3; } td.name { text-align: left; } td.paper, th.paper { background: #f7f3ea; }
.note { color: #555; font-size: .85rem; } figure { margin: 1rem 0 2rem; } figcaption { color: #444; font-size: .9rem; }
img { max-width: 100%; height: auto; border: 1px solid #eee; }
.films { display: flex; flex-wrap: wrap; gap: 1.2rem; } .films figure { margin: 0; }
ul.provenance li { font-family: ui-monospace, monospace; font-size: .8rem; }
"""


def data_uri(path: Path) -> str:
    """A file as a ``data:`` URI (its type from the suffix)."""
    mime = _MIME.get(path.suffix.lower(), "application/octet-stream")
    data = read_user_file(path, what="report file", max_bytes=MAX_EMBEDDED_BYTES, hint="remove it from the report directory, or report without --html")
    return f"data:{mime};base64," + base64.b64encode(data).decode("ascii")


def _e(text: Any) -> str:
    return html.escape(str(text), quote=True)


def _table(block: TableBlock, *, table_id: str, paper_columns: Sequence[int] = ()) -> str:
    paper_class = ' class="paper"'
    head = "".join(f"<th{paper_class if i in paper_columns else ''}>{_e(h)}</th>" for i, h in enumerate(block.header))
    rows = []
    for cells in block.body:
        tds = []
        for i, cell in enumerate(cells):
            cls = "name" if i < 2 else ("paper" if i in paper_columns else "")
            tds.append(f'<td class="{cls}">{_e(cell)}</td>' if cls else f"<td>{_e(cell)}</td>")
        rows.append("<tr>" + "".join(tds) + "</tr>")
    return f'<h3>{_e(block.title)}</h3>\n<table id="{_e(table_id)}" class="figure2"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'


def _figure(path: Path, caption: str, alt: str) -> str:
    return f'<figure><img src="{data_uri(path)}" alt="{_e(alt)}"><figcaption>{_e(caption)}</figcaption></figure>'


def render_html(
    analysis: Analysis,
    *,
    overview: str,
    method: str,
    summary: Sequence[str],
    figure2: Sequence[TableBlock],
    plots: Mapping[str, tuple[str, Path]],
    films: Mapping[str, Path],
    provenance: Sequence[str],
    unfilmed: Sequence[str] = (),
    generalization: Sequence[TableBlock] = (),
) -> str:
    """The page. ``plots`` maps a plot name to (caption, PNG path); ``films`` a scenario to its
    GIF; ``unfilmed`` names the scenarios without a film (no solved episode to show)."""
    parts = [
        "<!doctype html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>llcps experiment report</title><style>{_STYLE}</style></head><body>",
        "<h1>Experiment report</h1>",
        f"<p>{_e(overview)}</p>",
        f'<p class="note">{_e(method)}</p>',
        '<section id="provenance"><h2>Where it ran</h2>',
    ]
    if provenance:
        parts.append('<ul class="provenance">' + "".join(f"<li>{_e(line)}</li>" for line in provenance) + "</ul>")
    else:
        parts.append('<p class="note">No provenance recorded (results read from a file without it).</p>')
    parts += ["</section>", '<section id="summary"><h2>Summary (generated from the numbers)</h2><ul>']
    parts += [f"<li>{_e(line)}</li>" for line in summary]
    parts += ["</ul></section>", '<section id="figure2-section"><h2>Figure 2: % change in exploration with model updates, ours beside the paper\'s</h2>']
    if figure2:
        for i, block in enumerate(figure2):
            paper = [j for j, h in enumerate(block.header) if h.endswith(" paper")]
            parts.append(_table(block, table_id="figure2" if i == 0 else f"figure2-{i}", paper_columns=paper))
    else:
        parts.append('<p class="note">No Figure-2 cells: the results have no update/reset pairs in scenarios 2 and 3.</p>')
    parts.append(
        '<p class="note">* p &lt; 0.05 (paired Wilcoxon over seeds, uncorrected); ** also after Holm\'s correction. '
        "Shaded columns are the paper's numbers (4 runs per cell, no intervals).</p></section>"
    )
    if generalization:
        parts.append('<section id="generalization"><h2>Leave one family out</h2>')
        parts += [_table(block, table_id=f"generalization-{i}") for i, block in enumerate(generalization)]
        parts.append("</section>")
    parts.append('<section id="films"><h2>A resolving trial per scenario</h2>')
    if films:
        parts.append('<div class="films">')
        parts += [_figure(path, f"{scenario}: the resolving trial and the plan it enabled", f"{scenario} film") for scenario, path in films.items()]
        parts.append("</div>")
    else:
        parts.append('<p class="note">No films: no solved episode in these results, or the report was built without the store.</p>')
    if films and unfilmed:
        parts.append(f'<p class="note">No film of {_e(", ".join(unfilmed))}: no episode there resolved its novelty within the budget.</p>')
    parts.append("</section>")
    parts.append('<section id="plots"><h2>Plots</h2>')
    parts += [_figure(path, caption, name) for name, (caption, path) in plots.items()]
    parts.append("</section>")
    parts += [f'<p class="note">Bootstrap: {analysis.resamples} resamples, seed {analysis.seed}. Every table, for every cell: report.md beside this page.</p>', "</body></html>"]
    return "\n".join(parts) + "\n"


#: Public names of the page's parts, for other pages of the report (the lives' report).
STYLE = _STYLE
escape = _e
table_html = _table
figure_html = _figure

__all__ = ["STYLE", "data_uri", "escape", "figure_html", "render_html", "table_html"]
