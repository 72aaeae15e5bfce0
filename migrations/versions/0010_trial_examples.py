"""Stored goal examples: each trial's encoded (candidate, atom) examples, kept once.

A fit of the goal-aware head reads every visible trial's examples; encoding them is a
per-trial walk over the scene's atoms in Python and was half of a fit's time, repeated
at every episode. They are now encoded once (the first time a fit reads the trial)
and kept here, tagged with the digest of the model code that encoded them
(``llcps.models.persistence.model_code``): rows of other code are encoded again. A
derived table: the downgrade drops it and nothing is lost.

Revision ID: 0010
Revises: 0009
Create Date: 2026-11-26
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "trial_examples",
        sa.Column("trial_id", sa.Integer(), nullable=False),
        sa.Column("code", sa.String(length=16), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.ForeignKeyConstraint(
            ["trial_id"], ["trials.id"], name="fk_trial_examples_trial_id_trials", ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("trial_id", name="pk_trial_examples"),
    )


def downgrade() -> None:
    op.drop_table("trial_examples")
