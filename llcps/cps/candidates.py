"""The exploration candidate space: every (action, rate, movement magnitude,
orientation, arguments) combination of the documented discretization.

The default order is the one an agent without a world model would follow:
*focused* exploration first (the failed action a_f with every other setting, on
its own arguments), then *defocused* exploration (a_f on other entities, then the
other actions on every valid argument tuple). A world model and a measure reorder
this list; ``random`` shuffles it.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass
from typing import Iterator, Mapping, Sequence

from llcps.cps.discretization import EXPLORATION_ORIENTATIONS, MOVEMENT_MAGNITUDES, RATES
from llcps.domain import ACTIONS, ControllerParams
from llcps.errors import LlcpsError
from llcps.limits import MAX_GRID_POINTS, MAX_GRID_VALUES, MAX_MOVEMENT_MAGNITUDE, MAX_RATE, MIN_RATE
from llcps.trial_records import TrialSpec

#: Entity kinds an argument slot accepts, per action.
ARGUMENT_KINDS: Mapping[str, tuple[frozenset[str], ...]] = {
    "push": (frozenset({"object", "container"}),),
    "push_together": (frozenset({"object", "container"}), frozenset({"object", "container"})),
    "remove_from_container": (frozenset({"object"}), frozenset({"container"})),
    "place_in_container": (frozenset({"object"}), frozenset({"container"})),
}


#: The hint of a grid beyond the limits.
_GRID_HINT = f"list at most {MAX_GRID_VALUES} rates and {MAX_GRID_VALUES} movement magnitudes (see Limits in docs/scenarios.md)"


@dataclass(frozen=True)
class Grid:
    """A discretization of controller settings."""

    rates: tuple[float, ...] = RATES
    movement_magnitudes: tuple[float, ...] = MOVEMENT_MAGNITUDES
    orientations: tuple[str, ...] = EXPLORATION_ORIENTATIONS

    def params(self) -> Iterator[ControllerParams]:
        for orientation, magnitude, rate in itertools.product(
            self.orientations, self.movement_magnitudes, self.rates
        ):
            yield ControllerParams(rate=rate, movement_magnitude=magnitude, orientation=orientation)

    def __post_init__(self) -> None:
        """The bounds of :mod:`llcps.limits` (a scenario file's grid is checked against them
        when it is read; this holds a grid built in code to them too)."""
        if not all(isinstance(v, (int, float)) and MIN_RATE <= v <= MAX_RATE for v in self.rates):
            raise LlcpsError(f"grid rates must lie within [{MIN_RATE:g}, {MAX_RATE:g}] m/s, got {self.rates!r}", hint=_GRID_HINT)
        if not all(isinstance(v, (int, float)) and 0 <= v <= MAX_MOVEMENT_MAGNITUDE for v in self.movement_magnitudes):
            raise LlcpsError(
                f"grid movement magnitudes must lie within [0, {MAX_MOVEMENT_MAGNITUDE:g}] m, got {self.movement_magnitudes!r}", hint=_GRID_HINT
            )
        if self.size > MAX_GRID_POINTS:
            raise LlcpsError(
                f"a grid of {self.size} points, more than the {MAX_GRID_POINTS} exploration may search",
                hint=_GRID_HINT,
            )

    @property
    def size(self) -> int:
        return len(self.rates) * len(self.movement_magnitudes) * len(self.orientations)


def argument_tuples(action: str, entities: Mapping[str, str]) -> list[tuple[str, ...]]:
    """Every valid argument tuple of ``action`` over ``entities`` (name -> kind), sorted."""
    slots = ARGUMENT_KINDS[action]
    pools = [sorted(name for name, kind in entities.items() if kind in allowed) for allowed in slots]
    return [args for args in itertools.product(*pools) if len(set(args)) == len(args)]


def enumerate_candidates(
    *,
    failed: TrialSpec | None,
    entities: Mapping[str, str],
    grid: Grid = Grid(),
) -> list[TrialSpec]:
    """All candidates in the default order, without the failed trial itself.

    Args:
        failed: the controller call that failed (a_f with its arguments and settings);
            ``None`` enumerates the whole space in action order.
        entities: manipulable entities of the scene, name -> "object" | "container".
        grid: the discretization of controller settings.

    Returns:
        Distinct candidates: focused ones first, then defocused ones.
    """
    order: list[tuple[str, tuple[str, ...]]] = []
    if failed is not None:
        order.append((failed.action, failed.arguments))
        order.extend(
            (failed.action, args)
            for args in argument_tuples(failed.action, entities)
            if args != failed.arguments
        )
    for action in ACTIONS:
        if failed is not None and action == failed.action:
            continue
        order.extend((action, args) for args in argument_tuples(action, entities))

    candidates: list[TrialSpec] = []
    for action, args in order:
        for params in grid.params():
            spec = TrialSpec(action=action, arguments=args, params=params)
            if failed is not None and spec == failed:
                continue
            candidates.append(spec)
    return candidates


def focused_count(candidates: Sequence[TrialSpec], failed: TrialSpec) -> int:
    """How many leading candidates vary only the failed action's settings."""
    n = 0
    for spec in candidates:
        if spec.action != failed.action or spec.arguments != failed.arguments:
            break
        n += 1
    return n


@functools.cache  # the scenarios' scenes are fixed: counted once per process
def candidate_space_size(scenario: str | None = None) -> int:
    """How many exploration candidates a scenario's novelty offers (the largest of all
    scenarios for None): every combination of the grid, less the failed call itself.

    What an exploration budget of "the whole candidate space" means (467 for the three
    scenarios of the paper: 13 action-argument pairs x 36 settings - 1).
    """
    from llcps.scenarios import SCENARIOS, get_scenario

    chosen = SCENARIOS.values() if scenario is None else [get_scenario(scenario)]
    sizes = []
    for spec in chosen:
        kinds = {e.name: e.kind for e in spec.scene("novelty").entities}  # type: ignore[attr-defined]
        sizes.append(len(enumerate_candidates(failed=None, entities=kinds)) - 1)
    return max(sizes)
