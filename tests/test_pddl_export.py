"""The PDDL export (``llcps inspect knowledge --pddl``) read by other tools: the `pddl`
library and unified-planning parse it, Fast Downward (another planner family: heuristic
search on a translated SAS+ task) solves it, and UP's validator accepts llcps's plans."""

from __future__ import annotations

import contextlib
import tempfile

import pytest
import unified_planning.shortcuts as up
from typer.testing import CliRunner
from unified_planning.engines import PlanGenerationResultStatus, ValidationResultStatus
from unified_planning.io import PDDLReader
from unified_planning.plans import ActionInstance, SequentialPlan

import llcps
from llcps.cli.main import app
from llcps.cps.scene_task import perceived_task
from llcps.domain import CONDITIONS, ControllerParams, fluent
from llcps.trial_records import TrialSpec
from llcps.errors import LlcpsError
from llcps.scenarios import SCENARIOS
from llcps.symbolic.experience import Experience
from llcps.symbolic.export import COST_SCALE, export_domain, export_problem, integer_cost
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.operators import learn_operator
from llcps.symbolic.pddl_text import parse_domain_text, parse_problem_text
from llcps.symbolic.planner import Plan, plan, plan_cost
from llcps.symbolic.task import Task

up.get_environment().credits_stream = None

OBJECTS = {"block": "item", "can": "item", "bin": "container"}
UNSOLVABLE = {PlanGenerationResultStatus.UNSOLVABLE_PROVEN, PlanGenerationResultStatus.UNSOLVABLE_INCOMPLETELY}


def _k_prime() -> KnowledgeBase:
    """K' with a push learned on (block bin can) that brings the can into the bin by pushing
    the block against it: (?o ?c ?o2) with ?o and ?o2 both items."""
    before = frozenset({fluent("visible", "block"), fluent("visible", "can"), fluent("near", "block", "can")})
    after = before | {fluent("in", "can", "bin")}
    spec = TrialSpec("push_together", ("block", "bin"), ControllerParams(0.1, 0.05, "left"))
    op = learn_operator(spec=spec, before=before, after=after, objects=OBJECTS, focus=("can",))
    assert [t for _, t in op.parameters].count("item") == 2
    return KnowledgeBase.default().with_operator(op)


def _task(init: frozenset = frozenset()) -> Task:
    start = init or frozenset({fluent("visible", "block"), fluent("visible", "can"), fluent("near", "block", "can")})
    return Task(OBJECTS, start, goal_pos=frozenset({fluent("in", "can", "bin")}), name="can-in-bin")


def _parse(domain: str, problem: str):
    return PDDLReader().parse_problem_string(domain, problem)


def _solve(problem, *, optimal: bool = True):
    # Fast Downward's translator writes output.sas into the working directory: one of its
    # own per call, or two test processes read each other's.
    with tempfile.TemporaryDirectory() as scratch, contextlib.chdir(scratch):
        with up.OneshotPlanner(name="fast-downward-opt" if optimal else "fast-downward") as planner:
            return planner.solve(problem)


def _validate(problem, steps: Plan | SequentialPlan):
    """UP's verdict on llcps's plan (or on a plan UP found)."""
    if not isinstance(steps, SequentialPlan):
        steps = SequentialPlan([ActionInstance(problem.action(s.name), [problem.object(a) for a in s.args]) for s in steps])
    with up.PlanValidator(name="sequential_plan_validator") as validator:
        return validator.validate(problem, steps)


def _metric(result) -> int:
    (value,) = result.metric_evaluations.values()
    return int(value)


def _without_comments(text: str) -> str:
    return "\n".join(line for line in text.splitlines() if not line.startswith(";"))


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("costs", ["integer", "none"])
def test_the_export_round_trips_through_the_pddl_library_and_unified_planning(costs: str) -> None:
    kb, task = _k_prime(), _task()
    domain, problem = export_domain(kb, costs=costs), export_problem(kb, task, costs=costs)
    assert str(parse_domain_text(domain)).strip() == _without_comments(domain).strip()
    assert str(parse_problem_text(problem)).strip() == _without_comments(problem).strip()
    parsed = _parse(domain, problem)
    assert sorted(a.name for a in parsed.actions) == sorted(op.name for op in kb.operators())
    assert sorted(o.name for o in parsed.all_objects) == sorted(task.all_objects(kb))
    assert ("ACTIONS_COST" in parsed.kind.features) == (costs == "integer")
    if costs == "none":
        assert "total-cost" not in domain and "total-cost" not in problem and ":metric" not in problem


def test_costs_are_scaled_to_integers_in_the_same_order() -> None:
    kb = _k_prime()
    learned = kb.learned[0].name
    kb = kb.with_experience(Experience.of([(learned, frozenset(), True), ("push", frozenset(), False)]))
    text = export_domain(kb)
    for op in kb.operators():
        assert f"(increase (total-cost) {integer_cost(op.cost)})" in text
    assert integer_cost(kb.cost(learned)) == round(0.75 * COST_SCALE) < integer_cost(kb.cost("push")) == 1500
    assert f"x {COST_SCALE}" in text


def test_an_unknown_cost_compilation_is_a_project_error() -> None:
    with pytest.raises(LlcpsError, match="cost compilation"):
        export_domain(KnowledgeBase.default(), costs="real")


# --------------------------------------------------------------------------- inequalities and bans


