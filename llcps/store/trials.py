"""Trials between :class:`~llcps.domain.TrialRecord` and table rows.

Reading the lifelong training set is the hot path (every model refit loads it),
so rows are read with Core selects that skip SQLAlchemy's JSON and datetime
processing, and the immutable parts of a record that repeat across trials
(controller settings, entity features, outcomes) are built once per load.
"""

from __future__ import annotations

import gc
import json
from contextlib import contextmanager
from dataclasses import fields
from datetime import datetime
from typing import Any, Iterable, Iterator, Mapping, Sequence

from sqlalchemy import String, Text, type_coerce

from llcps.domain import (
    ACTIONS,
    OUTCOME_NAMES,
    TRIAL_SOURCES,
    ControllerParams,
    EntityFeatures,
    Outcome,
    TrialRecord,
    TrialSpec,
)
from llcps.errors import LlcpsError
from llcps.store.schema import Trial


#: Typed feature columns per argument slot (``arg0_*``, ``arg1_*``), in EntityFeatures' field order.
FEATURE_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(EntityFeatures))
FEATURE_SLOTS = 2


def feature_column_names(slot: int) -> tuple[str, ...]:
    """The columns holding the features of argument ``slot``."""
    return tuple(f"arg{slot}_{name}" for name in FEATURE_FIELDS)


def trial_row(trial: TrialRecord, *, branch_id: int, created_at: datetime) -> dict[str, Any]:
    """The column values of a new trial, after checking what the domain types cannot."""
    if trial.source not in TRIAL_SOURCES:
        raise LlcpsError(f"unknown trial source {trial.source!r}", hint=f"known sources: {', '.join(TRIAL_SOURCES)}")
    if len(trial.features) != len(trial.spec.arguments):
        raise LlcpsError(
            f"a trial needs one feature set per argument: {len(trial.spec.arguments)} argument(s), "
            f"{len(trial.features)} feature set(s)",
            hint="pass features in argument order",
        )
    if len(trial.features) > FEATURE_SLOTS:  # pragma: no cover - no action takes more arguments
        raise LlcpsError(f"a trial has at most {FEATURE_SLOTS} arguments, not {len(trial.features)}")
    params = trial.spec.params
    row: dict[str, Any] = {
        "branch_id": branch_id,
        "run_id": trial.run_id,
        "episode_id": trial.episode_id,
        "source": trial.source,
        "scenario": trial.scenario,
        "action": trial.spec.action,
        "arguments": list(trial.spec.arguments),
        "rate": float(params.rate),
        "movement_magnitude": float(params.movement_magnitude),
        "orientation": params.orientation,
        "solved": bool(trial.solved),
        "sim_steps": int(trial.sim_steps),
        "wall_seconds": float(trial.wall_seconds),
        "cache_hit": bool(trial.cache_hit),
        "simulation_wall_seconds": None if trial.simulation_wall_seconds is None else float(trial.simulation_wall_seconds),
        "seed": int(trial.seed),
        "snapshot_id": trial.snapshot_id,
        "created_at": created_at,
        "extra": dict(trial.extra),
    }
    for slot in range(FEATURE_SLOTS):
        entity = trial.features[slot] if slot < len(trial.features) else None
        for name, column in zip(FEATURE_FIELDS, feature_column_names(slot)):
            value = None if entity is None else getattr(entity, name)
            row[column] = value if value is None or isinstance(value, str) else float(value)
    row.update(trial.outcome.as_dict())
    return row


#: Columns read for a TrialRecord, in the order :class:`TrialDecoder` unpacks them.
TRIAL_COLUMNS = (
    Trial.id,
    Trial.branch_id,
    Trial.run_id,
    Trial.episode_id,
    Trial.source,
    Trial.scenario,
    Trial.action,
    type_coerce(Trial.arguments, Text),
    Trial.rate,
    Trial.movement_magnitude,
    Trial.orientation,
    *(getattr(Trial, name) for name in OUTCOME_NAMES),
    Trial.solved,
    Trial.sim_steps,
    Trial.wall_seconds,
    Trial.seed,
    Trial.snapshot_id,
    type_coerce(Trial.created_at, String),
    type_coerce(Trial.extra, Text),
    Trial.cache_hit,
    Trial.simulation_wall_seconds,
    *(getattr(Trial, name) for slot in range(FEATURE_SLOTS) for name in feature_column_names(slot)),
)
#: Where the feature columns start in a row of :data:`TRIAL_COLUMNS`.
_FEATURES_AT = len(TRIAL_COLUMNS) - FEATURE_SLOTS * len(FEATURE_FIELDS)


def _json(value: Any) -> Any:
    """Decode a JSON column read as text (drivers that decode JSON themselves pass through)."""
    return json.loads(value) if isinstance(value, str) else value


def _key(value: Any) -> Any:
    return value if isinstance(value, str) else json.dumps(value, sort_keys=True)


def iso_timestamp(value: Any) -> str | None:
    """One spelling of a stored timestamp: ISO 8601 with a space, UTC, no offset.

    SQLite keeps DateTime as exactly this text, so the hot path passes it through.
    """
    if value is None or isinstance(value, str):
        return value
    return value.isoformat(sep=" ")


@contextmanager
def gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector while building many acyclic objects.

    Loading 100k trials allocates ~1M containers; without the pause the collector's
    repeated full passes over them cost about 40% of the load.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


_TRIAL_RECORD_FIELDS = frozenset(f.name for f in fields(TrialRecord))


