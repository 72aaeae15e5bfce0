"""Entities E of the knowledge base, built from PyBullet primitives.

An *entity* is something the robot acts on: a manipulable **object** (sphere, box
or cylinder) or a **container** (an open box on the table, a bucket on the
floor). A *fixture* is static scenery: the table, the floor, and any wall, lip or
shelf a scenario adds. Every shape is a primitive, so building a scene downloads
and parses nothing.

Geometry conventions (see docs/world.md): the world frame has the robot base at
the origin, +x pointing away from the robot over the table, +z up and the table
top at z = 0. ``EntitySpec.position`` is the centre of the entity's bounding box
and ``size`` its bounding-box dimensions along the entity's own axes (x, y, z),
which are rotated by ``yaw`` about +z.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass
from typing import Any, Mapping, Sequence

import pybullet as p

from llcps.domain import COLORS, SHAPES

#: Entity kinds.
KINDS: tuple[str, ...] = ("object", "container")

#: Display colours (RGBA) of the entity colours of Table 1.
RGBA: Mapping[str, tuple[float, float, float, float]] = {
    "red": (0.85, 0.15, 0.15, 1.0),
    "blue": (0.15, 0.3, 0.85, 1.0),
    "green": (0.15, 0.7, 0.25, 1.0),
}

#: Colours of fixtures (not part of Table 1: fixtures are never action arguments).
FIXTURE_RGBA: Mapping[str, tuple[float, float, float, float]] = {
    "wood": (0.72, 0.56, 0.38, 1.0),
    "gray": (0.55, 0.55, 0.58, 1.0),
    "dark": (0.3, 0.3, 0.32, 1.0),
    "floor": (0.9, 0.9, 0.88, 1.0),
}

#: Density of solid objects when no mass is given (kg/m^3, light wood).
DEFAULT_DENSITY = 500.0

#: Wall and floor thickness of containers (m).
DEFAULT_WALL = 0.01

#: Segments of a bucket's polygonal wall.
BUCKET_SEGMENTS = 12

#: Friction of entities, fixtures and table (Coulomb coefficient).
LATERAL_FRICTION = 0.5
#: Rolling friction of spheres and cylinders, so that a rolling ball comes to rest.
ROLLING_FRICTION = 0.0005
SPINNING_FRICTION = 0.001


#: Bounds of what a scene may describe (m, kg): a stored scene is untrusted input, and
#: a kilometre-wide box or a million-kilogram cube would stall the engine.
MAX_EXTENT = 10.0
MAX_DISTANCE = 100.0
MAX_MASS = 1000.0
MAX_NAME = 64


def _triple(values: Sequence[float], what: str, bound: float) -> tuple[float, float, float]:
    if isinstance(values, (str, bytes)) or len(values) != 3:
        raise ValueError(f"{what} needs 3 numbers, got {values!r}")
    out = tuple(_number(v, what, bound) for v in values)
    return out  # type: ignore[return-value]


def _number(value: object, what: str, bound: float) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not -bound <= float(value) <= bound:
        raise ValueError(f"{what} must be a number within +-{bound:g}, got {value!r}")
    return float(value)


def _name(value: object, what: str) -> None:
    if not isinstance(value, str) or not value.strip() or len(value) > MAX_NAME or not value.isprintable():
        raise ValueError(f"{what} needs a printable name of at most {MAX_NAME} characters, got {value!r}")


@dataclass(frozen=True)
class EntitySpec:
    """A JSON-able description of one entity, from which it is rebuilt exactly.

    Attributes:
        name: unique name; it is the entity's symbol in fluents and plans.
        kind: ``"object"`` or ``"container"``.
        shape: one of SHAPES (a bucket is a cylinder, an open box a box).
        color: one of COLORS.
        size: bounding-box dimensions along the entity's axes (m); a sphere has
            three equal values, a cylinder equal x and y (its diameter).
        mass: kg.
        position: centre of the bounding box in the world frame (m).
        yaw: rotation about +z (rad).
        wall: wall and floor thickness of a container (m); unused for objects.
    """

    name: str
    kind: str
    shape: str
    color: str
    size: tuple[float, float, float]
    mass: float
    position: tuple[float, float, float]
    yaw: float = 0.0
    wall: float = DEFAULT_WALL

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", _triple(self.size, "size", MAX_EXTENT))
        object.__setattr__(self, "position", _triple(self.position, "position", MAX_DISTANCE))
        object.__setattr__(self, "yaw", _number(self.yaw, "yaw", MAX_DISTANCE))
        object.__setattr__(self, "mass", _number(self.mass, "mass", MAX_MASS))
        object.__setattr__(self, "wall", _number(self.wall, "wall", MAX_EXTENT))
        _name(self.name, "an entity")
        if self.kind not in KINDS:
            raise ValueError(f"unknown entity kind {self.kind!r}; expected one of {KINDS}")
        if self.shape not in SHAPES:
            raise ValueError(f"unknown shape {self.shape!r}; expected one of {SHAPES}")
        if self.color not in COLORS:
            raise ValueError(f"unknown color {self.color!r}; expected one of {COLORS}")
        if min(self.size) <= 0 or self.mass <= 0:
            raise ValueError(f"entity {self.name!r} needs a positive size and mass")
        sx, sy, sz = self.size
        if self.shape == "sphere" and not (sx == sy == sz):
            raise ValueError(f"sphere {self.name!r} needs three equal size values")
        if self.shape == "cylinder" and sx != sy:
            raise ValueError(f"cylinder {self.name!r} needs equal x and y size (its diameter)")
        if self.kind == "container":
            if self.shape == "sphere":
                raise ValueError(f"container {self.name!r} must be a box or a cylinder")
            if not 0 < 2 * self.wall < min(sx, sy) or not self.wall < sz:
                raise ValueError(f"container {self.name!r}: wall {self.wall} too thick for size {self.size}")

    @property
    def volume(self) -> float:
        """Volume of the entity's envelope (m^3): a container counts its opening too."""
        sx, sy, sz = self.size
        if self.shape == "sphere":
            return math.pi * sx**3 / 6.0
        if self.shape == "cylinder":
            return math.pi * (sx / 2.0) ** 2 * sz
        return sx * sy * sz

    def moved(self, position: Sequence[float], yaw: float | None = None) -> "EntitySpec":
        """The same entity elsewhere."""
        return EntitySpec(**{**asdict(self), "position": tuple(position), "yaw": self.yaw if yaw is None else yaw})

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["size"] = list(self.size)
        d["position"] = list(self.position)
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "EntitySpec":
        return cls(**dict(data))


