"""The scenario file format: what a TOML scenario file may hold, checked by pydantic.

A file declares the table, the entities (objects and containers), the fixtures (lips,
walls, shelves), the goal as PDDL atoms, and for each condition (``original``,
``novelty``) what differs from the base scene. Wherever the scene may vary, a value
can be a range instead: ``x = [0.36, 0.44]`` for a number, a list of colours for a
colour. docs/scenarios.md describes every field.

Validation errors name the file and the field (``entities[1].size``) with the reason,
and become one :class:`~llcps.errors.LlcpsError` (exit code 2).
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, PlainValidator, ValidationError, field_validator, model_validator

from llcps.domain import COLORS, ORIENTATIONS
from llcps.errors import LlcpsError
from llcps.domain import CONDITIONS as CONDITION_NAMES
from llcps.limits import (
    MAX_DISTANCE,
    MAX_ENTITIES,
    MAX_EXTENT,
    MAX_FRICTION,
    MAX_GOAL_ATOMS,
    MAX_GRID_VALUES,
    MAX_GRIP_FORCE,
    MAX_MASS,
    MAX_MOVEMENT_MAGNITUDE,
    MAX_RATE,
    MAX_SCENE_BODIES,
    MAX_TEXT,
    MIN_RATE,
)
from llcps.sim.specs import BEYOND_REACH

#: What an entity, fixture, scenario or alias name may look like (a PDDL object name).
NAME = re.compile(r"^[a-z][a-z0-9_]*$")
#: Names the simulator gives its own bodies.
RESERVED_NAMES: frozenset[str] = frozenset({"table", "floor"})
#: How many numbers a size lists, per shape: a sphere's diameter, a cylinder's diameter and
#: height, a box's x, y, z.
SIZE_FIELDS: dict[str, str] = {"sphere": "[diameter]", "cylinder": "[diameter, height]", "box": "[x, y, z]"}
SIZE_LENGTH: dict[str, int] = {"sphere": 1, "cylinder": 2, "box": 3}

Range = tuple[float, float]
#: A number, or a range ``(low, high)`` a variant draws from.
Scalar = Union[float, Range]


def _number(value: Any, bound: float = MAX_DISTANCE) -> float | None:
    """A finite number within +-``bound`` (None: not a number at all)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"must be a finite number, got {number}")
    if abs(number) > bound:
        raise ValueError(f"must be within +-{bound:g}, got {number:g}")
    return number


def _scalar(value: Any, *, positive: bool = False, what: str = "a number", bound: float = MAX_DISTANCE) -> Scalar:
    """A number or a ``[low, high]`` range (a variant draws from it), finite and within
    +-``bound`` (:mod:`llcps.limits`); ``positive`` bounds both from below."""
    number = _number(value, bound)
    if number is not None:
        if positive and not number > 0:
            raise ValueError(f"must be positive, got {number}")
        return number
    if isinstance(value, list):
        if not value:
            raise ValueError("an empty range: write a number or [low, high]")
        bounds = [_number(v, bound) for v in value]
        if len(value) != 2 or None in bounds:
            raise ValueError(f"must be {what} or a range [low, high] of numbers, got {value!r}")
        low, high = bounds  # type: ignore[misc]
        if not low < high:  # type: ignore[operator]
            raise ValueError(f"the range [{low}, {high}] is {'empty' if low == high else 'inverted'}: low must be below high")
        if positive and not low > 0:  # type: ignore[operator]
            raise ValueError(f"must be positive, got the range [{low}, {high}]")
        return (low, high)  # type: ignore[return-value]
    raise ValueError(f"must be {what} or a range [low, high], got {value!r}")


AnyScalar = Annotated[Scalar, PlainValidator(lambda v: _scalar(v))]
PositiveScalar = Annotated[Scalar, PlainValidator(lambda v: _scalar(v, positive=True, what="a positive number"))]
#: A positive length of a body (m), at most :data:`~llcps.limits.MAX_EXTENT`.
Extent = Annotated[Scalar, PlainValidator(lambda v: _scalar(v, positive=True, what="a positive number", bound=MAX_EXTENT))]
#: A positive force (N), finite: its bound is checked where it is declared.
Force = Annotated[Scalar, PlainValidator(lambda v: _scalar(v, positive=True, what="a positive number", bound=math.inf))]
#: A positive mass (kg), at most :data:`~llcps.limits.MAX_MASS`.
Mass = Annotated[Scalar, PlainValidator(lambda v: _scalar(v, positive=True, what="a positive number", bound=MAX_MASS))]


