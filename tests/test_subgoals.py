"""Subgoals: the other way to a failure's missing atoms through K (llcps.cps.failure_point, llcps.cps.ranking).

A trial resolves a novelty when the goal holds after it, or when K's plan from the state
it leaves works. So a step of K that would make a missing atom, but lacks preconditions
at the failure, names what a trial may achieve instead; goal-directed ranking combines
both ways (resolve_probability).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from llcps.cps.failure_point import (
    MAX_CLEARANCES,
    MAX_SUBGOAL_ATOMS,
    Subgoal,
    attempted,
    clearances,
    own_action,
    subgoals,
)
from llcps.cps.ranking import SUBGOAL_TRUST, blocked_belief, rank_candidates, resolve_probability
from llcps.cps.plan_execution import Failure, with_attempts
from llcps.domain import fluent
from llcps.models.measures import GOAL_FLOOR, rank
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.task import Task
from llcps.symbolic.monitor import StepFailure, check_step
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


def test_a_contact_that_blocked_a_f_keeps_a_fs_own_action_from_the_atoms_by_hand() -> None:
    """Candidates 0 and 1 are a_f's own action on its arguments, 2 is not; one clearance,
    believed with 0.9 to have blocked a_f."""
    goal = np.array([[0.9], [0.9], [0.1]])
    sub = np.array([[0.0], [0.8], [0.6]])
    trust = np.array([0.9])
    blocking = np.array([[0.9], [0.9], [0.0]])
    p = resolve_probability(goal, sub, trust, blocking)
    # 0: the atoms only if the contact did not block: 0.9 (1 - 0.9); it does not end the contact.
    # 1: 0.9 (1 - 0.9 * 0.2) directly, or the contact ended (0.8) and K's step then works (0.9).
    # 2: not a_f's: as without blocking.
    assert p == pytest.approx([0.09, 1 - (1 - 0.9 * 0.82) * (1 - 0.8 * 0.9), 1 - 0.9 * (1 - 0.6 * 0.9)])
    assert resolve_probability(goal, sub, trust, np.zeros((3, 1))) == pytest.approx(resolve_probability(goal, sub, trust))
    assert p[2] == pytest.approx(resolve_probability(goal, sub, trust)[2])


def test_a_body_met_on_a_fs_path_keeps_the_candidates_whose_path_meets_it_from_the_atoms_by_hand() -> None:
    """Candidates 0 and 1 are a_f's own action; 0's path meets the body a_f's stroke met
    (believed with 0.8 to have blocked a_f), 1's does not, 2 is another action."""
    goal = np.array([[0.9], [0.9], [0.3]])
    sub, trust = np.array([[0.5], [0.5], [0.5]]), np.array([0.5])
    p = resolve_probability(goal, sub, trust, stroke=np.array([0.8, 0.0, 0.0]))
    # 0: the atoms only if the body does not block its path too: 0.9 (1 - 0.8); subgoals as before.
    assert p == pytest.approx([1 - (1 - 0.9 * 0.2) * (1 - 0.25), 1 - 0.1 * 0.75, 1 - 0.7 * 0.75])
    assert p[1:] == pytest.approx(resolve_probability(goal, sub, trust)[1:])


def test_a_way_around_a_body_met_is_one_more_route_by_hand() -> None:
    """Candidate 1 would take a_f's argument off the body's path: K's step then works with
    the belief 0.3 it is given; 0 and 2 are not such candidates."""
    goal = np.array([[0.2], [0.1], [0.1]])
    sub, trust = np.zeros((3, 0)), np.zeros(0)
    p = resolve_probability(goal, sub, trust, around=np.array([0.0, 0.3, 0.0]))
    assert p == pytest.approx([0.2, 1 - 0.9 * 0.7, 0.1])
    assert resolve_probability(goal, sub, trust, around=np.zeros(3)) == pytest.approx(resolve_probability(goal, sub, trust))


@given(st.floats(0, 1), st.floats(0, 1))
def test_the_belief_that_a_contact_blocked_a_f_grows_with_how_sure_the_model_was_of_a_f(p: float, q: float) -> None:
    """t / (t + (1 - t)(1 - p)): the prior when the model expected nothing of a_f, certainty
    when it was sure, and more the surer it was."""
    assert blocked_belief(0.0) == pytest.approx(SUBGOAL_TRUST) and blocked_belief(1.0) == 1.0
    assert blocked_belief(0.9) == pytest.approx(0.5 / (0.5 + 0.5 * 0.1))
    low, high = sorted((p, q))
    assert SUBGOAL_TRUST - 1e-12 <= blocked_belief(low) <= blocked_belief(high) + 1e-12 <= 1.0 + 1e-12


