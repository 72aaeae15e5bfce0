"""The physics bound on a trial: raw step and control-loop rates of every scenario's scene.

A trial is a control loop (IK, motor commands, a physics step) run until the arm
settles, so the control-loop rate of a scene bounds the trials per second any agent
can run in it; the exploration group measures the agent against this bound.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial

from llcps.bench.core import Figure, Progress, figure, say
from llcps.sim.world import SETTLE_STEPS
from llcps.scenarios import SCENARIOS
from llcps.sim.motion import control_loop_rate
from llcps.sim.world import World

GROUP = "physics"
_figure = partial(figure, GROUP)


def settled_world(scenario: str, condition: str = "novelty") -> World:
    """The world of ``scenario``'s ``condition`` scene, settled as the agent settles it."""
    world = World.from_scene(SCENARIOS[scenario].scene(condition))
    world.settle(max_steps=SETTLE_STEPS)
    return world


def _raw_step_rate(world: World, steps: int, clock: Callable[[], float]) -> float:
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


def run(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Raw physics steps/s and control-loop (IK + motors + step) rate of each scenario's novelty scene."""
    steps = 600 if quick else 2400
    figures = []
    for name in SCENARIOS:
        say(progress, f"physics: {name}")
        world = settled_world(name)
        try:
            figures += [
                _figure("step_rate", _raw_step_rate(world, steps, time.process_time), "steps/s cpu", subject=name, note="world.step(), motors holding"),
                _figure("step_rate_wall", _raw_step_rate(world, steps, time.perf_counter), "steps/s wall", subject=name),
                _figure(
                    "control_loop",
                    control_loop_rate(world, steps=steps, clock=time.process_time),
                    "steps/s cpu",
                    subject=name,
                    note="IK + motor command + step: the bound of a moving arm",
                ),
                _figure("control_loop_wall", control_loop_rate(world, steps=steps), "steps/s wall", subject=name),
            ]
        finally:
            world.close()
    return figures


__all__ = ["GROUP", "run", "settled_world"]
