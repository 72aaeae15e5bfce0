"""The experience store: every trial the robot executes, on git-like branches.

Which rows a branch sees is the algebra of :mod:`llcps.store.visibility`; this
module maps it onto queries. Every write is one transaction that holds the
store's writer lock (SQLite: ``BEGIN IMMEDIATE``; PostgreSQL: an advisory lock),
so trial ids commit in increasing order, as that algebra needs.

Every byte read back is untrusted: a row that does not decode is a
:class:`~llcps.errors.StoreError` naming the row, never a crash.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from contextlib import contextmanager
from datetime import datetime, timezone
from typing import Any, Callable, Iterator, Mapping, Sequence

from sqlalchemy import (
    URL,
    ColumnElement,
    Connection,
    Engine,
    and_,
    delete,
    func,
    insert,
    inspect,
    or_,
    select,
    text,
    update,
)
from sqlalchemy.exc import IntegrityError, SQLAlchemyError

from llcps.domain import TrialChange, TrialRecord, check_id
from llcps.provenance import Provenance
from llcps.provenance import current as provenance_of_process
from llcps.errors import LlcpsError, StoreError
from llcps.store import backends
from llcps.store import migrations, visibility
from llcps.store.records import (
    BranchChange,
    BranchInfo,
    CompactResult,
    EpisodeRecord,
    ExecutionCounts,
    ModelArtifact,
    OperatorRecord,
    RunRecord,
    SnapshotRecord,
    StoreStatus,
)
from llcps.store.tables import (
    MAX_BRANCH_NAME,
    Base,
    Branch,
    Episode,
    Operator,
    OperatorExecution,
    Run,
    Setting,
    Snapshot,
    Trial,
    TrialChangeRow,
    WorldModel,
)
from llcps.store.visibility import Link
from llcps.store.trial_changes import CHANGE_COLUMNS, UNKNOWN, ChangeDecoder, change_row
from llcps.store.trials import TRIAL_COLUMNS, TrialDecoder, gc_paused, iso_timestamp, trial_row

#: The root branch every store starts with.
MAIN_BRANCH = "main"

CURRENT_BRANCH_KEY = "current_branch"

#: ``at=`` / ``to=`` value meaning "the last visible pretraining trial".
PRETRAIN = "pretrain"

RESET_TARGETS: tuple[str, ...] = (PRETRAIN, "empty")

#: Largest stored physics state read back (bytes, compressed); larger rows are refused unread.
MAX_SNAPSHOT_BYTES = 8 * 2**20

_CHANGED = "the row was changed outside llcps; restore the database from a copy (or delete the row)"

_WHITESPACE = re.compile(r"\s")
_INSERT_TRIAL = insert(Trial)
_INSERT_TRIALS = insert(Trial).returning(Trial.id, sort_by_parameter_order=True)


def validate_branch_name(name: str) -> str:
    """Reject names that would be ambiguous on a command line or in a path."""
    problem = None
    if not name or not name.strip():
        problem = "is empty"
    elif _WHITESPACE.search(name):
        problem = "contains whitespace"
    elif "/" in name:
        problem = "contains '/'"
    elif ".." in name:
        problem = "contains '..'"
    elif len(name) > MAX_BRANCH_NAME:
        problem = f"is longer than {MAX_BRANCH_NAME} characters"
    elif name.startswith("-"):
        problem = "starts with '-'"
    elif not name.isprintable():
        problem = "contains control characters"
    if problem:
        raise LlcpsError(f"invalid branch name {name[:40]!r}: it {problem}", hint="use letters, digits, '-', '_' or '.'")
    return name


def _now() -> datetime:
    return datetime.now(timezone.utc).replace(tzinfo=None)


def _db_error(exc: SQLAlchemyError) -> StoreError:
    detail = str(getattr(exc, "orig", None) or exc).splitlines()[0]
    lowered = detail.lower()
    if "locked" in lowered or "busy" in lowered:
        hint = "another process held the database for longer than the busy timeout; retry when it is done"
    elif "readonly" in lowered or "read-only" in lowered or "permission" in lowered:
        hint = "the database file or its directory is not writable"
    elif "connect" in lowered:
        hint = "check the --db URL and that the database server is running"
    else:
        hint = "check `llcps db status`"
    return StoreError(f"database error: {detail}", hint=hint)


def run_provenance_values(provenance: Provenance) -> dict[str, Any]:
    """The ``runs`` columns that hold a run's provenance."""
    values = provenance.as_json()
    values["llcps_version"] = values["llcps_version"] or "unknown"  # the column predates provenance and is NOT NULL
    return values


def run_record(row: Any) -> RunRecord:
    """A ``runs`` row as a :class:`RunRecord` (the one place runs are read)."""
    return RunRecord(
        id=row.id,
        command=row.command,
        seed=row.seed,
        config=_mapping(row.config, f"run {row.id}", "config"),
        branch=row.branch,
        status=row.status,
        started_at=iso_timestamp(row.started_at) or "",
        finished_at=iso_timestamp(row.finished_at),
        provenance=Provenance(
            llcps_version=row.llcps_version,
            git_commit=row.git_commit,
            git_dirty=None if row.git_dirty is None else bool(row.git_dirty),
            python_version=row.python_version,
            pybullet_version=row.pybullet_version,
            torch_version=row.torch_version,
            sklearn_version=row.sklearn_version,
            numpy_version=row.numpy_version,
            host=row.host,
            cpu_count=row.cpu_count,
        ),
    )


