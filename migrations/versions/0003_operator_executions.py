"""Operator executions: success or failure of each plan step and its context, for costs by experience.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-22
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "operator_executions",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("branch_id", sa.Integer(), nullable=False),
        sa.Column("operator", sa.String(length=200), nullable=False),
        sa.Column("success", sa.Boolean(), nullable=False),
        sa.Column("context", sa.JSON(), nullable=False),
        sa.Column("episode_id", sa.Integer(), nullable=True),
        sa.Column("trial_id", sa.Integer(), nullable=True),
        sa.Column("watermark", sa.BigInteger(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["branch_id"], ["branches.id"], name="fk_operator_executions_branch_id_branches"),
        sa.ForeignKeyConstraint(["episode_id"], ["episodes.id"], name="fk_operator_executions_episode_id_episodes"),
        sa.ForeignKeyConstraint(["trial_id"], ["trials.id"], name="fk_operator_executions_trial_id_trials"),
        sa.PrimaryKeyConstraint("id", name="pk_operator_executions"),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_operator_executions_branch_id_id", "operator_executions", ["branch_id", "id"])


def downgrade() -> None:
    op.drop_index("ix_operator_executions_branch_id_id", table_name="operator_executions")
    op.drop_table("operator_executions")
