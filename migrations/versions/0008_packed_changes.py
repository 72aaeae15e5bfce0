"""Packed trial changes.

A change's states (``before``, ``added``, ``deleted``) and its scene (``bodies``) move
from JSON lists into binary values of fixed layout (``llcps.store.trial_changes.pack_atoms``:
the atoms as text with control-character separators; ``pack_bodies``: per body nine
doubles, then the names, kinds and shapes as text), so a fit, which reads every
visible trial's change, parses no JSON. A stored value that does not convert (a row
changed outside llcps) is kept as its text behind layout byte 0, which the library
refuses as malformed, as it refused the JSON before; the downgrade gives the text back.

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
ATOM_SEPARATOR = "\x1e"
STATES = ("before", "added", "deleted")
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
    """The layout of ``llcps.store.trial_changes.pack_bodies`` at this revision (kept here: a
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


def _pack_atoms(atoms: Any) -> bytes:
    """The layout of ``llcps.store.trial_changes.pack_atoms`` at this revision."""
    if not isinstance(atoms, list):
        raise ValueError("not a list of atoms")
    texts = []
    for atom in atoms:
        if not isinstance(atom, list) or not 1 <= len(atom) <= 3:
            raise ValueError("not an atom")
        if not all(isinstance(p, str) and p and SEPARATOR not in p and ATOM_SEPARATOR not in p for p in atom):
            raise ValueError("not an atom")
        texts.append(SEPARATOR.join(atom))
    return bytes((LAYOUT,)) + ATOM_SEPARATOR.join(sorted(texts)).encode()


def _packer(pack: Any) -> Any:
    def packed(value: Any) -> bytes:
        """A stored JSON value packed; a value that does not convert kept as its text behind layout 0."""
        text = value if isinstance(value, str) else json.dumps(value)
        try:
            return pack(json.loads(text))
        except (ValueError, TypeError, OverflowError):
            return bytes((UNREADABLE,)) + text.encode()

    return packed


def _kept(data: bytes) -> str | None:
    """The text a value that did not convert was kept as (None for a packed value)."""
    if not data or data[0] != LAYOUT:
        return data[1:].decode(errors="replace") or "null"
    return None


def _unpacked_atoms(value: Any) -> str:
    data = bytes(value)
    kept = _kept(data)
    if kept is not None:
        return kept
    text = data[1:].decode()
    return json.dumps([atom.split(SEPARATOR) for atom in text.split(ATOM_SEPARATOR)] if text else [])


def _unpacked(value: Any) -> str:
    data = bytes(value)
    kept = _kept(data)
    if kept is not None:
        return kept
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
    columns = (*STATES, "bodies")
    with op.batch_alter_table("trial_changes") as batch:
        for column in columns:
            batch.add_column(sa.Column(f"packed_{column}", sa.LargeBinary(), nullable=True))
    for column in STATES:
        _convert(conn, sa.column(column, sa.Text()), f"packed_{column}", _packer(_pack_atoms))
    _convert(conn, sa.column("bodies", sa.Text()), "packed_bodies", _packer(_pack))
    with op.batch_alter_table("trial_changes") as batch:
        for column in columns:
            batch.drop_column(column)
            batch.alter_column(f"packed_{column}", new_column_name=column, existing_type=sa.LargeBinary(), nullable=False)


def downgrade() -> None:
    conn = op.get_bind()
    columns = (*STATES, "bodies")
    with op.batch_alter_table("trial_changes") as batch:
        for column in columns:
            batch.add_column(sa.Column(f"json_{column}", sa.Text(), nullable=True))
    for column in STATES:
        _convert(conn, sa.column(column, sa.LargeBinary()), f"json_{column}", _unpacked_atoms)
    _convert(conn, sa.column("bodies", sa.LargeBinary()), "json_bodies", _unpacked)
    with op.batch_alter_table("trial_changes") as batch:
        for column in columns:
            batch.drop_column(column)
            batch.alter_column(f"json_{column}", new_column_name=column, type_=sa.JSON(), existing_type=sa.Text(), nullable=False)