def _episode_record(row: Any) -> EpisodeRecord:
    """An ``episodes`` row joined with its branch name, as an :class:`EpisodeRecord`."""
    return EpisodeRecord(
        id=row.id,
        run_id=row.run_id,
        branch=row.branch_name,
        scenario=row.scenario,
        condition=row.condition,
        model=row.model,
        measure=row.measure,
        seed=row.seed,
        status=row.status,
        summary=_mapping(row.summary, f"episode {row.id}", "summary"),
        started_at=iso_timestamp(row.started_at) or "",
        finished_at=iso_timestamp(row.finished_at),
    )


def _context_atoms(row_id: int, context: Any) -> tuple[tuple[str, ...], ...]:
    """A stored execution context, checked: a list of atoms, each a list of 2 to 4 strings."""
    if isinstance(context, str):
        try:
            context = json.loads(context)
        except ValueError:
            context = None
    if not isinstance(context, list) or not all(
        isinstance(atom, list) and 2 <= len(atom) <= 4 and all(isinstance(t, str) for t in atom) for atom in context
    ):
        raise StoreError(
            f"operator execution {row_id} has a malformed context",
            hint="the row was not written by llcps; delete it or restore the store from a backup",
        )
    return tuple(sorted(tuple(atom) for atom in context))


def _trial_id(record: TrialRecord) -> int:
    return record.id  # type: ignore[return-value]


def _change_id(change: TrialChange) -> int:
    return change.trial_id  # type: ignore[return-value]


