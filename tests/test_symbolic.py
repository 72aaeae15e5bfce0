"""The knowledge base K, the planner, the independent validator, the monitor and K -> K'."""

from __future__ import annotations

import pytest
from pddl.parser.domain import DomainParser

from llcps.domain import ACTIONS, ControllerParams, fluent
from llcps.trial_records import TrialSpec
from llcps.errors import LlcpsError, UnknownNameError
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.pddl_domain import default_domain_pddl
from llcps.symbolic.task import Task
from llcps.symbolic.monitor import check_step
from llcps.symbolic.operators import (
    LearnedOperator,
    learn_operator,
    operator_name,
    parse_operator_name,
)
from llcps.symbolic.experience import Experience
from llcps.symbolic.planner import PlanningLimitError, plan, plan_cost
from llcps.symbolic.validate import validate

F = fluent
KB = KnowledgeBase.default()
PUSH_TRAY = TrialSpec("push", ("tray",), ControllerParams(rate=0.2, movement_magnitude=0.3, orientation="front"))


def replay(kb: KnowledgeBase, task: Task, steps) -> object:
    return validate(kb.to_pddl(), task.problem_pddl(kb), [(s.name, s.args) for s in steps])


def planned(kb: KnowledgeBase, task: Task) -> list[str]:
    steps = plan(kb, task)
    assert steps is not None
    verdict = replay(kb, task, steps)
    assert verdict.ok, verdict.reason
    assert verdict.cost == plan_cost(steps)
    return [s.label for s in steps]


# --------------------------------------------------------------------------- K


def test_default_domain_is_the_naive_k():
    assert sorted(op.name for op in KB.operators()) == sorted(ACTIONS)
    assert set(KB.predicates) == {"visible", "reachable", "touching", "on", "in", "holding", "near"}
    assert {op.name: op.cost for op in KB.operators()} == {
        "push": 1,
        "push_together": 1,
        "place_in_container": 2,
        "remove_from_container": 2,
    }
    assert KB.constants == {"table": "surface"}
    # Nothing in the naive K knows about reachability.
    assert not any(a[0] == "reachable" for op in KB.operators() for a in op.preconditions)
    push = KB.operator("push")
    assert (push.controller.action, push.controller.arguments, push.controller.toward) == ("push", ("?o",), "?c")


def test_domain_round_trips_through_pddl():
    text = KB.to_pddl()
    DomainParser()(text)  # the pddl library reads what we write
    assert KnowledgeBase.from_pddl(text) == KB


@pytest.mark.parametrize(
    "text, message",
    [
        ("(define (domain", "cannot read the PDDL domain"),
        (KB.to_pddl().replace("(:action push_together", "(:action shove"), "neither one of"),
    ],
)
def test_bad_domain_text_is_a_project_error(text, message):
    with pytest.raises(LlcpsError, match=message):
        KnowledgeBase.from_pddl(text)


# --------------------------------------------------------------------------- planning

CUBE_BUCKET = {"cube": "item", "bucket": "container"}


@pytest.mark.parametrize(
    "objects, init, goal_pos, goal_neg, expected",
    [
        pytest.param(
            CUBE_BUCKET,
            {F("visible", "cube"), F("near", "cube", "bucket"), F("on", "cube", "table")},
            {F("in", "cube", "bucket")},
            set(),
            ["(push cube bucket)"],
            id="near-pushes",
        ),
        pytest.param(
            CUBE_BUCKET,
            {F("visible", "cube"), F("on", "cube", "table")},
            {F("in", "cube", "bucket")},
            set(),
            ["(place_in_container cube bucket)"],
            id="not-near-places",
        ),
        pytest.param(
            {"ball": "item", "bin": "container", "table": "surface"},  # naming the constant is allowed
            {F("visible", "ball"), F("visible", "bin"), F("on", "ball", "table"), F("on", "bin", "table")},
            {F("in", "ball", "bin")},
            set(),
            ["(place_in_container ball bin)"],
            id="far-bin-places",
        ),
        pytest.param(
            {"cube": "item", "tray": "container"},
            {F("visible", "cube"), F("visible", "tray"), F("in", "cube", "tray"), F("on", "tray", "table")},
            set(),
            {F("in", "cube", "tray")},
            ["(remove_from_container cube tray)"],
            id="empty-tray-removes",
        ),
        pytest.param(
            CUBE_BUCKET,
            {F("visible", "cube"), F("visible", "bucket")},
            {F("touching", "bucket", "cube")},
            set(),
            ["(push_together bucket cube)"],
            id="touching-is-symmetric",
        ),
        pytest.param(
            CUBE_BUCKET,
            {F("visible", "cube"), F("in", "cube", "bucket")},
            {F("in", "cube", "bucket")},
            set(),
            [],
            id="goal-already-holds",
        ),
    ],
)
def test_planner_finds_the_cheapest_valid_plan(objects, init, goal_pos, goal_neg, expected):
    task = Task(objects, frozenset(init), frozenset(goal_pos), frozenset(goal_neg))
    assert planned(KB, task) == expected