def test_each_failed_attempt_at_the_atoms_is_evidence_that_the_contact_blocked_them() -> None:
    """a_f, and a repair's step that missed the same atom, each failed: t / (t + (1 - t)
    (1 - p_1)(1 - p_2)), worked by hand; one attempt is a_f's alone."""
    t = SUBGOAL_TRUST
    assert blocked_belief([0.9, 0.5]) == pytest.approx(t / (t + (1 - t) * 0.1 * 0.5))
    assert blocked_belief([0.9]) == pytest.approx(blocked_belief(0.9))
    assert blocked_belief([]) == pytest.approx(t)  # no attempt the model expected anything of: the prior


@given(st.lists(st.floats(0, 1), max_size=4), st.floats(0, 1))
def test_a_further_failed_attempt_never_lowers_the_belief_that_the_contact_blocked(ps: list[float], p: float) -> None:
    assert blocked_belief([*ps, p]) >= blocked_belief(ps) - 1e-12


def test_each_action_on_its_arguments_is_one_attempt_however_often_it_failed() -> None:
    """a_f is a push of the can; the attempts repeat it (another operator with the same
    controller call) and name the placement twice, at other settings: two attempts, and
    only the candidates of those two actions on their arguments are a failed attempt's."""
    from llcps.cps.failure_point import FailurePoint
    from llcps.domain import ControllerParams
    from llcps.trial_records import TrialSpec

    kb = KnowledgeBase.default()
    _, pushed = _failure(kb, "push")

    def spec(action, arguments, rate=0.4):
        return TrialSpec(action, arguments, ControllerParams(rate=rate, movement_magnitude=0.15, orientation="top"))

    candidates = (spec("push", ("can",), 0.1), spec("place_in_container", ("can", "bin"), 0.1), spec("push_together", ("can", "bin")))
    point = FailurePoint(
        scenario="mine", failure=pushed, state=STATE, bodies=(), candidates=candidates, inputs=(), desired=np.zeros(6),
        failed=spec("push", ("can",)),
        attempts=(spec("push", ("can",), 1.0), spec("place_in_container", ("can", "bin")), spec("place_in_container", ("can", "bin"), 1.0)),
    )  # fmt: skip
    masks = attempted(point, [0, 1, 2])
    assert [m.tolist() for m in masks] == [[True, False, False], [False, True, False]]
    assert own_action(point, [2, 1, 0]).tolist() == [False, True, True]


def test_a_failure_point_asks_for_a_fs_missing_atoms_and_every_subgoal_s() -> None:
    """What episode evidence may count (``FailurePoint.asked``): a_f's missing atoms and
    each subgoal's atoms, with their signs; nothing else."""
    from llcps.cps.failure_point import FailurePoint

    kb = KnowledgeBase.default()
    _, pushed = _failure(kb, "push")
    clear = Subgoal("(push can bin)", ((fluent("touching", "can", "board"), False),), clearance=True)
    point = FailurePoint(scenario="mine", failure=pushed, state=STATE, bodies=(), candidates=(), inputs=(), desired=np.zeros(6))
    assert point.asked == {(fluent("in", "can", "bin"), True)} | {(atom, False) for atom in pushed.missing_del}
    with_clearance = FailurePoint(
        scenario="mine", failure=pushed, state=STATE, bodies=(), candidates=(), inputs=(), desired=np.zeros(6), subgoals=(clear,)
    )  # fmt: skip
    assert with_clearance.asked == point.asked | {(fluent("touching", "can", "board"), False)}


