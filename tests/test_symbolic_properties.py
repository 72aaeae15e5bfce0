"""Property: every plan the planner returns passes the independent validator."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from llcps.domain import ACTION_ARITY, ControllerParams, fluent
from llcps.trial_records import TrialSpec
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.task import Task
from llcps.symbolic.experience import Experience
from llcps.symbolic.operators import learn_operator
from llcps.symbolic.planner import ground, plan, plan_cost
from llcps.symbolic.validate import validate

OBJECTS = {"cube": "item", "ball": "item", "tray": "container", "bin": "container"}
EVERYTHING = [*OBJECTS, "table"]
ATOMS = sorted(
    {fluent(p, e) for p in ("visible", "reachable", "holding") for e in EVERYTHING}
    | {fluent(p, a, b) for p in ("touching", "near", "on", "in") for a, b in itertools.permutations(EVERYTHING, 2)}
)


def _k_prime() -> KnowledgeBase:
    """K expanded by a learned push of the tray that brings the cube in it within reach."""
    before = frozenset({fluent("visible", "tray"), fluent("in", "cube", "tray")})
    after = before | {fluent("reachable", "cube")}
    spec = TrialSpec("push", ("tray",), ControllerParams(0.2, 0.3, "front"))
    return KnowledgeBase.default().with_operator(learn_operator(spec=spec, before=before, after=after, objects=OBJECTS))


def _experienced() -> KnowledgeBase:
    """K' with experience: the removal failed where the cube was out of reach, the push worked."""
    kb = _k_prime()
    (learned,) = kb.learned
    remove = kb.operator("remove_from_container").ground(("cube", "tray"))
    assert remove is not None
    where = frozenset({fluent("in", "?o", "?c")})
    return kb.with_experience(
        Experience.of([("remove_from_container", where, False), (learned.name, learned.preconditions, True)])
    )


KNOWLEDGE = [KnowledgeBase.default(), _k_prime(), _experienced()]

#: Goal literals some operator can achieve, so that plans are more than empty.
ACHIEVABLE = sorted(
    {fluent("in", i, c) for i in ("cube", "ball") for c in ("tray", "bin")}
    | {fluent("on", i, "table") for i in ("cube", "ball")}
    | {fluent("touching", a, b) for a, b in itertools.combinations(OBJECTS, 2)}
    | {fluent("reachable", "cube")}
)


@st.composite
def tasks(draw: st.DrawFn) -> Task:
    objects = draw(st.sets(st.sampled_from(sorted(OBJECTS)), min_size=2))
    names = {*objects, "table"}

    def known(atoms: set) -> frozenset:
        return frozenset(a for a in atoms if set(a[1:]) <= names)

    hidden = draw(st.sets(st.sampled_from(sorted(objects)), max_size=1))
    visible = set(objects) - hidden
    init = known(draw(st.sets(st.sampled_from(ATOMS), max_size=10))) | {fluent("visible", o) for o in visible}
    achievable = sorted(known(set(ACHIEVABLE)))
    goal_pos = frozenset(draw(st.sets(st.sampled_from(achievable), min_size=1, max_size=3)))
    goal_neg = frozenset(draw(st.sets(st.sampled_from(achievable), max_size=1))) - goal_pos
    return Task({o: OBJECTS[o] for o in objects}, init, goal_pos, goal_neg)