def test_unreachable_goal_has_no_plan():
    task = Task(CUBE_BUCKET, frozenset({F("visible", "cube")}), goal_pos=frozenset({F("holding", "cube")}))
    assert plan(KB, task) is None


def test_push_together_never_binds_one_entity_twice():
    task = Task({"cube": "item"}, frozenset({F("visible", "cube")}), goal_pos=frozenset({F("touching", "cube", "cube")}))
    assert plan(KB, task) is None


def test_search_budget_is_reported_not_silent():
    task = Task(CUBE_BUCKET, frozenset({F("visible", "cube")}), goal_pos=frozenset({F("in", "cube", "bucket")}))
    with pytest.raises(PlanningLimitError):
        plan(KB, task, max_expansions=0)


def test_plan_steps_carry_their_controller_call():
    task = Task(
        CUBE_BUCKET,
        frozenset({F("visible", "cube"), F("near", "cube", "bucket")}),
        goal_pos=frozenset({F("in", "cube", "bucket")}),
    )
    (step,) = plan(KB, task)
    nominal = ControllerParams(rate=0.1, movement_magnitude=0.2, orientation="left")
    assert step.controller.spec(nominal) == TrialSpec("push", ("cube",), nominal)
    assert step.controller.toward == "bucket"


@pytest.mark.parametrize(
    "task, error",
    [
        (Task({"cube": "item"}, frozenset({F("visible", "ghost")})), LlcpsError),
        (Task({"cube": "item"}, frozenset({F("glowing", "cube")})), UnknownNameError),
        (Task({"cube": "gadget"}, frozenset()), LlcpsError),
        (Task({"cube.1": "item"}, frozenset()), LlcpsError),
        (Task({"cube": "item"}, frozenset({F("on", "cube")})), LlcpsError),
        (Task({"table": "item"}, frozenset()), LlcpsError),
    ],
    ids=["unknown-object", "unknown-predicate", "unknown-type", "bad-name", "wrong-arity", "retyped-constant"],
)
def test_tasks_that_do_not_fit_k_are_project_errors(task, error):
    with pytest.raises(error):
        plan(KB, task)


# --------------------------------------------------------------------------- validator

EMPTY_TRAY = Task(
    {"cube": "item", "tray": "container"},
    frozenset({F("visible", "cube"), F("in", "cube", "tray")}),
    goal_neg=frozenset({F("in", "cube", "tray")}),
)


@pytest.mark.parametrize(
    "steps, failing_step, reason",
    [
        ([("push", ("cube", "tray"))], 0, "precondition"),
        ([("remove_from_container", ("cube",))], 0, "takes 2"),
        ([("remove_from_container", ("cube", "bowl"))], 0, "unknown object"),
        ([("remove_from_container", ("tray", "cube"))], 0, "not a"),
        ([("juggle", ("cube",))], 0, "no action"),
        ([], None, "goal"),
        ([("remove_from_container", ("cube", "tray")), ("remove_from_container", ("cube", "tray"))], 1, "precondition"),
    ],
    ids=["inapplicable", "arity", "unknown-object", "wrong-type", "unknown-action", "goal-not-reached", "second-step"],
)
def test_validator_rejects_bad_plans(steps, failing_step, reason):
    verdict = validate(KB.to_pddl(), EMPTY_TRAY.problem_pddl(KB), steps)
    assert not verdict.ok
    assert verdict.failing_step == failing_step
    assert reason in verdict.reason


