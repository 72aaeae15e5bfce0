"""Looking after a store: what ``llcps db status`` reports, and giving back the space
of removed rows (``llcps db compact``)."""

from __future__ import annotations

import os

from sqlalchemy import func, inspect, select, text

from llcps.errors import StoreError
from llcps.store import backends, migrations, visibility
from llcps.store import writers
from llcps.store.records import CompactResult, StoreStatus
from llcps.store.tables import Base, Trial, TrialChangeRow
from llcps.store.training_set import TrialQueries


class MaintenanceQueries(TrialQueries):
    """Status (schema, branches, trial counts) and compaction."""

    def status(self, branch: str | None = None) -> StoreStatus:
        """What ``llcps db status`` shows: schema, branches and trial counts."""
        head = migrations.head_revision()
        with self._read() as conn:
            revision = migrations.current_revision(conn)
            current = self._name(conn, None)
            name = current if branch is None else branch
            # Only tables of the first revision are read, so an outdated store can report.
            rows = self._branches(conn)
            chain = self._chain(conn, name, rows)
            by_source = dict(
                conn.execute(
                    select(Trial.source, func.count()).where(visibility.clause(chain, Trial.branch_id, Trial.id)).group_by(Trial.source)
                ).all()
            )
            return StoreStatus(
                url=self.url,
                revision=revision,
                head=head,
                up_to_date=revision == head,
                current_branch=current,
                branch=name,
                branches=len(rows),
                trials_total=conn.scalar(select(func.count()).select_from(Trial)) or 0,
                visible_trials=sum(by_source.values()),
                visible_by_source=by_source,
                changes=self.change_counts() if inspect(conn).has_table(TrialChangeRow.__tablename__) else None,
                writers=tuple(writers.writers(conn)) if revision == head else (),
            )

    def _size(self) -> int | None:
        """Bytes the store takes on disk: a SQLite file with its write-ahead log, or a
        PostgreSQL database; None in memory."""
        path = backends.sqlite_path(self._url)
        if path is not None:
            return sum(os.path.getsize(p) for p in (str(path), f"{path}-wal") if os.path.exists(p))
        if self._engine.dialect.name == "postgresql":
            with self._read() as conn:
                return int(conn.scalar(text("SELECT pg_database_size(current_database())")) or 0)
        return None

    def compact(self) -> CompactResult:
        """Give the space of removed rows back: SQLite's ``VACUUM`` rewrites the file
        (it needs as much free disk again while it runs) and the write-ahead log is
        emptied; PostgreSQL's ``VACUUM`` marks the space for reuse.

        A table rebuilt by a schema revision, a deleted branch or a pruned physics
        cache leaves free pages that SQLite keeps in the file until then. Nothing
        stored changes.

        Raises:
            StoreError: the database refused (another process holding it, for one).
        """
        before = self._size()
        raw = self._engine.raw_connection()
        driver = raw.driver_connection
        postgres = self._engine.dialect.name == "postgresql"
        try:
            if postgres:
                driver.autocommit = True  # VACUUM runs outside a transaction
            cursor = driver.cursor()
            try:
                if postgres:  # the store's own tables, not every table of the database
                    quote = self._engine.dialect.identifier_preparer.quote
                    cursor.execute("VACUUM " + ", ".join(quote(name) for name in sorted(Base.metadata.tables)))
                else:
                    cursor.execute("VACUUM")
                if backends.sqlite_path(self._url) is not None:
                    cursor.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            finally:
                cursor.close()
        except self._engine.dialect.loaded_dbapi.Error as exc:
            raise StoreError(
                f"cannot compact {self.url}: {exc}",
                hint="another process may be using the store; try again when it is done",
            ) from None
        finally:
            if postgres:
                driver.autocommit = False
            raw.close()
        return CompactResult(url=self.url, before=before, after=self._size())
