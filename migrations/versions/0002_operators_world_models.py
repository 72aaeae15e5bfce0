"""Learned operators (K') and fitted world models, both owned by a branch.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-22
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "operators",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("branch_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("pddl", sa.Text(), nullable=False),
        sa.Column("definition", sa.JSON(), nullable=False),
        sa.Column("scenario", sa.String(length=64), nullable=True),
        sa.Column("episode_id", sa.Integer(), nullable=True),
        sa.Column("watermark", sa.BigInteger(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["branch_id"], ["branches.id"], name="fk_operators_branch_id_branches"),
        sa.ForeignKeyConstraint(["episode_id"], ["episodes.id"], name="fk_operators_episode_id_episodes"),
        sa.PrimaryKeyConstraint("id", name="pk_operators"),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_operators_branch_id_id", "operators", ["branch_id", "id"])
    op.create_table(
        "world_models",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("branch_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("watermark", sa.BigInteger(), nullable=False),
        sa.Column("artifact", sa.LargeBinary(), nullable=False),
        sa.Column("sha256", sa.String(length=64), nullable=False),
        sa.Column("meta", sa.JSON(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["branch_id"], ["branches.id"], name="fk_world_models_branch_id_branches"),
        sa.PrimaryKeyConstraint("id", name="pk_world_models"),
        sqlite_autoincrement=True,
    )
    op.create_index("ix_world_models_branch_id_name_seed", "world_models", ["branch_id", "name", "seed"])


def downgrade() -> None:
    op.drop_index("ix_world_models_branch_id_name_seed", table_name="world_models")
    op.drop_table("world_models")
    op.drop_index("ix_operators_branch_id_id", table_name="operators")
    op.drop_table("operators")
