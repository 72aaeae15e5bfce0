"""Trials between :class:`~llcps.domain.TrialRecord` and table rows.

Reading the lifelong training set is the hot path (every model refit loads it),
so rows are read with Core selects that skip SQLAlchemy's JSON and datetime
processing, and the immutable parts of a record that repeat across trials
(controller settings, entity features, outcomes) are built once per load.

Rows are untrusted input. Each distinct spec, feature set and outcome is checked
when it is first built (names from the vocabulary, finite numbers, exact fields),
and each row's scalars by type, so a row changed outside llcps gives a
:class:`~llcps.errors.StoreError` naming its trial id instead of a crash later.
A malformed row is refused rather than skipped: skipping it would silently change
a branch's training set.
"""

from __future__ import annotations

import gc
import json
import math
from contextlib import contextmanager
from dataclasses import fields
from datetime import datetime
from typing import Any, Iterable, Iterator, Mapping, Sequence

from sqlalchemy import String, Text, type_coerce

from llcps.domain import (
    ACTIONS,
    COLORS,
    OUTCOME_NAMES,
    SHAPES,
    TRIAL_SOURCES,
    ControllerParams,
    EntityFeatures,
    Outcome,
    TrialRecord,
    TrialSpec,
)
from llcps.errors import LlcpsError, StoreError
from llcps.store.schema import Trial


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
        "features": [f.as_dict() for f in trial.features],
        "solved": bool(trial.solved),
        "sim_steps": int(trial.sim_steps),
        "wall_seconds": float(trial.wall_seconds),
        "seed": int(trial.seed),
        "snapshot_id": trial.snapshot_id,
        "created_at": created_at,
        "extra": dict(trial.extra),
    }
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
    type_coerce(Trial.features, Text),
    *(getattr(Trial, name) for name in OUTCOME_NAMES),
    Trial.solved,
    Trial.sim_steps,
    Trial.wall_seconds,
    Trial.seed,
    Trial.snapshot_id,
    type_coerce(Trial.created_at, String),
    type_coerce(Trial.extra, Text),
)


def _json(value: Any) -> Any:
    """Decode a JSON column read as text (drivers that decode JSON themselves pass through)."""
    return json.loads(value) if isinstance(value, str) else value


class _Malformed(ValueError):
    """A stored value that does not describe what its column should hold."""


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
_ENTITY_FEATURE_FIELDS = frozenset(f.name for f in fields(EntityFeatures))
_ENTITY_NUMBERS = tuple(f.name for f in fields(EntityFeatures) if f.name not in ("shape", "color"))
_SOURCES = frozenset(TRIAL_SOURCES)
_SCALAR_TYPES = (int, int, float, int)


