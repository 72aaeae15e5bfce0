"""The lifelong agent gets better and never worse, in real physics on a real store:
what it learns in a novelty solves the next novelty without exploring and does not break
the original condition. Operators are costed by experience, on branches."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from llcps.cps.candidates import candidate_space_size
from llcps.cps.episode import SolveConfig, solve
from llcps.domain import ControllerParams, fluent
from llcps.trial_records import TrialSpec
from llcps.cps.pretraining import pretrain
from llcps.scenarios import SCENARIOS
from llcps.store import Store
from llcps.cps.branch_knowledge import load_experience, load_knowledge
from llcps.symbolic.experience import Experience, experience_cost
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.task import Task
from llcps.symbolic.operators import learn_operator
from llcps.symbolic.planner import plan

PRETRAIN_TRIALS = 30
SEED = 3
BUDGET = candidate_space_size()  # the whole candidate space: a novelty that can be resolved is
NAMES = tuple(SCENARIOS)


def _config(name: str, condition: str = "novelty") -> SolveConfig:
    return SolveConfig(scenario=name, condition=condition, budget=BUDGET, seed=SEED)


@pytest.fixture(scope="module")
def pretrained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store whose main branch holds a small seeded pretraining set."""
    path = tmp_path_factory.mktemp("lifelong") / "lifelong.db"
    with Store.open(str(path), create=True) as store:
        pretrain(store, branch="main", n=PRETRAIN_TRIALS, seed=1)
    return path