def test_validator_accepts_and_costs_a_good_plan():
    verdict = validate(KB.to_pddl(), EMPTY_TRAY.problem_pddl(KB), [("REMOVE_FROM_CONTAINER", ("Cube", "tray"))])
    assert verdict.ok and verdict.cost == 2


# --------------------------------------------------------------------------- monitor


def test_monitor_names_the_failed_action_and_its_missing_effects():
    (step,) = plan(KB, EMPTY_TRAY)
    assert check_step(step, step.apply(EMPTY_TRAY.init)) is None
    failure = check_step(step, EMPTY_TRAY.init)  # nothing changed: the removal failed
    assert failure is not None
    assert (failure.action, failure.arguments) == ("remove_from_container", ("cube", "tray"))
    assert failure.missing_add == {F("on", "cube", "table")}
    assert failure.missing_del == {F("in", "cube", "tray")}
    assert failure.describe() == "(remove_from_container cube tray) failed: missing (on cube table); still (in cube tray)"


# --------------------------------------------------------------------------- learned operators

TRAY_OBJECTS = {"cube": "item", "tray": "container", "ball": "item"}
#: The cube sits in a tray the arm cannot reach into; the ball is elsewhere.
FAILURE_STATE = frozenset(
    {
        F("visible", "cube"),
        F("visible", "tray"),
        F("visible", "ball"),
        F("in", "cube", "tray"),
        F("on", "tray", "table"),
        F("on", "ball", "table"),
        F("touching", "cube", "tray"),
        F("reachable", "ball"),
    }
)
#: Pushing the tray brought it and the cube within reach; the ball's visibility flickered.
AFTER_PUSH = (FAILURE_STATE | {F("reachable", "tray"), F("reachable", "cube")}) - {F("visible", "ball")}


def learned_push() -> LearnedOperator:
    return learn_operator(spec=PUSH_TRAY, before=FAILURE_STATE, after=AFTER_PUSH, objects=TRAY_OBJECTS)


def test_learned_operator_keeps_what_matters():
    op = learned_push()
    assert op.name == "push_front_r0p2_m0p3"
    assert op.parameters == (("?c", "container"), ("?o", "item"))  # the ball had nothing to do with it
    assert op.arguments == ("?c",) and op.source_arguments == ("tray", "cube")
    assert op.add == {F("reachable", "?c"), F("reachable", "?o")}
    assert op.delete == frozenset()
    assert F("in", "?o", "?c") in op.preconditions and F("on", "?c", "table") in op.preconditions
    assert not any("ball" in a for a in op.preconditions | op.negative_preconditions)
    # the context: what did not hold among the parameters holds no more where it applies
    assert {F("reachable", "?c"), F("reachable", "?o"), F("on", "?o", "table")} <= op.negative_preconditions
    assert not op.preconditions & op.negative_preconditions
    assert op.controller_spec(("bin", "ball")) == TrialSpec("push", ("bin",), PUSH_TRAY.params)
    assert op.controller_spec({"?c": "tray", "?o": "cube"}) == PUSH_TRAY


@pytest.mark.parametrize(
    "params",
    [
        ControllerParams(rate=0.2, movement_magnitude=0.3, orientation="front"),
        ControllerParams(rate=1.0, movement_magnitude=0.05, orientation="left"),
        ControllerParams(rate=0.125, movement_magnitude=0.0, orientation="top"),
    ],
)
@pytest.mark.parametrize("action", ACTIONS)
def test_operator_names_encode_controller_settings(action, params):
    name = operator_name(action, params)
    assert parse_operator_name(name) == (action, params, 1)
    assert parse_operator_name(operator_name(action, params, copy=3)) == (action, params, 3)
    assert parse_operator_name(action) is None