def test_the_learned_operator_binds_distinct_items_in_fast_downward_too() -> None:
    kb = _k_prime()
    (learned,) = kb.learned
    # Only the can is there to push against: (learned can bin can) is the one binding left.
    task = Task({"can": "item", "bin": "container"}, frozenset({fluent("visible", "can")}), goal_pos=frozenset({fluent("in", "can", "bin")}))
    forbidden = kb.with_experience(Experience.of([("place_in_container", frozenset({fluent("visible", "?o")}), False)]))
    assert plan(forbidden, task) is None
    assert f"(not (= ?{learned.variables[0][1:]} ?{learned.variables[2][1:]}))" in export_domain(kb)
    result = _solve(_parse(export_domain(forbidden), export_problem(forbidden, task)))
    assert result.status in UNSOLVABLE


def test_a_context_ban_keeps_fast_downward_out_of_that_context_only() -> None:
    kb = KnowledgeBase.default()
    task = Task({"cube": "item", "bucket": "container"}, frozenset({fluent("visible", "cube")}), goal_pos=frozenset({fluent("in", "cube", "bucket")}))
    banned_here = kb.with_experience(
        Experience.of([("place_in_container", frozenset({fluent("visible", "?o")}), False)])
    )
    banned_elsewhere = kb.with_experience(
        Experience.of([("place_in_container", frozenset({fluent("visible", "?o"), fluent("reachable", "?o")}), False)])
    )
    assert plan(banned_here, task) is None
    domain = export_domain(banned_here)
    assert ":disjunctive-preconditions" in domain and "(or " in domain
    assert _solve(_parse(domain, export_problem(banned_here, task))).status in UNSOLVABLE
    steps = plan(banned_elsewhere, task)
    assert steps is not None
    problem = _parse(export_domain(banned_elsewhere), export_problem(banned_elsewhere, task))
    assert _validate(problem, steps).status == ValidationResultStatus.VALID
    assert _solve(problem).plan is not None


def test_context_costs_pddl_cannot_carry_are_listed_in_a_comment() -> None:
    kb = KnowledgeBase.default()
    here, elsewhere = frozenset({fluent("visible", "?o")}), frozenset({fluent("reachable", "?o")})
    kb = kb.with_experience(Experience.of([("push", here, True), ("push", elsewhere, True), ("push", elsewhere, False)]))
    header = [line for line in export_domain(kb).splitlines() if line.startswith(";")]
    assert any("Not expressed" in line for line in header)
    assert ";   push in {(visible ?o)}: 750 (file: 833)" in header  # 1 x 5/6 over both contexts
    assert ";   push in {(reachable ?o)}: 1000 (file: 833)" in header


# --------------------------------------------------------------------------- every shipped scenario


@pytest.mark.slow
@pytest.mark.parametrize("condition", CONDITIONS)
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_fast_downward_solves_every_scenario_k_solves_and_validates_llcps_plan(name: str, condition: str) -> None:
    task = perceived_task(SCENARIOS[name], condition=condition)
    for kb in (KnowledgeBase.default(), _k_prime()):
        steps = plan(kb, task)
        problem = _parse(export_domain(kb), export_problem(kb, task))
        result = _solve(problem)
        if steps is None:
            assert result.status in UNSOLVABLE
            continue
        assert result.status == PlanGenerationResultStatus.SOLVED_OPTIMALLY
        verdict = _validate(problem, steps)
        assert verdict.status == ValidationResultStatus.VALID, verdict
        # Without experience every step costs its operator's cost: both plans are optimal.
        assert _metric(verdict) == integer_cost(plan_cost(steps)) == _metric(_validate(problem, result.plan))
        free = _parse(export_domain(kb, costs="none"), export_problem(kb, task, costs="none"))
        assert _solve(free, optimal=False).plan is not None


# --------------------------------------------------------------------------- the command


def test_inspect_knowledge_writes_the_domain_and_a_scenario_problem(tmp_path) -> None:
    runner = CliRunner()
    db = str(tmp_path / "k.db")
    assert runner.invoke(app, ["--db", db, "db", "init"]).exit_code == 0
    domain, problem = tmp_path / "domain.pddl", tmp_path / "problem.pddl"
    result = runner.invoke(app, ["--db", db, "inspect", "knowledge", "--pddl", "domain", "--out", str(domain)])
    assert result.exit_code == 0, result.output
    result = runner.invoke(
        app, ["--db", db, "inspect", "knowledge", "--pddl", "problem", "--scenario", "container", "--condition", "original", "--out", str(problem)]
    )
    assert result.exit_code == 0, result.output
    assert "(define (problem scenario2-original)" in problem.read_text()
    with llcps.open(db) as wb:
        assert wb.pddl("domain") == domain.read_text()
    parsed = PDDLReader().parse_problem(str(domain), str(problem))
    assert _solve(parsed).status == PlanGenerationResultStatus.SOLVED_OPTIMALLY


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--pddl", "problem"], "needs a scenario"),
        (["--out", "x.pddl"], "--out is an option of --pddl"),
        (["--pddl", "problem", "--scenario", "nope"], "nope"),
    ],
)
def test_bad_export_options_are_errors_that_change_nothing(tmp_path, args: list[str], message: str) -> None:
    db = tmp_path / "k.db"
    result = CliRunner().invoke(app, ["--db", str(db), "inspect", "knowledge", *args])
    assert result.exit_code == 2
    assert message in result.output
    assert not db.exists()