def _colors(value: Any) -> str | tuple[str, ...]:
    """One colour, or a list a variant chooses from (the first is variant 0's)."""
    options = value if isinstance(value, list) else [value]
    if not options:
        raise ValueError("an empty list of colors")
    for option in options:
        if option not in COLORS:
            raise ValueError(f"unknown color {option!r}: choose from {', '.join(COLORS)}")
    if len(set(options)) != len(options):
        raise ValueError(f"a color is listed twice in {value!r}")
    return options[0] if len(options) == 1 and not isinstance(value, list) else tuple(options)


Color = Annotated[Union[str, tuple[str, ...]], PlainValidator(_colors)]


def _size(value: Any) -> tuple[Scalar, ...]:
    """A list of positive numbers or ranges; a bare number is a one-element list."""
    items = value if isinstance(value, list) else [value]
    if not items or len(items) > 3:
        raise ValueError(f"must list one to three positive numbers or ranges, got {value!r}")
    return tuple(_scalar(v, positive=True, what="a positive number", bound=MAX_EXTENT) for v in items)


Size = Annotated[tuple[Scalar, ...], PlainValidator(_size)]


def _name(value: Any) -> str:
    if not isinstance(value, str) or not NAME.match(value):
        raise ValueError(f"must be a lower-case name (letters, digits, '_', starting with a letter), got {value!r}")
    if value in RESERVED_NAMES:
        raise ValueError(f"{value!r} is the simulator's own body: choose another name")
    return value


Name = Annotated[str, PlainValidator(_name)]


def _pair(value: Any) -> tuple[Scalar, Scalar]:
    if not isinstance(value, list) or len(value) != 2:
        raise ValueError(f"must be [dx, dy], two numbers or ranges, got {value!r}")
    return (_scalar(value[0]), _scalar(value[1]))