def test_learned_operator_round_trips_through_pddl_and_the_planner_prefers_it():
    op = learned_push()
    # The operator's own :action text, dropped into the naive domain, parses back into K'.
    naive = default_domain_pddl().rstrip()
    assert naive.endswith(")")
    text = naive[:-1] + op.to_pddl() + "\n)\n"
    kb = KnowledgeBase.from_pddl(text)
    assert kb == KnowledgeBase.from_pddl(KB.with_operator(op).to_pddl())
    (back,) = kb.learned
    assert back.same_knowledge(op) and back.source_arguments is None
    assert back.action == "push" and back.params == PUSH_TRAY.params and back.arguments == ("?c",)
    # Goal: the cube within reach. The learned push is the only way, and is used.
    task = Task(TRAY_OBJECTS, FAILURE_STATE, goal_pos=frozenset({F("reachable", "cube")}))
    assert plan(KB, task) is None
    assert planned(kb, task) == ["(push_front_r0p2_m0p3 tray cube)"]
    (step,) = plan(kb, task)
    assert step.controller.spec(ControllerParams(9.0, 9.0, "top")) == PUSH_TRAY


def test_planner_prefers_a_cheaper_learned_operator_over_a_domain_action():
    # A learned way of putting the cube in the bucket: cheaper than place_in_container (2).
    spec = TrialSpec("push_together", ("cube", "bucket"), ControllerParams(0.3, 0.2, "left"))
    before = frozenset({F("visible", "cube"), F("visible", "bucket"), F("on", "cube", "table")})
    after = (before | {F("in", "cube", "bucket")}) - {F("on", "cube", "table")}
    op = learn_operator(spec=spec, before=before, after=after, objects=CUBE_BUCKET)
    kb = KnowledgeBase.from_pddl(KB.with_operator(op).to_pddl())
    task = Task(CUBE_BUCKET, before, goal_pos=frozenset({F("in", "cube", "bucket")}))
    assert planned(KB, task) == ["(place_in_container cube bucket)"]
    assert planned(kb, task) == [f"({op.name} cube bucket)"]


def test_learned_operator_round_trips_through_json():
    op = learned_push()
    assert LearnedOperator.from_json(op.to_json()) == op
    with pytest.raises(LlcpsError):
        LearnedOperator.from_json({"name": "push_front_r0p2_m0p3"})


def test_adding_the_same_knowledge_twice_changes_nothing_and_clashes_are_renamed():
    op = learned_push()
    kb = KB.with_operator(op)
    assert kb.with_operator(op) is kb
    other = learn_operator(spec=PUSH_TRAY, before=FAILURE_STATE, after=FAILURE_STATE | {F("near", "cube", "tray")}, objects=TRAY_OBJECTS)
    kb2 = kb.with_operator(other)
    assert [o.name for o in kb2.learned] == ["push_front_r0p2_m0p3", "push_front_r0p2_m0p3_2"]
    assert KnowledgeBase.from_pddl(kb2.to_pddl()).learned[1].params == PUSH_TRAY.params


# --------------------------------------------------------------------------- where a_f failed


