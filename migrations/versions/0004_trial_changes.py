"""Trial changes: the atoms each trial added and deleted, and the scene it found.

The goal-aware world model learns from them. Trials stored before this revision get
no row here; ``llcps db upgrade`` recovers their change by deterministic replay from
the stored start state where there is one, and marks it ``unknown`` otherwise
(docs/store.md).

Revision ID: 0004
Revises: 0006
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "trial_changes",
        sa.Column("trial_id", sa.Integer(), nullable=False),
        sa.Column("source", sa.String(length=16), nullable=False),
        sa.Column("before", sa.JSON(), nullable=False),
        sa.Column("added", sa.JSON(), nullable=False),
        sa.Column("deleted", sa.JSON(), nullable=False),
        sa.Column("bodies", sa.JSON(), nullable=False),
        sa.ForeignKeyConstraint(
            ["trial_id"], ["trials.id"], name="fk_trial_changes_trial_id_trials", ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("trial_id", name="pk_trial_changes"),
    )


def downgrade() -> None:
    op.drop_table("trial_changes")
