"""How close each layer comes to the physics bound: the figures ``llcps bench`` prints.

llcps exists to run many exploration trials, and physics bounds how fast it can.
Each group below measures one layer with the code the agent itself runs and
returns :class:`Figure` rows; a figure with a ``target`` says whether it was met.
Figures are measurements to report (docs/performance.md), never test assertions.

Rates are given per second of *CPU time* of this process (``time.process_time``)
as well as of wall-clock time: other jobs on a shared machine slow the wall clock
but not the CPU time, so the CPU figures are the stable ones to compare.

Groups (``GROUPS``): ``physics`` (raw step and control-loop rates of every
scenario's scene), ``exploration`` (a real ``solve`` against the control-loop rate
of its scene), ``models`` (fit / update / predict of every registered world model),
``ranking`` (1,000 candidates under every measure), ``store`` (durable commits,
batched inserts, the visible set of a deep branch) and ``scaling`` (the smoke
experiment grid on 1 and 2 worker processes).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Self

#: Exploration episode of the bench: scenario 1's novelty on an empty store, the naive Bayes
#: model ranking by the paper's ``most-changes`` (the measure of the paper grid, whose cost
#: the bench is for). The episode must use its whole budget, so that what is timed does not
#: shrink when exploration gets better: the default ``goal-directed`` resolves this novelty
#: in 2 trials (4,222 physics steps, mostly start-up), ``most-changes`` spends 40 trials
#: without resolving it.
EXPLORE_SCENARIO = "scenario1"
EXPLORE_MEASURE = "most-changes"
EXPLORE_BUDGET = 20
EXPLORE_BUDGET_QUICK = 5
#: Control-loop steps of each measurement of the exploration group's bound.
BOUND_STEPS = 2400
#: A drift of the bound beyond this (after / before the episodes) marks a machine whose
#: speed changed during the group.
DRIFT_WARNING = 0.05
#: Workers of the scaling group that got less CPU time per wall second than this shared
#: their cores with other jobs.
CORE_SHARE_WARNING = 0.9
#: Trials the deepest branch of the store bench sees.
VISIBLE_TRIALS = 100_000
VISIBLE_TRIALS_QUICK = 10_000
#: Training-set sizes of the world-model timings.
MODEL_SIZES = (200, 2_000, 10_000)
MODEL_SIZES_QUICK = (200, 2_000)
#: The experiment preset whose grid the scaling group runs.
SCALING_PRESET = "smoke"

Progress = Callable[[str], None]
"""Called with a short description before each measurement."""


@dataclass(frozen=True)
class Figure:
    """One measured figure.

    Attributes:
        name: dotted name, group first (``store.commits_per_s``).
        value: the measurement (finite).
        unit: unit of ``value``.
        target: the goal, as text (``">= 1000"``), or None.
        met: whether ``value`` meets ``target`` (None without a target).
        note: what was measured, briefly.
    """

    name: str
    value: float
    unit: str
    target: str | None = None
    met: bool | None = None
    note: str = ""

    def as_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": self.value,
            "unit": self.unit,
            "target": self.target,
            "met": self.met,
            "note": self.note,
        }


def figure(name: str, value: float, unit: str, *, at_least: float | None = None, at_most: float | None = None, note: str = "") -> Figure:
    """A figure, with its target check when it has one."""
    value = float(value)
    if at_least is not None:
        return Figure(name, value, unit, f">= {at_least:g}", value >= at_least, note)
    if at_most is not None:
        return Figure(name, value, unit, f"<= {at_most:g}", value <= at_most, note)
    return Figure(name, value, unit, note=note)


class _Clock:
    """Wall and CPU seconds of a block."""

    def __enter__(self) -> Self:
        self._wall, self._cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc: object) -> None:
        self.wall = time.perf_counter() - self._wall
        self.cpu = time.process_time() - self._cpu


def _say(progress: Progress | None, text: str) -> None:
    if progress is not None:
        progress(text)


# --------------------------------------------------------------------------- physics
def _settled_world(scenario: str, condition: str = "novelty") -> Any:
    from llcps.cps.agent import SETTLE_STEPS
    from llcps.scenarios import SCENARIOS
    from llcps.sim.world import World

    world = World.from_scene(SCENARIOS[scenario].scene(condition))
    world.settle(max_steps=SETTLE_STEPS)
    return world


def _raw_step_rate(world: Any, steps: int, clock: Callable[[], float]) -> float:
    """``world.step()`` per second of ``clock``, motors holding; the state is restored."""
    state = world.serialize_state()
    try:
        step = world.step
        start = clock()
        for _ in range(steps):
            step()
        elapsed = clock() - start
    finally:
        world.restore_serialized(state)
    return steps / elapsed


def bench_physics(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Raw physics steps/s and control-loop (IK + motors + step) rate of each scenario's novelty scene."""
    from llcps.scenarios import SCENARIOS
    from llcps.sim.motion import control_loop_rate

    steps = 600 if quick else 2400
    figures = []
    for name in SCENARIOS:
        _say(progress, f"physics: {name}")
        world = _settled_world(name)
        try:
            figures += [
                figure(f"physics.{name}.step_rate", _raw_step_rate(world, steps, time.process_time), "steps/s cpu", note="world.step(), motors holding"),
                figure(f"physics.{name}.step_rate_wall", _raw_step_rate(world, steps, time.perf_counter), "steps/s wall"),
                figure(
                    f"physics.{name}.control_loop",
                    control_loop_rate(world, steps=steps, clock=time.process_time),
                    "steps/s cpu",
                    note="IK + motor command + step: the bound of a moving arm",
                ),
                figure(f"physics.{name}.control_loop_wall", control_loop_rate(world, steps=steps), "steps/s wall"),
            ]
        finally:
            world.close()
    return figures


