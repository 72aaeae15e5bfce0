"""The lifelong CPS agent: plan, execute with monitoring, explore on failure, learn K'.

One call of :func:`solve` is one *episode*: a scenario in one condition, solved on
one branch of the experience store. Every trial the robot executes is written to
the store as it happens; the world model trains on every trial the branch can see
(the lifelong training set) and is refit during exploration, as the paper's agent
does within a scenario.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from llcps.cps.candidates import enumerate_candidates
from llcps.cps.episode import SolveConfig, SolveResult
from llcps.cps.knowledge import load_knowledge
from llcps.cps.outcomes import desired_outcome
from llcps.domain import ControllerParams, State, TrialRecord, TrialSpec, WorldModelInput
from llcps.errors import LlcpsError
from llcps.models.measures import rank
from llcps.models.persistence import fit_or_load
from llcps.scenarios.base import Scenario
from llcps.sim.controllers import DEFAULT_MAX_STEPS, PUSH_DIRECTION
from llcps.sim.memo import TrialMemo, memo_key
from llcps.sim.perception import entity_features, perceive
from llcps.sim.trial import TrialResult, run_trial
from llcps.sim.world import World
from llcps.store import Store
from llcps.symbolic.knowledge import KnowledgeBase, Task
from llcps.symbolic.monitor import check_step
from llcps.symbolic.operators import learn_operator, refine_failed_action
from llcps.symbolic.planner import GroundAction, plan

#: Controller settings of K's own actions: the robot's nominal way of doing each.
NOMINAL_RATE = 0.4
NOMINAL_MAGNITUDE = 0.15
#: Push directions K may use to move an object toward a target ("top" tips it instead).
PUSH_DIRECTIONS = {k: v for k, v in PUSH_DIRECTION.items() if k != "top"}
#: Cap on steps of one settle/trial, as a safety net (240 Hz).
SETTLE_STEPS = 480


ProgressCallback = Callable[[str, int, int], None]
"""Called as ``progress(phase, done, total)``: phase is "fit world model NAME", "plan",
"explore", "re-plan" or "render"; done and total count exploration trials (total 0: not
known yet), or frames while rendering."""


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
        progress: ProgressCallback | None = None,
    ) -> None:
        self.store = store
        self.branch = branch
        self.world = world
        self.scenario = scenario
        self.config = config
        self.result = result
        self.records = records
        self.kinds = {name: entity.spec.kind for name, entity in world.entities.items()}
        self.memo = memo
        self.progress = progress
        self._explore_total = 0
        # Physics state of each stored snapshot this episode took, by snapshot id.
        self._states: dict[int, bytes] = {}
        # End state of a trial answered by the memo, loaded when the world is next used.
        self._pending: bytes | None = None

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
        if snapshot_id is not None and self.memo is not None:
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
        trial_id = self.store.add_trial(new)
        record = replace(new, id=trial_id)
        self.records.append(record)
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
        gif: film the episode to this GIF afterwards (:func:`llcps.cps.film.film_episode`);
            the episode's stored wall time does not include it.
        progress: optional callback for progress bars (see :data:`ProgressCallback`).
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
        if progress is not None:
            progress(f"fit world model {config.model}", 0, 0)
        records = list(store.visible_trials(branch_name))
        model = fit_or_load(store, branch_name, config.model, config.fit_seed, records=records)
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
            progress=progress,
        )
        _episode(agent, kb, model, result)
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
    if gif is not None and result.status != "interrupted":
        from llcps.cps.film import film_episode

        film_episode(store, result.episode_id, gif, progress=progress)
    return result


def _episode(agent: Agent, kb: KnowledgeBase, model, result: SolveResult) -> None:
    """Plan with K, execute with the monitor; at the first failure, explore (as the paper does)."""
    agent.report("plan")
    state = perceive(agent.world)
    if agent.scenario.goal_reached(state):
        result.status = "solved"
        return
    steps = plan(kb, agent.task(state))
    if steps is None:
        result.status = "no_plan"
        return
    result.plan = [step.label for step in steps]
    state, failed_step, failure = agent.run_plan(kb, steps)
    if failed_step is None:
        result.status = "solved" if agent.scenario.goal_reached(state) else "no_plan"
        return
    result.failed_action = failed_step.label
    result.missing_effects = failure.describe()
    _explore(agent, kb, model, failed_step, failure, state, result)


def _explore(agent: Agent, kb: KnowledgeBase, model, failed_step, failure, failure_state: State, result):
    """Try ranked candidates from the failure snapshot until one resolves the novelty."""
    world, config = agent.world, agent.config
    snapshot = agent.snapshot()
    failed_spec = agent.controller_call(failed_step)
    candidates = enumerate_candidates(failed=failed_spec, entities=agent.kinds, grid=config.grid)
    result.candidates = len(candidates)
    features = {name: entity_features(world, name) for name in agent.kinds}
    inputs = [WorldModelInput(spec=c, features=tuple(features[a] for a in c.arguments)) for c in candidates]
    desired = desired_outcome(missing_add=failure.missing_add, missing_del=failure.missing_del)
    remaining = list(range(len(candidates)))
    order = _rank(model, inputs, remaining, config, desired)
    agent.report("explore", total=min(config.budget, len(candidates)))
    tried = 0
    while order and result.exploration_trials < config.budget:
        index = order.pop(0)
        remaining.remove(index)
        spec = candidates[index]
        trial, record = agent.execute(spec, source="exploration", snapshot_id=snapshot, start=snapshot)
        tried += 1
        agent.report("explore")
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
            return new_kb
        if tried % config.refit_every == 0 and remaining:
            model.update(agent.records)
            order = _rank(model, inputs, remaining, config, desired)
    result.status = "budget_exhausted"
    return kb


def _rank(model, inputs, remaining: list[int], config: SolveConfig, desired) -> list[int]:
    proba = model.predict_proba([inputs[i] for i in remaining])
    order = rank(proba, config.measure, seed=config.seed, desired=desired)
    return [remaining[i] for i in order]


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
    agent.report("re-plan")
    state, failed, _ = agent.run_plan(kb, steps, store=store)
    return failed is None and agent.scenario.goal_reached(state), True


def _config_json(config: SolveConfig) -> dict[str, object]:
    return {
        "scenario": config.scenario,
        "condition": config.condition,
        "model": config.model,
        "measure": config.measure,
        "seed": config.seed,
        "model_seed": config.fit_seed,
        "budget": config.budget,
        "refit_every": config.refit_every,
    }


__all__ = ["SolveConfig", "SolveResult", "solve", "load_knowledge"]
