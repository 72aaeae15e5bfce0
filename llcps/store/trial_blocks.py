"""Trials as columns, and the packed blocks a branch's trials are kept in beside their rows.

A :class:`TrialColumns` holds many trials as numpy arrays, one per field, with the
names (sources, scenarios, actions, arguments, orientations) as codes into small
vocabularies: what a table of a million trials costs in memory and time, where a
:class:`~llcps.trial_records.TrialRecord` per trial costs a Python object each. Reading
a million rows of the ``trials`` table takes SQLite alone several seconds before one
record exists (docs/performance.md), so every :data:`BLOCK` trials of a branch are
also kept as one packed row of ``trial_blocks`` (:func:`pack`), written in the
transaction that stores the trial completing it (:mod:`llcps.store.training_set`).
A branch's visible set is then its blocks, a few hundred rows for a million trials,
and the trials after the last of them.

Blocks are derived data: built from the rows as the record decoder reads them (so
with the rows' checks), dropped with any trial they hold, and checked again when read
(:func:`unpack`: exact sizes, codes within their vocabularies, finite numbers, ids in
order and within the block's range). A block that fails a check, or whose trial count
no longer matches its rows, is not used: its trials are read from their rows.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, fields
from datetime import datetime
from typing import Any, Iterable, Sequence

import numpy as np

from llcps import bounded_json
from llcps.domain import ACTIONS, COLORS, ENTITY_NUMBERS, ORIENTATIONS, SHAPES, TRIAL_SOURCES
from llcps.trial_records import StoredFeatures, TrialRecord

#: Trials per block.
BLOCK = 4096
#: Most trials a stored block may declare (a block is refused beyond it, before any allocation).
MAX_BLOCK = 65_536
#: Argument slots per trial.
SLOTS = 2
#: Numbers per argument slot.
_NUMBERS = len(ENTITY_NUMBERS)
#: An absent integer (run, episode, snapshot) and an absent timestamp.
NONE = -1
NO_TIME = np.iinfo(np.int64).min
#: Bit of ``flags``: Omega's six bits (0..5), then ``solved`` and ``cache_hit``.
SOLVED_BIT, CACHE_HIT_BIT = 6, 7

_LAYOUT = 1
_HEADER = struct.Struct("<BII")  # layout, trials, bytes of the vocabularies' JSON
_MAX_VOCABULARY_BYTES = 1 << 20


@dataclass(frozen=True, eq=False)
class TrialColumns:
    """Trials as arrays of equal length, in id order.

    Names are codes into the vocabularies (``scenario`` -1: none); argument slot ``k``'s
    ``shape``/``color`` codes index :data:`~llcps.domain.SHAPES` and
    :data:`~llcps.domain.COLORS` (-1: the action has fewer arguments), and ``numbers``
    holds its :data:`~llcps.domain.ENTITY_NUMBERS` (NaN where absent). Integers that may
    be absent hold :data:`NONE`; ``created_at`` is microseconds since 1970 UTC
    (:data:`NO_TIME`: none).
    """

    id: np.ndarray
    branch_id: np.ndarray
    run_id: np.ndarray
    episode_id: np.ndarray
    snapshot_id: np.ndarray
    seed: np.ndarray
    sim_steps: np.ndarray
    created_at: np.ndarray
    rate: np.ndarray
    movement_magnitude: np.ndarray
    wall_seconds: np.ndarray
    simulation_wall_seconds: np.ndarray
    numbers: np.ndarray  # (n, SLOTS, len(ENTITY_NUMBERS))
    source: np.ndarray
    scenario: np.ndarray
    action: np.ndarray
    arguments: np.ndarray
    orientation: np.ndarray
    shape: np.ndarray  # (n, SLOTS)
    color: np.ndarray  # (n, SLOTS)
    flags: np.ndarray
    sources: tuple[str, ...] = ()
    scenarios: tuple[str, ...] = ()
    actions: tuple[str, ...] = ()
    argument_lists: tuple[tuple[str, ...], ...] = ()
    orientations: tuple[str, ...] = ()
    #: Branch id -> name, for the branches the trials belong to (filled by the store's read).
    branch_names: tuple[tuple[int, str], ...] = ()

    def __len__(self) -> int:
        return len(self.id)

    def where(self, keep: np.ndarray) -> TrialColumns:
        """The trials ``keep`` selects (a boolean mask, or indices in the order wanted)."""
        return TrialColumns(**{name: values[keep] for name, values in self._arrays()}, **self._vocabularies())

    def codes_of(self, field: str, value: Any) -> np.ndarray:
        """Rows whose ``field`` (source, scenario, action, orientation) equals ``value``."""
        vocabulary = getattr(self, _VOCABULARY_OF[field])
        code = vocabulary.index(value) if value in vocabulary else -2
        return getattr(self, field) == code

    def bit(self, index: int) -> np.ndarray:
        """Flag bit ``index`` as booleans (0..5: Omega's bits, :data:`SOLVED_BIT`, :data:`CACHE_HIT_BIT`)."""
        return (self.flags >> index) & 1 == 1

    def _arrays(self) -> list[tuple[str, np.ndarray]]:
        return [(f.name, getattr(self, f.name)) for f in fields(self) if f.name in _ARRAY_FIELDS]

    def _vocabularies(self) -> dict[str, tuple[Any, ...]]:
        return {name: getattr(self, name) for name in (*_VOCABULARIES, "branch_names")}


_VOCABULARY_OF = {"source": "sources", "scenario": "scenarios", "action": "actions", "arguments": "argument_lists", "orientation": "orientations"}
_VOCABULARIES = tuple(_VOCABULARY_OF.values())
#: The packed arrays, in stored order: name, dtype, values per trial.
_PACKED: tuple[tuple[str, str, int], ...] = (
    ("id", "<i8", 1),
    ("run_id", "<i8", 1),
    ("episode_id", "<i8", 1),
    ("snapshot_id", "<i8", 1),
    ("seed", "<i8", 1),
    ("sim_steps", "<i8", 1),
    ("created_at", "<i8", 1),
    ("rate", "<f8", 1),
    ("movement_magnitude", "<f8", 1),
    ("wall_seconds", "<f8", 1),
    ("simulation_wall_seconds", "<f8", 1),
    ("numbers", "<f8", SLOTS * _NUMBERS),
    ("source", "<i4", 1),
    ("scenario", "<i4", 1),
    ("action", "<i4", 1),
    ("arguments", "<i4", 1),
    ("orientation", "<i4", 1),
    ("shape", "i1", SLOTS),
    ("color", "i1", SLOTS),
    ("flags", "u1", 1),
)
_ARRAY_FIELDS = frozenset(name for name, _, _ in _PACKED) | {"branch_id"}
_SHAPES_OF = {"numbers": (SLOTS, _NUMBERS), "shape": (SLOTS,), "color": (SLOTS,)}
_BYTES_PER_TRIAL = sum(np.dtype(dtype).itemsize * width for _, dtype, width in _PACKED)


class _Vocabulary:
    """Codes of values in first-seen order."""

    def __init__(self) -> None:
        self.codes: dict[Any, int] = {}

    def code(self, value: Any) -> int:
        found = self.codes.get(value)
        if found is None:
            found = self.codes[value] = len(self.codes)
        return found

    def values(self) -> tuple[Any, ...]:
        return tuple(self.codes)


def _microseconds(stamp: str | None) -> int:
    """A stored timestamp (ISO 8601, UTC, no offset) as microseconds since 1970; NO_TIME if none or unreadable."""
    if stamp is None:
        return int(NO_TIME)
    try:
        moment = datetime.fromisoformat(stamp)
    except (TypeError, ValueError):
        return int(NO_TIME)
    if moment.tzinfo is not None:
        moment = moment.replace(tzinfo=None) - moment.utcoffset()  # type: ignore[operator]
    return (moment - _EPOCH) // _MICROSECOND


_EPOCH = datetime(1970, 1, 1)
_MICROSECOND = datetime(1970, 1, 1, 0, 0, 0, 1) - _EPOCH


def from_records(records: Sequence[TrialRecord], branch_ids: dict[str, int]) -> TrialColumns:
    """Records (as the store's decoder builds them) as columns.

    Args:
        branch_ids: branch name -> id, for every record's ``branch``.
    """
    n = len(records)
    ints = np.full((7, n), NONE, dtype=np.int64)
    floats = np.full((4, n), np.nan)
    numbers = np.full((n, SLOTS, _NUMBERS), np.nan)
    codes = np.full((5, n), NONE, dtype=np.int32)
    shape = np.full((n, SLOTS), NONE, dtype=np.int8)
    color = np.full((n, SLOTS), NONE, dtype=np.int8)
    flags = np.zeros(n, dtype=np.uint8)
    branch = np.zeros(n, dtype=np.int64)
    vocabularies = [_Vocabulary() for _ in _VOCABULARIES]
    sources, scenarios, actions, arguments, orientations = vocabularies
    shapes, colors = {s: i for i, s in enumerate(SHAPES)}, {c: i for i, c in enumerate(COLORS)}
    outcomes: dict[Any, int] = {}  # the decoder shares an outcome among the records that have it
    for i, r in enumerate(records):
        spec, params = r.spec, r.spec.params
        ints[:, i] = (
            r.id, NONE if r.run_id is None else r.run_id, NONE if r.episode_id is None else r.episode_id,
            NONE if r.snapshot_id is None else r.snapshot_id, r.seed, r.sim_steps, _microseconds(r.created_at),
        )
        floats[:, i] = (params.rate, params.movement_magnitude, r.wall_seconds,
                        np.nan if r.simulation_wall_seconds is None else r.simulation_wall_seconds)
        codes[:, i] = (
            sources.code(r.source), NONE if r.scenario is None else scenarios.code(r.scenario), actions.code(spec.action),
            arguments.code(tuple(spec.arguments)), orientations.code(params.orientation),
        )
        stored = r.stored_features or StoredFeatures.of(r.features)
        for slot in range(min(len(stored), SLOTS)):
            numbers[i, slot] = stored.numbers[_NUMBERS * slot : _NUMBERS * (slot + 1)]
            shape[i, slot] = shapes[stored.names[2 * slot]]
            color[i, slot] = colors[stored.names[2 * slot + 1]]
        bits = outcomes.get(r.outcome)
        if bits is None:
            bits = outcomes[r.outcome] = sum(int(b) << k for k, b in enumerate(r.outcome.bits()))
        flags[i] = bits | (int(r.solved) << SOLVED_BIT) | (int(r.cache_hit) << CACHE_HIT_BIT)
        branch[i] = branch_ids[r.branch]
    return TrialColumns(
        **dict(zip(("id", "run_id", "episode_id", "snapshot_id", "seed", "sim_steps", "created_at"), ints)),
        **dict(zip(("rate", "movement_magnitude", "wall_seconds", "simulation_wall_seconds"), floats)),
        **dict(zip(_VOCABULARY_OF, codes)),
        branch_id=branch, numbers=numbers, shape=shape, color=color, flags=flags,
        **{name: v.values() for name, v in zip(_VOCABULARIES, vocabularies)},
    )


def empty() -> TrialColumns:
    """No trials."""
    return from_records([], {})


def concat(parts: Iterable[TrialColumns]) -> TrialColumns:
    """Several column sets as one, in the order given, their codes mapped to shared vocabularies."""
    parts = [p for p in parts if len(p)]
    if not parts:
        return empty()
    if len(parts) == 1:
        return parts[0]
    joined: dict[str, Any] = {}
    recoded: dict[str, list[np.ndarray]] = {field: [] for field in _VOCABULARY_OF}
    for field, name in _VOCABULARY_OF.items():
        vocabulary = _Vocabulary()
        for part in parts:
            mapping = np.array([vocabulary.code(v) for v in getattr(part, name)] + [NONE], dtype=np.int32)
            recoded[field].append(mapping[getattr(part, field)])  # code -1 maps to the last entry: NONE
        joined[name] = vocabulary.values()
    for name in _ARRAY_FIELDS:
        joined[name] = np.concatenate(recoded[name] if name in recoded else [getattr(p, name) for p in parts])
    return TrialColumns(**joined)


def pack(columns: TrialColumns) -> bytes:
    """The stored form of a block (checked again by :func:`unpack` when read)."""
    vocabularies = json.dumps(
        {name: [list(v) if isinstance(v, tuple) else v for v in getattr(columns, name)] for name in _VOCABULARIES},
        separators=(",", ":"),
    ).encode()
    arrays = [np.ascontiguousarray(getattr(columns, name), dtype=dtype).tobytes() for name, dtype, _ in _PACKED]
    return _HEADER.pack(_LAYOUT, len(columns), len(vocabularies)) + vocabularies + b"".join(arrays)


class BlockError(ValueError):
    """A stored block that does not hold what :func:`pack` writes."""


def _names(value: Any, allowed: Sequence[str] | None = None) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value) or len(set(value)) != len(value):
        raise BlockError("a vocabulary is not a list of distinct names")
    if allowed is not None and not set(value) <= set(allowed):
        raise BlockError(f"a vocabulary holds unknown names: {sorted(set(value) - set(allowed))}")
    return tuple(value)


