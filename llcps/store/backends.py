"""Turning ``--db`` into an engine, safely.

A path or URL is checked before anything is written: a missing directory, a
directory, an unreadable file, a file that is not SQLite, or a SQLite file that is
not an llcps store all raise :class:`~llcps.errors.StoreError` and leave the file
byte-identical. Only then does the engine (which switches SQLite to WAL) connect.

A new SQLite store is made beside its path with its ``application_id`` in the header
and then hard-linked into place, which fails if the path exists: the path never holds
a half-made file (a creator killed by ``kill -9`` leaves at most a hidden
``.NAME.*.new`` beside it), and of several creators at once one wins and the others
open its store.

SQLite connections get WAL journaling, a busy timeout (30 s, ``LLCPS_DB_TIMEOUT``), foreign keys and
``synchronous=NORMAL``: a committed transaction is in the WAL file before the
commit returns, so it survives a killed process (an OS crash or power cut can
lose the last commits, never consistency). Write transactions start with
``BEGIN IMMEDIATE`` so concurrent writers queue on the busy timeout instead of
failing with "database is locked" when a read would have to upgrade to a write.

On PostgreSQL a write transaction first takes a transaction-level advisory lock
(:data:`WRITER_LOCK`), the counterpart of ``BEGIN IMMEDIATE``: writers queue, so
trial ids commit in the order they were drawn, which branch visibility relies on
(see :mod:`llcps.store.visibility`). Readers never wait. A server that does not
answer a connection within ``LLCPS_DB_TIMEOUT`` seconds (30), a lock held longer
than that (``lock_timeout``) and a statement running longer than
``LLCPS_DB_STATEMENT_TIMEOUT`` seconds (3600; ``statement_timeout``) end with an error.
Everything backend-specific lives in this module.
"""

from __future__ import annotations

import math
import os
import sqlite3
import tempfile
from contextlib import closing
from pathlib import Path
from typing import Any

from sqlalchemy import URL, Engine, create_engine, event, make_url
from sqlalchemy.exc import ArgumentError, IntegrityError, NoSuchModuleError
from sqlalchemy.pool import NullPool, StaticPool

from llcps import bounded_json
from llcps.errors import StoreError
from llcps.inputs import check_regular_file
from llcps.store.tables import SQLITE_APPLICATION_ID

#: How long a SQLite writer waits for another writer's lock, in milliseconds (the default of
#: :data:`TIMEOUT_VARIABLE`).
BUSY_TIMEOUT_MS = 30_000

#: Environment variable: seconds to wait for a database server to answer a connection, and
#: for a lock another process holds (SQLite's busy timeout, PostgreSQL's ``lock_timeout``).
TIMEOUT_VARIABLE = "LLCPS_DB_TIMEOUT"

#: Environment variable: seconds a PostgreSQL statement may run (``statement_timeout``; 0: no limit).
STATEMENT_TIMEOUT_VARIABLE = "LLCPS_DB_STATEMENT_TIMEOUT"

#: Default of :data:`STATEMENT_TIMEOUT_VARIABLE`: longer than any query llcps makes (a
#: compaction of a large store included).
STATEMENT_TIMEOUT_S = 3600.0

#: Largest timeout either variable takes (a day).
MAX_TIMEOUT_S = 86_400.0

SQLITE_MAGIC = b"SQLite format 3\x00"

#: Hint of a row that does not decode: it was not written by llcps.
CHANGED_HINT = "the row was changed outside llcps; restore the database from a copy (or delete the row)"

#: Execution option that marks a connection's transaction as a write.
WRITE_OPTION = "llcps_write"

#: PostgreSQL advisory lock key that serializes writers ("LLCPSWRT" as a signed 64-bit number).
WRITER_LOCK = int.from_bytes(b"LLCPSWRT", "big", signed=True)

#: PostgreSQL's SQLSTATE for a foreign key violation.
_FOREIGN_KEY_VIOLATION = "23503"


