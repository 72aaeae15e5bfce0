"""Subgoals: the other way to a failure's missing atoms through K (llcps.cps.exploration).

A trial resolves a novelty when the goal holds after it, or when K's plan from the state
it leaves works. So a step of K that would make a missing atom, but lacks preconditions
at the failure, names what a trial may achieve instead; goal-directed ranking combines
both ways (resolve_probability).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from llcps.cps.exploration import MAX_CLEARANCES, MAX_SUBGOAL_ATOMS, SUBGOAL_TRUST, Subgoal, clearances, resolve_probability, subgoals
from llcps.domain import fluent
from llcps.models.measures import GOAL_FLOOR, rank
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.task import Task
from llcps.symbolic.monitor import check_step
from llcps.symbolic.planner import ground

OBJECTS = {"can": "item", "bin": "container"}
#: The can on the table, the bin out of reach: not near each other.
STATE = frozenset({fluent("visible", "can"), fluent("reachable", "can"), fluent("on", "can", "table")})
GOAL = frozenset({fluent("in", "can", "bin")})


def _failure(kb: KnowledgeBase, name: str, state=STATE):
    task = Task(objects=OBJECTS, init=state, goal_pos=GOAL)
    (step,) = [s for s in ground(kb, task) if s.name == name and s.args == ("can", "bin")]
    failure = check_step(step, state)  # nothing changed: the step's add effects are missing
    assert failure is not None and fluent("in", "can", "bin") in failure.missing_add
    return task, failure


def test_a_step_of_k_that_makes_the_missing_atom_names_what_it_lacks() -> None:
    kb = KnowledgeBase.default()
    task, failure = _failure(kb, "place_in_container")
    found = subgoals(kb, task, failure, STATE)
    # K's push puts the can in the bin, but only from near it: the subgoal is (near can bin).
    assert ("(push can bin)", ((fluent("near", "can", "bin"), True),)) in found
    # the failed step itself is never a subgoal, and no subgoal is empty or too long
    assert all(not label.startswith("(place_in_container can bin)") for label, _ in found)
    assert all(0 < len(atoms) <= MAX_SUBGOAL_ATOMS for _, atoms in found)


def test_a_step_applicable_at_the_failure_is_no_subgoal() -> None:
    """Where K's step could run already, exploring cannot make it more possible."""
    kb = KnowledgeBase.default()
    near = STATE | {fluent("near", "can", "bin")}
    task, failure = _failure(kb, "place_in_container", near)
    assert not any(label == "(push can bin)" for label, _ in subgoals(kb, task, failure, near))


def test_a_body_in_contact_with_an_argument_of_the_failed_step_is_a_clearance() -> None:
    """What touches, carries or holds an argument of a_f may be why it failed: ending every
    contact of each other body with it is a way K's step may work again. The support
    and the ground, and contacts between two arguments or two other bodies, are not."""
    kb = KnowledgeBase.default()
    kinds = {"can": "object", "bin": "container", "board": "object", "shelf": "fixture", "box": "object", "table": "table", "floor": "floor"}
    state = STATE | {
        fluent("on", "board", "bin"), fluent("touching", "board", "bin"), fluent("touching", "bin", "board"),
        fluent("touching", "can", "shelf"), fluent("touching", "board", "box"), fluent("touching", "bin", "floor"),
        fluent("touching", "can", "bin"),
    }  # fmt: skip
    _, failure = _failure(kb, "place_in_container", state)
    found = clearances(failure, state, kinds)
    board = (fluent("on", "board", "bin"), fluent("touching", "board", "bin"))  # touching is symmetric: one atom
    assert found == [
        ("(place_in_container can bin)", tuple((atom, False) for atom in board)),
        ("(place_in_container can bin)", ((fluent("touching", "can", "shelf"), False),)),
    ]
    assert all(Subgoal(label, atoms).met(STATE) for label, atoms in found)  # both ended: met
    # Pushed off the bin's top but leaning on its rim, the board is not out of the way.
    leaning = STATE | {fluent("touching", "board", "bin")}
    assert not Subgoal(*found[0]).met(leaning)
    assert not clearances(failure, STATE, kinds)  # nothing but the support touches the can
    crowd = {f"b{i}": "object" for i in range(10)}
    crowded = STATE | {fluent("touching", "can", name) for name in crowd}
    assert len(clearances(failure, crowded, {**kinds, **crowd})) == MAX_CLEARANCES


def test_a_subgoal_is_met_when_every_atom_holds_with_its_sign() -> None:
    near, on = fluent("near", "can", "bin"), fluent("on", "can", "table")
    subgoal = Subgoal("(push can bin)", ((near, True), (on, False)))
    assert subgoal.met(frozenset({near}))
    assert not subgoal.met(frozenset({near, on}))
    assert not subgoal.met(frozenset())
    assert subgoal.label == "(push can bin) needs +(near can bin) -(on can table)"


def test_resolve_probability_by_hand() -> None:
    goal = np.array([[0.1], [0.5], [0.1]])
    sub = np.array([[0.8], [0.0], [0.0]])
    p = resolve_probability(goal, sub, np.array([0.5]))
    # 1 - (1 - 0.1)(1 - 0.5 * 0.8); 0.5 alone; 0.1 alone
    assert p == pytest.approx([1 - 0.9 * 0.6, 0.5, 0.1])
    assert resolve_probability(goal, np.zeros((3, 0)), np.zeros(0)) == pytest.approx([0.1, 0.5, 0.1])
    # two missing atoms: their product
    assert resolve_probability(np.array([[0.5, 0.5]]), np.zeros((1, 0)), np.zeros(0)) == pytest.approx([0.25])


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0, 1), st.floats(0, 1), st.floats(0, 1), st.integers(0, 6), st.integers(0, 2**31 - 1)
)
@example(0.0, 0.0, 2.220446049250313e-16, 0, 0)  # both below GOAL_FLOOR: a tie, broken by the seed
@example(0.0, 0.0, 1e-9, 0, 0)  # above it: the likelier subgoal first
def test_a_likelier_subgoal_ranks_first_and_failures_weaken_it(goal_p, low, high, failures, seed) -> None:
    """Under goal-directed, of two candidates equally likely to make the missing atom,
    the one likelier to meet a subgoal never ranks second; each failure after meeting
    it halves the subgoal's trust, so its weight only falls."""
    low, high = sorted((low, high))
    goal = np.array([[goal_p], [goal_p]])
    sub = np.array([[low], [high]])
    trust = np.array([SUBGOAL_TRUST * 0.5**failures])
    p = resolve_probability(goal, sub, trust)
    assert np.all((0 <= p) & (p <= 1)) and p[1] >= p[0] >= goal_p - 1e-12
    order = rank(np.zeros((2, 6)), "goal-directed", seed=seed, goal=p[:, None])
    if max(p[1], GOAL_FLOOR) > max(p[0], GOAL_FLOOR):  # below the measure's floor, both tie
        assert order[0] == 1
    weaker = resolve_probability(goal, sub, trust / 2)
    assert np.all(weaker <= p + 1e-15)
