"""Live-writer markers on runs.

Two nullable columns on ``runs``: ``pid``, the process id of the command that writes
the run (beside ``host``, its machine), and ``heartbeat_at``, when that process last
said it was alive. A run still ``running`` whose process is gone (same host: no such
pid; another host: no heartbeat for a while) is stale, not a live writer: ``llcps db
status`` reports it and ``llcps db delete`` does not wait for it (see
``llcps.store.writers``). Runs stored before carry neither and count as stale.

Revision ID: 0009
Revises: 0008
Create Date: 2026-11-26
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        batch.add_column(sa.Column("pid", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("heartbeat_at", sa.DateTime(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        batch.drop_column("heartbeat_at")
        batch.drop_column("pid")
