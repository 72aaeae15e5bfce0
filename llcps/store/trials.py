"""Trials between :class:`~llcps.trial_records.TrialRecord` and table rows.

Reading the lifelong training set is the hot path (every model refit loads it),
so rows are read with Core selects that skip SQLAlchemy's JSON and datetime
processing, and the immutable parts of a record that repeat across trials
(controller settings, entity features, outcomes) are built once per load. A record's
entity features are held as checked names and numbers
(:class:`~llcps.trial_records.StoredFeatures`), which is what the models read; its
:class:`~llcps.domain.EntityFeatures` are built when ``features`` is first used.

Rows are untrusted input. Each distinct spec, feature set and outcome is checked
when it is first built (names from the vocabulary, finite numbers, exact fields),
and each row's scalars by type, so a row changed outside llcps gives a
:class:`~llcps.errors.StoreError` naming its trial id instead of a crash later.
A malformed row is refused rather than skipped: skipping it would silently change
a branch's training set.
"""

from __future__ import annotations

import functools
import gc
import json
import math
import struct
from contextlib import contextmanager
from dataclasses import fields
from datetime import datetime
from typing import Any, Iterable, Iterator, Mapping, Sequence

from sqlalchemy import Integer, String, Text, and_, case, cast, type_coerce

from llcps import bounded_json
from llcps.domain import ACTIONS, COLORS, ENTITY_NUMBERS, OUTCOME_NAMES, SHAPES, TRIAL_SOURCES, ControllerParams, EntityFeatures
from llcps.trial_records import Outcome, StoredFeatures, TrialRecord, TrialSpec
from llcps.errors import LlcpsError, StoreError
from llcps.store.tables import Trial


#: Packed features: a layout byte, the entity count, per entity five little-endian doubles
#: (volume, vector_magnitude, unit_x, unit_y, unit_z), then the shapes and colours as UTF-8
#: text, each entity's "shape<US>colour", joined by US (0x1f).
FEATURES_LAYOUT = 1
_SEPARATOR = "\x1f"
#: Most arguments a trial has.
MAX_ARGUMENTS = 2
_DOUBLES = [struct.Struct(f"<{5 * n}d") for n in range(MAX_ARGUMENTS + 1)]


def pack_features(features: Sequence[EntityFeatures]) -> bytes:
    """The stored form of a trial's Table-1 features (see :data:`FEATURES_LAYOUT`)."""
    if len(features) > MAX_ARGUMENTS:
        raise LlcpsError(f"a trial has at most {MAX_ARGUMENTS} arguments, not {len(features)}")
    names = []
    for f in features:
        if _SEPARATOR in f.shape or _SEPARATOR in f.color:
            raise LlcpsError(f"an entity's shape or colour cannot hold control characters: {f.shape!r}, {f.color!r}")
        names += [f.shape, f.color]
    numbers = [float(getattr(f, name)) for f in features for name in ENTITY_NUMBERS]
    return bytes((FEATURES_LAYOUT, len(features))) + _DOUBLES[len(features)].pack(*numbers) + _SEPARATOR.join(names).encode()


@functools.lru_cache(maxsize=10_000)
def _decode_names(data: bytes) -> tuple[tuple[str, ...] | None, bool]:
    """The text part of packed features, decoded once per process (a training set repeats
    few): its names (None if they are not non-empty UTF-8 text) and whether they are all
    Table 1's shapes and colours."""
    try:
        names: tuple[str, ...] | None = tuple(data.decode().split(_SEPARATOR)) if data else ()
    except UnicodeDecodeError:
        names = None
    if names is not None and not all(names):
        names = None
    in_table1 = names is not None and all(s in SHAPES for s in names[::2]) and all(c in COLORS for c in names[1::2])
    return names, in_table1


def read_features(data: bytes, *, table1: bool = False) -> StoredFeatures:
    """Check :func:`pack_features`'s bytes (they come from a database) and hold their
    names and numbers; the EntityFeatures are built on first use.

    Args:
        table1: also refuse shapes and colours outside Table 1's categories.
    """
    try:
        n = data[1] if data[0] == FEATURES_LAYOUT else -1
        doubles = _DOUBLES[n]
        numbers = doubles.unpack_from(data, 2)
    except (IndexError, TypeError, struct.error):
        n, numbers = -1, ()
    tail = data[2 + 40 * n :] if n >= 0 else b""
    names, in_table1 = _decode_names(tail)
    if n < 0 or names is None or len(names) != 2 * n:
        raise LlcpsError("stored trial features are malformed", hint="the store may be damaged; `llcps db status`")
    if table1 and not in_table1:
        raise LlcpsError(f"stored trial features name an unknown shape or color ({', '.join(map(repr, names))})")
    # A finite sum has finite terms (inf and nan propagate); only a non-finite sum needs a closer look.
    if not math.isfinite(sum(numbers)) and not all(map(math.isfinite, numbers)):
        raise LlcpsError("stored trial features hold a value that is not a finite number", hint="the store may be damaged; `llcps db status`")
    return StoredFeatures(names, numbers)


