"""Run provenance: the git commit, library versions, Python, host and CPU count of each run.

Revision ID: 0005
Revises: 0003
Create Date: 2026-11-23
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0003"
branch_labels = None
depends_on = None

#: The new columns of ``runs``; all nullable, so runs stored before stay as they were.
COLUMNS = (
    ("git_commit", sa.String(length=64)),
    ("git_dirty", sa.Boolean()),
    ("python_version", sa.String(length=32)),
    ("pybullet_version", sa.String(length=32)),
    ("torch_version", sa.String(length=32)),
    ("sklearn_version", sa.String(length=32)),
    ("numpy_version", sa.String(length=32)),
    ("host", sa.String(length=255)),
    ("cpu_count", sa.Integer()),
)


def upgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        for name, type_ in COLUMNS:
            batch.add_column(sa.Column(name, type_, nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        for name, _ in reversed(COLUMNS):
            batch.drop_column(name)