class Store:
    """A handle on one experience database. Create it with :meth:`Store.open`.

    Safe to share between threads; after ``os.fork`` open a new one in the child.
    """

    def __init__(self, engine: Engine, url: URL) -> None:
        self._engine = engine
        self._url = url
        self._branch_ids: dict[str, int] = {}

    # ------------------------------------------------------------------ opening

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
        if path is not None and not backends.check_sqlite_file(path, create=create):
            backends.create_sqlite_file(path)
        engine = backends.make_engine(url)
        store = cls(engine, url)
        try:
            store._check_schema(create=create, allow_outdated=allow_outdated)
        except SQLAlchemyError as exc:
            engine.dispose()
            raise _db_error(exc) from exc
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
            raise _db_error(exc) from exc
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

    def close(self) -> None:
        """Release pooled connections."""
        self._engine.dispose()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Store({self.url!r})"

    @property
    def url(self) -> str:
        """The database URL, password hidden."""
        return self._url.render_as_string(hide_password=True)

    @property
    def engine(self) -> Engine:
        """The SQLAlchemy engine, for tools that need raw access (benchmarks, exports)."""
        return self._engine

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
            raise _db_error(exc) from exc
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

    # --------------------------------------------------------------- sessions

    @contextmanager
    def _read(self) -> Iterator[Connection]:
        try:
            with self._engine.connect() as conn:
                yield conn
        except SQLAlchemyError as exc:
            raise _db_error(exc) from exc
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:  # a JSON column's text, decoded as rows are read
            raise StoreError(f"a stored JSON value is malformed ({exc})", hint=_CHANGED) from None

    @contextmanager
    def _write(self) -> Iterator[Connection]:
        """One transaction that takes the write lock up front (SQLite: BEGIN IMMEDIATE)."""
        try:
            with self._engine.connect() as conn:
                conn.execution_options(**{backends.WRITE_OPTION: True})
                with conn.begin():
                    yield conn
        except SQLAlchemyError as exc:
            raise _db_error(exc) from exc

    @staticmethod
    def _get_setting(conn: Connection, key: str) -> str | None:
        return conn.scalar(select(Setting.value).where(Setting.key == key))

    @staticmethod
    def _set_setting(conn: Connection, key: str, value: str) -> None:
        if conn.execute(update(Setting).where(Setting.key == key).values(value=value)).rowcount == 0:
            conn.execute(insert(Setting).values(key=key, value=value))

    # --------------------------------------------------------------- branches

    def _branches(self, conn: Connection) -> list[Any]:
        rows = list(conn.execute(select(Branch.id, Branch.name, Branch.parent_id, Branch.fork_point, Branch.created_at).order_by(Branch.id)))
        for r in rows:
            if not isinstance(r.name, str) or not isinstance(r.fork_point, int) or not isinstance(r.parent_id, int | None):
                raise StoreError(f"branch row {r.id} is malformed (name {r.name!r}, parent {r.parent_id!r}, fork point {r.fork_point!r})", hint=_CHANGED)
        return rows

    def _chain(self, conn: Connection, name: str, rows: list[Any] | None = None) -> list[Link]:
        return visibility.Tree(self._branches(conn) if rows is None else rows).chain(name)

    def _name(self, conn: Connection, name: str | None) -> str:
        if name is not None:
            return name
        return self._get_setting(conn, CURRENT_BRANCH_KEY) or MAIN_BRANCH

    def current_branch(self) -> str:
        """The branch commands use when none is named."""
        with self._read() as conn:
            return self._name(conn, None)

    def checkout(self, name: str) -> BranchInfo:
        """Make ``name`` the current branch."""
        with self._write() as conn:
            self._chain(conn, name)
            self._set_setting(conn, CURRENT_BRANCH_KEY, name)
            return self._info(conn, name)

    def resolve_branch(self, name: str | None) -> BranchInfo:
        """The named branch, or the current one for None.

        Raises:
            UnknownNameError: no such branch (the message lists the known ones).
        """
        with self._read() as conn:
            return self._info(conn, self._name(conn, name))

    def _count(self, conn: Connection, chain: Sequence[Link], *extra: ColumnElement[bool]) -> int:
        return conn.scalar(select(func.count()).select_from(Trial).where(visibility.clause(chain, Trial.branch_id, Trial.id), *extra)) or 0

    def _max_visible(self, conn: Connection, chain: Sequence[Link], *extra: ColumnElement[bool]) -> int:
        best = 0
        for link in chain:  # one index range per link beats one OR scan
            stmt = select(func.max(Trial.id)).where(Trial.branch_id == link.branch_id, *extra)
            if link.limit is not None:
                stmt = stmt.where(Trial.id <= link.limit)
            best = max(best, conn.scalar(stmt) or 0)
        return best

    def _info(
        self,
        conn: Connection,
        name: str,
        tree: visibility.Tree | None = None,
        current: str | None = None,
        count: Callable[[Link], int] | None = None,
    ) -> BranchInfo:
        """A branch's row and trial counts; ``count`` counts one link's trials (default: a query each)."""
        tree = visibility.Tree(self._branches(conn)) if tree is None else tree
        count = (lambda link: self._count(conn, [link])) if count is None else count
        chain = tree.chain(name)
        row = tree.by_name[name]
        parent = tree.by_id[row.parent_id].name if row.parent_id is not None else None
        current = self._name(conn, None) if current is None else current
        return BranchInfo(
            id=row.id,
            name=name,
            parent=parent,
            fork_point=row.fork_point,
            own_trials=count(chain[0]),
            visible_trials=sum(count(link) for link in chain),  # a chain's branches are distinct
            created_at=iso_timestamp(row.created_at) or "",
            is_current=name == current,
        )

    def branch_names(self) -> list[str]:
        """Every branch's name, oldest first: what ``list_branches`` gives without counting trials."""
        with self._read() as conn:
            return [r.name for r in self._branches(conn)]

    def list_branches(self) -> list[BranchInfo]:
        """Every branch with its parent, fork point and trial counts, oldest first."""
        with self._read() as conn:
            tree = visibility.Tree(self._branches(conn))
            current = self._name(conn, None)
            own = {b: int(n) for b, n in conn.execute(select(Trial.branch_id, func.count()).group_by(Trial.branch_id))}
            upto: dict[tuple[int, int], int] = {}  # siblings share their parent's count up to the fork point

            def count(link: Link) -> int:
                if link.limit is None:
                    return own.get(link.branch_id, 0)
                key = (link.branch_id, link.limit)
                if key not in upto:
                    upto[key] = self._count(conn, [link])
                return upto[key]

            return [self._info(conn, r.name, tree, current, count) for r in tree.rows]

    def create_branch(self, name: str, *, from_branch: str | None = None, at: int | str | None = None) -> BranchInfo:
        """Fork a new branch.

        Args:
            from_branch: the parent (default: the current branch).
            at: the fork point: a trial id visible on the parent, ``"pretrain"`` for
                the parent's last visible pretraining trial (0 if it has none), or
                None for its latest visible trial.
        """
        validate_branch_name(name)
        with self._write() as conn:
            rows = self._branches(conn)
            if any(r.name == name for r in rows):
                raise StoreError(f"branch {name!r} already exists", hint="pick another name or `llcps db checkout` it")
            parent_name = self._name(conn, from_branch)
            chain = self._chain(conn, parent_name, rows)
            fork = self._fork_point(conn, chain, at)
            conn.execute(insert(Branch).values(name=name, parent_id=chain[0].branch_id, fork_point=fork, created_at=_now()))
            return self._info(conn, name)

    def _fork_point(self, conn: Connection, chain: Sequence[Link], at: int | str | None) -> int:
        if at is None:
            return self._max_visible(conn, chain)
        if isinstance(at, str):
            if at == PRETRAIN:
                return self._max_visible(conn, chain, Trial.source == PRETRAIN)
            if not at.strip().isdigit():
                raise LlcpsError(f"invalid fork point {at!r}", hint="pass a trial id or 'pretrain'")
            at = int(at)
        check_id(at, "fork point")
        if at == 0:
            return 0
        if at < 0 or self._count(conn, chain, Trial.id == at) == 0:
            raise LlcpsError(
                f"trial {at} is not visible on branch {chain[0].name!r}",
                hint=f"its visible trials end at id {self._max_visible(conn, chain)}; see `llcps inspect trials`",
            )
        return int(at)

    def _removal(self, conn: Connection, name: str, action: str, to: str | None) -> tuple[BranchChange, dict[str, Any]]:
        """Count what deleting/resetting ``name`` removes; refuse if children see any of it."""
        rows = self._branches(conn)
        chain = self._chain(conn, name, rows)
        bid = chain[0].branch_id
        keep = 0
        if to == PRETRAIN:
            keep = self._max_visible(conn, chain, Trial.source == PRETRAIN)
            trial_clause = and_(Trial.branch_id == bid, Trial.id > keep)
            op_clause = and_(Operator.branch_id == bid, Operator.watermark > keep)
            execution_clause = and_(OperatorExecution.branch_id == bid, OperatorExecution.watermark > keep)
            model_clause = and_(WorldModel.branch_id == bid, WorldModel.watermark > keep)
        else:  # everything the branch owns, whatever its watermark
            trial_clause = Trial.branch_id == bid
            op_clause = Operator.branch_id == bid
            execution_clause = OperatorExecution.branch_id == bid
            model_clause = WorldModel.branch_id == bid
        if to != PRETRAIN:
            episode_clause = Episode.branch_id == bid
        else:
            kept_episodes = select(Trial.episode_id).where(Trial.branch_id == bid, Trial.id <= keep, Trial.episode_id.is_not(None))
            episode_clause = and_(Episode.branch_id == bid, Episode.id.not_in(kept_episodes))
        children = [r for r in rows if r.parent_id == bid]
        if action == "delete" and children:
            raise StoreError(
                f"branch {name!r} has child branches: {', '.join(r.name for r in children)}",
                hint="delete them first",
            )
        first_removed = min(
            (
                v
                for v in (
                    conn.scalar(select(func.min(Trial.id)).where(trial_clause)),
                    conn.scalar(select(func.min(Operator.watermark)).where(op_clause)),
                    conn.scalar(select(func.min(OperatorExecution.watermark)).where(execution_clause)),
                    conn.scalar(select(func.min(WorldModel.watermark)).where(model_clause)),
                )
                if v is not None
            ),
            default=None,
        )
        blocking = visibility.blocking_children(children, first_removed)
        if blocking:
            raise StoreError(
                f"branch(es) {', '.join(blocking)} forked from {name!r} after trial {first_removed - 1}",
                hint="they still see what a reset would remove; delete or reset them first",
            )
        change = BranchChange(
            branch=name,
            action=action,
            to=to,
            dry_run=True,
            trials=conn.scalar(select(func.count()).select_from(Trial).where(trial_clause)) or 0,
            operators=conn.scalar(select(func.count()).select_from(Operator).where(op_clause)) or 0,
            world_models=conn.scalar(select(func.count()).select_from(WorldModel).where(model_clause)) or 0,
            episodes=conn.scalar(select(func.count()).select_from(Episode).where(episode_clause)) or 0,
            kept_until=keep if action == "reset" else None,
        )
        clauses = {"trial": trial_clause, "operator": op_clause, "execution": execution_clause, "model": model_clause, "episode": episode_clause, "branch_id": bid}
        return change, clauses

    def _apply_removal(self, conn: Connection, clauses: Mapping[str, Any]) -> None:
        episode_ids = select(Episode.id).where(clauses["episode"])
        conn.execute(delete(Operator).where(or_(clauses["operator"], Operator.episode_id.in_(episode_ids))))
        trial_ids = select(Trial.id).where(clauses["trial"])
        conn.execute(
            delete(OperatorExecution).where(
                or_(
                    clauses["execution"],
                    OperatorExecution.episode_id.in_(episode_ids),
                    OperatorExecution.trial_id.in_(trial_ids),
                )
            )
        )
        conn.execute(delete(WorldModel).where(clauses["model"]))
        conn.execute(delete(TrialChangeRow).where(TrialChangeRow.trial_id.in_(trial_ids)))
        conn.execute(delete(Trial).where(clauses["trial"]))
        conn.execute(delete(Episode).where(clauses["episode"]))

    def delete_branch(self, name: str, *, dry_run: bool) -> BranchChange:
        """Remove a branch and everything it owns.

        Refused for ``main``, the current branch and branches with children.
        With ``dry_run`` only counts what would go.
        """
        with self._write() as conn:
            if name == MAIN_BRANCH:
                raise StoreError("the main branch cannot be deleted", hint="`llcps db reset --to empty` clears it")
            self._chain(conn, name)
            if name == self._name(conn, None):
                raise StoreError(f"branch {name!r} is checked out", hint="`llcps db checkout main` first")
            change, clauses = self._removal(conn, name, "delete", None)
            if dry_run:
                return change
            self._apply_removal(conn, clauses)
            conn.execute(delete(Branch).where(Branch.id == clauses["branch_id"]))
        self._branch_ids.pop(name, None)
        return _applied(change)

    def reset_branch(self, name: str | None, *, to: str = PRETRAIN, dry_run: bool) -> BranchChange:
        """Drop a branch's own experience after a point.

        Args:
            name: the branch (None: the current one).
            to: ``"pretrain"`` keeps its own trials up to the last visible
                pretraining trial (and operators/models with a watermark up to it);
                ``"empty"`` removes all it owns.
            dry_run: only count what would go.
        """
        if to not in RESET_TARGETS:
            raise LlcpsError(f"unknown reset target {to!r}", hint=f"use one of: {', '.join(RESET_TARGETS)}")
        with self._write() as conn:
            name = self._name(conn, name)
            change, clauses = self._removal(conn, name, "reset", to)
            if not dry_run:
                self._apply_removal(conn, clauses)
        return change if dry_run else _applied(change)

    # ------------------------------------------------------------- provenance

    def start_run(
        self,
        *,
        command: str,
        seed: int | None,
        config: Mapping[str, Any],
        branch: str,
        provenance: Provenance | None = None,
    ) -> int:
        """Record the start of a CLI invocation or experiment sequence.

        Args:
            provenance: where the run runs (default: this process, :func:`llcps.provenance.current`).
        """
        env = provenance_of_process() if provenance is None else provenance
        with self._write() as conn:
            self._chain(conn, branch)
            return conn.execute(
                insert(Run).values(
                    command=command,
                    seed=seed,
                    config=dict(config),
                    branch=branch,
                    status="running",
                    started_at=_now(),
                    **run_provenance_values(env),
                )
            ).inserted_primary_key[0]

    def finish_run(self, run_id: int, *, status: str) -> None:
        """Record how a run ended (e.g. ``ok``, ``failed``, ``interrupted``)."""
        with self._write() as conn:
            if conn.execute(update(Run).where(Run.id == run_id).values(status=status, finished_at=_now())).rowcount == 0:
                raise LlcpsError(f"unknown run {run_id}", hint="see `llcps inspect runs`")

    def start_episode(
        self,
        *,
        run_id: int | None,
        branch: str,
        scenario: str,
        condition: str,
        model: str | None,
        measure: str | None,
        seed: int | None,
    ) -> int:
        """Record the start of one scenario solve."""
        with self._write() as conn:
            chain = self._chain(conn, branch)
            return conn.execute(
                insert(Episode).values(
                    run_id=run_id,
                    branch_id=chain[0].branch_id,
                    scenario=scenario,
                    condition=condition,
                    model=model,
                    measure=measure,
                    seed=seed,
                    status="running",
                    summary={},
                    started_at=_now(),
                )
            ).inserted_primary_key[0]

    def finish_episode(self, episode_id: int, *, status: str, summary: Mapping[str, Any]) -> None:
        """Record an episode's outcome and summary (trial counts, times, learned operator)."""
        with self._write() as conn:
            stmt = update(Episode).where(Episode.id == episode_id).values(status=status, summary=dict(summary), finished_at=_now())
            if conn.execute(stmt).rowcount == 0:
                raise LlcpsError(f"unknown episode {episode_id}", hint="see `llcps inspect runs`")

    def list_runs(
        self, *, branch: str | None = None, limit: int | None = None, ids: Sequence[int] | None = None
    ) -> list[RunRecord]:
        """Runs, newest first (``ids``: only these runs)."""
        stmt = select(Run).order_by(Run.id.desc()).limit(limit)
        if branch is not None:
            stmt = stmt.where(Run.branch == branch)
        if ids is not None:
            stmt = stmt.where(Run.id.in_(list(ids)))
        with self._read() as conn:
            return [run_record(r) for r in conn.execute(stmt)]

    def run_activity(self, run_ids: Sequence[int]) -> dict[int, dict[str, int]]:
        """Per run: its episodes and its trials by source (``{"episodes": 3, "pretrain": 0, ...}``)."""
        ids = list(run_ids)
        out: dict[int, dict[str, int]] = {i: {"episodes": 0, "trials": 0} for i in ids}
        if not ids:
            return out
        with self._read() as conn:
            episodes = conn.execute(
                select(Episode.run_id, func.count()).where(Episode.run_id.in_(ids)).group_by(Episode.run_id)
            ).all()
            trials = conn.execute(
                select(Trial.run_id, Trial.source, func.count()).where(Trial.run_id.in_(ids)).group_by(Trial.run_id, Trial.source)
            ).all()
        for run_id, count in episodes:
            out[run_id]["episodes"] = int(count)
        for run_id, source, count in trials:
            out[run_id][str(source)] = int(count)
            out[run_id]["trials"] += int(count)
        return out

    def get_run(self, run_id: int) -> RunRecord:
        """One run by id."""
        found = self.list_runs(ids=[run_id])
        if not found:
            raise LlcpsError(f"unknown run {run_id}", hint="see `llcps inspect runs` for run ids")
        return found[0]

    def list_episodes(
        self,
        *,
        run_id: int | None = None,
        branch: str | None = None,
        scenario: str | None = None,
        limit: int | None = None,
    ) -> list[EpisodeRecord]:
        """Episodes, newest first; ``branch`` means episodes run on that branch itself."""
        stmt = (
            select(Episode, Branch.name.label("branch_name"))
            .join(Branch, Branch.id == Episode.branch_id)
            .order_by(Episode.id.desc())
            .limit(limit)
        )
        if run_id is not None:
            stmt = stmt.where(Episode.run_id == run_id)
        if branch is not None:
            stmt = stmt.where(Branch.name == branch)
        if scenario is not None:
            stmt = stmt.where(Episode.scenario == scenario)
        with self._read() as conn:
            return [_episode_record(r) for r in conn.execute(stmt)]

    def get_episode(self, episode_id: int) -> EpisodeRecord:
        """One episode by id, on whatever branch it ran."""
        stmt = (
            select(Episode, Branch.name.label("branch_name"))
            .join(Branch, Branch.id == Episode.branch_id)
            .where(Episode.id == episode_id)
        )
        with self._read() as conn:
            row = conn.execute(stmt).first()
        if row is None:
            raise LlcpsError(f"unknown episode {episode_id}", hint="see `llcps inspect episodes` for episode ids")
        return _episode_record(row)

    # -------------------------------------------------------------- snapshots

    @staticmethod
    def snapshot_hash(scene: Mapping[str, Any], state: bytes) -> str:
        """Content hash of a snapshot: canonical scene JSON, a NUL, the state bytes."""
        digest = hashlib.sha256(json.dumps(scene, sort_keys=True, separators=(",", ":")).encode())
        digest.update(b"\x00")
        digest.update(state)
        return digest.hexdigest()

    def put_snapshot(self, *, scene: Mapping[str, Any], state: bytes) -> int:
        """Store a physics state once; the same scene and bytes give the same id."""
        sha = self.snapshot_hash(scene, state)
        found = self._snapshot_id(sha)
        if found is not None:
            return found
        try:
            with self._engine.connect() as conn:
                conn.execution_options(**{backends.WRITE_OPTION: True})
                with conn.begin():
                    return conn.execute(
                        insert(Snapshot).values(sha256=sha, scene=dict(scene), state=bytes(state), created_at=_now())
                    ).inserted_primary_key[0]
        except IntegrityError:  # another writer stored the same content first
            found = self._snapshot_id(sha)
            if found is None:
                raise
            return found
        except SQLAlchemyError as exc:
            raise _db_error(exc) from exc

    def _snapshot_id(self, sha: str) -> int | None:
        with self._read() as conn:
            return conn.scalar(select(Snapshot.id).where(Snapshot.sha256 == sha))

    def get_snapshot(self, snapshot_id: int) -> SnapshotRecord:
        """A stored physics state by id, after checking its size and its content hash.

        Raises:
            StoreError: the row is larger than :data:`MAX_SNAPSHOT_BYTES`, its scene is
                not a JSON object, or scene and state no longer match the stored hash.
        """
        check_id(snapshot_id, "snapshot id")
        with self._read() as conn:
            size = conn.execute(select(func.length(Snapshot.state)).where(Snapshot.id == snapshot_id)).first()
            if size is None:
                raise LlcpsError(f"unknown snapshot {snapshot_id}", hint="snapshot ids come from a trial's snapshot_id")
            if size[0] is None or size[0] > MAX_SNAPSHOT_BYTES:
                raise StoreError(f"snapshot {snapshot_id} holds {size[0]} bytes, more than the {MAX_SNAPSHOT_BYTES:,} a physics state may", hint=_CHANGED)
            row = conn.execute(select(Snapshot.id, Snapshot.scene, Snapshot.state, Snapshot.sha256).where(Snapshot.id == snapshot_id)).first()
        if row is None:
            raise LlcpsError(f"unknown snapshot {snapshot_id}", hint="snapshot ids come from a trial's snapshot_id")
        if not isinstance(row.scene, dict) or not isinstance(row.state, (bytes, bytearray, memoryview)):
            raise StoreError(f"snapshot {snapshot_id} is malformed: its scene is not a JSON object", hint=_CHANGED)
        state = bytes(row.state)
        if not isinstance(row.sha256, str) or self.snapshot_hash(row.scene, state) != row.sha256:
            raise StoreError(f"snapshot {snapshot_id} does not match its content hash: it was changed after it was stored", hint=_CHANGED)
        return SnapshotRecord(id=row.id, scene=row.scene, state=state, sha256=row.sha256)

    # ----------------------------------------------------------------- trials

    def _branch_id(self, conn: Connection, name: str) -> int:
        bid = self._branch_ids.get(name)
        if bid is None:
            bid = self._chain(conn, name)[0].branch_id
            self._branch_ids[name] = bid
        return bid

    def add_trial(self, trial: TrialRecord, *, change: TrialChange | None = None) -> int:
        """Write one trial (and its symbolic change); committed (durable) when this returns its id."""
        return self.add_trials([trial], changes=None if change is None else [change])[0]

    def add_trials(
        self, trials: Sequence[TrialRecord], *, changes: Sequence[TrialChange | None] | None = None
    ) -> list[int]:
        """Write several trials in one transaction; ids in input order.

        Args:
            changes: each trial's symbolic change, in the same order (None: a trial
                without one); written in the same transaction as the trials.
        """
        if not trials:
            return []
        if changes is not None and len(changes) != len(trials):
            raise LlcpsError(f"{len(trials)} trial(s) but {len(changes)} change(s)", hint="pass one change per trial, or None")
        now = _now()
        try:
            with self._write() as conn:
                rows = [trial_row(t, branch_id=self._branch_id(conn, t.branch), created_at=now) for t in trials]
                if len(rows) == 1:
                    ids = [conn.execute(_INSERT_TRIAL, rows[0]).inserted_primary_key[0]]
                else:
                    ids = list(conn.execute(_INSERT_TRIALS, rows).scalars())
                if changes is not None:
                    self._insert_changes(conn, [(i, c) for i, c in zip(ids, changes) if c is not None])
                return ids
        except StoreError as exc:
            if "FOREIGN KEY" in exc.message.upper() or "foreign key" in exc.message:
                stale = {t.branch for t in trials}
                self._branch_ids.clear()
                raise StoreError(
                    f"a trial refers to something that does not exist (branch {', '.join(sorted(stale))}, run, episode or snapshot)",
                    hint="check the ids passed in; `llcps db list` shows the branches",
                ) from exc
            raise

    def get_trial(self, trial_id: int) -> TrialRecord:
        """One trial by id, on whatever branch owns it."""
        check_id(trial_id, "trial id")
        with self._read() as conn:
            names = {r.id: r.name for r in self._branches(conn)}
            row = conn.execute(select(*TRIAL_COLUMNS).where(Trial.id == trial_id)).first()
        if row is None:
            raise LlcpsError(f"unknown trial {trial_id}", hint="see `llcps inspect trials` for trial ids")
        return TrialDecoder(names).decode([row])[0]

    def _trial_filters(
        self,
        source: str | None,
        scenario: str | None,
        solved: bool | None,
        after_id: int | None,
        episode: int | None = None,
    ) -> list[ColumnElement[bool]]:
        filters: list[ColumnElement[bool]] = []
        if episode is not None:
            filters.append(Trial.episode_id == episode)
        if source is not None:
            filters.append(Trial.source == source)
        if scenario is not None:
            filters.append(Trial.scenario == scenario)
        if solved is not None:
            filters.append(Trial.solved == solved)
        if after_id is not None:
            filters.append(Trial.id > after_id)
        return filters

    def visible_trials(
        self,
        branch: str | None,
        *,
        source: str | None = None,
        scenario: str | None = None,
        solved: bool | None = None,
        episode: int | None = None,
        limit: int | None = None,
        after_id: int | None = None,
        newest_first: bool = False,
    ) -> list[TrialRecord]:
        """The trials ``branch`` sees (None: the current branch), in id order.

        Args:
            source, scenario, solved, episode: keep only trials with these values.
            after_id: only trials with a larger id (incremental loading).
            limit: at most this many, taken from the start of the order.
            newest_first: descending id order.
        """
        for value, what in ((limit, "limit"), (after_id, "after_id")):
            if value is not None:
                check_id(value, what)
        filters = self._trial_filters(source, scenario, solved, after_id, episode)
        order = Trial.id.desc() if newest_first else Trial.id

        def select_trials(links: Sequence[Link]) -> Any:
            return select(*TRIAL_COLUMNS).where(visibility.clause(links, Trial.branch_id, Trial.id), *filters).order_by(order)

        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            decoder = TrialDecoder({link.branch_id: link.name for link in chain})
            with gc_paused():  # the fetch builds as many containers as the decoding
                records = None
                if limit is None:
                    records = self._read_by_link(
                        conn, chain, lambda link: select_trials([link]), decoder.decode_result, _trial_id, newest_first
                    )
                if records is None:  # one query, sorted by the database
                    records = decoder.decode_result(conn.execute(select_trials(chain).limit(limit)))
                return records

    @staticmethod
    def _read_by_link(
        conn: Connection,
        chain: Sequence[Link],
        select_link: Callable[[Link], Any],
        decode: Callable[[Any], list[Any]],
        position: Callable[[Any], int],
        newest_first: bool = False,
    ) -> list[Any] | None:
        """Visible rows read one chain link at a time, each in id order from the
        (branch, id) index, decoded and joined; None if the links' id ranges overlap.

        One query over the whole chain makes SQLite collect the rows of every link and
        sort them again (a fifth of the query's time for 100,000 trials). The ranges do
        not overlap while ids commit in increasing order (see
        :mod:`llcps.store.visibility`): an ancestor's visible ids end at a fork point
        and a descendant's own trials were written after the fork.

        Args:
            select_link: the ordered query of one link's rows.
            decode: the decoded items of a query's result.
            position: an item's trial id.
        """
        links = chain if newest_first else chain[::-1]
        items: list[Any] = []
        for link in links:
            part = decode(conn.execute(select_link(link)))
            if part and items and (position(part[0]) > position(items[-1])) == newest_first:
                return None
            items += part
        return items

    def count_visible_trials(self, branch: str | None, source: str | None = None) -> int:
        """How many trials ``branch`` sees (optionally of one source)."""
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            return self._count(conn, chain, *self._trial_filters(source, None, None, None))

    # ---------------------------------------------------------- trial changes

    @staticmethod
    def _insert_changes(conn: Connection, changes: Sequence[tuple[int, TrialChange | None]]) -> None:
        if changes:
            conn.execute(insert(TrialChangeRow), [change_row(trial_id, change) for trial_id, change in changes])

    def visible_changes(self, branch: str | None, *, after_id: int | None = None) -> dict[int, TrialChange]:
        """The known symbolic changes of the trials ``branch`` sees, by trial id.

        Visibility follows the trials'. Trials whose change is unknown (or was never
        recovered) are left out.

        Raises:
            LlcpsError: a stored change is malformed.
        """
        filters = [TrialChangeRow.source != UNKNOWN] + ([] if after_id is None else [Trial.id > after_id])

        def select_changes(links: Sequence[Link]) -> Any:
            return (
                select(*CHANGE_COLUMNS)
                .join(Trial, Trial.id == TrialChangeRow.trial_id)
                .where(visibility.clause(links, Trial.branch_id, Trial.id), *filters)
                .order_by(Trial.id)
            )

        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            decoder = ChangeDecoder()
            with gc_paused():
                changes = self._read_by_link(conn, chain, lambda link: select_changes([link]), decoder.decode_result, _change_id)
                if changes is None:  # one query, sorted by the database
                    changes = decoder.decode_result(conn.execute(select_changes(chain)))
                return {c.trial_id: c for c in changes}  # type: ignore[misc]

    def get_change(self, trial_id: int) -> TrialChange | None:
        """One trial's symbolic change; None when it is unknown or not recorded."""
        with self._read() as conn:
            row = conn.execute(select(*CHANGE_COLUMNS).where(TrialChangeRow.trial_id == trial_id)).first()
        return None if row is None else ChangeDecoder().decode(row)

    def count_visible_changes(self, branch: str | None) -> int:
        """How many trials ``branch`` sees have a known change (part of a fitted model's identity)."""
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            stmt = (
                select(func.count())
                .select_from(TrialChangeRow)
                .join(Trial, Trial.id == TrialChangeRow.trial_id)
                .where(visibility.clause(chain, Trial.branch_id, Trial.id), TrialChangeRow.source != UNKNOWN)
            )
            return conn.scalar(stmt) or 0

    def change_counts(self) -> dict[str, int]:
        """Trials of the whole store by how their change is known: ``recorded``,
        ``replayed``, ``unknown``, and ``missing`` (no row: a store not yet backfilled)."""
        with self._read() as conn:
            counts = dict(conn.execute(select(TrialChangeRow.source, func.count()).group_by(TrialChangeRow.source)).all())
            total = conn.scalar(select(func.count()).select_from(Trial)) or 0
        out = {source: int(counts.get(source, 0)) for source in ("recorded", "replayed", UNKNOWN)}
        out["missing"] = total - sum(counts.values())
        return out

    def trials_without_change(self, *, limit: int | None = None) -> list[tuple[int, int | None]]:
        """(trial id, snapshot id) of every trial with no change row, in id order."""
        with self._read() as conn:
            stmt = (
                select(Trial.id, Trial.snapshot_id)
                .outerjoin(TrialChangeRow, TrialChangeRow.trial_id == Trial.id)
                .where(TrialChangeRow.trial_id.is_(None))
                .order_by(Trial.id)
                .limit(limit)
            )
            return [(int(i), None if s is None else int(s)) for i, s in conn.execute(stmt)]

    def put_changes(self, changes: Sequence[tuple[int, TrialChange | None]]) -> None:
        """Record the changes of stored trials that have none yet (None: unknown), in one transaction.

        Raises:
            StoreError: a trial already has a change, or does not exist.
        """
        try:
            with self._write() as conn:
                self._insert_changes(conn, changes)
        except StoreError as exc:
            raise StoreError(exc.message, hint="a change is recorded once per trial; only trials without one are backfilled") from exc

    def max_visible_trial_id(self, branch: str | None) -> int:
        """The largest trial id ``branch`` sees, 0 if none: the watermark of a fit on it."""
        with self._read() as conn:
            return self._max_visible(conn, self._chain(conn, self._name(conn, branch)))

    # -------------------------------------------------------------- operators

    def add_operator(
        self,
        *,
        branch: str,
        name: str,
        pddl: str,
        definition: Mapping[str, Any],
        scenario: str | None,
        episode_id: int | None,
    ) -> int:
        """Persist a learned operator on ``branch``, stamped with its current watermark."""
        with self._write() as conn:
            chain = self._chain(conn, branch)
            return conn.execute(
                insert(Operator).values(
                    branch_id=chain[0].branch_id,
                    name=name,
                    pddl=pddl,
                    definition=dict(definition),
                    scenario=scenario,
                    episode_id=episode_id,
                    watermark=self._max_visible(conn, chain),
                    created_at=_now(),
                )
            ).inserted_primary_key[0]

    def visible_operators(self, branch: str | None) -> list[OperatorRecord]:
        """The operators ``branch`` has learned or inherited, oldest first."""
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            names = {link.branch_id: link.name for link in chain}
            stmt = select(Operator).where(visibility.clause(chain, Operator.branch_id, Operator.watermark)).order_by(Operator.id)
            return [
                OperatorRecord(
                    id=r.id,
                    branch=names[r.branch_id],
                    name=r.name,
                    pddl=r.pddl,
                    definition=r.definition,
                    scenario=r.scenario,
                    episode_id=r.episode_id,
                    watermark=r.watermark,
                    created_at=iso_timestamp(r.created_at) or "",
                )
                for r in conn.execute(stmt)
            ]

    def add_operator_execution(
        self,
        *,
        branch: str,
        operator: str,
        success: bool,
        context: Sequence[Sequence[str]] = (),
        episode_id: int | None = None,
        trial_id: int | None = None,
    ) -> int:
        """Record that ``operator`` ran as a plan step on ``branch``, whether its effects
        held, and its context (the lifted facts over its arguments before it ran).

        Stamped with the branch's watermark, so that it is seen by the branch and by
        branches forked from it later, like the trial it followed.
        """
        atoms = sorted([str(term) for term in atom] for atom in context)
        with self._write() as conn:
            chain = self._chain(conn, branch)
            return conn.execute(
                insert(OperatorExecution).values(
                    branch_id=chain[0].branch_id,
                    operator=operator,
                    success=bool(success),
                    context=atoms,
                    episode_id=episode_id,
                    trial_id=trial_id,
                    watermark=self._max_visible(conn, chain),
                    created_at=_now(),
                )
            ).inserted_primary_key[0]

    def operator_experience(self, branch: str | None) -> list[ExecutionCounts]:
        """Successes and failures of every operator per context, over what ``branch`` sees.

        Raises:
            StoreError: a stored context is not a list of atoms (lists of strings).
        """
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            stmt = (
                select(OperatorExecution.id, OperatorExecution.operator, OperatorExecution.context, OperatorExecution.success)
                .where(visibility.clause(chain, OperatorExecution.branch_id, OperatorExecution.watermark))
                .order_by(OperatorExecution.id)
            )
            counts: dict[tuple[str, tuple[tuple[str, ...], ...]], list[int]] = {}
            for row_id, name, context, success in conn.execute(stmt):
                key = (str(name), _context_atoms(row_id, context))
                counts.setdefault(key, [0, 0])[0 if success else 1] += 1
        return [ExecutionCounts(name, context, s, f) for (name, context), (s, f) in sorted(counts.items())]

    # ----------------------------------------------------------- world models

    def save_world_model(
        self, *, branch: str, name: str, seed: int, watermark: int, artifact: bytes, meta: Mapping[str, Any]
    ) -> int:
        """Store a fitted world model's bytes (a safe format: npz, state_dict, JSON).

        Args:
            watermark: :meth:`max_visible_trial_id` of ``branch`` when the fit started.
        """
        if not isinstance(artifact, (bytes, bytearray, memoryview)):
            raise LlcpsError("a world model artifact must be bytes", hint="serialise it as npz, a torch state_dict or JSON")
        data = bytes(artifact)
        with self._write() as conn:
            chain = self._chain(conn, branch)
            return conn.execute(
                insert(WorldModel).values(
                    branch_id=chain[0].branch_id,
                    name=name,
                    seed=int(seed),
                    watermark=int(watermark),
                    artifact=data,
                    sha256=hashlib.sha256(data).hexdigest(),
                    meta=dict(meta),
                    created_at=_now(),
                )
            ).inserted_primary_key[0]

    def latest_world_model(self, branch: str | None, name: str, seed: int) -> ModelArtifact | None:
        """The visible model of that name and seed fitted on the most data (then the newest)."""
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            names = {link.branch_id: link.name for link in chain}
            row = conn.execute(
                select(WorldModel)
                .where(visibility.clause(chain, WorldModel.branch_id, WorldModel.watermark), WorldModel.name == name, WorldModel.seed == seed)
                .order_by(WorldModel.watermark.desc(), WorldModel.id.desc())
                .limit(1)
            ).first()
        if row is None:
            return None
        if not isinstance(row.artifact, (bytes, bytearray, memoryview)) or not isinstance(row.meta, dict):
            raise StoreError(f"stored world model {row.id} is malformed: its artifact is not bytes or its meta not an object", hint=_CHANGED)
        return ModelArtifact(
            id=row.id,
            branch=names[row.branch_id],
            name=row.name,
            seed=row.seed,
            watermark=row.watermark,
            artifact=bytes(row.artifact),
            sha256=row.sha256,
            meta=row.meta,
            created_at=iso_timestamp(row.created_at) or "",
        )

    # ----------------------------------------------------------------- status

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
            )


    # ------------------------------------------------------------------ upkeep

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


def _mapping(value: Any, row: str, column: str) -> Mapping[str, Any]:
    """A JSON column that must hold an object."""
    if not isinstance(value, dict):
        raise StoreError(f"{row} is malformed: its {column} is not a JSON object", hint=_CHANGED)
    return value


def _applied(change: BranchChange) -> BranchChange:
    return BranchChange(**{**change.as_json(), "dry_run": False})