def unpack_features(data: bytes, *, table1: bool = False) -> tuple[EntityFeatures, ...]:
    """Read :func:`pack_features`'s bytes back as EntityFeatures, checking them as :func:`read_features` does."""
    return read_features(data, table1=table1).entities()


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
        "features": pack_features(trial.features),
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
    row.update(trial.outcome.as_dict())
    return row


#: The flags of a row whose bits are not all 0 or 1 (SQLite keeps whatever a row was given).
MALFORMED_FLAGS = 256


def _flags() -> Any:
    """The six outcome bits, ``solved`` and ``cache_hit`` as one integer, computed by the database.

    Bit i (0..5) is Omega's i-th bit, bit 6 ``solved``, bit 7 ``cache_hit``: one value
    per row instead of eight, which is most of what fetching a row costs. A row with
    any of them other than 0 or 1 (a row changed outside llcps) gives
    :data:`MALFORMED_FLAGS`, which the decoder refuses.
    """
    # Booleans (solved, cache_hit) and small integers (the bits) alike, as integers: a
    # PostgreSQL smallint does not compare with a boolean.
    parts = [cast(column, Integer) for column in [*(getattr(Trial, name) for name in OUTCOME_NAMES), Trial.solved, Trial.cache_hit]]
    flags = parts[0]
    for bit, column in enumerate(parts[1:], start=1):
        flags = flags.op("|")(column.op("<<")(bit))
    return case((and_(*(column.in_((0, 1)) for column in parts)), flags), else_=MALFORMED_FLAGS)


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
    Trial.features,
    _flags(),
    Trial.sim_steps,
    Trial.wall_seconds,
    Trial.seed,
    Trial.snapshot_id,
    type_coerce(Trial.created_at, String),
    type_coerce(Trial.extra, Text),
    Trial.simulation_wall_seconds,
)


