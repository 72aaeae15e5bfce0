"""The store on PostgreSQL. Runs when LLCPS_TEST_POSTGRES_URL names a database it may
create schemas in, e.g. ``postgresql+psycopg://postgres@/llcps_test?host=/tmp&port=5432``."""

from __future__ import annotations

import os
import uuid
from typing import Iterator

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import create_engine, make_url, text
from store_writer import sample_trial
from test_store_branches import BranchMachine, run_machine

from llcps.errors import StoreError
from llcps.store import Store
from llcps.store.schema import VERSION_TABLE, Base

URL = os.environ.get("LLCPS_TEST_POSTGRES_URL")
pytestmark = pytest.mark.skipif(not URL, reason="set LLCPS_TEST_POSTGRES_URL to test on PostgreSQL")


def _fresh_schema_url() -> str:
    """A URL whose search_path is a new, empty schema: a fresh database for one test."""
    schema = f"t_{uuid.uuid4().hex[:12]}"
    engine = create_engine(URL)  # type: ignore[arg-type]
    with engine.begin() as conn:
        conn.execute(text(f"CREATE SCHEMA {schema}"))
    engine.dispose()
    url = make_url(URL).update_query_dict({"options": f"-csearch_path={schema}"})  # type: ignore[arg-type]
    return url.render_as_string(hide_password=False)


@pytest.fixture
def pg_store() -> Iterator[Store]:
    with Store.open(_fresh_schema_url(), create=True) as store:
        yield store


def test_schema_and_round_trip(pg_store: Store) -> None:
    with pg_store.engine.connect() as conn:
        context = MigrationContext.configure(conn, opts={"version_table": VERSION_TABLE, "compare_type": True})
        assert compare_metadata(context, Base.metadata) == []
    new = sample_trial(3, extra={"k": [1, 2]})
    trial_id = pg_store.add_trial(new)
    got = pg_store.get_trial(trial_id)
    assert (got.spec, got.features, got.outcome, got.extra, got.seed) == (new.spec, new.features, new.outcome, {"k": [1, 2]}, 3)
    assert pg_store.visible_trials("main") == [got]
    assert pg_store.add_trials([sample_trial(i) for i in range(3)]) == [trial_id + 1, trial_id + 2, trial_id + 3]
    snapshot = pg_store.put_snapshot(scene={"a": 1}, state=b"\x00s")
    assert pg_store.put_snapshot(scene={"a": 1}, state=b"\x00s") == snapshot


def test_a_database_with_other_tables_is_refused() -> None:
    url = _fresh_schema_url()
    engine = create_engine(url)
    with engine.begin() as conn:
        conn.execute(text("CREATE TABLE notes (body text)"))
    engine.dispose()
    with pytest.raises(StoreError, match="not an llcps store"):
        Store.open(url, create=True)


class PostgresBranchMachine(BranchMachine):
    def make_store(self) -> Store:
        self.dir = None  # type: ignore[assignment]
        return Store.open(_fresh_schema_url(), create=True)

    def teardown(self) -> None:
        self.store.close()


def test_branch_visibility_on_postgres() -> None:
    run_machine(PostgresBranchMachine, max_examples=10)
