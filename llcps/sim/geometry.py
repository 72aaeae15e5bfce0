"""Measurements on the bodies of a world shared by the controllers and perception:
extents, tops and bottoms, footprints, and containers' interior volumes."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

if TYPE_CHECKING:
    from llcps.sim.world import World

Vec3 = tuple[float, float, float]


def unit2(dx: float, dy: float, default: tuple[float, float] = (1.0, 0.0)) -> tuple[float, float]:
    """A horizontal unit vector (``default`` for a zero vector)."""
    n = math.hypot(dx, dy)
    return (dx / n, dy / n) if n > 1e-9 else default


def yaw_of(d: Sequence[float]) -> float:
    """Gripper yaw whose hand x axis points along ``d``, folded to (-pi/2, pi/2]:
    the two-finger hand is symmetric under a half turn."""
    yaw = math.atan2(d[1], d[0])
    while yaw > math.pi / 2:
        yaw -= math.pi
    while yaw <= -math.pi / 2:
        yaw += math.pi
    return yaw


def extent_along(world: "World", name: str, d: Sequence[float]) -> float:
    """Half the horizontal width of a body measured along the unit vector ``d`` (from its AABB)."""
    lo, hi = world.aabb(name)
    return 0.5 * ((hi[0] - lo[0]) * abs(d[0]) + (hi[1] - lo[1]) * abs(d[1]))


def top(world: "World", name: str) -> float:
    return world.aabb(name)[1][2]


def bottom(world: "World", name: str) -> float:
    return world.aabb(name)[0][2]


def footprint_gap(a: tuple[Vec3, Vec3], b: tuple[Vec3, Vec3]) -> float:
    """Horizontal distance between two AABB footprints (0 when they overlap)."""
    dx = max(0.0, a[0][0] - b[1][0], b[0][0] - a[1][0])
    dy = max(0.0, a[0][1] - b[1][1], b[0][1] - a[1][1])
    return math.hypot(dx, dy)


def to_local(world: "World", name: str, point: Sequence[float]) -> Vec3:
    """``point`` in the frame of an entity's bounding box (centre origin, entity axes)."""
    c = world.client
    centre, orn = world.pose(name)
    inv_pos, inv_orn = c.invertTransform(centre, orn)
    return c.multiplyTransforms(inv_pos, inv_orn, point, (0, 0, 0, 1))[0]


def in_interior(world: "World", point: Sequence[float], container: str) -> bool:
    """Whether ``point`` lies in the open interior of a container (between its walls,
    above its floor, below its rim), whatever the container's pose."""
    spec = world.entity(container).spec
    if spec.kind != "container":
        return False
    x, y, z = to_local(world, container, point)
    sx, sy, sz = spec.size
    w = spec.wall
    if not (-sz / 2 + w <= z <= sz / 2):
        return False
    if spec.shape == "cylinder":
        return math.hypot(x, y) <= sx / 2 - w
    return abs(x) <= sx / 2 - w and abs(y) <= sy / 2 - w


def inner_floor_z(world: "World", container: str) -> float:
    """Height of a container's inner floor (its bottom, for a plain object)."""
    spec = world.entity(container).spec
    return bottom(world, container) + (spec.wall if spec.kind == "container" else 0.0)


def inner_half(world: "World", container: str, d: Sequence[float]) -> float:
    """Half the inner width of a container along ``d`` (outer half width for objects)."""
    spec = world.entity(container).spec
    outer = extent_along(world, container, d)
    return max(0.0, outer - spec.wall) if spec.kind == "container" else outer
