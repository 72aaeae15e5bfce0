"""Headless frames of a world: PNG stills and GIFs of trials (TinyRenderer, no display).

A GIF frames the scene's objects (:func:`frame_camera`), not the whole room, and
carries a caption under each frame: which trial, which phase of the episode, the
action and its parameters. Captions are drawn when the GIF is written, so the
capture itself is only the renderer's work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np
from llcps.sim.bullet import pybullet as p
from PIL import Image, ImageDraw, ImageFont

from llcps.outputs import written_atomically

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
#: The direction :func:`frame_camera` looks from (that of ``VIEW``), eye minus target.
FRAME_DIRECTION = (1.1, -0.95, 0.93)
#: Bodies :func:`frame_camera` leaves out: they are larger than anything worth seeing.
UNFRAMED = ("table", "floor")
#: Pixels of the caption band under each GIF frame.
CAPTION_HEIGHT = 34


def frame_camera(
    world: "World",
    *,
    fov: float = 45.0,
    margin: float = 1.7,
    min_radius: float = 0.25,
    headroom: float = 0.2,
) -> Camera:
    """A camera that fits every entity and fixture of the scene (table and floor aside).

    The box around them is raised by ``headroom`` (the gripper comes from above) and
    viewed from :data:`FRAME_DIRECTION` at the distance that fits its bounding sphere,
    times ``margin``, in the vertical field of view.
    """
    names = [*world.entities, *(n for n in world.fixtures if n not in UNFRAMED)]
    if not names:
        return VIEW
    boxes = np.array([np.concatenate(world.aabb(n)) for n in names])
    low, high = boxes[:, :3].min(axis=0), boxes[:, 3:].max(axis=0)
    high[2] += headroom
    center = (low + high) / 2
    radius = max(min_radius, float(np.linalg.norm(high - low)) / 2)
    distance = margin * radius / math.tan(math.radians(fov) / 2)
    direction = np.asarray(FRAME_DIRECTION) / np.linalg.norm(FRAME_DIRECTION)
    eye = center + direction * distance
    return Camera(eye=tuple(eye.tolist()), target=tuple(center.tolist()), fov=fov, far=distance + 4 * radius)


def capture(
    world: "World", *, width: int = 320, height: int = 240, camera: Camera = VIEW, shadow: bool = True
) -> np.ndarray:
    """One RGB frame (height x width x 3, uint8)."""
    world.ensure_visuals()
    c = world.client
    view = c.computeViewMatrix(camera.eye, camera.target, (0.0, 0.0, 1.0))
    proj = c.computeProjectionMatrixFOV(camera.fov, width / height, camera.near, camera.far)
    _, _, rgba, _, _ = c.getCameraImage(
        width, height, view, proj, renderer=p.ER_TINY_RENDERER, shadow=int(shadow), lightDirection=(0.4, -0.6, 1.0)
    )
    return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]


def render_png(world: "World", path: str | Path, *, width: int = 320, height: int = 240, camera: Camera = VIEW) -> Path:
    """Save the current scene as a PNG; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    image = Image.fromarray(capture(world, width=width, height=height, camera=camera))
    with written_atomically(path, what="picture") as target:
        image.save(target, format="PNG")
    return path


def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # pragma: no cover - Pillow < 10.1 has one bitmap size
        return ImageFont.load_default()


#: Caption font sizes, largest first: a line too wide for the frame takes a smaller one.
CAPTION_SIZES = (12, 11, 10, 9, 8)
#: Pixels left free at each side of a caption line.
CAPTION_MARGIN = 6


def _fitted(draw: ImageDraw.ImageDraw, line: str, width: int) -> tuple[str, ImageFont.ImageFont | ImageFont.FreeTypeFont]:
    """``line`` and the largest caption font it fits ``width`` pixels in; a line too wide
    even at the smallest size is cut, with an ellipsis."""
    for size in CAPTION_SIZES:
        font = _font(size)
        if draw.textlength(line, font=font) <= width:
            return line, font
    while line and draw.textlength(line + "…", font=font) > width:
        line = line[:-1]
    return line.rstrip() + "…", font


