"""``llcps inspect``: look at what the store holds (more subcommands attach to ``app``)."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from llcps.cli._common import JsonFlag, choice_enum, db_location, new_app, print_json, print_table, selected_branch
from llcps.cli._conventions import examples
from llcps.domain import MAX_ID, OUTCOME_NAMES, TRIAL_SOURCES
from llcps.trial_records import TrialRecord
from llcps.jobs.inspect import list_trials

app = new_app(
    "Inspect the experience store: trials, runs, episodes and what was learned from them.",
    epilog=examples(
        "llcps inspect trials --source exploration",
        "llcps inspect episodes",
        "llcps inspect runs --compare 1 2",
        "llcps inspect model --scenario scenario2",
    ),
)

TrialSource = choice_enum("TrialSource", TRIAL_SOURCES)

_OUTCOME_SHORT = {name: ("+" if name.startswith("positive") else "-") + name.split("_", 1)[1][:5] for name in OUTCOME_NAMES}


def outcome_text(record: TrialRecord) -> str:
    """Omega in a few characters, e.g. ``+touch -reach``."""
    return " ".join(_OUTCOME_SHORT[name] for name, bit in record.outcome.as_dict().items() if bit) or "-"


@app.command(
    "trials",
    epilog=examples(
        "llcps inspect trials                                # the newest 20",
        "llcps inspect trials --source exploration --solved",
        "llcps inspect trials --episode 3 --limit 0 --json   # one episode's trials, for scripts",
    ),
)
def trials_cli(
    ctx: typer.Context,
    scenario: Annotated[
        Optional[str], typer.Option("--scenario", metavar="NAME", help="Only trials of this scenario (a name or its alias).", show_default=False)
    ] = None,
    source: Annotated[
        Optional[TrialSource],  # type: ignore[valid-type]
        typer.Option("--source", help="Only trials from this source.", show_default=False),
    ] = None,
    solved: Annotated[
        Optional[bool],
        typer.Option("--solved/--unsolved", help="Only trials that solved (or did not solve) their task.", show_default=False),
    ] = None,
    episode: Annotated[
        Optional[int], typer.Option("--episode", metavar="ID", min=1, max=MAX_ID, help="Only trials of this episode.", show_default=False)
    ] = None,
    limit: Annotated[int, typer.Option("--limit", min=0, max=MAX_ID, metavar="N", help="Show the newest N matching trials; 0 shows all.")] = 20,
    as_json: JsonFlag = False,
) -> None:
    """List the trials --branch (default: the current branch) sees, oldest of the selection first."""
    result = list_trials(
        store=db_location(ctx),
        branch=selected_branch(ctx),
        source=None if source is None else str(source.value),  # type: ignore[attr-defined]
        scenario=scenario,
        solved=solved,
        episode=episode,
        limit=limit or None,
    )
    branch, records = result.branch, result.trials
    if as_json:
        print_json([r.as_json() for r in records])
        return
    print_table(
        f"trials visible on {branch} ({len(records)} shown)",
        ("id", "branch", "source", "scenario", "action", "rate m/s, magnitude m, side", "outcome", "solved", "steps", "seconds", "seed"),
        [
            (
                r.id,
                r.branch,
                r.source,
                r.scenario or "-",
                f"{r.spec.action}({', '.join(r.spec.arguments)})",
                f"{r.spec.params.rate:g}, {r.spec.params.movement_magnitude:g}, {r.spec.params.orientation}",
                outcome_text(r),
                "yes" if r.solved else "no",
                r.sim_steps,
                f"{r.wall_seconds:.3f}",
                r.seed,
            )
            for r in records
        ],
    )
