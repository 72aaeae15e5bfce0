"""Where exploration starts: the failure point and its candidates.

One place for what exploration knows once a plan step failed, used by the episode
(:mod:`llcps.cps.episode`), the Gymnasium environment (:mod:`llcps.gym`) and ``llcps
inspect model`` (:mod:`llcps.cps.inspection`): the candidates in the default order, each
described for the world model (Table-1 inputs for Omega, and the goal-aware query of the
failure's missing atoms over the scene as it is at the failure), and the other ways to
the missing atoms that the ranking (:mod:`llcps.cps.ranking`) values.

**Subgoals: the other way to the missing atoms.** A trial resolves the novelty when the
goal holds after it, or when K plans from the state it leaves and that plan works
(:func:`llcps.cps.plan_execution.resolves`). So a trial need not make a missing atom itself: it
may meet what another step of K lacks. Every ground step of K (other than a_f) that
would make a missing atom but is not applicable at the failure gives a
:class:`Subgoal`: its unmet preconditions (at most :data:`MAX_SUBGOAL_ATOMS`; K's
``push(can, bin)`` lacks ``(near can bin)`` when the bin is out of reach).

**Clearances: what is in the way.** a_f may have failed because of a body in contact
with its arguments: a board lying across the container's opening, a box standing on the
object. Each body other than a_f's arguments, the support and the ground that touches,
carries or holds one of them at the failure gives one more subgoal of a_f itself
(:func:`clearances`): ending that contact, every relation of it that holds (``in``,
``on``, ``touching``): a board pushed off the bin's top that still leans on its rim is
not out of the way. A failure with no such contact has no clearances.

**A body met on a_f's path.** What stopped a_f may touch neither argument once it
failed: a low fence the pushed block hit and bounced back from, a screen the carried can
hit before it fell. So exploration starts by replaying a_f's stroke from its stored
start, recording every body the arm or an argument met on the way
(:meth:`ExplorationSite.met`; not a trial, nothing stored). A body met that no clearance
names, and that a_f's planned path goes through (by geometry alone,
:func:`~llcps.sim.controllers.path_meets`), is kept (:attr:`FailurePoint.met`), with the
candidates of a_f's own action on its arguments (in either order: the block pushed
against the puck or the puck against the block) whose planned path goes through it too
(:attr:`FailurePoint.in_the_way`).

**A way around it.** If that body stopped an a_f aimed at its other argument (a push of
one body against another), a_f may work from elsewhere: the block pushed aside is
pushed against the puck along a line that misses the fence, and still ends against it.
The candidates whose planned motion takes an argument of a_f, by a path that misses the
bodies met, to a place on the support from where a_f's planned path misses them too
(:func:`relocations`, geometry alone) are kept (:attr:`FailurePoint.relocations`).

K's repairs may have tried for the same missing atoms another way before exploration
started (a placement of the can, after a push of it into the bin failed), and failed
too (:attr:`~llcps.cps.plan_execution.Failure.attempts`): the failure point keeps their
controller calls (:attr:`FailurePoint.attempts`, :func:`attempted`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Collection, Mapping, Protocol, Sequence

import numpy as np

from llcps.cps.candidates import Grid, enumerate_candidates
from llcps.cps.outcomes import desired_outcome
from llcps.domain import GROUND_KIND, SUPPORT_KIND, Fluent, State, format_fluent
from llcps.trial_records import Body, TrialSpec, WorldModelInput
from llcps.models.relational import GoalQuery
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.task import Task
from llcps.symbolic.monitor import StepFailure
from llcps.symbolic.planner import GroundAction, ground

if TYPE_CHECKING:
    from llcps.cps.branch_knowledge import BranchExperience
    from llcps.cps.plan_execution import Failure
    from llcps.scenarios.base import Scenario
    from llcps.sim.world import World

#: Most unmet preconditions a step of K may lack to be a subgoal (see the module docstring).
MAX_SUBGOAL_ATOMS = 2
#: Predicates of contact: a body that touches, carries or holds an argument of a_f (see :func:`clearances`).
CONTACT_PREDICATES = ("in", "on", "touching")
#: Most clearances a failure point gets (each is one more goal-head question per ranking).
MAX_CLEARANCES = 4
#: The actions whose stroke is aimed at another of their arguments, wherever the two stand
#: (:func:`relocations`): moved elsewhere, the object is still pushed to the other one.
AIMED_ACTIONS = ("push_together",)


@dataclass(frozen=True)
class Subgoal:
    """A step of K that would make a missing atom, and the preconditions it lacks at the failure.

    Attributes:
        step: the step's label (``(push can bin)``).
        atoms: its unmet preconditions, each with its sign (True: must become true).
        claimed: per candidate, the atoms the knowledge base claims its action makes.
    """

    step: str
    atoms: tuple[tuple[Fluent, bool], ...]
    claimed: tuple[frozenset[tuple[Fluent, bool]], ...] = ()
    #: A clearance (:func:`clearances`): a contact that may have blocked a_f itself.
    clearance: bool = False

    @property
    def label(self) -> str:
        needs = " ".join(("+" if add else "-") + format_fluent(atom) for atom, add in self.atoms)
        return f"{self.step} needs {needs}"

    def met(self, state: State) -> bool:
        """Whether every atom holds as the step needs in ``state``."""
        return all((atom in state) == add for atom, add in self.atoms)


def clearances(failure: StepFailure, state: State, kinds: Mapping[str, str]) -> list[tuple[str, tuple[tuple[Fluent, bool], ...]]]:
    """(a_f's label, one contact to end) for each contact of an argument of a_f with a body
    that is not one (see the module docstring): a_f may have failed because of what
    touches, carries or holds its arguments, so ending that contact is a way K's own
    step may work again. The support and the ground, which everything stands on, are
    left out. One clearance per pair of bodies, ending every contact relation of the pair
    that holds (``in``, ``on``, ``touching``: ending the closest alone may leave the body
    leaning where it was); at most :data:`MAX_CLEARANCES`, in atom order."""
    arguments = set(failure.step.args)
    contacts: dict[frozenset[str], list[Fluent]] = {}
    for atom in sorted(state):
        if len(atom) != 3 or atom[0] not in CONTACT_PREDICATES or atom in failure.missing_del:
            continue
        bodies = frozenset(atom[1:])
        others = bodies - arguments
        if len(bodies) != 2 or len(others) != 1 or kinds.get(next(iter(others))) in (None, SUPPORT_KIND, GROUND_KIND):
            continue
        contacts.setdefault(bodies, []).append(atom)
    ends = sorted(tuple(sorted(atoms)) for atoms in contacts.values())
    return [(failure.step.label, tuple((atom, False) for atom in atoms)) for atoms in ends[:MAX_CLEARANCES]]


def subgoals(kb: KnowledgeBase, task: Task, failure: StepFailure, state: State) -> list[tuple[str, tuple[tuple[Fluent, bool], ...]]]:
    """(step label, unmet preconditions) of each ground step of ``kb`` that would make one
    of the failure's missing atoms and is not applicable in ``state`` (a_f left out), in
    the planner's grounding order, without repeats."""
    missing_add, missing_del = set(failure.missing_add), set(failure.missing_del)
    found: list[tuple[str, tuple[tuple[Fluent, bool], ...]]] = []
    for step in ground(kb, task):
        if (step.name, step.args) == (failure.step.name, failure.step.args):
            continue
        if not (missing_add & step.add or missing_del & step.delete):
            continue
        unmet = tuple((atom, True) for atom in sorted(step.preconditions - state)) + tuple(
            (atom, False) for atom in sorted(step.negative_preconditions & state)
        )
        if 0 < len(unmet) <= MAX_SUBGOAL_ATOMS and unmet not in (atoms for _, atoms in found):
            found.append((step.label, unmet))
    return found


def attempted(point: FailurePoint, indices: Sequence[int]) -> list[np.ndarray]:
    """Per failed attempt at the missing atoms (a_f, then :attr:`FailurePoint.attempts`),
    each action on its arguments once (two of K's operators may share a controller
    call): which candidates of ``indices`` are it, bool (n,) each."""
    specs = ((point.failed,) if point.failed is not None else ()) + point.attempts
    keys = list(dict.fromkeys((spec.action, spec.arguments) for spec in specs))
    of = [(point.candidates[i].action, point.candidates[i].arguments) for i in indices]
    return [np.array([k == key for k in of], dtype=bool).reshape(len(indices)) for key in keys]


def own_action(point: FailurePoint, indices: Sequence[int]) -> np.ndarray:
    """Per candidate of ``indices``: whether it is the action of a failed attempt at the
    missing atoms (a_f's, or a repair's) on its arguments, bool (n,)."""
    masks = attempted(point, indices)
    return np.logical_or.reduce(masks) if masks else np.zeros(len(indices), dtype=bool)


def _signed_missing(failure: StepFailure) -> list[tuple[Fluent, bool]]:
    """The failure's missing atoms, each with its sign (True: must become true)."""
    return [(atom, True) for atom in failure.missing_add] + [(atom, False) for atom in failure.missing_del]


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
        refused: the candidates whose controller would refuse them here, a waypoint out
            of the arm's reach (:func:`~llcps.sim.controllers.refuses`): they can move
            nothing. Empty unless asked for (``reach_check``).
        failed: a_f's controller call.
        attempts: the controller calls of the other steps of K's plans that missed the
            same atoms (:attr:`~llcps.cps.plan_execution.Failure.attempts`).
        met: the bodies a_f's stroke met that touch none of its arguments at the
            failure (no clearance ends them), other than the support and the ground,
            and that lie on a_f's planned path (:func:`~llcps.sim.controllers.path_meets`).
        in_the_way: the candidates of a_f's own action on its arguments, in any order,
            whose planned path meets a body of ``met``.
        relocations: the candidates whose planned motion takes an argument of a_f, by a
            path that meets no body of ``met``, to a place on the support from where
            a_f's planned path meets none of them (:func:`relocations`).
    """

    scenario: str
    failure: StepFailure
    state: State
    bodies: tuple[Body, ...]
    candidates: tuple[TrialSpec, ...]
    inputs: tuple[WorldModelInput, ...]
    desired: np.ndarray
    claimed: tuple[frozenset[tuple[Fluent, bool]], ...] = ()
    subgoals: tuple[Subgoal, ...] = ()
    refused: frozenset[int] = frozenset()
    failed: TrialSpec | None = None
    attempts: tuple[TrialSpec, ...] = ()
    met: tuple[str, ...] = ()
    in_the_way: frozenset[int] = frozenset()
    relocations: frozenset[int] = frozenset()

    @property
    def ranks_by_resolve(self) -> bool:
        """Whether a candidate's probability of resolving the failure is more than its
        missing atoms' joint probability (:func:`~llcps.cps.ranking.resolve_probability`):
        the point has subgoals, or candidates whose path meets a body a_f's stroke met or
        that take an argument of a_f off that path."""
        return bool(self.subgoals or self.in_the_way or self.relocations)

    @property
    def missing_effects(self) -> str:
        return self.failure.describe()

    @property
    def asked(self) -> frozenset[tuple[Fluent, bool]]:
        """Every atom (with its sign) a goal-aware question here asks for: a_f's missing
        atoms and each subgoal's."""
        return frozenset(_signed_missing(self.failure)).union(*(subgoal.atoms for subgoal in self.subgoals))

    def query(self, indices: Sequence[int] | None = None) -> GoalQuery:
        """The goal-aware question for some candidates (all by default): will they make
        the missing atoms hold (and the atoms that should go, go)?"""
        return self._query(_signed_missing(self.failure), self.claimed, indices)

    def subgoal_query(self, k: int, indices: Sequence[int] | None = None) -> GoalQuery:
        """The goal-aware question for subgoal ``k``: will the candidates meet it?"""
        subgoal = self.subgoals[k]
        return self._query(subgoal.atoms, subgoal.claimed, indices)

    def _query(
        self,
        atoms: Sequence[tuple[Fluent, bool]],
        claimed: Sequence[frozenset[tuple[Fluent, bool]]],
        indices: Sequence[int] | None,
    ) -> GoalQuery:
        chosen = range(len(self.candidates)) if indices is None else indices
        specs = tuple(self.candidates[i] for i in chosen)
        by_spec = {self.candidates[i]: claimed[i] for i in chosen} if claimed else {}
        return GoalQuery.from_missing(
            specs,
            missing_add=[atom for atom, add in atoms if add],
            missing_del=[atom for atom, add in atoms if not add],
            bodies=self.bodies,
            before=self.state,
            claims=(lambda spec, atom, add: (atom, add) in by_spec[spec]) if by_spec else None,
        )


class FailureSite(Protocol):
    """What :func:`failure_point` needs of the trial executor
    (:class:`~llcps.cps.executor.TrialExecutor` is one): the world just after a_f failed,
    its entities, and how K's steps and states become controller calls and tasks."""

    @property
    def world(self) -> World: ...
    @property
    def scenario(self) -> Scenario: ...
    @property
    def kinds(self) -> Mapping[str, str]: ...
    def sync(self) -> None: ...
    def controller_call(self, step: GroundAction) -> TrialSpec: ...
    def task(self, state: State) -> Task: ...


def failure_point(
    site: FailureSite,
    failure: StepFailure,
    state: State,
    kb: KnowledgeBase,
    *,
    grid: Grid,
    known: KnowledgeBase | None = None,
    reach_check: bool = False,
    attempts: Sequence[GroundAction] = (),
    met: Collection[str] = (),
) -> FailurePoint:
    """The failure point of ``site``'s world as it is now (just after a_f failed).

    Args:
        kb: says which candidates' actions claim the missing atoms as effects.
        grid: the controller settings the candidates take.
        known: K costed by the experience the branch has now, whose steps give the
            subgoals (default: ``kb``).
        reach_check: also find the candidates the arm would refuse here
            (:attr:`FailurePoint.refused`); the check solves IK, which leaves the arm's
            joints as they were but not every byte the world saves next, so only a
            caller that restores the world before its next trial asks for it.
        attempts: the other plan steps that missed the same atoms
            (:attr:`FailurePoint.attempts`).
        met: the bodies a_f's stroke met (:meth:`ExplorationSite.met`); those in
            contact with its arguments at the failure, the support and the ground are
            left out of :attr:`FailurePoint.met`.
    """
    from llcps.sim.controllers import path_meets, refuses
    from llcps.sim.perception import entity_features, scene_bodies

    world = site.world
    site.sync()
    failed_spec = site.controller_call(failure.step)
    specs = enumerate_candidates(failed=failed_spec, entities=site.kinds, grid=grid)
    features = {name: entity_features(world, name) for name in site.kinds}
    inputs = tuple(WorldModelInput(spec=c, features=tuple(features[a] for a in c.arguments)) for c in specs)
    task = site.task(state)

    def claimed_by(atoms: Sequence[tuple[Fluent, bool]]) -> tuple[frozenset[tuple[Fluent, bool]], ...]:
        return tuple(frozenset(m for m in atoms if kb.claims(c, m[0], add=m[1], objects=task.objects)) for c in specs)

    claimed = claimed_by(_signed_missing(failure))
    steps_of = kb if known is None else known
    bodies = scene_bodies(world)
    kinds = {body.name: body.kind for body in bodies}
    cleared = clearances(failure, state, kinds)
    routes = tuple(Subgoal(step, atoms, claimed_by(atoms)) for step, atoms in subgoals(steps_of, task, failure, state)) + tuple(
        Subgoal(step, atoms, claimed_by(atoms), clearance=True) for step, atoms in cleared
    )
    refused = frozenset(i for i, spec in enumerate(specs) if refuses(world, spec)) if reach_check else frozenset()
    in_contact = {body for _, atoms in cleared for (atom, _) in atoms for body in atom[1:]}
    # a body met on a_f's planned path: the evidence is about a_f, so only its own action on
    # its arguments (in any order) is judged by it, each candidate by whether its planned
    # path meets it too
    stroke = tuple(
        b for b in sorted(met) if b not in in_contact and kinds.get(b) not in (None, SUPPORT_KIND, GROUND_KIND) and path_meets(world, failed_spec, b)
    )
    own = [i for i, spec in enumerate(specs) if (spec.action, sorted(spec.arguments)) == (failed_spec.action, sorted(failed_spec.arguments))]
    in_the_way = frozenset(i for i in own if any(path_meets(world, specs[i], b) for b in stroke))
    way_around: frozenset[int] = frozenset()
    if stroke:
        supports = [world.aabb(body.name) for body in bodies if body.kind == SUPPORT_KIND]
        way_around = relocations(world, failed_spec, specs, stroke, supports, skip=own)
    return FailurePoint(
        scenario=site.scenario.name,
        failure=failure,
        state=state,
        bodies=bodies,
        candidates=tuple(specs),
        inputs=inputs,
        desired=desired_outcome(missing_add=failure.missing_add, missing_del=failure.missing_del),
        claimed=claimed,
        subgoals=routes,
        refused=refused,
        failed=failed_spec,
        attempts=tuple(site.controller_call(step) for step in attempts),
        met=stroke,
        in_the_way=in_the_way,
        relocations=way_around,
    )


def relocations(
    world: World,
    failed: TrialSpec,
    specs: Sequence[TrialSpec],
    met: Sequence[str],
    supports: Sequence[tuple[tuple[float, float, float], tuple[float, float, float]]],
    *,
    skip: Collection[int] = (),
) -> frozenset[int]:
    """The candidates of ``specs`` (but ``skip``) that would take a_f's stroke off the
    bodies it met (see the module docstring), by geometry alone
    (:func:`~llcps.sim.controllers.planned_end`, :func:`~llcps.sim.controllers.path_meets`):
    each moves an argument of a_f (``failed``), by a path that meets no body of ``met``,
    to a place within a support's footprint from where a_f's planned path meets none of
    them. Only an a_f aimed at its other argument has them (:data:`AIMED_ACTIONS`): a
    push one way, or a carry, from elsewhere ends elsewhere, so its effect is not what
    K expected of it."""
    from llcps.sim.controllers import planned_end, path_meets

    if failed.action not in AIMED_ACTIONS:
        return frozenset()
    found, skipped = set(), set(skip)
    for i, spec in enumerate(specs):
        end = None if i in skipped else planned_end(world, spec)
        if end is None or end[0] not in failed.arguments:
            continue
        x, y = end[1]
        if not any(lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1] for lo, hi in supports):
            continue
        if any(path_meets(world, spec, b) or path_meets(world, failed, b, at={end[0]: end[1]}) for b in met):
            continue
        found.add(i)
    return frozenset(found)


