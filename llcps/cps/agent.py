"""The lifelong CPS agent: plan, execute with monitoring, repair the plan, explore on
failure, learn K'.

One call of :func:`solve` is one *episode*: a scenario in one condition, solved on
one branch of the experience store. Every trial the robot executes is written to
the store as it happens; the world model trains on every trial the branch can see
(the lifelong training set) and is refit during exploration, as the paper's agent
does within a scenario.

Before it explores, the agent tries what it already knows: when a plan step fails, it
re-plans from the perceived state without that ground action (the operator that failed
is demoted by its failure, see :func:`llcps.symbolic.knowledge.experience_cost`),
executes the repaired plan, and repeats up to :data:`MAX_PLAN_REPAIRS` times. Only when
no repaired plan reaches the goal does creative problem solving start, for the first step
that failed, a_f: the novelty is that a_f fails where K expected it to work, so
exploration looks for an alternative to a_f from the state a_f was executed in (the
snapshot stored before it), and a learned operator records that state as its context.
"""

from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence, TypeVar

import numpy as np

from llcps.cps.episode import SolveConfig, SolveResult
from llcps.cps.exploration import failure_point, rank_candidates
from llcps.cps.knowledge import load_experience, load_knowledge
from llcps.domain import PUSH_DIRECTION, ControllerParams, State, TrialChange, TrialRecord, TrialSpec
from llcps.errors import LlcpsError
from llcps.models.measures import get_measure
from llcps.models.persistence import fit_or_load
from llcps.outputs import GIF_SUFFIXES, check_output_file
from llcps.scenarios.base import Scenario
from llcps.scenarios.goal import goal_text
from llcps.sim.cache import CachedTrial, PhysicsCache, trial_key
from llcps.sim.controllers import DEFAULT_MAX_STEPS
from llcps.sim.perception import perceive
from llcps.sim.trial import TrialResult, run_trial
from llcps.sim.world import SavedState, World
from llcps.store import Store
from llcps.symbolic.experience import Context, Experience
from llcps.symbolic.knowledge_base import KnowledgeBase
from llcps.symbolic.task import Task
from llcps.symbolic.monitor import StepFailure, check_step
from llcps.symbolic.operators import learn_operator
from llcps.symbolic.planner import GroundAction, plan

#: Controller settings of K's own actions: the robot's nominal way of doing each.
NOMINAL_RATE = 0.4
NOMINAL_MAGNITUDE = 0.15
#: Push directions K may use to move an object toward a target ("top" tips it instead).
PUSH_DIRECTIONS = {k: v for k, v in PUSH_DIRECTION.items() if k != "top"}
#: Cap on steps of one settle/trial, as a safety net (240 Hz).
SETTLE_STEPS = 480
#: Re-plans after the first failed plan step before exploration starts.
MAX_PLAN_REPAIRS = 3

#: Per process: what was read from a world loaded from a serialized end state (and
#: perceived, where it was), by scene key, digest of the end state and query (see
#: Agent.remembered). Those reads are functions of the bytes and the scene alone.
_REMEMBERED: OrderedDict[tuple[object, ...], Any] = OrderedDict()
_REMEMBERED_CAPACITY = 2048  # up to ~40 kB a serialized state: at most ~80 MB


T = TypeVar("T")

ProgressCallback = Callable[[str, int, int], None]
"""Called as ``progress(phase, done, total)``: phase is "fit world model NAME", "plan",
"explore", "re-plan" or "render"; done and total count exploration trials (total 0: not
known yet), or frames while rendering."""


@dataclass(frozen=True)
class Failure:
    """A plan step that failed: the step a_f, what the monitor found missing, and the
    state it was executed from: perceived, as physics (serialized) and as a stored
    snapshot (None when the plan was not stored). Exploration looks for an alternative to
    a_f from that state."""

    step: GroundAction
    monitor: StepFailure
    state: State
    physics: bytes
    snapshot: int | None


@dataclass(frozen=True)
class PlanRun:
    """How a plan execution ended: the state after the last executed step and, if a step
    failed, the failure."""

    state: State
    failure: Failure | None = None