# 27 tasks for each knowledge base, a test each: a planner search that exhausts an
# unsolvable task is slow, and 80 tasks in one test took a ninth of the timeout idle.
@pytest.mark.parametrize("which", range(len(KNOWLEDGE)), ids=["K", "K-prime", "K-prime-experienced"])
@settings(max_examples=27, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(task=tasks())
def test_every_plan_passes_the_validator(task: Task, which: int) -> None:
    kb = KNOWLEDGE[which]
    steps = plan(kb, task)
    if steps is None:
        return
    verdict = validate(kb.to_pddl(), task.problem_pddl(kb), [(s.name, s.args) for s in steps])
    assert verdict.ok, verdict.reason
    assert verdict.cost == plan_cost(steps)
    assert plan(kb, task) == steps  # deterministic


# --------------------------------------------------------------------------- binding

#: Entities a learned operator may be lifted from; two items, two containers and a surface,
#: so that parameters of one type (or of an ancestor and a descendant) are common.
LEARNING_OBJECTS = {"block": "item", "can": "item", "bin": "container", "tray": "container", "shelf": "surface"}
LEARNING_ATOMS = sorted(
    {fluent(p, e) for p in ("visible", "reachable") for e in LEARNING_OBJECTS}
    | {fluent(p, a, b) for p in ("touching", "near", "in", "on") for a, b in itertools.permutations(LEARNING_OBJECTS, 2)}
)


@st.composite
def learned_operators(draw: st.DrawFn) -> tuple[KnowledgeBase, str]:
    """K' with one operator learned from a random trial; and that operator's name."""
    action = draw(st.sampled_from(sorted(ACTION_ARITY)))
    arguments = draw(st.permutations(sorted(LEARNING_OBJECTS)))[: ACTION_ARITY[action]]
    before = frozenset(draw(st.sets(st.sampled_from(LEARNING_ATOMS), max_size=8)))
    changed = frozenset(draw(st.sets(st.sampled_from(LEARNING_ATOMS), min_size=1, max_size=4)))
    after = before ^ changed
    spec = TrialSpec(action, tuple(arguments), ControllerParams(0.2, 0.3, "left"))
    op = learn_operator(spec=spec, before=before, after=after, objects=LEARNING_OBJECTS)
    return KnowledgeBase.default().with_operator(op), op.name


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(learned=learned_operators())
def test_no_ground_learned_operator_binds_one_entity_to_two_distinct_parameters(learned: tuple[KnowledgeBase, str]) -> None:
    kb, name = learned
    (op,) = kb.learned
    assert op.source_arguments is not None and len(set(op.source_arguments)) == len(op.source_arguments)
    task = Task(dict(LEARNING_OBJECTS), frozenset())
    steps = [a for a in ground(kb, task) if a.name == name]
    assert steps, "the operator grounds at least where it was learned"
    assert tuple(op.source_arguments) in {a.args for a in steps}
    for step in steps:
        assert len(set(step.args)) == len(step.args), f"{step.label} binds one entity twice"
    # K' read back from its PDDL (which forgets source_arguments) binds the same way.
    again = KnowledgeBase.from_pddl(kb.to_pddl())
    assert {a.args for a in ground(again, task) if a.name == name} == {a.args for a in steps}


# --------------------------------------------------------------------------- experience


@st.composite
def failure_histories(draw: st.DrawFn) -> tuple[KnowledgeBase, Task]:
    """A task, and K' costed by a random history of plan steps that failed (mostly) or
    worked, each in the context of a random state over the task's objects: the history
    a branch has after episodes of other scenarios with entities of the same names."""
    task = draw(tasks())
    kb = KNOWLEDGE[draw(st.integers(0, 1))]
    steps = ground(kb, task)
    executions = []
    for _ in range(draw(st.integers(1, 12))):
        step = draw(st.sampled_from(steps))
        state = task.init if draw(st.booleans()) else frozenset(draw(st.sets(st.sampled_from(ATOMS), max_size=10)))
        executions.append((step.name, kb.context(step, state), draw(st.integers(0, 3)) == 0))
    return kb.with_experience(Experience.of(executions)), task


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(history=failure_histories())
def test_experience_never_removes_the_last_plan(history: tuple[KnowledgeBase, Task]) -> None:
    """Costing by experience orders plans and never leaves K without one it had: an agent
    whose K can solve the task has a plan, executes it, and explores where it fails."""
    costed, task = history
    naive = costed.with_experience(Experience())
    assert (plan(costed, task, last_resort=True) is None) == (plan(naive, task) is None)
