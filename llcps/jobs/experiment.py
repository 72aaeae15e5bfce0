"""Jobs of ``llcps experiment``: run a preset's grid over many seeds and report on it, or
rebuild the report from stored results.

Running (:mod:`llcps.experiments`) and reporting (:mod:`llcps.analysis`,
:mod:`llcps.report`) know nothing of each other; "run, then report" is composed here
once, for the CLI and :mod:`llcps.api` alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from llcps.analysis.results import ResultsTable, merge_tables, table_from_episodes
from llcps.analysis.selection import one_preset, results_table, select_scenes, with_baseline
from llcps.experiments.presets import Preset, get_preset, run_seeds
from llcps.experiments.runner import run_experiment
from llcps.experiments.scheduler import ProgressCallback, RunSummary
from llcps.errors import LlcpsError
from llcps.outputs import check_output_dir
from llcps.report.build import default_out_dir, write_report
from llcps.store import Store

#: Called as ``progress(phase, done, total)`` while the report is built.
ReportProgress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class ExperimentRun:
    """What ``experiment run`` did, and the report it wrote.

    ``report_dir`` and ``analysis`` are None when the run was interrupted (nothing is
    reported; the same command resumes) or when it left no results to report.
    """

    summary: RunSummary
    report_dir: Path | None = None
    #: The analysis as JSON data (``figure2.json``, with the provenance and report.html's path).
    analysis: Mapping[str, Any] | None = None


def run_experiment_job(
    *,
    store: Store,
    preset: str | Preset = "smoke",
    seeds: int | Iterable[int] | None = None,
    first_seed: int = 0,
    variants: range | None = None,
    scenarios: Iterable[str] | None = None,
    with_others: bool = False,
    ordering: str | None = None,
    random_draws: int | None = None,
    workers: int = 1,
    engine: str = "local",
    ray_address: str | None = None,
    cache: bool = True,
    out_dir: str | Path | None = None,
    html: bool = False,
    progress: ProgressCallback | None = None,
    report_progress: ReportProgress | None = None,
) -> ExperimentRun:
    """Run every sequence of a preset's grid the store does not hold yet, then report on its seeds.

    Args:
        store: the experience store; the only writer of this run.
        preset: a name in :data:`~llcps.experiments.presets.PRESETS` or a :class:`Preset`.
        seeds: a count (from ``first_seed``), explicit seeds, or None for the preset's default.
        first_seed: where a count of seeds starts (runners on several machines take disjoint seeds).
        variants: scene variants paired with the seeds (seed N solves variant N); takes
            the place of ``seeds`` and ``first_seed``.
        scenarios: the scenarios each sequence solves (names, aliases or .toml paths);
            None: the preset's own (the paper's three, or every shipped one for
            ``generalization``). The report covers these scenarios only.
        with_others: give each held-out scenario the other scenarios' episodes first
            (the preset's ``reset`` becomes ``others``).
        ordering: the exploration ordering (None: the preset's; :mod:`llcps.cps.orderings`).
        random_draws: permutations of the random order per seed (None: the preset's).
        workers, engine, ray_address, cache, progress: see
            :func:`~llcps.experiments.runner.run_experiment`.
        out_dir: the report's directory (default: ``results/<preset>``).
        html: also write report.html, with a film of a resolving trial per scenario.
        report_progress: called as ``(phase, done, total)`` while the report is built.
    """
    grid = (get_preset(preset) if isinstance(preset, str) else preset).with_scenarios(scenarios).with_ordering(ordering)
    grid = grid.with_random_draws(random_draws)
    if with_others:
        grid = grid.with_others()
    chosen = run_seeds(grid, seeds=seeds, first_seed=first_seed, variants=variants)
    paired = variants is not None
    summary = run_experiment(
        store,
        preset=grid,
        seeds=chosen,
        variants=paired,
        workers=workers,
        engine=engine,
        ray_address=ray_address,
        progress=progress,
        cache=cache,
    )
    if summary.status == "interrupted":
        return ExperimentRun(summary)
    table = results_table(store, summary.preset, summary.seeds, variants=paired, scenarios=grid.scenario_names())
    if len(table) == 0:
        return ExperimentRun(summary)
    target = out_dir if out_dir is not None else default_out_dir(summary.preset)
    report_dir, analysis = write_report(table, target, store=store, html=html, progress=report_progress)
    return ExperimentRun(summary, report_dir, analysis)


@dataclass(frozen=True)
class ExperimentReport:
    """The report ``experiment report`` wrote."""

    preset: str
    report_dir: Path
    #: The analysis as JSON data (``figure2.json``, with the provenance and report.html's path).
    analysis: Mapping[str, Any]
    #: Rows on other scenes left out: a report pairs seeds over one set of scenes.
    left_out: int


def default_results_dir(preset: str | None = None) -> Path:
    """The results directory ``experiment report`` reads when given none: that of ``preset``
    (None: the default preset), ``results/<preset>``, when it holds a results.csv.

    Raises:
        LlcpsError: it holds none, naming what to pass instead.
    """
    from llcps.experiments.presets import PRESETS

    name = preset or PRESETS.default
    path = default_out_dir(name)
    if not (path / "results.csv").is_file():
        raise LlcpsError(
            f"no results directory given, and {path} holds no results.csv",
            hint=f"pass a results directory (`llcps experiment report DIR`), run the grid first "
            f"(`llcps experiment run --preset {name}`), or read the store's episodes with --from-db "
            f"(`llcps --db runs.db experiment report --from-db --preset {name}`)",
        )
    return path


def read_results(paths: Sequence[str | Path]) -> ResultsTable:
    """The rows of one or several results directories or files, merged into one table
    (:func:`~llcps.analysis.results.merge_tables`: rows several hold alike are kept once,
    differing rows of one key are an error naming both)."""
    return merge_tables((str(path), ResultsTable.read(path)) for path in paths)


def report_experiment_job(
    *,
    source: str | Path | Store | Sequence[str | Path] | None = None,
    preset: str | None = None,
    baseline_preset: str | None = None,
    variants: range | None = None,
    out_dir: str | Path | None = None,
    html: bool = False,
    progress: ReportProgress | None = None,
) -> ExperimentReport:
    """Rebuild a report from stored results, running no experiment.

    Args:
        source: a results directory (its results.csv), a results .csv/.json file, several
            of them (their rows merged into one table: :func:`read_results`, e.g. the
            results of two orderings run into two stores), or a store (its episodes;
            provenance and films come from it too). From a directory, the provenance
            and films it already holds are kept; from several, every directory's
            provenance. None: the default results directory of ``preset``
            (:func:`default_results_dir`).
        preset: the preset to report on (needed when the results hold several).
        baseline_preset: add the random-model results of this preset (run on the same store).
        variants: report on the sequences run on these scene variants (default: the
            canonical scenes, or all when the results are of one variants run).
        out_dir: the report's directory (default: the source directory itself, or
            ``results/<preset>`` from a store); needed with several sources.
        html: also write report.html.
        progress: called as ``(phase, done, total)`` while the report is built.
    """
    if source is None:
        source = default_results_dir(preset)
    store = source if isinstance(source, Store) else None
    if store is not None:
        paths: list[Path] = []
    elif isinstance(source, (str, Path)):
        paths = [Path(source)]
    else:
        paths = list(dict.fromkeys(Path(p) for p in source))  # the same directory twice is read once
    if store is None and not paths:
        raise LlcpsError("no results directory given", hint="pass one or more results directories or results files")
    if len(paths) > 1 and out_dir is None:
        raise LlcpsError(
            f"a report of {len(paths)} results directories needs its own directory",
            hint="name it with --out-dir, e.g. `llcps experiment report results/ranked results/hedged --out-dir results/orderings`",
        )
    source_dirs = list(dict.fromkeys(path if path.is_dir() else path.parent for path in paths))
    table = table_from_episodes(store.list_episodes()).table if store is not None else read_results(paths)
    name, mine = one_preset(table, preset)
    if baseline_preset is not None:
        mine = with_baseline(mine, table, baseline_preset)
    mine, left_out = select_scenes(mine, variants)
    target = out_dir if out_dir is not None else (default_out_dir(name) if not source_dirs else source_dirs[0])
    target = check_output_dir(target, what="--out-dir")
    report_dir, analysis = write_report(mine, target, store=store, source_dirs=source_dirs, html=html, progress=progress)
    return ExperimentReport(name, report_dir, analysis, left_out)


__all__ = ["ExperimentReport", "ExperimentRun", "default_results_dir", "read_results", "report_experiment_job", "run_experiment_job"]
