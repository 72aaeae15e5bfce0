"""``llcps experiment run`` and ``llcps experiment report``: the paper's grid over many seeds."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Optional

import typer

from llcps.cli._common import EXIT_FAILED, EXIT_OK, resumable, settle_run, CreateFlag, JsonFlag, choice_enum, comma_list, message, new_app, notice, open_store, print_json, print_table
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display
from llcps.domain import MAX_SEED
from llcps.errors import LlcpsError
from llcps.outputs import check_output_dir
from llcps.provenance import cpu_count
from llcps.cps.orderings import ORDERINGS
from llcps.experiments.design import MAX_DRAWS
from llcps.experiments.executors import ENGINES
from llcps.experiments.presets import MAX_SEEDS, PRESETS
from llcps.scenarios.variants import parse_range

if TYPE_CHECKING:
    from llcps.experiments.scheduler import RunSummary

app = new_app(
    "Run the experiment grid (Figure 2 over many seeds) and report on it.",
    epilog=examples(
        "llcps --db runs.db experiment run --preset smoke --html",
        "llcps experiment report results/paper --html",
    ),
)

OutDir = Annotated[
    Optional[Path],
    typer.Option("--out-dir", metavar="DIR", help="Report directory (default: results/<preset>).", show_default=False, file_okay=False),
]
VARIANTS_HELP = (
    "Scene variants A:B (A..B-1), paired with the seeds: seed N solves its scenarios in variant N, "
    "so the statistics cover layouts as well as pretraining draws (variant 0 is the canonical scene)."
)
HtmlFlag = Annotated[
    bool,
    typer.Option("--html", help="Also write report.html: one self-contained page with every plot and a film of a resolving trial per scenario."),
]

PresetName = choice_enum("PresetName", tuple(PRESETS))
EngineName = choice_enum("EngineName", ENGINES)

#: Most workers one run may ask for.
MAX_WORKERS = 1024

_PRESET_HELP = "Grid to run: " + "; ".join(
    f"{p.name} ({len(p.cells())} cells, {p.default_seeds} seeds, budget {'the whole candidate space' if p.budget is None else p.budget})"
    for p in PRESETS.values()
) + "."


@app.command(
    "run",
    epilog=examples(
        "llcps --db runs.db experiment run --preset smoke                 # a couple of minutes",
        "llcps --db runs.db experiment run --preset paper --seeds 20 --workers 2",
        "llcps --db runs.db experiment run --preset paper --first-seed 20 --seeds 20   # another machine's share",
        "llcps --db runs.db experiment run --preset smoke --html --out-dir report/",
        "llcps --db runs.db experiment run --preset vs_random --variants 100:110   # seeds 100-109 on variants 100-109",
        "llcps --db runs.db experiment run --preset generalization --variants 0:10   # leave one family out, every shipped scenario",
        "llcps --db runs.db experiment run --preset generalization --scenarios scenario2,mine.toml --variants 0:5",
        "llcps --db runs.db experiment run --preset lifelong --scenarios scenario1,scenario4",
    ),
)
def run_cli(
    ctx: typer.Context,
    preset: Annotated[PresetName, typer.Option("--preset", help=_PRESET_HELP)] = PRESETS.default,  # type: ignore[valid-type, assignment]
    seeds: Annotated[
        Optional[int],
        typer.Option("--seeds", metavar="N", min=1, max=MAX_SEEDS, help="How many seeds (default: the preset's count).", show_default=False),
    ] = None,
    first_seed: Annotated[
        int,
        typer.Option(
            "--first-seed", metavar="K", min=0, max=MAX_SEED,
            help="Start the seeds at K (K..K+N-1): runners on several machines sharing one PostgreSQL store take disjoint seeds.",
        ),
    ] = 0,
    variants: Annotated[
        Optional[str],
        typer.Option("--variants", metavar="A:B", help=VARIANTS_HELP + " Takes the place of --seeds and --first-seed.", show_default=False),
    ] = None,
    scenarios: Annotated[
        Optional[str],
        typer.Option(
            "--scenarios",
            metavar="A,B,...",
            help="Scenarios each sequence solves, in order: names, aliases or .toml files (default: the preset's; "
            "the paper's three for the paper's presets, every shipped scenario for generalization).",
            show_default=False,
        ),
    ] = None,
    with_others: Annotated[
        bool,
        typer.Option(
            "--with-others",
            help="Solve each scenario on its own branch after the other scenarios of the list (the preset's reset "
            "becomes 'others'): the held-out family with experience of the rest.",
        ),
    ] = False,
    ordering: Annotated[
        Optional[str],
        typer.Option(
            "--ordering",
            metavar="NAME",
            help="Exploration ordering of every episode (default: the preset's: hedged, the default, for generalization, the paper's ranked for the others; the random order is always ranked); one of: " + ", ".join(ORDERINGS) + ". Run another ordering into another store "
            "and compare them in one report: `llcps experiment report DIR DIR --out-dir DIR`.",
            show_default=False,
        ),
    ] = None,
    random_draws: Annotated[
        Optional[int],
        typer.Option(
            "--random-draws",
            metavar="N",
            min=1,
            max=MAX_DRAWS,
            help="Permutations of the random order per seed (default: the preset's, 3 for generalization, else 1); "
            "leave one family out compares each ordering with their mean per variant.",
            show_default=False,
        ),
    ] = None,
    workers: Annotated[
        Optional[int],
        typer.Option("--workers", metavar="N", min=1, max=MAX_WORKERS, help="Worker processes or Ray tasks at once (default: one per CPU core).", show_default=False),
    ] = None,
    engine: Annotated[EngineName, typer.Option("--engine", help="local: a process pool; ray: Ray tasks (pip install 'llcps[ray]').")] = "local",  # type: ignore[valid-type, assignment]
    ray_address: Annotated[
        Optional[str],
        typer.Option("--ray-address", metavar="ADDR", help="Ray cluster to join (default: start a local Ray instance).", show_default=False),
    ] = None,
    out_dir: OutDir = None,
    html: HtmlFlag = False,
    cache: Annotated[
        bool,
        typer.Option(
            "--cache/--no-cache",
            help="Answer a trial simulated before (same physics settings, scene, state, call and step cap) from the store's physics cache, shared by all workers and later runs; results are identical either way.",
        ),
    ] = True,
    create: CreateFlag = False,
    as_json: JsonFlag = False,
) -> None:
    """Run every sequence of the grid the store does not hold yet, then write the report.

    Each task (a seed's pretraining, or one sequence) runs in a worker against a
    private store; this process imports each result in one transaction on the
    sequence's branch. A re-run skips what is stored: after Ctrl-C (exit 130) or a
    kill, run the same command again. Results are identical for any --workers and
    either engine. Exit code 1 when a task failed.
    """
    from llcps.jobs.experiment import run_experiment_job  # the runner and the report load here, not at start
    from llcps.experiments.presets import get_preset, run_seeds
    from llcps.report.build import default_out_dir

    name = str(preset.value)  # type: ignore[attr-defined]
    scenes = None if variants is None else parse_range(variants)
    chosen = comma_list(scenarios)
    target = check_output_dir(out_dir if out_dir is not None else default_out_dir(name), what="--out-dir")
    # The seeds and scenarios are checked before the store opens, so bad options create no store file.
    grid = get_preset(name).with_scenarios(chosen).with_ordering(ordering).with_random_draws(random_draws)
    if with_others:
        grid.with_others()
    run_seeds(grid, seeds=seeds, first_seed=first_seed, variants=scenes)
    with resumable("task"):
        with open_store(ctx, create=create) as store:
            with progress_display(f"experiment run {name}", "planning the tasks") as bar:

                def report(done: int, total: int, label: str) -> None:
                    bar(f"tasks (last: {label})" if label else "tasks", done, total)

                result = run_experiment_job(
                    store=store,
                    preset=name,
                    seeds=seeds,
                    first_seed=first_seed,
                    variants=scenes,
                    scenarios=chosen,
                    with_others=with_others,
                    ordering=ordering,
                    random_draws=random_draws,
                    workers=workers if workers is not None else cpu_count(),
                    engine=str(engine.value),  # type: ignore[attr-defined]
                    ray_address=ray_address,
                    cache=cache,
                    out_dir=target,
                    html=html,
                    progress=report,
                    report_progress=bar,
                )
    summary = result.summary
    settle_run(summary)
    if summary.blocked:
        notice(f"{summary.blocked} sequence(s) not run: their pretraining failed")
    if result.report_dir is None or result.analysis is None:
        raise LlcpsError("no results to report", hint="see the failed tasks above")
    out_dir, analysis = result.report_dir, dict(result.analysis)
    if as_json:
        print_json({"run": summary.as_json(), "report_dir": str(out_dir), **analysis})
    else:
        show_run(summary, out_dir)
        show_provenance(analysis)
        show_results(analysis)
    raise typer.Exit(EXIT_OK if summary.status == "ok" else EXIT_FAILED)


@app.command(
    "report",
    epilog=examples(
        "llcps experiment report --html                              # results/paper, with report.html",
        "llcps experiment report results/paper                       # rebuild from results.csv",
        "llcps experiment report results/ranked results/trial-and-error --out-dir results/orderings   # two orderings in one report",
        "llcps --db runs.db experiment report --from-db --preset paper --html",
        "llcps --db runs.db experiment report --from-db --preset paper --baseline-preset random --out-dir results/paper",
        "llcps --db runs.db experiment report --from-db --preset vs_random --variants 100:110 --out-dir results/held-apart",
    ),
)
def report_cli(
    ctx: typer.Context,
    sources: Annotated[
        Optional[list[Path]],
        typer.Argument(
            metavar="DIR",
            help="Results directories (their results.csv) or results .csv/.json files; the rows of several are merged "
            "into one table, rows they hold alike kept once (default: results/<preset>, that of --preset or of the "
            "default preset, when it holds results).",
            show_default=False,
        ),
    ] = None,
    from_db: Annotated[bool, typer.Option("--from-db", help="Read the results from the store's episodes instead (see --db).")] = False,
    preset: Annotated[
        Optional[str],
        typer.Option("--preset", metavar="NAME", help="Report on this preset only (needed when the results hold several).", show_default=False),
    ] = None,
    baseline_preset: Annotated[
        Optional[str],
        typer.Option(
            "--baseline-preset",
            metavar="NAME",
            help="Compare with the random-model results of this preset too (e.g. `random`, run on the same store).",
            show_default=False,
        ),
    ] = None,
    variants: Annotated[
        Optional[str],
        typer.Option(
            "--variants",
            metavar="A:B",
            help="Report on the sequences run with `experiment run --variants` over A..B-1 (default: the canonical scenes, or all when the results are of one variants run).",
            show_default=False,
        ),
    ] = None,
    out_dir: Annotated[
        Optional[Path],
        typer.Option(
            "--out-dir",
            metavar="DIR",
            help="Report directory (default: DIR itself, or results/<preset> with --from-db; required with several DIRs).",
            show_default=False,
            file_okay=False,
        ),
    ] = None,
    html: HtmlFlag = False,
    as_json: JsonFlag = False,
) -> None:
    """Rebuild the tables, CSV/JSON, plots and report.md (and report.html) from stored results,
    running no experiment; prints where the runs ran and our Figure 2.

    Without DIR or --from-db, the results directory of the preset (results/paper by
    default) is read. From a results directory, the provenance and films it already holds
    are used (`experiment run --html` films them); the films of report.html are made only
    with --from-db, which reads the results, and films a resolving trial per scenario,
    from the store (--db).

    Several DIRs make one report of their rows, e.g. of orderings run into separate stores
    (`experiment run --ordering`): leave one family out then compares every ordering with
    the same random-order rows. Rows the DIRs hold alike (the random order's, from copies
    of one store) count once; two different results for one branch, scenario and ordering
    are an error naming both DIRs. Each result row records its ordering; a results file
    written before it did reads as ranked. The provenance of every DIR is kept."""
    from llcps.jobs.experiment import report_experiment_job  # the analysis and the plots load here, not at start

    if sources and from_db:
        raise LlcpsError("give results directories or --from-db, not both", hint="e.g. `llcps experiment report results/paper`")
    scenes = None if variants is None else parse_range(variants)

    def build(results: Any, bar: Any) -> Any:
        return report_experiment_job(
            source=results, preset=preset, baseline_preset=baseline_preset, variants=scenes, out_dir=out_dir, html=html, progress=bar
        )

    with progress_display("experiment report", "reading the results") as bar:
        if not from_db:
            result = build(sources or None, bar)
        else:
            with open_store(ctx) as store:
                result = build(store, bar)
    if result.left_out:
        notice(
            f"{result.left_out} episode(s) on other scenes left out: a report pairs seeds over one set of scenes"
            + ("" if scenes is not None else " (report scene variants with --variants A:B)")
        )
    written, analysis = result.report_dir, dict(result.analysis)
    if html and not from_db and not analysis.get("films"):
        message(f"report.html has no films: {written} holds none; --from-db films a resolving trial per scenario from the store")
    if as_json:
        print_json({"report_dir": str(written), **analysis})
    else:
        message(f"report written to {written / 'report.md'}" + (f" and {analysis['report_html']}" if analysis.get("report_html") else ""))
        show_provenance(analysis)
        show_results(analysis)


def show_provenance(analysis: dict[str, Any]) -> None:
    """Where the results' runs ran, one line per distinct environment (stderr)."""
    from llcps.report.artifacts import provenance_line  # the report package loads here, not at start

    environments = analysis.get("provenance") or []
    if not environments:
        message("provenance: none recorded with these results")
    for item in environments:
        message(f"provenance: {provenance_line(item)}")


def show_run(summary: "RunSummary", out_dir: Path) -> None:
    """What the run did, for people (stderr)."""
    failed = f", {len(summary.failed)} failed" if summary.failed else ""
    rate = summary.cache_hit_rate
    cache = "" if rate is None else f", physics cache answered {summary.cache.get('hits', 0)} trial(s) ({rate:.0%})"  # type: ignore[union-attr]
    message(
        f"{summary.preset}: {summary.done} task(s) run, {summary.skipped} already stored{failed} "
        f"({summary.workers} {summary.engine} worker(s), {summary.wall_seconds:.1f} s{cache}); report in {out_dir / 'report.md'}"
    )


def _pct(value: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    return f"{value:+.0f}%"


def _ci(low: Any, high: Any) -> str:
    if low is None or high is None:
        return "n/a"
    return f"[{_pct(low)}, {_pct(high)}]"


def _num(value: Any) -> str:
    return "n/a" if value is None else f"{value:.1f}"


def _p(value: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    return "<0.001" if value < 0.001 else f"{value:.3f}"


def show_results(analysis: dict[str, Any]) -> None:
    """Our Figure 2 when the results pair update with reset, and the comparison with the
    random order when they hold it (a reset-only preset such as vs_random has only that)."""
    if analysis.get("figure2"):
        show_figure2(analysis)
    if (analysis.get("generalization") or {}).get("families"):
        show_generalization(analysis)
    elif analysis.get("random_comparison"):
        show_random(analysis)
    if not analysis.get("figure2") and not analysis.get("random_comparison"):
        notice("no update/reset pairs and no random-order results to compare: see the report's tables")


def show_random(analysis: dict[str, Any]) -> None:
    """Model-guided against the random order, per cell and scenario (medians, Holm-corrected p)."""
    rows = analysis.get("random_comparison", [])
    print_table(
        f"median {analysis.get('metric', 'exploration')}: model-guided vs random order (negative: the model explored less)",
        ("model", "measure", "pretrain", "condition", "scenario", "n", "median", "median random", "% change", "p", "Holm p"),
        [
            (
                r["model"],
                r["measure"],
                r["pretrain_size"],
                r["condition"],
                r["scenario"],
                r["n_model"],
                _num(r["median_model"]),
                _num(r["median_random"]),
                _pct(r["pct_change_median"]),
                _p(r["p_value"]),
                _p(r["p_holm"]),
            )
            for r in rows
        ],
    )


def _ratio(value: Any) -> str:
    if value is None:
        return "n/a"  # JSON null: infinite or undefined
    return f"{value:.2f}"


def show_generalization(analysis: dict[str, Any]) -> None:
    """Leave one family out: per held-out family, each row group (model / measure / ordering, when
    not all ran the paper's / pretraining / condition) against the random order, and overall."""
    from llcps.report.formatting import model_side_share

    data = analysis["generalization"]
    print_table(
        "leave one family out: median exploration trials per held-out family, row group vs random order "
        "(ratio > 1: the row group explored more)",
        ("family", "row group", "n", "random draws", "median", "median random", "median of ratios", "ratio of medians", "Wilcoxon p", "Holm p", "unsolved", "log-rank p", "by model side"),
        [
            (
                r["family"],
                r["label"] + (" (default)" if r["default"] else ""),
                r["n"],
                r["random_draws"],
                _num(r["median_model"]),
                _num(r["median_random"]),
                _ratio(r["median_ratio"]),
                _ratio(r["ratio_of_medians"]),
                _p(r["p_value"]),
                _p(r["p_holm"]),
                f"{r['unsolved_model']}/{r['unsolved_random']}",
                "-" if r["logrank_p"] is None else _p(r["logrank_p"]),
                model_side_share(r["resolved_by_model"], r["resolved_with_pick"]),
            )
            for r in data["families"]
        ],
    )
    print_table(
        f"over every family (geometric mean of the {data['headline_ratio']})",
        ("row group", "families", "geometric mean ratio", "families with ratio > 1"),
        [
            (
                r["label"] + (" (default)" if r["default"] else ""),
                r["families"],
                _ratio(r["geomean_ratio"]),
                r["worse_than_random"],
            )
            for r in data["overall"]
        ],
    )


def show_figure2(analysis: dict[str, Any]) -> None:
    """Our Figure 2 (update vs reset) with intervals and p-values, beside the paper's."""
    rows = analysis.get("figure2", [])
    print_table(
        f"% change of {analysis.get('metric', 'exploration')} with updates vs reset (negative: updates explored less)",
        ("model", "measure", "pretrain", "scenario", "seeds", "update", "reset", "% change", "95% CI", "p", "paper"),
        [
            (
                r["model"],
                r["measure"],
                r["pretrain_size"],
                r["scenario"],
                r["n_seeds"],
                _num(r["mean_update"]),
                _num(r["mean_reset"]),
                _pct(r["pct_change"]),
                _ci(r["ci_low"], r["ci_high"]),
                _p(r["p_value"]),
                _pct(r["paper_pct_change"]),
            )
            for r in rows
        ],
    )