# --------------------------------------------------------------------------- exploration
@dataclass(frozen=True)
class ExplorationRun:
    """One measured ``solve`` episode."""

    status: str
    sim_steps: int
    trials: int
    exploration_trials: int
    cpu_seconds: float
    wall_seconds: float


def run_exploration(
    budget: int, *, scenario: str = EXPLORE_SCENARIO, measure: str = EXPLORE_MEASURE, seed: int = 0
) -> ExplorationRun:
    """Solve ``scenario``'s novelty on a fresh temporary store; CPU and wall time of the whole episode.

    What a process pays once (importing the world model's library, compiling the
    PDDL parser for K, reading the shipped scenario files, connecting the physics
    engine, which closed worlds leave to the next) is paid before the clock starts:
    :func:`warm_up` measures it.
    """
    from llcps.cps.agent import solve
    from llcps.cps.episode import SolveConfig
    from llcps.store import Store

    config = SolveConfig(scenario=scenario, budget=budget, seed=seed, measure=measure)
    warm_up(config.model)
    with (
        tempfile.TemporaryDirectory(prefix="llcps-bench-") as tmp,
        Store.open(str(Path(tmp) / "bench.db"), create=True) as store,
        _Clock() as clock,
    ):
        result = solve(store, branch=None, config=config, command="bench")
    return ExplorationRun(
        status=result.status,
        sim_steps=result.sim_steps,
        trials=result.exploration_trials + result.plan_trials,
        exploration_trials=result.exploration_trials,
        cpu_seconds=clock.cpu,
        wall_seconds=clock.wall,
    )


def warm_up(model: str) -> float:
    """Pay the once-per-process costs of an episode; returns their CPU seconds (0 when already paid)."""
    from llcps.models.registry import WORLD_MODELS
    from llcps.scenarios import SCENARIOS
    from llcps.sim.world import World
    from llcps.symbolic.knowledge_base import KnowledgeBase

    start = time.process_time()
    WORLD_MODELS[model].model_class()
    KnowledgeBase.default()
    len(SCENARIOS)  # the shipped scenario files, read on first use
    World().close()  # the engine's connection (kept for the next world) and the Panda's private URDF
    return time.process_time() - start