def resolve_url(url_or_path: str) -> URL:
    """Read ``--db``: an SQLAlchemy URL if it has a scheme, else a file path."""
    text = url_or_path.strip()
    if not text:
        raise StoreError("the database location is empty", hint="pass --db PATH or --db URL")
    if "://" in text:
        try:
            return make_url(text)
        except (ArgumentError, ValueError) as exc:
            raise StoreError(f"cannot parse database URL {text!r}", hint="e.g. sqlite:///llcps.db or postgresql+psycopg://user@host/db") from exc
    path = Path(text).expanduser().absolute()
    return URL.create("sqlite", database=str(path))


def sqlite_path(url: URL) -> Path | None:
    """The file behind a SQLite URL, or None for other backends and in-memory DBs."""
    if url.get_backend_name() != "sqlite":
        return None
    database = url.database or ""
    if database in ("", ":memory:") or database.startswith("file:"):
        return None
    return Path(database)


def check_sqlite_file(path: Path, *, create: bool) -> bool:
    """Make sure ``path`` can be an llcps store without touching it.

    Returns:
        True when the file exists and is an llcps store; False when it is absent (or
        an empty database) and ``create`` allows making it.
    """
    if path.is_dir():
        raise StoreError(f"{path} is a directory, not a database file", hint=f"pass a file path, e.g. --db {path / 'llcps.db'}")
    if not path.parent.is_dir():
        raise StoreError(f"directory {path.parent} does not exist", hint="create it first or choose another --db path")
    if not path.exists():
        if create:
            if not os.access(path.parent, os.W_OK):
                raise StoreError(f"cannot create {path}: directory {path.parent} is not writable", hint="choose another --db path")
            return False
        raise StoreError(f"no llcps database at {path}", hint=f"create one with `llcps --db {path} db init` (or pass --create)")
    check_regular_file(path, what="--db", hint="pass the path of an llcps store (a regular file), or a new path with `db init`")
    try:
        with path.open("rb") as fh:
            header = fh.read(100)
    except OSError as exc:
        raise StoreError(f"cannot read {path}: {exc.strerror or exc}", hint="check the file's permissions") from exc
    if len(header) < 100 or not header.startswith(SQLITE_MAGIC):
        raise StoreError(f"{path} is not a SQLite database", hint="choose another --db path; the file was left untouched")
    if int.from_bytes(header[68:72], "big") == SQLITE_APPLICATION_ID:
        return True
    if _read_application_id(path) == SQLITE_APPLICATION_ID:  # still in the write-ahead log (older stores)
        return True
    raise StoreError(
        f"{path} is a SQLite database but not an llcps store",
        hint="choose another --db path (or a new file for `llcps db init`); the file was left untouched",
    )


def _read_application_id(path: Path) -> int:
    """The application id SQLite reports, reading the file (and its WAL) only."""
    try:
        with closing(sqlite3.connect(f"{path.as_uri()}?mode=ro", uri=True, timeout=timeout_seconds_or_default())) as conn:
            return int(conn.execute("PRAGMA application_id").fetchone()[0])
    except sqlite3.Error as exc:
        raise StoreError(f"cannot read {path}: {exc}", hint="check the file and its permissions; the file was left untouched") from exc


def create_sqlite_file(path: Path, image: bytes | None = None) -> bool:
    """Put a new SQLite file marked as an llcps store at ``path``, atomically.

    The file is empty, or holds ``image`` (the bytes of a database, see
    :func:`sqlite_image`). It is made under a temporary name in the same directory and
    hard-linked to ``path``; if ``path`` exists by then (another creator won), that
    file is kept.

    Returns:
        Whether the file at ``path`` is the one this call made.
    """
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".new")
    except OSError as exc:
        raise StoreError(f"cannot create {path}: {exc.strerror or exc}", hint="check that the directory is writable") from exc
    os.close(fd)
    try:
        with closing(sqlite3.connect(tmp)) as conn:
            if image is not None:
                with closing(sqlite3.connect(":memory:")) as source:
                    source.deserialize(image)
                    source.backup(conn)
            conn.execute(f"PRAGMA application_id = {SQLITE_APPLICATION_ID}")
            conn.commit()
        try:
            os.link(tmp, path)
        except FileExistsError:
            return False  # another creator made it first: open that one
        except OSError:  # a filesystem without hard links: a rename that checks first
            if path.exists():
                return False
            os.rename(tmp, path)
        return True
    except (OSError, sqlite3.Error) as exc:
        raise StoreError(f"cannot create {path}: {exc}", hint="check that the directory is writable") from exc
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def sqlite_image(path: Path) -> bytes:
    """The SQLite database at ``path`` as bytes, for :func:`create_sqlite_file` to copy.

    The file is switched out of write-ahead logging first (its log folded in), so that
    the bytes are a whole database that SQLite can read from memory.
    """
    with closing(sqlite3.connect(path)) as conn:
        conn.execute("PRAGMA journal_mode = DELETE")
        return conn.serialize()


