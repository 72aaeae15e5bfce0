"""One trial: perceive, execute a controller call, perceive again, and compute
the meta-outcome Omega (Table 2) from the two symbolic states."""

from __future__ import annotations

import time

from llcps.trial_records import Outcome, TrialSpec
from llcps.sim.controllers import DEFAULT_MAX_STEPS, execute
from llcps.sim.perception import entity_features, perceive, scene_bodies
from llcps.sim.result import TrialResult
from llcps.sim.world import World

__all__ = ["TrialResult", "run_trial"]


def run_trial(world: World, spec: TrialSpec, *, max_steps: int = DEFAULT_MAX_STEPS) -> TrialResult:
    """Execute ``spec`` from the world's current state and observe what changed.

    For a reproducible trial, restore a snapshot first: the same snapshot and spec
    give the same result, in this process or another.
    """
    t0 = time.perf_counter()
    features = tuple(entity_features(world, name) for name in spec.arguments)
    before = perceive(world)
    bodies = scene_bodies(world)
    steps = execute(world, spec, max_steps=max_steps)
    after = perceive(world)
    return TrialResult(
        spec=spec,
        features=features,
        before=before,
        after=after,
        outcome=Outcome.between(before, after),
        sim_steps=steps,
        wall_seconds=time.perf_counter() - t0,
        bodies=bodies,
    )