def test_the_repairs_steps_that_missed_a_fs_atoms_are_its_attempts() -> None:
    """K's push of the can into the bin failed (a_f); its repair, the placement, missed
    the same atom: the placement is an attempt, once, and a_f's own step is not; a step
    that missed other atoms is not either."""
    kb = KnowledgeBase.default()
    task, pushed = _failure(kb, "push")
    _, placed = _failure(kb, "place_in_container")

    def failure(monitor):
        return Failure(step=monitor.step, state=STATE, physics=b"", snapshot=None, monitor=monitor)

    (together,) = [s for s in ground(kb, task) if s.name == "push_together" and s.args == ("can", "bin")]
    other = StepFailure(together, frozenset({fluent("touching", "can", "bin")}), frozenset())
    a_f = failure(pushed)
    found = with_attempts(a_f, [a_f, failure(other), failure(placed), failure(placed), a_f])
    assert found is not None and found.attempts == (placed.step,)
    assert (found.step, found.monitor) == (a_f.step, a_f.monitor)
    assert with_attempts(None, [a_f]) is None
    assert with_attempts(a_f, [a_f]).attempts == ()


@pytest.mark.slow
def test_a_real_failure_at_a_contact_blocks_a_fs_own_action_from_the_first_ranking_on(readme_pretrained: Path, tmp_path: Path) -> None:
    """scenario10: the can stands against the shelf's post, and K's placement fails. The
    contact is a clearance; the nb model of the README's pretraining expected the placement
    to work, so the contact is believed to have blocked it, a_f's own placements are
    lowered and nothing else, and an ordering keeps its first ranking's belief."""
    from llcps.cps.inspection import reach_failure
    from llcps.cps.orderings.base import Exploration
    from llcps.cps.orderings.ranked import Ranked
    from llcps.models.persistence import fit_or_load
    from llcps.store import Store

    with Store.open(str(shutil.copyfile(readme_pretrained, tmp_path / "llcps.db"))) as store:
        point = reach_failure(store, branch="main", scenario="scenario10", seed=0, reach_check=False)
        model = fit_or_load(store, "main", "nb", 1, records=store.visible_trials("main"), changes=store.visible_changes("main"))
    assert point.failed is not None and (point.failed.action, point.failed.arguments) == ("place_in_container", ("can", "bin"))
    cleared = [s for s in point.subgoals if s.clearance]
    assert cleared and all(s.step == point.failure.step.label for s in cleared)
    assert all(not s.clearance for s in point.subgoals if s.step != point.failure.step.label)
    ranking = rank_candidates(model, point, measure="goal-directed", seed=0)
    own = own_action(point, ranking.indices)
    assert own.any() and not own.all()
    assert ranking.goal is not None and ranking.subgoals is not None and ranking.resolve is not None
    direct = np.prod(ranking.goal, axis=1)
    assert ranking.blocked == pytest.approx(blocked_belief(float(direct[own].mean()))) and ranking.blocked > SUBGOAL_TRUST
    clearance = np.array([s.clearance for s in point.subgoals])
    trust = np.where(clearance, ranking.blocked, SUBGOAL_TRUST)
    unblocked = resolve_probability(ranking.goal, ranking.subgoals, trust)
    assert np.all(ranking.resolve[own] <= unblocked[own] + 1e-12) and np.any(ranking.resolve[own] < unblocked[own])
    assert ranking.resolve[~own] == pytest.approx(unblocked[~own])
    ordering = Ranked(Exploration(model=model, point=point, measure="goal-directed", seed=0))
    first = ordering.blocked
    assert first == pytest.approx(ranking.blocked)
    tried = ordering.next()
    assert tried is not None
    ordering.observe(tried, point.state)  # a failure: ranked again, with the first ranking's belief
    assert ordering.ranking.blocked == first and tried not in ordering.ranking.indices


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


