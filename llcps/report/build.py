"""Building a report: every file from one results table into one directory.

:func:`build_report` needs only a :class:`~llcps.analysis.results.ResultsTable`, so a
report can be rebuilt from a saved ``results.csv`` or from the store at any time
without re-running anything: results.csv, figure2.csv/json, the comparisons' CSVs,
the plots, report.md with our Figure 2 beside the paper's, and report.html.
:func:`write_report` adds what only the store knows (where the runs ran, films).
"""

from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from llcps.analysis.analyse import analyse, analysis_json
from llcps.analysis.figure2 import Figure2Row
from llcps.analysis.generalization import FamilyResult
from llcps.analysis.results import ResultsTable, table_budget
from llcps.analysis.selection import one_ordering
from llcps.analysis.stats import DEFAULT_RESAMPLES
from llcps.analysis.survival import SurvivalComparison
from llcps.analysis.versus_random import RandomComparison
from llcps.errors import LlcpsError
from llcps.experiments.design import scenario_rank
from llcps.outputs import replaced_atomically, write_text
from llcps.report import artifacts, plots
from llcps.report.html import render_html
from llcps.report.markdown import render_markdown
from llcps.report.tables import figure2_blocks, generalization_block, generalization_overall_block
from llcps.report.text import method_text, overview_text, plot_caption, summary_lines
from llcps.store import Store
from llcps.tabular import csv_value

#: Where ``llcps experiment run`` writes a preset's report unless told otherwise.
RESULTS_DIR = Path("results")


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
    #: Leave one family out, per family and ordering (None: no random-order pairs).
    generalization_csv: Path | None = None
    generalization_json: Path | None = None

    def all(self) -> tuple[Path, ...]:
        """Every file written, for listing or checking."""
        files = [self.results_csv, self.figure2_csv, self.figure2_json, self.report_md]
        if self.random_csv is not None:
            files.append(self.random_csv)
        if self.survival_csv is not None:
            files.append(self.survival_csv)
        if self.report_html is not None:
            files.append(self.report_html)
        files.extend(p for p in (self.generalization_csv, self.generalization_json) if p is not None)
        files.extend(self.films.values())
        for paths in self.plots.values():
            files.extend(paths)
        return tuple(files)


