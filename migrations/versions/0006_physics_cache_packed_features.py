"""The physics cache, trials answered from it, and packed feature values.

A trial's Table-1 features move from a JSON list of objects into one binary value
of fixed layout (``llcps.store.trials.pack_features``: per entity five doubles,
then the shapes and colours as text), so loading a training set decodes no JSON
and fetches one value per trial for them. Trials gain ``cache_hit`` and
``simulation_wall_seconds`` (the wall time of the simulation that computed a
cached result; this run's own time stays in ``wall_seconds``). The new
``physics_cache`` table holds simulated trials by a digest of their inputs.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-22
"""

from __future__ import annotations

import json
import struct
from typing import Any

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

NUMBERS = ("volume", "vector_magnitude", "unit_x", "unit_y", "unit_z")
SEPARATOR = "\x1f"
LAYOUT = 1
BATCH = 5_000


def _pack(entities: list[dict[str, Any]]) -> bytes:
    """The layout of ``llcps.store.trials.pack_features`` at this revision (kept here: a
    revision must not change when the library does)."""
    numbers = [float(e[name]) for e in entities for name in NUMBERS]
    names = SEPARATOR.join(str(e[k]) for e in entities for k in ("shape", "color"))
    return bytes((LAYOUT, len(entities))) + struct.pack(f"<{len(numbers)}d", *numbers) + names.encode()


def _unpack(data: bytes) -> list[dict[str, Any]]:
    n = data[1]
    numbers = struct.unpack_from(f"<{5 * n}d", data, 2)
    names = data[2 + 40 * n :].decode().split(SEPARATOR) if n else []
    return [
        {"shape": names[2 * i], "volume": numbers[5 * i], "color": names[2 * i + 1],
         **dict(zip(NUMBERS[1:], numbers[5 * i + 1 : 5 * i + 5]))}
        for i in range(n)
    ]  # fmt: skip


def _sqlite_sequence(conn: sa.Connection) -> int | None:
    """The trials table's AUTOINCREMENT high-water mark (SQLite): kept across the table rebuild."""
    if conn.dialect.name != "sqlite":
        return None
    return conn.exec_driver_sql("SELECT seq FROM sqlite_sequence WHERE name = 'trials'").scalar()


def _restore_sequence(conn: sa.Connection, seq: int | None) -> None:
    if seq is None:
        return
    if conn.exec_driver_sql("UPDATE sqlite_sequence SET seq = max(seq, ?) WHERE name = 'trials'", (seq,)).rowcount == 0:
        conn.exec_driver_sql("INSERT INTO sqlite_sequence (name, seq) VALUES ('trials', ?)", (seq,))


def _decode(value: Any) -> list[dict[str, Any]]:
    """A JSON column's value (drivers may hand it over decoded)."""
    return json.loads(value) if isinstance(value, (str, bytes)) else list(value or [])


def _convert(conn: sa.Connection, source: str, target: str, convert: Any) -> None:
    """Fill column ``target`` of every trial from column ``source``, in batches."""
    trials = sa.table("trials", sa.column("id", sa.Integer()), sa.column(source), sa.column(target))
    last = 0
    while True:
        rows = conn.execute(
            sa.select(trials.c.id, trials.c[source]).where(trials.c.id > last).order_by(trials.c.id).limit(BATCH)
        ).all()
        if not rows:
            return
        conn.execute(
            trials.update().where(trials.c.id == sa.bindparam("trial_id")).values({target: sa.bindparam("value")}),
            [{"trial_id": trial_id, "value": convert(value)} for trial_id, value in rows],
        )
        last = rows[-1][0]


def upgrade() -> None:
    conn = op.get_bind()
    seq = _sqlite_sequence(conn)
    op.create_table(
        "physics_cache",
        sa.Column("key", sa.String(length=64), nullable=False),
        sa.Column("result", sa.LargeBinary(), nullable=False),
        sa.Column("end_state", sa.LargeBinary(), nullable=False),
        sa.Column("sha256", sa.String(length=64), nullable=False),
        sa.Column("size", sa.Integer(), nullable=False),
        sa.Column("hits", sa.Integer(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("last_used", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("key", name="pk_physics_cache"),
    )
    op.create_index("ix_physics_cache_last_used", "physics_cache", ["last_used"])
    with op.batch_alter_table("trials", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("packed_features", sa.LargeBinary(), nullable=True))
        batch.add_column(sa.Column("cache_hit", sa.Boolean(), nullable=False, server_default=sa.false()))
        batch.add_column(sa.Column("simulation_wall_seconds", sa.Float(), nullable=True))
    _convert(conn, "features", "packed_features", lambda value: _pack(_decode(value)))
    with op.batch_alter_table("trials", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.drop_column("features")
        batch.alter_column("packed_features", new_column_name="features", existing_type=sa.LargeBinary(), nullable=False)
    _restore_sequence(conn, seq)


def downgrade() -> None:
    conn = op.get_bind()
    seq = _sqlite_sequence(conn)
    with op.batch_alter_table("trials", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("json_features", sa.Text(), nullable=True))
    _convert(conn, "features", "json_features", lambda value: json.dumps(_unpack(bytes(value))))
    with op.batch_alter_table("trials", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.drop_column("features")
        batch.drop_column("cache_hit")
        batch.drop_column("simulation_wall_seconds")
        batch.alter_column("json_features", new_column_name="features", type_=sa.JSON(), existing_type=sa.Text(), nullable=False)
    _restore_sequence(conn, seq)
    op.drop_index("ix_physics_cache_last_used", table_name="physics_cache")
    op.drop_table("physics_cache")
