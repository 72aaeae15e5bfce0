"""Alembic, run from code: no ``alembic.ini`` is needed at runtime.

The revisions live in the top-level ``migrations/`` directory, shipped inside the
package as ``llcps/_migrations`` so installed and editable copies find them alike.
"""

from __future__ import annotations

from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import Connection, inspect

from llcps.store.tables import VERSION_TABLE

if TYPE_CHECKING:
    from alembic.config import Config
    from alembic.script import ScriptDirectory


def migrations_dir() -> Path:
    """Where the Alembic environment and revisions are installed."""
    return Path(str(resources.files("llcps") / "_migrations"))


def alembic_config(connection: Connection | None = None) -> Config:
    """An Alembic config pointing at the shipped revisions (and a connection, if given)."""
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(migrations_dir()))
    cfg.attributes["connection"] = connection
    return cfg


@lru_cache(maxsize=1)
def _script() -> ScriptDirectory:
    from alembic.script import ScriptDirectory

    return ScriptDirectory.from_config(alembic_config())


def head_revision() -> str:
    """The newest schema revision this llcps knows."""
    head = _script().get_current_head()
    assert head is not None, "migrations/versions holds no revision"
    return head


def known_revisions() -> list[str]:
    """All revisions, oldest first."""
    return [rev.revision for rev in reversed(list(_script().walk_revisions()))]


def revision_label(revision: str | None) -> str:
    """A revision with its place in the chain, ``0004 (6 of 6)``: revision ids are names, not
    an order (a later migration may carry a smaller number)."""
    chain = known_revisions()
    if revision not in chain:
        return str(revision)
    return f"{revision} ({chain.index(revision) + 1} of {len(chain)})"


def current_revision(connection: Connection) -> str | None:
    """The revision recorded in the database, or None if it has no llcps version table."""
    if not inspect(connection).has_table(VERSION_TABLE):
        return None
    rows = connection.exec_driver_sql(f"SELECT version_num FROM {VERSION_TABLE}").all()
    return rows[0][0] if rows else None


def upgrade(connection: Connection, target: str = "head") -> None:
    """Migrate the database on ``connection`` (inside its transaction) to ``target``."""
    from alembic import command

    command.upgrade(alembic_config(connection), target)
