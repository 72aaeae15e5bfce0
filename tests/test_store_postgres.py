"""What only PostgreSQL needs checking: its schema against the typed models, a database
with other tables, and branch visibility over random trees there (the other store tests
run on both backends through the ``store`` fixture)."""

from __future__ import annotations

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from conftest import POSTGRES_SKIP, fresh_postgres_url
from sqlalchemy import create_engine, text
from test_store_branches import BranchMachine, run_machine

from llcps.errors import StoreError
from llcps.store import Store
from llcps.store.tables import VERSION_TABLE, Base

pytestmark = [pytest.mark.postgresql, pytest.mark.skipif(POSTGRES_SKIP is not None, reason=POSTGRES_SKIP or "")]


def test_schema_matches_the_typed_models() -> None:
    with Store.open(fresh_postgres_url(), create=True) as store, store.engine.connect() as conn:
        context = MigrationContext.configure(conn, opts={"version_table": VERSION_TABLE, "compare_type": True})
        assert compare_metadata(context, Base.metadata) == []


def test_a_database_with_other_tables_is_refused() -> None:
    url = fresh_postgres_url()
    engine = create_engine(url)
    with engine.begin() as conn:
        conn.execute(text("CREATE TABLE notes (body text)"))
    engine.dispose()
    with pytest.raises(StoreError, match="not an llcps store"):
        Store.open(url, create=True)


class PostgresBranchMachine(BranchMachine):
    def make_store(self) -> Store:
        self.dir = None  # type: ignore[assignment]
        return Store.open(fresh_postgres_url(), create=True)

    def teardown(self) -> None:
        self.store.close()


def test_branch_visibility_on_postgres() -> None:
    run_machine(PostgresBranchMachine, max_examples=10)
