"""Reading a scenario file: TOML in, a checked :class:`ScenarioSource` out, and the
concrete scene of any condition and variant from it.

Everything a file can get wrong is caught here, before anything is simulated or
stored: the format (:mod:`llcps.scenarios.file_format`), names that do not exist (goal
atoms, containers, condition changes), and the canonical layout itself
(:mod:`llcps.scenarios.layout`). Each error names the file and the field.
"""

from __future__ import annotations

import copy
import json
import math
import re
import tomllib
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping

from llcps.domain import Fluent
from llcps.errors import LlcpsError
from llcps.inputs import read_user_text
from llcps.limits import MAX_FILE_DEPTH, MAX_FILE_ITEMS, MAX_SCENARIO_FILE_BYTES, MAX_TEXT
from llcps.scenarios import file_format, layout
from llcps.scenarios.goal import parse_atom
from llcps.scenarios.file_format import CONDITION_NAMES, LIMITS_HINT, EntityModel, ScenarioModel, file_error
from llcps.scenarios.variants import MAX_ATTEMPTS, Draws, check_variant
from llcps.sim.builders import bucket, edge_lip, inside, open_box, shelf, solid, stacked
from llcps.sim.specs import EntitySpec, FixtureSpec, RobotSpec, SceneSpec, TableSpec

#: Fields whose value is a number or a range.
_NUMBER_FIELDS = frozenset({"x", "y", "yaw", "mass", "wall", "height", "thickness", "clearance", "x_min", "x_max", "y_half", "friction", "grip_force", "reach"})
#: Fields that list numbers or ranges.
_LIST_FIELDS = frozenset({"size", "offset"})


