"""Alembic environment of the experience store.

Run from code (llcps.store.migrations), which hands over an open connection in
``config.attributes["connection"]``; batch mode lets SQLite alter tables.
"""

from __future__ import annotations

from alembic import context

from llcps.store.tables import VERSION_TABLE, Base

connection = context.config.attributes.get("connection")
if connection is None:
    raise RuntimeError("run migrations through llcps (`llcps db upgrade`), not the alembic command")

context.configure(
    connection=connection,
    target_metadata=Base.metadata,
    render_as_batch=True,
    version_table=VERSION_TABLE,
    compare_type=True,
)
with context.begin_transaction():
    context.run_migrations()
