"""The lifelong CPS agent: plan, execute with monitoring, explore on failure, learn K'.

One call of :func:`solve` is one *episode*: a scenario in one condition, solved on
one branch of the experience store. Every trial the robot executes is written to
the store as it happens; the world model trains on every trial the branch can see
(the lifelong training set) and is refit during exploration, as the paper's agent
does within a scenario.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from llcps.cps.episode import SolveConfig, SolveResult
from llcps.cps.exploration import failure_point, rank_candidates
from llcps.cps.knowledge import load_knowledge
from llcps.domain import PUSH_DIRECTION, ControllerParams, State, TrialChange, TrialRecord, TrialSpec
from llcps.errors import LlcpsError
from llcps.models.persistence import fit_or_load
from llcps.scenarios.base import Scenario
from llcps.sim.controllers import DEFAULT_MAX_STEPS
from llcps.sim.memo import TrialMemo, memo_key
from llcps.sim.perception import perceive
from llcps.sim.render import GifRecorder
from llcps.sim.trial import TrialResult, run_trial
from llcps.sim.world import World
from llcps.store import Store
from llcps.symbolic.knowledge import KnowledgeBase, Task
from llcps.symbolic.monitor import StepFailure, check_step
from llcps.symbolic.operators import learn_operator, refine_failed_action
from llcps.symbolic.planner import GroundAction, plan

#: Controller settings of K's own actions: the robot's nominal way of doing each.
NOMINAL_RATE = 0.4
NOMINAL_MAGNITUDE = 0.15
#: Push directions K may use to move an object toward a target ("top" tips it instead).
PUSH_DIRECTIONS = {k: v for k, v in PUSH_DIRECTION.items() if k != "top"}
#: Simulation steps between GIF frames (240 Hz / 8 = 30 frames per simulated second).
GIF_EVERY = 8
#: Cap on steps of one settle/trial, as a safety net (240 Hz).
SETTLE_STEPS = 480


ProgressCallback = Callable[[str, int, int], None]
"""Called as ``progress(phase, done, total)``; phase is "plan" or "explore"."""


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
        memo: TrialMemo | None = None,
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
        self.recorder: GifRecorder | None = None
        self.memo = memo
        # Physics state of each stored snapshot this episode took, by snapshot id.
        self._states: dict[int, bytes] = {}
        # End state of a trial answered by the memo, loaded when the world is next used.
        self._pending: bytes | None = None

    def filmed(self):
        """A context that records frames into the episode's GIF, if one was asked for."""
        return self.recorder if self.recorder is not None else contextlib.nullcontext()

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
            orientation = self.orientation_toward(call.arguments[0], call.toward)
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
        ``snapshot_id=None`` the trial is a re-enactment for a GIF: it is not stored.
        A stored trial leaves the world in its serialized end state, so what follows
        is the same whether the trial was simulated or answered by the memo.
        """
        trial: TrialResult | None = None
        key: bytes | None = None
        if snapshot_id is not None and self.memo is not None and self.recorder is None:
            key = memo_key(self.world.scene.to_dict(), self._states[snapshot_id], spec, DEFAULT_MAX_STEPS)
            cached = self.memo.get(key)
            if cached is not None:
                trial, self._pending = cached
        if trial is None:
            if start is not None:
                self.restore(start)
            else:
                self.sync()
            trial = run_trial(self.world, spec)
            if snapshot_id is None:
                return trial, None
            end = self.world.serialize_state()
            if key is not None:
                self.memo.put(key, trial, end)
        new = TrialRecord(
            branch=self.branch,
            source=source,
            spec=spec,
            features=trial.features,
            outcome=trial.outcome,
            solved=self.scenario.goal_reached(trial.after),
            sim_steps=trial.sim_steps,
            wall_seconds=trial.wall_seconds,
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
        if source == "plan":
            self.result.plan_trials += 1
        elif source == "exploration":
            self.result.exploration_trials += 1
        return trial, record

    def snapshot(self) -> int:
        """Save the world's physics state in the store; returns the snapshot id."""
        self.sync()
        state = self.world.serialize_state()
        stored = self.store.put_snapshot(scene=self.world.scene.to_dict(), state=state)
        self._states[stored] = state
        return stored

    def restore(self, snapshot_id: int) -> None:
        """Return the world to a snapshot taken by :meth:`snapshot`."""
        self._pending = None
        self.world.restore_serialized(self._states[snapshot_id])

    def sync(self) -> None:
        """Bring the world to the end state of the last trial, if the memo answered it."""
        if self._pending is not None:
            state, self._pending = self._pending, None
            self.world.restore_serialized(state)

    def run_plan(
        self, kb: KnowledgeBase, steps: Sequence[GroundAction], *, store: bool = True
    ) -> tuple[State, GroundAction | None, object]:
        """Execute a plan step by step with the monitor; stop at the first failing step.

        The monitor checks the effects the plan relies on (causal links): those in the
        goal or needed by a later step's preconditions. A learned operator records every
        change it was seen to make; an incidental one (a neighbour nudged) need not
        recur for the plan to work. Reaching the goal ends the plan early.
        """
        self.sync()
        state = perceive(self.world)
        for index, step in enumerate(steps):
            spec = self.controller_call(step)
            stored = self.snapshot() if store else None
            trial, _ = self.execute(spec, source="plan", snapshot_id=stored)
            state = trial.after
            if self.scenario.goal_reached(state):
                return state, None, None
            failure = check_step(_relied_on(step, steps[index + 1 :], self.scenario), state)
            if failure is not None:
                return state, step, failure
        return state, None, None


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
    memo: TrialMemo | None = None,
) -> SolveResult:
    """Solve one scenario on one branch; see the module docstring.

    Args:
        store: the experience store (trials, operators and models are read and written there).
        branch: branch name, ``None`` for the store's current branch.
        config: scenario, condition, world model, measure, seed, budget.
        command: the command line recorded with the run.
        gui: open a PyBullet GUI window (needs a display).
        gif: write the plan's execution and the resolving trial to this GIF.
        progress: optional callback for progress bars.
        memo: trials already simulated (:mod:`llcps.sim.memo`), to answer repeats without
            stepping the engine; what the episode records is the same with or without it.

    Returns:
        The episode summary; ``status`` is ``solved``, ``budget_exhausted``,
        ``no_plan`` or ``interrupted``.
    """
    scenario = config.validate()
    branch_name = store.resolve_branch(branch).name
    started = time.perf_counter()
    result = SolveResult(
        scenario=scenario.name,
        condition=config.condition,
        model=config.model,
        measure=config.measure,
        seed=config.seed,
        branch=branch_name,
    )
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
        records = list(store.visible_trials(branch_name))
        changes = store.visible_changes(branch_name)
        model = fit_or_load(store, branch_name, config.model, config.seed, records=records, changes=changes)
        kb = load_knowledge(store, branch_name)
        world = World.from_scene(scenario.scene(config.condition), gui=gui)
        world.settle(max_steps=SETTLE_STEPS)
        agent = Agent(
            store=store,
            branch=branch_name,
            world=world,
            scenario=scenario,
            config=config,
            result=result,
            records=records,
            memo=memo,
            changes=changes,
        )
        if gif is not None:
            agent.recorder = GifRecorder(world, every=GIF_EVERY)
        _episode(agent, kb, model, result, progress)
        if agent.recorder is not None and agent.recorder.frames:
            agent.recorder.save(gif, speedup=2.0)
    except KeyboardInterrupt:
        result.status = "interrupted"
    finally:
        result.wall_seconds = time.perf_counter() - started
        result.sim_seconds = result.sim_steps * (world.time_step if world is not None else 1 / 240)
        if world is not None:
            world.close()
        if result.status == "running":
            result.status = "error"
        store.finish_episode(result.episode_id, status=result.status, summary=result.as_json())
        store.finish_run(result.run_id, status=result.status)
    return result


