"""One trial: perceive, execute a controller call, perceive again, and compute
the meta-outcome Omega (Table 2) from the two symbolic states."""

from __future__ import annotations

import time
from dataclasses import dataclass

from llcps.domain import Body, EntityFeatures, Outcome, State, TrialChange, TrialSpec, WorldModelInput
from llcps.sim.controllers import DEFAULT_MAX_STEPS, execute
from llcps.sim.perception import entity_features, perceive, scene_bodies
from llcps.sim.world import World


@dataclass(frozen=True)
class TrialResult:
    """What a trial did.

    Attributes:
        spec: the controller call.
        features: Table-1 features of each argument, measured before the action.
        before: symbolic state before.
        after: symbolic state after.
        outcome: Omega between ``before`` and ``after``.
        sim_steps: physics steps the controller used.
        wall_seconds: wall time of the whole trial (perception included).
        bodies: every entity and fixture before the action (the change's scene).
    """

    spec: TrialSpec
    features: tuple[EntityFeatures, ...]
    before: State
    after: State
    outcome: Outcome
    sim_steps: int
    wall_seconds: float
    bodies: tuple[Body, ...] = ()

    @property
    def model_input(self) -> WorldModelInput:
        return WorldModelInput(spec=self.spec, features=self.features)

    @property
    def change(self) -> TrialChange:
        """The symbolic change this trial made (stored beside its row)."""
        return TrialChange.between(self.before, self.after, self.bodies)


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
