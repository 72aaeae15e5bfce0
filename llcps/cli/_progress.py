"""One progress display for every long command: a spinner from the first moment, the
phase, a bar with counts when the phase has a size, elapsed time and an ETA.

It goes to stderr and disappears when done; on a terminal only (piped stderr stays
clean for scripts). A library function reports through a plain callback
(``progress(phase, done, total)``), so the library never imports rich.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

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

from llcps.cli._common import err_console


class PhaseProgress:
    """The handle of a progress display: name the phase, report counts.

    Calling it as ``progress(phase, done, total)`` fits the library's callbacks. A new
    total (a new count starting) restarts the rate estimate, so the ETA is of what is
    being counted now; phases that share a count (explore, re-plan) keep it.
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
        """Change the description without touching the counts (a step inside a phase)."""
        self._progress.update(self._task, description=f"{self._label}: {text}" if self._label else text)


class _NoProgress(PhaseProgress):
    """The handle when stderr is not a terminal: progress is not shown at all."""

    def __init__(self) -> None:
        pass

    def __call__(self, phase: str, done: int = 0, total: int | None = None) -> None:
        pass

    def note(self, text: str) -> None:
        pass


@contextmanager
def progress_display(label: str, first_phase: str = "starting") -> Iterator[PhaseProgress]:
    """Show progress on stderr while the block runs; yields the :class:`PhaseProgress`.

    Piped stderr gets nothing (not even the blank line a finished display leaves), so
    a script sees only messages and the ``error:``/``hint:`` lines.
    """
    if not err_console.is_terminal:
        yield _NoProgress()
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
        yield PhaseProgress(display, task, label)
