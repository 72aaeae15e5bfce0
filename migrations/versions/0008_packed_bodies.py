"""Packed bodies in trial changes.

A change's scene (``trial_changes.bodies``) moves from a JSON list of objects into
one binary value of fixed layout (``llcps.store.changes.pack_bodies``: per body nine
doubles, then the names, kinds and shapes as text), so a fit, which reads every
visible trial's change, decodes no JSON for the bodies. A stored value that is not
a list of bodies (a row changed outside llcps) is kept as its text behind layout
byte 0, which the library refuses as malformed, as it refused the JSON before; the
downgrade gives the text back.

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-24
"""

from __future__ import annotations

import json
import math
import struct
from typing import Any

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None

LAYOUT = 1
UNREADABLE = 0
SEPARATOR = "\x1f"
BATCH = 5_000
FIELDS = {"name", "kind", "shape", "lo", "hi", "centre"}


def _numbers(value: Any) -> list[float]:
    if not isinstance(value, list) or len(value) != 3 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise ValueError("not three numbers")
    numbers = [float(v) for v in value]
    if not all(math.isfinite(v) for v in numbers):
        raise ValueError("not finite")
    return numbers


def _pack(bodies: Any) -> bytes:
    """The layout of ``llcps.store.changes.pack_bodies`` at this revision (kept here: a
    revision must not change when the library does)."""
    if not isinstance(bodies, list) or len(bodies) > 0xFFFF:
        raise ValueError("not a list of bodies")
    numbers: list[float] = []
    names: list[str] = []
    for body in bodies:
        if not isinstance(body, dict) or set(body) != FIELDS:
            raise ValueError("not a body")
        parts = (body["name"], body["kind"], body["shape"] or "")
        if not all(isinstance(p, str) and SEPARATOR not in p for p in parts):
            raise ValueError("not a body")
        names += parts
        numbers += _numbers(body["lo"]) + _numbers(body["hi"]) + _numbers(body["centre"])
    return bytes((LAYOUT,)) + len(bodies).to_bytes(2, "little") + struct.pack(f"<{len(numbers)}d", *numbers) + SEPARATOR.join(names).encode()


def _packed(value: Any) -> bytes:
    """A stored JSON value packed; text that is not a list of bodies kept behind layout 0."""
    text = value if isinstance(value, str) else json.dumps(value)
    try:
        return _pack(json.loads(text))
    except (ValueError, TypeError, OverflowError):
        return bytes((UNREADABLE,)) + text.encode()


def _unpacked(value: Any) -> str:
    data = bytes(value)
    if not data or data[0] != LAYOUT:
        return data[1:].decode(errors="replace") or "null"
    n = int.from_bytes(data[1:3], "little")
    numbers = struct.unpack_from(f"<{9 * n}d", data, 3)
    parts = data[3 + 72 * n :].decode().split(SEPARATOR) if n else []
    return json.dumps(
        [
            {
                "name": parts[3 * i],
                "kind": parts[3 * i + 1],
                "shape": parts[3 * i + 2] or None,
                "lo": list(numbers[9 * i : 9 * i + 3]),
                "hi": list(numbers[9 * i + 3 : 9 * i + 6]),
                "centre": list(numbers[9 * i + 6 : 9 * i + 9]),
            }
            for i in range(n)
        ]
    )


def _convert(conn: sa.Connection, source: sa.Column[Any], target: str, convert: Any) -> None:
    """Fill column ``target`` of every change from column ``source``, in batches."""
    changes = sa.table("trial_changes", sa.column("trial_id", sa.Integer()), source, sa.column(target))
    source_name = source.name
    last = 0
    while True:
        rows = conn.execute(
            sa.select(changes.c.trial_id, changes.c[source_name])
            .where(changes.c.trial_id > last)
            .order_by(changes.c.trial_id)
            .limit(BATCH)
        ).all()
        if not rows:
            return
        conn.execute(
            changes.update().where(changes.c.trial_id == sa.bindparam("id")).values({target: sa.bindparam("value")}),
            [{"id": trial_id, "value": convert(value)} for trial_id, value in rows],
        )
        last = rows[-1][0]


def upgrade() -> None:
    conn = op.get_bind()
    with op.batch_alter_table("trial_changes") as batch:
        batch.add_column(sa.Column("packed_bodies", sa.LargeBinary(), nullable=True))
    _convert(conn, sa.column("bodies", sa.Text()), "packed_bodies", _packed)
    with op.batch_alter_table("trial_changes") as batch:
        batch.drop_column("bodies")
        batch.alter_column("packed_bodies", new_column_name="bodies", existing_type=sa.LargeBinary(), nullable=False)


def downgrade() -> None:
    conn = op.get_bind()
    with op.batch_alter_table("trial_changes") as batch:
        batch.add_column(sa.Column("json_bodies", sa.Text(), nullable=True))
    _convert(conn, sa.column("bodies", sa.LargeBinary()), "json_bodies", _unpacked)
    with op.batch_alter_table("trial_changes") as batch:
        batch.drop_column("bodies")
        batch.alter_column("json_bodies", new_column_name="bodies", type_=sa.JSON(), existing_type=sa.Text(), nullable=False)
