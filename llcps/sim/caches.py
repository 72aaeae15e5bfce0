"""What a process remembers about the simulator, forgotten in one call (tests start from
a new process's knowledge with it). Importing this module loads the physics engine."""

from __future__ import annotations

from llcps.sim import connection, robot, snapshot, state_check


def clear_caches() -> None:
    """Forget everything this process remembers about the simulator: idle connections
    (and the IK solutions of their robots), trusted states, parsed reference states and
    the Panda's files. What follows computes the same, only slower at first."""
    connection.POOL.clear()
    snapshot.TRUSTED.clear()
    state_check.clear_caches()
    robot.panda_urdf.cache_clear()
