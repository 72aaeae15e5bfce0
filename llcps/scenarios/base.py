"""What a CPS scenario is: a scene in two conditions and a task over it.

A scenario is the paper's unit of evaluation (Figure 1): in the *original*
condition the nominal plan from K succeeds; in the *novelty* condition something
about the world has changed so that the same plan fails and the robot must explore.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

from llcps.domain import Fluent, State
from llcps.errors import LlcpsError, UnknownNameError

CONDITIONS: tuple[str, ...] = ("original", "novelty")


@dataclass(frozen=True)
class Scenario:
    """One CPS scenario.

    Attributes:
        name: registry key (``scenario1`` ...).
        alias: a descriptive second name accepted wherever the name is.
        title: one line for tables.
        story: what the robot must do, and what the novelty changes.
        build_scene: condition -> a scene description ``llcps.sim.world.World.from_scene`` builds.
        goal: fluents that must hold (``goal_pos``) and must not hold (``goal_neg``).
    """

    name: str
    alias: str
    title: str
    story: str
    build_scene: Callable[[str], object]
    goal_pos: frozenset[Fluent] = frozenset()
    goal_neg: frozenset[Fluent] = frozenset()

    def scene(self, condition: str) -> object:
        if condition not in CONDITIONS:
            raise LlcpsError(
                f"unknown condition {condition!r}", hint=f"choose one of: {', '.join(CONDITIONS)}"
            )
        return self.build_scene(condition)

    def goal_reached(self, state: State) -> bool:
        return self.goal_pos <= state and not (self.goal_neg & state)


def lookup(registry: Mapping[str, Scenario], name: str) -> Scenario:
    """Find a scenario by name or alias; an unknown one lists the known names."""
    if name in registry:
        return registry[name]
    for scenario in registry.values():
        if scenario.alias == name:
            return scenario
    raise UnknownNameError("scenario", name, [f"{s.name} ({s.alias})" for s in registry.values()])
