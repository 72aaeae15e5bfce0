"""Core tables: branches, settings, runs, episodes, snapshots, trials; the main branch.

Revision ID: 0001
Revises:
Create Date: 2026-11-22
"""

from __future__ import annotations

from datetime import datetime, timezone

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

AUTOINCREMENT = {"sqlite_autoincrement": True}
OUTCOME_COLUMNS = (
    "positive_visibility",
    "negative_visibility",
    "positive_reachability",
    "negative_reachability",
    "positive_touching",
    "negative_touching",
)


def upgrade() -> None:
    branches = op.create_table(
        "branches",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("parent_id", sa.Integer(), nullable=True),
        sa.Column("fork_point", sa.BigInteger(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["parent_id"], ["branches.id"], name="fk_branches_parent_id_branches"),
        sa.PrimaryKeyConstraint("id", name="pk_branches"),
        sa.UniqueConstraint("name", name="uq_branches_name"),
        **AUTOINCREMENT,
    )
    settings = op.create_table(
        "settings",
        sa.Column("key", sa.String(length=64), nullable=False),
        sa.Column("value", sa.Text(), nullable=False),
        sa.PrimaryKeyConstraint("key", name="pk_settings"),
    )
    op.create_table(
        "runs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("command", sa.Text(), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=True),
        sa.Column("config", sa.JSON(), nullable=False),
        sa.Column("branch", sa.String(length=100), nullable=False),
        sa.Column("llcps_version", sa.String(length=32), nullable=False),
        sa.Column("status", sa.String(length=32), nullable=False),
        sa.Column("started_at", sa.DateTime(), nullable=False),
        sa.Column("finished_at", sa.DateTime(), nullable=True),
        sa.PrimaryKeyConstraint("id", name="pk_runs"),
        **AUTOINCREMENT,
    )
    op.create_table(
        "episodes",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=True),
        sa.Column("branch_id", sa.Integer(), nullable=False),
        sa.Column("scenario", sa.String(length=64), nullable=False),
        sa.Column("condition", sa.String(length=32), nullable=False),
        sa.Column("model", sa.String(length=64), nullable=True),
        sa.Column("measure", sa.String(length=64), nullable=True),
        sa.Column("seed", sa.BigInteger(), nullable=True),
        sa.Column("status", sa.String(length=32), nullable=False),
        sa.Column("summary", sa.JSON(), nullable=False),
        sa.Column("started_at", sa.DateTime(), nullable=False),
        sa.Column("finished_at", sa.DateTime(), nullable=True),
        sa.ForeignKeyConstraint(["branch_id"], ["branches.id"], name="fk_episodes_branch_id_branches"),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name="fk_episodes_run_id_runs"),
        sa.PrimaryKeyConstraint("id", name="pk_episodes"),
        **AUTOINCREMENT,
    )
    op.create_index("ix_episodes_branch_id", "episodes", ["branch_id"])
    op.create_table(
        "snapshots",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("sha256", sa.String(length=64), nullable=False),
        sa.Column("scene", sa.JSON(), nullable=False),
        sa.Column("state", sa.LargeBinary(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name="pk_snapshots"),
        sa.UniqueConstraint("sha256", name="uq_snapshots_sha256"),
        **AUTOINCREMENT,
    )
    op.create_table(
        "trials",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("branch_id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=True),
        sa.Column("episode_id", sa.Integer(), nullable=True),
        sa.Column("source", sa.String(length=16), nullable=False),
        sa.Column("scenario", sa.String(length=64), nullable=True),
        sa.Column("action", sa.String(length=32), nullable=False),
        sa.Column("arguments", sa.JSON(), nullable=False),
        sa.Column("rate", sa.Float(), nullable=False),
        sa.Column("movement_magnitude", sa.Float(), nullable=False),
        sa.Column("orientation", sa.String(length=16), nullable=False),
        sa.Column("features", sa.JSON(), nullable=False),
        *(sa.Column(name, sa.SmallInteger(), nullable=False) for name in OUTCOME_COLUMNS),
        sa.Column("solved", sa.Boolean(), nullable=False),
        sa.Column("sim_steps", sa.Integer(), nullable=False),
        sa.Column("wall_seconds", sa.Float(), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("snapshot_id", sa.Integer(), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("extra", sa.JSON(), nullable=False),
        sa.ForeignKeyConstraint(["branch_id"], ["branches.id"], name="fk_trials_branch_id_branches"),
        sa.ForeignKeyConstraint(["episode_id"], ["episodes.id"], name="fk_trials_episode_id_episodes"),
        sa.ForeignKeyConstraint(["run_id"], ["runs.id"], name="fk_trials_run_id_runs"),
        sa.ForeignKeyConstraint(["snapshot_id"], ["snapshots.id"], name="fk_trials_snapshot_id_snapshots"),
        sa.PrimaryKeyConstraint("id", name="pk_trials"),
        **AUTOINCREMENT,
    )
    op.create_index("ix_trials_branch_id_id", "trials", ["branch_id", "id"])

    # Every store starts with a root branch `main`, checked out.
    now = datetime.now(timezone.utc).replace(tzinfo=None)
    op.bulk_insert(branches, [{"name": "main", "parent_id": None, "fork_point": 0, "created_at": now}])  # id from the sequence
    op.bulk_insert(settings, [{"key": "current_branch", "value": "main"}])


def downgrade() -> None:
    op.drop_index("ix_trials_branch_id_id", table_name="trials")
    op.drop_table("trials")
    op.drop_table("snapshots")
    op.drop_index("ix_episodes_branch_id", table_name="episodes")
    op.drop_table("episodes")
    op.drop_table("runs")
    op.drop_table("settings")
    op.drop_table("branches")
