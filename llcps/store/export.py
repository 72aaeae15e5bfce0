"""The visible trials of a branch as CSV or JSON lines, for pandas and friends.

CSV flattens a trial into one row: the argument slots become ``arg0_*`` and
``arg1_*`` columns and the outcome its six Table-2 columns. JSON lines keep the
shape of :meth:`llcps.domain.TrialRecord.as_json`, one trial per line.
"""

from __future__ import annotations

import csv
import json
from dataclasses import fields
from typing import Any, TextIO

from llcps.domain import ACTION_ARITY, OUTCOME_NAMES, EntityFeatures, TrialRecord
from llcps.errors import LlcpsError
from llcps.store.store import Store

EXPORT_FORMATS: tuple[str, ...] = ("csv", "jsonl")

_SLOTS = max(ACTION_ARITY.values())
_ENTITY_FIELDS = tuple(f.name for f in fields(EntityFeatures))

#: Columns of the CSV export, in order.
CSV_COLUMNS: tuple[str, ...] = (
    "id", "branch", "run_id", "episode_id", "scenario", "source", "action",
    "rate", "movement_magnitude", "orientation",
    *(f"arg{slot}" for slot in range(_SLOTS)),
    *(f"arg{slot}_{name}" for slot in range(_SLOTS) for name in _ENTITY_FIELDS),
    *OUTCOME_NAMES,
    "solved", "sim_steps", "wall_seconds", "seed", "snapshot_id", "created_at",
)  # fmt: skip


def csv_row(record: TrialRecord) -> dict[str, Any]:
    """One trial as a flat CSV row (missing argument slots stay empty)."""
    data = record.as_json()
    row = {key: data[key] for key in CSV_COLUMNS if key in data}
    for slot, (name, features) in enumerate(zip(record.spec.arguments, record.features, strict=True)):
        row[f"arg{slot}"] = name
        for field_name, value in features.as_dict().items():
            row[f"arg{slot}_{field_name}"] = value
    row.update(record.outcome.as_dict())
    row["solved"] = int(record.solved)
    return row


def export_trials(store: Store, branch: str | None, fmt: str, out: TextIO, *, batch: int = 5000) -> int:
    """Write the trials ``branch`` sees to ``out``, in id order, a batch at a time.

    Returns:
        The number of trials written.
    """
    if fmt not in EXPORT_FORMATS:
        raise LlcpsError(f"unknown export format {fmt!r}", hint=f"use one of: {', '.join(EXPORT_FORMATS)}")
    branch = store.resolve_branch(branch).name
    writer = None
    if fmt == "csv":
        writer = csv.DictWriter(out, fieldnames=CSV_COLUMNS, extrasaction="raise", lineterminator="\n")
        writer.writeheader()
    count, after = 0, 0
    while True:
        records = store.visible_trials(branch, after_id=after, limit=batch)
        if not records:
            return count
        for record in records:
            if writer is not None:
                writer.writerow(csv_row(record))
            else:
                out.write(json.dumps(record.as_json()) + "\n")
        count += len(records)
        after = records[-1].id
