"""The cost of an exploration episode: a real ``solve`` against the control-loop rate of its scene.

The efficiency is the episode's physics steps per CPU second over the scene's
control-loop rate (:mod:`llcps.bench.physics`), the bound measured before and after
the episodes; a second, instrumented run of the same episode splits its CPU time
into the control loop and everything else the agent does.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from llcps.bench.core import DRIFT_WARNING, Clock, Figure, Progress, figure, say
from llcps.bench.physics import settled_world
from llcps.cps.episode import solve
from llcps.cps.episode import SolveConfig
from llcps.models.registry import WORLD_MODELS
from llcps.scenarios import SCENARIOS
from llcps.sim.motion import control_loop_rate
from llcps.sim.robot import Robot
from llcps.sim.world import World
from llcps.store import Store
from llcps.symbolic.knowledge_base import KnowledgeBase

GROUP = "exploration"
_figure = partial(figure, GROUP)

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
    config = SolveConfig(scenario=scenario, budget=budget, seed=seed, measure=measure)
    warm_up(config.model)
    with (
        tempfile.TemporaryDirectory(prefix="llcps-bench-") as tmp,
        Store.open(str(Path(tmp) / "bench.db"), create=True) as store,
        Clock() as clock,
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


def _bound(clock: Callable[[], float]) -> float:
    """Control-loop rate of the episode's scene, arm in free air, in steps per second of ``clock``."""
    world = settled_world(EXPLORE_SCENARIO)
    try:
        return control_loop_rate(world, steps=BOUND_STEPS, clock=clock)
    finally:
        world.close()


def run(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Sim steps/s and trials/s achieved in ``solve``, and efficiency against the control-loop rate.

    A second, instrumented run of the same episode splits its CPU time into the
    control loop (physics steps, IK, motor commands) and everything else the agent
    does; the wrappers cost a little, so its figures are not mixed with the first run's.
    """
    load = os.getloadavg()[0]
    say(progress, f"exploration: control-loop rate of {EXPLORE_SCENARIO}")
    before_cpu, bound_wall = _bound(time.process_time), _bound(time.perf_counter)
    startup = warm_up(SolveConfig(scenario=EXPLORE_SCENARIO).model)
    budget = EXPLORE_BUDGET_QUICK if quick else EXPLORE_BUDGET
    say(progress, f"exploration: solve {EXPLORE_SCENARIO} novelty ({EXPLORE_MEASURE}), budget {budget}")
    episode = run_exploration(budget)
    say(progress, "exploration: the same episode, CPU time split by layer")
    with _cpu_in([(World, "step")]) as physics, _cpu_in([(Robot, "ik"), (Robot, "command_arm")]) as control:
        split = run_exploration(budget)
    say(progress, f"exploration: control-loop rate of {EXPLORE_SCENARIO} again")
    after_cpu = _bound(time.process_time)
    # The episodes ran between the two measurements of the bound: their mean is the
    # estimate of the bound the episodes met, and their difference says how steady
    # the machine's speed was meanwhile.
    bound_cpu = (before_cpu + after_cpu) / 2
    rate_cpu = episode.sim_steps / episode.cpu_seconds
    rate_wall = episode.sim_steps / episode.wall_seconds
    loop = physics["cpu"] + control["cpu"]
    plan_trials = episode.trials - episode.exploration_trials
    return [
        _figure("sim_steps", episode.sim_steps, "steps", note=f"{episode.status}: {episode.exploration_trials} exploration + {plan_trials} plan trials"),
        _figure("sim_step_rate", rate_cpu, "steps/s cpu"),
        _figure("sim_step_rate_wall", rate_wall, "steps/s wall"),
        _figure("trial_rate", episode.trials / episode.cpu_seconds, "trials/s cpu"),
        _figure("trial_rate_wall", episode.trials / episode.wall_seconds, "trials/s wall"),
        _figure("control_loop", bound_cpu, "steps/s cpu", note="the bound: control-loop rate of the same scene, arm in free air (mean of before and after the episodes)"),
        _figure("control_loop_before", before_cpu, "steps/s cpu"),
        _figure("control_loop_after", after_cpu, "steps/s cpu"),
        _figure(
            "control_loop_drift",
            after_cpu / before_cpu - 1,
            "ratio",
            note=f"the bound after / before, minus 1: beyond +-{DRIFT_WARNING:.0%} the machine's speed changed during the group, and its ratios are uncertain by as much",
        ),
        _figure(
            "episode_drift",
            split.cpu_seconds / episode.cpu_seconds - 1,
            "ratio",
            note=f"CPU of the instrumented run of the episode / the first, minus 1: the same episode twice, a few percent apart on a quiet machine; beyond +-{DRIFT_WARNING:.0%} the machine's speed changed between them",
        ),
        _figure("load_average", load, "runnable", note=f"1-minute load average before the group, on {os.cpu_count()} CPUs"),
        _figure("efficiency", rate_cpu / bound_cpu, "ratio", at_least=0.8, note="achieved steps/s / control-loop rate (CPU time)"),
        _figure("efficiency_wall", rate_wall / bound_wall, "ratio", note="the same on the wall clock (disturbed by other jobs)"),
        _figure("process_startup", startup, "s cpu", note="once per process, not charged above: model library import, K's PDDL parser, the shipped scenario files, the physics engine's connection"),
        _figure("step_cost", 1e6 * physics["cpu"] / max(physics["calls"], 1), "us cpu", note="per physics step in the episode, contacts included"),
        _figure("control_loop_cost", 1e6 / bound_cpu, "us cpu", note="per control-loop step in free air (IK + motors + step)"),
        _figure("control_loop_share", loop / split.cpu_seconds, "ratio", note="episode CPU in physics steps, IK and motor commands (instrumented run)"),
        _figure(
            "efficiency_ceiling",
            (split.sim_steps / loop) / bound_cpu,
            "ratio",
            note="efficiency with no agent overhead: the control loop's rate in the scene (contacts) / in free air",
        ),
        _figure("agent_overhead", (split.cpu_seconds - loop) / split.cpu_seconds, "ratio", note="episode CPU outside the control loop: restores, snapshots, perception, models, store, planner"),
    ]


__all__ = [
    "BOUND_STEPS",
    "EXPLORE_BUDGET",
    "EXPLORE_BUDGET_QUICK",
    "EXPLORE_MEASURE",
    "EXPLORE_SCENARIO",
    "GROUP",
    "ExplorationRun",
    "run",
    "run_exploration",
    "warm_up",
]
