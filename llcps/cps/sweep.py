"""A sweep of a novelty's candidate space: which candidates resolve it, and where the
first of them sits in the default order.

It is the yardstick of a scenario (docs/scenarios.md): K's plan is executed and repaired
as an episode would, then every candidate of the exploration space is tried, in the
default order, from the state the failed step a_f was executed in, and judged by the
agent's own definition of a resolution. Everything runs in real physics and is recorded
in a throwaway in-memory store, so nothing reaches the experience store.

Every candidate starts from the same stored snapshot and a re-plan counts no operator
execution, so what a candidate gives does not depend on which candidates were tried
before it: a sweep of some positions of the default order (``positions``) finds for them
what the whole sweep finds. The test suite splits the sweeps into slices that way.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

from llcps.cps.branch_knowledge import BranchExperience, load_knowledge
from llcps.cps.candidates import enumerate_candidates
from llcps.cps.episode import SolveConfig
from llcps.cps.executor import TrialExecutor
from llcps.cps.plan_execution import PlanLog, plan_and_repair, resolves
from llcps.scenarios.base import Scenario
from llcps.sim.perception import perceive
from llcps.sim.world import SETTLE_STEPS, World
from llcps.store import Store


@dataclass
class Sweep:
    """What a sweep found.

    Attributes:
        scenario: the scenario's name.
        plan: K's first plan; ``plan_repairs`` the repairs tried, as in ``solve --json``.
        failed_action: the step a_f whose alternatives were swept (None: the plan worked).
        candidates: the size of the candidate space.
        tried: candidates executed (all of them unless the sweep stopped at the first, or
            swept only some positions).
        resolving: 0-based positions, in the default order, of the tried candidates that resolve.
        labels: the resolving candidates, as text.
    """

    scenario: str
    plan: list[str] = field(default_factory=list)
    plan_repairs: list[dict[str, object]] = field(default_factory=list)
    failed_action: str | None = None
    candidates: int = 0
    tried: int = 0
    resolving: list[int] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)

    @property
    def first_position(self) -> int | None:
        """1-based position in the default order of the first resolving candidate tried."""
        return self.resolving[0] + 1 if self.resolving else None

    def as_json(self) -> dict[str, object]:
        return {
            "scenario": self.scenario,
            "plan": self.plan,
            "plan_repairs": self.plan_repairs,
            "failed_action": self.failed_action,
            "candidates": self.candidates,
            "tried": self.tried,
            "resolving": len(self.resolving),
            "first_position": self.first_position,
            "resolving_candidates": self.labels,
        }


def sweep(
    scenario: Scenario,
    *,
    variant: int = 0,
    stop_at_first: bool = False,
    positions: Sequence[int] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Sweep:
    """Sweep ``scenario``'s novelty (see the module docstring).

    Args:
        scenario: the scenario (its novelty condition is swept).
        variant: the scene variant (0: the canonical scene).
        stop_at_first: stop at the first resolving candidate.
        positions: try only the candidates at these 0-based positions of the default order,
            in increasing order (None: every candidate).
        progress: called as ``progress(done, total)`` once the candidates are known (done 0)
            and after every candidate (total: the candidates to try).
    """
    config = SolveConfig(scenario=scenario.name, variant=variant)
    found = Sweep(scenario=scenario.name)
    with Store.open("sqlite://", create=True) as store:
        branch = store.current_branch()
        world = World.from_scene(scenario.scene("novelty", variant))
        try:
            world.settle(max_steps=SETTLE_STEPS)
            executor = TrialExecutor(store=store, branch=branch, world=world, scenario=scenario, seed=config.seed)
            experience = BranchExperience(store, branch)
            kb = load_knowledge(store, branch)
            log = PlanLog()
            failure = plan_and_repair(executor, experience, kb, perceive(world), log)
            found.plan, found.plan_repairs, found.failed_action = log.plan, log.repairs, log.failed_action
            if failure is None or failure.snapshot is None:
                return found
            candidates = enumerate_candidates(
                failed=executor.controller_call(failure.step), entities=executor.kinds, grid=config.candidate_grid(scenario)
            )
            found.candidates = len(candidates)
            chosen = range(len(candidates)) if positions is None else sorted(set(positions))
            if chosen and not 0 <= chosen[0] <= chosen[-1] < len(candidates):
                raise ValueError(f"positions must lie in 0..{len(candidates) - 1}, the {len(candidates)} candidates")
            if progress is not None:
                progress(0, len(chosen))
            for done, index in enumerate(chosen, start=1):
                spec = candidates[index]
                trial, _ = executor.execute(spec, source="exploration", snapshot_id=failure.snapshot, start=failure.snapshot)
                found.tried += 1
                if resolves(executor, experience, kb, trial, failure, count=False):
                    found.resolving.append(index)
                    found.labels.append(spec.label)
                if progress is not None:
                    progress(done, len(chosen))
                if stop_at_first and found.resolving:
                    break
        finally:
            world.close()
    return found
