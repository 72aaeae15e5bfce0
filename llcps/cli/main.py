"""The ``llcps`` command: global options and the registry of command modules.

Each command module is option parsing and presentation over a job, a plain function
in llcps/jobs/ that llcps.api calls too (see llcps/cli/_common.py for the shared
helpers). To add commands, write a job and a module and register it below with ONE line:

* a command group (``llcps db ...``): ``app.add_typer(module.app, name="db")``
* a single command (``llcps solve``): ``app.command("solve")(module.solve_cli)``
* more subcommands of an existing group (``llcps inspect model``): decorate with
  ``@inspect.app.command("model")`` in your module and import it here.

Every command module is imported at start, so each imports heavy library code (the
simulator, the experiment runner, numpy, the scenario files) inside the commands that
need it, not at module level: light commands (``db list``, ``--help``) then start fast.
"""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from llcps.cli import bench, cache, db, experiment, inspect, inspect_model, inspect_runs, life, pretrain, replay, rl, scenario, solve  # noqa: F401 - inspect_* add `inspect` subcommands
from llcps.cli._common import DEFAULT_DB, CliContext, LlcpsGroup, new_app, terminate_like_interrupt
from llcps.cli._conventions import examples

app = new_app(
    "Life-long creative problem solving: a robot that explores novelties and learns world models "
    "from every trial, kept in a branchable experience store.",
    cls=LlcpsGroup,
    add_completion=True,
    epilog=examples(
        "llcps db init                                   # a store at ./llcps.db",
        "llcps pretrain --trials 200 --seed 1            # random interactions, models fitted",
        "llcps solve scenario2                           # plan, explore, learn an operator",
        "llcps --db runs.db --branch exp inspect trials  # global options, before or after the command",
        "llcps pretrain > out.txt 2> progress.log        # off a terminal: a progress line every 5 s",
        "llcps --quiet solve scenario2 --json            # only the result (and any error)",
        "llcps --version",
    ),
)


def _show_version(value: bool) -> None:
    """Print the version (and the source commit, in a git checkout) and stop."""
    if not value:
        return
    import llcps
    from llcps.provenance import git_state

    commit, dirty = git_state()
    suffix = f" (commit {commit[:12]}{'+dirty' if dirty else ''})" if commit else ""
    typer.echo(f"llcps {llcps.__version__}{suffix}")
    raise typer.Exit()


@app.callback()
def _global_options(
    ctx: typer.Context,
    db_location: Annotated[
        str,
        typer.Option(
            "--db", envvar="LLCPS_DB", metavar="PATH|URL", help="Experience store: a SQLite file path or an SQLAlchemy URL (before or after the command)."
        ),
    ] = DEFAULT_DB,
    branch: Annotated[
        Optional[str],
        typer.Option(
            "--branch",
            envvar="LLCPS_BRANCH",
            metavar="NAME",
            help="Branch to read and write (default: the store's current branch; before or after the command).",
            show_default=False,
        ),
    ] = None,
    quiet: Annotated[
        bool,
        typer.Option(
            "--quiet",
            "-q",
            envvar="LLCPS_QUIET",
            help="No progress and no messages on stderr; errors, warnings and the result still print (before or after the command).",
        ),
    ] = False,
    version: Annotated[
        bool,
        typer.Option("--version", is_eager=True, callback=_show_version, help="Print the llcps version and exit."),
    ] = False,
) -> None:
    """Life-long creative problem solving with world models trained on an experience store.

    Every error prints `error:` and `hint:` lines on stderr and exits 2. Long commands
    show their phase, counts and ETA on stderr: a live display on a terminal, otherwise
    a plain line when a phase starts and ends and a heartbeat every 5 s
    (LLCPS_HEARTBEAT_SECONDS); --quiet silences them.
    """
    ctx.obj = CliContext(db=db_location, branch=branch, quiet=quiet)


# Command registry: one line per module.
app.add_typer(db.app, name="db")
app.add_typer(inspect.app, name="inspect")
app.command("solve", epilog=solve.EXAMPLES)(solve.solve_cli)
app.command("pretrain", epilog=pretrain.EXAMPLES)(pretrain.pretrain_cli)
app.command("replay", epilog=replay.EXAMPLES)(replay.replay_cli)
app.command("bench", epilog=bench.EXAMPLES)(bench.bench_cli)
app.add_typer(experiment.app, name="experiment")
app.add_typer(life.app, name="life")
app.add_typer(cache.app, name="cache")
app.add_typer(scenario.app, name="scenario")
app.add_typer(rl.app, name="rl")


def main() -> None:
    """Console-script entry point."""
    terminate_like_interrupt()
    app(prog_name="llcps")


if __name__ == "__main__":
    main()
