"""One progress display for every long command: the phase, counts when the phase has a
size, elapsed time and an ETA, on stderr.

* On a terminal: a live rich display (spinner, phase, bar, counts, elapsed, ETA) that
  disappears when done.
* Anywhere else (a pipe, a file, CI, ``nohup``): plain lines, so a reader can tell work
  from a hang (:class:`HeartbeatLines`). Nothing in the first interval (a command that
  ends or fails sooner prints only its result, or its ``error:``/``hint:`` lines); then a
  heartbeat at most every interval (5 s, or ``LLCPS_HEARTBEAT_SECONDS``) and a line
  when a phase starts and ends.
* With ``--quiet``: nothing.

A library function reports through a plain callback (``progress(phase, done, total)``),
so the library never imports rich.
"""

from __future__ import annotations

import math
import os
import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterator, TextIO

from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from llcps.cli._common import err_console, quiet
from llcps.errors import LlcpsError

#: The environment variable that sets the heartbeat interval off a terminal, in seconds.
HEARTBEAT_ENV = "LLCPS_HEARTBEAT_SECONDS"
DEFAULT_HEARTBEAT_SECONDS = 5.0


class PhaseProgress:
    """The handle of a progress display: name the phase, report counts.

    Calling it as ``progress(phase, done, total)`` fits the library's callbacks (a total
    of 0 or None: the phase has no size yet). This base shows nothing.
    """

    def __call__(self, phase: str, done: int = 0, total: int | None = None) -> None:
        pass

    def note(self, text: str) -> None:
        """Change what the phase is called without touching the counts (a step inside it)."""


class _RichProgress(PhaseProgress):
    """The live display on a terminal.

    A new total (a new count starting) restarts the rate estimate, so the ETA is of what
    is being counted now; phases that share a count (explore, re-plan) keep it.
    """

    def __init__(self, progress: Progress, task: TaskID, label: str) -> None:
        self._progress = progress
        self._task = task
        self._label = label
        self._total: int | None = None
        self._done = 0

    def __call__(self, phase: str, done: int = 0, total: int | None = None) -> None:
        total = total if total else None
        description = f"{self._label}: {phase}" if self._label else phase
        restart = total != self._total or done < self._done
        self._total, self._done = total, done
        if restart:
            self._progress.reset(self._task, total=total, completed=done, description=description)
        else:
            self._progress.update(self._task, completed=done, description=description)

    def note(self, text: str) -> None:
        self._progress.update(self._task, description=f"{self._label}: {text}" if self._label else text)


def clock_text(seconds: float) -> str:
    """A duration as ``H:MM:SS``, as the terminal display shows it."""
    whole = max(0, int(seconds))
    return f"{whole // 3600}:{whole // 60 % 60:02d}:{whole % 60:02d}"


