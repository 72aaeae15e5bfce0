"""``llcps life run|report|list|show``: lives in which novelty families recur, paired over conditions."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from llcps.cli._common import EXIT_FAILED, EXIT_OK, resumable, settle_run, CreateFlag, JsonFlag, choice_enum, comma_list, message, new_app, open_store, print_json, print_table
from llcps.cli._conventions import examples
from llcps.domain import MAX_SEED
from llcps.cli._progress import progress_display
from llcps.errors import LlcpsError
from llcps.experiments.executors import ENGINES
from llcps.experiments.life import LIFE_CONDITIONS, MAX_EPISODES, condition_names
from llcps.outputs import check_output_dir
from llcps.provenance import cpu_count

app = new_app(
    "Run lives (sequences of episodes in which novelty families recur) under paired conditions, and report their transfer.",
    epilog=examples(
        "llcps life list",
        "llcps life show default --life 3",
        "llcps --db lives.db life run default --lives 20 --workers 2 --out-dir results/life_default --html",
        "llcps --db lives.db life report default --html",
    ),
)

EngineName = choice_enum("EngineName", ENGINES)
MAX_WORKERS = 1024

LifeArg = Annotated[str, typer.Argument(metavar="LIFE", help="A shipped life (`llcps life list`) or a life .toml file.")]
OutDir = Annotated[
    Optional[Path],
    typer.Option("--out-dir", metavar="DIR", help="Report directory (default: results/life_<name>).", show_default=False, file_okay=False),
]
HtmlFlag = Annotated[bool, typer.Option("--html", help="Also write report.html: one self-contained page with the curves and tables.")]


@app.command(
    "run",
    epilog=examples(
        "llcps --db lives.db life run paper --lives 20 --workers 2          # the lifelong preset's episodes, as lives",
        "llcps --db lives.db life run default --lives 20 --workers 2 --html",
        "llcps --db lives.db life run default --lives 2 --episodes 8 --conditions update,reset   # a quick look",
        "llcps --db lives.db life run default --lives 20 --conditions update,reset,ranked   # an ordering as a condition",
        "llcps --db postgresql://host/lives life run default --first-life 20 --lives 20   # another machine's share",
        "llcps --db lives.db life run mine.toml --lives 5 --json",
    ),
)
def run_cli(
    ctx: typer.Context,
    life: LifeArg,
    lives: Annotated[int, typer.Option("--lives", metavar="N", min=1, max=10_000, help="How many lives (life N draws its episodes from seed N).")] = 1,
    first_life: Annotated[
        int,
        typer.Option("--first-life", metavar="K", min=0, max=MAX_SEED, help="Start at life K (K..K+N-1): runners on several machines sharing one store take disjoint lives."),
    ] = 0,
    episodes: Annotated[
        Optional[int],
        typer.Option("--episodes", metavar="K", min=1, max=MAX_EPISODES, help="Cut each life to its first K episodes (a quick look; a store holds one length per life).", show_default=False),
    ] = None,
    conditions: Annotated[
        Optional[str],
        typer.Option("--conditions", metavar="A,B", help="Conditions to run instead of the file's: "
                     + "; ".join(f"{c.name} ({c.description})" for c in LIFE_CONDITIONS.values())
                     + "; or an exploration ordering, update exploring in it ('_' for '-'): "
                     + ", ".join(n for n in condition_names() if n not in LIFE_CONDITIONS) + ".", show_default=False),
    ] = None,
    workers: Annotated[
        Optional[int],
        typer.Option("--workers", metavar="N", min=1, max=MAX_WORKERS, help="Worker processes or Ray tasks at once (default: one per CPU core).", show_default=False),
    ] = None,
    engine: Annotated[EngineName, typer.Option("--engine", help="local: a process pool; ray: Ray tasks.")] = "local",  # type: ignore[valid-type, assignment]
    ray_address: Annotated[Optional[str], typer.Option("--ray-address", metavar="ADDR", help="Ray cluster to join.", show_default=False)] = None,
    cache: Annotated[bool, typer.Option("--cache/--no-cache", help="Share the store's physics cache between workers and runs (results are identical).")] = True,
    out_dir: OutDir = None,
    html: HtmlFlag = False,
    create: CreateFlag = False,
    as_json: JsonFlag = False,
) -> None:
    """Run every (life, condition) the store does not hold yet, then write the report
    (episodes.csv, metrics.csv, the learning curves).

    One task is one life under one condition, run in a worker against a private store
    and imported in one transaction: after Ctrl-C (exit 130) or a kill, the same command
    resumes with the lives not stored. Exit code 1 when a task failed.
    """
    from llcps.jobs.life import default_life_dir, life_seeds, resolve_life, run_life_job  # the runner loads here

    chosen_conditions = comma_list(conditions)
    # Checked before the store opens: bad options create no store file.
    chosen = resolve_life(life, episodes=episodes, conditions=chosen_conditions)
    life_seeds(lives, first_life)
    target = check_output_dir(out_dir if out_dir is not None else default_life_dir(chosen.name), what="--out-dir")
    with resumable("life"):
        with open_store(ctx, create=create) as store:
            with progress_display(f"life run {chosen.name}", "planning the lives") as bar:

                def report(done: int, total: int, label: str) -> None:
                    bar(f"lives x conditions (last: {label})" if label else "lives x conditions", done, total)

                result = run_life_job(
                    store=store,
                    life=chosen,
                    lives=lives,
                    first_life=first_life,
                    workers=workers if workers is not None else cpu_count(),
                    engine=str(engine.value),  # type: ignore[attr-defined]
                    ray_address=ray_address,
                    cache=cache,
                    out_dir=target,
                    html=html,
                    progress=report,
                )
    summary = result.summary
    settle_run(summary)
    if result.report is None or result.metrics is None:
        raise LlcpsError("no episodes to report", hint="see the failed tasks above")
    if as_json:
        print_json({"run": summary.as_json(), "report_dir": str(result.report.directory), **result.metrics})
    else:
        rate = summary.cache_hit_rate
        cached = "" if rate is None else f", physics cache answered {rate:.0%} of the trials"
        message(
            f"{chosen.name}: {summary.done} task(s) run, {summary.skipped} already stored ({summary.workers} worker(s), "
            f"{summary.wall_seconds:.1f} s{cached}); report in {result.report.markdown}"
        )
        show_metrics(result.metrics)
    raise typer.Exit(EXIT_OK if summary.status == "ok" else EXIT_FAILED)


@app.command(
    "report",
    epilog=examples(
        "llcps --db lives.db life report default --html",
        "llcps --db lives.db life report paper --out-dir results/life_paper --json",
        "llcps --db lives.db life report default --conditions update,reset,case_based   # the lives these three hold",
    ),
)
def report_cli(
    ctx: typer.Context,
    life: LifeArg,
    out_dir: OutDir = None,
    html: HtmlFlag = False,
    conditions: Annotated[
        Optional[str],
        typer.Option(
            "--conditions",
            metavar="A,B",
            help="Report only these stored conditions (default: all). The metrics cover the lives every reported "
            "condition holds, so name reset beside the others for the transfer figures.",
            show_default=False,
        ),
    ] = None,
    as_json: JsonFlag = False,
) -> None:
    """Rebuild a life's report from the store's episodes (every life and condition stored), running nothing."""
    from llcps.jobs.life import report_life_job

    chosen_conditions = comma_list(conditions)
    with open_store(ctx) as store:
        result = report_life_job(store=store, life=life, out_dir=out_dir, html=html, conditions=chosen_conditions)
    if as_json:
        print_json({"report_dir": str(result.report.directory), **result.metrics})
        return
    message(f"{result.life.name}: {result.rows} episode(s); report in {result.report.markdown}")
    show_metrics(result.metrics)


@app.command("list", epilog=examples("llcps life list", "llcps life list --json"))
def list_cli(as_json: JsonFlag = False) -> None:
    """The shipped lives: families, episodes, recurrence probability, probes and conditions."""
    from llcps.jobs.life import list_lives_job

    listing = list_lives_job()
    if as_json:
        print_json([item.as_json() for item in listing])
        return
    print_table(
        "Lives",
        ["name", "episodes", "p_recur", "probes", "families", "conditions", "description"],
        [
            (i.name, i.episodes, i.p_recur, i.probes if isinstance(i.probes, int) else ",".join(i.probes), ", ".join(i.families),
             ", ".join(i.conditions), i.description)
            for i in listing
        ],  # fmt: skip
    )


@app.command("show", epilog=examples("llcps life show default", "llcps life show default --life 3", "llcps life show mine.toml --life 0 --json"))
def show_cli(
    life: LifeArg,
    seed: Annotated[Optional[int], typer.Option("--life", metavar="N", min=0, max=MAX_SEED, help="Also list the episodes life N draws.", show_default=False)] = None,
    episodes: Annotated[Optional[int], typer.Option("--episodes", metavar="K", min=1, max=MAX_EPISODES, help="Cut the life to K episodes.", show_default=False)] = None,
    as_json: JsonFlag = False,
) -> None:
    """A life file as written, and with --life N the episodes of life N (every condition solves these)."""
    from llcps.jobs.life import show_life_job

    shown = show_life_job(life=life, seed=seed, episodes=episodes)
    if as_json:
        print_json(shown.as_json())
        return
    typer.echo(shown.life.text.rstrip("\n"))
    if shown.draw is not None:
        print_table(
            f"Life {shown.draw.seed} (probes: {', '.join(shown.draw.probes) or 'none'})",
            ["episode", "family", "variant", "condition", "first encounter", "probe"],
            [(e.index, e.family, e.variant, e.condition, "yes" if e.first_encounter else "", "yes" if e.probe else "") for e in shown.draw.episodes],
        )
        if shown.draw.after:
            print_table("Re-solved after the life (forgetting)", ["family", "variant"], shown.draw.after)


def _est(data: Any) -> str:
    if not isinstance(data, dict) or data.get("value") is None:
        return "n/a"
    text = f"{data['value']:.3f}"
    if data.get("low") is not None and data.get("high") is not None:
        text += f" [{data['low']:.3f}, {data['high']:.3f}]"
    return text


def _p(value: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    return "<0.001" if value < 0.001 else f"{value:.3f}"


def show_metrics(metrics: Any) -> None:
    print_table(
        f"Life {metrics['life']}: {len(metrics['lives'])} lives, {metrics['episodes']} episodes, tau {metrics['tau']}",
        ["condition", "AUC_life", "vs reset", "p", "FT first", "FT recurrence", "curve ratio", "NRP", "forgetting"],
        [
            (c["condition"], _est(c["auc_life"]), _est(c["auc_difference"]), _p(c["wilcoxon_p"]), _est(c["ft_first"]),
             _est(c["ft_recurrence"]), _est(c["curve_ratio"]), _est(c["nrp"]), _est(c["forgetting"]))
            for c in metrics["conditions"]
        ],  # fmt: skip
    )