class _Fresh:
    """Exploration trials of each scenario's novelty on a fresh branch at the pretraining
    point, solved when first asked for (``-k scenarioN`` solves that scenario alone); each
    such branch is kept (``fresh-<scenario>``) for the tests that go on from there."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.explored: dict[str, int] = {}

    def __getitem__(self, name: str) -> int:
        if name not in self.explored:
            with Store.open(str(self.path)) as store:
                store.create_branch(f"fresh-{name}", from_branch="main", at="pretrain")
                result = solve(store, branch=f"fresh-{name}", config=_config(name))
            assert result.status == "solved", result.as_json()
            assert result.candidates == candidate_space_size(name)  # the agent's space is the one the budget names
            self.explored[name] = result.exploration_trials
        return self.explored[name]


@pytest.fixture(scope="module")
def fresh(pretrained: Path) -> _Fresh:
    """See :class:`_Fresh`."""
    return _Fresh(pretrained)


#: A known limit, not a defect of the code: scenario13's novelty (a sticky table) leaves
#: every fact as it is in the original condition. The lesson learned in the novelty is
#: planned in the original, fails there, is blamed, and K's own push reaches the goal (0
#: trials). That push is then counted a success in the very context where it failed in the
#: novelty, so the next novelty plans it first; it fails, and from where it left the puck
#: no repair plans: with this test's seeds that novelty needs 1 exploration trial. Strict:
#: the mark goes once the agent can tell.
REUSE_AFTER_ORIGINAL = "a novelty no fact tells from the original: K's step that worked in the original is tried in the novelty (1 trial)"
#: (scenario5, whose novelty no fact shows either, passes in the default ordering: its
#: lesson holds in both conditions. In the ranked ordering, with these seeds, a fast stroke
#: from the top resolved it, which in the original throws the light crate out of reach.)
_REUSE_CASES = [
    pytest.param(name, marks=pytest.mark.xfail(strict=True, raises=AssertionError, reason=REUSE_AFTER_ORIGINAL))
    if name == "scenario13"
    else name
    for name in NAMES
]


@pytest.mark.slow
@pytest.mark.parametrize("name", _REUSE_CASES)
def test_novelty_then_original_then_novelty(pretrained: Path, fresh: _Fresh, name: str) -> None:
    assert fresh[name] > 0, "the novelty needed no exploration: nothing to learn"
    with Store.open(str(pretrained)) as store:
        branch = f"fresh-{name}"
        learned = store.visible_operators(branch)
        assert learned, "resolving the novelty taught no operator"
        original = solve(store, branch=branch, config=_config(name, "original"))
        assert original.status == "solved" and original.exploration_trials == 0, original.as_json()
        again = solve(store, branch=branch, config=_config(name))
        assert again.status == "solved" and again.exploration_trials == 0, again.as_json()
        names = {record.name for record in learned}
        assert any(step[1:].split()[0] in names for step in again.plan + [r for p in again.plan_repairs for r in p["plan"]])


# ----------------------------------------------------------------- costs by experience


def test_experience_cost_is_nominal_over_the_smoothed_success_rate() -> None:
    assert experience_cost(2.0, 0, 0) == 2.0  # never executed: the nominal cost
    assert experience_cost(2.0, 1, 0) == 1.5
    assert experience_cost(1.0, 0, 1) == 1.5
    assert experience_cost(1.0, 0, 4) == 3.0
    assert experience_cost(1.0, 98, 0) == pytest.approx(100 / 198)
    with pytest.raises(ValueError):
        experience_cost(1.0, -1, 0)


OBJECTS = {"cube": "item", "bucket": "container"}
BEFORE = frozenset({fluent("visible", "cube"), fluent("reachable", "cube"), fluent("on", "cube", "table")})
GOAL = frozenset({fluent("in", "cube", "bucket")})


def _learned():
    spec = TrialSpec("place_in_container", ("cube", "bucket"), ControllerParams(1.0, 0.3, "left"))
    after = (BEFORE - {fluent("on", "cube", "table")}) | GOAL
    return learn_operator(spec=spec, before=BEFORE, after=after, objects=OBJECTS)


def _first_step(kb: KnowledgeBase) -> str:
    steps = plan(kb, Task(objects=OBJECTS, init=BEFORE, goal_pos=GOAL))
    assert steps
    return steps[0].name


ROOM = {"can": "item", "block": "item", "bin": "container"}
#: The bin out of reach, the can and a bystander block alike in every fact.
OUT_OF_REACH = frozenset(
    {fluent(p, o) for o in ("can", "block") for p in ("visible", "reachable")}
    | {fluent("on", o, "table") for o in ("can", "block", "bin")}
    | {fluent("touching", o, "table") for o in ("can", "block", "bin")}
    | {fluent("visible", "bin")}
)
IN_BIN = frozenset({fluent("in", "can", "bin")})


def _reach_first() -> tuple[KnowledgeBase, object]:
    """K' with a push that brings the bin within reach, learned on (bin, can), and the
    experience of K's placement failing out of reach and working within it."""
    spec = TrialSpec("push_together", ("bin", "can"), ControllerParams(0.1, 0.3, "front"))
    within = OUT_OF_REACH | {fluent("reachable", "bin")}
    learned = learn_operator(spec=spec, before=OUT_OF_REACH, after=within, objects=ROOM, replaces="place_in_container")
    kb = KnowledgeBase.default().with_operator(learned)
    (place,) = plan(KnowledgeBase.default(), Task(objects=ROOM, init=within, goal_pos=IN_BIN))
    experience = Experience.of([(place.name, kb.context(place, OUT_OF_REACH), False), (place.name, kb.context(place, within), True)])
    return kb.with_experience(experience), learned


def test_of_equally_cheap_plans_the_planner_acts_on_the_goals_objects() -> None:
    """The learned push binds the can (the goal's object) rather than the block, which no
    fact tells from it and which comes first by name."""
    kb, learned = _reach_first()
    steps = plan(kb, Task(objects=ROOM, init=OUT_OF_REACH, goal_pos=IN_BIN))
    assert [(s.name, s.args) for s in steps] == [(learned.name, ("bin", "can")), ("place_in_container", ("can", "bin"))]


def test_a_learned_step_is_monitored_for_the_context_it_gives_the_next_step() -> None:
    """A learned operator is planned for the facts it makes about the next step's arguments
    (the bin within reach for the placement), even where no precondition names them: the
    monitor checks them, so K' bound wrongly fails at its own step."""
    from llcps.cps.plan_execution import _relied_on

    kb, learned = _reach_first()
    push, place = plan(kb, Task(objects=ROOM, init=OUT_OF_REACH, goal_pos=IN_BIN))
    scenario = SCENARIOS["scenario7"]
    assert fluent("reachable", "bin") in _relied_on(push, [place], scenario, learned=True).add
    assert fluent("reachable", "bin") not in _relied_on(push, [place], scenario).add