@pytest.mark.slow
def test_a_real_repair_that_missed_a_fs_atom_is_blocked_by_the_contact_beside_a_f(readme_pretrained: Path, tmp_path: Path) -> None:
    """docs/heldout/lid.toml: a board lies across the bin. K pushes the can into the bin
    (a_f) and fails; its repair places the can and fails too. The placement is an attempt
    at the same atom: the nb model expected it to work, so the belief that the board
    blocked grows beyond a_f's alone, the can's placements into the bin are lowered as a_f's
    pushes are, and no other candidate moves."""
    from llcps.cps.inspection import reach_failure
    from llcps.models.persistence import fit_or_load
    from llcps.store import Store

    lid = str(Path(__file__).resolve().parents[1] / "docs" / "heldout" / "lid.toml")
    with Store.open(str(shutil.copyfile(readme_pretrained, tmp_path / "llcps.db"))) as store:
        point = reach_failure(store, branch="main", scenario=lid, seed=0, reach_check=False)
        model = fit_or_load(store, "main", "nb", 1, records=store.visible_trials("main"), changes=store.visible_changes("main"))
    assert point.failed is not None and (point.failed.action, point.failed.arguments) == ("push", ("can",))
    assert [(a.action, a.arguments) for a in point.attempts] == [("place_in_container", ("can", "bin"))]
    assert any(s.clearance for s in point.subgoals)
    ranking = rank_candidates(model, point, measure="goal-directed", seed=0)
    assert ranking.goal is not None and ranking.subgoals is not None and ranking.resolve is not None
    pushes, placements = attempted(point, ranking.indices)
    own = own_action(point, ranking.indices)
    assert pushes.any() and placements.any() and np.array_equal(own, pushes | placements)
    direct = np.prod(ranking.goal, axis=1)
    assert ranking.blocked == pytest.approx(blocked_belief([float(direct[pushes].mean()), float(direct[placements].mean())]))
    assert ranking.blocked > blocked_belief(float(direct[pushes].mean()))
    clearance = np.array([s.clearance for s in point.subgoals])
    trust = np.where(clearance, ranking.blocked, SUBGOAL_TRUST)
    unblocked = resolve_probability(ranking.goal, ranking.subgoals, trust)
    assert np.all(ranking.resolve[placements] < unblocked[placements])
    assert ranking.resolve[~own] == pytest.approx(unblocked[~own])


@pytest.mark.slow
def test_a_real_stroke_that_met_a_fence_lowers_a_fs_own_action_on_every_path_through_it(readme_pretrained: Path, tmp_path: Path) -> None:
    """docs/heldout/fence.toml: K pushes the block toward the puck (a_f) and a low fence
    between them stops it; at the failure the fence touches neither, so no clearance
    explains it. The replayed stroke met the fence, every planned path of a_f's own
    action on the two bodies, pushed either way, goes through it, and those candidates
    are lowered by the belief that it blocked a_f (and K's repairs that missed the same
    atom). The candidates that would take the block or the puck off the fence's line
    (by geometry) are raised by the same belief; no other candidate moves."""
    from llcps.cps.inspection import reach_failure
    from llcps.models.persistence import fit_or_load
    from llcps.store import Store

    fence = str(Path(__file__).resolve().parents[1] / "docs" / "heldout" / "fence.toml")
    with Store.open(str(shutil.copyfile(readme_pretrained, tmp_path / "llcps.db"))) as store:
        point = reach_failure(store, branch="main", scenario=fence, seed=0, reach_check=False)
        model = fit_or_load(store, "main", "nb", 1, records=store.visible_trials("main"), changes=store.visible_changes("main"))
    assert point.failed is not None and point.failed.action == "push_together"
    assert point.met == ("fence",) and not any(s.clearance for s in point.subgoals)
    own = {i for i, c in enumerate(point.candidates) if (c.action, sorted(c.arguments)) == (point.failed.action, sorted(point.failed.arguments))}
    assert point.in_the_way == own
    assert {point.candidates[i].arguments for i in own} == {point.failed.arguments, point.failed.arguments[::-1]}
    ranking = rank_candidates(model, point, measure="goal-directed", seed=0)
    assert ranking.goal is not None and ranking.subgoals is not None and ranking.resolve is not None
    mask = np.isin(ranking.indices, sorted(own))
    direct = np.prod(ranking.goal, axis=1)
    assert ranking.blocked == pytest.approx(blocked_belief([float(direct[m].mean()) for m in attempted(point, ranking.indices) if m.any()]))
    trust = np.full(len(point.subgoals), SUBGOAL_TRUST)
    free = resolve_probability(ranking.goal, ranking.subgoals, trust)
    around = np.isin(ranking.indices, sorted(point.relocations))
    assert point.relocations and not point.relocations & own
    assert all(point.candidates[i].arguments[0] in point.failed.arguments for i in point.relocations)
    assert ranking.resolve[~mask & ~around] == pytest.approx(free[~mask & ~around])
    assert ranking.resolve[mask] == pytest.approx(resolve_probability(ranking.goal, ranking.subgoals, trust, stroke=ranking.blocked * mask)[mask])
    assert np.any(ranking.resolve[mask] < free[mask])
    way = ranking.blocked * SUBGOAL_TRUST * around
    assert ranking.resolve[around] == pytest.approx(resolve_probability(ranking.goal, ranking.subgoals, trust, around=way)[around])
    assert np.all(ranking.resolve[around] > free[around])
