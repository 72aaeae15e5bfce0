"""The properties every scenario must have, checked in real physics for a range of variants.

1. ``original_solved``: in the original condition K's plan reaches the goal with no
   exploration (a solve with budget 0).
2. ``novelty_defeats_plan``: in the novelty K's plan fails, and so does every plan
   repair, so that only creative problem solving can reach the goal.
3. ``resolvable``: the sweep of the candidate space (:func:`llcps.cps.sweep.sweep`)
   finds a candidate that resolves the novelty.
4. ``ranking_matters``: the first resolving candidate is not the first of the default
   order, so the order a world model gives matters.

Everything runs in throwaway in-memory stores: nothing reaches the experience store.
A *quick* check stops each sweep at the first resolving candidate: it decides every
property, but counts resolving candidates only as "at least one".

A full sweep runs every candidate in physics (minutes per variant), so a check can say
how long each sweep may take once its first :data:`TIMED_TRIALS` candidates are timed
(:class:`SweepEstimate`). A check of some positions of the default order
(``positions``, 0 among them) decides every property too: where the first resolving
candidate is known, the first candidate and that one suffice.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

from llcps.cps.episode import SolveConfig, solve
from llcps.cps.sweep import Sweep, sweep
from llcps.scenarios.base import Scenario
from llcps.store import Store

#: The properties, in order, with what each says.
PROPERTIES: dict[str, str] = {
    "original_solved": "in the original condition K's plan succeeds with 0 exploration",
    "novelty_defeats_plan": "in the novelty K's plan and every plan repair fail",
    "resolvable": "some candidate of the sweep resolves the novelty",
    "ranking_matters": "the first resolving candidate is not first in the default order",
}

ProgressCallback = Callable[[str, int, int], None]
"""Called as ``progress(phase, done, total)``: phase names the variant and what runs;
done and total count candidates while sweeping (total 0: not known yet)."""

#: Candidates a sweep times before it estimates how long the whole sweep takes.
TIMED_TRIALS = 3
#: A rough wall time of one sweep trial. The shipped scenarios' full sweeps of 467
#: candidates took 115-708 s (0.25-1.5 s a trial; docs/scenarios.md), and the default order
#: puts cheap candidates first (scenario2's first 50 took 0.02 s each), so the first
#: trials alone under-estimate a sweep: the estimate takes the larger of the two.
TYPICAL_SECONDS_PER_TRIAL = 0.5


@dataclass(frozen=True)
class SweepEstimate:
    """How long a variant's sweep may take: its candidates times a wall time per trial,
    the larger of its first trials' and :data:`TYPICAL_SECONDS_PER_TRIAL`. Wall time
    only; nothing of it is stored.

    Attributes:
        variant: the variant swept.
        candidates: the size of its candidate space.
        timed: the trials timed.
        measured: their mean wall time, in seconds.
        quick: the sweep stops at the first resolving candidate (the estimate is then a bound).
    """

    variant: int
    candidates: int
    timed: int
    measured: float
    quick: bool

    @property
    def seconds_per_trial(self) -> float:
        """The wall time per trial the estimate assumes."""
        return max(self.measured, TYPICAL_SECONDS_PER_TRIAL)

    @property
    def seconds(self) -> float:
        """The whole sweep, every candidate tried."""
        return self.candidates * self.seconds_per_trial


EstimateCallback = Callable[[SweepEstimate], None]
"""Called once per variant with the :class:`SweepEstimate` of its sweep (when the sweep
lasts beyond its first timed trials)."""


@dataclass
class VariantCheck:
    """What the check found for one variant.

    Attributes:
        variant: the variant.
        original_status: how the original condition's solve ended.
        sweep: the novelty's sweep.
        quick: whether the sweep stopped at the first resolving candidate.
        properties: each property of :data:`PROPERTIES`, held or not.
        reasons: for each property that does not hold, why.
    """

    variant: int
    original_status: str
    original_exploration: int
    sweep: Sweep
    quick: bool
    properties: dict[str, bool] = field(default_factory=dict)
    reasons: dict[str, str] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return all(self.properties.values())

    @property
    def resolving_label(self) -> str:
        """Resolving candidates: a count, or ``>= 1`` when a quick sweep stopped at the first."""
        n = len(self.sweep.resolving)
        return ">= 1" if self.quick and n else str(n)

    def as_json(self) -> dict[str, object]:
        return {
            "variant": self.variant,
            "passed": self.passed,
            "properties": dict(self.properties),
            "reasons": dict(self.reasons),
            "original_status": self.original_status,
            "original_exploration_trials": self.original_exploration,
            "plan": self.sweep.plan,
            "plan_repairs": self.sweep.plan_repairs,
            "failed_action": self.sweep.failed_action,
            "candidates": self.sweep.candidates,
            "tried": self.sweep.tried,
            "resolving": self.resolving_label if self.quick else len(self.sweep.resolving),
            "first_position": self.sweep.first_position,
            "resolving_candidates": self.sweep.labels,
        }


@dataclass
class CheckReport:
    """A check over a range of variants."""

    scenario: str
    variants: list[VariantCheck]
    quick: bool

    @property
    def passed(self) -> bool:
        return all(v.passed for v in self.variants)

    def shares(self) -> dict[str, float]:
        """The share of variants where each property holds."""
        n = len(self.variants)
        return {name: sum(v.properties[name] for v in self.variants) / n if n else 0.0 for name in PROPERTIES}

    def as_json(self) -> dict[str, object]:
        return {
            "scenario": self.scenario,
            "quick": self.quick,
            "passed": self.passed,
            "variants": [v.as_json() for v in self.variants],
            "shares": self.shares(),
            "properties": dict(PROPERTIES),
        }


def check_variant(
    scenario: Scenario,
    ref: str,
    variant: int,
    *,
    quick: bool,
    positions: Sequence[int] | None = None,
    progress: ProgressCallback | None = None,
    estimate: EstimateCallback | None = None,
) -> VariantCheck:
    """Check the four properties of one variant (see the module docstring).

    Args:
        scenario: the scenario.
        ref: what :func:`llcps.scenarios.get_scenario` finds it by (its name, or its file).
        variant: the scene variant.
        quick: stop the sweep at the first resolving candidate.
        positions: sweep only these 0-based positions of the default order (None: all).
            Position 0 must be among them: ``ranking_matters`` asks whether it resolves.
        progress: see :data:`ProgressCallback`.
        estimate: see :data:`EstimateCallback`.
    """
    if positions is not None and 0 not in positions:
        raise ValueError("positions must include 0, the first candidate of the default order")
    if progress is not None:
        progress(f"variant {variant}: original condition", 0, 0)
    with Store.open("sqlite://", create=True) as store:
        original = solve(store, branch=None, config=SolveConfig(scenario=ref, condition="original", budget=0, variant=variant))

    first_trial: list[float] = []  # when the first candidate began

    def swept(done: int, total: int) -> None:
        if progress is not None:
            progress(f"variant {variant}: novelty sweep", done, total)
        if estimate is None or not total:
            return
        if done == 0:
            first_trial.append(time.perf_counter())
        elif first_trial and done == min(TIMED_TRIALS, total):
            estimate(SweepEstimate(variant, total, done, (time.perf_counter() - first_trial[0]) / done, quick))

    swept(0, 0)
    found = sweep(scenario, variant=variant, stop_at_first=quick, positions=positions, progress=swept)
    report = VariantCheck(variant, original.status, original.exploration_trials, found, quick)
    judge(report)
    return report


def judge(report: VariantCheck) -> None:
    """Decide each property of a variant from its solve and its sweep."""
    found = report.sweep
    holds = report.properties
    why = report.reasons
    holds["original_solved"] = report.original_status == "solved" and report.original_exploration == 0
    if not holds["original_solved"]:
        why["original_solved"] = f"the original condition's solve ended {report.original_status!r}"
    repaired = [r for r in found.plan_repairs if r.get("failed_action") is None]
    holds["novelty_defeats_plan"] = found.failed_action is not None and not repaired
    if found.failed_action is None:
        why["novelty_defeats_plan"] = "K has no plan in the novelty" if not found.plan else "K's plan reached the goal in the novelty"
    elif repaired:
        why["novelty_defeats_plan"] = f"the plan repair {' '.join(repaired[0]['plan'])} reached the goal"  # type: ignore[arg-type]
    holds["resolvable"] = bool(found.resolving)
    if not holds["resolvable"]:
        why["resolvable"] = (
            f"none of the {found.candidates} candidates resolves the novelty" if found.candidates else "there was nothing to sweep"
        )
    holds["ranking_matters"] = found.first_position is not None and found.first_position > 1
    if not holds["ranking_matters"]:
        why["ranking_matters"] = (
            "the first candidate of the default order resolves the novelty" if found.first_position == 1 else "no candidate resolves it"
        )


def check_scenario(
    scenario: Scenario,
    ref: str,
    *,
    variants: Sequence[int] = (0,),
    quick: bool = False,
    progress: ProgressCallback | None = None,
    estimate: EstimateCallback | None = None,
) -> CheckReport:
    """Check every variant of ``variants`` in turn (see :func:`check_variant`)."""
    return CheckReport(
        scenario=scenario.name,
        variants=[check_variant(scenario, ref, v, quick=quick, progress=progress, estimate=estimate) for v in variants],
        quick=quick,
    )


__all__ = ["PROPERTIES", "TIMED_TRIALS", "TYPICAL_SECONDS_PER_TRIAL", "CheckReport", "SweepEstimate", "VariantCheck", "check_scenario", "check_variant", "judge"]
