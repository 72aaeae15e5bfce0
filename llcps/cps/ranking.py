"""How the world model ranks a failure point's candidates.

:func:`rank_candidates` ranks the candidates of a failure point
(:mod:`llcps.cps.failure_point`) under a measure. The goal-directed measure ranks by the
probability that a candidate resolves the novelty (:func:`resolve_probability`): it
makes the missing atoms, or it meets a subgoal (a step of K that lacks preconditions, or
a clearance) and K's step works from there:
``1 - (1 - P(missing atoms)) * prod_k (1 - t_k P(subgoal k))``, where ``t_k``, the
belief that K's step works once its preconditions hold, starts at
:data:`SUBGOAL_TRUST` and halves each time a trial met the subgoal and K's plan from
there still failed. The world model's goal head predicts a subgoal's atoms as it
predicts the missing ones.

**A contact that blocked a_f.** A clearance is also an explanation of the failure: its
contact blocks a_f's own action on its arguments, in every setting, while it lasts (a
board across the bin's opening stops every placement of the can into the bin). a_f's
failure is evidence for it: certain if the contact blocks, and of chance ``1 - p``
otherwise, ``p`` being the model's probability that a_f's action on its arguments makes
the missing atoms (the mean over those candidates at the first ranking). So the belief
starts at ``b = t / (t + (1 - t)(1 - p))`` from ``t`` = :data:`SUBGOAL_TRUST`
(:func:`blocked_belief`): a model that expected a_f to work learns that the contact is
the likely reason it did not; one that expected nothing of a_f learns nothing. ``b`` is
the clearance's trust (halved as above), and a candidate of a_f's own action and
arguments makes the missing atoms directly only with the contact's end or its absence:
its probability of doing so is multiplied by ``1 - b (1 - q)``, ``q`` being its
probability of ending the contact. Other candidates are not judged by it: the evidence
is about a_f. A contact whose end did not let K's plan work stops mattering after a few
trials, as K's subgoals do.

**A body met on a_f's path** (:attr:`~llcps.cps.failure_point.FailurePoint.met`)
explains the failure as a clearance does, with the same belief ``b``. It cannot be
ended, so a candidate of a_f's own action on its arguments whose planned path goes
through it too (:attr:`~llcps.cps.failure_point.FailurePoint.in_the_way`) makes the
missing atoms directly with its probability times ``1 - b``; one whose path passes it
(the can lifted over the screen) is not judged by it. A candidate that takes an
argument of an a_f aimed at its other argument off that path (:attr:`~llcps.cps.failure_point.FailurePoint.relocations`)
is one more way: K's step from there works with the belief ``b t``, ``t`` starting at
:data:`SUBGOAL_TRUST` and halving with each such candidate that failed, as a subgoal's
trust does (the geometry says where the argument would go, not that it gets there, nor
that nothing else stops a_f).

Each failed attempt of K's repairs at the same missing atoms
(:attr:`~llcps.cps.failure_point.FailurePoint.attempts`) is evidence for the contact in
the same way, independently: ``b = t / (t + (1 - t) prod_i (1 - p_i))`` over a_f and
the attempts, and the candidates of each attempt's action on its arguments are blocked
as a_f's own are.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from llcps.cps.failure_point import FailurePoint, attempted, own_action
from llcps.models.base import WorldModel
from llcps.models.goal import joint_probability
from llcps.models.measures import get_measure, rank

#: Belief, before any evidence, that a step of K works once a trial met its preconditions.
SUBGOAL_TRUST = 0.5


def resolve_probability(
    goal: np.ndarray,
    subgoals: np.ndarray,
    trust: np.ndarray,
    blocking: np.ndarray | None = None,
    stroke: np.ndarray | None = None,
    around: np.ndarray | None = None,
) -> np.ndarray:
    """P(a candidate resolves the novelty) per candidate: it makes the missing atoms, or
    it meets a subgoal and K's step works from there (see the module docstring).

    Args:
        goal: (n, k) probabilities of the missing atoms (their product is used).
        subgoals: (n, s) probability that the candidate meets each subgoal.
        trust: (s,) belief that each subgoal's step works once met.
        blocking: (n, s) per candidate and subgoal, the belief that the subgoal's
            contact keeps the candidate from making the missing atoms while it lasts
            (a clearance's belief on the candidates of a_f's own action and arguments,
            else 0; see the module docstring). None: nothing blocks.
        stroke: (n,) per candidate, the belief that a body a_f's stroke met keeps it
            from making the missing atoms (on a_f's own action and arguments where its
            planned path meets it, else 0). None: nothing met.
        around: (n,) per candidate, the belief that K's step works once the candidate
            took an argument of a_f off the path of a body a_f's stroke met (0 for the
            others). None: no such candidate.
    """
    met = np.clip(subgoals, 0.0, 1.0)
    direct = joint_probability(goal)
    if blocking is not None and subgoals.size:
        direct = direct * np.prod(1.0 - blocking * (1.0 - met), axis=1)
    if stroke is not None:
        direct = direct * (1.0 - stroke)
    miss = 1.0 - direct
    if subgoals.size:
        miss = miss * np.prod(1.0 - met * trust, axis=1)
    if around is not None:
        miss = miss * (1.0 - around)
    return 1.0 - miss


def blocked_belief(own_probability: float | Sequence[float]) -> float:
    """The belief that a contact at the failure (a clearance) blocked a_f, now that a_f
    failed (see the module docstring): ``t / (t + (1 - t) prod_i (1 - p_i))`` from the
    prior ``t`` = :data:`SUBGOAL_TRUST`, ``p_i`` being the model's probability that the
    i-th failed attempt's action on its arguments makes the missing atoms
    (``own_probability``: a_f's alone, or one per attempt)."""
    t = SUBGOAL_TRUST
    missed = float(np.prod(1.0 - np.clip(np.atleast_1d(np.asarray(own_probability, dtype=np.float64)), 0.0, 1.0)))
    return t / (t + (1.0 - t) * missed)


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
        subgoals: predicted probability that each candidate meets each of the failure
            point's subgoals (n, s), or None when the measure does not use the goal.
        resolve: what ``goal-directed`` ranked by, :func:`resolve_probability` (n,),
            or None when the measure does not use the goal.
    """

    order: list[int]
    indices: list[int]
    score: np.ndarray
    outcome: np.ndarray
    goal: np.ndarray | None
    subgoals: np.ndarray | None = None
    resolve: np.ndarray | None = None
    #: The belief that a clearance's contact blocked a_f (None: no clearance, or a
    #: measure without the goal).
    blocked: float | None = None


def rank_candidates(
    model: WorldModel,
    point: FailurePoint,
    *,
    measure: str,
    seed: int,
    indices: Sequence[int] | None = None,
    subgoal_failures: Sequence[int] | None = None,
    blocked: float | None = None,
    relocation_failures: int = 0,
) -> Ranking:
    """Rank some of a failure point's candidates (all by default) under ``measure``.

    Args:
        subgoal_failures: per subgoal of ``point``, how many trials met it without K's
            plan from there working (each halves its trust; none by default).
        blocked: the belief that a clearance's contact blocked a_f (None: worked out
            from this ranking's candidates, :func:`blocked_belief`; an ordering that ranks
            again passes its first ranking's, :attr:`Ranking.blocked`).
        relocation_failures: how many failed trials were candidates of
            :attr:`~llcps.cps.failure_point.FailurePoint.relocations` (each halves the
            trust in that way around).

    Returns:
        The ranking; ``order`` holds candidate indices into ``point.candidates``.
    """
    chosen = list(range(len(point.candidates))) if indices is None else list(indices)
    outcome = model.predict_proba([point.inputs[i] for i in chosen])
    goal = subgoal = resolve = None
    if get_measure(measure).uses_goal:
        goal = model.predict_goal(point.query(chosen))
        subgoal = np.zeros((len(chosen), len(point.subgoals)))
        for k in range(len(point.subgoals)):
            subgoal[:, k] = joint_probability(model.predict_goal(point.subgoal_query(k, chosen)))
        failures = np.zeros(len(point.subgoals)) if subgoal_failures is None else np.asarray(subgoal_failures, dtype=np.float64)
        decay = 0.5**failures
        trust, blocking = SUBGOAL_TRUST * decay, None
        clearance = np.array([s.clearance for s in point.subgoals], dtype=bool)
        stroke = around = None
        if clearance.any() or point.in_the_way:
            if blocked is None:
                direct = joint_probability(goal)
                blocked = blocked_belief([float(np.mean(direct[mask])) for mask in attempted(point, chosen) if mask.any()])
        if clearance.any():
            trust = np.where(clearance, blocked * decay, trust)
            blocking = np.outer(own_action(point, chosen), np.where(clearance, trust, 0.0))
        if point.in_the_way:
            stroke = blocked * np.isin(chosen, sorted(point.in_the_way))
            if point.relocations:
                around = blocked * SUBGOAL_TRUST * 0.5**relocation_failures * np.isin(chosen, sorted(point.relocations))
        resolve = resolve_probability(goal, subgoal, trust, blocking, stroke, around)
    # Otherwise the missing atoms' probabilities themselves (the same order, and the score
    # keeps one term per atom).
    ranked_by = resolve[:, None] if resolve is not None and point.ranks_by_resolve else goal
    order = rank(outcome, measure, seed=seed, desired=point.desired, goal=ranked_by)
    score = get_measure(measure).score(outcome, point.desired, ranked_by)
    return Ranking(
        order=[chosen[i] for i in order], indices=chosen, score=score, outcome=outcome, goal=goal, subgoals=subgoal, resolve=resolve,
        blocked=blocked,
    )


def resolve_probabilities(ranking: Ranking, point: FailurePoint) -> np.ndarray | None:
    """Per ranked candidate (``ranking.indices``): the world model's probability that it
    resolves the failure, as ``ranking`` holds it (:func:`resolve_probability` where
    :attr:`FailurePoint.ranks_by_resolve`, else the missing atoms' joint probability);
    None for a measure without the goal-aware head."""
    if ranking.resolve is not None and point.ranks_by_resolve:
        return ranking.resolve
    if ranking.goal is not None:
        return joint_probability(ranking.goal)
    return None


def candidate_probability(point: FailurePoint, ranking: Ranking) -> np.ndarray:
    """Per candidate of ``point`` (n,): :func:`resolve_probabilities`; 0.5 for a measure
    without the goal-aware head, and for the candidates ``ranking`` left out."""
    probability = np.full(len(point.candidates), 0.5)
    resolve = resolve_probabilities(ranking, point)
    if resolve is not None and ranking.indices:
        probability[np.asarray(ranking.indices)] = resolve
    return probability
