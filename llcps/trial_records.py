"""What one trial is: its call (spec), the world model's input, its meta-outcome Omega,
the record the experience store keeps of it, the bodies it saw and the symbolic change
it made. The vocabulary these are written in is :mod:`llcps.domain`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Protocol

from llcps.domain import (
    ACTIONS,
    ACTION_ARITY,
    BODY_KINDS,
    CHANGE_SOURCES,
    ControllerParams,
    ENTITY_NUMBERS,
    EntityFeatures,
    Fluent,
    OUTCOME_FLUENTS,
    OUTCOME_NAMES,
    SHAPES,
    State,
)


class StoredFeatures:
    """A trial's Table-1 features as a store holds them: names and numbers, checked.

    ``names`` are each entity's shape and colour in turn, ``numbers`` its
    :data:`ENTITY_NUMBERS` in turn. A record read from a store carries these and builds
    its :class:`EntityFeatures` on first use (:meth:`entities`), once for all the records
    that share them: a load of 100,000 trials would otherwise build 200,000 objects
    that a fit, which reads names and numbers, never looks at.
    """

    __slots__ = ("names", "numbers", "_entities")

    def __init__(self, names: tuple[str, ...], numbers: tuple[float, ...]) -> None:
        self.names = names
        self.numbers = numbers
        self._entities: tuple[EntityFeatures, ...] | None = None

    @classmethod
    def of(cls, features: Iterable[EntityFeatures]) -> "StoredFeatures":
        """The names and numbers of built features."""
        entities = tuple(features)
        stored = cls(
            tuple(name for f in entities for name in (f.shape, f.color)),
            tuple(float(getattr(f, n)) for f in entities for n in ENTITY_NUMBERS),
        )
        stored._entities = entities
        return stored

    def __len__(self) -> int:
        return len(self.names) // 2

    def entity_fields(self, i: int) -> dict[str, float | str]:
        """Argument ``i``'s features by field name, as ``entities()[i].as_dict()`` gives them."""
        names, (v, m, x, y, z) = self.names, self.numbers[5 * i : 5 * i + 5]
        return {"shape": names[2 * i], "volume": v, "color": names[2 * i + 1], "vector_magnitude": m, "unit_x": x, "unit_y": y, "unit_z": z}

    def entities(self) -> tuple[EntityFeatures, ...]:
        """One EntityFeatures per argument, built once."""
        if self._entities is None:
            new, set_dict = object.__new__, object.__setattr__
            out = []
            for i in range(len(self)):
                entity = new(EntityFeatures)  # checked values only: the store checks them before holding them
                set_dict(entity, "__dict__", self.entity_fields(i))
                out.append(entity)
            self._entities = tuple(out)
        return self._entities

    def __repr__(self) -> str:
        return f"StoredFeatures({self.names!r}, {self.numbers!r})"


@dataclass(frozen=True)
class TrialSpec:
    """What to execute: an action a_i, its arguments and controller settings r_i."""

    action: str
    arguments: tuple[str, ...]
    params: ControllerParams

    def __post_init__(self) -> None:
        if self.action not in ACTIONS:
            raise ValueError(f"unknown action {self.action!r}; expected one of {ACTIONS}")
        if len(self.arguments) != ACTION_ARITY[self.action]:
            raise ValueError(
                f"{self.action} takes {ACTION_ARITY[self.action]} argument(s), got {self.arguments}"
            )

    @property
    def label(self) -> str:
        p = self.params
        return (
            f"{self.action}({', '.join(self.arguments)}) "
            f"rate={p.rate:g} magnitude={p.movement_magnitude:g} orientation={p.orientation}"
        )


@dataclass(frozen=True)
class WorldModelInput:
    """One input of the world model W: (a_i, r_i, nabla_i, X_i).

    ``features`` holds one :class:`EntityFeatures` per argument, in argument order.
    Both stored trials and not-yet-executed candidates are described this way.
    """

    spec: TrialSpec
    features: tuple[EntityFeatures, ...]


@dataclass(frozen=True)
class Outcome:
    """Omega: six meta-level symbolic changes (Table 2).

    A bit is True when at least one fluent instance of that kind changed that way.
    """

    positive_visibility: bool = False
    negative_visibility: bool = False
    positive_reachability: bool = False
    negative_reachability: bool = False
    positive_touching: bool = False
    negative_touching: bool = False

    @classmethod
    def between(cls, before: Iterable[Fluent], after: Iterable[Fluent]) -> "Outcome":
        """Compute Omega from the fluent sets before and after a trial."""
        before_set, after_set = frozenset(before), frozenset(after)
        bits: dict[str, bool] = {}
        for predicate, stem in OUTCOME_FLUENTS.items():
            gained = any(f[0] == predicate for f in after_set - before_set)
            lost = any(f[0] == predicate for f in before_set - after_set)
            bits[f"positive_{stem}"] = gained
            bits[f"negative_{stem}"] = lost
        return cls(**bits)

    @classmethod
    def from_bits(cls, bits: Iterable[int | bool]) -> "Outcome":
        values = [bool(b) for b in bits]
        if len(values) != len(OUTCOME_NAMES):
            raise ValueError(f"an outcome has {len(OUTCOME_NAMES)} bits, got {len(values)}")
        return cls(**dict(zip(OUTCOME_NAMES, values)))

    def bits(self) -> tuple[int, ...]:
        return tuple(int(getattr(self, name)) for name in OUTCOME_NAMES)

    def as_dict(self) -> dict[str, int]:
        return dict(zip(OUTCOME_NAMES, self.bits()))