def _write_rows_csv(path: Path, rows: Iterable[Any], columns: Iterable[str]) -> Path:
    columns = list(columns)
    with replaced_atomically(path, what="report") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            record = asdict(row)
            writer.writerow({k: csv_value(record[k]) for k in columns})
    return path


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
    """Write results.csv, figure2.csv/json, random_comparison.csv, survival.csv,
    generalization.csv/json (leave one family out, when the random order ran beside
    another ordering), the plots and report.md (and report.html).

    Args:
        table: the results to report on.
        out_dir: directory for every file (created; existing report files are overwritten).
        metric: which of :data:`~llcps.experiments.rows.METRICS` counts as exploration.
        resamples: bootstrap resamples per interval.
        seed: seed of the bootstrap streams; same table and seed give identical files.
        provenance: where the runs ran (:func:`~llcps.report.artifacts.table_provenance`);
            written to provenance.json. None: what ``out_dir`` already holds, if anything.
        films: scenario -> GIF of a resolving trial. None: the films ``out_dir`` already holds.
        html: also write the self-contained report.html.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LlcpsError(f"cannot create report directory {out}: {exc.strerror}") from None
    analysis = analyse(table, metric=metric, resamples=resamples, seed=seed)
    results_csv = table.write_csv(out / "results.csv")
    figure2_csv = _write_rows_csv(out / "figure2.csv", analysis.figure2, (f.name for f in fields(Figure2Row)))
    figure2_json = out / "figure2.json"
    write_text(figure2_json, json.dumps(analysis_json(analysis), indent=1, allow_nan=False) + "\n", what="report")
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
        "distribution": plots.exploration_distribution(
            one_ordering(table)[1], plot_dir / "distribution", metric=metric, budget=table_budget(table)
        ),
        "cumulative": plots.cumulative_plot(analysis.cumulative, plot_dir / "cumulative", metric=metric),
    }
    if analysis.figure2:  # a preset of one condition has no Figure 2 to draw
        plot_paths = {"figure2": plots.figure2_heatmap(analysis.figure2, plot_dir / "figure2"), **plot_paths}
    plot_paths.update({f"survival_{s}": paths for s, paths in plots.survival_plots(analysis.curves, plot_dir).items()})
    generalization_csv = generalization_json = None
    if analysis.generalization:
        plot_paths["generalization"] = plots.generalization_plot(analysis.generalization, plot_dir / "generalization")
        generalization_csv = _write_rows_csv(
            out / "generalization.csv", analysis.generalization, (f.name for f in fields(FamilyResult))
        )
        generalization_json = out / "generalization.json"
        write_text(generalization_json, json.dumps(analysis_json(analysis)["generalization"], indent=1, allow_nan=False) + "\n", what="report")
    survival_csv = None
    if analysis.survival:
        survival_csv = _write_rows_csv(out / "survival.csv", analysis.survival, (f.name for f in fields(SurvivalComparison)))
    report_md = out / "report.md"
    write_text(report_md, render_markdown(analysis, plot_paths, out, provenance=environments, films=film_paths), what="report")
    report_html = None
    if html:
        report_html = out / "report.html"
        pngs = {
            name: (plot_caption(name, metric), next(p for p in paths if p.suffix == ".png"))
            for name, paths in plot_paths.items()
            if any(p.suffix == ".png" for p in paths)
        }
        write_text(
            report_html,
            render_html(
                analysis,
                overview=overview_text(analysis),
                method=method_text(analysis).replace("**", "").replace("`", ""),
                summary=summary_lines(analysis),
                figure2=figure2_blocks(analysis.figure2),
                plots=pngs,
                films=film_paths,
                provenance=environments,
                unfilmed=[s for s in sorted(table.unique("scenario"), key=scenario_rank) if s not in film_paths],
                generalization=(
                    [generalization_overall_block(analysis.generalization_overall), generalization_block(analysis.generalization)]
                    if analysis.generalization
                    else []
                ),
            ),
            what="report",
        )
    return ReportPaths(
        out,
        results_csv,
        figure2_csv,
        figure2_json,
        random_csv,
        report_md,
        plot_paths,
        survival_csv,
        report_html,
        film_paths,
        generalization_csv,
        generalization_json,
    )


def default_out_dir(preset: str) -> Path:
    """``results/<preset>``."""
    return RESULTS_DIR / preset


def write_report(
    table: ResultsTable,
    out_dir: str | Path,
    *,
    store: Store | None = None,
    source_dirs: Sequence[Path] = (),
    html: bool = False,
    progress: Callable[[str, int, int], None] | None = None,
) -> tuple[Path, dict[str, Any]]:
    """Build every report file into ``out_dir``; returns it and the analysis as JSON data.

    With the ``store`` the results came from, the report records where their runs ran
    and, with ``html``, films a resolving trial per scenario for report.html. Without a
    store, where the runs ran comes from the report directory the results were read
    from (``source_dirs``), else from what ``out_dir`` holds; from several, every
    directory's, each marked with its directory (:func:`~llcps.report.artifacts.merged_provenance`).
    """
    provenance = films = None
    if store is None and len(source_dirs) > 1:
        provenance = artifacts.merged_provenance(source_dirs) or None
    elif store is None and source_dirs and Path(source_dirs[0]).resolve() != Path(out_dir).resolve():
        provenance = artifacts.read_provenance(Path(source_dirs[0])) or None
    if store is not None:
        provenance = artifacts.table_provenance(store, table)
        if html:
            films = artifacts.film_resolutions(store, table, Path(out_dir), progress=progress)
    if progress is not None:
        progress("statistics and plots", 0, 0)
    paths = build_report(table, out_dir, provenance=provenance, films=films, html=html)
    analysis = json.loads(paths.figure2_json.read_text(encoding="utf-8"))
    analysis["provenance"] = provenance if provenance is not None else artifacts.read_provenance(paths.out_dir)
    analysis["report_html"] = None if paths.report_html is None else str(paths.report_html)
    analysis["films"] = sorted(paths.films)
    return paths.out_dir, analysis


__all__ = ["RESULTS_DIR", "ReportPaths", "build_report", "default_out_dir", "write_report"]
