"""The bench's shared machinery: typed figures and their targets, clocks, the steadiness
of the machine while figures were taken, and the run of the chosen groups.

Nothing here loads a group: :func:`run_bench` imports ``llcps.bench.<group>`` when that
group runs, so naming the groups (``llcps bench --help``) stays as cheap as this module.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol, Self

from llcps.errors import UnknownNameError

#: The groups, in the order they run. Each is the module ``llcps.bench.<name>``, whose
#: ``run(quick, progress)`` returns its figures.
GROUPS: tuple[str, ...] = ("physics", "exploration", "models", "ranking", "store", "life", "scaling")
#: Groups left out of ``--quick``: the experiment grid alone takes more than a minute, and
#: so does a life's fit at episode 1,000.
SLOW_GROUPS: tuple[str, ...] = ("life", "scaling")
#: A drift of the bound beyond this (after / before the episodes) marks a machine whose
#: speed changed during the group.
DRIFT_WARNING = 0.05
#: Workers of the scaling group that got less CPU time per wall second than this shared
#: their cores with other jobs.
CORE_SHARE_WARNING = 0.9
#: What a target figure of an unsteady group says instead of met or missed.
NOT_JUDGED = "not judged: the machine's speed changed while its group ran (see the warning); run it again on a quieter machine"

Progress = Callable[[str], None]
"""Called with a short description before each measurement."""


# --------------------------------------------------------------------------- figures
@dataclass(frozen=True)
class Figure:
    """One measured figure, named by its parts: ``group[.subject][.sign]``.

    Attributes:
        group: the group that measured it (one of :data:`GROUPS`).
        sign: which quantity it is (``core_share``, ``step_rate``); empty for a
            subject's own figure (``scaling.workers1``: the grid's wall time).
        value: the measurement (finite).
        unit: unit of ``value``.
        target: the goal, as text (``">= 1000"``), or None.
        met: whether ``value`` meets ``target`` (None without a target).
        note: what was measured, briefly.
        subject: what in the group it measures (``workers2``, ``scenario1``,
            ``nb.10000``); empty for the group as a whole.
    """

    group: str
    sign: str
    value: float
    unit: str
    target: str | None = None
    met: bool | None = None
    note: str = ""
    subject: str = ""

    @property
    def where(self) -> str:
        """The group and the subject (``scaling.workers2``): what the figure is about."""
        return f"{self.group}.{self.subject}" if self.subject else self.group

    @property
    def name(self) -> str:
        """The dotted name, group first (``scaling.workers2.core_share``)."""
        return f"{self.where}.{self.sign}" if self.sign else self.where

    def as_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": self.value,
            "unit": self.unit,
            "target": self.target,
            "met": self.met,
            "note": self.note,
        }


def figure(
    group: str,
    sign: str,
    value: float,
    unit: str,
    *,
    subject: str = "",
    at_least: float | None = None,
    at_most: float | None = None,
    note: str = "",
) -> Figure:
    """A figure, with its target check when it has one (``at_least`` or ``at_most``)."""
    value = float(value)
    if at_least is not None:
        return Figure(group, sign, value, unit, f">= {at_least:g}", value >= at_least, note, subject)
    if at_most is not None:
        return Figure(group, sign, value, unit, f"<= {at_most:g}", value <= at_most, note, subject)
    return Figure(group, sign, value, unit, note=note, subject=subject)


# --------------------------------------------------------------------------- timing
class Clock:
    """Wall and CPU seconds of a block (``with Clock() as c: ...; c.wall, c.cpu``)."""

    def __enter__(self) -> Self:
        self._wall, self._cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc: object) -> None:
        self.wall = time.perf_counter() - self._wall
        self.cpu = time.process_time() - self._cpu


def best_of(action: Callable[[], object], repeats: int, clock: Callable[[], float] = time.perf_counter) -> float:
    """Seconds of ``clock`` of the fastest of ``repeats`` calls of ``action`` (the least disturbed)."""
    times = []
    for _ in range(repeats):
        start = clock()
        action()
        times.append(clock() - start)
    return min(times)


def say(progress: Progress | None, text: str) -> None:
    """Tell ``progress`` (when given) what is measured next."""
    if progress is not None:
        progress(text)


# --------------------------------------------------------------------------- the run
class Group(Protocol):
    """What a group's module provides."""

    def run(self, quick: bool = False, progress: Progress | None = None) -> list[Figure]: ...


