"""``llcps db``: create, inspect, migrate, branch and export the experience store."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from llcps.cli._common import (
    JsonFlag,
    YesFlag,
    choice_enum,
    db_location,
    human_bytes,
    message,
    new_app,
    notice,
    print_json,
    print_table,
    selected_branch,
)
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display
from llcps.domain import MAX_ID, TRIAL_SOURCES
from llcps.jobs import db as jobs
from llcps.store import PRETRAIN, RESET_TARGETS, BranchChange, BranchInfo, StoreStatus
from llcps.store.export import EXPORT_FORMATS
from llcps.store.tables import MAX_BRANCH_NAME

app = new_app(
    "Create, inspect, migrate, branch and export the experience store.",
    epilog=examples(
        "llcps db init && llcps db status",
        "llcps db branch fresh --at pretrain && llcps db checkout fresh",
        "llcps db export --format parquet --out trials.parquet",
    ),
)

ResetTarget = choice_enum("ResetTarget", RESET_TARGETS)
ExportFormat = choice_enum("ExportFormat", EXPORT_FORMATS)
TrialSource = choice_enum("ExportSource", TRIAL_SOURCES)
DEFAULT_RESET_TARGET = ResetTarget(PRETRAIN)
DEFAULT_EXPORT_FORMAT = ExportFormat("csv")

BranchName = Annotated[
    str, typer.Argument(metavar="NAME", help=f"Branch name (no whitespace, '/', '..'; at most {MAX_BRANCH_NAME} characters).", show_default=False)
]


def _print_status(status: StoreStatus, as_json: bool) -> None:
    if as_json:
        print_json(status.as_json())
        return
    by_source = ", ".join(f"{k} {v}" for k, v in sorted(status.visible_by_source.items())) or "none"
    schema = status.revision if status.up_to_date else f"{status.revision} (outdated; head {status.head}: run `llcps db upgrade`)"
    print_table(
        None,
        ("", ""),
        [
            ("database", status.url),
            ("schema revision", schema),
            ("current branch", status.current_branch),
            ("branch shown", status.branch),
            ("branches", status.branches),
            ("trials in database", status.trials_total),
            ("visible trials", f"{status.visible_trials} ({by_source})"),
            *(
                [("trial changes", ", ".join(f"{k} {v}" for k, v in status.changes.items()))]
                if status.changes is not None
                else []
            ),
            *[(f"{'live' if w.live else 'stale'} writer on {w.branch}", w.describe()) for w in status.writers],
        ],
        show_header=False,
    )


def _print_branch(info: BranchInfo, as_json: bool, text: str) -> None:
    if as_json:
        print_json(info.as_json())
    message(text)


ForceFlag = Annotated[
    bool,
    typer.Option(
        "--force",
        help="With --yes: remove even while a live command writes to the branch. That command fails at its next write, "
        "its run and episode are marked aborted, and what it wrote so far is removed too.",
    ),
]


def _report_removal(change: BranchChange, as_json: bool) -> None:
    """Report a removal, or what a dry run of it would do (exit 0: a dry run is not an error)."""
    if as_json:
        print_json(change.as_json())
    if change.dry_run:  # what a dry run would do is its result: --quiet keeps it
        notice(f"{change.summary}; nothing changed (rerun with --yes to do it)")
    else:
        message(change.summary)


def _fork_point(value: Optional[str]) -> Optional[str]:
    """``--at``: 'pretrain' or a trial id within the range a store can hold."""
    if value is None or value == PRETRAIN:
        return value
    text = value.strip()
    if not text.isdigit() or int(text) > MAX_ID:
        raise typer.BadParameter(f"{value!r} is neither 'pretrain' nor a trial id from 0 to {MAX_ID}")
    return text


@app.command(
    "init",
    epilog=examples(
        "llcps db init                       # ./llcps.db, branch main",
        "llcps --db runs.db db init --json",
        "llcps --db postgresql+psycopg://me@dbhost/llcps db init",
    ),
)
def init_cli(ctx: typer.Context, as_json: JsonFlag = False) -> None:
    """Create the store with a `main` branch, or migrate an existing one to the newest schema."""
    result = jobs.init_store(store=db_location(ctx))
    if result.upgraded:
        message(f"upgraded {result.url} from schema {result.before} to {result.after}")
    message(f"llcps store ready at {result.url} (schema {result.after}, current branch {result.current_branch})")
    if as_json:
        _print_status(jobs.store_status(store=db_location(ctx), branch=selected_branch(ctx)), True)


@app.command(
    "status",
    epilog=examples(
        "llcps db status",
        "llcps --branch exp db status --json",
    ),
)
def status_cli(ctx: typer.Context, as_json: JsonFlag = False) -> None:
    """Show the database URL, schema revision, current branch and trial counts."""
    _print_status(jobs.store_status(store=db_location(ctx), branch=selected_branch(ctx)), as_json)


@app.command(
    "list",
    epilog=examples(
        "llcps db list",
        "llcps db list --json",
    ),
)
def list_cli(ctx: typer.Context, as_json: JsonFlag = False) -> None:
    """List branches with parent, fork point, own and visible trial counts."""
    branches = jobs.list_branches(store=db_location(ctx))
    if as_json:
        print_json([b.as_json() for b in branches])
        return
    print_table(
        None,
        ("", "branch", "parent", "fork point", "own trials", "visible trials", "created (UTC)"),
        [
            ("*" if b.is_current else "", b.name, b.parent or "-", b.fork_point, b.own_trials, b.visible_trials, b.created_at[:19])
            for b in branches
        ],
    )


@app.command(
    "branch",
    epilog=examples(
        "llcps db branch fresh --at pretrain   # back to the pretraining data",
        "llcps db branch exp --from main --at 120",
        "llcps db branch copy --json",
    ),
)
def branch_cli(
    ctx: typer.Context,
    name: BranchName,
    from_branch: Annotated[
        Optional[str], typer.Option("--from", metavar="NAME", help="Parent branch (default: --branch, else the current branch).", show_default=False)
    ] = None,
    at: Annotated[
        Optional[str],
        typer.Option(
            "--at",
            metavar="TRIAL_ID|pretrain",
            help="Fork point: a trial id the parent sees, or 'pretrain' for its pretraining point, the last trial "
            "of the first unbroken run of pretraining trials (no exploration, no learned operator; docs/store.md) "
            "(default: the parent's latest trial).",
            show_default=False,
            callback=_fork_point,
        ),
    ] = None,
    as_json: JsonFlag = False,
) -> None:
    """Create a branch that sees its parent's trials up to the fork point (it is not checked out)."""
    fork: int | str | None = int(at) if at is not None and at != PRETRAIN else at
    info = jobs.create_branch(store=db_location(ctx), name=name, parent=from_branch or selected_branch(ctx), at=fork)
    _print_branch(
        info,
        as_json,
        f"created branch {info.name} from {info.parent} at trial {info.fork_point} "
        f"({info.visible_trials} visible trials); switch with `llcps db checkout {info.name}`",
    )