def _extra(value: Any) -> dict[str, Any]:
    decoded = _json(value)
    if not isinstance(decoded, dict):
        raise _Malformed("extra is not a JSON object")
    return decoded


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
        self._features: dict[Any, tuple[EntityFeatures, ...]] = {}
        self._outcomes: dict[tuple[int, ...], Outcome] = {}

    def _spec(self, action: str, arguments: Any, rate: float, magnitude: float, orientation: str) -> TrialSpec:
        key = (action, _key(arguments), rate, magnitude, orientation)
        spec = self._specs.get(key)
        if spec is None:
            if action not in ACTIONS:
                raise _Malformed(f"unknown action {action!r}")
            names = _json(arguments)
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise _Malformed("arguments are not a list of entity names")
            if not all(type(v) is float and math.isfinite(v) for v in (rate, magnitude)):
                raise _Malformed("rate or movement magnitude is not a finite number")
            spec = TrialSpec(action, tuple(names), ControllerParams(rate, magnitude, orientation))
            self._specs[key] = spec
        return spec

    def _feature_tuple(self, features: Any) -> tuple[EntityFeatures, ...]:
        key = _key(features)
        found = self._features.get(key)
        if found is None:
            decoded = _json(features)
            if not isinstance(decoded, list):
                raise _Malformed("features are not a list")
            for entity in decoded:
                if not isinstance(entity, dict) or entity.keys() != _ENTITY_FEATURE_FIELDS:
                    raise _Malformed(f"features have fields {sorted(entity) if isinstance(entity, dict) else type(entity).__name__}")
                if entity["shape"] not in SHAPES or entity["color"] not in COLORS:
                    raise _Malformed(f"features name an unknown shape or color ({entity['shape']!r}, {entity['color']!r})")
                if not all(type(entity[k]) in (int, float) and math.isfinite(entity[k]) for k in _ENTITY_NUMBERS):
                    raise _Malformed("features hold a value that is not a finite number")
            found = tuple(_frozen(EntityFeatures, entity) for entity in decoded)
            self._features[key] = found
        return found

    def _outcome(self, bits: tuple[int, ...]) -> Outcome:
        found = self._outcomes.get(bits)
        if found is None:
            if not all(b in (0, 1) and type(b) in (int, bool) for b in bits):
                raise _Malformed(f"outcome bits {bits!r} are not 0 or 1")
            found = Outcome.from_bits(bits)
            self._outcomes[bits] = found
        return found

    def decode(self, rows: Sequence[Sequence[Any]]) -> list[TrialRecord]:
        """Decode many rows of :data:`TRIAL_COLUMNS`.

        Raises:
            StoreError: a row is malformed (the message names its trial id).
        """
        try:
            return self._decode(rows)
        except (ValueError, TypeError, KeyError, AttributeError, RecursionError) as exc:
            for row in rows:  # find the row to name: slow, but only on the way to an error
                try:
                    self._decode([row])
                except (ValueError, TypeError, KeyError, AttributeError, RecursionError) as row_exc:
                    exc = row_exc
                    trial = row[0]
                    break
            else:  # pragma: no cover - a batch fails only through one of its rows
                trial = "?"
            raise StoreError(
                f"stored trial {trial} is malformed: {exc}",
                hint="the row was changed outside llcps; delete it or restore the database from a copy",
            ) from None

    def _decode(self, rows: Iterable[Sequence[Any]]) -> list[TrialRecord]:
        """The hot loop: locals, caches, and only type checks per row."""
        names = self._names
        specs, spec_of = self._specs, self._spec
        features_cache, features_of = self._features, self._feature_tuple
        outcomes, outcome_of = self._outcomes, self._outcome
        new, record_cls = object.__new__, TrialRecord
        sources = _SOURCES
        out: list[TrialRecord] = []
        append = out.append
        for (
            id_, branch_id, run_id, episode_id, source, scenario, action, arguments, rate, magnitude,
            orientation, features, b0, b1, b2, b3, b4, b5, solved, sim_steps, wall_seconds, seed,
            snapshot_id, created_at, extra,
        ) in rows:
            spec = specs.get((action, arguments, rate, magnitude, orientation)) if isinstance(arguments, str) else None
            if spec is None:
                spec = spec_of(action, arguments, rate, magnitude, orientation)
            entity_features = features_cache.get(features) if isinstance(features, str) else None
            if entity_features is None:
                entity_features = features_of(features)
            bits = (b0, b1, b2, b3, b4, b5)
            outcome = outcomes.get(bits) or outcome_of(bits)
            if (type(sim_steps), type(seed), type(wall_seconds), type(branch_id)) != _SCALAR_TYPES or source not in sources:
                raise _Malformed(f"source, steps, seconds or seed of the wrong type ({source!r}, {sim_steps!r}, {wall_seconds!r}, {seed!r})")
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
                    "extra": {} if extra in ("{}", None) else _extra(extra),
                }
            )
            append(record)
        return out


# The fast constructor must fill every field of the records it builds.
_DECODED_FIELDS = frozenset(
    {"id", "branch", "source", "spec", "features", "outcome", "solved", "sim_steps", "wall_seconds", "seed",
     "run_id", "episode_id", "snapshot_id", "scenario", "created_at", "extra"}
)
if _DECODED_FIELDS != _TRIAL_RECORD_FIELDS:  # pragma: no cover - guards a change in llcps.domain
    raise ImportError(f"llcps.store.trials decodes {sorted(_DECODED_FIELDS)} but TrialRecord has {sorted(_TRIAL_RECORD_FIELDS)}")
