"""``llcps scenario``: list, show, render and check the scenario files."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence

from llcps.jobs._common import Progress

if TYPE_CHECKING:
    from llcps.cps.check import CheckReport, SweepEstimate


@dataclass(frozen=True)
class ScenarioInfo:
    """A shipped scenario: name, alias, task, goal atoms, whether variants differ, and its file."""

    name: str
    alias: str | None
    title: str
    goal: tuple[str, ...]
    varies: bool
    file: str | None

    def as_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "alias": self.alias,
            "title": self.title,
            "goal": list(self.goal),
            "varies": self.varies,
            "file": self.file,
        }


@dataclass(frozen=True)
class RenderResult:
    """The pictures of one variant of a scenario."""

    scenario: str
    variant: int
    files: tuple[Path, ...]

    def as_json(self) -> dict[str, Any]:
        return {"scenario": self.scenario, "variant": self.variant, "files": [str(p) for p in self.files]}


def scenario_ref(name: str) -> str:
    """How the library finds scenario ``name`` again: its registered name, or the file given."""
    from llcps.scenarios import SCENARIOS, get_scenario

    scenario = get_scenario(name)
    return scenario.name if SCENARIOS.get(scenario.name) is scenario else name


def list_scenarios() -> list[ScenarioInfo]:
    """The shipped scenarios, in registry order."""
    from llcps.scenarios import SCENARIOS
    from llcps.scenarios.goal import goal_text

    return [
        ScenarioInfo(
            name=s.name,
            alias=s.alias,
            title=s.title,
            goal=tuple(goal_text(s.goal_pos, s.goal_neg)),
            varies=s.varies,
            file=str(s.source.path) if s.source is not None else None,
        )
        for s in SCENARIOS.values()
    ]


def show_scenario(*, name: str, fmt: str = "toml", variant: int | None = None) -> str:
    """The text of scenario ``name``'s file as ``fmt`` (toml or json); with ``variant``, the file
    with every range drawn for that variant. Saved as TOML it loads back to the same scenes;
    a shipped scenario's name and alias are commented out, so that the copy is a scenario of
    its own, named by its file name (``my.toml``: ``my``) unless a name is set in it."""
    from llcps.scenarios import RESERVED, get_scenario
    from llcps.scenarios.loader import dump

    scenario = get_scenario(name)
    assert scenario.source is not None
    return dump(scenario.source, fmt=fmt, variant=variant, reserved=RESERVED)


def render_scenario(
    *,
    name: str,
    out_dir: Path,
    variant: int | None = None,
    conditions: Iterable[str] | None = None,
    progress: Progress | None = None,
) -> RenderResult:
    """Render the settled scenes of ``variant`` (None: 0) to PNGs in ``out_dir``, one per condition
    (default: both)."""
    from llcps.outputs import check_output_dir
    from llcps.scenarios import CONDITIONS, get_scenario

    scenario = get_scenario(name)
    check_output_dir(out_dir, what="--out-dir")
    from llcps.scenarios.pictures import render_scenes  # the simulator loads only here

    chosen = tuple(CONDITIONS if conditions is None else conditions)
    written = render_scenes(scenario, out_dir, variant=variant or 0, conditions=chosen, progress=progress)
    return RenderResult(scenario=scenario.name, variant=variant or 0, files=tuple(written))


def check_scenario(
    *,
    name: str,
    variants: Sequence[int] = (0,),
    quick: bool = False,
    progress: Progress | None = None,
    estimate: Callable[[SweepEstimate], None] | None = None,
) -> CheckReport:
    """Check, in physics, the properties every scenario must have on each of ``variants``
    (``quick``: stop each sweep at the first resolving candidate). Nothing is stored.

    ``estimate`` hears how long each variant's sweep may take, once its first trials are timed.
    """
    from llcps.scenarios import get_scenario

    ref = scenario_ref(name)
    scenario = get_scenario(ref)
    from llcps.cps.check import check_scenario as check  # the simulator loads only here

    return check(scenario, ref, variants=variants, quick=quick, progress=progress, estimate=estimate)