class ExplorationSite(FailureSite, Protocol):
    """A :class:`FailureSite` that can return its world to a stored snapshot, and replay a
    controller call from one to see what its stroke meets."""

    def restore(self, snapshot_id: int) -> None: ...
    def met(self, spec: TrialSpec) -> frozenset[str]: ...


def start_exploration(
    site: ExplorationSite, experience: BranchExperience, kb: KnowledgeBase, failure: Failure, *, grid: Grid, reach_check: bool = False
) -> FailurePoint:
    """Return the world to the stored state a_f was executed from and describe the
    failure point there (subgoals from K costed by the branch's experience now; with
    ``reach_check``, the candidates the arm would refuse there). Every trial from the
    failure point must restore ``failure.snapshot`` first, as :meth:`TrialExecutor.execute
    <llcps.cps.executor.TrialExecutor.execute>` with ``start`` does.

    What an episode (:mod:`llcps.cps.episode`) and the Gymnasium environment
    (:mod:`llcps.gym`) both do once K's plan failed; every candidate starts from
    ``failure.snapshot``.
    """
    if failure.snapshot is None:
        raise ValueError("exploration starts from a stored snapshot: run the plan with store=True")
    site.restore(failure.snapshot)
    met = site.met(site.controller_call(failure.monitor.step))
    site.restore(failure.snapshot)
    return failure_point(
        site, failure.monitor, failure.state, kb, grid=grid, known=experience.costed(kb), reach_check=reach_check, attempts=failure.attempts,
        met=met,
    )
