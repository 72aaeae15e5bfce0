"""The visible trials of a branch as CSV, JSON lines or parquet, for pandas and friends.

Every format holds the same flat columns (:mod:`llcps.store.flat`): one row per
trial, one column per Table-1 feature per argument slot, one per outcome bit.
Booleans are booleans everywhere: ``true``/``false`` in CSV and JSON lines, a
boolean column in parquet; an absent value is an empty CSV field, ``null`` in JSON
and a null in parquet.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any, Iterator, Sequence, TextIO

from llcps.errors import LlcpsError
from llcps.outputs import replaced_atomically, written_atomically
from llcps.store.flat import Column, flat_rows, trial_columns
from llcps.store.store import Store
from llcps.tabular import csv_value

EXPORT_FORMATS: tuple[str, ...] = ("csv", "jsonl", "parquet")
#: Formats that are bytes, written to a file only.
BINARY_FORMATS: tuple[str, ...] = ("parquet",)


def _batches(
    store: Store, branch: str, *, source: str | None, scenario: str | None, episode: int | None, batch: int
) -> Iterator[list[dict[str, Any]]]:
    after = 0
    while True:
        records = store.visible_trials(branch, source=source, scenario=scenario, episode=episode, after_id=after, limit=batch)
        if not records:
            return
        yield flat_rows(store, records)
        after = records[-1].id


def _arrow_schema(columns: Sequence[Column]) -> Any:
    import pyarrow as pa

    types = {
        "int": pa.int64(),
        "nullable_int": pa.int64(),
        "float": pa.float64(),
        "bool": pa.bool_(),
        "nullable_bool": pa.bool_(),
        "string": pa.string(),
        "category": pa.dictionary(pa.int32(), pa.string()),
        "timestamp": pa.timestamp("us"),
    }
    return pa.schema([pa.field(c.name, types[c.kind]) for c in columns])


def _arrow_rows(rows: list[dict[str, Any]], columns: Sequence[Column]) -> list[dict[str, Any]]:
    from datetime import datetime

    stamps = [c.name for c in columns if c.kind == "timestamp"]
    for row in rows:
        for name in stamps:
            if isinstance(row[name], str):
                row[name] = datetime.fromisoformat(row[name])
    return rows


def export_trials(
    store: Store,
    *,
    branch: str | None,
    fmt: str,
    out: TextIO | str | Path,
    source: str | None = None,
    scenario: str | None = None,
    episode: int | None = None,
    batch: int = 5000,
    what: str = "out",
) -> int:
    """Write the trials ``branch`` sees (optionally filtered) to ``out``, in id order.

    A file path is written under a temporary name and renamed into place at the end,
    so a failed export (a damaged row, a full disk) leaves no half-written file.

    Args:
        branch: the branch (None: the current one).
        fmt: one of :data:`EXPORT_FORMATS`.
        out: a text stream (csv, jsonl) or a file path (any format; parquet needs one).
        source, scenario, episode: keep only trials with these values.
        batch: trials read per query.
        what: how the caller named ``out``, for errors (e.g. ``"--out"``).

    Returns:
        The number of trials written.
    """
    if fmt not in EXPORT_FORMATS:
        raise LlcpsError(f"unknown export format {fmt!r}", hint=f"use one of: {', '.join(EXPORT_FORMATS)}")
    name = store.resolve_branch(branch).name
    columns = trial_columns()
    batches = _batches(store, name, source=source, scenario=scenario, episode=episode, batch=batch)
    if fmt in BINARY_FORMATS:
        if not isinstance(out, (str, Path)):
            raise LlcpsError(f"{fmt} is binary: it is written to a file", hint="pass --out FILE")
        with written_atomically(out, what=what) as target:
            return _write_parquet(target, batches, columns)
    if isinstance(out, (str, Path)):
        with replaced_atomically(out, what=what) as fh:
            return _write_text(fh, fmt, batches, columns)
    return _write_text(out, fmt, batches, columns)


def _write_text(out: TextIO, fmt: str, batches: Iterator[list[dict[str, Any]]], columns: Sequence[Column]) -> int:
    names = [c.name for c in columns]
    writer = None
    if fmt == "csv":
        writer = csv.DictWriter(out, fieldnames=names, extrasaction="raise", lineterminator="\n")
        writer.writeheader()
    count = 0
    for rows in batches:
        for row in rows:
            if writer is not None:
                writer.writerow({k: csv_value(v) for k, v in row.items()})
            else:
                out.write(json.dumps(row) + "\n")
        count += len(rows)
    return count


def _write_parquet(path: Path, batches: Iterator[list[dict[str, Any]]], columns: Sequence[Column]) -> int:
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = _arrow_schema(columns)
    count = 0
    with pq.ParquetWriter(path, schema) as writer:
        for rows in batches:
            writer.write_table(pa.Table.from_pylist(_arrow_rows(rows, columns), schema=schema))
            count += len(rows)
        if count == 0:
            writer.write_table(schema.empty_table())
    return count
