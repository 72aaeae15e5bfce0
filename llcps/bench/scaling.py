"""Worker scaling: the smoke experiment grid on 1 and 2 worker processes, with and without
the physics cache, and the speed-up between them.

Worker processes are spawned, so a script that runs this group needs the
``if __name__ == "__main__":`` guard.
"""

from __future__ import annotations

import os
import resource
import tempfile
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from llcps.bench.core import Figure, Progress, figure, say
from llcps.errors import LlcpsError
from llcps.experiments.runner import run_experiment
from llcps.store import Store

GROUP = "scaling"
_figure = partial(figure, GROUP)

#: The experiment preset whose grid the scaling group runs.
SCALING_PRESET = "smoke"


@dataclass(frozen=True)
class ExperimentRun:
    """One run of the scaling grid: wall seconds, summed task seconds, CPU seconds of all processes."""

    wall: float
    task_seconds: float
    cpu: float
    status: str


def _children_cpu() -> float:
    """CPU seconds of this process's reaped children (workers are reaped when the pool closes)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_scaling_grid(workers: int, *, preset: str = SCALING_PRESET, cache: bool = True) -> ExperimentRun:
    """Run ``preset``'s experiment grid into a fresh temporary store on ``workers`` processes.

    With ``cache`` the workers share the store's physics cache, cold at the start.
    """
    cpu0, kids0 = time.process_time(), _children_cpu()
    with tempfile.TemporaryDirectory(prefix="llcps-bench-") as tmp, Store.open(str(Path(tmp) / "bench.db"), create=True) as store:
        summary = run_experiment(store, preset=preset, workers=workers, cache=cache)
    cpu = time.process_time() - cpu0 + _children_cpu() - kids0
    return ExperimentRun(summary.wall_seconds, sum(summary.task_seconds.values()), cpu, summary.status)


def run(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """The smoke experiment grid on 1 and 2 worker processes (wall time) and the speed-up,
    with the physics cache (cold at the start of each grid) and without it.
    """
    load_before = os.getloadavg()[0]
    runs = {}
    for cache in (True, False):
        for workers in (1, 2):
            say(progress, f"scaling: {SCALING_PRESET} grid on {workers} worker(s){'' if cache else ', no physics cache'}")
            grid = run_scaling_grid(workers, cache=cache)
            if grid.status != "ok":
                raise LlcpsError(f"the {SCALING_PRESET} experiment ended {grid.status} on {workers} worker(s)")
            runs[workers, cache] = grid
    figures = []
    for (workers, cache), grid in runs.items():
        subject = f"workers{workers}" + ("" if cache else ".no_cache")
        figures += [
            _figure("", grid.wall, "s wall", subject=subject, note=f"{SCALING_PRESET} preset grid"),
            _figure("task_seconds", grid.task_seconds, "s wall", subject=subject, note="the tasks' own wall seconds, summed"),
            _figure("cpu", grid.cpu, "s cpu", subject=subject, note="this process and its workers"),
            _figure("core_share", grid.cpu / (grid.wall * workers), "ratio", subject=subject, note="CPU seconds per worker per wall second: below 1, the cores were busy elsewhere"),
        ]
    return figures + [
        _figure("speedup", runs[1, True].wall / runs[2, True].wall, "ratio", at_least=1.7, note="1-worker / 2-worker wall time"),
        _figure(
            "speedup_no_cache",
            runs[1, False].wall / runs[2, False].wall,
            "ratio",
            note="the same without the physics cache: one worker alone gets the cache hits of a twin run before",
        ),
        _figure("load_average", load_before, "runnable", note=f"1-minute load average before, on {os.cpu_count()} CPUs"),
        _figure("load_average_after", os.getloadavg()[0], "runnable"),
    ]


__all__ = ["GROUP", "SCALING_PRESET", "ExperimentRun", "run", "run_scaling_grid"]
