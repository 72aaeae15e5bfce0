"""Seals on physics cache entries.

A nullable ``seal`` column on ``physics_cache``: an HMAC of the entry's key and
content hash under a secret kept outside the store (see
``llcps.store.physics_cache``). Entries stored before carry none; they are checked
as before when next read, and sealed once they pass.

Revision ID: 0007
Revises: 0004
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("physics_cache") as batch:
        batch.add_column(sa.Column("seal", sa.String(length=64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("physics_cache") as batch:
        batch.drop_column("seal")
