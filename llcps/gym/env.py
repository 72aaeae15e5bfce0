"""``llcps/Explore-v0``: one RL episode is one novelty episode's exploration.

At :meth:`ExploreEnv.reset` the environment picks one of its (scenario, variant) pairs
(with the reset's seed when it has several), builds the scene in the novelty condition,
executes K's plan with its repairs as an episode does
(:func:`llcps.cps.plan_execution.find_failure`; the steps are stored as ``plan``
trials) and stops at the failure point, where exploration would start
(:func:`llcps.cps.failure_point.start_exploration`). The plan runs once per pair: later
resets of the same pair start from the stored failure snapshot at once.

- **Observation**: a ``Dict`` of ``failure`` (``(FAILURE_FEATURES,)``) and
  ``candidates`` (``(MAX_CANDIDATES, CANDIDATE_FEATURES)``), float32, as
  :mod:`llcps.cps.observation` documents.
- **Action**: the index of the candidate to try (``Discrete(MAX_CANDIDATES)``);
  :meth:`ExploreEnv.action_masks` is True for the candidates not tried yet (sb3-contrib's
  ``MaskablePPO`` convention). A masked action (a padding row, or a candidate tried
  already) costs a trial and does nothing. With ``reach_check`` (the default, as the
  agent's), the candidates the arm would refuse at the failure point (a pick-and-place
  waypoint out of reach: they move nothing) are masked from the start and show as
  unavailable in the observation, as the ``rl`` ordering shows them to the policy.
- **Reward**: ``+1`` when the trial resolves the novelty
  (:func:`llcps.cps.plan_execution.resolves`), minus ``trial_cost`` for every trial.
- **End**: ``terminated`` when the novelty is resolved; ``truncated`` when the budget
  is spent or every candidate was tried (every one the arm would not refuse).

Every trial goes to the store with ``source = "gym"`` (the re-plans that check whether
it resolved the novelty as ``plan`` trials), in one store episode per RL episode, so the
world models train on them like on any other. The environment learns no operator: K
and its operator experience stay as they were when the environment was made (a plan
run's failed steps count for that failure point only, and are not stored), so its
episodes are alike and the failure points do not depend on the order of the resets. The world
model (``model``, ``measure``) is fitted once, when the environment is made, on what
the branch saw then; its predictions are features of the candidates.

Deterministic: physics is, the plan is, and the reset's seed only picks the pair.
With ``cache=True`` (the default) trials simulated before are answered by the physics
cache in the store, so repeated episodes cost little.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from typing import Any, Sequence

import gymnasium
import numpy as np

from llcps.cps.branch_knowledge import BranchExperience, load_experience, load_knowledge
from llcps.cps.episode import DEFAULT_BUDGET, SolveConfig
from llcps.cps.executor import TrialExecutor
from llcps.cps.failure_point import FailurePoint, start_exploration
from llcps.cps.ranking import rank_candidates
from llcps.cps.observation import MAX_CANDIDATES, FailureObservation, action_space, observation_space
from llcps.cps.plan_execution import Failure, PlanLog, find_failure, resolves
from llcps.errors import LlcpsError
from llcps.models import MEASURES, WORLD_MODELS
from llcps.store import Store
from llcps.symbolic.experience import Context, Experience
from llcps.symbolic.knowledge_base import KnowledgeBase

#: What each trial costs in reward (a resolve earns 1).
DEFAULT_TRIAL_COST = 0.01
#: The trial source of the environment's trials.
GYM_SOURCE = "gym"


class _SiteExperience(BranchExperience):
    """The branch's operator experience as the environment was made, plus what one
    failure point's own plan runs add, kept in memory: the failure points do not depend
    on each other or on the order of the resets."""

    def __init__(self, store: Store, branch: str, experience: Experience) -> None:
        super().__init__(store, branch, experience=experience)

    def record(self, operator: str, context: Context, success: bool, trial_id: int | None) -> None:
        self.count(operator, context, success)


@dataclass
class _Site:
    """One (scenario, variant) pair at its failure point: the world, its executor and
    the failure exploration starts from."""

    executor: TrialExecutor
    experience: BranchExperience
    kb: KnowledgeBase
    failure: Failure
    point: FailurePoint
    observation: FailureObservation
    snapshot: int


class ExploreEnv(gymnasium.Env[dict[str, np.ndarray], np.int64]):
    """Novelty exploration as a Gymnasium environment (see the module docstring).

    Args:
        scenario: a scenario name or ``.toml`` file, or several (reset picks one).
        variant: the scene variant, or several (reset picks one).
        db: the store (a SQLite path or SQLAlchemy URL, created if missing, or an open
            :class:`~llcps.store.Store`, left open); None: a temporary store, deleted
            at :meth:`close`.
        branch: the store's branch (None: its current branch).
        model: the world model whose predictions are candidate features.
        measure: the measure that orders the candidates for the ``model_rank`` feature.
        budget: trials per episode before it is truncated.
        trial_cost: reward subtracted per trial.
        seed: the seed recorded with the trials and the world model's fit seed.
        cache: answer trials simulated before from the store's physics cache.
        reach_check: mask the candidates the arm would refuse at the failure point.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        scenario: str | Sequence[str] = "scenario2",
        *,
        variant: int | Sequence[int] = 0,
        db: str | os.PathLike[str] | Store | None = None,
        branch: str | None = None,
        model: str = WORLD_MODELS.default,
        measure: str = MEASURES.default,
        budget: int = DEFAULT_BUDGET,
        trial_cost: float = DEFAULT_TRIAL_COST,
        seed: int = 0,
        cache: bool = True,
        reach_check: bool = True,
    ) -> None:
        super().__init__()
        names = [scenario] if isinstance(scenario, (str, os.PathLike)) else list(scenario)
        variants = [variant] if isinstance(variant, int) else list(variant)
        if not names or not variants:
            raise LlcpsError("the environment needs at least one scenario and one variant")
        if not 1 <= budget <= MAX_CANDIDATES:
            raise LlcpsError(f"budget must be from 1 to {MAX_CANDIDATES}, got {budget}")
        if not (np.isfinite(trial_cost) and trial_cost >= 0):
            raise LlcpsError(f"trial_cost must be a finite number >= 0, got {trial_cost}")
        # Every name and number is checked as an episode's config is, before anything runs.
        self.configs = [
            SolveConfig(scenario=str(name), model=model, measure=measure, seed=seed, budget=budget, variant=v, reach_check=reach_check)
            for name in names
            for v in variants
        ]
        self.scenarios = [config.validate().name for config in self.configs]
        self.budget = budget
        self.reach_check = bool(reach_check)
        self.trial_cost = float(trial_cost)
        self.seed_value = seed
        self.observation_space = observation_space()
        self.action_space = action_space()
        self._tmp: str | None = None
        if db is None:
            self._tmp = tempfile.mkdtemp(prefix="llcps-gym-")
            db = os.path.join(self._tmp, "gym.db")
        self._own_store = not isinstance(db, Store)
        self.store = db if isinstance(db, Store) else Store.open(os.fspath(db), create=True)
        self.branch = self.store.resolve_branch(branch).name
        self._cache = None
        if cache:
            from llcps.store.physics_cache import StorePhysicsCache

            self._cache = StorePhysicsCache(self.store.engine)
        self._sites: dict[int, _Site] = {}
        self._kb = load_knowledge(self.store, self.branch)
        self._experience = load_experience(self.store, self.branch)
        self._model: Any = None
        self._run_id: int | None = None
        self._episode_id: int | None = None
        self._site: _Site | None = None
        self._config_index = 0
        self.tried: list[int] = []
        self.trials = 0
        self.resolved = False
        self._resolving: int | None = None
        #: One entry per finished episode (solved or out of budget), oldest first:
        #: scenario, variant, trials, resolved.
        self.history: list[dict[str, Any]] = []
        #: The store id of the last trial :meth:`step` took (None: the action was masked).
        self.last_trial_id: int | None = None

    # -- set-up ------------------------------------------------------------------
    def _world_model(self) -> Any:
        if self._model is None:
            from llcps.models.measures import get_measure
            from llcps.models.persistence import fit_or_load

            config = self.configs[0]
            goal = get_measure(config.measure).uses_goal
            self._model = fit_or_load(self.store, self.branch, config.model, config.fit_seed, goal=goal)
        return self._model

    def _start_run(self) -> int:
        if self._run_id is None:
            config = self.configs[0]
            self._run_id = self.store.start_run(
                command="gym",
                seed=self.seed_value,
                config={
                    "env": "llcps/Explore-v0",
                    "scenarios": [c.scenario for c in self.configs],
                    "variants": sorted({c.variant for c in self.configs}),
                    "model": config.model,
                    "measure": config.measure,
                    "budget": self.budget,
                    "trial_cost": self.trial_cost,
                    "reach_check": self.reach_check,
                },
                branch=self.branch,
            )
        return self._run_id

    def _site_of(self, index: int) -> _Site:
        """The failure point of configuration ``index``, planned to on first use."""
        if index in self._sites:
            return self._sites[index]
        from llcps.sim.world import SETTLE_STEPS, World

        config = self.configs[index]
        scenario = config.validate()
        model = self._world_model()
        world = World.from_scene(scenario.scene(config.condition, config.variant))
        try:
            world.settle(max_steps=SETTLE_STEPS)
            records, changes = self.store.training_set(self.branch)
            executor = TrialExecutor(
                store=self.store,
                branch=self.branch,
                world=world,
                scenario=scenario,
                seed=config.seed,
                run_id=self._run_id,
                episode_id=self._episode_id,
                records=records,
                changes=changes,
                cache=self._cache,
            )
            experience = _SiteExperience(self.store, self.branch, self._experience)
            kb = self._kb
            failure = find_failure(executor, experience, kb, PlanLog())
            if failure is None:
                raise LlcpsError(
                    f"K's plan for {scenario.name} (variant {config.variant}) does not fail, or there is none: nothing to explore",
                    hint="the environment explores a novelty: pick a scenario whose plan fails on this branch",
                )
            grid = config.candidate_grid(scenario)
            point = start_exploration(executor, experience, kb, failure, grid=grid, reach_check=self.reach_check)
            ranking = rank_candidates(model, point, measure=config.measure, seed=config.seed)
            observation = FailureObservation.of(point, ranking)
        except BaseException:
            world.close()
            raise
        assert failure.snapshot is not None
        site = _Site(executor, experience, kb, failure, point, observation, failure.snapshot)
        self._sites[index] = site
        return site

    # -- the Gymnasium interface --------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        self._finish_episode("interrupted")
        self._config_index = int(self.np_random.integers(len(self.configs))) if len(self.configs) > 1 else 0
        config = self.configs[self._config_index]
        run_id = self._start_run()
        self._episode_id = self.store.start_episode(
            run_id=run_id,
            branch=self.branch,
            scenario=self.scenarios[self._config_index],
            condition=config.condition,
            model=config.model,
            measure=config.measure,
            seed=config.seed,
        )
        site = self._site_of(self._config_index)
        site.executor.run_id, site.executor.episode_id = run_id, self._episode_id
        site.executor.restore(site.snapshot)
        self._site = site
        self.tried, self.trials, self.resolved, self._resolving = [], 0, False, None
        return self._observation(), self._info()

    def step(self, action: int | np.integer) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        site = self._site
        if site is None or self._episode_id is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        index = int(action)
        self.trials += 1
        reward = -self.trial_cost
        valid = 0 <= index < site.observation.n and index not in self.tried and index not in site.point.refused
        trial_id = None
        if valid:
            self.tried.append(index)
            spec = site.point.candidates[index]
            trial, record = site.executor.execute(spec, source=GYM_SOURCE, snapshot_id=site.snapshot, start=site.snapshot)
            trial_id = record.id if record is not None else None
            self.resolved = resolves(site.executor, site.experience, site.kb, trial, site.failure)
            if self.resolved:
                reward += 1.0
                self._resolving = trial_id
        terminated = self.resolved
        truncated = not terminated and (self.trials >= self.budget or len(self._unavailable()) >= site.observation.n)
        if terminated or truncated:
            self._finish_episode("solved" if terminated else "budget_exhausted")
        self.last_trial_id = trial_id
        info = self._info()
        info["valid"] = valid
        return self._observation(), reward, terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        """True for each candidate not tried yet and not refused (sb3-contrib's MaskablePPO calls this)."""
        if self._site is None:
            return np.zeros(MAX_CANDIDATES, dtype=bool)
        return self._site.observation.mask(self._unavailable())

    def close(self) -> None:
        self._finish_episode("interrupted")
        for site in self._sites.values():
            site.executor.world.close()
        self._sites.clear()
        self._site = None
        if self._cache is not None:
            self._cache.flush()
        if self._run_id is not None:
            self.store.finish_run(self._run_id, status="finished")
            self._run_id = None
        if self._own_store:
            self.store.close()
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None
        super().close()

    # -- helpers ---------------------------------------------------------------------
    def _unavailable(self) -> list[int]:
        """The candidates not to try (any more): those tried, and those the arm would refuse."""
        assert self._site is not None
        return self.tried + sorted(self._site.point.refused)

    def _observation(self) -> dict[str, np.ndarray]:
        assert self._site is not None
        return self._site.observation.observe(self._unavailable(), self.trials, self.budget)

    def _info(self) -> dict[str, Any]:
        config = self.configs[self._config_index]
        site = self._site
        return {
            "scenario": self.scenarios[self._config_index],
            "variant": config.variant,
            "candidates": site.observation.n if site is not None else 0,
            "refused": len(site.point.refused) if site is not None else 0,
            "trials": self.trials,
            "resolved": self.resolved,
            "action_mask": self.action_masks(),
        }

    def _finish_episode(self, status: str) -> None:
        """Record the store episode's outcome (once)."""
        if self._episode_id is None:
            return
        config = self.configs[self._config_index]
        summary = {
            "scenario": self.scenarios[self._config_index],
            "variant": config.variant,
            "model": config.model,
            "measure": config.measure,
            "ordering": "gym",
            "status": status,
            "solved": status == "solved",
            "exploration_trials": self.trials,
            "plan_trials": 0,
            "candidates": self._site.observation.n if self._site is not None else 0,
            "refused": len(self._site.point.refused) if self._site is not None else 0,
            "reach_check": self.reach_check,
            "failed_action": self._site.failure.step.label if self._site is not None else None,
            "missing_effects": self._site.failure.monitor.describe() if self._site is not None else None,
            "resolving_trial_id": self._resolving,
            "learned_operators": [],
            "tried": list(self.tried),
        }
        self.store.finish_episode(self._episode_id, status=status, summary=summary)
        self._episode_id = None
        if status != "interrupted":
            self.history.append({"scenario": summary["scenario"], "variant": config.variant, "trials": self.trials, "resolved": self.resolved})