def _codes(codes: np.ndarray, size: int, *, absent: bool = False) -> None:
    low = NONE if absent else 0
    if codes.size and (codes.min() < low or codes.max() >= size):
        raise BlockError("a code lies outside its vocabulary")


def unpack(data: bytes, branch_id: int) -> TrialColumns:
    """A stored block's columns, checked (they come from a database).

    Raises:
        BlockError: the block is not what :func:`pack` writes.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)) or len(data) < _HEADER.size:
        raise BlockError("a block is shorter than its header")
    layout, n, vocabulary_bytes = _HEADER.unpack_from(data)
    if layout != _LAYOUT or n > MAX_BLOCK or vocabulary_bytes > _MAX_VOCABULARY_BYTES:
        raise BlockError(f"a block of layout {layout}, {n} trials and {vocabulary_bytes} bytes of names is not one llcps writes")
    start = _HEADER.size + vocabulary_bytes
    if len(data) != start + n * _BYTES_PER_TRIAL:
        raise BlockError(f"a block of {n} trials holds {len(data)} bytes, not {start + n * _BYTES_PER_TRIAL}")
    try:
        named = bounded_json.loads(bytes(data[_HEADER.size : start]))
    except ValueError as exc:
        raise BlockError(f"a block's names are not readable: {exc}") from None
    if not isinstance(named, dict) or set(named) != set(_VOCABULARIES):
        raise BlockError("a block's names are not the vocabularies llcps writes")
    argument_lists = named["argument_lists"]
    if not isinstance(argument_lists, list) or not all(isinstance(a, list) and len(a) <= SLOTS for a in argument_lists):
        raise BlockError("a block's argument lists are not lists of at most two names")
    vocabularies = {
        "sources": _names(named["sources"], TRIAL_SOURCES),
        "scenarios": _names(named["scenarios"]),
        "actions": _names(named["actions"], ACTIONS),
        "argument_lists": tuple(_names(a) for a in argument_lists),
        "orientations": _names(named["orientations"], ORIENTATIONS),
    }
    if len(set(vocabularies["argument_lists"])) != len(argument_lists):
        raise BlockError("a block's argument lists repeat")
    arrays: dict[str, np.ndarray] = {}
    offset = start
    for name, dtype, width in _PACKED:
        values = np.frombuffer(data, dtype=dtype, count=n * width, offset=offset)
        offset += values.nbytes
        arrays[name] = values.reshape((n, *_SHAPES_OF[name])) if name in _SHAPES_OF else values
    arrays["branch_id"] = np.full(n, branch_id, dtype=np.int64)
    columns = TrialColumns(**arrays, **vocabularies)
    _check(columns)
    return columns


def _check(c: TrialColumns) -> None:
    """What :func:`from_records` guarantees of columns built from checked records."""
    ids = c.id
    if len(ids) and (ids[0] < 1 or np.any(np.diff(ids) <= 0)):
        raise BlockError("a block's trial ids are not increasing positive integers")
    for name in ("run_id", "episode_id", "snapshot_id"):
        values = getattr(c, name)
        if values.size and values.min() < NONE:
            raise BlockError(f"a block's {name} is negative")
    if c.sim_steps.size and c.sim_steps.min() < 0:
        raise BlockError("a block's sim_steps is negative")
    if not (np.isfinite(c.rate).all() and np.isfinite(c.movement_magnitude).all() and np.isfinite(c.wall_seconds).all()):
        raise BlockError("a block's rate, magnitude or wall time is not a finite number")
    if np.isinf(c.simulation_wall_seconds).any():
        raise BlockError("a block's simulation wall time is infinite")
    for field, name in _VOCABULARY_OF.items():
        _codes(getattr(c, field), len(getattr(c, name)), absent=field == "scenario")
    _codes(c.shape, len(SHAPES), absent=True)
    _codes(c.color, len(COLORS), absent=True)
    arity = np.array([len(a) for a in c.argument_lists] or [0])[c.arguments] if len(c) else np.zeros(0, dtype=int)
    present = np.arange(SLOTS)[None, :] < arity[:, None]
    if not (np.array_equal(c.shape >= 0, present) and np.array_equal(c.color >= 0, present)):
        raise BlockError("a block's features do not match its trials' arguments")
    finite = np.isfinite(c.numbers).all(axis=2)
    if not (np.array_equal(finite, present) and np.isnan(c.numbers[~present]).all()):
        raise BlockError("a block's feature numbers are not finite where an argument is, and absent where none is")


__all__ = [
    "BLOCK",
    "CACHE_HIT_BIT",
    "NONE",
    "NO_TIME",
    "SOLVED_BIT",
    "BlockError",
    "TrialColumns",
    "concat",
    "empty",
    "from_records",
    "pack",
    "unpack",
]