class HeartbeatLines(PhaseProgress):
    """Progress as plain lines, for a stderr that is not a terminal.

    A phase is what the callback names, except that a new name continuing the same
    count (same total, done not going back: explore then re-plan, one task after
    another) is a step inside the phase, shown in the next heartbeat. Lines look like::

        llcps pretrain [0:00:05] random interactions: 3/30 (10%), eta 0:00:41
        llcps pretrain [0:00:47] random interactions: done in 0:00:44, 30/30
        llcps pretrain [0:00:47] fitting world model nb: started
        llcps pretrain [0:01:02] finished

    Nothing is written in the first ``every`` seconds: a command that ends (or fails)
    sooner leaves stderr to its result and its error lines. The heartbeat thread
    (:meth:`running`) calls :meth:`tick`; a test may call it itself, with its own clock.

    Args:
        label: the command, as people type it after ``llcps``.
        first_phase: what runs before the first report.
        stream: where the lines go.
        every: the heartbeat interval in seconds.
        clock: seconds from any origin (``time.monotonic``).
    """

    def __init__(
        self, label: str, first_phase: str, *, stream: TextIO, every: float, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self._label = label
        self._stream = stream
        self._every = every
        self._clock = clock
        self._lock = threading.Lock()
        self._stop = threading.Event()
        now = clock()
        self._began = now
        self._talking = False  # set once the first interval has passed
        self._last_line = now
        self._start_phase(first_phase, 0, None, now)

    # -- the callback -------------------------------------------------------
    def __call__(self, phase: str, done: int = 0, total: int | None = None) -> None:
        total = total if total else None
        with self._lock:
            now = self._clock()
            continuing = phase == self._name or (total is not None and total == self._total and done >= self._done)
            if not continuing:
                self._end_phase(now)
                self._start_phase(phase, done, total, now)
                self._say(f"{self._shown}: started", now)
                return
            if total != self._total or done < self._done:  # a new count: the rate starts again
                self._origin = (now, done)
            self._shown, self._done, self._total = phase, done, total

    def note(self, text: str) -> None:
        with self._lock:
            self._shown = text

    # -- the heartbeat ------------------------------------------------------
    def tick(self) -> None:
        """Write a heartbeat when one is due (the first only after one interval)."""
        with self._lock:
            now = self._clock()
            if now - (self._last_line if self._talking else self._began) < self._every:
                return
            self._talking = True
            self._say(self._heartbeat(now), now)

    def finish(self) -> None:
        """The lines of a command that ended well: the last phase's end, and the total time."""
        with self._lock:
            now = self._clock()
            self._end_phase(now)
            self._say("finished", now)

    @contextmanager
    def running(self) -> Iterator[HeartbeatLines]:
        """Tick from a background thread while the block runs; :meth:`finish` when it ends
        without an exception (an error says the rest)."""
        thread = threading.Thread(target=self._beat, name="llcps-heartbeat", daemon=True)
        thread.start()
        try:
            yield self
        finally:
            self._stop.set()
            thread.join()
        self.finish()

    def _beat(self) -> None:
        while not self._stop.wait(self._until_due()):
            self.tick()

    def _until_due(self) -> float:
        with self._lock:
            since = self._last_line if self._talking else self._began
            return max(0.01, since + self._every - self._clock())

    # -- lines ----------------------------------------------------------------
    def _start_phase(self, name: str, done: int, total: int | None, now: float) -> None:
        self._name = self._shown = name
        self._done, self._total = done, total
        self._phase_began = now
        self._origin = (now, done)

    def _end_phase(self, now: float) -> None:
        counts = f", {self._done}/{self._total}" if self._total else ""
        self._say(f"{self._shown}: done in {clock_text(now - self._phase_began)}{counts}", now)

    def _heartbeat(self, now: float) -> str:
        if self._total is None:
            counted = f", {self._done} done" if self._done else ""
            return f"{self._shown}: running for {clock_text(now - self._phase_began)}{counted}"
        share = self._done / self._total
        return f"{self._shown}: {self._done}/{self._total} ({share:.0%}), eta {self._eta(now)}"

    def _eta(self, now: float) -> str:
        assert self._total is not None
        if self._done >= self._total:
            return clock_text(0)
        since, done_then = self._origin
        if self._done <= done_then:
            return "unknown"
        return clock_text(math.ceil((self._total - self._done) * (now - since) / (self._done - done_then)))

    def _say(self, text: str, now: float) -> None:
        """Write one line (only once talking: the first interval stays silent)."""
        if not self._talking:
            return
        label = f"llcps {self._label}" if self._label else "llcps"
        self._stream.write(f"{label} [{clock_text(now - self._began)}] {text}\n")
        self._stream.flush()
        self._last_line = now


def heartbeat_seconds() -> float:
    """The heartbeat interval off a terminal: ``LLCPS_HEARTBEAT_SECONDS``, else 5 s."""
    text = os.environ.get(HEARTBEAT_ENV, "").strip()
    if not text:
        return DEFAULT_HEARTBEAT_SECONDS
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise LlcpsError(f"{HEARTBEAT_ENV}={text!r} is not a number of seconds above 0", hint=f"e.g. {HEARTBEAT_ENV}=30, or unset it (5 s)")
    return value


@contextmanager
def progress_display(label: str, first_phase: str = "starting") -> Iterator[PhaseProgress]:
    """Show progress on stderr while the block runs; yields the :class:`PhaseProgress`.

    A live display on a terminal, :class:`HeartbeatLines` elsewhere, nothing with ``--quiet``.

    Args:
        label: the command, as typed after ``llcps`` (``scenario check scenario2``).
        first_phase: what runs before the first report.
    """
    if quiet():
        yield PhaseProgress()
        return
    if not err_console.is_terminal:
        lines = HeartbeatLines(label, first_phase, stream=err_console.file, every=heartbeat_seconds())
        with lines.running():
            yield lines
        return
    display = Progress(
        SpinnerColumn(),
        TextColumn("{task.description}", markup=False),  # phases carry names from the store
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        console=err_console,
        transient=True,
    )
    with display:
        task = display.add_task(f"{label}: {first_phase}" if label else first_phase, total=None)
        yield _RichProgress(display, task, label)
