"""One episode: what defines it (:class:`SolveConfig`), the loop that runs it
(:func:`solve`) and what it produced (:class:`SolveResult`).

One call of :func:`solve` is one *episode*: a scenario in one condition, solved on one
branch of the experience store. Every trial the robot executes is written to the store
as it happens; the world model trains on every trial the branch can see (the lifelong
training set) and is refit during exploration, as the paper's agent does within a
scenario.

The loop: perceive; execute K's plan, repairing it with what K knows when a step fails
(:mod:`llcps.cps.plan_execution`); only when no repaired plan reaches the goal does
creative problem solving start, for the first step that failed, a_f: the novelty is that
a_f fails where K expected it to work, so exploration tries candidates ranked by the
world model (:mod:`llcps.cps.ranking`) from the state a_f was executed in, until one
resolves the novelty, and a learned operator records that state as its context
(:mod:`llcps.cps.learning`).

Light to import: the CLI validates options with :class:`SolveConfig` before anything
loads, so the loop loads the simulator, the planner and numpy when it runs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Collection, Mapping

from llcps.cps.candidates import Grid
from llcps.cps.orderings import ORDERINGS
from llcps.domain import check_seed
from llcps.errors import LlcpsError, UnknownNameError
from llcps.models import MEASURES, WORLD_MODELS
from llcps.outputs import GIF_SUFFIXES, check_output_file
from llcps.scenarios import get_scenario
from llcps.scenarios.base import CONDITIONS, Scenario
from llcps.scenarios.variants import check_variant

if TYPE_CHECKING:
    from llcps.cps.branch_knowledge import BranchExperience
    from llcps.cps.executor import ProgressCallback, TrialExecutor
    from llcps.cps.plan_execution import Failure, PlanLog
    from llcps.models.base import WorldModel
    from llcps.sim.cache import PhysicsCache
    from llcps.store import Store
    from llcps.symbolic.knowledge_base import KnowledgeBase
    from llcps.training import TrainingSet

DEFAULT_BUDGET = 300
#: Largest exploration budget (and refit interval) accepted: far beyond any candidate space.
MAX_BUDGET = 1_000_000


@dataclass(frozen=True)
class SolveConfig:
    """Everything that defines an episode, so a stored run can be repeated."""

    scenario: str
    condition: str = "novelty"
    model: str = WORLD_MODELS.default
    measure: str = MEASURES.default
    #: The exploration ordering (:mod:`llcps.cps.orderings`).
    ordering: str = ORDERINGS.default
    seed: int = 0
    budget: int = DEFAULT_BUDGET
    refit_every: int = 1
    #: The candidate grid (None: the one the scenario's file asks for, by default the documented grid).
    grid: Grid | None = None
    #: The scene variant (0: the canonical scene; see docs/scenarios.md).
    variant: int = 0
    #: Seed of the world model's fit (None: the episode's ``seed``).
    model_seed: int | None = None
    #: Try last the candidates the arm would refuse at the failure point (a pick-and-place
    #: waypoint out of reach, :func:`~llcps.sim.controllers.refuses`): they move nothing.
    #: The paper's agent tries every candidate in its ordering's order (False).
    reach_check: bool = True

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
        if self.ordering not in ORDERINGS:
            raise UnknownNameError("ordering", self.ordering, list(ORDERINGS))
        check_seed(self.seed)
        if self.model_seed is not None:
            check_seed(self.model_seed, "model seed")
        if not 0 <= self.budget <= MAX_BUDGET:
            raise LlcpsError(f"budget must be from 0 to {MAX_BUDGET}, got {self.budget}", hint="pass --budget 0 or more")
        if not 1 <= self.refit_every <= MAX_BUDGET:
            raise LlcpsError(f"refit_every must be from 1 to {MAX_BUDGET}, got {self.refit_every}")
        return scenario


@dataclass(frozen=True)
class SolveResult:
    """The summary of one episode (``llcps solve --json`` prints :meth:`as_json`)."""

    scenario: str
    condition: str
    model: str
    measure: str
    seed: int
    branch: str
    variant: int = 0
    ordering: str = ORDERINGS.default
    #: Whether candidates the arm would refuse were tried last (:attr:`SolveConfig.reach_check`).
    reach_check: bool = False
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
    #: What the ordering decided per trial (:meth:`Ordering.trace`; the hedge: which side chose each).
    ordering_trace: dict[str, list[Any]] | None = None
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
            "ordering": self.ordering,
            "reach_check": self.reach_check,
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
            **({} if self.ordering_trace is None else {"ordering_trace": self.ordering_trace}),
        }


@dataclass
class _Progress:
    """What the loop found so far (written as it goes, so an interrupted episode is summed
    up with what it found before the interruption)."""

    plan: PlanLog
    status: str = "running"
    candidates: int = 0
    learned_operators: list[str] = field(default_factory=list)
    resolving_trial_id: int | None = None
    ordering: Any = None  # the exploration's ordering (llcps.cps.orderings.base.Ordering), once it exists


def solve(
    store: Store,
    *,
    branch: str | None,
    config: SolveConfig,
    command: str = "solve",
    gui: bool = False,
    gif: str | Path | None = None,
    progress: ProgressCallback | None = None,
    cache: PhysicsCache | None = None,
) -> SolveResult:
    """Solve one scenario on one branch; see the module docstring.

    Args:
        store: the experience store (trials, operators and models are read and written there).
        branch: branch name, ``None`` for the store's current branch.
        config: scenario, condition, world model, measure, seed, budget.
        command: the command line recorded with the run.
        gui: open a PyBullet GUI window (needs a display).
        gif: film the episode to this GIF afterwards (:func:`llcps.cps.film.film_episode`);
            the episode's stored wall time does not include it.
        progress: optional callback for progress bars (see :data:`~llcps.cps.executor.ProgressCallback`).
        cache: the physics cache (:mod:`llcps.store.physics_cache`), to answer trials
            simulated before without stepping the engine; what the episode records is
            the same with or without it, but for the trials marked ``cache_hit`` and
            their wall seconds.

    Returns:
        The episode summary; ``status`` is ``solved``, ``budget_exhausted``,
        ``no_plan`` or ``interrupted``.
    """
    # PyBullet, the planner, numpy and the world models load only when an episode runs.
    from llcps.cps.branch_knowledge import BranchExperience, load_knowledge
    from llcps.cps.executor import TrialExecutor
    from llcps.cps.plan_execution import PlanLog
    from llcps.models.measures import get_measure
    from llcps.models.persistence import fit_or_load
    from llcps.sim.world import SETTLE_STEPS, World

    scenario = config.validate()
    if gif is not None:
        check_output_file(gif, what="gif", suffixes=GIF_SUFFIXES)
    branch_name = store.resolve_branch(branch).name
    started = time.perf_counter()
    from llcps.store import utc_now  # here, not where the module loads: it needs no SQLAlchemy

    # The run starts with the command: reading the trials and fitting the model count.
    started_at = utc_now()
    # What the store holds is read (and checked) as the fit reads it, before the episode
    # writes anything (a refitted model, its run): a malformed row stops it there. An
    # episode that counts its new trials into a stored model reads only those
    # (:class:`~llcps.training.TrainingSet`), the rest having been read by the fits before.
    if progress is not None:
        progress(f"fit world model {config.model}", 0, 0)
    records, changes = store.training_set(branch_name)
    goal = get_measure(config.measure).uses_goal  # a measure ranking by Omega alone needs no goal head
    kb = load_knowledge(store, branch_name)  # before the fit, which may store a model
    model = fit_or_load(store, branch_name, config.model, config.fit_seed, records=records, changes=changes, goal=goal)
    run_id = store.start_run(
        command=command, seed=config.seed, config=_config_json(config), branch=branch_name, started_at=started_at
    )
    episode_id = store.start_episode(
        run_id=run_id,
        branch=branch_name,
        scenario=scenario.name,
        condition=config.condition,
        model=config.model,
        measure=config.measure,
        seed=config.seed,
    )
    found = _Progress(plan=PlanLog())
    world: World | None = None
    executor: TrialExecutor | None = None
    try:
        world = World.from_scene(scenario.scene(config.condition, config.variant), gui=gui)
        world.settle(max_steps=SETTLE_STEPS)
        executor = TrialExecutor(
            store=store,
            branch=branch_name,
            world=world,
            scenario=scenario,
            seed=config.seed,
            run_id=run_id,
            episode_id=episode_id,
            records=records,
            changes=changes,
            cache=cache,
            progress=progress,
        )
        experience = BranchExperience(store, branch_name, episode_id=episode_id, experience=kb.experience)
        _run(executor, experience, kb, model, config, found)
    except KeyboardInterrupt:
        found.status = "interrupted"
    finally:
        tally = executor.tally if executor is not None else None
        sim_steps = tally.sim_steps if tally is not None else 0
        log = found.plan
        result = SolveResult(
            scenario=scenario.name,
            condition=config.condition,
            model=config.model,
            measure=config.measure,
            seed=config.seed,
            branch=branch_name,
            variant=config.variant,
            ordering=config.ordering,
            reach_check=config.reach_check,
            status="error" if found.status == "running" else found.status,
            plan=list(log.plan),
            plan_repairs=list(log.repairs),
            failed_action=log.failed_action,
            missing_effects=log.missing_effects,
            exploration_trials=tally.exploration_trials if tally is not None else 0,
            plan_trials=tally.plan_trials if tally is not None else 0,
            cache_hits=tally.cache_hits if tally is not None else 0,
            candidates=found.candidates,
            sim_steps=sim_steps,
            sim_seconds=sim_steps * (world.time_step if world is not None else 1 / 240),
            wall_seconds=time.perf_counter() - started,
            learned_operators=list(found.learned_operators),
            resolving_trial_id=found.resolving_trial_id,
            ordering_trace=found.ordering.trace() if found.ordering is not None else None,
            episode_id=episode_id,
            run_id=run_id,
        )
        if world is not None:
            world.close()
        if cache is not None:
            cache.flush()
        store.finish_episode(episode_id, status=result.status, summary=result.as_json())
        store.finish_run(run_id, status=result.status)
    if gif is not None and result.status != "interrupted":
        from llcps.cps.film import film_episode

        film_episode(store, episode_id, gif, progress=progress)
    return result


def _run(executor: TrialExecutor, experience: BranchExperience, kb: KnowledgeBase, model: WorldModel, config: SolveConfig, found: _Progress) -> None:
    """Plan with K and repair the plan; only if no plan reaches the goal, explore."""
    from llcps.cps.plan_execution import find_failure

    failure = find_failure(executor, experience, kb, found.plan)
    if found.plan.solved:
        found.status = "solved"
        return
    if failure is None:
        found.status = "no_plan"
        return
    _explore(executor, experience, kb, model, config, failure, found)


def _explore(
    executor: TrialExecutor,
    experience: BranchExperience,
    kb: KnowledgeBase,
    model: WorldModel,
    config: SolveConfig,
    failure: Failure,
    found: _Progress,
) -> None:
    """Try candidates from the failure snapshot, in the config's ordering, until one resolves the novelty."""
    from llcps.cps.failure_point import start_exploration
    from llcps.cps.learning import learn
    from llcps.cps.orderings import get_ordering
    from llcps.cps.orderings.base import Exploration
    from llcps.cps.plan_execution import resolves

    snapshot = failure.snapshot
    assert snapshot is not None  # the episode stores its plan
    point = start_exploration(executor, experience, kb, failure, grid=config.candidate_grid(executor.scenario), reach_check=config.reach_check)
    candidates = point.candidates
    found.candidates = len(candidates)
    trial_ids: dict[int, int | None] = {}  # candidate index -> the id of its stored trial
    ordering = get_ordering(config.ordering)(
        Exploration(
            model=model,
            point=point,
            measure=config.measure,
            seed=config.seed,
            refit_every=config.refit_every,
            update=lambda only: model.update(_taken(executor.records, trial_ids, only), executor.changes, start=snapshot, asked=point.asked),
            store=executor.store,
            branch=executor.branch,
            episode_id=executor.episode_id,
        )
    )
    found.ordering = ordering
    # What the arm would refuse moves nothing, so it cannot resolve the novelty: tried
    # only once every other candidate was, in candidate order, unknown to the ordering.
    refused = sorted(point.refused)
    ordering.exclude(refused)
    executor.report("explore", total=min(config.budget, len(candidates)))
    while executor.tally.exploration_trials < config.budget:
        index = ordering.next()
        deferred = index is None
        if index is None:
            if not refused:
                break
            index = refused.pop(0)
        spec = candidates[index]
        trial, record = executor.execute(spec, source="exploration", snapshot_id=snapshot, start=snapshot)
        trial_ids[index] = record.id if record is not None else None
        executor.report("explore")
        if resolves(executor, experience, kb, trial, failure):
            found.learned_operators.append(learn(executor, experience, kb, spec, trial, failure, record))
            found.resolving_trial_id = record.id if record is not None else None
            found.status = "solved"
            return
        if not deferred:
            ordering.observe(index, trial.after)
    found.status = "budget_exhausted"


def _taken(records: TrainingSet, trial_ids: Mapping[int, int | None], only: Collection[int] | None) -> TrainingSet:
    """The training set with this episode's exploration trials of candidates outside
    ``only`` left out (None: nothing left out)."""
    if only is None:
        return records
    kept = set(only)
    left_out = {trial_id for index, trial_id in trial_ids.items() if index not in kept and trial_id is not None}
    return records.without(left_out) if left_out else records


def _config_json(config: SolveConfig) -> dict[str, Any]:
    return {
        "scenario": config.scenario,
        "condition": config.condition,
        "model": config.model,
        "measure": config.measure,
        "ordering": config.ordering,
        "seed": config.seed,
        "variant": config.variant,
        "model_seed": config.fit_seed,
        "budget": config.budget,
        "refit_every": config.refit_every,
        "reach_check": config.reach_check,
    }
