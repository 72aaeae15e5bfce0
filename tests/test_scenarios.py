"""Every scenario tells its story in real physics: K's nominal plan works in the original
condition; in the novelty it fails and so does every plan repair, so that only creative
problem solving can reach the goal; and some candidate of the exploration space resolves
the novelty, though not the first one of the default order (so ranking matters)."""

from __future__ import annotations

from pathlib import Path

import pytest

from llcps.cps.agent import Agent, solve
from llcps.cps.candidates import enumerate_candidates
from llcps.cps.episode import SolveConfig, SolveResult
from llcps.scenarios import SCENARIOS, get_scenario
from llcps.sim.perception import perceive
from llcps.sim.world import World
from llcps.store import Store
from llcps.symbolic.knowledge import KnowledgeBase
from llcps.symbolic.planner import plan

SCENARIO_NAMES = tuple(SCENARIOS)


def test_aliases_resolve_to_the_same_scenario() -> None:
    for scenario in SCENARIOS.values():
        assert get_scenario(scenario.alias) is scenario


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_original_condition_plan_succeeds(tmp_path: Path, name: str) -> None:
    with Store.open(str(tmp_path / "o.db"), create=True) as store:
        result = solve(store, branch=None, config=SolveConfig(scenario=name, condition="original", budget=0))
    assert result.status == "solved", result.as_json()
    assert result.exploration_trials == 0 and result.plan_repairs == [] and result.failed_action is None
    assert result.plan_trials == len(result.plan) >= 1


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_novelty_defeats_the_plan_and_every_plan_repair(tmp_path: Path, name: str) -> None:
    with Store.open(str(tmp_path / "n.db"), create=True) as store:
        result = solve(store, branch=None, config=SolveConfig(scenario=name, budget=0))
        executions = store.operator_experience("main")
    assert result.status == "budget_exhausted", result.as_json()
    assert result.failed_action is not None and result.failed_action in result.plan
    assert "missing" in result.missing_effects or "still" in result.missing_effects
    # every repaired plan that was tried failed in physics, each at a step of its own
    assert all(repair["failed_action"] in repair["plan"] for repair in result.plan_repairs)
    failed = [result.failed_action] + [repair["failed_action"] for repair in result.plan_repairs]
    assert len(set(failed)) == len(failed)
    # each failed step was counted as a failure of its operator, and nothing as a success
    assert sum(c.failures for c in executions) == len(failed) and all(c.successes == 0 for c in executions)
    assert result.plan_trials == sum(len(repair["plan"]) for repair in result.plan_repairs) + len(result.plan)


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_sweep_finds_a_resolving_candidate_after_the_first(tmp_path: Path, name: str) -> None:
    """Candidates from the state a_f was executed in, in the default order, until one resolves."""
    store = Store.open(str(tmp_path / "s.db"), create=True)
    scenario = get_scenario(name)
    world = World.from_scene(scenario.scene("novelty"))
    world.settle(max_steps=480)
    config = SolveConfig(scenario=name)
    result = SolveResult(scenario=name, condition="novelty", model="-", measure="-", seed=0, branch="-")
    agent = Agent(store=store, branch="main", world=world, scenario=scenario, config=config, result=result, records=[])
    steps = plan(KnowledgeBase.default(), agent.task(perceive(world)))
    assert steps and len(steps) == 1, "the sweep assumes K's plan is a single step"
    start = world.snapshot()
    failure = agent.run_plan(steps, store=False).failure
    assert failure is not None
    candidates = enumerate_candidates(failed=agent.controller_call(failure.step), entities=agent.kinds)
    first = None
    for index, spec in enumerate(candidates):
        world.restore(start)
        trial, _ = agent.execute(spec, source="exploration", snapshot_id=None)
        if scenario.goal_reached(trial.after):
            first = index
            break
    world.close()
    store.close()
    assert first is not None, "no candidate resolves the novelty"
    assert first > 0, "the first candidate of the default order resolves the novelty: ranking would not matter"