@dataclass(frozen=True)
class PlanOutcome:
    """How executing K's plan went: ``solved``, ``no_plan``, or ``failed`` at ``failure``.

    Attributes:
        status: solved, no_plan or failed.
        plan: the plan's step labels.
        state: the symbolic state where execution stopped.
        failure: the failed step and its missing effects (status ``failed``).
    """

    status: str
    plan: tuple[str, ...] = ()
    state: State = frozenset()
    failure: StepFailure | None = None


def plan_to_failure(agent: Agent, kb: KnowledgeBase, *, store: bool = True) -> PlanOutcome:
    """Plan with K from what the robot perceives and execute under the monitor, up to
    the first failing step: where exploration starts (the agent's path, also taken by
    ``llcps inspect model`` without storing anything)."""
    state = perceive(agent.world)
    if agent.scenario.goal_reached(state):
        return PlanOutcome("solved", state=state)
    steps = plan(kb, agent.task(state))
    if steps is None:
        return PlanOutcome("no_plan", state=state)
    labels = tuple(step.label for step in steps)
    with agent.filmed():
        state, failed_step, failure = agent.run_plan(kb, steps, store=store)
    if failed_step is None:
        return PlanOutcome("solved" if agent.scenario.goal_reached(state) else "no_plan", labels, state)
    return PlanOutcome("failed", labels, state, failure)


