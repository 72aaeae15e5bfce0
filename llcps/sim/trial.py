"""One trial: perceive, execute a controller call, perceive again, and compute
the meta-outcome Omega (Table 2) from the two symbolic states."""

from __future__ import annotations

import time

from llcps.trial_records import Outcome, TrialSpec
from llcps.sim.controllers import DEFAULT_MAX_STEPS, execute
from llcps.sim.contact import TOUCH_DISTANCE
from llcps.sim.perception import entity_features, perceive, scene_bodies
from llcps.sim.result import TrialResult
from llcps.sim.world import World

__all__ = ["TrialResult", "bodies_met", "run_trial"]


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


def bodies_met(world: World, spec: TrialSpec, *, max_steps: int = DEFAULT_MAX_STEPS) -> frozenset[str]:
    """Execute ``spec`` from the world's current state, and name the bodies its stroke met.

    A body is met when the arm or one of ``spec``'s arguments touches it at some step of
    the stroke and touched neither before it: the bodies in the way of the motion, which
    the states before and after need not show (a fence that stopped a pushed puck, which
    rolled back from it). The arguments themselves are not named. The world is left
    where the stroke ends; restore a snapshot to undo it.
    """
    client = world.client
    names = world.names
    movers = [world.robot.body_id, *(world.body(name) for name in spec.arguments)]
    own = set(movers)

    def touched() -> set[int]:
        return {
            cp[2] for mover in movers for cp in client.getContactPoints(bodyA=mover) if cp[8] <= TOUCH_DISTANCE and cp[2] not in own
        }

    client.performCollisionDetection()
    before = touched()
    met: set[int] = set()

    def observe(_: World) -> None:
        met.update(touched())

    world.add_observer(observe)
    try:
        execute(world, spec, max_steps=max_steps)
    finally:
        world.remove_observer(observe)
    return frozenset(names[body] for body in met - before if body in names)