class Agent:
    """Executes trials in one world and records each one in the store."""

    def __init__(
        self,
        *,
        store: Store,
        branch: str,
        world: World,
        scenario: Scenario,
        config: SolveConfig,
        result: SolveResult,
        records: list[TrialRecord],
        cache: PhysicsCache | None = None,
        max_steps: int = DEFAULT_MAX_STEPS,
        progress: ProgressCallback | None = None,
        changes: dict[int, TrialChange] | None = None,
    ) -> None:
        self.store = store
        self.branch = branch
        self.world = world
        self.scenario = scenario
        self.config = config
        self.result = result
        self.records = records
        #: The known symbolic change of each trial in ``records``, by trial id.
        self.changes: dict[int, TrialChange] = {} if changes is None else changes
        self.kinds = {name: entity.spec.kind for name, entity in world.entities.items()}
        self.cache = cache
        self.progress = progress
        self._explore_total = 0
        #: The step cap of every trial: the one the physics runs under and the cache keys by.
        self.max_steps = max_steps
        # Physics state of each stored snapshot this episode took, by snapshot id.
        self._states: dict[int, bytes] = {}
        # The serialized end state of the last stored trial (a SavedState when this
        # process simulated it): the world continues from exactly these bytes, loaded
        # when it is next used (unless a restore comes first).
        self._pending: bytes | SavedState | None = None
        # Set when the world, still to be loaded from _pending, has also been perceived
        # (see perceive): the serialized state it then has.
        self._perceived: bytes | None = None
        # Operator executions as plan steps the branch sees, this episode's included.
        self.experience: Experience = load_experience(store, branch)

    def knowledge(self, kb: KnowledgeBase) -> KnowledgeBase:
        """``kb`` costed by the experience the branch has, this episode's included."""
        return kb.with_experience(self.experience)

    def record_execution(self, operator: str, context: Context, success: bool, trial_id: int | None) -> None:
        """Store one execution of ``operator`` as a plan step in ``context`` (see
        :mod:`llcps.symbolic.experience`); the operator's cost follows from the counts."""
        self.store.add_operator_execution(
            branch=self.branch,
            operator=operator,
            success=success,
            context=sorted(context),
            episode_id=self.result.episode_id,
            trial_id=trial_id,
        )
        self.experience = self.experience.added(operator, context, success)

    def report(self, phase: str, *, total: int | None = None) -> None:
        """Tell the progress callback the phase and the exploration trials done so far."""
        if total is not None:
            self._explore_total = total
        if self.progress is not None:
            self.progress(phase, self.result.exploration_trials, self._explore_total)

    # -- symbolic glue -------------------------------------------------------
    def task(self, state: State) -> Task:
        objects = {name: ("item" if kind == "object" else "container") for name, kind in self.kinds.items()}
        objects.update({name: "surface" for name in self.world.fixtures if name != "table"})
        return Task(objects=objects, init=state, goal_pos=self.scenario.goal_pos, goal_neg=self.scenario.goal_neg)

    def controller_call(self, step: GroundAction) -> TrialSpec:
        """Map a plan step to its controller call: learned settings, or K's nominal ones."""
        call = step.controller
        if call is None:
            raise LlcpsError(f"plan step {step.label} has no controller")
        orientation = "top"
        if call.action == "push" and call.toward is not None:
            obj, target = call.arguments[0], call.toward
            orientation = self.remembered(("toward", obj, target), lambda: self.orientation_toward(obj, target))
        return call.spec(ControllerParams(NOMINAL_RATE, NOMINAL_MAGNITUDE, orientation))

    def orientation_toward(self, obj: str, target: str) -> str:
        """K's push moves ``obj`` toward ``target``: the approach side whose push does."""
        a = np.asarray(self.world.center(obj)[:2])
        b = np.asarray(self.world.center(target)[:2])
        d = b - a
        return max(PUSH_DIRECTIONS, key=lambda k: float(np.dot(PUSH_DIRECTIONS[k], d)))

    # -- trials ----------------------------------------------------------------
    def execute(
        self, spec: TrialSpec, *, source: str, snapshot_id: int | None, start: int | None = None
    ) -> tuple[TrialResult, TrialRecord | None]:
        """Run one trial and store it durably.

        The trial starts from the stored snapshot ``start`` if given, else from the
        world's current state, which must then be the state of ``snapshot_id``. With
        ``snapshot_id=None`` the trial is not stored (nor answered by the cache).
        A stored trial leaves the world in its serialized end state, so what follows
        is the same whether the trial was simulated or answered by the physics cache;
        a cached answer is recorded as such, with this run's wall seconds.
        """
        started = time.perf_counter()
        cached: CachedTrial | None = None
        key: str | None = None
        if snapshot_id is not None and self.cache is not None:
            key = trial_key(self.world.settings, self.world.scene.to_dict(), self._states[snapshot_id], spec, self.max_steps)
            # The end state comes from the database: checked like a stored snapshot (a state
            # this process made, or checked before, or sealed by this machine costs a digest).
            cached = self.cache.get(key, check=self.world.check_serialized, trust=self.world.trust_serialized)
            if cached is not None and cached.result.spec != spec:  # a damaged entry: simulate instead
                cached = None
            if cached is None and start is None:
                start = snapshot_id  # a check may have rebuilt the world: start from the stored bytes
        if cached is not None:
            trial = cached.result
            self._continue_from(cached.end_state)
        else:
            if start is not None:
                self.restore(start)
            else:
                self.sync()
            trial = run_trial(self.world, spec, max_steps=self.max_steps)
            if snapshot_id is None:
                return trial, None
            # Continue from exactly the stored bytes; the restore waits until the world is
            # used again, and is skipped when a restore of another state comes first.
            self._continue_from(self.world.save())  # compressed only if stored or remembered
            if key is not None:
                self.cache.put(key, trial, self._serialized_pending())
        new = TrialRecord(
            branch=self.branch,
            source=source,
            spec=spec,
            features=trial.features,
            outcome=trial.outcome,
            solved=self.scenario.goal_reached(trial.after),
            sim_steps=trial.sim_steps,
            wall_seconds=trial.wall_seconds if cached is None else time.perf_counter() - started,
            cache_hit=cached is not None,
            simulation_wall_seconds=trial.wall_seconds,
            seed=self.config.seed,
            run_id=self.result.run_id,
            episode_id=self.result.episode_id,
            snapshot_id=snapshot_id,
            scenario=self.scenario.name,
        )
        change = trial.change
        trial_id = self.store.add_trial(new, change=change)
        record = replace(new, id=trial_id)
        self.records.append(record)
        self.changes[trial_id] = replace(change, trial_id=trial_id)
        self.result.sim_steps += trial.sim_steps
        if cached is not None:
            self.result.cache_hits += 1
        if source == "plan":
            self.result.plan_trials += 1
        elif source == "exploration":
            self.result.exploration_trials += 1
        return trial, record

    def snapshot(self) -> int:
        """Save the world's physics state in the store; returns the snapshot id."""
        state = self.checkpoint()
        stored = self.store.put_snapshot(scene=self.scene_record(), state=state)
        self._states[stored] = state
        return stored

    def checkpoint(self) -> bytes:
        """The world's state serialized (:meth:`World.serialize_state`'s bytes); the world
        continues from exactly these bytes, loaded when it is next used (see :meth:`sync`).

        With an end state still to be loaded, the bytes its restore would save are
        :meth:`remembered`: when the next trial is answered by the physics cache, the
        world is not rebuilt at all.
        """
        if self._perceived is not None:
            state = self._perceived
        else:
            state = self.remembered(("save",), self.world.save_state)
            if self._pending is not None:
                self.world.trust_serialized(state)  # this process saved it
        self._continue_from(state)
        return state

    def perceive(self) -> State:
        """The symbolic state of the world (:func:`~llcps.sim.perception.perceive`).

        Perception probes the arm (IK), which changes what the world saves next. With
        an end state still to be loaded, what it perceives and what the world then
        saves are :meth:`remembered`; nothing is loaded, :meth:`checkpoint` gives the
        saved bytes, and :meth:`sync` loads the end state and perceives it again.
        """
        if self._perceived is not None:
            self.sync()
        state, saved = self.remembered(("perceive",), lambda: (perceive(self.world), self.world.save_state()))
        if self._pending is not None:  # remembered: the world was not loaded
            self._perceived = saved
            self.world.trust_serialized(saved)  # this process saved it
        return state

    def remembered(self, query: tuple[object, ...], read: Callable[[], T]) -> T:
        """``read()`` of the world as it stands.

        While the world is still to be loaded from an end state, the result is a
        function of those bytes and the scene, so this process remembers it (bounded)
        under ``query`` and loads the world (:meth:`sync`) only the first time. ``read`` must not
        change what the world saves next, unless its caller accounts for it (see
        :meth:`perceive`).
        """
        if self._pending is None:
            return read()
        digest = hashlib.sha256(self._serialized_pending()).hexdigest()
        key = (self.world.scene_key, digest, self._perceived is not None, *query)
        if key in _REMEMBERED:
            _REMEMBERED.move_to_end(key)
            return _REMEMBERED[key]  # type: ignore[no-any-return]
        self.sync()
        value = read()
        _REMEMBERED[key] = value
        while len(_REMEMBERED) > _REMEMBERED_CAPACITY:
            _REMEMBERED.popitem(last=False)
        return value

    def scene_record(self) -> dict[str, object]:
        """The scene as a snapshot stores it: what the world is built from, and the task's goal,
        so that a trial replays (and is judged) from the store alone, whatever file it came from."""
        return {**self.world.scene.to_dict(), "goal": goal_text(self.scenario.goal_pos, self.scenario.goal_neg)}

    def restore(self, snapshot_id: int) -> None:
        """Return the world to a snapshot taken by :meth:`snapshot`."""
        self._pending = self._perceived = None
        self.world.restore_serialized(self._states[snapshot_id])

    def sync(self) -> None:
        """Bring the world to the serialized end state of the last stored trial (and
        perceived, if :meth:`perceive` was answered without it), if not done yet."""
        if self._pending is not None:
            state, perceived, self._pending, self._perceived = self._pending, self._perceived, None, None
            if isinstance(state, SavedState):
                self.world.restore_saved(state)
            else:
                self.world.restore_serialized(state)
            if perceived is not None:
                perceive(self.world)  # what it did to the world, again

    def _continue_from(self, state: bytes | SavedState) -> None:
        """The world goes on from exactly ``state``, loaded when it is next used."""
        self._pending, self._perceived = state, None

    def _serialized_pending(self) -> bytes:
        """The end state still to be loaded, as serialized bytes."""
        state = self._pending
        assert state is not None
        return state.serialized if isinstance(state, SavedState) else state

    def run_plan(
        self, steps: Sequence[GroundAction], *, store: bool = True, record: KnowledgeBase | None = None
    ) -> PlanRun:
        """Execute a plan step by step with the monitor; stop at the first failing step.

        The monitor checks the effects the plan relies on (causal links): those in the
        goal or needed by a later step's preconditions. A learned operator records every
        change it was seen to make; an incidental one (a neighbour nudged) need not
        recur for the plan to work. Reaching the goal ends the plan early.

        Args:
            steps: the plan.
            store: store each step as a ``plan`` trial (False: nothing is stored, e.g. to
                find where a plan fails).
            record: the knowledge base the plan was made with: count each step as an
                execution of its operator in its context (success or failure), which sets
                the operator's cost by experience. None: count nothing.
        """
        state = self.perceive()
        for index, step in enumerate(steps):
            spec = self.controller_call(step)
            if store:
                stored = self.snapshot()
                physics = self._states[stored]
            else:
                stored, physics = None, self.checkpoint()
            trial, record_ = self.execute(spec, source="plan", snapshot_id=stored)
            reached = self.scenario.goal_reached(trial.after)
            failure = None if reached else check_step(_relied_on(step, steps[index + 1 :], self.scenario), trial.after)
            if record is not None and store:
                context = record.context(step, trial.before)
                self.record_execution(step.name, context, failure is None, record_.id if record_ is not None else None)
            if reached:
                return PlanRun(trial.after)
            if failure is not None:
                return PlanRun(trial.after, Failure(step, failure, trial.before, physics, stored))
            state = trial.after
        return PlanRun(state)