class _Facts:
    """A world of facts alone, for the plan logic: ``outcome(step, state)`` is the state a
    step leaves; a snapshot's physics is its state's repr. Stands in for the executor."""

    def __init__(self, state: frozenset, outcome) -> None:  # noqa: ANN001
        self.state, self.outcome = state, outcome
        self.scenario = type("Goal", (), {"goal_pos": IN_BIN, "goal_neg": frozenset(), "goal_reached": staticmethod(IN_BIN.issubset)})()
        self.snapshots: list[frozenset] = []
        self.resumed: list[frozenset] = []

    def report(self, *_: object, **__: object) -> None:
        pass

    def task(self, state: frozenset) -> Task:
        return Task(objects=ROOM, init=state, goal_pos=IN_BIN)

    def perceive(self) -> frozenset:
        return self.state

    def controller_call(self, step: object) -> object:
        return step

    def snapshot(self) -> int:
        self.snapshots.append(self.state)
        return len(self.snapshots)

    def snapshot_state(self, snapshot: int) -> bytes:
        return repr(sorted(self.snapshots[snapshot - 1])).encode()

    def restore(self, snapshot: int) -> None:
        self.state = self.snapshots[snapshot - 1]

    def resume(self, physics: bytes) -> None:
        (self.state,) = {s for s in self.snapshots if repr(sorted(s)).encode() == physics}
        self.resumed.append(self.state)

    def execute(self, step, *, source: str, snapshot_id: int | None):  # noqa: ANN001, ANN201
        before, self.state = self.state, self.outcome(step, self.state)
        return type("Trial", (), {"before": before, "after": self.state})(), None


def test_a_step_failing_after_a_learned_step_blames_it_and_a_f_is_where_it_started(sqlite_store: Store) -> None:
    """The learned push works by its facts (the bin within reach) but the placement after
    it fails (here: always, as where the push left the can out of reach in truth). The
    push is counted failed, the world returns to where it started, K alone plans there,
    and its placement's failure is a_f: exploration starts where the reset agent's would,
    not from the state the misleading push left."""
    from llcps.cps.branch_knowledge import BranchExperience
    from llcps.cps.plan_execution import PlanLog, plan_and_repair

    kb, learned = _reach_first()
    within = OUT_OF_REACH | {fluent("reachable", "bin")}
    world = _Facts(OUT_OF_REACH, lambda step, state: within if step.name == learned.name else state)
    experience = BranchExperience(sqlite_store, "main", experience=kb.experience)
    log = PlanLog()
    failure = plan_and_repair(world, experience, kb.with_experience(Experience()), OUT_OF_REACH, log)  # type: ignore[arg-type]
    assert log.plan == [f"({learned.name} bin can)", "(place_in_container can bin)"]
    assert world.resumed == [OUT_OF_REACH]
    assert log.repairs[0]["plan"] == ["(place_in_container can bin)"]
    assert failure is not None and failure.step.name == "place_in_container" and failure.blamed is None
    assert failure.state == OUT_OF_REACH and log.failed_action == "(place_in_container can bin)"
    push_context = kb.context(plan(kb, Task(objects=ROOM, init=OUT_OF_REACH, goal_pos=IN_BIN))[0], OUT_OF_REACH)
    assert experience.experience.counts(learned.name, push_context) == (0, 1)


def test_a_learned_step_that_fails_is_repaired_with_k_alone(sqlite_store: Store) -> None:
    """K' planned where no fact tells the scene from the one it was learned in: the learned
    push fails at its own effects; the repair returns to where it started and K's own
    placement, which experience had made dear there, reaches the goal."""
    from llcps.cps.branch_knowledge import BranchExperience
    from llcps.cps.plan_execution import PlanLog, plan_and_repair

    kb, learned = _reach_first()
    world = _Facts(OUT_OF_REACH, lambda step, state: state | IN_BIN if step.name == "place_in_container" else state - {fluent("visible", "can")})
    experience = BranchExperience(sqlite_store, "main", experience=kb.experience)
    log = PlanLog()
    assert plan_and_repair(world, experience, kb, OUT_OF_REACH, log) is not None  # type: ignore[arg-type]
    assert log.solved and world.resumed == [OUT_OF_REACH]
    assert log.repairs == [{"plan": ["(place_in_container can bin)"], "rewound": True, "failed_action": None, "missing_effects": None}]
    assert log.failed_action == f"({learned.name} bin can)"


