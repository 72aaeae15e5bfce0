"""Packed trial blocks: every 4,096 trials of a branch kept as columns beside their rows.

Reading a branch's visible set row by row costs the database alone several seconds per
million trials before anything is decoded. Each block holds 4,096 consecutive trials
of one branch as arrays (``llcps.store.trial_blocks``), so a visible set is read as a
few hundred rows. A derived table: blocks are written as trials are stored, the
downgrade drops it and nothing is lost; a store upgraded to it reads its older trials
from their rows until new trials complete a block.

Revision ID: 0011
Revises: 0010
Create Date: 2026-11-29
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0011"
down_revision = "0010"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "trial_blocks",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("branch_id", sa.Integer(), nullable=False),
        sa.Column("first_id", sa.Integer(), nullable=False),
        sa.Column("last_id", sa.Integer(), nullable=False),
        sa.Column("trials", sa.Integer(), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.ForeignKeyConstraint(
            ["branch_id"], ["branches.id"], name="fk_trial_blocks_branch_id_branches", ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name="pk_trial_blocks"),
    )
    op.create_index("ix_trial_blocks_branch_id_first_id", "trial_blocks", ["branch_id", "first_id"])


def downgrade() -> None:
    op.drop_index("ix_trial_blocks_branch_id_first_id", table_name="trial_blocks")
    op.drop_table("trial_blocks")