class ExecutedTrial(Protocol):
    """What a trial record is made from: a trial as executed
    (:class:`llcps.sim.result.TrialResult` is one)."""

    @property
    def spec(self) -> TrialSpec: ...
    @property
    def features(self) -> tuple[EntityFeatures, ...]: ...
    @property
    def outcome(self) -> Outcome: ...
    @property
    def sim_steps(self) -> int: ...
    @property
    def wall_seconds(self) -> float: ...


@dataclass(frozen=True)
class TrialRecord:
    """A trial as the experience store keeps it: the lifelong training set's unit.

    The one record type of a trial, written and read alike: a trial about to be
    stored has no ``id`` and no ``created_at`` yet; the store assigns both.
    """

    branch: str
    source: str
    spec: TrialSpec
    features: tuple[EntityFeatures, ...]
    outcome: Outcome
    solved: bool
    sim_steps: int
    wall_seconds: float
    seed: int
    id: int | None = None
    run_id: int | None = None
    episode_id: int | None = None
    snapshot_id: int | None = None
    scenario: str | None = None
    created_at: str | None = None
    extra: Mapping[str, object] = field(default_factory=dict)
    #: Answered from the physics cache: ``wall_seconds`` is then what this run spent
    #: on it, and ``simulation_wall_seconds`` the wall time of the simulation that
    #: computed the result (for a simulated trial, its own simulation time).
    cache_hit: bool = False
    simulation_wall_seconds: float | None = None

    @classmethod
    def from_result(
        cls,
        result: ExecutedTrial,
        *,
        branch: str,
        source: str,
        seed: int,
        solved: bool = False,
        run_id: int | None = None,
        episode_id: int | None = None,
        snapshot_id: int | None = None,
        scenario: str | None = None,
        extra: Mapping[str, object] | None = None,
        wall_seconds: float | None = None,
        cache_hit: bool = False,
        simulation_wall_seconds: float | None = None,
    ) -> TrialRecord:
        """The record of an executed trial, about to be stored.

        Args:
            result: the trial as executed: its controller call, features, Omega and steps.
            wall_seconds: what this run spent on it (default: the result's own wall time).
            cache_hit: the result was answered by the physics cache, not simulated.
            simulation_wall_seconds: the wall time of the simulation that computed the
                result (None: not recorded).
            The other arguments are the record's fields of the same name.
        """
        return cls(
            branch=branch,
            source=source,
            spec=result.spec,
            features=result.features,
            outcome=result.outcome,
            solved=solved,
            sim_steps=result.sim_steps,
            wall_seconds=result.wall_seconds if wall_seconds is None else wall_seconds,
            seed=seed,
            run_id=run_id,
            episode_id=episode_id,
            snapshot_id=snapshot_id,
            scenario=scenario,
            extra={} if extra is None else extra,
            cache_hit=cache_hit,
            simulation_wall_seconds=simulation_wall_seconds,
        )

    @property
    def model_input(self) -> WorldModelInput:
        return WorldModelInput(spec=self.spec, features=self.features)

    @property
    def stored_features(self) -> StoredFeatures | None:
        """The features' names and numbers as read from a store (None for a record made in memory)."""
        return self.__dict__.get("_stored_features")

    def __getattr__(self, name: str) -> Any:
        # Called only for attributes not found: a record read from a store holds
        # StoredFeatures and builds ``features`` on first use, once.
        if name == "features":
            stored = self.__dict__.get("_stored_features")
            if stored is not None:
                features = stored.entities()
                object.__setattr__(self, "features", features)
                return features
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def as_json(self) -> dict[str, object]:
        """The JSON shape used by ``--json`` outputs and ``db export``."""
        p = self.spec.params
        return {
            "id": self.id,
            "branch": self.branch,
            "run_id": self.run_id,
            "episode_id": self.episode_id,
            "scenario": self.scenario,
            "source": self.source,
            "action": self.spec.action,
            "rate": p.rate,
            "movement_magnitude": p.movement_magnitude,
            "orientation": p.orientation,
            "arguments": list(self.spec.arguments),
            "features": [f.as_dict() for f in self.features],
            "outcome": self.outcome.as_dict(),
            "solved": self.solved,
            "sim_steps": self.sim_steps,
            "wall_seconds": self.wall_seconds,
            "cache_hit": self.cache_hit,
            "simulation_wall_seconds": self.simulation_wall_seconds,
            "seed": self.seed,
            "snapshot_id": self.snapshot_id,
            "created_at": self.created_at,
        }


Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Body:
    """One body of a scene as a trial found it, described without its name's meaning.

    The goal-aware world model places an atom's bodies relative to a candidate's
    arguments from these: kind, shape and axis-aligned bounding box.

    Attributes:
        name: the body's symbol in fluents.
        kind: one of BODY_KINDS.
        shape: the entity's shape (SHAPES); None for a fixture.
        lo: lower corner of its world-frame bounding box (m).
        hi: upper corner (m); the floor is a thin slab of the floor's visible extent.
        centre: the entity's bounding-box centre in its own frame, in the world (m);
            for a fixture the middle of ``lo`` and ``hi``.
    """

    name: str
    kind: str
    shape: str | None
    lo: Vec3
    hi: Vec3
    centre: Vec3

    def __post_init__(self) -> None:
        if self.kind not in BODY_KINDS:
            raise ValueError(f"unknown body kind {self.kind!r}; expected one of {BODY_KINDS}")
        if self.shape is not None and self.shape not in SHAPES:
            raise ValueError(f"unknown shape {self.shape!r}; expected one of {SHAPES}")
        for name in ("lo", "hi", "centre"):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != 3 or not all(math.isfinite(v) for v in value):
                raise ValueError(f"body {self.name!r}: {name} needs 3 finite numbers")
            object.__setattr__(self, name, value)

    @property
    def is_entity(self) -> bool:
        return self.kind in ("object", "container")

    @classmethod
    def from_dict(cls, item: object) -> "Body":
        """Read back :meth:`as_dict`, checking every field (it may come from a database).

        Raises:
            ValueError: ``item`` does not describe a body.
        """
        if not isinstance(item, dict) or set(item) != {"name", "kind", "shape", "lo", "hi", "centre"}:
            raise ValueError("a body has exactly name, kind, shape, lo, hi and centre")
        if not isinstance(item["name"], str) or item["kind"] not in BODY_KINDS:
            raise ValueError("bad name or kind")
        if item["shape"] is not None and not isinstance(item["shape"], str):
            raise ValueError("bad shape")
        vectors = []
        for name in ("lo", "hi", "centre"):
            value = item[name]
            if not isinstance(value, list) or len(value) != 3 or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
            ):
                raise ValueError(f"{name}: expected 3 numbers")
            try:
                vectors.append((float(value[0]), float(value[1]), float(value[2])))
            except OverflowError:  # an int too large for a float
                raise ValueError(f"{name}: a number too large for a float") from None
        return cls(item["name"], item["kind"], item["shape"], *vectors)

    def as_dict(self) -> dict[str, object]:
        return {
            "name": self.name,
            "kind": self.kind,
            "shape": self.shape,
            "lo": list(self.lo),
            "hi": list(self.hi),
            "centre": list(self.centre),
        }


