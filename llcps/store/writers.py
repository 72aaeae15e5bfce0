"""Live writers: runs still ``running``, and whether the process writing each is alive.

A run records the process that writes it (``host``, ``pid``) and a heartbeat
(``heartbeat_at``), which a thread of that process renews every
:data:`HEARTBEAT_SECONDS` until the run finishes (:class:`Heartbeats`). A run left
``running`` by a process that was killed (``kill -9``, a power cut) is then *stale*,
not live: on the same host its pid no longer exists (or the heartbeat stopped: the pid
was reused); on another host the heartbeat is older than :data:`STALE_AFTER`. Runs
stored before revision 0009 carry no marker and count as stale.

``llcps db delete`` and ``db reset`` refuse a branch with a live writer (``--force``
overrides, and marks those runs ``aborted``); ``llcps db status`` lists live and stale
writers.
"""

from __future__ import annotations

import os
import socket
import threading
from dataclasses import asdict, dataclass
from datetime import datetime, timedelta
from typing import Any, Callable

from sqlalchemy import Connection, select

from llcps.store.tables import Run
from llcps.store.transactions import utc_now

#: How often a running command renews its heartbeat.
HEARTBEAT_SECONDS = 30.0

#: A heartbeat older than this marks a run of another host (or a reused pid) as stale.
STALE_AFTER = timedelta(minutes=10)


@dataclass(frozen=True)
class Writer:
    """A run still marked ``running``, and whether its process is alive."""

    run_id: int
    command: str
    branch: str
    host: str | None
    pid: int | None
    heartbeat_at: str | None
    live: bool
    #: Why it counts as live or stale, for people.
    reason: str

    @property
    def this_process(self) -> bool:
        """Whether the run is written by the process asking (not a concurrent writer)."""
        return self.pid == os.getpid() and self.host == this_host()

    def describe(self) -> str:
        where = f"pid {self.pid} on {self.host or '?'}" if self.pid is not None else f"on {self.host or '?'}"
        return f"run {self.run_id} ({self.command[:60]}, {where}): {self.reason}"

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


def this_host() -> str:
    """The host name runs record (:func:`llcps.provenance.current` records the same)."""
    return socket.gethostname()


def _as_time(value: Any) -> datetime | None:
    if isinstance(value, datetime):
        return value
    try:
        return datetime.fromisoformat(str(value)) if value is not None else None
    except ValueError:  # a changed row: no usable heartbeat
        return None


def _pid_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    except (OverflowError, ValueError, OSError):  # not a pid at all
        return False
    return True


def liveness(host: str | None, pid: Any, heartbeat: datetime | None, now: datetime) -> tuple[bool, str]:
    """Whether the process of a running run is alive, and why it counts so."""
    if not isinstance(pid, int) or heartbeat is None:
        return False, "stale: no live-writer marker (a run of an older llcps, or a changed row)"
    old = (now - heartbeat) > STALE_AFTER
    beat = f"last heartbeat {heartbeat.isoformat(sep=' ', timespec='seconds')} UTC"
    if host == this_host():
        if pid <= 0 or not _pid_exists(pid):
            return False, f"stale: process {pid} is gone ({beat})"
        if old:
            return False, f"stale: {beat}, over {STALE_AFTER.total_seconds() / 60:.0f} min ago (process {pid} is another program now)"
        return True, f"live ({'this process' if pid == os.getpid() else beat})"
    if old:
        return False, f"stale: {beat}, over {STALE_AFTER.total_seconds() / 60:.0f} min ago, from another host"
    return True, f"live ({beat}, another host)"


def writers(conn: Connection, branch: str | None = None) -> list[Writer]:
    """Runs marked ``running`` (on ``branch``, or on any), live or stale, oldest first."""
    stmt = select(Run.id, Run.command, Run.branch, Run.host, Run.pid, Run.heartbeat_at).where(Run.status == "running").order_by(Run.id)
    if branch is not None:
        stmt = stmt.where(Run.branch == branch)
    now = utc_now()
    found = []
    for row in conn.execute(stmt):
        beat = _as_time(row.heartbeat_at)
        live, reason = liveness(row.host, row.pid, beat, now)
        found.append(
            Writer(
                run_id=row.id,
                command=str(row.command),
                branch=str(row.branch),
                host=None if row.host is None else str(row.host),
                pid=row.pid if isinstance(row.pid, int) else None,
                heartbeat_at=None if beat is None else beat.isoformat(sep=" ", timespec="seconds"),
                live=live,
                reason=reason,
            )
        )
    return found


class Heartbeats:
    """Renews the heartbeat of this process's running runs every :data:`HEARTBEAT_SECONDS`,
    on one daemon thread, until they finish or the store closes."""

    def __init__(self, beat: Callable[[list[int]], None]) -> None:
        self._beat = beat
        self._runs: set[int] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, run_id: int) -> None:
        with self._lock:
            self._runs.add(run_id)
            if self._thread is None or not self._thread.is_alive():
                self._stop.clear()
                self._thread = threading.Thread(target=self._loop, name="llcps-heartbeat", daemon=True)
                self._thread.start()

    def finish(self, run_id: int) -> None:
        with self._lock:
            self._runs.discard(run_id)

    def close(self) -> None:
        self._stop.set()

    def _loop(self) -> None:
        while not self._stop.wait(HEARTBEAT_SECONDS):
            with self._lock:
                runs = sorted(self._runs)
            if not runs:
                continue
            try:
                self._beat(runs)
            except Exception:  # noqa: BLE001 - a missed beat only makes the run look stale later
                pass