@contextlib.contextmanager
def _cpu_in(targets: Sequence[tuple[type, str]]) -> Iterator[dict[str, float]]:
    """Count CPU seconds spent in some methods (``{"cpu": s, "calls": n}``) while the block runs.

    The methods are wrapped on their classes and put back afterwards. Calls made from
    inside a counted call are not counted twice.
    """
    counts = {"cpu": 0.0, "calls": 0.0}
    busy = [False]
    clock = time.process_time
    saved = [(cls, name, cls.__dict__[name]) for cls, name in targets]

    def counted(method: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            if busy[0]:
                return method(*args, **kwargs)
            busy[0] = True
            start = clock()
            try:
                return method(*args, **kwargs)
            finally:
                counts["cpu"] += clock() - start
                counts["calls"] += 1
                busy[0] = False

        return wrapper

    for cls, name, method in saved:
        setattr(cls, name, counted(method))
    try:
        yield counts
    finally:
        for cls, name, method in saved:
            setattr(cls, name, method)


def bench_exploration(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Sim steps/s and trials/s achieved in ``solve``, and efficiency against the control-loop rate.

    A second, instrumented run of the same episode splits its CPU time into the
    control loop (physics steps, IK, motor commands) and everything else the agent
    does; the wrappers cost a little, so its figures are not mixed with the first run's.
    """
    from llcps.cps.episode import SolveConfig
    from llcps.sim.motion import control_loop_rate
    from llcps.sim.robot import Robot
    from llcps.sim.world import World

    def bound(clock: Callable[[], float]) -> float:
        world = _settled_world(EXPLORE_SCENARIO)
        try:
            return control_loop_rate(world, steps=BOUND_STEPS, clock=clock)
        finally:
            world.close()

    load = os.getloadavg()[0]
    _say(progress, f"exploration: control-loop rate of {EXPLORE_SCENARIO}")
    before_cpu, bound_wall = bound(time.process_time), bound(time.perf_counter)
    startup = warm_up(SolveConfig(scenario=EXPLORE_SCENARIO).model)
    budget = EXPLORE_BUDGET_QUICK if quick else EXPLORE_BUDGET
    _say(progress, f"exploration: solve {EXPLORE_SCENARIO} novelty ({EXPLORE_MEASURE}), budget {budget}")
    run = run_exploration(budget)
    _say(progress, "exploration: the same episode, CPU time split by layer")
    with _cpu_in([(World, "step")]) as physics, _cpu_in([(Robot, "ik"), (Robot, "command_arm")]) as control:
        split = run_exploration(budget)
    _say(progress, f"exploration: control-loop rate of {EXPLORE_SCENARIO} again")
    after_cpu = bound(time.process_time)
    # The episodes ran between the two measurements of the bound: their mean is the
    # estimate of the bound the episodes met, and their difference says how steady
    # the machine's speed was meanwhile.
    bound_cpu = (before_cpu + after_cpu) / 2
    rate_cpu = run.sim_steps / run.cpu_seconds
    rate_wall = run.sim_steps / run.wall_seconds
    loop = physics["cpu"] + control["cpu"]
    p = "exploration"
    return [
        figure(f"{p}.sim_steps", run.sim_steps, "steps", note=f"{run.status}: {run.exploration_trials} exploration + {run.trials - run.exploration_trials} plan trials"),
        figure(f"{p}.sim_step_rate", rate_cpu, "steps/s cpu"),
        figure(f"{p}.sim_step_rate_wall", rate_wall, "steps/s wall"),
        figure(f"{p}.trial_rate", run.trials / run.cpu_seconds, "trials/s cpu"),
        figure(f"{p}.trial_rate_wall", run.trials / run.wall_seconds, "trials/s wall"),
        figure(f"{p}.control_loop", bound_cpu, "steps/s cpu", note="the bound: control-loop rate of the same scene, arm in free air (mean of before and after the episodes)"),
        figure(f"{p}.control_loop_before", before_cpu, "steps/s cpu"),
        figure(f"{p}.control_loop_after", after_cpu, "steps/s cpu"),
        figure(
            f"{p}.control_loop_drift",
            after_cpu / before_cpu - 1,
            "ratio",
            note=f"the bound after / before, minus 1: beyond +-{DRIFT_WARNING:.0%} the machine's speed changed during the group, and its ratios are uncertain by as much",
        ),
        figure(
            f"{p}.episode_drift",
            split.cpu_seconds / run.cpu_seconds - 1,
            "ratio",
            note=f"CPU of the instrumented run of the episode / the first, minus 1: the same episode twice, a few percent apart on a quiet machine; beyond +-{DRIFT_WARNING:.0%} the machine's speed changed between them",
        ),
        figure(f"{p}.load_average", load, "runnable", note=f"1-minute load average before the group, on {os.cpu_count()} CPUs"),
        figure(f"{p}.efficiency", rate_cpu / bound_cpu, "ratio", at_least=0.8, note="achieved steps/s / control-loop rate (CPU time)"),
        figure(f"{p}.efficiency_wall", rate_wall / bound_wall, "ratio", note="the same on the wall clock (disturbed by other jobs)"),
        figure(f"{p}.process_startup", startup, "s cpu", note="once per process, not charged above: model library import, K's PDDL parser, the shipped scenario files, the physics engine's connection"),
        figure(f"{p}.step_cost", 1e6 * physics["cpu"] / max(physics["calls"], 1), "us cpu", note="per physics step in the episode, contacts included"),
        figure(f"{p}.control_loop_cost", 1e6 / bound_cpu, "us cpu", note="per control-loop step in free air (IK + motors + step)"),
        figure(f"{p}.control_loop_share", loop / split.cpu_seconds, "ratio", note="episode CPU in physics steps, IK and motor commands (instrumented run)"),
        figure(
            f"{p}.efficiency_ceiling",
            (split.sim_steps / loop) / bound_cpu,
            "ratio",
            note="efficiency with no agent overhead: the control loop's rate in the scene (contacts) / in free air",
        ),
        figure(f"{p}.agent_overhead", (split.cpu_seconds - loop) / split.cpu_seconds, "ratio", note="episode CPU outside the control loop: restores, snapshots, perception, models, store, planner"),
    ]


# --------------------------------------------------------------------------- world models
#: Targets of ``update`` with one more trial at 10,000 trials (seconds) by model name.
UPDATE_TARGETS = {"nb": 0.020, "nn": 2.0}
#: Models timed once per size in the full run: a fit takes about a second or more, so the
#: minimum of three adds little but time.
SLOW_MODELS = ("nn", "logreg", "forest")


def bench_models(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Fit, update (+1 trial) and predict (1,000 candidates) of every registered model at each size.

    ``update`` is what the agent calls during exploration, and it is not the same work
    for every model: a refit on n + 1 trials for naive Bayes and the baselines, a
    fixed number of fine-tuning steps of the current weights for the network.

    Quick mode times the paper's models only, at 10,000 trials only where a target
    is set, with one repeat.
    """
    from llcps.models.benchmark import time_world_models
    from llcps.models.registry import PAPER_MODELS, WORLD_MODELS

    figures = []
    names = PAPER_MODELS if quick else tuple(WORLD_MODELS)
    for name in names:
        sizes = MODEL_SIZES_QUICK + ((10_000,) if name in UPDATE_TARGETS else ()) if quick else MODEL_SIZES
        _say(progress, f"models: {name} at {', '.join(map(str, sizes))} trials")
        WORLD_MODELS[name].model_class()  # import scikit-learn / torch before the clock starts
        repeats = 1 if quick or name in SLOW_MODELS else 3
        what = _update_note(name)
        for row in time_world_models([name], sizes, repeats=repeats):
            p = f"models.{name}.{row.n_trials}"
            target = UPDATE_TARGETS.get(name) if row.n_trials == 10_000 else None
            figures += [
                figure(f"{p}.fit", row.fit * 1e3, "ms"),
                figure(f"{p}.update", row.update * 1e3, "ms", at_most=None if target is None else target * 1e3, note=what),
                figure(f"{p}.predict", row.predict * 1e3, "ms", note="1,000 candidates"),
            ]
    # CPU time where it means the model's own work: naive Bayes runs on one thread (torch
    # uses several, so its CPU time would count each of them).
    _say(progress, "models: nb update at 10,000 trials in CPU time")
    (row,) = time_world_models(["nb"], (10_000,), repeats=5, clock=time.process_time)
    figures.append(figure("models.nb.10000.update_cpu", row.update * 1e3, "ms cpu", note="the same update in CPU time, steady on a busy machine"))
    return figures


def _update_note(name: str) -> str:
    """What ``update()`` with one more trial does for a model, truthfully."""
    from llcps.models.registry import WORLD_MODELS

    steps = getattr(WORLD_MODELS[name].model_class(), "update_steps", None)
    if steps is not None:
        return f"update() with one more trial: {steps} fine-tuning steps of the current weights, not a fit on n + 1"
    return "update() with one more trial: a refit on n + 1 trials"


def bench_ranking(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Ranking 1,000 candidates (given predictions) under every measure."""
    from llcps.models.benchmark import time_ranking
    from llcps.models.measures import MEASURES

    _say(progress, "ranking: 1,000 candidates")
    seconds = time_ranking(1000, repeats=3 if quick else 10)
    return [figure("ranking.all_measures_1000", seconds * 1e3, "ms", at_most=50, note=f"all {len(MEASURES)} measures")]


# --------------------------------------------------------------------------- store
def _trials(n: int, branch: str, start: int = 0, *, unique: bool = True) -> Iterator[Any]:
    """``n`` TrialRecords on ``branch``: a seeded pool of 997 cycled; with ``unique`` every
    trial's features are made distinct (the store's decoder shares repeated ones).
    """
    from llcps.domain import TrialRecord

    pool = _pool()
    for i in range(start, start + n):
        r = pool[i % len(pool)]
        first = r.features[0]
        features = (replace(first, volume=first.volume * (1.0 + i * 1e-9)),) + r.features[1:] if unique else r.features
        yield TrialRecord(
            branch=branch,
            source="pretrain",
            spec=r.spec,
            features=features,
            outcome=r.outcome,
            solved=r.solved,
            sim_steps=r.sim_steps,
            wall_seconds=r.wall_seconds,
            seed=i,
        )


_POOL: list[Any] = []
_POOL_CHANGES: dict[int, Any] = {}


def _pool() -> list[Any]:
    if not _POOL:
        from llcps.models.synthetic import synthetic_trials

        _POOL.extend(synthetic_trials(997, seed=7))
    return _POOL


def _changes(n: int, start: int = 0) -> list[Any]:
    """The symbolic changes of :func:`_trials`'s trials, each in a scene of its own (as in
    pretraining: the first body moved by a trial-specific amount), so none is shared."""
    from llcps.domain import Body
    from llcps.models.synthetic import synthetic_changes

    pool = _pool()
    if not _POOL_CHANGES:
        _POOL_CHANGES.update(synthetic_changes(pool, seed=7))
    out = []
    for i in range(start, start + n):
        change = _POOL_CHANGES[pool[i % len(pool)].id]
        first = change.bodies[0]
        moved = Body(first.name, first.kind, first.shape, (first.lo[0] + i * 1e-9, *first.lo[1:]), first.hi, first.centre)
        out.append(replace(change, bodies=(moved, *change.bodies[1:]), trial_id=None))
    return out


def _deep_branch(path: Path, visible: int, *, unique: bool, repeats: int) -> tuple[int, float, list[_Clock], list[_Clock]]:
    """Fill main <- level1 <- level2 <- level3 (a quarter each) in batches, then load level3's visible set.

    With ``unique`` every trial also gets a symbolic change of its own, and the changes
    level3 sees are loaded too (what a fit reads beside the trials).

    Returns (trials seen, batched inserts/s of the trials alone, one clock per load of
    the trials, one per load of the changes).
    """
    from llcps.store import Store

    batch = 5000
    chain = ("main", "level1", "level2", "level3")
    inserted, wall = 0, 0.0
    with Store.open(str(path), create=True) as store:
        for level, name in enumerate(chain):
            if level:
                store.create_branch(name, from_branch=chain[level - 1])
            share = visible // len(chain) if level < len(chain) - 1 else visible - inserted
            while share > 0:
                rows = list(_trials(min(batch, share), name, start=inserted, unique=unique))
                if unique:
                    store.add_trials(rows, changes=_changes(len(rows), start=inserted))
                else:
                    with _Clock() as clock:
                        store.add_trials(rows)
                    wall += clock.wall
                inserted += len(rows)
                share -= len(rows)
        loads = []
        for _ in range(repeats):
            with _Clock() as load:
                records = store.visible_trials(chain[-1])
            seen = len(records)
            del records  # freeing 100,000 records (~0.1 s) is not part of loading them
            loads.append(load)
        change_loads = []
        for _ in range(repeats if unique else 0):
            with _Clock() as load:
                changes = store.visible_changes(chain[-1])
            del changes
            change_loads.append(load)
    return seen, inserted / wall if wall else float("nan"), loads, change_loads


def bench_store(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Durable single-trial commits, batched inserts, and the visible set of a branch three levels deep.

    The visible set is loaded twice: with every trial's features distinct (pretraining
    trials, each from its own random scene: the decoder's worst case) and with
    features repeated as in exploration (one scene per episode). The first also holds
    each trial's symbolic change, in a scene of its own, and loads those as well.
    """
    from llcps.store import Store

    commits = 300 if quick else 1000
    visible = VISIBLE_TRIALS_QUICK if quick else VISIBLE_TRIALS
    repeats = 2
    target = 1.0 if visible == VISIBLE_TRIALS else None
    with tempfile.TemporaryDirectory(prefix="llcps-bench-") as tmp:
        with Store.open(str(Path(tmp) / "commits.db"), create=True) as store:
            _say(progress, f"store: {commits} single-trial commits")
            one_by_one = list(_trials(commits, "main"))
            with _Clock() as single:
                for trial in one_by_one:
                    store.add_trial(trial)
        _say(progress, f"store: a branch 3 levels deep seeing {visible:,} trials with distinct features")
        seen, _, unique, changes = _deep_branch(Path(tmp) / "unique.db", visible, unique=True, repeats=repeats)
        _say(progress, f"store: a branch 3 levels deep seeing {visible:,} trials with repeated features")
        _, batched, shared, _ = _deep_branch(Path(tmp) / "shared.db", visible, unique=False, repeats=repeats)
    p = "store"
    return [
        figure(f"{p}.commits_per_s", commits / single.wall, "trials/s wall", at_least=1000, note="add_trial one at a time, each durable on return"),
        figure(f"{p}.batched_inserts_per_s", batched, "trials/s wall", note="add_trials, 5,000 per transaction (trials without changes)"),
        figure(f"{p}.visible_trials", seen, "trials", note="seen by a branch 3 levels deep"),
        figure(f"{p}.visible_load", min(c.wall for c in unique), "s wall", at_most=target, note="every trial's features distinct (pretraining)"),
        figure(f"{p}.visible_load_cpu", min(c.cpu for c in unique), "s cpu"),
        figure(f"{p}.visible_load_shared", min(c.wall for c in shared), "s wall", note="features repeated (exploration in one scene)"),
        figure(f"{p}.visible_load_shared_cpu", min(c.cpu for c in shared), "s cpu"),
        figure(f"{p}.visible_changes_load", min(c.wall for c in changes), "s wall", note="the same trials' symbolic changes, each in a scene of its own: what a fit reads beside them"),
        figure(f"{p}.visible_changes_load_cpu", min(c.cpu for c in changes), "s cpu"),
    ]


# --------------------------------------------------------------------------- scaling
@dataclass(frozen=True)
class ExperimentRun:
    """One run of the scaling grid: wall seconds, summed task seconds, CPU seconds of all processes."""

    wall: float
    task_seconds: float
    cpu: float
    status: str


def run_scaling_grid(workers: int, *, preset: str = SCALING_PRESET, cache: bool = True) -> ExperimentRun:
    """Run ``preset``'s experiment grid into a fresh temporary store on ``workers`` processes.

    With ``cache`` the workers share the store's physics cache, cold at the start.
    """
    import resource

    from llcps.experiments.runner import run_experiment
    from llcps.store import Store

    def children() -> float:
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)  # workers are reaped when the pool closes
        return usage.ru_utime + usage.ru_stime

    cpu0, kids0 = time.process_time(), children()
    with tempfile.TemporaryDirectory(prefix="llcps-bench-") as tmp, Store.open(str(Path(tmp) / "bench.db"), create=True) as store:
        summary = run_experiment(store, preset=preset, workers=workers, cache=cache)
    cpu = time.process_time() - cpu0 + children() - kids0
    return ExperimentRun(summary.wall_seconds, sum(summary.task_seconds.values()), cpu, summary.status)


