"""Headless frames of a world: PNG stills and GIFs of trials (TinyRenderer, no display)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np
import pybullet as p
from PIL import Image

from llcps.outputs import write_error

if TYPE_CHECKING:
    from llcps.sim.world import World


@dataclass(frozen=True)
class Camera:
    """A pinhole camera looking from ``eye`` at ``target`` (+z up)."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    fov: float = 50.0  # vertical field of view, degrees
    near: float = 0.05
    far: float = 6.0


#: A three-quarter view of the robot, the table and the floor beyond its far edge.
VIEW = Camera(eye=(1.55, -0.95, 1.05), target=(0.45, 0.0, 0.12), fov=55.0)
#: Closer on the arm's workspace on the table (the floor beyond the edge is out of frame).
CLOSE = Camera(eye=(1.25, -0.75, 0.8), target=(0.42, 0.0, 0.15), fov=55.0)


def capture(world: "World", *, width: int = 320, height: int = 240, camera: Camera = VIEW) -> np.ndarray:
    """One RGB frame (height x width x 3, uint8)."""
    world.ensure_visuals()
    c = world.client
    view = c.computeViewMatrix(camera.eye, camera.target, (0.0, 0.0, 1.0))
    proj = c.computeProjectionMatrixFOV(camera.fov, width / height, camera.near, camera.far)
    _, _, rgba, _, _ = c.getCameraImage(
        width, height, view, proj, renderer=p.ER_TINY_RENDERER, shadow=1, lightDirection=(0.4, -0.6, 1.0)
    )
    return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]


def render_png(world: "World", path: str | Path, *, width: int = 320, height: int = 240, camera: Camera = VIEW) -> Path:
    """Save the current scene as a PNG; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(capture(world, width=width, height=height, camera=camera)).save(path)
    return path


class GifRecorder:
    """Captures every ``every``-th simulation step of a world while active.

    Use as a context manager around :func:`llcps.sim.controllers.execute` (or any
    stepping), then :meth:`save`::

        with GifRecorder(world, every=8) as rec:
            execute(world, spec)
        rec.save("docs/img/push.gif")
    """

    def __init__(
        self, world: "World", *, every: int = 8, width: int = 320, height: int = 240, camera: Camera = VIEW
    ) -> None:
        if every < 1:
            raise ValueError("every must be >= 1")
        self.world = world
        self.every = every
        self.width = width
        self.height = height
        self.camera = camera
        self.frames: list[np.ndarray] = []
        self._count = 0

    def _observe(self, world: "World") -> None:
        self._count += 1
        if self._count % self.every == 0:
            self.frames.append(capture(world, width=self.width, height=self.height, camera=self.camera))

    def __enter__(self) -> "GifRecorder":
        self.world.ensure_visuals()
        self.frames.append(capture(self.world, width=self.width, height=self.height, camera=self.camera))
        self.world.add_observer(self._observe)
        return self

    def __exit__(self, *exc: object) -> None:
        self.world.remove_observer(self._observe)
        self.frames.append(capture(self.world, width=self.width, height=self.height, camera=self.camera))

    def save(self, path: str | Path, *, speedup: float = 1.0, hold_last: int = 6) -> Path:
        """Write the frames as a looping GIF playing at ``speedup`` x real time.

        Raises:
            LlcpsError: the file cannot be written (its directory is not created here).
        """
        if not self.frames:
            raise ValueError("no frames recorded")
        path = Path(path)
        ms = max(20, int(round(1000 * self.every * self.world.time_step / speedup)))
        frames = [Image.fromarray(f) for f in self.frames] + [Image.fromarray(self.frames[-1])] * hold_last
        pal = [f.quantize(colors=128, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE) for f in frames]
        try:
            pal[0].save(path, format="GIF", save_all=True, append_images=pal[1:], duration=ms, loop=0, optimize=True)
        except OSError as exc:
            raise write_error(path, exc, what="GIF") from None
        return path


def frame_at(frames: Sequence[np.ndarray], index: int) -> Image.Image:
    """One recorded frame as an image (for checking a GIF by eye)."""
    return Image.fromarray(frames[index])