def captioned(frame: np.ndarray, caption: Sequence[str]) -> Image.Image:
    """``frame`` with up to two caption lines in a band beneath it, each within the
    frame's width (in a smaller font when it must)."""
    image = Image.fromarray(frame)
    out = Image.new("RGB", (image.width, image.height + CAPTION_HEIGHT), (250, 250, 250))
    out.paste(image, (0, 0))
    draw = ImageDraw.Draw(out)
    for i, line in enumerate(list(caption)[:2]):
        text, font = _fitted(draw, line, image.width - 2 * CAPTION_MARGIN)
        draw.text((CAPTION_MARGIN, image.height + 3 + 15 * i), text, fill=(20, 20, 20), font=font)
    return out


class GifRecorder:
    """Captures every ``every``-th simulation step of a world while active.

    Use as a context manager around :func:`llcps.sim.controllers.execute` (or any
    stepping), then :meth:`save`::

        with GifRecorder(world, every=8) as rec:
            rec.caption = ("trial 12 · plan", "push(cube) ...")
            execute(world, spec)
        rec.save("docs/img/push.gif")

    Attributes:
        caption: lines drawn under the frames captured from now on (empty: no band).
        on_frame: called after each captured frame (e.g. to move a progress bar).
    """

    def __init__(
        self,
        world: "World",
        *,
        every: int = 8,
        width: int = 320,
        height: int = 240,
        camera: Camera | None = VIEW,
        shadow: bool = True,
    ) -> None:
        if every < 1:
            raise ValueError("every must be >= 1")
        self.world = world
        self.every = every
        self.width = width
        self.height = height
        self.camera = camera if camera is not None else frame_camera(world)
        self.shadow = shadow
        self.frames: list[np.ndarray] = []
        self.captions: list[tuple[str, ...]] = []
        self.caption: tuple[str, ...] = ()
        self.on_frame: Callable[[int], None] | None = None
        self._count = 0
        self._active = False

    def grab(self) -> None:
        """Capture one frame now, with the current caption."""
        self.frames.append(
            capture(self.world, width=self.width, height=self.height, camera=self.camera, shadow=self.shadow)
        )
        self.captions.append(tuple(self.caption))
        if self.on_frame is not None:
            self.on_frame(len(self.frames))

    def _observe(self, world: "World") -> None:
        self._count += 1
        if self._count % self.every == 0:
            self.grab()

    def __enter__(self) -> "GifRecorder":
        self.world.ensure_visuals()
        self.grab()
        self.world.add_observer(self._observe)
        return self

    def __exit__(self, *exc: object) -> None:
        self.world.remove_observer(self._observe)
        self.grab()

    def save(self, path: str | Path, *, speedup: float = 1.0, hold_last: int = 6) -> Path:
        """Write the frames as a looping GIF playing at ``speedup`` x real time.

        Raises:
            LlcpsError: the file cannot be written (its directory is not created here).
        """
        if not self.frames:
            raise ValueError("no frames recorded")
        path = Path(path)
        ms = max(20, int(round(1000 * self.every * self.world.time_step / speedup)))
        if any(self.captions):
            images = [captioned(f, c) for f, c in zip(self.frames, self.captions)]
        else:
            images = [Image.fromarray(f) for f in self.frames]
        images += [images[-1]] * hold_last
        pal = [f.quantize(colors=128, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE) for f in images]
        with written_atomically(path, what="GIF") as target:
            pal[0].save(target, format="GIF", save_all=True, append_images=pal[1:], duration=ms, loop=0, optimize=True)
        return path


def frame_at(frames: Sequence[np.ndarray], index: int) -> Image.Image:
    """One recorded frame as an image (for checking a GIF by eye)."""
    return Image.fromarray(frames[index])