def test_a_step_is_not_planned_where_its_operator_failed_and_the_learned_way_is():
    """Where the removal failed (cube out of reach in the tray), the planner takes the learned
    push that brings both within reach and then the removal; elsewhere, the removal alone."""
    task = Task(TRAY_OBJECTS, FAILURE_STATE, goal_neg=frozenset({F("in", "cube", "tray")}))
    (failed,) = plan(KB, task)
    assert failed.name == "remove_from_container"
    assert check_step(failed, FAILURE_STATE) is not None  # it fails in the novelty

    kb = KB.with_operator(learned_push())
    kb = kb.with_experience(Experience.of([(failed.name, kb.context(failed, FAILURE_STATE), False)]))
    assert not kb.allowed(failed, FAILURE_STATE) and kb.allowed(failed, AFTER_PUSH)
    # predicted after the push, the removal's context contains the one it failed in: never
    # seen to work there, it stays out of the plan; only as a last resort (the agent's
    # first plan) is the failed step planned again, dearer
    assert not kb.allowed(failed, AFTER_PUSH, predicted=True) and plan(kb, task) is None
    assert [s.label for s in plan(kb, task, last_resort=True)] == ["(remove_from_container cube tray)"]
    # the removal that worked after the push (the re-plan that resolved the novelty) counts
    kb = kb.with_experience(kb.experience.added(failed.name, kb.context(failed, AFTER_PUSH), True))
    assert planned(kb, task) == ["(push_front_r0p2_m0p3 tray cube)", "(remove_from_container cube tray)"]
    reachable = Task(TRAY_OBJECTS, AFTER_PUSH, goal_neg=task.goal_neg)
    assert planned(kb, reachable) == ["(remove_from_container cube tray)"]
    # a success in the same context lifts the ban: the cost decides again
    worked = kb.with_experience(kb.experience.added(failed.name, kb.context(failed, FAILURE_STATE), True))
    assert worked.allowed(failed, FAILURE_STATE)
    # without a learned way around it, the ban does not leave K without a plan: the step that
    # failed is still planned (dearer), so the agent executes it, fails, and explores from there
    naive = KB.with_experience(Experience.of([(failed.name, KB.context(failed, FAILURE_STATE), False)]))
    assert not naive.allowed(failed, FAILURE_STATE)
    assert [s.label for s in plan(naive, task, last_resort=True)] == ["(remove_from_container cube tray)"]


CAN_BIN = {"can": "item", "bin": "container"}
#: A bin under a shelf: the can within reach, the bin not.
UNDER_SHELF = frozenset(
    {F("visible", "can"), F("visible", "bin"), F("reachable", "can"), F("on", "can", "table"), F("on", "bin", "table")}
)


def test_an_untried_step_that_only_adds_a_fact_does_not_reopen_the_failed_one():
    """The placement failed where the bin stood under a shelf; moving the bin out (the learned
    push_together) made it work. K's own push_together, never tried, would add only
    `touching` to the placement's context: the planner does not take it to try the placement
    again, however often placements worked elsewhere, and replays what worked."""
    goal = frozenset({F("in", "can", "bin")})
    task = Task(CAN_BIN, UNDER_SHELF, goal_pos=goal)
    (place,) = plan(KB, task)
    moved = UNDER_SHELF | {F("reachable", "bin")}
    spec = TrialSpec("push_together", ("bin", "can"), ControllerParams(0.1, 0.3, "front"))
    learned = learn_operator(spec=spec, before=UNDER_SHELF, after=moved, objects=CAN_BIN, replaces="place_in_container")
    kb = KB.with_operator(learned)
    elsewhere = frozenset({F("visible", "?o"), F("visible", "?c"), F("near", "?o", "?c")})
    kb = kb.with_experience(
        Experience.of(
            [(place.name, kb.context(place, UNDER_SHELF), False), (place.name, kb.context(place, moved), True), (learned.name, frozenset(learned.preconditions), True)]
            + [(place.name, elsewhere, True)] * 20
        )
    )
    touching = UNDER_SHELF | {F("touching", "bin", "can"), F("touching", "can", "bin")}
    assert kb.allowed(place, touching) and not kb.allowed(place, touching, predicted=True)
    assert planned(kb, task) == [f"({learned.name} bin can)", "(place_in_container can bin)"]


def test_stored_refinements_of_earlier_versions_still_load():
    stored = {
        "operator": learned_push().to_json(),
        "refinement": {"action": "remove_from_container", "preconditions": [["reachable", "?c"], ["reachable", "?o"]]},
    }
    kb = KB.apply_learned(stored)
    assert kb.operator("remove_from_container").preconditions == {F("in", "?o", "?c"), F("reachable", "?o"), F("reachable", "?c")}
    with pytest.raises(LlcpsError):
        KB.apply_learned({"operator": learned_push().to_json(), "refinement": {"action": "remove_from_container"}})