def _episode(agent: Agent, kb: KnowledgeBase, model, result: SolveResult, progress) -> None:
    """Plan with K, execute with the monitor; at the first failure, explore (as the paper does)."""
    outcome = plan_to_failure(agent, kb)
    result.plan = list(outcome.plan)
    if outcome.failure is None:
        result.status = outcome.status
        return
    failure = outcome.failure
    result.failed_action = failure.step.label
    result.missing_effects = failure.describe()
    _explore(agent, kb, model, failure.step, failure, outcome.state, result, progress)


def _explore(agent: Agent, kb: KnowledgeBase, model, failed_step, failure, failure_state: State, result, progress):
    """Try ranked candidates from the failure snapshot until one resolves the novelty."""
    config = agent.config
    snapshot = agent.snapshot()
    point = failure_point(agent, failure, failure_state)
    candidates = point.candidates
    result.candidates = len(candidates)
    remaining = list(range(len(candidates)))
    order = rank_candidates(model, point, measure=config.measure, seed=config.seed, indices=remaining).order
    tried = 0
    while order and result.exploration_trials < config.budget:
        index = order.pop(0)
        remaining.remove(index)
        spec = candidates[index]
        trial, record = agent.execute(spec, source="exploration", snapshot_id=snapshot, start=snapshot)
        tried += 1
        if progress is not None:
            progress("explore", result.exploration_trials, min(config.budget, len(candidates)))
        resolved, needed_plan = _resolves(agent, kb, trial, failed_step, failure_state)
        if resolved:
            learned = learn_operator(
                spec=spec,
                before=failure_state,
                after=trial.after,
                objects=agent.task(failure_state).objects,
                focus=failed_step.args,
            )
            definition = {"operator": learned.to_json(), "refinement": None}
            new_kb = kb.with_operator(learned)
            if needed_plan:
                new_kb = refine_failed_action(new_kb, failed_step, learned, failure_state)
                definition["refinement"] = new_kb.refinement_of(failed_step.name)
            agent.store.add_operator(
                branch=agent.branch,
                name=learned.name,
                pddl=learned.to_pddl(),
                definition=definition,
                scenario=agent.scenario.name,
                episode_id=result.episode_id,
            )
            result.learned_operators.append(learned.to_pddl())
            result.resolving_trial_id = record.id
            result.status = "solved"
            if agent.recorder is not None:
                _film_resolution(agent, kb, spec, snapshot)
            return new_kb
        if tried % config.refit_every == 0 and remaining:
            model.update(agent.records, agent.changes)
            order = rank_candidates(model, point, measure=config.measure, seed=config.seed, indices=remaining).order
    result.status = "budget_exhausted"
    return kb


def _film_resolution(agent: Agent, kb: KnowledgeBase, spec: TrialSpec, snapshot: int) -> None:
    """Re-enact the resolving trial (and the plan it enabled) for the GIF; nothing is stored.

    Physics is deterministic from the snapshot, so the film shows what was recorded.
    """
    agent.restore(snapshot)
    with agent.filmed():
        trial, _ = agent.execute(spec, source="exploration", snapshot_id=None)
        if not agent.scenario.goal_reached(trial.after):
            steps = plan(kb, agent.task(trial.after)) or ()
            agent.run_plan(kb, steps, store=False)


def _resolves(
    agent: Agent,
    kb: KnowledgeBase,
    trial: TrialResult,
    failed_step: GroundAction,
    failure_state: State,
    *,
    store: bool = True,
) -> tuple[bool, bool]:
    """Did this trial resolve the novelty? Returns (resolved, through a re-plan).

    The novelty is that a_f fails. A trial resolves it if the goal now holds, or if
    it made a_f work: K plans from the new state through a_f, and that plan, executed,
    reaches the goal. (A plan around a_f with K's other actions is not a resolution:
    it would not need the trial.) A trial that changed no fluent is not re-planned.
    """
    if agent.scenario.goal_reached(trial.after):
        return True, False
    if trial.after == failure_state:
        return False, False
    steps = plan(kb, agent.task(trial.after))
    if not steps or not any(s.name == failed_step.name and s.args == failed_step.args for s in steps):
        return False, False
    state, failed, _ = agent.run_plan(kb, steps, store=store)
    return failed is None and agent.scenario.goal_reached(state), True


def _config_json(config: SolveConfig) -> dict[str, object]:
    return {
        "scenario": config.scenario,
        "condition": config.condition,
        "model": config.model,
        "measure": config.measure,
        "seed": config.seed,
        "budget": config.budget,
        "refit_every": config.refit_every,
    }


__all__ = ["PlanOutcome", "SolveConfig", "SolveResult", "load_knowledge", "plan_to_failure", "solve"]
