"""Step-level motion: straight tool-point segments tracked by IK and joint motors.

Every step of a moving segment solves IK for the next point of the path and
commands the joint motors, then advances the physics one step: the same control
loop whose raw rate :func:`control_loop_rate` measures. Holding still needs no
new IK (motor targets persist), which keeps the cost of waiting close to the raw
physics step.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Callable, Sequence

from llcps.sim.robot import FINGER_FORCE, FINGER_OPEN, HOME, top_down
from llcps.sim.world import REST_CHECKS

if TYPE_CHECKING:
    from llcps.sim.world import World

#: Speed of approach and return motions (m/s); the action's own motion uses ``rate``.
TRANSIT_SPEED = 0.5
#: Speed of vertical descents onto an entity and of lifts (m/s).
VERTICAL_SPEED = 0.25
#: A segment is reached when the tool is this close to its end (m) ...
REACHED = 0.005
#: ... or after this many extra steps (the arm does its best, then moves on).
CONVERGE_STEPS = 48
#: Steps between checks of stop conditions and convergence.
CHECK_EVERY = 4


class CapReached(Exception):
    """The trial's step budget ran out."""


class Motion:
    """Drives the robot of one world for one trial, counting steps against a cap."""

    def __init__(self, world: "World", *, max_steps: int) -> None:
        self.world = world
        self.robot = world.robot
        self.max_steps = max_steps
        self.steps = 0
        # from the joints themselves: link poses cached by the engine may predate a restore
        self.target: list[float] = list(self.robot.tool_position(fresh=True))
        self.yaw = 0.0
        self._ik = self.robot.ik
        self._command = self.robot.command_arm

    def _tick(self) -> None:
        if self.steps >= self.max_steps:
            raise CapReached
        self.world.step()
        self.steps += 1

    def wait(self, n: int) -> None:
        """Hold the current motor targets for ``n`` steps."""
        for _ in range(n):
            self._tick()

    def wait_until(self, done: Callable[[], bool], *, max_steps: int) -> bool:
        """Hold still until ``done()`` (checked every few steps) or ``max_steps``."""
        taken = 0
        while taken < max_steps:
            self.wait(CHECK_EVERY)
            taken += CHECK_EVERY
            if done():
                return True
        return False

    def move_to(
        self,
        goal: Sequence[float],
        speed: float,
        *,
        yaw: float | None = None,
        until: Callable[[], bool] | None = None,
        converge: bool = True,
    ) -> bool:
        """Move the tool point along a straight line to ``goal`` at ``speed`` (m/s).

        Args:
            goal: tool-point position (m).
            speed: tool speed along the path (m/s).
            yaw: gripper yaw at the end of the segment (interpolated on the way).
            until: a stop condition checked every few steps; the segment ends early when true.
            converge: after the path, wait (briefly) for the tool to catch up.

        Returns:
            True when ``until`` stopped the segment early.
        """
        start = self.target
        gx, gy, gz = float(goal[0]), float(goal[1]), float(goal[2])
        dx, dy, dz = gx - start[0], gy - start[1], gz - start[2]
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        yaw0 = self.yaw
        yaw1 = yaw0 if yaw is None else yaw
        n = max(1, math.ceil(dist / (max(speed, 1e-6) * self.world.time_step)))
        ik, command, tick = self._ik, self._command, self._tick
        sx, sy, sz = start
        turning = yaw1 != yaw0
        orn = top_down(yaw1)
        for i in range(1, n + 1):
            f = i / n
            pos = (sx + f * dx, sy + f * dy, sz + f * dz)
            command(ik(pos, top_down(yaw0 + f * (yaw1 - yaw0)) if turning else orn))
            tick()
            if until is not None and i % CHECK_EVERY == 0 and until():
                # stop where the tool is, not where the (leading) target was
                tx, ty, _ = self.robot.tool_position()
                self.target = [tx, ty, pos[2]]
                self.yaw = yaw0 + f * (yaw1 - yaw0)
                command(ik(self.target, top_down(self.yaw)))
                return True
        self.target = [gx, gy, gz]
        self.yaw = yaw1
        if converge:
            self.converge()
        return False

    def converge(self) -> None:
        """Refine the arm's joint targets for the current tool target and wait until
        the tool is there (or CONVERGE_STEPS pass)."""
        self._command(self.robot.ik(self.target, top_down(self.yaw), iterations=60))
        goal = self.target
        self.wait_until(lambda: math.dist(self.robot.tool_position(), goal) < REACHED, max_steps=CONVERGE_STEPS)

    def wait_rest(self, *, max_steps: int) -> bool:
        """Hold still until every entity has been at rest for a few checks in a row."""
        quiet = 0

        def done() -> bool:
            nonlocal quiet
            quiet = quiet + 1 if self.world.at_rest() else 0
            return quiet >= REST_CHECKS

        return self.wait_until(done, max_steps=max_steps)

    def set_fingers(self, each: float, *, steps: int = 0) -> None:
        self.robot.command_fingers(each, force=FINGER_FORCE)
        self.wait(steps)

    def grasp(self, body: int, *, max_steps: int = 72) -> bool:
        """Close the fingers; attach ``body`` only once both fingers touch it."""
        robot = self.robot
        robot.command_fingers(0.0, force=FINGER_FORCE)
        if self.wait_until(lambda: robot.fingers_touch(body), max_steps=max_steps):
            self.wait(CHECK_EVERY)
            if robot.fingers_touch(body):
                robot.attach(body)
                return True
        return False

    def open_hand(self, *, steps: int = 24) -> None:
        """Release any grasp and open the fingers."""
        self.robot.release()
        self.set_fingers(FINGER_OPEN, steps=steps)

    def go_home(self, safe_z: float) -> None:
        """Rise to ``safe_z``, travel to above the home position, settle in HOME."""
        x, y, z = self.target
        if z < safe_z:
            self.move_to((x, y, safe_z), VERTICAL_SPEED, converge=False)
        hx, hy, hz = self.robot.home_tool
        self.move_to((hx, hy, max(hz, safe_z)), TRANSIT_SPEED, yaw=0.0, converge=False)
        self.move_to((hx, hy, hz), VERTICAL_SPEED, yaw=0.0, converge=False)
        self.robot.command_arm(HOME)
        self.wait(CONVERGE_STEPS // 2)


def control_loop_rate(world: "World", *, steps: int = 1200, clock: Callable[[], float] = time.perf_counter) -> float:
    """Raw control-loop rate of a world: IK + motor command + physics step per second.

    The tool circles over the table; the world is restored afterwards.

    Args:
        world: the scene to measure, in its current state.
        steps: loop iterations.
        clock: ``time.perf_counter`` for wall time; ``time.process_time`` for CPU
            time, which other processes on a busy machine do not inflate.

    Returns:
        Steps per second of ``clock``.
    """
    state = world.serialize_state()
    try:
        robot = world.robot
        hx, hy, hz = robot.home_tool
        orn = top_down(0.0)
        ik, command, step = robot.ik, robot.command_arm, world._step
        t0 = clock()
        for k in range(steps):
            a = k * world.time_step
            command(ik((hx + 0.1 * math.sin(a), hy + 0.1 * math.cos(a) - 0.1, hz - 0.1), orn))
            step()
        elapsed = clock() - t0
    finally:
        world.restore_serialized(state)
    return steps / elapsed