@app.command(
    "checkout",
    epilog=examples(
        "llcps db checkout exp",
        "llcps db checkout main --json",
    ),
)
def checkout_cli(ctx: typer.Context, name: BranchName, as_json: JsonFlag = False) -> None:
    """Make a branch the current one (the default of --branch)."""
    info = jobs.checkout_branch(store=db_location(ctx), name=name)
    _print_branch(info, as_json, f"switched to branch {info.name} ({info.visible_trials} visible trials)")


@app.command(
    "reset",
    epilog=examples(
        "llcps db reset                       # dry run: what would go",
        "llcps --branch exp db reset --to pretrain --yes",
        "llcps db reset --to empty --yes --json",
    ),
)
def reset_cli(
    ctx: typer.Context,
    to: Annotated[
        ResetTarget,  # type: ignore[valid-type]
        typer.Option("--to", help="'pretrain' keeps the branch's trials up to its pretraining point (the end of its first unbroken run "
            "of pretraining trials); 'empty' removes all it owns."),
    ] = DEFAULT_RESET_TARGET,  # type: ignore[assignment]
    yes: YesFlag = False,
    force: ForceFlag = False,
    as_json: JsonFlag = False,
) -> None:
    """Drop the own experience of --branch (default: the current branch) after a point."""
    target = str(to.value)  # type: ignore[attr-defined]
    change = jobs.reset_branch(store=db_location(ctx), branch=selected_branch(ctx), to=target, dry_run=not yes, force=force)
    _report_removal(change, as_json)


@app.command(
    "delete",
    epilog=examples(
        "llcps db delete exp                  # dry run",
        "llcps db delete exp --yes",
        "llcps db delete exp --yes --force    # even while a solve writes to exp (it fails)",
    ),
)
def delete_cli(ctx: typer.Context, name: BranchName, yes: YesFlag = False, force: ForceFlag = False, as_json: JsonFlag = False) -> None:
    """Delete a branch and everything it owns (not main, the current branch, or a parent).

    A branch that a running command (solve, pretrain, experiment) writes to is refused;
    a run left `running` by a killed process is stale and does not count (`llcps db status`
    lists both)."""
    change = jobs.delete_branch(store=db_location(ctx), name=name, dry_run=not yes, force=force)
    _report_removal(change, as_json)