def test_a_first_plan_experience_turned_aside_that_fails_is_rewound_and_k_alone_plans(sqlite_store: Store) -> None:
    """Experience made K's placement dear where it failed in look-alike scenes, so K' plans
    a push of the bin first; here the push leaves the bin where the placement fails, while
    the placement alone works from the start (an original scene). The detour fails, the
    world returns to the start, and K alone's plan reaches the goal, as for a reset agent.
    Where K alone's plan fails too, its failure is a_f, not the detour's."""
    from llcps.cps.branch_knowledge import BranchExperience
    from llcps.cps.plan_execution import PlanLog, plan_and_repair

    kb = KnowledgeBase.default()
    start = OUT_OF_REACH | {fluent("reachable", "bin")}
    touching = start | {fluent("touching", "bin", "can"), fluent("touching", "can", "bin")}
    (place,) = plan(kb, Task(objects=ROOM, init=start, goal_pos=IN_BIN))
    dear = Experience.of([(place.name, kb.context(place, start), False)] * 3 + [(place.name, kb.context(place, touching), True)])
    detour = plan(kb.with_experience(dear), Task(objects=ROOM, init=start, goal_pos=IN_BIN))
    assert detour is not None and [s.name for s in detour] == ["push_together", "place_in_container"]

    def original(step, state):  # noqa: ANN001, ANN202
        if step.name == "place_in_container":
            return state | IN_BIN if state == start else state
        return touching

    world = _Facts(start, original)
    experience = BranchExperience(sqlite_store, "main", experience=dear)
    log = PlanLog()
    plan_and_repair(world, experience, kb.with_experience(dear), start, log)  # type: ignore[arg-type]
    assert log.plan == [s.label for s in detour] and world.resumed == [start]
    assert log.solved and log.repairs == [{"plan": [place.label], "rewound": True, "failed_action": None, "missing_effects": None}]

    novelty = _Facts(start, lambda step, state: touching if step.name != "place_in_container" else state)
    log = PlanLog()
    failure = plan_and_repair(novelty, BranchExperience(sqlite_store, "main", experience=dear), kb.with_experience(dear), start, log)  # type: ignore[arg-type]
    assert not log.solved and novelty.resumed[0] == start
    assert failure is not None and failure.step.label == place.label and failure.state == start
    assert log.failed_action == place.label and log.repairs[0]["rewound"] is True


def test_a_detour_of_learned_steps_blamed_midway_goes_back_to_its_start(sqlite_store: Store) -> None:
    """K' plans two learned steps before the placement: the first works by its facts
    (the can pushed against the bin), the second fails at its own step and is blamed.
    The world goes back to where the detour started, not to where the blamed step did:
    the step before it left the can where K's placement fails, while from the start K
    alone's placement reaches the goal (an original scene after a life)."""
    from llcps.cps.branch_knowledge import BranchExperience
    from llcps.cps.plan_execution import PlanLog, plan_and_repair

    start = OUT_OF_REACH | {fluent("reachable", "bin")}
    pushed = start | {fluent("touching", "can", "bin"), fluent("touching", "bin", "can")}
    ready = pushed - {fluent("on", "can", "table")}
    first = learn_operator(
        spec=TrialSpec("push", ("can",), ControllerParams(0.1, 0.3, "left")), before=start, after=pushed, objects=ROOM, replaces="place_in_container"
    )
    second = learn_operator(
        spec=TrialSpec("push_together", ("can", "bin"), ControllerParams(1.0, 0.05, "left")), before=pushed, after=ready, objects=ROOM,
        replaces="place_in_container",
    )
    kb = KnowledgeBase.default().with_operator(first).with_operator(second)
    (place,) = plan(KnowledgeBase.default(), Task(objects=ROOM, init=start, goal_pos=IN_BIN))
    placing = [(place.name, kb.context(place, state), False) for state in (start, pushed) for _ in range(4)]
    placing += [(place.name, kb.context(place, ready), True)] * 3  # it worked where the second push left the can
    push = plan(kb.with_experience(Experience.of(placing)), Task(objects=ROOM, init=start, goal_pos=IN_BIN))[0]
    assert push.name == "push_together"  # K's own push makes the first push's facts too; it failed here
    dear = Experience.of(placing + [(push.name, kb.context(push, start), False)] * 4)
    detour = plan(kb.with_experience(dear), Task(objects=ROOM, init=start, goal_pos=IN_BIN))
    assert detour is not None and [s.name for s in detour] == [first.name, second.name, place.name]

    def original(step, state):  # noqa: ANN001, ANN202
        if step.name == place.name:
            return state | IN_BIN if state == start else state
        return pushed if step.name == first.name else state  # the second push moves nothing

    world = _Facts(start, original)
    log = PlanLog()
    plan_and_repair(world, BranchExperience(sqlite_store, "main", experience=dear), kb.with_experience(dear), start, log)  # type: ignore[arg-type]
    assert log.plan == [s.label for s in detour] and world.resumed == [start]
    assert log.solved and log.repairs == [{"plan": [place.label], "rewound": True, "failed_action": None, "missing_effects": None}]