@dataclass(frozen=True)
class ScenarioSource:
    """A checked scenario file.

    Attributes:
        where: how errors name the file (its path as given).
        path: the file (None for text that came from elsewhere).
        text: the file's text, as read.
        data: the parsed TOML document.
        model: the validated document.
        goal_pos, goal_neg: the goal's atoms that must and must not hold.
    """

    where: str
    path: Path | None
    text: str
    data: Mapping[str, Any]
    model: ScenarioModel
    goal_pos: frozenset[Fluent]
    goal_neg: frozenset[Fluent]
    _entities: Mapping[str, tuple[EntityModel, ...]] = field(repr=False, compare=False)
    _attempts: dict[int, int] = field(default_factory=dict, repr=False, compare=False)
    _scenes: dict[tuple[str, int], Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def name(self) -> str:
        return self.model.name

    @property
    def varies(self) -> bool:
        """Whether any field is a range or a list of colours (else every variant is variant 0)."""
        return _varies(self.data)

    def entities(self, condition: str) -> tuple[EntityModel, ...]:
        """The entities of a condition, its changes applied, in the file's order."""
        return self._entities[condition]

    def scene(self, condition: str, variant: int = 0) -> Any:
        """The concrete :class:`~llcps.sim.specs.SceneSpec` of ``condition`` in ``variant``.

        The same (file, condition, variant) gives the same scene, bit for bit.
        """
        if condition not in CONDITION_NAMES:
            raise LlcpsError(f"unknown condition {condition!r}", hint=f"choose one of: {', '.join(CONDITION_NAMES)}")
        check_variant(variant)
        key = (condition, variant)
        if key not in self._scenes:
            attempt = self.attempt(variant)
            self._scenes[key] = self._build(condition, Draws(variant, attempt))[0]
        return self._scenes[key]

    def attempt(self, variant: int) -> int:
        """The first draw of ``variant`` whose layout is valid in both conditions."""
        check_variant(variant)
        if variant in self._attempts:
            return self._attempts[variant]
        last: tuple[str, layout.Problem] | None = None
        for attempt in range(MAX_ATTEMPTS if variant and self.varies else 1):
            draws = Draws(variant, attempt)
            last = None
            for condition in CONDITION_NAMES:
                scene, declared = self._build(condition, draws)
                found = layout.problems(scene, declared)
                if found:
                    last = (condition, found[0])
                    break
            if last is None:
                self._attempts[variant] = attempt
                return attempt
        assert last is not None
        condition, problem = last
        where = self._entity_path(problem.name)
        if variant == 0:
            raise file_error(
                self.where,
                where,
                f"{problem.message} (in the {condition} condition)",
                hint="move or resize it so that nothing overlaps or floats, and reach is as declared",
            )
        raise file_error(
            self.where,
            where,
            f"variant {variant}: no valid layout in {MAX_ATTEMPTS} draws; the last {problem.message} (in the {condition} condition)",
            hint="narrow the ranges that let entities overlap, float or leave the arm's reach",
        )

    def concrete(self, variant: int) -> dict[str, Any]:
        """The file with every range replaced by ``variant``'s value: a file of that scene alone."""
        draws = Draws(variant, self.attempt(variant))
        data = _resolve(copy.deepcopy(dict(self.data)), draws)
        if variant:  # a file of its own: a name of its own
            data["name"] = f"{self.model.name}_v{variant}"
            data.pop("alias", None)
        return data

    def _entity_path(self, name: str) -> str:
        for index, entity in enumerate(self.model.entities):
            if entity.name == name:
                return f"entities[{index}] ({name})"
        return name

    @contextmanager
    def _blamed(self, where: str, condition: str) -> Iterator[None]:
        """A value the scene's own checks refuse (a wall too thick for its container) as an
        error naming the file and the part of it."""
        try:
            yield
        except ValueError as exc:
            raise file_error(self.where, where, f"{exc} (in the {condition} condition)") from None

    def _build(self, condition: str, draws: Draws) -> tuple[Any, dict[str, layout.Declared]]:
        table_fields = dict(self.model.table.model_dump(exclude_none=True))
        changes = self.model.conditions.get(condition)
        if changes is not None and changes.table is not None:
            table_fields.update(changes.table.model_dump(exclude_none=True))
        with self._blamed("table", condition):
            table = TableSpec(**{k: draws.number(v, f"table.{k}") for k, v in table_fields.items()})
        robot_fields = dict(self.model.robot.model_dump(exclude_none=True))
        if changes is not None and changes.robot is not None:
            robot_fields.update(changes.robot.model_dump(exclude_none=True))
        with self._blamed("robot", condition):
            robot = RobotSpec(**{k: draws.number(v, f"robot.{k}") for k, v in robot_fields.items()})
        entities = self.entities(condition)
        built: dict[str, Any] = {}
        pending = list(entities)
        while pending:  # containers and supports before what rests on them (no cycles: checked at load)
            ready = [e for e in pending if (e.inside or e.on_top_of) is None or (e.inside or e.on_top_of) in built]
            for entity in ready:
                with self._blamed(self._entity_path(entity.name), condition):
                    built[entity.name] = _entity_spec(entity, draws, built, table.floor_z)
                pending.remove(entity)
        fixtures: list[Any] = []
        for fixture in (*self.model.fixtures, *(changes.fixtures if changes is not None else ())):
            with self._blamed(f"fixtures ({fixture.name})", condition):
                fixtures.extend(_fixture_specs(fixture, draws, table))
        suffix = "" if draws.variant == 0 else f"/v{draws.variant}"
        try:
            scene = SceneSpec(
                entities=tuple(built[e.name] for e in entities),
                fixtures=tuple(fixtures),
                table=table,
                name=f"{self.model.name}/{condition}{suffix}",
                robot=robot,
            )
        except ValueError as exc:
            raise file_error(self.where, f"conditions.{condition}", str(exc)) from None
        declared = {
            e.name: layout.Declared(rests_in=e.inside, rests_on=e.on_top_of, reachable=e.reachable) for e in entities
        }
        return scene, declared


def _entity_spec(m: EntityModel, d: Draws, built: Mapping[str, Any], floor_z: float) -> Any:
    """The spec of one entity, through the same builders hand-written scenes use."""
    spec = _built_entity(m, d, built, floor_z)
    if m.friction is None:
        return spec
    return EntitySpec(**{**asdict(spec), "friction": d.number(m.friction, f"entities.{m.name}.friction")})


def _built_entity(m: EntityModel, d: Draws, built: Mapping[str, Any], floor_z: float) -> Any:
    key = f"entities.{m.name}"
    size = [d.number(v, f"{key}.size[{i}]") for i, v in enumerate(m.size)]
    color = d.choice(m.color, f"{key}.color")
    yaw = d.number(m.yaw, f"{key}.yaw")
    mass = None if m.mass is None else d.number(m.mass, f"{key}.mass")
    on = 0.0 if m.on == "table" else floor_z
    placed = m.inside is not None or m.on_top_of is not None
    offset = (d.number(m.offset[0], f"{key}.offset[0]"), d.number(m.offset[1], f"{key}.offset[1]")) if placed else (0.0, 0.0)
    at = (0.0, 0.0) if placed else (d.number(m.x, f"{key}.x"), d.number(m.y, f"{key}.y"))  # type: ignore[arg-type]
    if m.kind == "object":
        made = solid(m.name, m.shape, color, size, at=at, on=on, yaw=yaw, mass=mass)
        if m.inside is not None:
            return inside(made, built[m.inside], offset=offset)
    else:
        extra: dict[str, float] = {}
        if mass is not None:
            extra["mass"] = mass
        if m.wall is not None:
            extra["wall"] = d.number(m.wall, f"{key}.wall")
        if m.shape == "box":
            made = open_box(m.name, color, at=at, size=size, on=on, yaw=yaw, **extra)
        else:
            made = bucket(m.name, color, at=at, diameter=size[0], height=size[1], on=on, **extra)
    return made if m.on_top_of is None else stacked(made, built[m.on_top_of], offset=offset)


def _fixture_specs(f: Any, d: Draws, table: Any) -> tuple[Any, ...]:
    key = f"fixtures.{f.name}"
    if f.type == "lip":
        return (
            edge_lip(
                table, f.side, height=d.number(f.height, f"{key}.height"), thickness=d.number(f.thickness, f"{key}.thickness"), name=f.name
            ),
        )
    size = tuple(d.number(v, f"{key}.size[{i}]") for i, v in enumerate(f.size))
    x, y = d.number(f.x, f"{key}.x"), d.number(f.y, f"{key}.y")
    if f.type == "shelf":
        return shelf(f.name, at=(x, y), clearance=d.number(f.clearance, f"{key}.clearance"), size=size, post=f.post)
    base = 0.0 if f.on == "table" else table.floor_z
    return (FixtureSpec(f.name, size, (x, y, base + size[2] / 2), d.number(f.yaw, f"{key}.yaw"), f.color),)


def _varies(data: Any) -> bool:
    if isinstance(data, dict):
        return any(
            (k in _NUMBER_FIELDS and isinstance(v, list))
            or (k in _LIST_FIELDS and isinstance(v, list) and any(isinstance(e, list) for e in v))
            or (k == "color" and isinstance(v, list) and len(v) > 1)
            or _varies(v)
            for k, v in data.items()
            if k != "grid"
        )
    if isinstance(data, list):
        return any(_varies(v) for v in data)
    return False


def _resolve(data: dict[str, Any], draws: Draws) -> dict[str, Any]:
    """Replace every range of a parsed file by its drawn value (keys as the scene builder uses)."""

    def fields(item: dict[str, Any], key: str) -> None:
        for name, value in list(item.items()):
            if name in _NUMBER_FIELDS and isinstance(value, list):
                item[name] = draws.number(tuple(value), f"{key}.{name}")  # type: ignore[arg-type]
            elif name in _LIST_FIELDS and isinstance(value, list):
                item[name] = [
                    draws.number(tuple(v) if isinstance(v, list) else v, f"{key}.{name}[{i}]") for i, v in enumerate(value)
                ]
            elif name == "color" and isinstance(value, list):
                item[name] = draws.choice(tuple(value), f"{key}.color")

    for entity in data.get("entities", []):
        fields(entity, f"entities.{entity.get('name')}")
    for fixture in data.get("fixtures", []):
        fields(fixture, f"fixtures.{fixture.get('name', fixture.get('type'))}")
    for section in ("table", "robot"):
        if isinstance(data.get(section), dict):
            fields(data[section], section)
    for changes in data.get("conditions", {}).values():
        for name, patch in changes.get("entities", {}).items():
            fields(patch, f"entities.{name}")
        for fixture in changes.get("fixtures", []):
            fields(fixture, f"fixtures.{fixture.get('name', fixture.get('type'))}")
        for section in ("table", "robot"):
            if isinstance(changes.get(section), dict):
                fields(changes[section], section)
    return data


def read_text(text: str, *, where: str, path: Path | None = None, reserved: Mapping[str, str] | None = None) -> ScenarioSource:
    """Check a scenario file's text (see the module docstring).

    Args:
        text: TOML.
        where: how errors name the file.
        path: the file it came from.
        reserved: names and aliases the file may not take (the shipped scenarios'), with
            whose they are.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise file_error(where, "", f"not valid TOML: {exc}", hint="check the line named above against docs/scenarios.md") from None
    except RecursionError:  # tomllib parses nested arrays and inline tables recursively
        raise file_error(where, "", f"arrays or tables nested deeper than the {MAX_FILE_DEPTH} levels allowed", hint=LIMITS_HINT) from None
    _check_bounds(where, data)
    named = "name" in data
    if not named:
        data = {"name": _stem_name(where, path), **data}
    model = file_format.validate(where, data)
    for key in ("name", "alias"):
        value = getattr(model, key)
        if value is not None and reserved and value in reserved:
            if key == "name" and not named:
                raise file_error(
                    where,
                    key,
                    f"the file has no name, and its file name gives it {value!r}, the shipped scenario {reserved[value]}'s name",
                    hint='rename the file (my.toml names the scenario "my") or set name = "..." in it',
                )
            raise file_error(where, key, f"{value!r} is the shipped scenario {reserved[value]}'s name", hint=f"give the file a {key} of its own")
    entities = {condition: _merged_entities(where, data, model, condition) for condition in CONDITION_NAMES}
    names = _check_names(where, model, entities)
    positive: set[Fluent] = set()
    negative: set[Fluent] = set()
    for index, atom in enumerate(model.goal):
        try:
            holds, atom_ = parse_atom(atom, names)
        except ValueError as exc:
            raise file_error(where, ("goal", index), str(exc)) from None
        if atom_ in (negative if holds else positive):
            raise file_error(
                where,
                ("goal", index),
                f"{atom!r} contradicts another atom of the goal: an atom and its negation cannot both hold",
                hint="remove one of the two atoms",
            )
        (positive if holds else negative).add(atom_)
    source = ScenarioSource(
        where=where,
        path=path,
        text=text,
        data=data,
        model=model,
        goal_pos=frozenset(positive),
        goal_neg=frozenset(negative),
        _entities=entities,
    )
    source.attempt(0)  # the canonical layout must be valid
    return source


def _check_bounds(where: str, data: Mapping[str, Any]) -> None:
    """The document's shape within :mod:`llcps.limits`, before any field is validated:
    nesting depth, items per array or table, text length, finite numbers. Iterative, so
    that no document can exhaust the stack."""
    stack: list[tuple[Any, tuple[Any, ...]]] = [(data, ())]
    while stack:
        value, loc = stack.pop()
        if isinstance(value, (dict, list)):
            if len(loc) >= MAX_FILE_DEPTH:
                raise file_error(where, loc, f"nested deeper than the {MAX_FILE_DEPTH} levels allowed", hint=LIMITS_HINT)
            if len(value) > MAX_FILE_ITEMS:
                raise file_error(where, loc, f"{len(value)} items, more than the {MAX_FILE_ITEMS} allowed", hint=LIMITS_HINT)
            items = value.items() if isinstance(value, dict) else enumerate(value)
            stack.extend((item, (*loc, key)) for key, item in reversed(list(items)))
        elif isinstance(value, str):
            if len(value) > MAX_TEXT:
                raise file_error(where, loc, f"{len(value):,} characters, more than the {MAX_TEXT:,} allowed", hint=LIMITS_HINT)
        elif isinstance(value, float) and not math.isfinite(value):
            raise file_error(where, loc, f"must be a finite number, got {value}", hint="write a number (nan and inf are not one)")


def _stem_name(where: str, path: Path | None) -> str:
    """The name of a file that declares none: its file name without ``.toml``, lower-case,
    with ``-`` and spaces as ``_`` (``My-Bin.toml`` names ``my_bin``)."""
    hint = 'set name = "..." in the file (lower-case letters, digits and _, starting with a letter)'
    if path is None:
        raise file_error(where, "name", "the scenario has no name", hint=hint)
    name = path.stem.lower().replace("-", "_").replace(" ", "_")
    if not file_format.NAME.match(name) or name in file_format.RESERVED_NAMES:
        raise file_error(where, "name", f"the file has no name, and its file name {path.stem!r} is not one", hint=f"rename the file or {hint}")
    return name


#: Top-level ``name`` and ``alias`` lines of a scenario file.
_NAME_LINE = re.compile(r"^(name|alias)\s*=")


def without_shipped_names(text: str) -> str:
    """A shipped file's text with its ``name`` and ``alias`` commented out, for a copy of
    one's own: the copy then takes its name from its file name (or from a name set in it),
    as two scenarios may not share a name."""
    out: list[str] = []
    top, noted = True, False
    for line in text.splitlines(keepends=True):
        if line.lstrip().startswith("["):  # the top-level keys end at the first table
            top = False
        if top and _NAME_LINE.match(line):
            if not noted:
                out.append(
                    "# The shipped scenario's name and alias, left for you to set: a file without a name\n"
                    '# takes its file name (my.toml names the scenario "my"); no two scenarios share one.\n'
                )
                noted = True
            line = f"# {line}"
        out.append(line)
    return "".join(out)


def read_file(path: str | Path, *, reserved: Mapping[str, str] | None = None) -> ScenarioSource:
    """Read and check a scenario file (see :func:`read_text`)."""
    path = Path(path)
    text = read_user_text(
        path,
        what="scenario file",
        max_bytes=MAX_SCENARIO_FILE_BYTES,
        hint="give the path of a UTF-8 .toml file, or a scenario name (`llcps scenario list`)",
    )
    return read_text(text, where=str(path), path=path, reserved=reserved)


#: How an entity's place is given: on a surface at (x, y), or inside / on top of another entity.
_ON_SURFACE, _ON_ENTITY = ("x", "y"), ("inside", "on_top_of", "offset")


def _placement_replaced(raw: Mapping[str, Any], patch: Mapping[str, Any]) -> dict[str, Any]:
    """The base entity's fields without the placement a condition's patch gives anew: a
    patch that puts the entity inside or on top of another drops the base's ``x``/``y``
    (and its other ``inside``/``on_top_of``), one that gives ``x`` or ``y`` drops the base's
    ``inside``/``on_top_of``/``offset``, so one condition may stand on the table what the
    other puts in a container."""
    base = dict(raw)
    if any(key in patch for key in ("inside", "on_top_of")):
        for key in (*_ON_SURFACE, *_ON_ENTITY):
            if key not in patch:
                base.pop(key, None)
    elif any(key in patch for key in _ON_SURFACE):
        for key in _ON_ENTITY:
            base.pop(key, None)
    return base


def _merged_entities(where: str, data: Mapping[str, Any], model: ScenarioModel, condition: str) -> tuple[EntityModel, ...]:
    """The base entities with one condition's changes applied, each checked again."""
    changes = model.conditions.get(condition)
    patches = changes.entities if changes is not None else {}
    known = [e.name for e in model.entities]
    for name, patch in patches.items():
        if name not in known:
            raise file_error(where, ("conditions", condition, "entities", name), f"no entity named {name!r} (the file has {', '.join(known)})")
        if "name" in patch:
            raise file_error(where, ("conditions", condition, "entities", name, "name"), "a condition cannot rename an entity")
    merged: list[EntityModel] = []
    for index, (entity, raw) in enumerate(zip(model.entities, data["entities"])):
        patch = patches.get(entity.name)
        if not patch:
            merged.append(entity)
            continue
        base = _placement_replaced(raw, patch)
        blame: dict[str, tuple[Any, ...]] = {k: ("entities", index, k) for k in base}
        blame.update({k: ("conditions", condition, "entities", entity.name, k) for k in patch})
        merged.append(file_format.validate_entity(where, {**base, **patch}, blame))
    return tuple(merged)


def _check_names(where: str, model: ScenarioModel, entities: Mapping[str, tuple[EntityModel, ...]]) -> set[str]:
    """Names are unique and every reference names what it must; returns every name a goal may use."""
    seen_names: set[str] = set()
    for index, entity in enumerate(model.entities):
        if entity.name in seen_names:
            raise file_error(where, ("entities", index, "name"), f"{entity.name!r} names two entities", hint="give every entity its own name")
        seen_names.add(entity.name)
    names: set[str] = {"table"}
    for condition in CONDITION_NAMES:
        changes = model.conditions.get(condition)
        fixtures = [*model.fixtures, *(changes.fixtures if changes is not None else ())]
        seen: dict[str, str] = {}
        for index, entity in enumerate(entities[condition]):
            seen[entity.name] = f"entities[{index}]"
        for fixture in fixtures:
            for name in (fixture.name, f"{fixture.name}_post") if fixture.type == "shelf" and fixture.post else (fixture.name,):
                if name in seen:
                    raise file_error(where, "fixtures", f"the name {name!r} is used twice ({seen[name]} has it too)", hint="give every entity and fixture its own name")
                seen[name] = "a fixture"
        names.update(seen)
        by_name = {e.name: e for e in entities[condition]}
        for index, entity in enumerate(entities[condition]):
            for key in ("inside", "on_top_of"):
                target = getattr(entity, key)
                if target is None:
                    continue
                if target not in by_name or target == entity.name:
                    raise file_error(where, ("entities", index, key), f"no other entity named {target!r}")
                if key == "inside" and by_name[target].kind != "container":
                    raise file_error(where, ("entities", index, key), f"{target!r} is not a container")
            chain, current = [entity.name], entity
            while (current.inside or current.on_top_of) is not None:
                current = by_name[current.inside or current.on_top_of]  # type: ignore[index]
                if current.name in chain:
                    raise file_error(where, ("entities", index), f"rests on itself through {' -> '.join(chain + [current.name])}")
                chain.append(current.name)
    return names


def dump(source: ScenarioSource, *, fmt: str, variant: int | None = None, reserved: Mapping[str, str] | None = None) -> str:
    """The file as TOML (its own text, or a variant's concrete file) or as JSON.

    A TOML file whose name is in ``reserved`` (a shipped scenario's) has its ``name`` and
    ``alias`` commented out, so that the copy loads back as a scenario of its own, named
    by its file name; JSON, for scripts, keeps every key."""
    if fmt not in ("toml", "json"):
        raise LlcpsError(f"unknown format {fmt!r}", hint="choose toml or json")
    data = source.concrete(variant) if variant is not None else dict(source.data)
    if fmt == "json":
        return json.dumps(data, indent=2) + "\n"
    shipped = reserved is not None and data.get("name") in reserved
    if variant is None:
        return without_shipped_names(source.text) if shipped else source.text
    import tomli_w

    header = (
        f"# Variant {variant} of {source.name} ({Path(source.where).name}) with every range drawn:\n"
        f"# its variant 0 is that scene (`llcps scenario show {source.name} --variant {variant}`).\n"
    )
    if shipped:
        data = {k: v for k, v in data.items() if k not in ("name", "alias")}
        header += '# No name: the file takes its file name (my.toml names the scenario "my"), or set one.\n'
    return header + tomli_w.dumps(data)


__all__ = ["ScenarioSource", "dump", "read_file", "read_text", "without_shipped_names"]
