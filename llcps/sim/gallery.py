"""One trial of each action controller in a small demonstration scene, rendered
to GIFs for the documentation::

    python -m llcps.sim.gallery docs/img

The scene and the calls are fixed, so the GIFs are reproducible.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Mapping

from llcps.domain import ACTIONS, ControllerParams
from llcps.trial_records import TrialSpec
from llcps.sim.builders import bucket, inside, open_box, solid
from llcps.sim.render import CLOSE, GifRecorder, render_png
from llcps.sim.trial import TrialResult, run_trial
from llcps.sim.world import SceneSpec, World

_BIN = open_box("green_bin", "green", at=(0.42, -0.28), size=(0.24, 0.24, 0.07))

#: The demonstration scene: objects on the table, an open bin holding a cube, a bucket on the floor.
DEMO_SCENE = SceneSpec(
    entities=(
        solid("red_cube", "box", "red", (0.05, 0.05, 0.05), at=(0.55, 0.05)),
        solid("blue_can", "cylinder", "blue", (0.05, 0.09), at=(0.45, 0.3)),
        solid("green_ball", "sphere", "green", 0.05, at=(0.72, 0.22)),
        _BIN,
        inside(solid("blue_cube", "box", "blue", (0.05, 0.05, 0.05), at=(0, 0)), _BIN),
        bucket("red_bucket", "red", at=(1.2, 0.05)),
    ),
    name="gallery",
)

#: One call per action, shown in docs/world.md.
DEMO_TRIALS: Mapping[str, TrialSpec] = {
    "push": TrialSpec("push", ("red_cube",), ControllerParams(0.2, 0.2, "front")),
    "push_together": TrialSpec("push_together", ("red_cube", "blue_can"), ControllerParams(0.1, 0.0, "front")),
    "remove_from_container": TrialSpec(
        "remove_from_container", ("blue_cube", "green_bin"), ControllerParams(0.4, 0.1, "front")
    ),
    "place_in_container": TrialSpec("place_in_container", ("red_cube", "green_bin"), ControllerParams(0.4, 0.1, "top")),
}
assert tuple(DEMO_TRIALS) == ACTIONS


def render_gallery(out_dir: str | Path, *, every: int = 12, speedup: float = 2.0) -> dict[str, TrialResult]:
    """Render ``<action>.gif`` for every action and ``scene.png`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, TrialResult] = {}
    with World.from_scene(DEMO_SCENE, visuals=True) as world:
        world.settle(max_steps=240)
        start = world.snapshot()
        render_png(world, out / "scene.png", width=480, height=360)
        for action, spec in DEMO_TRIALS.items():
            world.restore(start)
            with GifRecorder(world, every=every, camera=CLOSE) as rec:
                results[action] = run_trial(world, spec)
            rec.save(out / f"{action}.gif", speedup=speedup)
    return results


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    for action, r in render_gallery(args[0] if args else "docs/img").items():
        print(f"{r.spec.label}: {r.sim_steps} steps, outcome {r.outcome.as_dict()}")


if __name__ == "__main__":
    main()
