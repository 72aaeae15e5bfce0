"""What a trial did (:func:`llcps.sim.trial.run_trial` makes it): a plain record, light
to import for code that stores or caches trials without simulating them."""

from __future__ import annotations

from dataclasses import dataclass

from llcps.domain import EntityFeatures, State
from llcps.trial_records import Body, Outcome, TrialChange, TrialSpec, WorldModelInput


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
