"""Pictures of a scenario's scenes: one PNG per condition of a variant, rendered headless."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterable

from llcps.scenarios.base import CONDITIONS, Scenario

#: Size of a scene picture (pixels); the documentation's pictures are this size.
PICTURE_SIZE = (480, 360)


def picture_name(scenario: str, condition: str, variant: int) -> str:
    """``scenario1_novelty.png`` for variant 0, ``scenario1_v3_novelty.png`` for variant 3."""
    return f"{scenario}_{condition}.png" if variant == 0 else f"{scenario}_v{variant}_{condition}.png"


def render_scenes(
    scenario: Scenario,
    out_dir: str | Path,
    *,
    variant: int = 0,
    conditions: Iterable[str] = CONDITIONS,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[Path]:
    """Render each condition of ``variant`` after the scene settles; returns the files written."""
    from llcps.sim.render import render_png
    from llcps.sim.world import SETTLE_STEPS, World

    chosen = list(conditions)
    written: list[Path] = []
    for index, condition in enumerate(chosen):
        if progress is not None:
            progress(f"render {condition}", index, len(chosen))
        with World.from_scene(scenario.scene(condition, variant), visuals=True) as world:
            world.settle(max_steps=SETTLE_STEPS)
            written.append(
                render_png(world, Path(out_dir) / picture_name(scenario.name, condition, variant), width=PICTURE_SIZE[0], height=PICTURE_SIZE[1])
            )
    return written


__all__ = ["PICTURE_SIZE", "picture_name", "render_scenes"]
