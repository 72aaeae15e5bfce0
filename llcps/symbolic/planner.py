"""The planner: cheapest plans for a task T = (K, s0, sg).

The knowledge bases here are tiny (a handful of operators over a handful of
entities), so the planner grounds every operator over the task's objects and runs a
uniform-cost search on the ground problem. Maintained pure-Python planners do not fit:
pyperplan handles STRIPS only (no negative preconditions, no action costs), and
unified-planning would need a compilation step and a heavy dependency for this size.
The tests hold it against one all the same: Fast Downward, through unified-planning, on
K' as :mod:`llcps.symbolic.export` writes it.

Steps are costed by K's experience in the context they would run in, and a step is
left out where its operator has failed in that context and never worked there; in a state
the plan predicts (beyond the perceived one), also where it failed in a context the
predicted one contains and never worked in one (:meth:`KnowledgeBase.step_cost`,
:meth:`KnowledgeBase.allowed`). Experience only orders plans, it never removes the last
one: when every plan uses a step experience left out, the agent's first plan is searched
again with those steps allowed (at their experience cost; ``last_resort``). A task K can solve has a plan under any
experience, so the agent always reaches a step to fail at, and explores from there.

Ties between plans of equal cost are broken deterministically: fewer steps first, then
the order in which operators and their arguments sort.
"""

from __future__ import annotations

import heapq
import itertools
import math
from typing import Collection

from llcps.errors import LlcpsError
from llcps.limits import MAX_GROUND_ACTIONS, MAX_PLANNER_STATES
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.task import Task
from llcps.symbolic.lifted import GroundAction

Plan = tuple[GroundAction, ...]
"""A plan pi = [a_1, ..., a_n]: ground actions in execution order."""

#: Default bound on the number of states the search expands.
MAX_EXPANSIONS = 200_000


class PlanningLimitError(LlcpsError):
    """The search ran out of its budget (expansions, states held, ground actions) before
    it could decide the task."""

    exit_code = 1


def ground(kb: KnowledgeBase, task: Task, *, max_actions: int = MAX_GROUND_ACTIONS) -> list[GroundAction]:
    """Every ground action of K over the task's objects, in a deterministic order.

    A parameter of type t takes every object whose type is t or a subtype of t.

    Raises:
        PlanningLimitError: more than ``max_actions`` argument tuples to try.
    """
    objects = task.all_objects(kb)
    names = sorted(objects)
    actions: list[GroundAction] = []
    tried = 0
    for op in sorted(kb.operators(), key=lambda o: o.name):
        domains = [[o for o in names if kb.is_subtype(objects[o], kind)] for _, kind in op.parameters]
        tried += math.prod(len(d) for d in domains)
        if tried > max_actions:
            raise PlanningLimitError(
                f"the task grounds more than {max_actions:,} actions ({len(objects)} objects)",
                hint="give the task fewer objects (see Limits in docs/scenarios.md)",
            )
        for args in itertools.product(*domains):
            step = op.ground(args)
            if step is not None:
                actions.append(step)
    return actions


def plan(
    kb: KnowledgeBase,
    task: Task,
    *,
    exclude: Collection[tuple[str, tuple[str, ...]]] = (),
    max_expansions: int = MAX_EXPANSIONS,
    max_states: int = MAX_PLANNER_STATES,
    last_resort: bool = False,
) -> Plan | None:
    """The cheapest plan from the task's initial state to its goal.

    Args:
        kb: the knowledge base K.
        task: objects, initial state and goal.
        exclude: ground actions ``(operator name, args)`` the plan may not use, e.g.
            a step that just failed (plan repair).
        max_expansions: how many states the search may expand before giving up.
        max_states: how many states it may hold (reached, with cost and parent): this,
            not the expansions, bounds its memory.
        last_resort: when experience leaves out every plan, search again with the steps
            it left out allowed (at their experience cost). The agent asks for this for
            its first plan only, so that it always reaches a step to fail at; a re-plan
            after an exploration trial does not, or a trial would "resolve" the novelty
            by re-running a step experience ruled out there.

    Returns:
        A cheapest plan (empty when s0 already satisfies the goal), or None when no plan
        exists with K (whatever its experience: see the module docstring).

    Raises:
        LlcpsError: the task does not fit K (unknown objects, predicates, types).
        PlanningLimitError: the budget ran out first.
    """
    task.check(kb)
    banned = {(name.lower(), tuple(args)) for name, args in exclude}
    actions = [a for a in ground(kb, task) if (a.name.lower(), a.args) not in banned]
    # Of equally cheap plans, the one acting on the goal's objects: a learned operator's
    # context rarely tells the object it was learned on from a bystander of its type.
    goal_objects = {term for atom in (*task.goal_pos, *task.goal_neg) for term in atom[1:]}
    actions.sort(key=lambda a: -len(goal_objects.intersection(a.args)))
    found = _search(kb, task, actions, max_expansions=max_expansions, max_states=max_states, by_experience=True)
    if found is None and last_resort and kb.experience.entries:
        # Experience left out every plan: it may make a step dear, never impossible.
        found = _search(kb, task, actions, max_expansions=max_expansions, max_states=max_states, by_experience=False)
    return found


def _search(
    kb: KnowledgeBase, task: Task, actions: list[GroundAction], *, max_expansions: int, max_states: int, by_experience: bool
) -> Plan | None:
    """Uniform-cost search over ``actions``; ``by_experience`` leaves out the steps
    experience does not allow (:meth:`KnowledgeBase.allowed`)."""
    start = task.init
    # (cost, steps, insertion order, state); the insertion order makes ties deterministic.
    counter = itertools.count()
    frontier: list[tuple[float, int, int, frozenset]] = [(0.0, 0, next(counter), start)]
    best: dict[frozenset, tuple[float, int]] = {start: (0.0, 0)}
    parent: dict[frozenset, tuple[frozenset, GroundAction] | None] = {start: None}
    closed: set[frozenset] = set()
    expansions = 0
    while frontier:
        cost, steps, _, state = heapq.heappop(frontier)
        if state in closed:
            continue
        if task.satisfied_by(state):
            return _extract(parent, state)
        closed.add(state)
        expansions += 1
        if expansions > max_expansions:
            raise PlanningLimitError(
                f"planning gave up after {max_expansions} expansions",
                hint="raise max_expansions or give the task fewer objects",
            )
        for action in actions:
            if not action.applicable(state) or (by_experience and not kb.allowed(action, state, predicted=state is not start)):
                continue
            successor = action.apply(state)
            if successor in closed:
                continue
            key = (cost + kb.step_cost(action, state), steps + 1)
            if key < best.get(successor, (float("inf"), 0)):
                if successor not in best and len(best) >= max_states:
                    raise PlanningLimitError(
                        f"planning gave up holding {max_states:,} states",
                        hint="give the task fewer objects (see Limits in docs/scenarios.md)",
                    )
                best[successor] = key
                parent[successor] = (state, action)
                heapq.heappush(frontier, (*key, next(counter), successor))
    return None


def _extract(parent: dict[frozenset, tuple[frozenset, GroundAction] | None], state: frozenset) -> Plan:
    steps: list[GroundAction] = []
    link = parent[state]
    while link is not None:
        previous, action = link
        steps.append(action)
        link = parent[previous]
    return tuple(reversed(steps))


def plan_cost(steps: Plan) -> float:
    """The metric value of a plan in PDDL: the sum of its steps' costs by their operators'
    experience in every context (the cost a PDDL validator adds up)."""
    return sum(step.cost for step in steps)
