"""``llcps replay``: re-execute a stored trial and check that it reproduces."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from llcps.jobs._common import Progress, StoreRef, opened

if TYPE_CHECKING:
    from llcps.cps.replay import ReplayReport


def replay(
    *, store: StoreRef, trial_id: int, gif: str | Path | None = None, gui: bool = False, progress: Progress | None = None
) -> ReplayReport:
    """Restore trial ``trial_id``'s start state, run it again and compare Omega, solved and sim
    steps with what was recorded (``.matches``); ``gif`` also films it, captioned, and ``gui``
    shows it in a PyBullet window."""
    from llcps.outputs import GIF_SUFFIXES, check_output_file

    if gif is not None:
        check_output_file(gif, what="--gif", suffixes=GIF_SUFFIXES)
    from llcps.cps.replay import replay as run_replay  # the simulator loads only when needed

    with opened(store) as s:
        return run_replay(s, trial_id, gif=gif, gui=gui, progress=progress)