def test_after_a_trial_k_alone_plans_where_the_re_plan_experience_turned_aside_fails(sqlite_store: Store) -> None:
    """A trial moved the bin; experience from look-alike scenes made the placement dear in
    the context it left, so K' re-plans a push first, which fails. K alone's placement
    works from there: the trial resolves the novelty, as it would for a reset agent."""
    from llcps.cps.branch_knowledge import BranchExperience
    from llcps.cps.plan_execution import resolves

    kb = KnowledgeBase.default()
    start = OUT_OF_REACH | {fluent("reachable", "bin")}
    moved = start | {fluent("touching", "bin", "block"), fluent("touching", "block", "bin")}
    (place,) = plan(kb, Task(objects=ROOM, init=start, goal_pos=IN_BIN))
    touching = moved | {fluent("touching", "bin", "can"), fluent("touching", "can", "bin")}
    dear = Experience.of([(place.name, kb.context(place, moved), False)] * 3 + [(place.name, kb.context(place, touching), True)])
    world = _Facts(moved, lambda step, state: state | IN_BIN if step.name == "place_in_container" and state == moved else (state if step.name == "place_in_container" else touching))
    trial = type("Trial", (), {"after": moved})()
    failure = type("Failure", (), {"step": place, "state": start})()
    assert resolves(world, BranchExperience(sqlite_store, "main", experience=dear), kb.with_experience(dear), trial, failure)  # type: ignore[arg-type]
    assert world.state == moved | IN_BIN


def test_a_failed_learned_operator_is_demoted_and_forks_keep_their_counts(store: Store, new_trial) -> None:  # noqa: ANN001
    learned = _learned()
    kb = KnowledgeBase.default().with_operator(learned)
    (place,) = plan(KnowledgeBase.default(), Task(objects=OBJECTS, init=BEFORE, goal_pos=GOAL))

    def execute(operator: str, success: bool) -> None:
        trial_id = store.add_trial(new_trial(len(store.visible_trials("main")), source="plan"))
        context = sorted(kb.context(place, BEFORE)) if operator == place.name else sorted(learned.preconditions)
        store.add_operator_execution(branch="main", operator=operator, success=success, context=context, trial_id=trial_id)

    execute("place_in_container", True)  # K's place worked once
    execute(learned.name, True)
    execute(learned.name, True)  # the learned one twice
    costed = kb.with_experience(load_experience(store, "main"))
    assert costed.cost(learned.name) < costed.cost("place_in_container")
    assert _first_step(costed) == learned.name
    store.create_branch("before-failure", from_branch="main")

    execute(learned.name, False)
    execute(learned.name, False)
    demoted = kb.with_experience(load_experience(store, "main"))
    assert demoted.cost(learned.name) > costed.cost(learned.name)
    assert demoted.counts(learned.name) == (2, 2)
    assert _first_step(demoted) == "place_in_container"
    assert learned.name in {op.name for op in demoted.learned}  # demoted, not deleted

    kept = load_experience(store, "before-failure")
    assert kept.counts(learned.name) == (2, 0) and kept.counts("place_in_container") == (1, 0)
    assert _first_step(kb.with_experience(kept)) == learned.name


