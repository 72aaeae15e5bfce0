"""Every scenario tells its story in real physics: K's nominal plan works in the original
condition; in the novelty it fails and so does every plan repair, so that only creative
problem solving can reach the goal; and some candidate of the exploration space resolves
the novelty, though not the first one of the default order (so ranking matters)."""

from __future__ import annotations

from pathlib import Path

import pytest

from llcps.cps.episode import SolveConfig, solve
from llcps.cps.sweep import sweep
from llcps.scenarios import SCENARIOS, get_scenario
from llcps.store import Store

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
def test_sweep_finds_a_resolving_candidate_after_the_first(name: str) -> None:
    """Candidates from the state a_f was executed in, in the default order, until one resolves."""
    found = sweep(get_scenario(name), stop_at_first=True)
    assert found.failed_action is not None
    assert found.resolving, "no candidate resolves the novelty"
    assert found.first_position > 1, "the first candidate of the default order resolves the novelty: ranking would not matter"
    assert found.tried == found.first_position < found.candidates
