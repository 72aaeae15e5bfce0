"""The world and the robot's hands and eyes: the sub-symbolic knowledge base Psi of the paper.

- The world: a PyBullet simulation of the table, the Panda arm and the scenario's
  entities (:mod:`~llcps.sim.world`, built from plain scene descriptions in
  :mod:`~llcps.sim.specs`), with exact snapshots (:mod:`~llcps.sim.snapshot`).
- The action controllers R, one per action of K (push, push_together,
  remove_from_container, place_in_container), each with its continuous settings
  (:mod:`~llcps.sim.controllers`, on the motions of :mod:`~llcps.sim.motion`).
- Perception of fluents: the symbolic state s (visible, reachable, touching, on, in,
  holding, near) read from the simulation, and the entity features X of Table 1
  (:mod:`~llcps.sim.perception`); a trial runs a controller between two perceptions
  and yields its meta-outcome Omega (:mod:`~llcps.sim.trial`).
- Random pretraining interactions (:mod:`~llcps.sim.sampler`).

See docs/world.md and docs/controllers.md.
"""

from __future__ import annotations

import contextlib
import os
import sys
from typing import Iterator

#: Revision of llcps's own controllers, motion primitives, robot model and perception.
#: Raise it with any change that alters what a trial computes from the same scene,
#: state and call: the physics cache keys every trial by it (together with the
#: engine's settings), so trials simulated by older code are never reused.
CONTROLLERS_REVISION = 1


@contextlib.contextmanager
def native_output_silenced() -> Iterator[None]:
    """Discard what native code writes to file descriptors 1 and 2 meanwhile.

    The physics engine prints a banner when imported and a line when a client
    connects; stdout carries ``--json`` data and stderr llcps's own messages.
    """
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = (os.dup(1), os.dup(2))
    except (OSError, ValueError):  # no real file descriptors (captured): nothing to protect
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


def clear_caches() -> None:
    """Forget everything this process remembers about the simulator: idle connections
    (and the IK solutions of their robots), trusted states, parsed reference states and
    the Panda's files. What follows computes the same, only slower at first."""
    # Imported here: importing llcps.sim must not load the physics engine.
    from llcps.sim import connection, robot, snapshot, state_check

    connection.POOL.clear()
    snapshot.TRUSTED.clear()
    state_check.clear_caches()
    robot.panda_urdf.cache_clear()