def test_a_step_is_costed_by_its_experience_in_the_same_context() -> None:
    (push,) = plan(KnowledgeBase.default(), Task(objects=OBJECTS, init=BEFORE | {fluent("near", "cube", "bucket")}, goal_pos=GOAL))
    assert push.name == "push"
    kb = KnowledgeBase.default()
    here = BEFORE | {fluent("near", "cube", "bucket")}
    there = here | {fluent("visible", "bucket")}
    experience = Experience.of([("push", kb.context(push, here), True)] * 2 + [("push", kb.context(push, there), False)] * 3)
    costed = kb.with_experience(experience)
    assert costed.step_cost(push, here) == experience_cost(1.0, 2, 0)  # it worked here
    assert costed.step_cost(push, there) == experience_cost(1.0, 0, 3)  # it failed there
    elsewhere = here - {fluent("reachable", "cube")}
    assert costed.step_cost(push, elsewhere) == experience_cost(1.0, 2, 3)  # never here: all it knows
    # where push failed, the planner takes the dearer place; where it worked, push
    assert plan(costed, Task(objects=OBJECTS, init=there, goal_pos=GOAL))[0].name == "place_in_container"
    assert plan(costed, Task(objects=OBJECTS, init=here, goal_pos=GOAL))[0].name == "push"


def test_a_learned_operator_applies_only_where_its_arguments_stand_as_they_stood() -> None:
    learned = _learned()
    kb = KnowledgeBase.default().with_operator(learned)
    kb = kb.with_experience(Experience.of([(learned.name, frozenset(learned.preconditions), True)] * 5))
    assert _first_step(kb) == learned.name
    elsewhere = BEFORE - {fluent("reachable", "cube")}  # the cube stands differently: not observed
    steps = plan(kb, Task(objects=OBJECTS, init=elsewhere, goal_pos=GOAL))
    assert steps and steps[0].name == "place_in_container"
    # the same skill seen to work there too generalizes the operator to both contexts
    spec = TrialSpec("place_in_container", ("cube", "bucket"), ControllerParams(1.0, 0.3, "left"))
    after = (elsewhere - {fluent("on", "cube", "table")}) | GOAL
    wider = kb.with_operator(learn_operator(spec=spec, before=elsewhere, after=after, objects=OBJECTS))
    assert len(wider.learned) == 1
    assert plan(wider, Task(objects=OBJECTS, init=elsewhere, goal_pos=GOAL))[0].name == learned.name


def test_branch_knowledge_is_costed_by_its_experience(store: Store, new_trial) -> None:  # noqa: ANN001
    trial_id = store.add_trial(new_trial(0, source="plan"))
    store.add_operator_execution(branch="main", operator="push", success=False, context=[("visible", "?o")], trial_id=trial_id)
    kb = load_knowledge(store, "main")
    assert kb.counts("push") == (0, 1) and kb.cost("push") == 1.5
    assert store.operator_experience("main")[0].context == (("visible", "?o"),)


def test_where_experience_leaves_no_plan_the_agent_still_finds_a_f(sqlite_store: Store, new_trial) -> None:  # noqa: ANN001
    """A placement that failed in another task where the can stood as in scenario12's novelty
    (within sight, out of reach, like a can under a shelf) bans every plan there; K's own
    plan is then executed, and its failure is a_f, where exploration starts, rather than the
    episode ending with no plan (a life met this)."""
    from llcps.sim.perception import perceive
    from llcps.sim.world import SETTLE_STEPS, World

    scenario = SCENARIOS["scenario12"]
    with World.from_scene(scenario.scene("novelty")) as world:
        world.settle(max_steps=SETTLE_STEPS)
        state = perceive(world)
    kb = KnowledgeBase.default()
    objects = {"can": "item", "bin": "container", "block": "item"}
    (place,) = plan(kb, Task(objects=objects, init=state, goal_pos=scenario.goal_pos))
    trial_id = sqlite_store.add_trial(new_trial(0, source="plan"))
    context = sorted(kb.context(place, state))
    sqlite_store.add_operator_execution(branch="main", operator=place.name, success=False, context=context, trial_id=trial_id)
    result = solve(sqlite_store, branch="main", config=SolveConfig(scenario="scenario12", budget=0))
    assert result.status == "budget_exhausted", result.as_json()
    assert result.failed_action == "(place_in_container can bin)"


