"""The experience store: every trial the robot executes, on git-like branches.

:class:`Store` opens a database (checking that it is an llcps store at a schema
revision this llcps knows), upgrades it, and owns its engine and the read and write
transactions every query runs in (:mod:`llcps.store.transactions`). The queries live
beside it, one module per idea, as the classes it is made of:

* :mod:`llcps.store.branches`: branches, the current branch, forks, delete and reset;
* :mod:`llcps.store.runs`: runs and their episodes;
* :mod:`llcps.store.snapshots`: the physics states trials start from;
* :mod:`llcps.store.training_set`: trials and their symbolic changes;
* :mod:`llcps.store.operator_log`: learned operators and operator executions;
* :mod:`llcps.store.model_artifacts`: fitted world models;
* :mod:`llcps.store.maintenance`: status and compaction.

Every byte read back is untrusted: a row that does not decode is a
:class:`~llcps.errors.StoreError` naming the row, never a crash.
"""

from __future__ import annotations

import sqlite3
import tempfile
from functools import lru_cache
from pathlib import Path
from typing import Callable

from sqlalchemy import inspect, select, update
from sqlalchemy.exc import SQLAlchemyError

from llcps.errors import StoreError
from llcps.store import backends, migrations
from llcps.store.branches import CURRENT_BRANCH_KEY, MAIN_BRANCH, BranchQueries
from llcps.store.maintenance import MaintenanceQueries
from llcps.store.model_artifacts import ModelArtifactQueries
from llcps.store.operator_log import OperatorQueries
from llcps.store.runs import RunQueries
from llcps.store.snapshots import SnapshotQueries
from llcps.store.tables import Branch
from llcps.store.training_set import TrialQueries
from llcps.store.transactions import db_error, utc_now


