"""Every scenario tells its story in real physics: the nominal plan from K works in
the original condition, fails in the novelty (the monitor names a_f), and some
candidate of the exploration space resolves the novelty, though not the first one
of the default order (so ranking matters)."""

from __future__ import annotations

import pytest

from llcps.cps.agent import Agent
from llcps.cps.candidates import enumerate_candidates
from llcps.cps.episode import SolveConfig, SolveResult
from llcps.scenarios import SCENARIOS, get_scenario
from llcps.sim.perception import perceive
from llcps.sim.world import World
from llcps.symbolic.knowledge import KnowledgeBase
from llcps.symbolic.planner import plan

SCENARIO_NAMES = tuple(SCENARIOS)

def _agent(name: str, condition: str) -> Agent:
    """An agent without a store: these tests record nothing."""
    scenario = get_scenario(name)
    world = World.from_scene(scenario.scene(condition))
    world.settle(max_steps=480)
    config = SolveConfig(scenario=name, condition=condition)
    result = SolveResult(scenario=name, condition=condition, model="nb", measure="goal-directed", seed=0, branch="-")
    return Agent(store=None, branch="-", world=world, scenario=scenario, config=config, result=result, records=[])  # type: ignore[arg-type]


def _nominal(name: str, condition: str):
    agent = _agent(name, condition)
    kb = KnowledgeBase.default()
    steps = plan(kb, agent.task(perceive(agent.world)))
    assert steps, f"K finds no plan for {name} ({condition})"
    state, failed, failure = agent.run_plan(kb, steps, store=False)
    return agent, kb, steps, state, failed, failure


def test_aliases_resolve_to_the_same_scenario() -> None:
    for scenario in SCENARIOS.values():
        assert get_scenario(scenario.alias) is scenario


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_original_condition_plan_succeeds(name: str) -> None:
    agent, _, _, state, failed, _ = _nominal(name, "original")
    assert failed is None
    assert agent.scenario.goal_reached(state)
    agent.world.close()


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_novelty_makes_the_plan_fail_and_the_monitor_names_the_action(name: str) -> None:
    agent, _, steps, state, failed, failure = _nominal(name, "novelty")
    assert failed is not None, "the novelty did not make the nominal plan fail"
    assert failed in steps
    assert failure.action == failed.name and failure.missing_add | failure.missing_del
    assert not agent.scenario.goal_reached(state)
    agent.world.close()


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_sweep_finds_a_resolving_candidate_after_the_first(name: str) -> None:
    from llcps.cps.agent import _resolves  # the agent's own definition of "resolves"

    agent, kb, _, failure_state, failed, _ = _nominal(name, "novelty")
    snapshot = agent.world.snapshot()
    candidates = enumerate_candidates(failed=agent.controller_call(failed), entities=agent.kinds)
    resolving = []
    for index, spec in enumerate(candidates):
        agent.world.restore(snapshot)
        trial, _ = agent.execute(spec, source="exploration", snapshot_id=None)
        if _resolves(agent, kb, trial, failed, failure_state, store=False)[0]:
            resolving.append(index)
    print(f"{name}: {len(candidates)} candidates, {len(resolving)} resolve, first at {resolving[:1]}")
    assert resolving, "no candidate resolves the novelty"
    assert resolving[0] > 0
    agent.world.close()
