"""PyBullet bodies of entities and fixtures, built from their specs.

Every shape is a primitive, so building a scene downloads and parses nothing; a
container is a compound of boxes (an open box) or of a round floor and wall staves
(a bucket), with its centre of mass where its parts put it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from llcps.sim.bullet import pybullet as p

from llcps.sim.specs import FIXTURE_RGBA, RGBA, EntitySpec, FixtureSpec

#: Segments of a bucket's polygonal wall.
BUCKET_SEGMENTS = 12

#: Friction of entities, fixtures and table (Coulomb coefficient).
LATERAL_FRICTION = 0.5
#: Rolling friction of spheres and cylinders, so that a rolling ball comes to rest.
ROLLING_FRICTION = 0.0005
SPINNING_FRICTION = 0.001



@dataclass
class Entity:
    """A built entity: its spec, body id and where its bounding-box centre sits
    relative to the body's centre of mass (non-zero for containers)."""

    name: str
    body_id: int
    spec: EntitySpec
    com_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def kind(self) -> str:
        return self.spec.kind

    @property
    def is_container(self) -> bool:
        return self.spec.kind == "container"


def _quat_yaw(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


def _container_parts(spec: EntitySpec) -> list[tuple[int, tuple[float, ...], tuple[float, float, float]]]:
    """Boxes (half extents, centre in the bounding-box frame) making up a container."""
    sx, sy, sz = spec.size
    w = spec.wall
    parts: list[tuple[int, tuple[float, ...], tuple[float, float, float]]] = []
    parts.append((p.GEOM_BOX, (sx / 2, sy / 2, w / 2), (0.0, 0.0, -sz / 2 + w / 2)))  # floor
    wall_h = sz - w
    zc = -sz / 2 + w + wall_h / 2
    if spec.shape == "box":
        parts.append((p.GEOM_BOX, (sx / 2, w / 2, wall_h / 2), (0.0, sy / 2 - w / 2, zc)))
        parts.append((p.GEOM_BOX, (sx / 2, w / 2, wall_h / 2), (0.0, -sy / 2 + w / 2, zc)))
        parts.append((p.GEOM_BOX, (w / 2, sy / 2 - w, wall_h / 2), (sx / 2 - w / 2, 0.0, zc)))
        parts.append((p.GEOM_BOX, (w / 2, sy / 2 - w, wall_h / 2), (-sx / 2 + w / 2, 0.0, zc)))
    else:  # a bucket: a round floor and a polygon of wall staves
        parts[0] = (p.GEOM_CYLINDER, (sx / 2, w), (0.0, 0.0, -sz / 2 + w / 2))
        r = sx / 2 - w / 2
        chord = 2 * (sx / 2) * math.tan(math.pi / BUCKET_SEGMENTS) + 0.002
        for k in range(BUCKET_SEGMENTS):
            a = 2 * math.pi * k / BUCKET_SEGMENTS
            parts.append((p.GEOM_BOX, (w / 2, chord / 2, wall_h / 2, a), (r * math.cos(a), r * math.sin(a), zc)))
    return parts


def _container_com(spec: EntitySpec, parts: list) -> tuple[float, float, float]:
    """Volume-weighted centre of the container's parts (its centre of mass)."""
    total = 0.0
    acc = [0.0, 0.0, 0.0]
    for geom, dims, centre in parts:
        vol = (8 * dims[0] * dims[1] * dims[2]) if geom == p.GEOM_BOX else math.pi * dims[0] ** 2 * dims[1]
        total += vol
        for i in range(3):
            acc[i] += vol * centre[i]
    return (acc[0] / total, acc[1] / total, acc[2] / total)


def build_entity(client: Any, spec: EntitySpec) -> Entity:
    """Create the PyBullet body of an entity (deterministic for a given spec)."""
    rgba = RGBA[spec.color]
    sx, sy, sz = spec.size
    yaw_q = _quat_yaw(spec.yaw)
    if spec.kind == "object":
        if spec.shape == "sphere":
            col = client.createCollisionShape(p.GEOM_SPHERE, radius=sx / 2)
            vis = client.createVisualShape(p.GEOM_SPHERE, radius=sx / 2, rgbaColor=rgba)
        elif spec.shape == "cylinder":
            col = client.createCollisionShape(p.GEOM_CYLINDER, radius=sx / 2, height=sz)
            vis = client.createVisualShape(p.GEOM_CYLINDER, radius=sx / 2, length=sz, rgbaColor=rgba)
        else:
            half = (sx / 2, sy / 2, sz / 2)
            col = client.createCollisionShape(p.GEOM_BOX, halfExtents=half)
            vis = client.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=rgba)
        body = client.createMultiBody(spec.mass, col, vis, basePosition=spec.position, baseOrientation=yaw_q)
        entity = Entity(spec.name, body, spec)
    else:
        parts = _container_parts(spec)
        com = _container_com(spec, parts)
        types, halfs, radii, lengths, frames, orns = [], [], [], [], [], []
        for geom, dims, centre in parts:
            types.append(geom)
            if geom == p.GEOM_BOX:
                halfs.append(list(dims[:3]))
                radii.append(0.0)
                lengths.append(0.0)
                orns.append(list(_quat_yaw(dims[3]) if len(dims) == 4 else (0, 0, 0, 1)))
            else:
                halfs.append([0.0, 0.0, 0.0])
                radii.append(dims[0])
                lengths.append(dims[1])
                orns.append([0, 0, 0, 1])
            frames.append([centre[i] - com[i] for i in range(3)])
        col = client.createCollisionShapeArray(
            shapeTypes=types,
            halfExtents=halfs,
            radii=radii,
            lengths=lengths,
            collisionFramePositions=frames,
            collisionFrameOrientations=orns,
        )
        vis = client.createVisualShapeArray(
            shapeTypes=types,
            halfExtents=halfs,
            radii=radii,
            lengths=lengths,
            rgbaColors=[list(rgba)] * len(types),
            visualFramePositions=frames,
            visualFrameOrientations=orns,
        )
        cy, sn = math.cos(spec.yaw), math.sin(spec.yaw)
        world_com = (
            spec.position[0] + cy * com[0] - sn * com[1],
            spec.position[1] + sn * com[0] + cy * com[1],
            spec.position[2] + com[2],
        )
        body = client.createMultiBody(spec.mass, col, vis, basePosition=world_com, baseOrientation=yaw_q)
        entity = Entity(spec.name, body, spec, com_offset=com)
    client.changeDynamics(
        body,
        -1,
        lateralFriction=LATERAL_FRICTION if spec.friction is None else spec.friction,
        spinningFriction=SPINNING_FRICTION,
        rollingFriction=ROLLING_FRICTION if spec.shape != "box" else 0.0,
        restitution=0.0,
    )
    return entity


def build_fixture(client: Any, spec: FixtureSpec) -> int:
    """Create a static box fixture; returns its body id."""
    half = [s / 2 for s in spec.size]
    col = client.createCollisionShape(p.GEOM_BOX, halfExtents=half)
    vis = client.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=FIXTURE_RGBA[spec.color])
    body = client.createMultiBody(0.0, col, vis, basePosition=spec.position, baseOrientation=_quat_yaw(spec.yaw))
    client.changeDynamics(body, -1, lateralFriction=LATERAL_FRICTION, restitution=0.0)
    return body