#: The shipped families whose novelty shows in the facts K perceives (the original and
#: the novel scene differ in some fact; checked below against perception). The others
#: change only physics K has no fact for (mass, friction, a weak grip): there a K' learned
#: in the novelty is planned in the original condition too, and the reverse.
SHOWN_IN_FACTS = ("scenario1", "scenario2", "scenario3", "scenario4", "scenario7", "scenario9", "scenario10", "scenario12")
#: Those families are lived in this many lives (every fourth one in each), so each life is
#: a test of its own that fits well inside the per-test timeout.
LIVES = 4


def _perceived(name: str, condition: str) -> frozenset:
    from llcps.sim.perception import perceive
    from llcps.sim.world import SETTLE_STEPS, World

    with World.from_scene(SCENARIOS[name].scene(condition)) as world:
        world.settle(max_steps=SETTLE_STEPS)
        return perceive(world)


@pytest.mark.slow
def test_the_families_shown_in_facts_are_those_whose_scenes_perceive_differently() -> None:
    shown = tuple(name for name in NAMES if _perceived(name, "original") != _perceived(name, "novelty"))
    assert shown == SHOWN_IN_FACTS


def _live(store: Store, branch: str, names: tuple[str, ...], seed: int) -> list[tuple[str, str, int]]:
    """Solve the novelty and the original condition of every family of ``names``, and two
    of them again, in a seeded order on one branch; (name, condition, exploration trials)
    of each episode, every one asserted solved."""
    episodes = [(name, condition) for name in names for condition in ("original", "novelty")]
    rng = np.random.default_rng(seed)
    episodes += [episodes[i] for i in rng.choice(len(episodes), size=2, replace=False)]
    order = [episodes[i] for i in rng.permutation(len(episodes))]
    store.create_branch(branch, from_branch="main", at="pretrain")
    lived = []
    for name, condition in order:
        result = solve(store, branch=branch, config=_config(name, condition))
        assert result.status == "solved", (name, condition, result.as_json())
        lived.append((name, condition, result.exploration_trials))
    return lived


@pytest.mark.slow
@pytest.mark.parametrize("life", range(LIVES))
def test_a_life_solves_every_episode_and_no_original_needs_exploration(pretrained: Path, life: int) -> None:
    """A life over a share of the families shown in facts (every ``LIVES``-th one),
    novelties and originals mixed with repeats: every episode is solved, and no original
    condition needs exploration, before or after K' learned operators for its novelty.

    Whether a life's novelty needs fewer trials than the same novelty on a fresh branch is
    not asserted episode by episode: the order depends on what the model learned from the
    life's other trials, and one episode may lose where others gain. The lives benchmark
    (``llcps life run``) compares lives with fresh branches over many lives instead.
    """
    with Store.open(str(pretrained)) as store:
        lived = _live(store, f"life-{life}", SHOWN_IN_FACTS[life::LIVES], seed=7 + life)
    assert all(trials == 0 for _, condition, trials in lived if condition == "original"), lived


@pytest.mark.slow
@pytest.mark.parametrize("names", [("scenario2", "scenario8"), ("scenario6", "scenario12")])
def test_a_life_with_a_novelty_no_fact_shows(pretrained: Path, names: tuple[str, str]) -> None:
    """What a novelty no fact shows teaches holds in its original condition too, and must
    not cost the original exploration. scenario8's lesson (an icy table) fails in the
    original, is blamed, and K's own push reaches the goal (before the blame: 3 trials,
    and 3 again). scenario12's novelty (a short reach) makes K's placement dear in a
    context its original has too: K' pushes first, the placement after the push fails,
    the world returns to the start and K alone's placement works (before: 2 trials)."""
    with Store.open(str(pretrained)) as store:
        lived = _live(store, "life-" + "-".join(names), names, seed=8 if "scenario8" in names else 12)
    assert all(trials == 0 for _, condition, trials in lived if condition == "original"), lived