def _on_sqlite_connect(foreign_keys: bool, file_backed: bool, busy_timeout_ms: int):  # noqa: ANN202 - event hook factory
    def on_connect(dbapi_connection: Any, _record: Any) -> None:
        # Let SQLAlchemy's "begin" event issue BEGIN so we choose its kind.
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        try:
            cursor.execute(f"PRAGMA busy_timeout = {busy_timeout_ms}")
            if file_backed:
                cursor.execute("PRAGMA journal_mode = WAL")
            cursor.execute("PRAGMA synchronous = NORMAL")
            cursor.execute(f"PRAGMA foreign_keys = {'ON' if foreign_keys else 'OFF'}")
        finally:
            cursor.close()

    return on_connect


def _on_sqlite_begin(conn: Any) -> None:
    immediate = conn.get_execution_options().get(WRITE_OPTION, False)
    conn.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")


def _on_postgresql_begin(conn: Any) -> None:
    if conn.get_execution_options().get(WRITE_OPTION, False):
        conn.exec_driver_sql(f"SELECT pg_advisory_xact_lock({WRITER_LOCK})")


def timeout_seconds(variable: str = TIMEOUT_VARIABLE, default: float = BUSY_TIMEOUT_MS / 1000) -> float:
    """A timeout from the environment (:data:`TIMEOUT_VARIABLE` or :data:`STATEMENT_TIMEOUT_VARIABLE`), checked.

    Raises:
        StoreError: the value is not a number of seconds from 0 to :data:`MAX_TIMEOUT_S`
            (0 only for the statement timeout: no limit).
    """
    text = os.environ.get(variable, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    lowest = 0.0 if variable == STATEMENT_TIMEOUT_VARIABLE else 0.001
    if not lowest <= value <= MAX_TIMEOUT_S:
        raise StoreError(
            f"{variable}={text[:20]!r} is not a number of seconds from {lowest:g} to {MAX_TIMEOUT_S:g}",
            hint=f"e.g. {variable}=30 (unset it for the default, {default:g} s)",
        )
    return value


def timeout_seconds_or_default() -> float:
    """:func:`timeout_seconds`, or its default when the variable is not valid (for messages)."""
    try:
        return timeout_seconds()
    except StoreError:
        return BUSY_TIMEOUT_MS / 1000


def _postgresql_options(url: URL, lock_s: float, statement_s: float) -> str:
    """libpq's ``options`` for a session: the URL's own, then the lock and statement timeouts."""
    own = url.query.get("options", "")
    own = " ".join(own) if isinstance(own, tuple) else own
    timeouts = f"-c lock_timeout={round(lock_s * 1000)} -c statement_timeout={round(statement_s * 1000)}"
    return f"{own} {timeouts}".strip()


def stored_json(text: str | bytes) -> Any:
    """Decode a JSON column's text: every JSON column an engine of :func:`make_engine`
    reads comes here, bounded in size and nesting (:mod:`llcps.bounded_json`).

    Raises:
        StoreError: the text is not JSON, or larger or deeper than the bounds.
    """
    try:
        return bounded_json.loads(text)
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError, JsonLimitError
        raise StoreError(f"a stored JSON value is malformed ({exc})", hint=CHANGED_HINT) from None


def read_only(path: Path) -> bool:
    """Whether this process cannot write the SQLite file at ``path`` or its directory
    (where SQLite keeps the write-ahead log): a read-only file, directory or mount."""
    return not (os.access(path, os.W_OK) and os.access(path.parent, os.W_OK))


def _read_only_connector(path: Path, timeout_s: float):  # noqa: ANN202 - a DBAPI connect function
    """Connections that only read ``path``: ``mode=ro`` while SQLite can share the
    write-ahead log's index with writers, else ``immutable=1`` (a read-only directory or
    mount, where that index cannot be made; nothing writes there anyway)."""

    def connect() -> sqlite3.Connection:
        conn = sqlite3.connect(f"{path.as_uri()}?mode=ro", uri=True, timeout=timeout_s, check_same_thread=False)
        try:
            conn.execute("PRAGMA schema_version").fetchone()
            return conn
        except sqlite3.Error:
            conn.close()
        return sqlite3.connect(f"{path.as_uri()}?immutable=1", uri=True, timeout=timeout_s, check_same_thread=False)

    return connect


def make_engine(url: URL, *, foreign_keys: bool = True, pooled: bool = True, plain: bool = False) -> Engine:
    """Create the engine for an already checked URL.

    Args:
        foreign_keys: SQLite only; migrations turn them off while batch operations
            rebuild tables, as SQLite requires.
        pooled: keep connections open between calls (False for one-off use).
        plain: SQLite files only: no pragmas at all, for looking at a file that may
            not be ours without changing a byte of it.
    """
    kwargs: dict[str, Any] = {"json_deserializer": stored_json}
    is_sqlite = url.get_backend_name() == "sqlite"
    file_backed = is_sqlite and sqlite_path(url) is not None
    path = sqlite_path(url) if file_backed else None
    wait_s = timeout_seconds()
    only_reads = path is not None and path.exists() and read_only(path)
    if only_reads:
        assert path is not None
        kwargs["creator"] = _read_only_connector(path, wait_s)
    if plain and file_backed:
        return create_engine(url, poolclass=NullPool, **kwargs)
    if is_sqlite and not file_backed:
        # One shared connection, or every checkout would see a fresh empty DB.
        kwargs["poolclass"] = StaticPool
        kwargs["connect_args"] = {"check_same_thread": False}
    elif not pooled:
        kwargs["poolclass"] = NullPool
    if is_sqlite and not only_reads:
        kwargs.setdefault("connect_args", {})["timeout"] = wait_s
    elif url.get_backend_name() == "postgresql":
        statement_s = timeout_seconds(STATEMENT_TIMEOUT_VARIABLE, STATEMENT_TIMEOUT_S)
        # libpq counts connect_timeout in whole seconds, and takes less than 2 as 2.
        kwargs["connect_args"] = {"connect_timeout": max(2, math.ceil(wait_s)), "options": _postgresql_options(url, wait_s, statement_s)}
    try:
        engine = create_engine(url, **kwargs)
    except (NoSuchModuleError, ModuleNotFoundError, ImportError) as exc:
        raise StoreError(
            f"no database driver for {url.drivername!r}: {exc}",
            hint="for PostgreSQL install the extra: pip install 'llcps[postgres]' and use postgresql+psycopg://...",
        ) from exc
    if is_sqlite:
        event.listen(engine, "connect", _on_sqlite_connect(foreign_keys, file_backed and not only_reads, round(wait_s * 1000)))
        event.listen(engine, "begin", _on_sqlite_begin)
    elif url.get_backend_name() == "postgresql":
        event.listen(engine, "begin", _on_postgresql_begin)
    return engine


def violates_foreign_key(exc: IntegrityError) -> bool:
    """Whether the driver reports ``exc`` as a foreign key violation (by its error code,
    not its message): SQLite's ``SQLITE_CONSTRAINT_FOREIGNKEY``, PostgreSQL's SQLSTATE 23503."""
    orig = exc.orig
    if isinstance(orig, sqlite3.Error):
        return getattr(orig, "sqlite_errorcode", None) == sqlite3.SQLITE_CONSTRAINT_FOREIGNKEY
    return getattr(orig, "sqlstate", None) == _FOREIGN_KEY_VIOLATION