def _json(value: Any) -> Any:
    """Decode a JSON column read as text (drivers that decode JSON themselves pass through)."""
    return bounded_json.loads(value) if isinstance(value, str) else value


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
    """Pause the cyclic garbage collector while building many long-lived acyclic objects.

    Loading 100k trials allocates ~1M containers; without the pause the collector's
    repeated full passes over them cost about 40% of the load. When the pause ends,
    everything made in it would be young, and the next collection would traverse every
    object once more (about a tenth of the load). They are moved to the oldest
    generation instead, where objects that outlive a few collections (a training set)
    end up anyway: ``gc.freeze()`` then ``gc.unfreeze()``, which only relink the
    collector's lists. Skipped while anything else in the process keeps objects frozen.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if gc.get_freeze_count() == 0:
            gc.freeze()
            gc.unfreeze()
        if was_enabled:
            gc.enable()


_TRIAL_RECORD_FIELDS = frozenset(f.name for f in fields(TrialRecord))
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
        self._features: dict[bytes, StoredFeatures] = {}
        self._outcomes: dict[int, Outcome] = {}  # by the flags' low six bits

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

    def _stored_features(self, data: bytes) -> StoredFeatures:
        found = self._features.get(data)
        if found is None:
            try:
                found = read_features(data, table1=True)
            except LlcpsError as exc:
                raise _Malformed(exc.message) from None
            self._features[bytes(data)] = found
        return found

    def _outcome(self, flags: int) -> Outcome:
        found = self._outcomes.get(flags)
        if found is None:
            if not 0 <= flags < 64:
                raise _Malformed("outcome bits, solved or cache_hit are not 0 or 1")
            found = Outcome.from_bits([(flags >> bit) & 1 for bit in range(len(OUTCOME_NAMES))])
            self._outcomes[flags] = found
        return found

    def decode(self, rows: Sequence[Sequence[Any]]) -> list[TrialRecord]:
        """Decode many rows of :data:`TRIAL_COLUMNS`.

        Raises:
            StoreError: a row is malformed (the message names its trial id).
        """
        try:
            return self._decode(rows)
        except (ValueError, TypeError, KeyError, AttributeError, RecursionError) as batch_exc:
            trial, exc = "?", batch_exc  # a batch fails only through one of its rows, named below
            for row in rows:  # find the row to name: slow, but only on the way to an error
                try:
                    self._decode([row])
                except (ValueError, TypeError, KeyError, AttributeError, RecursionError) as row_exc:
                    trial, exc = row[0], row_exc
                    break
            raise StoreError(
                f"stored trial {trial} is malformed: {exc}",
                hint="the row was changed outside llcps; delete it or restore the database from a copy",
            ) from None

    def decode_result(self, result: Any, batch: int = 1000) -> list[TrialRecord]:
        """Decode every row of a query result (anything with ``fetchmany``), a batch at a time.

        Rows in small batches are decoded while they are still in the CPU's caches,
        and freed before the next batch: for 100,000 trials about a tenth faster
        than fetching them all first.

        Raises:
            StoreError: a row is malformed (the message names its trial id).
        """
        out: list[TrialRecord] = []
        while rows := result.fetchmany(batch):
            out += self.decode(rows)
        return out

    def _decode(self, rows: Iterable[Sequence[Any]]) -> list[TrialRecord]:
        """The hot loop: locals, caches, and only type checks per row."""
        names = self._names
        specs, spec_of = self._specs, self._spec
        features_cache, features_of = self._features, self._stored_features
        outcomes, outcome_of = self._outcomes, self._outcome
        new, record_cls, set_dict = object.__new__, TrialRecord, object.__setattr__
        sources = _SOURCES
        out: list[TrialRecord] = []
        append = out.append
        for (
            id_, branch_id, run_id, episode_id, source, scenario, action, arguments, rate, magnitude,
            orientation, features, flags, sim_steps, wall_seconds, seed, snapshot_id, created_at, extra,
            simulation_wall_seconds,
        ) in rows:
            spec = specs.get((action, arguments, rate, magnitude, orientation)) if isinstance(arguments, str) else None
            if spec is None:
                spec = spec_of(action, arguments, rate, magnitude, orientation)
            stored_features = features_cache.get(features)
            if stored_features is None:
                stored_features = features_of(features)
            bits = flags & ~192  # Omega's bits; a stored value other than 0 or 1 sets bit 8 (see _flags)
            outcome = outcomes.get(bits) or outcome_of(bits)
            if (type(sim_steps), type(seed), type(wall_seconds), type(branch_id)) != _SCALAR_TYPES or source not in sources:
                raise _Malformed(f"source, steps, seconds or seed of the wrong type ({source!r}, {sim_steps!r}, {wall_seconds!r}, {seed!r})")
            if simulation_wall_seconds is not None and type(simulation_wall_seconds) is not float:
                raise _Malformed(f"simulation_wall_seconds is not a number ({simulation_wall_seconds!r})")
            record = new(record_cls)  # see _frozen: complete, valid values only
            set_dict(
                record,
                "__dict__",
                {
                    "id": id_,
                    "branch": names[branch_id],
                    "source": source,
                    "spec": spec,
                    "_stored_features": stored_features,  # TrialRecord builds ``features`` from it on first use
                    "outcome": outcome,
                    "solved": flags & 64 != 0,
                    "sim_steps": sim_steps,
                    "wall_seconds": wall_seconds,
                    "seed": seed,
                    "run_id": run_id,
                    "episode_id": episode_id,
                    "snapshot_id": snapshot_id,
                    "scenario": scenario,
                    "created_at": created_at if created_at is None or isinstance(created_at, str) else iso_timestamp(created_at),
                    "extra": {} if extra in ("{}", None) else _extra(extra),
                    "cache_hit": flags & 128 != 0,
                    "simulation_wall_seconds": simulation_wall_seconds,
                },
            )
            append(record)
        return out


# The fast constructor must fill every field of the records it builds.
_DECODED_FIELDS = frozenset(
    {"id", "branch", "source", "spec", "_stored_features", "outcome", "solved", "sim_steps", "wall_seconds", "seed",
     "run_id", "episode_id", "snapshot_id", "scenario", "created_at", "extra", "cache_hit", "simulation_wall_seconds"}
)
if _DECODED_FIELDS != _TRIAL_RECORD_FIELDS - {"features"} | {"_stored_features"}:  # pragma: no cover - guards a change in llcps.domain
    raise ImportError(f"llcps.store.trials decodes {sorted(_DECODED_FIELDS)} but TrialRecord has {sorted(_TRIAL_RECORD_FIELDS)}")
if frozenset(f.name for f in fields(EntityFeatures)) != {"shape", "color", *ENTITY_NUMBERS}:  # pragma: no cover
    raise ImportError("llcps.store.trials packs fields that EntityFeatures does not have")