def group_module(name: str) -> Group:
    """The module of group ``name``, loaded now (it loads what the group measures).

    Raises:
        UnknownNameError: for a group not in :data:`GROUPS`.
    """
    if name not in GROUPS:
        raise UnknownNameError("bench group", name, list(GROUPS))
    return importlib.import_module(f"llcps.bench.{name}")  # type: ignore[return-value]


def run_bench(*, quick: bool = False, groups: Sequence[str] | None = None, progress: Progress | None = None) -> list[Figure]:
    """Run the chosen groups (default: all; with ``quick`` all but :data:`SLOW_GROUPS`), judged.

    Raises:
        UnknownNameError: for a group not in :data:`GROUPS` (before any group runs).
    """
    if groups is None:
        groups = [g for g in GROUPS if not (quick and g in SLOW_GROUPS)]
    modules = [group_module(name) for name in groups]
    figures: list[Figure] = []
    for module in modules:
        figures += module.run(quick, progress)
    return judged(figures)


# --------------------------------------------------------------------------- steadiness
def _unsteadiness(figures: Sequence[Figure]) -> Iterator[tuple[str, str]]:
    """(group, what was not steady, in words) for each sign in ``figures`` that the
    machine's speed did not hold while they were taken (see :func:`unsteady`)."""
    for f in figures:
        if f.sign == "control_loop_drift" and abs(f.value) > DRIFT_WARNING:
            yield f.group, (
                f"the control-loop bound of {f.where} moved by {f.value:+.1%} between before and after its episodes:"
                f" its ratios are uncertain by as much; run it again on a quieter machine"
            )
        elif f.sign == "episode_drift" and abs(f.value) > DRIFT_WARNING:
            yield f.group, (
                f"the second run of {f.where}'s episode took {f.value:+.1%} the CPU of the first: the machine's speed"
                f" changed while it ran, and its ratios are uncertain by as much; run it again on a quieter machine"
            )
        elif f.sign == "core_share" and f.value < CORE_SHARE_WARNING:
            yield f.group, f"{f.where} got {f.value:.2f} of its cores (other jobs ran beside it): its wall times and the speed-up are low"


def unsteady(figures: Sequence[Figure]) -> list[str]:
    """What in ``figures`` says the machine was not steady while they were taken, in words.

    The bench's ratios compare measurements taken one after the other, so they hold
    only while the machine's speed holds: a bound that drifted beyond
    :data:`DRIFT_WARNING` between before and after its episodes, the same episode
    run twice at CPU costs that far apart, or workers that got
    less than :data:`CORE_SHARE_WARNING` of their cores, make a figure worth taking again.
    """
    return [said for _, said in _unsteadiness(figures)]


def judged(figures: Sequence[Figure]) -> list[Figure]:
    """``figures`` with the target checks of unsteady groups withdrawn (``met`` None).

    A ratio taken while the machine's speed moved by more than the warning's threshold
    is uncertain by as much, so it can neither meet nor miss a target: a bound that
    fell by 39 % during the episodes once gave an efficiency of 0.95.
    """
    shaky = {group for group, _ in _unsteadiness(figures)}
    return [
        replace(f, met=None, note=f"{f.note}; {NOT_JUDGED}" if f.note else NOT_JUDGED) if f.target is not None and f.group in shaky else f
        for f in figures
    ]


__all__ = [
    "CORE_SHARE_WARNING",
    "DRIFT_WARNING",
    "GROUPS",
    "NOT_JUDGED",
    "SLOW_GROUPS",
    "Clock",
    "Figure",
    "Group",
    "Progress",
    "best_of",
    "figure",
    "group_module",
    "judged",
    "run_bench",
    "say",
    "unsteady",
]
