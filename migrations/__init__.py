"""Alembic environment and revisions of the experience store's schema, shipped inside the
package so `llcps db upgrade` (and Store.open) can migrate a store wherever llcps is installed."""
