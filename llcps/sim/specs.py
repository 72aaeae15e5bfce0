"""Scene descriptions: JSON-able, frozen specs of the entities, fixtures and table
from which :class:`~llcps.sim.world.World` builds the same bodies in the same order.

An *entity* is something the robot acts on: a manipulable **object** (sphere, box
or cylinder) or a **container** (an open box on the table, a bucket on the
floor). A *fixture* is static scenery: the table, the floor, and any wall, lip or
shelf a scene adds. Nothing here imports the physics engine: scenario files are
read and checked into these specs before any simulator is needed.

Geometry conventions (see docs/world.md): the world frame has the robot base at
the origin, +x pointing away from the robot over the table, +z up and the table
top at z = 0. ``EntitySpec.position`` is the centre of the entity's bounding box
and ``size`` its bounding-box dimensions along the entity's own axes (x, y, z),
which are rotated by ``yaw`` about +z.
"""

from __future__ import annotations

import math
import numbers
from collections import Counter
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping, Self, Sequence

from llcps.domain import COLORS, SHAPES
from llcps.errors import LlcpsError, UnknownNameError
# Bounds of what a scene may describe (m, kg; see llcps.limits): a stored scene is untrusted
# input, and a kilometre-wide box or a million-kilogram cube would stall the engine.
from llcps.limits import (
    MAX_DISTANCE,
    MAX_ENTITIES,
    MAX_EXTENT,
    MAX_FRICTION,
    MAX_GRIP_FORCE,
    MAX_MASS,
    MAX_NAME,
    MAX_SCENE_BODIES,
)

#: Names reserved for the built-in fixtures.
TABLE = "table"
FLOOR = "floor"
#: Half width of the floor a body description gives (m): the floor plane is unbounded,
#: its visible slab is this wide.
FLOOR_HALF_WIDTH = 3.0

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

#: Wall and floor thickness of containers (m).
DEFAULT_WALL = 0.01


#: Horizontal distances from the base (m) at which the tool reaches top-down onto things
#: 5-20 cm above the table (measured with :meth:`llcps.sim.robot.Robot.reach_error` in every direction);
#: beyond ``BEYOND_REACH`` it reaches nothing. Scenario files check declared reach with these.
TOP_DOWN_REACH: tuple[float, float] = (0.3, 0.78)
BEYOND_REACH = 0.82
#: Half width of the square the robot's base stands on (m): nothing may be placed there.
BASE_HALF = 0.12


def _triple(values: Sequence[float], what: str, bound: float) -> tuple[float, float, float]:
    if isinstance(values, (str, bytes)) or len(values) != 3:
        raise ValueError(f"{what} needs 3 numbers, got {values!r}")
    out = tuple(_number(v, what, bound) for v in values)
    return out  # type: ignore[return-value]


def _number(value: object, what: str, bound: float) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not -bound <= float(value) <= bound:
        raise ValueError(f"{what} must be a number within +-{bound:g}, got {value!r}")
    return float(value)


def _friction(value: object, what: str) -> float | None:
    """None (the default friction) or a coefficient in (0, MAX_FRICTION]."""
    if value is None:
        return None
    number = _number(value, f"{what}'s friction", MAX_FRICTION)
    if not number > 0:
        raise ValueError(f"{what}'s friction must be positive, got {value!r}")
    return number


def _without_default_friction(data: dict[str, Any]) -> dict[str, Any]:
    """A spec's JSON without ``friction`` when it is the default: the scenes written before
    the field existed keep their exact description (and the trial cache its keys)."""
    if data.get("friction") is None:
        data.pop("friction", None)
    return data


def _name(value: object, what: str) -> None:
    if not isinstance(value, str) or not value.strip() or len(value) > MAX_NAME or not value.isprintable():
        raise ValueError(f"{what} needs a printable name of at most {MAX_NAME} characters, got {value!r}")


class _Record:
    """JSON data of a frozen spec and back: tuples become lists, and ``from_dict`` goes
    through the constructor, so its checks see every stored scene."""

    def to_dict(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}  # type: ignore[call-overload]

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Self:
        return cls(**dict(data))


