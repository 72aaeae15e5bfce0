"""Builders of entity and fixture specs, in the terms a scene is described in:
an object resting on the table, an open box, a bucket on the floor, an object
inside a container or on top of another, a lip along a table edge, a shelf.

Each computes the spec's bounding-box centre from where the body rests, so a
scene written with them is physically consistent (nothing floats or overlaps its
support).
"""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Sequence

from llcps.sim.specs import DEFAULT_WALL, MAX_EXTENT, EntitySpec, FixtureSpec, TableSpec, _triple

#: Density of solid objects when no mass is given (kg/m^3, light wood).
DEFAULT_DENSITY = 500.0


def solid(
    name: str,
    shape: str,
    color: str,
    size: Sequence[float],
    *,
    at: Sequence[float],
    on: float = 0.0,
    yaw: float = 0.0,
    mass: float | None = None,
) -> EntitySpec:
    """A manipulable object resting with its bottom at height ``on`` (table top by default).

    Args:
        name: entity name.
        shape: sphere, box or cylinder.
        color: red, blue or green.
        size: a sphere's diameter (one value), a cylinder's (diameter, height), or
            a box's (x, y, z).
        at: (x, y) of its centre.
        on: height of the supporting surface under it (m).
        yaw: rotation about +z.
        mass: kg; by default from DEFAULT_DENSITY.
    """
    dims = _dims(shape, size)
    spec = EntitySpec(
        name=name,
        kind="object",
        shape=shape,
        color=color,
        size=dims,
        mass=1.0,
        position=(float(at[0]), float(at[1]), on + dims[2] / 2.0),
        yaw=yaw,
    )
    m = mass if mass is not None else max(0.02, DEFAULT_DENSITY * spec.volume)
    return EntitySpec(**{**asdict(spec), "mass": m})


def open_box(
    name: str,
    color: str,
    *,
    at: Sequence[float],
    size: Sequence[float] = (0.2, 0.2, 0.1),
    on: float = 0.0,
    yaw: float = 0.0,
    mass: float = 0.6,
    wall: float = DEFAULT_WALL,
) -> EntitySpec:
    """An open-topped box container (a tray when shallow), resting at height ``on``."""
    dims = _triple(size, "size", MAX_EXTENT)
    return EntitySpec(
        name=name,
        kind="container",
        shape="box",
        color=color,
        size=dims,
        mass=mass,
        position=(float(at[0]), float(at[1]), on + dims[2] / 2.0),
        yaw=yaw,
        wall=wall,
    )


def bucket(
    name: str,
    color: str,
    *,
    at: Sequence[float],
    diameter: float = 0.26,
    height: float = 0.22,
    on: float | None = None,
    table: TableSpec | None = None,
    mass: float = 1.0,
    wall: float = DEFAULT_WALL,
) -> EntitySpec:
    """A cylindrical bucket; by default standing on the floor beside the table."""
    base = on if on is not None else (table or TableSpec()).floor_z
    return EntitySpec(
        name=name,
        kind="container",
        shape="cylinder",
        color=color,
        size=(diameter, diameter, height),
        mass=mass,
        position=(float(at[0]), float(at[1]), base + height / 2.0),
        wall=wall,
    )


def inside(obj: EntitySpec, container: EntitySpec, *, offset: Sequence[float] = (0.0, 0.0)) -> EntitySpec:
    """``obj`` moved to rest on the inner floor of ``container`` (offset in the container frame)."""
    c = math.cos(container.yaw)
    s = math.sin(container.yaw)
    ox, oy = float(offset[0]), float(offset[1])
    floor_top = container.position[2] - container.size[2] / 2.0 + container.wall
    return obj.moved(
        (
            container.position[0] + c * ox - s * oy,
            container.position[1] + s * ox + c * oy,
            floor_top + obj.size[2] / 2.0,
        )
    )


def stacked(top: EntitySpec, below: EntitySpec, *, offset: Sequence[float] = (0.0, 0.0)) -> EntitySpec:
    """``top`` moved to rest on the top face of ``below``."""
    z = below.position[2] + below.size[2] / 2.0 + top.size[2] / 2.0
    return top.moved((below.position[0] + offset[0], below.position[1] + offset[1], z))


def edge_lip(
    table: TableSpec, side: str, *, height: float = 0.06, thickness: float = 0.02, name: str | None = None
) -> FixtureSpec:
    """A lip along one table edge ("front" = far edge +x, "left" = +y edge, "right" = -y edge)."""
    length_x = table.x_max - table.x_min
    cx = (table.x_max + table.x_min) / 2.0
    if side == "front":
        return FixtureSpec(
            name or "lip", (thickness, 2 * table.y_half, height), (table.x_max - thickness / 2, 0.0, height / 2)
        )
    if side in ("left", "right"):
        sign = 1.0 if side == "left" else -1.0
        return FixtureSpec(
            name or "lip", (length_x, thickness, height), (cx, sign * (table.y_half - thickness / 2), height / 2)
        )
    raise ValueError(f"unknown table edge {side!r}; expected front, left or right")


def shelf(
    name: str, *, at: Sequence[float], clearance: float, size: Sequence[float] = (0.3, 0.3, 0.02), post: bool = True
) -> tuple[FixtureSpec, ...]:
    """A board ``clearance`` above the table top at (x, y), on one post on its far side.

    Placed over a container it blocks the top approach while leaving the sides open.
    """
    sx, sy, sz = _triple(size, "size", MAX_EXTENT)
    board = FixtureSpec(name, (sx, sy, sz), (at[0], at[1], clearance + sz / 2.0), color="wood")
    if not post:
        return (board,)
    support = FixtureSpec(
        f"{name}_post", (0.03, 0.03, clearance), (at[0] + sx / 2 - 0.015, at[1], clearance / 2.0), color="dark"
    )
    return board, support


def _dims(shape: str, size: Sequence[float] | float) -> tuple[float, float, float]:
    values = [float(size)] if isinstance(size, (int, float)) else [float(v) for v in size]
    if shape == "sphere" and len(values) == 1:
        return (values[0],) * 3  # type: ignore[return-value]
    if shape == "cylinder" and len(values) == 2:
        return (values[0], values[0], values[1])
    if shape == "box" and len(values) == 3:
        return tuple(values)  # type: ignore[return-value]
    raise ValueError(f"size {size!r} does not describe a {shape}")
