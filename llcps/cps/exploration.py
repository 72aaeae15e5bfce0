"""Where exploration starts: the failure point, its candidates, and their ranking.

One place for the path from a failed plan step to an ordered list of candidate
trials, used by the agent (:mod:`llcps.cps.agent`) and by ``llcps inspect model``
(:mod:`llcps.cps.inspection`): enumerate the candidates in the default order, describe
each for the world model (Table-1 inputs for Omega, and the goal-aware query of the
failure's missing atoms over the scene as it is at the failure), and rank them with a
world model and a measure.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from llcps.cps.candidates import enumerate_candidates
from llcps.cps.outcomes import desired_outcome
from llcps.domain import Body, Fluent, State, TrialSpec, WorldModelInput
from llcps.models.base import WorldModel
from llcps.models.measures import get_measure, rank
from llcps.models.relational import GoalQuery
from llcps.symbolic.knowledge import KnowledgeBase
from llcps.symbolic.monitor import StepFailure

if TYPE_CHECKING:
    from llcps.cps.agent import Agent


@dataclass(frozen=True)
class FailurePoint:
    """What exploration starts from after a plan step failed.

    Attributes:
        scenario: the scenario's name.
        failure: the failed step a_f and its missing effects.
        state: the symbolic state at the failure.
        bodies: every entity and fixture at the failure (the goal-aware query's scene).
        candidates: the candidate trials in the default order (focused, then defocused).
        inputs: each candidate's Table-1 input (Omega's question).
        desired: Omega-bit weights for the kinds of change a_f lacked (the fallback measure).
        claimed: per candidate, the missing atoms (with their sign: True to add) that the
            knowledge base claims its action has as an effect (the goal head's prior).
    """

    scenario: str
    failure: StepFailure
    state: State
    bodies: tuple[Body, ...]
    candidates: tuple[TrialSpec, ...]
    inputs: tuple[WorldModelInput, ...]
    desired: np.ndarray
    claimed: tuple[frozenset[tuple[Fluent, bool]], ...] = ()

    @property
    def missing_effects(self) -> str:
        return self.failure.describe()

    def query(self, indices: Sequence[int] | None = None) -> GoalQuery:
        """The goal-aware question for some candidates (all by default): will they make
        the missing atoms hold (and the atoms that should go, go)?"""
        chosen = range(len(self.candidates)) if indices is None else indices
        specs = tuple(self.candidates[i] for i in chosen)
        claimed = {self.candidates[i]: self.claimed[i] for i in chosen} if self.claimed else {}
        return GoalQuery.from_missing(
            specs,
            missing_add=self.failure.missing_add,
            missing_del=self.failure.missing_del,
            bodies=self.bodies,
            before=self.state,
            claims=(lambda spec, atom, add: (atom, add) in claimed[spec]) if claimed else None,
        )


def failure_point(agent: Agent, failure: StepFailure, state: State, kb: KnowledgeBase) -> FailurePoint:
    """The failure point of ``agent``'s world as it is now (just after a_f failed);
    ``kb`` says which candidates' actions claim the missing atoms as effects."""
    from llcps.sim.perception import entity_features, scene_bodies

    world = agent.world
    agent.sync()
    failed_spec = agent.controller_call(failure.step)
    specs = enumerate_candidates(failed=failed_spec, entities=agent.kinds, grid=agent.config.candidate_grid(agent.scenario))
    features = {name: entity_features(world, name) for name in agent.kinds}
    inputs = tuple(WorldModelInput(spec=c, features=tuple(features[a] for a in c.arguments)) for c in specs)
    objects = agent.task(state).objects
    missing = [(atom, True) for atom in failure.missing_add] + [(atom, False) for atom in failure.missing_del]
    claimed = tuple(frozenset(m for m in missing if kb.claims(c, m[0], add=m[1], objects=objects)) for c in specs)
    return FailurePoint(
        scenario=agent.scenario.name,
        failure=failure,
        state=state,
        bodies=scene_bodies(world),
        candidates=tuple(specs),
        inputs=inputs,
        desired=desired_outcome(missing_add=failure.missing_add, missing_del=failure.missing_del),
        claimed=claimed,
    )


@dataclass(frozen=True)
class Ranking:
    """Candidates in a measure's order, with what they were ranked by.

    Attributes:
        order: candidate indices (into the failure point's candidates), best first.
        indices: the candidates ranked, in the order the arrays below follow.
        score: the measure's score of each (higher ranks first).
        outcome: predicted Omega of each (n, 6).
        goal: predicted probability of each missing atom (n, k), or None when the
            measure does not use it.
    """

    order: list[int]
    indices: list[int]
    score: np.ndarray
    outcome: np.ndarray
    goal: np.ndarray | None


def rank_candidates(
    model: WorldModel, point: FailurePoint, *, measure: str, seed: int, indices: Sequence[int] | None = None
) -> Ranking:
    """Rank some of a failure point's candidates (all by default) under ``measure``.

    Returns:
        The ranking; ``order`` holds candidate indices into ``point.candidates``.
    """
    chosen = list(range(len(point.candidates))) if indices is None else list(indices)
    outcome = model.predict_proba([point.inputs[i] for i in chosen])
    goal = model.predict_goal(point.query(chosen)) if get_measure(measure).uses_goal else None
    order = rank(outcome, measure, seed=seed, desired=point.desired, goal=goal)
    score = get_measure(measure).score(outcome, point.desired, goal)
    return Ranking(order=[chosen[i] for i in order], indices=chosen, score=score, outcome=outcome, goal=goal)