def test_a_tipping_trial_replaces_the_removal_where_the_removal_failed():
    # Tipping the tray spilled the cube onto the table: it does the removal's job another way.
    spec = TrialSpec("push", ("tray",), ControllerParams(0.5, 0.4, "top"))
    after = (FAILURE_STATE | {F("on", "cube", "table")}) - {F("in", "cube", "tray"), F("touching", "cube", "tray")}
    op = learn_operator(spec=spec, before=FAILURE_STATE, after=after, objects=TRAY_OBJECTS)
    task = Task(TRAY_OBJECTS, FAILURE_STATE, goal_neg=frozenset({F("in", "cube", "tray")}))
    (failed,) = plan(KB, task)
    kb = KB.with_operator(op)
    kb = kb.with_experience(Experience.of([(failed.name, kb.context(failed, FAILURE_STATE), False)]))
    assert kb.operator("remove_from_container").preconditions == KB.operator("remove_from_container").preconditions
    assert planned(kb, task) == [f"({op.name} tray cube)"]


def test_same_knowledge_compares_operators_with_different_parameters_without_error() -> None:
    """Two operators learned with the same settings but over different entities are different
    knowledge (regression: comparing them used to build an invalid operator and crash)."""
    from llcps.domain import ControllerParams, fluent
    from llcps.trial_records import TrialSpec
    from llcps.symbolic.operators import learn_operator

    spec = TrialSpec("place_in_container", ("cube", "bucket"), ControllerParams(1.0, 0.15, "right"))
    before = frozenset({fluent("visible", "cube"), fluent("near", "cube", "ball")})
    first = learn_operator(spec=spec, before=before, after=before | {fluent("in", "cube", "bucket")},
                           objects={"cube": "item", "bucket": "container", "ball": "item"})
    second = learn_operator(spec=spec, before=before, after=(before - {fluent("near", "cube", "ball")}) | {fluent("in", "cube", "bucket")},
                            objects={"cube": "item", "bucket": "container", "ball": "item"})
    assert first.parameters != second.parameters
    assert not first.same_knowledge(second) and not second.same_knowledge(first)
    assert first.same_knowledge(first)


# --------------------------------------------------------------------------- what K claims

CAN_BIN = {"can": "item", "block": "item", "bin": "container"}
FAST_FRONT = ControllerParams(1.0, 0.3, "front")


@pytest.mark.parametrize(
    "action, arguments, atom, add, claimed",
    [
        # push(?o) aimed at ?c adds (in ?o ?c): at any setting, for any container
        ("push", ("can",), F("in", "can", "bin"), True, True),
        ("push", ("block",), F("in", "can", "bin"), True, False),  # another object
        ("push", ("can",), F("in", "can", "bin"), False, False),  # the wrong sign
        ("push", ("bin",), F("in", "bin", "can"), True, False),  # ?o is an item, ?c a container
        ("place_in_container", ("can", "bin"), F("in", "can", "bin"), True, True),
        ("place_in_container", ("block", "bin"), F("in", "can", "bin"), True, False),
        ("push_together", ("can", "bin"), F("in", "can", "bin"), True, False),
        ("push_together", ("can", "block"), F("touching", "block", "can"), True, True),  # symmetric, read both ways
        ("remove_from_container", ("can", "bin"), F("in", "can", "bin"), False, True),
        ("remove_from_container", ("can", "bin"), F("on", "can", "table"), True, True),  # a constant in the effect
    ],
)
def test_k_claims_the_effects_of_its_actions_for_the_call_s_arguments(action, arguments, atom, add, claimed):
    call = TrialSpec(action, arguments, FAST_FRONT)
    assert KB.claims(call, atom, add=add, objects=CAN_BIN) is claimed


def test_a_learned_operator_claims_its_effects_only_at_its_own_settings():
    op = learned_push()  # push(tray) from the front at 0.2 m/s over 0.3 m made the cube reachable
    kb = KB.with_operator(op)
    atom = F("reachable", "cube")
    assert not KB.claims(PUSH_TRAY, atom, add=True, objects=TRAY_OBJECTS)
    assert kb.claims(PUSH_TRAY, atom, add=True, objects=TRAY_OBJECTS)
    other = TrialSpec("push", ("tray",), ControllerParams(1.0, 0.3, "front"))
    assert not kb.claims(other, atom, add=True, objects=TRAY_OBJECTS)
