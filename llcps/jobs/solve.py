"""``llcps solve``: one scenario, one episode, on one branch of the store."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from llcps.cps import episode
from llcps.cps.candidates import Grid
from llcps.cps.episode import SolveConfig, SolveResult
from llcps.jobs._common import Progress, StoreRef, opened
from llcps.outputs import GIF_SUFFIXES, check_output_file

if TYPE_CHECKING:
    from llcps.sim.cache import PhysicsCache


def solve(
    *,
    store: StoreRef,
    scenario: str,
    branch: str | None = None,
    condition: str | None = None,
    model: str | None = None,
    measure: str | None = None,
    ordering: str | None = None,
    reach_check: bool | None = None,
    seed: int | None = None,
    model_seed: int | None = None,
    budget: int | None = None,
    refit_every: int | None = None,
    variant: int | None = None,
    grid: Grid | None = None,
    gui: bool = False,
    gif: str | os.PathLike[str] | None = None,
    create: bool = False,
    command: str = "solve",
    cache: PhysicsCache | None = None,
    progress: Progress | None = None,
) -> SolveResult:
    """Solve ``scenario`` once on ``branch`` (None: the store's current branch): plan,
    execute, explore on failure, learn an operator; every trial goes to the store.

    The episode's settings are the fields of :class:`~llcps.cps.episode.SolveConfig`;
    one left None takes the config's default. They are checked, and so is ``gif`` (a
    film of the episode written afterwards), before the store is opened, so bad input
    creates and changes nothing. ``create`` makes the store when ``store`` names none
    yet; ``cache`` answers trials simulated before (see :func:`llcps.cps.episode.solve`).

    Returns:
        The episode's frozen summary; ``status`` is ``solved``, ``budget_exhausted``,
        ``no_plan`` or ``interrupted``.
    """
    given = {
        "condition": condition,
        "model": model,
        "measure": measure,
        "ordering": ordering,
        "reach_check": reach_check,
        "seed": seed,
        "model_seed": model_seed,
        "budget": budget,
        "refit_every": refit_every,
        "variant": variant,
        "grid": grid,
    }
    config = SolveConfig(scenario=scenario, **{name: value for name, value in given.items() if value is not None})  # type: ignore[arg-type]
    config.validate()
    if gif is not None:
        check_output_file(gif, what="gif", suffixes=GIF_SUFFIXES)
    with opened(store, create=create) as s:
        return episode.solve(s, branch=branch, config=config, command=command, gui=gui, gif=gif, progress=progress, cache=cache)
