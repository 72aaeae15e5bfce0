"""Checks of a concrete layout before any physics runs: nothing overlaps, nothing floats,
and what the file says the arm must (or must not) reach is where it says.

The checks work on bounding boxes of the specs, so they are fast enough to reject and
redraw a variant's layout many times (:mod:`llcps.scenarios.variants`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

from llcps.sim.specs import BASE_HALF, BEYOND_REACH, TOP_DOWN_REACH, EntitySpec, FixtureSpec, SceneSpec

#: Boxes that share less than this depth along some axis only touch (m).
TOLERANCE = 0.001

Box = tuple[tuple[float, float, float], tuple[float, float, float]]


@dataclass(frozen=True)
class Problem:
    """What is wrong with a layout, and which entity or fixture of the file it concerns."""

    name: str
    message: str


@dataclass(frozen=True)
class Declared:
    """What the file says about an entity beyond its spec: where it rests and its reach."""

    rests_in: str | None = None  # the container it lies in
    rests_on: str | None = None  # the entity it stands on
    reachable: bool | None = None


def _box(position: tuple[float, float, float], size: tuple[float, float, float], yaw: float, round_: bool) -> Box:
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    sx, sy, sz = size
    hx, hy = (sx / 2, sy / 2) if round_ else (c * sx / 2 + s * sy / 2, s * sx / 2 + c * sy / 2)
    x, y, z = position
    return (x - hx, y - hy, z - sz / 2), (x + hx, y + hy, z + sz / 2)


def entity_box(spec: EntitySpec) -> Box:
    """World axis-aligned bounding box of an entity spec."""
    return _box(spec.position, spec.size, spec.yaw, spec.shape != "box")


def fixture_box(spec: FixtureSpec) -> Box:
    """World axis-aligned bounding box of a fixture spec."""
    return _box(spec.position, spec.size, spec.yaw, False)


def overlap(a: Box, b: Box) -> bool:
    """Whether two boxes share a volume deeper than :data:`TOLERANCE` along every axis."""
    return all(min(a[1][i], b[1][i]) - max(a[0][i], b[0][i]) > TOLERANCE for i in range(3))


def problems(scene: SceneSpec, declared: Mapping[str, Declared]) -> list[Problem]:
    """Everything wrong with ``scene``'s layout, entity by entity (empty: a valid layout)."""
    found: list[Problem] = []
    table = scene.table
    table_box: Box = ((table.x_min, -table.y_half, -table.height), (table.x_max, table.y_half, 0.0))
    base_box: Box = ((-BASE_HALF, -BASE_HALF, 0.0), (BASE_HALF, BASE_HALF, 0.3))
    boxes = {e.name: entity_box(e) for e in scene.entities}
    specs = {e.name: e for e in scene.entities}
    fixtures = {f.name: fixture_box(f) for f in scene.fixtures}
    for index, entity in enumerate(scene.entities):
        name = entity.name
        box = boxes[name]
        info = declared.get(name, Declared())
        x, y, _ = entity.position
        related = {info.rests_in, info.rests_on} - {None}
        if overlap(box, table_box):
            found.append(Problem(name, "overlaps the table (an entity on the floor must stand beside it)"))
        if overlap(box, base_box):
            found.append(Problem(name, "overlaps the robot's base"))
        for other in scene.entities[index + 1 :]:
            other_info = declared.get(other.name, Declared())
            if other.name in related or name in {other_info.rests_in, other_info.rests_on}:
                continue
            if overlap(box, boxes[other.name]):
                found.append(Problem(name, f"overlaps {other.name!r}"))
        for fixture, fbox in fixtures.items():
            if overlap(box, fbox):
                found.append(Problem(name, f"overlaps the fixture {fixture!r}"))
        bottom = box[0][2]
        if info.rests_in is not None:
            found.extend(_inside_problems(entity, specs[info.rests_in]))
        elif info.rests_on is not None:
            below = specs[info.rests_on]
            bx, by, _ = below.position
            if abs(x - bx) > below.size[0] / 2 or abs(y - by) > below.size[1] / 2:
                found.append(Problem(name, f"floats: its centre is not over {below.name!r}"))
        elif abs(bottom) < 1e-9 and not (table.x_min <= x <= table.x_max and abs(y) <= table.y_half):
            found.append(Problem(name, "floats: it rests at table height but its centre is beyond the table's edge"))
        distance = math.hypot(x, y)
        if info.reachable is True and not TOP_DOWN_REACH[0] <= distance <= TOP_DOWN_REACH[1]:
            found.append(
                Problem(
                    name,
                    f"is {distance:.2f} m from the robot base, out of the arm's reach "
                    f"({TOP_DOWN_REACH[0]}-{TOP_DOWN_REACH[1]} m), but the file says reachable = true",
                )
            )
        if info.reachable is False and distance < BEYOND_REACH:
            found.append(
                Problem(name, f"is {distance:.2f} m from the robot base, within {BEYOND_REACH} m, but the file says reachable = false")
            )
    return found


def _inside_problems(obj: EntitySpec, container: EntitySpec) -> list[Problem]:
    """An object lying in a container must fit within its walls."""
    c, s = math.cos(container.yaw), math.sin(container.yaw)
    dx, dy = obj.position[0] - container.position[0], obj.position[1] - container.position[1]
    local = (c * dx + s * dy, -s * dx + c * dy)
    (lo, hi) = entity_box(obj)
    half = ((hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2)
    inner = (container.size[0] / 2 - container.wall, container.size[1] / 2 - container.wall)
    if any(abs(local[i]) + half[i] > inner[i] + TOLERANCE for i in range(2)):
        return [Problem(obj.name, f"does not fit inside {container.name!r}: it would overlap its walls")]
    return []


__all__ = ["Declared", "Problem", "entity_box", "fixture_box", "overlap", "problems"]
