"""Every scenario tells its story in real physics: K's nominal plan works in the original
condition; in the novelty it fails and so does every plan repair, so that only creative
problem solving can reach the goal; and some candidate of the exploration space resolves
the novelty, though not the first one of the default order (so ranking matters).

The sweep up to the first resolving candidate is split into slices of the default order
(tests/fixtures/scenario_sweeps.py), a test each, so that no test comes near its timeout:
together the slices find that no candidate before the recorded position resolves and the
one at it does."""

from __future__ import annotations

from pathlib import Path

import pytest

from scenario_sweeps import FIRST_RESOLVING, slices

from llcps.cps import plan_execution
from llcps.cps.branch_knowledge import BranchExperience, load_knowledge
from llcps.cps.candidates import candidate_space_size, enumerate_candidates
from llcps.cps.episode import SolveConfig, solve
from llcps.cps.executor import TrialExecutor
from llcps.cps.plan_execution import PlanLog, plan_and_repair, resolves
from llcps.cps.sweep import sweep
from llcps.scenarios import SCENARIOS, get_scenario
from llcps.sim.perception import perceive
from llcps.sim.world import SETTLE_STEPS, World
from llcps.store import Store

SCENARIO_NAMES = tuple(SCENARIOS)
#: A held-out family (docs/scenarios.md): a board lies over the bin K places the can in.
LID = Path(__file__).parent.parent / "docs" / "heldout" / "lid.toml"
#: The 0-based position, in lid's default order at variant 0, of a stroke that slides
#: the board off the bin: push_together(board, bin) at 0.4 m/s, 0.3 m, from the right.
BOARD_OFF = 384
SLICES = [
    pytest.param(name, part, id=f"{name}-{part.start}:{part.stop}")
    for name in SCENARIO_NAMES
    for part in slices(FIRST_RESOLVING.get(name, 1))
]


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


def test_every_scenario_records_where_its_first_resolving_candidate_sits() -> None:
    missing = set(SCENARIO_NAMES) - set(FIRST_RESOLVING)
    assert not missing, f"record the first resolving position of {sorted(missing)} in tests/fixtures/scenario_sweeps.py"
    assert all(1 < first <= candidate_space_size(name) for name, first in FIRST_RESOLVING.items() if name in SCENARIOS)


def test_slices_cover_every_position_before_the_first_resolving_one_once() -> None:
    for first in (1, 59, 60, 61, 432):
        parts = slices(first)
        assert [i for part in parts for i in part] == list(range(first))
        assert max(len(part) for part in parts) <= 60


@pytest.mark.slow
@pytest.mark.parametrize(("name", "part"), SLICES)
def test_sweep_finds_a_resolving_candidate_after_the_first(name: str, part: range) -> None:
    """Candidates from the state a_f was executed in, one slice of the default order: none
    resolves before the recorded first resolving position, and the one at it does."""
    first = FIRST_RESOLVING.get(name)
    assert first is not None, f"record the first resolving position of {name} in tests/fixtures/scenario_sweeps.py"
    found = sweep(get_scenario(name), positions=part)
    assert found.failed_action is not None
    assert found.candidates == candidate_space_size(name) and found.tried == len(part)
    expected = [first - 1] if first - 1 in part else []
    assert found.resolving == expected, f"resolving positions (1-based) {[i + 1 for i in found.resolving]}, recorded first {first}"


def test_a_trial_s_re_plan_is_repaired_as_k_s_first_plan_is(monkeypatch: pytest.MonkeyPatch) -> None:
    """In the lid family K plans to push the can over into the bin, which fails in every
    layout, and repairs the plan with its placement, which the board defeats. Once a
    trial slides the board off, K plans the push again, and only the repair (the
    placement) reaches the goal: the trial resolves the novelty because the re-plan after
    it is repaired as K's first plan was."""
    scenario = get_scenario(str(LID))
    found = sweep(scenario, positions=[BOARD_OFF])
    assert found.failed_action == "(push can bin)"
    assert found.labels == ["push_together(board, bin) rate=0.4 magnitude=0.3 orientation=right"]
    monkeypatch.setattr(plan_execution, "MAX_PLAN_REPAIRS", 0)
    assert sweep(scenario, positions=[BOARD_OFF]).resolving == []


def test_a_repaired_re_plan_that_resolves_counts_the_step_it_left_out_and_its_own_steps(tmp_path: Path) -> None:
    """When the re-plan after a trial reaches the goal only through a repair, the step the
    repair left out counts as a failure of its operator there, and the plan that worked
    as successes: K learns that the push fails after the board is gone, and the placement works."""
    scenario = get_scenario(str(LID))
    config = SolveConfig(scenario=str(LID))
    with Store.open(str(tmp_path / "r.db"), create=True) as store:
        branch = store.current_branch()
        world = World.from_scene(scenario.scene("novelty", 0))
        try:
            world.settle(max_steps=SETTLE_STEPS)
            executor = TrialExecutor(store=store, branch=branch, world=world, scenario=scenario, seed=config.seed)
            experience = BranchExperience(store, branch)
            kb = load_knowledge(store, branch)
            failure = plan_and_repair(executor, experience, kb, perceive(world), PlanLog())
            assert failure is not None and failure.snapshot is not None

            def counts() -> dict[str, tuple[int, int]]:
                total: dict[str, tuple[int, int]] = {}
                for c in store.operator_experience(branch):
                    won, lost = total.get(c.operator, (0, 0))
                    total[c.operator] = (won + c.successes, lost + c.failures)
                return total

            assert counts() == {"push": (0, 1), "place_in_container": (0, 1)}  # K's plan and its repair
            spec = enumerate_candidates(
                failed=executor.controller_call(failure.step), entities=executor.kinds, grid=config.candidate_grid(scenario)
            )[BOARD_OFF]
            trial, _ = executor.execute(spec, source="exploration", snapshot_id=failure.snapshot, start=failure.snapshot)
            assert resolves(executor, experience, kb, trial, failure)
        finally:
            world.close()
        assert counts() == {"push": (0, 2), "place_in_container": (1, 1)}
