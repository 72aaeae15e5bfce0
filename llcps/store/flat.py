"""Trials as flat, typed rows: the one tidy shape of every export and of the pandas API.

One row per trial and one column per thing: the controller call, one column per
Table-1 feature per argument slot (``arg0_shape``, ``arg1_volume``, ...; empty when
the action has fewer arguments), one per outcome bit of Table 2, and what the store
records about the trial. Booleans (the outcome bits and ``solved``) are booleans in
every format: ``true``/``false`` in CSV and JSON, ``bool`` in parquet and pandas.

More columns plug in as a :class:`ColumnSource` (e.g. a trial's recorded symbolic
change, from a table of its own): :func:`register_trial_columns` adds one, and every
export and DataFrame gets its columns, empty where a trial has no value.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

from llcps.domain import ACTION_ARITY, ACTIONS, COLORS, ORIENTATIONS, OUTCOME_NAMES, SHAPES, TRIAL_SOURCES, EntityFeatures
from llcps.trial_records import StoredFeatures, TrialRecord

if TYPE_CHECKING:
    from llcps.store.store import Store

#: Column kinds and their pandas dtypes (``category`` columns list their known values).
KINDS: Mapping[str, str] = {
    "int": "int64",
    "nullable_int": "Int64",
    "float": "float64",
    "bool": "bool",
    "nullable_bool": "boolean",
    "string": "string",
    "category": "category",
    "timestamp": "datetime64[ns]",
}

#: Argument slots: the largest arity of an action.
ARGUMENT_SLOTS = max(ACTION_ARITY.values())
ENTITY_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(EntityFeatures))
_ENTITY_CATEGORIES: Mapping[str, tuple[str, ...]] = {"shape": SHAPES, "color": COLORS}


@dataclass(frozen=True)
class Column:
    """One flat column: its name, kind (a key of :data:`KINDS`) and meaning."""

    name: str
    kind: str
    description: str
    categories: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown column kind {self.kind!r}")

    @property
    def dtype(self) -> str:
        """The pandas dtype of the column."""
        return KINDS[self.kind]


def _slot_columns(slot: int) -> list[Column]:
    which = "first" if slot == 0 else "second" if slot == 1 else f"#{slot}"
    cols = [Column(f"arg{slot}", "string", f"name of the {which} argument (empty when the action has fewer)")]
    for name in ENTITY_FIELDS:
        categories = _ENTITY_CATEGORIES.get(name, ())
        kind = "category" if categories else "float"
        cols.append(Column(f"arg{slot}_{name}", kind, f"Table-1 {name.replace('_', ' ')} of the {which} argument", categories))
    return cols


#: The columns every trial has, in order.
BASE_COLUMNS: tuple[Column, ...] = (
    Column("id", "int", "trial id (ids only grow)"),
    Column("branch", "string", "the branch that owns the trial"),
    Column("run_id", "nullable_int", "the run that wrote it"),
    Column("episode_id", "nullable_int", "the episode it belongs to (none for pretraining)"),
    Column("scenario", "string", "the scenario it ran in (none for pretraining)"),
    Column("source", "category", "pretrain, plan, exploration, replay or gym", TRIAL_SOURCES),
    Column("action", "category", "Table-1 action", ACTIONS),
    Column("rate", "float", "Table-1 rate, m/s"),
    Column("movement_magnitude", "float", "Table-1 movement magnitude, m"),
    Column("orientation", "category", "Table-1 orientation", ORIENTATIONS),
    *(c for slot in range(ARGUMENT_SLOTS) for c in _slot_columns(slot)),
    *(Column(name, "bool", f"Table-2 outcome bit: {name.replace('_', ' ')} change") for name in OUTCOME_NAMES),
    Column("solved", "bool", "the scenario's goal held after the trial"),
    Column("sim_steps", "int", "physics steps (240 Hz)"),
    Column("wall_seconds", "float", "wall time of the trial"),
    Column("seed", "int", "the seed recorded with the trial"),
    Column("snapshot_id", "nullable_int", "the stored physics state it started from"),
    Column("created_at", "timestamp", "when it was stored (UTC)"),
)


def base_values(record: TrialRecord) -> dict[str, Any]:
    """The :data:`BASE_COLUMNS` of one trial (absent argument slots are None)."""
    p = record.spec.params
    row: dict[str, Any] = {
        "id": record.id,
        "branch": record.branch,
        "run_id": record.run_id,
        "episode_id": record.episode_id,
        "scenario": record.scenario,
        "source": record.source,
        "action": record.spec.action,
        "rate": p.rate,
        "movement_magnitude": p.movement_magnitude,
        "orientation": p.orientation,
    }
    stored = record.stored_features or StoredFeatures.of(record.features)  # a read record's: no objects built
    for slot in range(ARGUMENT_SLOTS):
        has = slot < len(record.spec.arguments)
        row[f"arg{slot}"] = record.spec.arguments[slot] if has else None
        features = stored.entity_fields(slot) if has and slot < len(stored) else {}
        for name in ENTITY_FIELDS:
            row[f"arg{slot}_{name}"] = features.get(name)
    row.update({name: bool(bit) for name, bit in record.outcome.as_dict().items()})
    row["solved"] = bool(record.solved)
    row["sim_steps"] = record.sim_steps
    row["wall_seconds"] = record.wall_seconds
    row["seed"] = record.seed
    row["snapshot_id"] = record.snapshot_id
    row["created_at"] = record.created_at
    return row


ColumnValues = Callable[["Store", Sequence[TrialRecord]], Sequence[Mapping[str, Any]]]
"""``values(store, records)``: one mapping per record, in order (missing keys: no value)."""


@dataclass(frozen=True)
class ColumnSource:
    """A group of flat columns and where their values come from."""

    name: str
    columns: tuple[Column, ...]
    values: ColumnValues


def _base(store: "Store", records: Sequence[TrialRecord]) -> list[dict[str, Any]]:
    return [base_values(r) for r in records]


#: Every source of trial columns, in column order; the first is the trial itself.
TRIAL_COLUMN_SOURCES: list[ColumnSource] = [ColumnSource("trial", BASE_COLUMNS, _base)]


def register_trial_columns(source: ColumnSource) -> None:
    """Add a source of trial columns (once per name; names must not collide)."""
    if any(s.name == source.name for s in TRIAL_COLUMN_SOURCES):
        return
    taken = {c.name for s in TRIAL_COLUMN_SOURCES for c in s.columns}
    clash = taken & {c.name for c in source.columns}
    if clash:
        raise ValueError(f"trial columns {sorted(clash)} already exist")
    TRIAL_COLUMN_SOURCES.append(source)


def trial_columns() -> tuple[Column, ...]:
    """Every flat trial column, in order."""
    return tuple(c for s in TRIAL_COLUMN_SOURCES for c in s.columns)


def flat_rows(store: "Store", records: Sequence[TrialRecord]) -> list[dict[str, Any]]:
    """One flat row per record, with every column of every source (None where absent)."""
    empty = dict.fromkeys(c.name for c in trial_columns())
    rows = [empty.copy() for _ in records]
    for source in TRIAL_COLUMN_SOURCES:
        names = [c.name for c in source.columns]
        for row, values in zip(rows, source.values(store, records), strict=True):
            for name in names:
                if name in values:
                    row[name] = values[name]
    return rows


__all__ = [
    "ARGUMENT_SLOTS",
    "BASE_COLUMNS",
    "Column",
    "ColumnSource",
    "KINDS",
    "TRIAL_COLUMN_SOURCES",
    "base_values",
    "flat_rows",
    "register_trial_columns",
    "trial_columns",
]