def bench_scaling(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """The smoke experiment grid on 1 and 2 worker processes (wall time) and the speed-up,
    with the physics cache (cold at the start of each grid) and without it.

    Worker processes are spawned, so a script calling this needs the
    ``if __name__ == "__main__":`` guard.
    """
    from llcps.errors import LlcpsError

    load_before = os.getloadavg()[0]
    runs = {}
    for cache in (True, False):
        for workers in (1, 2):
            _say(progress, f"scaling: {SCALING_PRESET} grid on {workers} worker(s){'' if cache else ', no physics cache'}")
            run = run_scaling_grid(workers, cache=cache)
            if run.status != "ok":
                raise LlcpsError(f"the {SCALING_PRESET} experiment ended {run.status} on {workers} worker(s)")
            runs[workers, cache] = run
    figures = []
    for (workers, cache), run in runs.items():
        p = f"scaling.workers{workers}" + ("" if cache else ".no_cache")
        figures += [
            figure(p, run.wall, "s wall", note=f"{SCALING_PRESET} preset grid"),
            figure(f"{p}.task_seconds", run.task_seconds, "s wall", note="the tasks' own wall seconds, summed"),
            figure(f"{p}.cpu", run.cpu, "s cpu", note="this process and its workers"),
            figure(f"{p}.core_share", run.cpu / (run.wall * workers), "ratio", note="CPU seconds per worker per wall second: below 1, the cores were busy elsewhere"),
        ]
    return figures + [
        figure("scaling.speedup", runs[1, True].wall / runs[2, True].wall, "ratio", at_least=1.7, note="1-worker / 2-worker wall time"),
        figure(
            "scaling.speedup_no_cache",
            runs[1, False].wall / runs[2, False].wall,
            "ratio",
            note="the same without the physics cache: one worker alone gets the cache hits of a twin run before",
        ),
        figure("scaling.load_average", load_before, "runnable", note=f"1-minute load average before, on {os.cpu_count()} CPUs"),
        figure("scaling.load_average_after", os.getloadavg()[0], "runnable"),
    ]


# --------------------------------------------------------------------------- all
GROUPS: dict[str, Callable[[bool, Progress | None], list[Figure]]] = {
    "physics": bench_physics,
    "exploration": bench_exploration,
    "models": bench_models,
    "ranking": bench_ranking,
    "store": bench_store,
    "scaling": bench_scaling,
}
#: Groups left out of ``--quick``: the experiment grid alone takes more than a minute.
SLOW_GROUPS: tuple[str, ...] = ("scaling",)


def run_bench(*, quick: bool = False, groups: Sequence[str] | None = None, progress: Progress | None = None) -> list[Figure]:
    """Run the chosen groups (default: all; with ``quick`` all but :data:`SLOW_GROUPS`).

    Raises:
        UnknownNameError: for a group not in :data:`GROUPS`.
    """
    from llcps.errors import UnknownNameError

    if groups is None:
        groups = [g for g in GROUPS if not (quick and g in SLOW_GROUPS)]
    for name in groups:
        if name not in GROUPS:
            raise UnknownNameError("bench group", name, list(GROUPS))
    figures: list[Figure] = []
    for name in groups:
        figures += GROUPS[name](quick, progress)
    return judged(figures)


def _unsteadiness(figures: Sequence[Figure]) -> Iterator[tuple[str, str]]:
    """(group, what was not steady, in words) for each sign in ``figures`` that the
    machine's speed did not hold while they were taken (see :func:`unsteady`)."""
    for f in figures:
        group = f.name.split(".", 1)[0]
        where, sign = f.name.rsplit(".", 1)  # e.g. "scaling.workers2", "core_share"
        if sign == "control_loop_drift" and abs(f.value) > DRIFT_WARNING:
            yield group, (
                f"the control-loop bound of {where} moved by {f.value:+.1%} between before and after its episodes:"
                f" its ratios are uncertain by as much; run it again on a quieter machine"
            )
        elif sign == "episode_drift" and abs(f.value) > DRIFT_WARNING:
            yield group, (
                f"the second run of {where}'s episode took {f.value:+.1%} the CPU of the first: the machine's speed"
                f" changed while it ran, and its ratios are uncertain by as much; run it again on a quieter machine"
            )
        elif sign == "core_share" and f.value < CORE_SHARE_WARNING:
            yield group, f"{where} got {f.value:.2f} of its cores (other jobs ran beside it): its wall times and the speed-up are low"


def unsteady(figures: Sequence[Figure]) -> list[str]:
    """What in ``figures`` says the machine was not steady while they were taken, in words.

    The bench's ratios compare measurements taken one after the other, so they hold
    only while the machine's speed holds: a bound that drifted beyond
    :data:`DRIFT_WARNING` between before and after its episodes, the same episode
    run twice at CPU costs that far apart, or workers that got
    less than :data:`CORE_SHARE_WARNING` of their cores, make a figure worth taking again.
    """
    return [said for _, said in _unsteadiness(figures)]


#: What a target figure of an unsteady group says instead of met or missed.
NOT_JUDGED = "not judged: the machine's speed changed while its group ran (see the warning); run it again on a quieter machine"


def judged(figures: Sequence[Figure]) -> list[Figure]:
    """``figures`` with the target checks of unsteady groups withdrawn (``met`` None).

    A ratio taken while the machine's speed moved by more than the warning's threshold
    is uncertain by as much, so it can neither meet nor miss a target: a bound that
    fell by 39 % during the episodes once gave an efficiency of 0.95.
    """
    shaky = {group for group, _ in _unsteadiness(figures)}
    return [
        replace(f, met=None, note=f"{f.note}; {NOT_JUDGED}" if f.note else NOT_JUDGED)
        if f.target is not None and f.name.split(".", 1)[0] in shaky
        else f
        for f in figures
    ]


__all__ = [
    "GROUPS",
    "SLOW_GROUPS",
    "Figure",
    "figure",
    "judged",
    "run_bench",
    "run_exploration",
    "run_scaling_grid",
    "unsteady",
    "warm_up",
]