def _frozen(cls: type[Any], values: dict[str, Any]) -> Any:
    """Build a frozen dataclass from complete, already valid field values.

    Bypassing ``__init__`` makes loading 100k trials several times faster; the
    field sets are checked against the dataclasses in :class:`TrialDecoder`.
    """
    obj = object.__new__(cls)
    obj.__dict__.update(values)
    return obj


class TrialDecoder:
    """Builds TrialRecords from rows of :data:`TRIAL_COLUMNS`, sharing repeated parts.

    Args:
        branch_names: branch id -> name, for the ``branch`` field (the owning branch).
    """

    def __init__(self, branch_names: Mapping[int, str]) -> None:
        self._names = branch_names
        self._specs: dict[tuple[Any, ...], TrialSpec] = {}
        self._features: dict[tuple[Any, ...], tuple[EntityFeatures, ...]] = {}
        self._entities: dict[tuple[Any, ...], EntityFeatures] = {}
        self._outcomes: dict[tuple[int, ...], Outcome] = {}

    def _spec(self, action: str, arguments: Any, rate: float, magnitude: float, orientation: str) -> TrialSpec:
        key = (action, _key(arguments), rate, magnitude, orientation)
        spec = self._specs.get(key)
        if spec is None:
            if action not in ACTIONS:
                raise LlcpsError(f"stored trial has unknown action {action!r}", hint="upgrade llcps")
            spec = TrialSpec(action, tuple(_json(arguments)), ControllerParams(rate, magnitude, orientation))
            self._specs[key] = spec
        return spec

    def _feature_tuple(self, values: tuple[Any, ...]) -> tuple[EntityFeatures, ...]:
        found = self._features.get(values)
        if found is None:
            width = len(FEATURE_FIELDS)
            entities = []
            for slot in range(FEATURE_SLOTS):
                part = values[slot * width : (slot + 1) * width]
                if part[0] is None:
                    break
                if not (isinstance(part[0], str) and isinstance(part[2], str)):
                    raise LlcpsError("stored trial features are malformed", hint="the store may be damaged")
                entity = self._entities.get(part)
                if entity is None:
                    entity = _frozen(EntityFeatures, dict(zip(FEATURE_FIELDS, part)))
                    self._entities[part] = entity
                entities.append(entity)
            found = tuple(entities)
            self._features[values] = found
        return found

    def _outcome(self, bits: tuple[int, ...]) -> Outcome:
        found = self._outcomes.get(bits)
        if found is None:
            found = Outcome.from_bits(bits)
            self._outcomes[bits] = found
        return found

    def decode(self, rows: Iterable[Sequence[Any]]) -> list[TrialRecord]:
        """Decode many rows (the hot loop: locals, caches, no per-row validation)."""
        names = self._names
        specs, spec_of = self._specs, self._spec
        features_cache, features_of = self._features, self._feature_tuple
        outcomes, outcome_of = self._outcomes, self._outcome
        new, record_cls = object.__new__, TrialRecord
        at = _FEATURES_AT
        out: list[TrialRecord] = []
        append = out.append
        for row in rows:
            (
                id_, branch_id, run_id, episode_id, source, scenario, action, arguments, rate, magnitude,
                orientation, b0, b1, b2, b3, b4, b5, solved, sim_steps, wall_seconds, seed,
                snapshot_id, created_at, extra, cache_hit, simulation_wall_seconds,
            ) = row[:at]
            spec = specs.get((action, arguments, rate, magnitude, orientation)) if isinstance(arguments, str) else None
            if spec is None:
                spec = spec_of(action, arguments, rate, magnitude, orientation)
            values = tuple(row[at:])
            entity_features = features_cache.get(values)
            if entity_features is None:
                entity_features = features_of(values)
            bits = (b0, b1, b2, b3, b4, b5)
            outcome = outcomes.get(bits) or outcome_of(bits)
            record = new(record_cls)  # see _frozen: complete, valid values only
            record.__dict__.update(
                {
                    "id": id_,
                    "branch": names[branch_id],
                    "source": source,
                    "spec": spec,
                    "features": entity_features,
                    "outcome": outcome,
                    "solved": bool(solved),
                    "sim_steps": sim_steps,
                    "wall_seconds": wall_seconds,
                    "seed": seed,
                    "run_id": run_id,
                    "episode_id": episode_id,
                    "snapshot_id": snapshot_id,
                    "scenario": scenario,
                    "created_at": created_at if created_at is None or isinstance(created_at, str) else iso_timestamp(created_at),
                    "extra": {} if extra in ("{}", None) else _json(extra),
                    "cache_hit": bool(cache_hit),
                    "simulation_wall_seconds": simulation_wall_seconds,
                }
            )
            append(record)
        return out


# The fast constructor must fill every field of the records it builds.
_DECODED_FIELDS = frozenset(
    {"id", "branch", "source", "spec", "features", "outcome", "solved", "sim_steps", "wall_seconds", "seed",
     "run_id", "episode_id", "snapshot_id", "scenario", "created_at", "extra", "cache_hit", "simulation_wall_seconds"}
)
if _DECODED_FIELDS != _TRIAL_RECORD_FIELDS:  # pragma: no cover - guards a change in llcps.domain
    raise ImportError(f"llcps.store.trials decodes {sorted(_DECODED_FIELDS)} but TrialRecord has {sorted(_TRIAL_RECORD_FIELDS)}")