def _relied_on(step: GroundAction, later: Sequence[GroundAction], scenario: Scenario) -> GroundAction:
    """``step`` with only the effects the goal or a later step's preconditions need."""
    needed_true = set(scenario.goal_pos).union(*(s.preconditions for s in later))
    needed_false = set(scenario.goal_neg).union(*(s.negative_preconditions for s in later))
    return replace(step, add=step.add & needed_true, delete=step.delete & needed_false)


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
        progress: optional callback for progress bars (see :data:`ProgressCallback`).
        cache: the physics cache (:mod:`llcps.store.physics_cache`), to answer trials
            simulated before without stepping the engine; what the episode records is
            the same with or without it, but for the trials marked ``cache_hit`` and
            their wall seconds.

    Returns:
        The episode summary; ``status`` is ``solved``, ``budget_exhausted``,
        ``no_plan`` or ``interrupted``.
    """
    scenario = config.validate()
    if gif is not None:
        check_output_file(gif, what="gif", suffixes=GIF_SUFFIXES)
    branch_name = store.resolve_branch(branch).name
    started = time.perf_counter()
    result = SolveResult(
        scenario=scenario.name,
        condition=config.condition,
        model=config.model,
        measure=config.measure,
        seed=config.seed,
        branch=branch_name,
        variant=config.variant,
    )
    # What the store holds is read (and checked) first: a malformed row stops the
    # episode before it records a run.
    if progress is not None:
        progress(f"fit world model {config.model}", 0, 0)
    records = list(store.visible_trials(branch_name))
    changes = store.visible_changes(branch_name)
    goal = get_measure(config.measure).uses_goal  # a measure ranking by Omega alone needs no goal head
    model = fit_or_load(store, branch_name, config.model, config.fit_seed, records=records, changes=changes, goal=goal)
    kb = load_knowledge(store, branch_name)
    result.run_id = store.start_run(
        command=command, seed=config.seed, config=_config_json(config), branch=branch_name
    )
    result.episode_id = store.start_episode(
        run_id=result.run_id,
        branch=branch_name,
        scenario=scenario.name,
        condition=config.condition,
        model=config.model,
        measure=config.measure,
        seed=config.seed,
    )
    world: World | None = None
    try:
        world = World.from_scene(scenario.scene(config.condition, config.variant), gui=gui)
        world.settle(max_steps=SETTLE_STEPS)
        agent = Agent(
            store=store,
            branch=branch_name,
            world=world,
            scenario=scenario,
            config=config,
            result=result,
            records=records,
            cache=cache,
            progress=progress,
            changes=changes,
        )
        _episode(agent, kb, model, result)
    except KeyboardInterrupt:
        result.status = "interrupted"
    finally:
        result.wall_seconds = time.perf_counter() - started
        result.sim_seconds = result.sim_steps * (world.time_step if world is not None else 1 / 240)
        if world is not None:
            world.close()
        if cache is not None:
            cache.flush()
        if result.status == "running":
            result.status = "error"
        store.finish_episode(result.episode_id, status=result.status, summary=result.as_json())
        store.finish_run(result.run_id, status=result.status)
    if gif is not None and result.status != "interrupted":
        from llcps.cps.film import film_episode

        film_episode(store, result.episode_id, gif, progress=progress)
    return result


def _episode(agent: Agent, kb: KnowledgeBase, model, result: SolveResult) -> None:
    """Plan with K and repair the plan; only if no plan reaches the goal, explore."""
    state = agent.perceive()
    if agent.scenario.goal_reached(state):
        result.status = "solved"
        return
    failure = plan_and_repair(agent, kb, state, result)
    if result.status == "solved":
        return
    if failure is None:
        result.status = "no_plan"
        return
    _explore(agent, kb, model, failure, result)


def plan_and_repair(
    agent: Agent, kb: KnowledgeBase, state: State, result: SolveResult, *, store: bool = True
) -> Failure | None:
    """Execute K's plan; on a failed step re-plan without it, up to MAX_PLAN_REPAIRS times.

    Every executed step is a stored ``plan`` trial and counts as an execution of its
    operator, so a step that fails is demoted before the re-plan. Sets ``result.plan``
    (K's first plan), ``result.plan_repairs`` and, when a plan reaches the goal,
    ``result.status``. With ``store=False`` nothing is stored or counted (the path
    ``llcps inspect model`` takes to the failure point); the failed steps are still left
    out of the re-plans.

    Returns:
        The first failure, or None when no step failed. Exploration looks for an
        alternative to its step a_f from the state a_f was executed in.
    """
    first: Failure | None = None
    excluded: set[tuple[str, tuple[str, ...]]] = set()
    for attempt in range(1 + MAX_PLAN_REPAIRS):
        agent.report("plan" if attempt == 0 else "re-plan")
        known = agent.knowledge(kb)
        steps = plan(known, agent.task(state), exclude=excluded)
        if steps is None:
            break
        labels = [step.label for step in steps]
        if attempt == 0:
            result.plan = labels
        run = agent.run_plan(steps, store=store, record=known)
        state, failure = run.state, run.failure
        if attempt > 0:
            result.plan_repairs.append(
                {
                    "plan": labels,
                    "failed_action": failure.step.label if failure is not None else None,
                    "missing_effects": failure.monitor.describe() if failure is not None else None,
                }
            )
        if failure is None:
            if agent.scenario.goal_reached(state):
                result.status = "solved"
            return first
        if first is None:
            result.failed_action = failure.step.label
            result.missing_effects = failure.monitor.describe()
            first = failure
        excluded.add((failure.step.name, failure.step.args))
    return first


def _explore(agent: Agent, kb: KnowledgeBase, model, failure: Failure, result: SolveResult) -> None:
    """Try ranked candidates from the failure snapshot until one resolves the novelty."""
    config = agent.config
    snapshot = failure.snapshot
    agent.restore(snapshot)
    point = failure_point(agent, failure.monitor, failure.state, kb)
    candidates = point.candidates
    result.candidates = len(candidates)
    remaining = list(range(len(candidates)))
    order = rank_candidates(model, point, measure=config.measure, seed=config.seed, indices=remaining).order
    agent.report("explore", total=min(config.budget, len(candidates)))
    tried = 0
    subgoal_failures = [0] * len(point.subgoals)  # trials that met a subgoal, and K's plan still failed
    while order and result.exploration_trials < config.budget:
        index = order.pop(0)
        remaining.remove(index)
        spec = candidates[index]
        trial, record = agent.execute(spec, source="exploration", snapshot_id=snapshot, start=snapshot)
        tried += 1
        agent.report("explore")
        if resolves(agent, kb, trial, failure):
            _learn(agent, kb, spec, trial, failure, record, result)
            return
        for k, subgoal in enumerate(point.subgoals):
            subgoal_failures[k] += subgoal.met(trial.after)
        if tried % config.refit_every == 0 and remaining:
            model.update(agent.records, agent.changes, start=snapshot)
            order = rank_candidates(
                model, point, measure=config.measure, seed=config.seed, indices=remaining, subgoal_failures=subgoal_failures
            ).order
    result.status = "budget_exhausted"


def _learn(
    agent: Agent,
    kb: KnowledgeBase,
    spec: TrialSpec,
    trial: TrialResult,
    failure: Failure,
    record: TrialRecord | None,
    result: SolveResult,
) -> None:
    """K -> K': store the operator the resolving trial teaches.

    Where a_f failed needs no lesson of its own: the failure, counted in a_f's context,
    keeps the planner from a_f there (:meth:`KnowledgeBase.allowed`), so it reaches for the
    learned operator, followed by the plan it enabled when the trial needed one.
    """
    learned = learn_operator(
        spec=spec,
        before=failure.state,
        after=trial.after,
        objects=agent.task(failure.state).objects,
        predicates=kb.predicates,
        focus=failure.step.args,
        replaces=failure.step.name,
    )
    definition = {"operator": learned.to_json(), "refinement": None}
    new_kb = kb.with_operator(learned)
    agent.store.add_operator(
        branch=agent.branch,
        name=learned.name,
        pddl=learned.to_pddl(cost=kb.nominal_cost(failure.step.name)),
        definition=definition,
        scenario=agent.scenario.name,
        episode_id=result.episode_id,
    )
    known = new_kb.skill(learned)
    step = new_kb.operator(known.name).ground(learned.source_arguments or ())
    context = new_kb.context(step, failure.state) if step is not None else frozenset()
    agent.record_execution(known.name, context, True, record.id if record is not None else None)
    result.learned_operators.append(learned.to_pddl(cost=agent.knowledge(new_kb).cost(known.name)))
    result.resolving_trial_id = record.id if record is not None else None
    result.status = "solved"


def resolves(agent: Agent, kb: KnowledgeBase, trial: TrialResult, failure: Failure) -> bool:
    """Did this trial resolve the novelty?

    A trial resolves it if the goal now holds, or if K (costed by experience) plans from
    the new state and that plan, executed, reaches the goal: a plan K made from the
    failure point itself started with a_f, which failed there, so a plan that works now
    works because of the trial. Only a trial that changed a fact about an entity of a_f
    or of the goal is followed by a re-plan: other changes cannot have made a plan work
    that did not before.
    """
    if agent.scenario.goal_reached(trial.after):
        return True
    focus = set(failure.step.args) | {t for atom in agent.scenario.goal_pos | agent.scenario.goal_neg for t in atom[1:]}
    changed = trial.after ^ failure.state
    if not any(focus.intersection(atom[1:]) for atom in changed):
        return False
    steps = plan(agent.knowledge(kb), agent.task(trial.after))
    if not steps:
        return False
    agent.report("re-plan")
    run = agent.run_plan(steps)
    return run.failure is None and agent.scenario.goal_reached(run.state)


def _config_json(config: SolveConfig) -> dict[str, object]:
    return {
        "scenario": config.scenario,
        "condition": config.condition,
        "model": config.model,
        "measure": config.measure,
        "seed": config.seed,
        "variant": config.variant,
        "model_seed": config.fit_seed,
        "budget": config.budget,
        "refit_every": config.refit_every,
    }


__all__ = ["Failure", "PlanRun", "SolveConfig", "SolveResult", "load_knowledge", "plan_and_repair", "solve"]
