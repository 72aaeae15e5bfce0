"""The files through which a physics engine saves and restores states.

PyBullet saves and restores a state only through a file name, and its file layer
keeps every file it reads, by name, for the life of the engine. Restoring each
state from a new temporary file therefore keeps every state ever restored in
memory (about 90 kB each, so a worker grew by gigabytes over a long grid), and
restoring new bytes under a name the engine has read restores the old bytes.

:class:`StateFiles` gives each distinct state restored a file of its own; a
:class:`~llcps.sim.connection.Connection` holds the one of its engine. A state
the engine holds is restored without writing or reading anything; when
:data:`CAPACITY` states are held, the engine's file cache is cleared (file caching
off and on again: the robot's mesh files are read again on the next build).
On Linux the files are anonymous in-memory files of the process (``memfd``), so a
killed process leaves nothing behind; elsewhere they live in a private temporary
directory removed at exit.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import weakref
from typing import Any

#: Distinct states an engine holds in its file cache before it is cleared.
CAPACITY = 32

_PROC_FD = "/proc/self/fd"


class StateFiles:
    """Save and restore files of one engine (one PyBullet client) in this process."""

    def __init__(self, client: Any) -> None:
        self._client = client
        self.pid = os.getpid()
        self._memory = hasattr(os, "memfd_create") and os.path.isdir(_PROC_FD)
        self._directory: str | None = None
        self._files: list[tuple[int, str]] = []  # (fd, path) of each restore file, reused after a clear
        self._held: dict[bytes, int] = {}  # raw state -> index of the file the engine read it from
        self._save: list[tuple[int, str]] = []
        weakref.finalize(self, _close, self._files, self._save)

    def _new_file(self, name: str) -> tuple[int, str]:
        if self._memory:
            fd = os.memfd_create(f"llcps-{name}", os.MFD_CLOEXEC)
            return fd, f"{_PROC_FD}/{fd}"
        if self._directory is None:
            self._directory = tempfile.mkdtemp(prefix="llcps-states-")
            atexit.register(shutil.rmtree, self._directory, True)
        path = os.path.join(self._directory, f"{name}.bullet")
        return os.open(path, os.O_RDWR | os.O_CREAT, 0o600), path

    def save_path(self) -> str:
        """An empty file for the engine to save a state into (read it back with :meth:`read_saved`).

        The engine writes it without its file cache, so it is never restored from.
        """
        if not self._save:
            self._save.append(self._new_file("save"))
        fd, path = self._save[0]
        os.ftruncate(fd, 0)
        return path

    def read_saved(self) -> bytes:
        """What the engine saved into :meth:`save_path`."""
        fd = self._save[0][0]
        return os.pread(fd, os.fstat(fd).st_size, 0)

    def restore_path(self, raw: bytes) -> str:
        """The name under which the engine reads ``raw``: written now unless the engine holds it."""
        index = self._held.get(raw)
        if index is not None:
            return self._files[index][1]
        if len(self._held) >= CAPACITY:
            self._client.setPhysicsEngineParameter(enableFileCaching=0)  # drops every file it holds
            self._client.setPhysicsEngineParameter(enableFileCaching=1)
            self._held.clear()
        index = len(self._held)  # the engine has read files 0 .. index - 1 since its cache was cleared
        if index == len(self._files):
            self._files.append(self._new_file(f"state-{index}"))
        fd, path = self._files[index]
        os.ftruncate(fd, 0)
        os.pwrite(fd, raw, 0)
        self._held[raw] = index
        return path


def _close(*groups: list[tuple[int, str]]) -> None:
    for files in groups:
        for fd, _ in files:
            os.close(fd)

