"""What defines an episode (:class:`SolveConfig`) and what it produced
(:class:`SolveResult`). Light to import: the CLI validates options with it
before the simulator loads."""

from __future__ import annotations

from dataclasses import dataclass, field

from llcps.cps.candidates import Grid
from llcps.domain import check_seed
from llcps.errors import LlcpsError, UnknownNameError
from llcps.models import MEASURES, WORLD_MODELS
from llcps.scenarios import get_scenario
from llcps.scenarios.base import CONDITIONS, Scenario
from llcps.scenarios.variants import check_variant

DEFAULT_MODEL = "nb"
DEFAULT_MEASURE = "goal-directed"
DEFAULT_BUDGET = 300
#: Largest exploration budget (and refit interval) accepted: far beyond any candidate space.
MAX_BUDGET = 1_000_000


@dataclass(frozen=True)
class SolveConfig:
    """Everything that defines an episode, so a stored run can be repeated."""

    scenario: str
    condition: str = "novelty"
    model: str = DEFAULT_MODEL
    measure: str = DEFAULT_MEASURE
    seed: int = 0
    budget: int = DEFAULT_BUDGET
    refit_every: int = 1
    #: The candidate grid (None: the one the scenario's file asks for, by default the documented grid).
    grid: Grid | None = None
    #: The scene variant (0: the canonical scene; see docs/scenarios.md).
    variant: int = 0
    #: Seed of the world model's fit (None: the episode's ``seed``).
    model_seed: int | None = None

    @property
    def fit_seed(self) -> int:
        """The seed the world model is fitted (or loaded) with."""
        return self.seed if self.model_seed is None else self.model_seed

    def candidate_grid(self, scenario: Scenario) -> Grid:
        """The grid exploration searches: this config's, else the scenario's."""
        return self.grid if self.grid is not None else Grid(**scenario.grid)

    def validate(self) -> Scenario:
        """Check names and numbers before anything runs; returns the scenario."""
        scenario = get_scenario(self.scenario)
        check_variant(self.variant)
        if self.condition not in CONDITIONS:
            raise LlcpsError(f"unknown condition {self.condition!r}", hint=f"choose one of: {', '.join(CONDITIONS)}")
        if self.model not in WORLD_MODELS:
            raise UnknownNameError("world model", self.model, list(WORLD_MODELS))
        if self.measure not in MEASURES:
            raise UnknownNameError("measure", self.measure, list(MEASURES))
        check_seed(self.seed)
        if self.model_seed is not None:
            check_seed(self.model_seed, "model seed")
        if not 0 <= self.budget <= MAX_BUDGET:
            raise LlcpsError(f"budget must be from 0 to {MAX_BUDGET}, got {self.budget}", hint="pass --budget 0 or more")
        if not 1 <= self.refit_every <= MAX_BUDGET:
            raise LlcpsError(f"refit_every must be from 1 to {MAX_BUDGET}, got {self.refit_every}")
        return scenario


@dataclass
class SolveResult:
    """The summary of one episode (``llcps solve --json`` prints :meth:`as_json`)."""

    scenario: str
    condition: str
    model: str
    measure: str
    seed: int
    branch: str
    variant: int = 0
    status: str = "running"
    plan: list[str] = field(default_factory=list)
    plan_repairs: list[dict[str, object]] = field(default_factory=list)
    failed_action: str | None = None
    missing_effects: str | None = None
    exploration_trials: int = 0
    plan_trials: int = 0
    #: Trials answered from the physics cache instead of simulated.
    cache_hits: int = 0
    candidates: int = 0
    sim_steps: int = 0
    sim_seconds: float = 0.0
    wall_seconds: float = 0.0
    learned_operators: list[str] = field(default_factory=list)
    resolving_trial_id: int | None = None
    episode_id: int | None = None
    run_id: int | None = None

    @property
    def solved(self) -> bool:
        return self.status == "solved"

    def as_json(self) -> dict[str, object]:
        return {
            "scenario": self.scenario,
            "condition": self.condition,
            "model": self.model,
            "measure": self.measure,
            "seed": self.seed,
            "variant": self.variant,
            "branch": self.branch,
            "solved": self.solved,
            "status": self.status,
            "plan": self.plan,
            "plan_repairs": self.plan_repairs,
            "failed_action": self.failed_action,
            "missing_effects": self.missing_effects,
            "exploration_trials": self.exploration_trials,
            "plan_trials": self.plan_trials,
            "cache_hits": self.cache_hits,
            "candidates": self.candidates,
            "sim_steps": self.sim_steps,
            "sim_seconds": round(self.sim_seconds, 4),
            "wall_seconds": round(self.wall_seconds, 4),
            "learned_operators": self.learned_operators,
            "resolving_trial_id": self.resolving_trial_id,
            "episode_id": self.episode_id,
            "run_id": self.run_id,
        }
