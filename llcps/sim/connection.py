"""Connections to the physics engine, and the pool that passes them from world to world.

A :class:`Connection` is one PyBullet client with what lasts as long as it: the files
its states are saved and restored through (:mod:`llcps.sim.state_files`; the engine
keeps every file it read, so they must stay with it) and the IK solutions of the
Panda built in it (:class:`~llcps.sim.robot.ReachSolutions`).

Connecting costs more than rebuilding a scene, and an episode builds a world, so a
closed world leaves its headless connection to the next world of the process
(:class:`ConnectionPool`); the next world rebuilds it from its own scene.
"""

from __future__ import annotations

import os

from pybullet_utils import bullet_client

from llcps.sim.native import native_output_silenced
from llcps.sim.bullet import pybullet as p
from llcps.sim.robot import ReachSolutions
from llcps.sim.state_files import StateFiles

#: Idle headless connections the process's pool keeps.
IDLE_CAPACITY = 1


class Connection:
    """One PyBullet client (DIRECT unless ``gui``) and what lasts as long as it.

    Attributes:
        client: the BulletClient.
        gui: whether it shows a window.
        reach: the IK solutions of the robots built in it.
    """

    def __init__(self, *, gui: bool = False) -> None:
        with native_output_silenced():  # the engine prints a line on connect
            self.client = bullet_client.BulletClient(connection_mode=p.GUI if gui else p.DIRECT)
        self.gui = gui
        self.reach = ReachSolutions()
        self._files: StateFiles | None = None

    @property
    def files(self) -> StateFiles:
        """The files the engine saves and restores states through (a forked child makes its own)."""
        if self._files is None or self._files.pid != os.getpid():
            self._files = StateFiles(self.client)
        return self._files

    def disconnect(self) -> None:
        try:
            self.client.disconnect()
        except p.error:
            pass


class ConnectionPool:
    """Idle headless connections of closed worlds, for the next world (at most ``capacity``)."""

    def __init__(self, capacity: int = IDLE_CAPACITY) -> None:
        self.capacity = capacity
        self._idle: list[Connection] = []

    def connect(self, *, gui: bool = False) -> Connection:
        """An idle headless connection if there is one (and no window is asked for), else a new one."""
        if not gui and self._idle:
            return self._idle.pop()
        return Connection(gui=gui)

    def release(self, connection: Connection) -> None:
        """Keep a headless connection for the next world while there is room; disconnect it otherwise."""
        if not connection.gui and len(self._idle) < self.capacity:
            self._idle.append(connection)
        else:
            connection.disconnect()

    def clear(self) -> None:
        """Disconnect every idle connection."""
        while self._idle:
            self._idle.pop().disconnect()


#: The connections of this process's worlds.
POOL = ConnectionPool()
