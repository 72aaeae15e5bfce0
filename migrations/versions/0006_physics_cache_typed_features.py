"""The physics cache, trials answered from it, and typed feature columns.

A trial's Table-1 features move from a JSON list into typed columns (``arg0_*``
for the first argument, ``arg1_*`` for the second, NULL for one-argument
actions), so loading a training set decodes no JSON. Trials gain ``cache_hit`` and
``simulation_wall_seconds`` (the wall time of the simulation that computed a
cached result; this run's own time stays in ``wall_seconds``). The new
``physics_cache`` table holds simulated trials by a digest of their inputs.

Revision ID: 0006
Revises: 0002
Create Date: 2026-11-22
"""

from __future__ import annotations

import json
from typing import Any

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0002"
branch_labels = None
depends_on = None

FEATURES = ("shape", "volume", "color", "vector_magnitude", "unit_x", "unit_y", "unit_z")
TEXT_FEATURES = ("shape", "color")
SLOTS = (0, 1)
BATCH = 5_000


def _feature_columns(nullable_first: bool) -> list[sa.Column]:
    return [
        sa.Column(
            f"arg{slot}_{name}",
            sa.String(length=32) if name in TEXT_FEATURES else sa.Float(),
            nullable=nullable_first or slot > 0,
        )
        for slot in SLOTS
        for name in FEATURES
    ]


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
    return json.loads(value) if isinstance(value, (str, bytes)) else list(value or [])


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
        for column in _feature_columns(nullable_first=True):
            batch.add_column(column)
        batch.add_column(sa.Column("cache_hit", sa.Boolean(), nullable=False, server_default=sa.false()))
        batch.add_column(sa.Column("simulation_wall_seconds", sa.Float(), nullable=True))

    trials = sa.table("trials", sa.column("id", sa.Integer()), sa.column("features", sa.Text()),
                      *(sa.column(c.name) for c in _feature_columns(nullable_first=True)))  # fmt: skip
    last = 0
    while True:
        rows = conn.execute(
            sa.select(trials.c.id, trials.c.features).where(trials.c.id > last).order_by(trials.c.id).limit(BATCH)
        ).all()
        if not rows:
            break
        updates = []
        for trial_id, features in rows:
            values: dict[str, Any] = {"trial_id": trial_id}
            decoded = _decode(features)
            for slot in SLOTS:
                entity = decoded[slot] if slot < len(decoded) else {}
                for name in FEATURES:
                    values[f"arg{slot}_{name}"] = entity.get(name)
            updates.append(values)
        conn.execute(
            trials.update()
            .where(trials.c.id == sa.bindparam("trial_id"))
            .values({c.name: sa.bindparam(c.name) for c in _feature_columns(nullable_first=True)}),
            updates,
        )
        last = rows[-1][0]

    with op.batch_alter_table("trials", table_kwargs={"sqlite_autoincrement": True}) as batch:
        for column in _feature_columns(nullable_first=False):
            if not column.nullable:
                batch.alter_column(column.name, existing_type=column.type, nullable=False)
        batch.drop_column("features")
    _restore_sequence(conn, seq)


def downgrade() -> None:
    conn = op.get_bind()
    seq = _sqlite_sequence(conn)
    with op.batch_alter_table("trials", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.add_column(sa.Column("features", sa.JSON(), nullable=True))
    columns = [c.name for c in _feature_columns(nullable_first=True)]
    trials = sa.table("trials", sa.column("id", sa.Integer()), sa.column("features", sa.JSON()), *(sa.column(c) for c in columns))
    rows = conn.execute(sa.select(trials.c.id, *(trials.c[c] for c in columns))).all()
    for row in rows:
        features = []
        for slot in SLOTS:
            entity = {name: row._mapping[f"arg{slot}_{name}"] for name in FEATURES}
            if entity["shape"] is not None:
                features.append(entity)
        conn.execute(trials.update().where(trials.c.id == row.id).values(features=features))
    with op.batch_alter_table("trials", table_kwargs={"sqlite_autoincrement": True}) as batch:
        batch.alter_column("features", existing_type=sa.JSON(), nullable=False)
        for name in columns:
            batch.drop_column(name)
        batch.drop_column("cache_hit")
        batch.drop_column("simulation_wall_seconds")
    _restore_sequence(conn, seq)
    op.drop_index("ix_physics_cache_last_used", table_name="physics_cache")
    op.drop_table("physics_cache")