@dataclass(frozen=True)
class FixtureSpec:
    """A static box: a lip along a table edge, a wall, a shelf.

    Attributes:
        name: unique name (fluents may mention it, e.g. ``touching``).
        size: box dimensions (m) along its own axes.
        position: box centre in the world frame (m).
        yaw: rotation about +z (rad).
        color: a key of FIXTURE_RGBA.
    """

    name: str
    size: tuple[float, float, float]
    position: tuple[float, float, float]
    yaw: float = 0.0
    color: str = "gray"

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", _triple(self.size, "size", MAX_EXTENT))
        object.__setattr__(self, "position", _triple(self.position, "position", MAX_DISTANCE))
        object.__setattr__(self, "yaw", _number(self.yaw, "yaw", MAX_DISTANCE))
        _name(self.name, "a fixture")
        if min(self.size) <= 0:
            raise ValueError(f"fixture {self.name!r} needs a positive size")
        if self.color not in FIXTURE_RGBA:
            raise ValueError(f"unknown fixture color {self.color!r}; expected one of {tuple(FIXTURE_RGBA)}")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["size"] = list(self.size)
        d["position"] = list(self.position)
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "FixtureSpec":
        return cls(**dict(data))


@dataclass(frozen=True)
class TableSpec:
    """The table: a solid block whose top is the plane z = 0, resting on the floor.

    The robot base stands on it at the origin; the defaults leave about 0.25 m of
    table beyond the arm's top-down reach so that some objects can be out of reach.
    """

    x_min: float = -0.3
    x_max: float = 1.05
    y_half: float = 0.6
    height: float = 0.45

    def __post_init__(self) -> None:
        for name in ("x_min", "x_max", "y_half", "height"):
            object.__setattr__(self, name, _number(getattr(self, name), f"table {name}", MAX_EXTENT))
        if not (self.x_max > self.x_min and self.y_half > 0 and self.height > 0):
            raise ValueError(f"invalid table {self}")

    @property
    def floor_z(self) -> float:
        return -self.height

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "TableSpec":
        return cls(**dict(data))


# --------------------------------------------------------------------------- builders


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


# --------------------------------------------------------------------------- catalog


@dataclass(frozen=True)
class CatalogItem:
    """A kind of object the robot meets: shape and a size range (m), mass from density."""

    shape: str
    min_size: tuple[float, ...]
    max_size: tuple[float, ...]


#: Objects of the catalog. Sizes are ranges of the ``size`` argument of :func:`solid`.
#: Everything up to 7 cm wide fits the gripper (8 cm opening).
CATALOG: Mapping[str, CatalogItem] = {
    "ball": CatalogItem("sphere", (0.035,), (0.065,)),
    "cube": CatalogItem("box", (0.035, 0.035, 0.035), (0.06, 0.06, 0.06)),
    "brick": CatalogItem("box", (0.04, 0.06, 0.03), (0.06, 0.12, 0.05)),
    "can": CatalogItem("cylinder", (0.035, 0.05), (0.065, 0.1)),
    "tall_block": CatalogItem("box", (0.05, 0.07, 0.14), (0.06, 0.12, 0.2)),
    "tall_can": CatalogItem("cylinder", (0.05, 0.14), (0.065, 0.2)),
}


# --------------------------------------------------------------------------- PyBullet bodies


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
        lateralFriction=LATERAL_FRICTION,
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