Offset = Annotated[tuple[Scalar, Scalar], PlainValidator(_pair)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _friction_at_most(value: Scalar | None) -> Scalar | None:
    """A friction coefficient (or range) no larger than the engine takes."""
    high = value[1] if isinstance(value, tuple) else value
    if high is not None and high > MAX_FRICTION:
        raise ValueError(f"a friction coefficient is at most {MAX_FRICTION:g}, got {high}")
    return value


class TableModel(_Model):
    """The table (omitted fields keep :class:`~llcps.sim.specs.TableSpec`'s defaults)."""

    x_min: AnyScalar | None = None
    x_max: AnyScalar | None = None
    y_half: Extent | None = None
    height: Extent | None = None
    friction: PositiveScalar | None = None

    @field_validator("friction")
    @classmethod
    def _friction_bound(cls, value: Scalar | None) -> Scalar | None:
        return _friction_at_most(value)


class RobotModel(_Model):
    """What the scene changes about the robot (omitted: the Panda as built)."""

    grip_force: Force | None = None
    reach: PositiveScalar | None = None

    @field_validator("reach")
    @classmethod
    def _reach_bound(cls, value: Scalar | None) -> Scalar | None:
        high = value[1] if isinstance(value, tuple) else value
        if high is not None and high > BEYOND_REACH:
            raise ValueError(f"a reach is at most {BEYOND_REACH:g} m (the arm's own reaches no farther), got {high}")
        return value

    @field_validator("grip_force")
    @classmethod
    def _grip_bound(cls, value: Scalar | None) -> Scalar | None:
        high = value[1] if isinstance(value, tuple) else value
        if high is not None and high > MAX_GRIP_FORCE:
            raise ValueError(f"a grip is at most {MAX_GRIP_FORCE:g} N, got {high}")
        return value


class EntityModel(_Model):
    """One entity: an object (sphere, box, cylinder) or a container (an open box or a bucket)."""

    name: Name
    kind: Literal["object", "container"] = "object"
    shape: Literal["sphere", "box", "cylinder"]
    color: Color
    size: Size
    mass: Mass | None = None
    x: AnyScalar | None = None
    y: AnyScalar | None = None
    yaw: AnyScalar = 0.0
    on: Literal["table", "floor"] = "table"
    inside: Name | None = None
    on_top_of: Name | None = None
    offset: Offset = (0.0, 0.0)
    wall: Extent | None = None
    friction: PositiveScalar | None = None
    reachable: bool | None = None

    @field_validator("size")
    @classmethod
    def _size_fits_shape(cls, size: tuple[Scalar, ...], info: Any) -> tuple[Scalar, ...]:
        shape = info.data.get("shape")
        if shape in SIZE_LENGTH and len(size) != SIZE_LENGTH[shape]:
            count = ("one", "two", "three")[SIZE_LENGTH[shape] - 1]
            raise ValueError(f"must be {count} positive number{'s' if SIZE_LENGTH[shape] > 1 else ''} (a {shape}'s size is {SIZE_FIELDS[shape]})")
        return size

    @model_validator(mode="after")
    def _placement(self) -> "EntityModel":
        if self.kind == "container" and self.shape == "sphere":
            raise _FieldError("shape", "a container is a box (an open box) or a cylinder (a bucket)")
        if self.kind == "object" and self.wall is not None:
            raise _FieldError("wall", "only a container has a wall")
        if self.inside is not None and self.on_top_of is not None:
            raise _FieldError("inside", "an entity is either inside a container or on top of another entity")
        placed = self.inside or self.on_top_of
        if placed is not None:
            if self.kind == "container" and self.inside is not None:
                raise _FieldError("inside", "a container cannot be put inside another")
            for key in ("x", "y"):
                if getattr(self, key) is not None:
                    raise _FieldError(key, f"an entity {'inside' if self.inside else 'on top of'} {placed!r} takes its place from it: use offset = [dx, dy]")
        else:
            for key in ("x", "y"):
                if getattr(self, key) is None:
                    raise _FieldError(key, "missing: where the entity stands (or give inside = / on_top_of =)")
        return self


    @field_validator("friction")
    @classmethod
    def _friction_bound(cls, value: Scalar | None) -> Scalar | None:
        return _friction_at_most(value)


class _FieldError(ValueError):
    """A model-level check that blames one field."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field
        self.message = message


class LipModel(_Model):
    """A lip or fence along one table edge."""

    type: Literal["lip"]
    name: Name = "lip"
    side: Literal["front", "left", "right"]
    height: Extent = 0.06
    thickness: Extent = 0.02


class WallModel(_Model):
    """A static box standing on the table or the floor."""

    type: Literal["wall"]
    name: Name = "wall"
    size: Size
    x: AnyScalar
    y: AnyScalar
    yaw: AnyScalar = 0.0
    on: Literal["table", "floor"] = "table"
    color: Literal["wood", "gray", "dark"] = "gray"

    @field_validator("size")
    @classmethod
    def _three(cls, size: tuple[Scalar, ...]) -> tuple[Scalar, ...]:
        if len(size) != 3:
            raise ValueError("must be three positive numbers (a wall's size is [x, y, z])")
        return size


class ShelfModel(_Model):
    """A board ``clearance`` above the table on a post at its far side."""

    type: Literal["shelf"]
    name: Name = "shelf"
    x: AnyScalar
    y: AnyScalar
    clearance: Extent
    size: Size = (0.3, 0.3, 0.02)
    post: bool = True

    @field_validator("size")
    @classmethod
    def _three(cls, size: tuple[Scalar, ...]) -> tuple[Scalar, ...]:
        if len(size) != 3:
            raise ValueError("must be three positive numbers (a shelf's size is [x, y, z])")
        return size


FixtureModel = Annotated[Union[LipModel, WallModel, ShelfModel], Field(discriminator="type")]
#: Kinds of fixture a file may declare.
FIXTURE_TYPES: tuple[str, ...] = ("lip", "wall", "shelf")


class ConditionModel(_Model):
    """What one condition changes: fields of named entities, extra fixtures, the table."""

    entities: dict[str, dict[str, Any]] = {}
    fixtures: list[FixtureModel] = Field([], max_length=MAX_SCENE_BODIES)
    table: TableModel | None = None
    robot: RobotModel | None = None


class GridModel(_Model):
    """The candidate grid exploration searches (omitted fields: the default grid), within
    the bounds of :mod:`llcps.limits`."""

    rates: tuple[float, ...] | None = None
    movement_magnitudes: tuple[float, ...] | None = None
    orientations: tuple[Literal["left", "top", "right", "front"], ...] | None = None

    @field_validator("rates", "movement_magnitudes")
    @classmethod
    def _values(cls, values: tuple[float, ...] | None, info: Any) -> tuple[float, ...] | None:
        if values is None:
            return None
        if not values:
            raise ValueError("an empty list: omit the field for the default grid")
        if len(values) > MAX_GRID_VALUES:
            raise ValueError(f"{len(values)} values, more than the {MAX_GRID_VALUES} a grid axis may list")
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"must be finite numbers, got {list(values)!r}")
        if len(set(values)) != len(values):
            raise ValueError("a value is listed twice")
        if info.field_name == "rates":
            if not all(MIN_RATE <= v <= MAX_RATE for v in values):
                raise ValueError(f"rates must lie within [{MIN_RATE:g}, {MAX_RATE:g}] m/s")
        elif not all(0 <= v <= MAX_MOVEMENT_MAGNITUDE for v in values):
            raise ValueError(f"movement magnitudes must lie within [0, {MAX_MOVEMENT_MAGNITUDE:g}] m")
        return values

    @field_validator("orientations")
    @classmethod
    def _orientations(cls, values: tuple[str, ...] | None) -> tuple[str, ...] | None:
        if values is not None and (not values or len(set(values)) != len(values)):
            raise ValueError(f"must list distinct orientations of {', '.join(ORIENTATIONS)}")
        return values


class ScenarioModel(_Model):
    """A whole scenario file."""

    name: Name
    alias: Name | None = None
    title: str = Field("", max_length=MAX_TEXT)
    story: str = Field("", max_length=MAX_TEXT)
    goal: list[str] = Field(min_length=1, max_length=MAX_GOAL_ATOMS)
    table: TableModel = TableModel()
    robot: RobotModel = RobotModel()
    entities: list[EntityModel] = Field(min_length=1, max_length=MAX_ENTITIES)
    fixtures: list[FixtureModel] = Field([], max_length=MAX_SCENE_BODIES)
    conditions: dict[Literal["original", "novelty"], ConditionModel] = {}
    grid: GridModel = GridModel()


#: Fields an entity declares, in the file's order (conditions may change any but the name).
ENTITY_FIELDS: tuple[str, ...] = tuple(EntityModel.model_fields)


def field_path(loc: tuple[Any, ...]) -> str:
    """``("entities", 1, "size")`` -> ``entities[1].size``."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def _reason(error: dict[str, Any]) -> tuple[tuple[Any, ...], str]:
    loc = tuple(p for p in error["loc"] if not (isinstance(p, str) and p in ("lip", "wall", "shelf", "function-plain[<lambda>()]")))
    ctx = error.get("ctx") or {}
    exc = ctx.get("error")
    if isinstance(exc, _FieldError):
        return (*loc, exc.field), exc.message
    kind = error["type"]
    if kind == "extra_forbidden":
        return loc, "unknown key"
    if kind == "missing":
        return loc, "missing"
    if kind == "too_long":
        what = "characters" if "string" in error["msg"].lower() else "items"
        return loc, f"{ctx.get('actual_length', 'too many')} {what}, more than the {ctx.get('max_length')} allowed"
    if kind == "union_tag_invalid":
        return (*loc, "type"), f"unknown fixture type {ctx.get('tag')!r}: choose from {', '.join(FIXTURE_TYPES)}"
    if kind == "union_tag_not_found":
        return (*loc, "type"), f"missing: the fixture's type, one of {', '.join(FIXTURE_TYPES)}"
    message = str(exc) if isinstance(exc, ValueError) else error["msg"]
    return loc, message[0].lower() + message[1:] if message else message


#: The hint of an error about a limit of :mod:`llcps.limits`.
LIMITS_HINT = "see Limits in docs/scenarios.md: a scenario file stays within them"


def _hint(error: dict[str, Any]) -> str | None:
    """The limits hint for an error about a limit (too many items, a number out of bounds)."""
    exc = (error.get("ctx") or {}).get("error")
    if error["type"] == "too_long" or (isinstance(exc, ValueError) and any(w in str(exc) for w in ("within", "more than", "finite"))):
        return LIMITS_HINT
    return None


def validation_error(where: str, exc: ValidationError, *, prefix: tuple[Any, ...] = ()) -> LlcpsError:
    """The first error of a pydantic validation as one project error naming file and field."""
    first = exc.errors(include_url=False)[0]
    loc, message = _reason(first)
    return file_error(where, (*prefix, *loc), message, hint=_hint(first))


def file_error(where: str, loc: tuple[Any, ...] | str, message: str, *, hint: str | None = None) -> LlcpsError:
    """``<file>: <field>: <message>`` with a hint at the fix."""
    path = loc if isinstance(loc, str) else field_path(loc)
    return LlcpsError(
        f"{where}: {path}: {message}" if path else f"{where}: {message}",
        hint=hint or "see the file format in docs/scenarios.md, or `llcps scenario show scenario1` for a working file",
    )


def validate(where: str, data: dict[str, Any]) -> ScenarioModel:
    """A parsed TOML document as a :class:`ScenarioModel`, or one error naming the field."""
    try:
        return ScenarioModel.model_validate(data)
    except ValidationError as exc:
        raise validation_error(where, exc) from None


def validate_entity(where: str, data: dict[str, Any], blame: dict[str, tuple[Any, ...]]) -> EntityModel:
    """An entity with a condition's changes applied; an error is blamed on the field's source."""
    try:
        return EntityModel.model_validate(data)
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        loc, message = _reason(first)
        field = loc[0] if loc else ""
        origin = blame.get(str(field), ())
        return_loc = (*origin, *loc[1:]) if origin else loc
        raise file_error(where, return_loc, message, hint=_hint(first)) from None


__all__ = [
    "CONDITION_NAMES",
    "ENTITY_FIELDS",
    "EntityModel",
    "FixtureModel",
    "GridModel",
    "LipModel",
    "Range",
    "Scalar",
    "RobotModel",
    "ScenarioModel",
    "ShelfModel",
    "TableModel",
    "WallModel",
    "file_error",
    "validate",
    "validate_entity",
]