@dataclass(frozen=True)
class EntitySpec(_Record):
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
        friction: its Coulomb friction coefficient; None: the default of every body
            (:data:`llcps.sim.bodies.LATERAL_FRICTION`). The engine multiplies the
            coefficients of two bodies in contact.
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
    friction: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", _triple(self.size, "size", MAX_EXTENT))
        object.__setattr__(self, "position", _triple(self.position, "position", MAX_DISTANCE))
        object.__setattr__(self, "yaw", _number(self.yaw, "yaw", MAX_DISTANCE))
        object.__setattr__(self, "mass", _number(self.mass, "mass", MAX_MASS))
        object.__setattr__(self, "wall", _number(self.wall, "wall", MAX_EXTENT))
        object.__setattr__(self, "friction", _friction(self.friction, f"entity {self.name!r}"))
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

    def to_dict(self) -> dict[str, Any]:
        return _without_default_friction(super().to_dict())

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



@dataclass(frozen=True)
class FixtureSpec(_Record):
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



@dataclass(frozen=True)
class TableSpec(_Record):
    """The table: a solid block whose top is the plane z = 0, resting on the floor.

    The robot base stands on it at the origin; the defaults leave about 0.25 m of
    table beyond the arm's top-down reach so that some objects can be out of reach.
    ``friction`` is its top's Coulomb friction coefficient (None: the default of every
    body, :data:`llcps.sim.bodies.LATERAL_FRICTION`).
    """

    x_min: float = -0.3
    x_max: float = 1.05
    y_half: float = 0.6
    height: float = 0.45
    friction: float | None = None

    def __post_init__(self) -> None:
        for name in ("x_min", "x_max", "y_half", "height"):
            object.__setattr__(self, name, _number(getattr(self, name), f"table {name}", MAX_EXTENT))
        object.__setattr__(self, "friction", _friction(self.friction, "the table"))
        if not (self.x_max > self.x_min and self.y_half > 0 and self.height > 0):
            raise ValueError(f"invalid table {self}")

    def to_dict(self) -> dict[str, Any]:
        return _without_default_friction(super().to_dict())

    @property
    def floor_z(self) -> float:
        return -self.height

    @property
    def box(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """The table's world-frame bounding box (lower and upper corner, m)."""
        return (self.x_min, -self.y_half, self.floor_z), (self.x_max, self.y_half, 0.0)



@dataclass(frozen=True)
class RobotSpec(_Record):
    """What a scene changes about the robot's capabilities (None: the Panda as built).

    Attributes:
        grip_force: strength (N) of the grasp that holds a lifted object; None:
            :data:`llcps.sim.robot.GRASP_FORCE`. An object whose weight and
            acceleration ask more slips out of the hand.
        reach: the farthest horizontal distance (m) from the base at which the hand
            comes down top-down (to grasp, release, or perceive a thing as reachable);
            None: the arm's own, about :data:`TOP_DOWN_REACH`'s upper end. Strokes along
            the table are not limited by it.
    """

    grip_force: float | None = None
    reach: float | None = None

    def __post_init__(self) -> None:
        if self.grip_force is not None:
            force = _number(self.grip_force, "the robot's grip_force", MAX_GRIP_FORCE)
            if not force > 0:
                raise ValueError(f"the robot's grip_force must be positive, got {self.grip_force!r}")
            object.__setattr__(self, "grip_force", force)
        if self.reach is not None:
            reach = _number(self.reach, "the robot's reach", BEYOND_REACH)
            if not reach > 0:
                raise ValueError(f"the robot's reach must be positive, got {self.reach!r}")
            object.__setattr__(self, "reach", reach)

    def to_dict(self) -> dict[str, Any]:
        """Only the capabilities the scene changes: scenes written before a field existed
        keep their exact description (and cache keys)."""
        return {k: v for k, v in super().to_dict().items() if v is not None}

    @property
    def default(self) -> bool:
        return self.grip_force is None and self.reach is None


@dataclass(frozen=True)
class SceneSpec:
    """Everything needed to rebuild a world: table geometry, fixtures, entities.

    Attributes:
        entities: manipulable objects and containers, built in this order.
        fixtures: static boxes beyond the table and floor (lips, walls, shelves).
        table: the table's geometry.
        name: a label (scenario and condition, or "pretrain").
        robot: what the scene changes about the robot (by default nothing).
    """

    entities: tuple[EntitySpec, ...] = ()
    fixtures: tuple[FixtureSpec, ...] = ()
    table: TableSpec = field(default_factory=TableSpec)
    name: str = ""
    robot: RobotSpec = field(default_factory=RobotSpec)

    def __post_init__(self) -> None:
        object.__setattr__(self, "entities", tuple(self.entities))
        object.__setattr__(self, "fixtures", tuple(self.fixtures))
        if len(self.entities) > MAX_ENTITIES:
            raise ValueError(f"{len(self.entities)} entities, more than the {MAX_ENTITIES} a scene may hold")
        if len(self.entities) + len(self.fixtures) > MAX_SCENE_BODIES:
            raise ValueError(f"{len(self.entities) + len(self.fixtures)} entities and fixtures, more than the {MAX_SCENE_BODIES} a scene may hold")
        names = [e.name for e in self.entities] + [f.name for f in self.fixtures] + [TABLE, FLOOR]
        dupes = sorted(name for name, count in Counter(names).items() if count > 1)
        if dupes:
            raise ValueError(f"scene names must be unique (table and floor are reserved): {dupes}")

    def entity(self, name: str) -> EntitySpec:
        for e in self.entities:
            if e.name == name:
                return e
        raise UnknownNameError("entity", name, [e.name for e in self.entities])

    def replace(self, *specs: EntitySpec) -> "SceneSpec":
        """The scene with some entities replaced by name (or appended when new)."""
        by_name = {s.name: s for s in specs}
        kept = [by_name.pop(e.name, e) for e in self.entities]
        return SceneSpec(tuple(kept) + tuple(by_name.values()), self.fixtures, self.table, self.name, self.robot)

    def to_dict(self) -> dict[str, Any]:
        """JSON data of the scene; ``robot`` only when the scene changes the robot, so the
        scenes written before it existed keep their exact description (and cache keys)."""
        data: dict[str, Any] = {
            "name": self.name,
            "table": self.table.to_dict(),
            "fixtures": [f.to_dict() for f in self.fixtures],
            "entities": [e.to_dict() for e in self.entities],
        }
        if not self.robot.default:
            data["robot"] = self.robot.to_dict()
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "SceneSpec":
        """Rebuild a scene from :meth:`to_dict` output, checking it (it may come from a database).

        Raises:
            LlcpsError: not a scene description, or one beyond the bounds of :mod:`llcps.limits`.
        """
        try:
            if not isinstance(data, Mapping):
                raise TypeError(f"expected a JSON object, got {type(data).__name__}")
            entities, fixtures = data.get("entities", ()), data.get("fixtures", ())
            if not isinstance(entities, list | tuple) or not isinstance(fixtures, list | tuple):
                raise TypeError("entities and fixtures must be lists")
            if len(entities) > MAX_ENTITIES or len(entities) + len(fixtures) > MAX_SCENE_BODIES:
                raise ValueError(f"more than {MAX_ENTITIES} entities or {MAX_SCENE_BODIES} entities and fixtures")
            return cls(
                entities=tuple(EntitySpec.from_dict(_object(e)) for e in entities),
                fixtures=tuple(FixtureSpec.from_dict(_object(f)) for f in fixtures),
                table=TableSpec.from_dict(_object(data.get("table", {}))),
                name=str(data.get("name", ""))[:200],
                robot=RobotSpec.from_dict(_object(data.get("robot", {}))),
            )
        except (TypeError, ValueError, AttributeError, KeyError) as exc:
            raise LlcpsError(
                f"not a valid scene description: {exc}", hint="scenes come from SceneSpec.to_dict()"
            ) from exc


def _object(value: Any) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise TypeError(f"expected a JSON object, got {type(value).__name__}")
    return value
