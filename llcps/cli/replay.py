"""``llcps replay``: re-execute a stored trial and check it reproduces."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from llcps.cli._common import JsonFlag, db_location, message, notice, print_json, print_table
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display
from llcps.domain import MAX_ID
from llcps.jobs.replay import replay

EXAMPLES = examples(
    "llcps replay 42                       # must match what was recorded",
    "llcps replay 42 --gif trial42.gif     # and film it, captioned",
    "llcps replay 42 --json",
)


def replay_cli(
    ctx: typer.Context,
    trial_id: Annotated[
        int, typer.Argument(metavar="TRIAL_ID", min=1, max=MAX_ID, help="Id of a stored trial (see `llcps inspect trials`).", show_default=False)
    ],
    gif: Annotated[
        Optional[Path],
        typer.Option(
            "--gif",
            metavar="FILE",
            help="Render the replay to a GIF, captioned with the trial and its parameters (FILE ends in .gif; its directory must exist).",
            show_default=False,
            dir_okay=False,
        ),
    ] = None,
    gui: Annotated[bool, typer.Option("--gui", help="Watch in a PyBullet window (needs a display).")] = False,
    as_json: JsonFlag = False,
) -> None:
    """Restore a trial's start state, run it again, compare Omega, solved and sim steps.

    Exit code 0 when everything matches what was recorded, 1 when it does not, 2 for
    bad input (a stored trial or physics state that fails its checks included).
    """
    with progress_display("replay", "loading the simulator") as progress:
        report = replay(store=db_location(ctx), trial_id=trial_id, gif=gif, gui=gui, progress=progress)
    if as_json:
        print_json(report.as_json())
    else:
        rec, rep = report.trial, report
        print_table(
            f"trial {rec.id} ({rec.source}) {rec.spec.label}",
            ("", "recorded", "replayed"),
            [
                ("outcome", " ".join(map(str, rec.outcome.bits())), " ".join(map(str, rep.outcome.bits()))),
                ("solved", rec.solved, rep.solved),
                ("sim steps", rec.sim_steps, rep.sim_steps),
            ],
        )
        notice("match" if report.matches else "MISMATCH: the replay differs from the recorded trial")
        if gif is not None:
            message(f"wrote {gif}")
    raise typer.Exit(0 if report.matches else 1)