class Store(MaintenanceQueries, TrialQueries, OperatorQueries, ModelArtifactQueries, RunQueries, SnapshotQueries, BranchQueries):
    """A handle on one experience database. Create it with :meth:`Store.open`.

    Safe to share between threads; after ``os.fork`` open a new one in the child.
    """

    @classmethod
    def open(cls, url_or_path: str, *, create: bool = False, allow_outdated: bool = False) -> Store:
        """Open (or with ``create`` make) an llcps store.

        Args:
            url_or_path: a file path (SQLite) or an SQLAlchemy URL.
            create: make a new store when the file is absent (or the database is
                empty); an existing file that is not an llcps store is refused.
            allow_outdated: accept a store at an older schema revision (for
                ``db status`` and ``db upgrade``); otherwise it is refused with a hint.

        Raises:
            StoreError: the location cannot hold an llcps store, or its schema is
                newer than this llcps or (without ``allow_outdated``) older.
        """
        url = backends.resolve_url(url_or_path)
        path = backends.sqlite_path(url)
        copied = False  # made here from the image: its main is dated when the image was
        if path is not None and not backends.check_sqlite_file(path, create=create):
            image = _new_store_image()
            copied = backends.create_sqlite_file(path, image=image) and image is not None
        engine = backends.make_engine(url)
        store = cls(engine, url)
        try:
            store._check_schema(create=create, allow_outdated=allow_outdated)
            if copied:
                store._stamp_main_branch()
        except SQLAlchemyError as exc:
            engine.dispose()
            raise db_error(exc, url) from exc
        except BaseException:
            engine.dispose()
            raise
        return store

    def _check_schema(self, *, create: bool, allow_outdated: bool) -> None:
        # Look with a plain connection first: the SQLite engine's connect hook switches
        # the file to WAL, which would rewrite a foreign file's header.
        file_backed = backends.sqlite_path(self._url) is not None
        probe = backends.make_engine(self._url, pooled=False, plain=True) if file_backed else self._engine
        try:
            with probe.connect() as conn:
                revision = migrations.current_revision(conn)
                tables = inspect(conn).get_table_names() if revision is None else []
        except SQLAlchemyError as exc:
            raise db_error(exc, self._url) from exc
        finally:
            if probe is not self._engine:
                probe.dispose()
        if revision is None:
            if tables:
                raise StoreError(
                    f"{self.url} holds tables but is not an llcps store",
                    hint="choose another --db; the database was left untouched",
                )
            if not create:
                raise StoreError(f"no llcps store at {self.url}", hint="create one with `llcps db init` (or pass --create)")
            self.upgrade()
            return
        head = migrations.head_revision()
        if revision not in migrations.known_revisions():
            raise StoreError(
                f"the database is at schema revision {revision!r}, newer than this llcps knows (head {head!r})",
                hint="upgrade the llcps package to open it; `llcps db upgrade` only moves databases forward",
            )
        if revision != head and not allow_outdated:
            raise StoreError(
                f"the database is at schema revision {revision!r}, older than this llcps needs ({head!r})",
                hint="run `llcps db upgrade` to migrate it",
            )
        # An outdated store opened to be upgraded (or looked at) may lack trial_blocks.
        self._packs_blocks = revision == head

    def _stamp_main_branch(self) -> None:
        """Date ``main`` of a store just made from :func:`_new_store_image` now, as if
        its migrations had run now (they did, earlier in this process)."""
        with self._write() as conn:
            conn.execute(update(Branch).where(Branch.name == MAIN_BRANCH).values(created_at=utc_now()))

    def close(self) -> None:
        """Stop renewing heartbeats and release pooled connections."""
        beats = self.__dict__.get("_run_heartbeats")
        if beats is not None:
            beats.close()
        self._engine.dispose()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Store({self.url!r})"

    @property
    def revision(self) -> str | None:
        """The schema revision recorded in the database."""
        with self._read() as conn:
            return migrations.current_revision(conn)

    @property
    def head(self) -> str:
        """The newest schema revision this llcps knows."""
        return migrations.head_revision()

    def upgrade(self, *, progress: Callable[[str, int, int], None] | None = None) -> tuple[str | None, str]:
        """Migrate the schema to the newest revision, one revision at a time, in one transaction.

        Args:
            progress: called as ``progress(revision, done, total)`` before each revision.

        Returns:
            (revision before, revision after).
        """
        before = self.revision
        head = migrations.head_revision()
        self._packs_blocks = True  # at head once this returns
        if before == head:
            return before, head
        known = migrations.known_revisions()
        pending = known[known.index(before) + 1 :] if before in known else [head]
        file_backed = backends.sqlite_path(self._url) is not None
        # SQLite needs foreign keys off while batch operations rebuild tables.
        engine = backends.make_engine(self._url, foreign_keys=False, pooled=False) if file_backed else self._engine
        try:
            with engine.connect() as conn:
                conn.execution_options(**{backends.WRITE_OPTION: True})
                # The transaction holds the writer lock and Alembic reads the revision
                # inside it, so a concurrent upgrade finds the work done.
                with conn.begin():
                    for done, revision in enumerate(pending):
                        if progress is not None:
                            progress(revision, done, len(pending))
                        migrations.upgrade(conn, revision)
        except SQLAlchemyError as exc:
            raise db_error(exc, self._url) from exc
        finally:
            if engine is not self._engine:
                engine.dispose()
        if file_backed:  # pooled connections may cache the old schema
            self._engine.dispose()
        return before, head

    def init(self) -> str:
        """Bring the store to the newest schema and make sure a current branch exists.

        Returns:
            The schema revision after initialisation.
        """
        _, head = self.upgrade()
        with self._write() as conn:
            current = self._get_setting(conn, CURRENT_BRANCH_KEY)
            names = set(conn.scalars(select(Branch.name)))
            if current not in names:
                self._set_setting(conn, CURRENT_BRANCH_KEY, MAIN_BRANCH if MAIN_BRANCH in names else sorted(names)[0])
        return head


@lru_cache(maxsize=1)
def _new_store_image() -> bytes | None:
    """A new SQLite store at this llcps's head revision, as bytes, migrated once per process
    (None where no temporary directory can hold it: each new store is then migrated).

    Running the migrations takes about 0.1 s; copying their result takes a millisecond.
    A process that makes many stores (an experiment's worker makes one per task) makes
    each one from this image.
    """
    try:
        with tempfile.TemporaryDirectory(prefix="llcps-schema-") as tmp:
            path = Path(tmp) / "new.db"
            backends.create_sqlite_file(path)
            url = backends.resolve_url(str(path))
            store = Store(backends.make_engine(url), url)
            try:
                store.upgrade()
            finally:
                store.close()
            return backends.sqlite_image(path)
    except (OSError, StoreError, sqlite3.Error):
        return None
