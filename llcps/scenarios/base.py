"""What a CPS scenario is: a scene in two conditions and a task over it.

A scenario is the paper's unit of evaluation (Figure 1): in the *original*
condition the nominal plan from K succeeds; in the *novelty* condition something
about the world has changed so that the same plan fails and the robot must explore.
Every scenario is declared in a file (:mod:`llcps.scenarios.loader`); a *variant*
number draws a concrete scene from the ranges it declares, variant 0 being the
canonical one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping

from llcps.domain import CONDITIONS, Fluent, State
from llcps.errors import UnknownNameError

if TYPE_CHECKING:  # the loader validates with pydantic: it loads when a scenario is first read
    from llcps.scenarios.loader import ScenarioSource
    from llcps.sim.specs import SceneSpec

__all__ = ["CONDITIONS", "Scenario", "lookup"]


@dataclass(frozen=True)
class Scenario:
    """One CPS scenario.

    Attributes:
        name: registry key (``scenario1`` ...), or a file's own name.
        alias: a descriptive second name accepted wherever the name is.
        title: one line for tables.
        story: what the robot must do, and what the novelty changes.
        goal_pos, goal_neg: fluents that must hold, and must not hold.
        source: the checked file the scenario comes from.
    """

    name: str
    alias: str
    title: str
    story: str
    goal_pos: frozenset[Fluent] = frozenset()
    goal_neg: frozenset[Fluent] = frozenset()
    source: "ScenarioSource | None" = field(default=None, compare=False, repr=False)

    @classmethod
    def from_source(cls, source: "ScenarioSource") -> "Scenario":
        model = source.model
        return cls(
            name=model.name,
            alias=model.alias or "",
            title=model.title,
            story=" ".join(model.story.split()),
            goal_pos=source.goal_pos,
            goal_neg=source.goal_neg,
            source=source,
        )

    def scene(self, condition: str, variant: int = 0) -> "SceneSpec":
        """The concrete scene of ``condition`` in ``variant`` (0: the canonical scene)."""
        assert self.source is not None
        return self.source.scene(condition, variant)

    @property
    def grid(self) -> Mapping[str, Any]:
        """The candidate grid the file asks for: only the settings it changes from the default."""
        if self.source is None:
            return {}
        return {k: tuple(v) for k, v in self.source.model.grid.model_dump(exclude_none=True).items()}

    @property
    def varies(self) -> bool:
        """Whether variants differ (the file declares a range somewhere)."""
        return self.source is not None and self.source.varies

    def goal_reached(self, state: State) -> bool:
        return self.goal_pos <= state and not (self.goal_neg & state)


def lookup(registry: Mapping[str, Scenario], name: str) -> Scenario:
    """Find a scenario by name or alias; an unknown one lists the known names."""
    if name in registry:
        return registry[name]
    for scenario in registry.values():
        if scenario.alias == name:
            return scenario
    raise UnknownNameError("scenario", name, [f"{s.name} ({s.alias})" for s in registry.values()] + ["or a path to a .toml file"])