@app.command(
    "upgrade",
    epilog=examples(
        "llcps db upgrade",
        "llcps --db old.db db upgrade --json",
        "llcps db upgrade --no-replay-changes   # fast: mark older trials' changes unknown",
    ),
)
def upgrade_cli(
    ctx: typer.Context,
    replay_changes: Annotated[
        bool,
        typer.Option(
            "--replay-changes/--no-replay-changes",
            help="Recover the symbolic change of trials stored without one by replaying them from their "
            "stored start state; without replay they are marked unknown.",
        ),
    ] = True,
    as_json: JsonFlag = False,
) -> None:
    """Migrate the store to the newest schema revision this llcps knows, and give every
    trial its symbolic change (the goal-aware world model learns from it).

    Trials stored before changes were recorded are replayed from their start state
    (deterministic physics); one that has none, whose state does not rebuild, or whose
    replay disagrees with what was stored is marked unknown. `llcps db status` shows the
    counts.
    """
    with progress_display("db upgrade", "checking the schema") as progress:
        result = jobs.upgrade_store(store=db_location(ctx), replay_changes=replay_changes, progress=progress)
    if as_json:
        print_json(result.as_json())
    from llcps.store.migrations import revision_label

    report = result.changes
    message(
        f"upgraded from schema {revision_label(result.before)} to {revision_label(result.after)}"
        if result.changed
        else f"already at schema {revision_label(result.after)}"
    )
    if report.total:
        message(
            f"trial changes: {report.replayed} replayed, {report.unknown} unknown "
            f"({report.no_snapshot} without a stored start state or replay, {report.failed} whose state did not "
            f"rebuild, {report.mismatched} whose replay disagreed)"
        )


@app.command(
    "compact",
    epilog=examples(
        "llcps db compact",
        "llcps db delete old-exp --yes && llcps db compact",
        "llcps --db runs.db db compact --json",
    ),
)
def compact_cli(ctx: typer.Context, as_json: JsonFlag = False) -> None:
    """Give the space of removed rows back to the disk: SQLite rewrites the file (VACUUM),
    PostgreSQL marks the space for reuse. Nothing stored changes.

    Deleting or resetting branches, pruning the physics cache and schema upgrades that
    rebuild a table leave free pages that a SQLite file keeps until it is compacted.
    SQLite needs as much free disk again as the file takes while it runs.
    """
    with progress_display("db compact", "compacting the store"):
        result = jobs.compact_store(store=db_location(ctx))
    if as_json:
        print_json(result.as_json())
        return
    if result.before is None or result.after is None:
        message(f"compacted {result.url}")
    else:
        message(f"compacted {result.url}: {human_bytes(result.before)} -> {human_bytes(result.after)}")


@app.command(
    "export",
    epilog=examples(
        "llcps db export --out trials.csv",
        "llcps --branch exp db export --format parquet --out exp.parquet",
        "llcps db export --format jsonl --source exploration --scenario scenario2 > explore.jsonl",
        "llcps db export --episode 3 --out episode3.csv",
    ),
)
def export_cli(
    ctx: typer.Context,
    fmt: Annotated[
        ExportFormat,  # type: ignore[valid-type]
        typer.Option(
            "--format",
            help="csv, jsonl (one flat JSON object per line) or parquet (needs --out); every format has the same flat columns.",
        ),
    ] = DEFAULT_EXPORT_FORMAT,  # type: ignore[assignment]
    out: Annotated[
        Optional[Path],
        typer.Option("--out", metavar="FILE", help="File to write (default: stdout); its directory must exist.", show_default=False, dir_okay=False),
    ] = None,
    source: Annotated[
        Optional[TrialSource],  # type: ignore[valid-type]
        typer.Option("--source", help="Only trials from this source.", show_default=False),
    ] = None,
    scenario: Annotated[Optional[str], typer.Option("--scenario", metavar="NAME", help="Only trials of this scenario (a name or its alias).", show_default=False)] = None,
    episode: Annotated[Optional[int], typer.Option("--episode", metavar="ID", min=1, max=MAX_ID, help="Only trials of this episode.", show_default=False)] = None,
) -> None:
    """Export the trials --branch (default: the current branch) sees, in id order, one flat row per trial."""
    result = jobs.export_trials(
        store=db_location(ctx),
        branch=selected_branch(ctx),
        fmt=str(fmt.value),  # type: ignore[attr-defined]
        out=sys.stdout if out is None else out,
        source=None if source is None else str(source.value),  # type: ignore[attr-defined]
        scenario=scenario,
        episode=episode,
    )
    message(f"exported {result.count} trial(s) of branch {result.branch}" + (f" to {out}" if out else ""))