@dataclass(frozen=True)
class TrialChange:
    """The symbolic change a trial made, and the scene it made it in.

    Beside Omega (which says what *kind* of fluent changed), this says *which* atoms
    changed: the goal-aware world model learns from it whether a candidate would make
    a failure's missing atoms hold. Stored per trial id in the experience store.

    Attributes:
        before: the symbolic state before the trial.
        added: atoms that became true.
        deleted: atoms that stopped being true.
        bodies: every entity and fixture of the scene as the trial found it.
        source: how the change is known (CHANGE_SOURCES, never ``unknown`` here).
        trial_id: the trial it belongs to (None before the trial is stored).
    """

    before: State
    added: frozenset[Fluent]
    deleted: frozenset[Fluent]
    bodies: tuple[Body, ...]
    source: str = "recorded"
    trial_id: int | None = None

    def __post_init__(self) -> None:
        if self.source not in CHANGE_SOURCES or self.source == "unknown":
            raise ValueError(f"a known change has source 'recorded' or 'replayed', not {self.source!r}")
        if self.added & self.before or not self.deleted <= self.before:
            raise ValueError("a change adds atoms that were false and deletes atoms that were true")

    @classmethod
    def between(
        cls, before: Iterable[Fluent], after: Iterable[Fluent], bodies: Iterable[Body], *, source: str = "recorded"
    ) -> "TrialChange":
        """The change from the fluent set ``before`` to ``after``."""
        b, a = frozenset(before), frozenset(after)
        return cls(before=b, added=a - b, deleted=b - a, bodies=tuple(bodies), source=source)

    @property
    def after(self) -> State:
        return (self.before - self.deleted) | self.added

    def body(self, name: str) -> Body | None:
        """The body called ``name``, if the scene has one."""
        return next((b for b in self.bodies if b.name == name), None)

    def as_json(self) -> dict[str, object]:
        return {
            "trial_id": self.trial_id,
            "source": self.source,
            "added": [list(a) for a in sorted(self.added)],
            "deleted": [list(a) for a in sorted(self.deleted)],
            "before": [list(a) for a in sorted(self.before)],
            "bodies": [b.as_dict() for b in self.bodies],
        }
