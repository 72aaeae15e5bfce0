"""The store's engine and the two kinds of transaction every query runs in.

A read is a plain connection; a write is one transaction that holds the store's
writer lock from its first statement (SQLite: ``BEGIN IMMEDIATE``; PostgreSQL: an
advisory lock, see :mod:`llcps.store.backends`), so trial ids commit in increasing
order, as :mod:`llcps.store.visibility` needs. Both turn a database error into a
:class:`~llcps.errors.StoreError` with a hint, as a write rolls back.

:class:`Transactions` is the base of every query class of the store
(:class:`~llcps.store.store.Store` is their union).
"""

from __future__ import annotations

import json
import os
from contextlib import contextmanager
from datetime import datetime, timezone
from typing import Iterator

from sqlalchemy import URL, Connection, Engine
from sqlalchemy.exc import SQLAlchemyError

from llcps.errors import StoreError
from llcps.store import backends
from llcps.store.backends import CHANGED_HINT

__all__ = ["CHANGED_HINT", "Transactions", "db_error", "utc_now"]



def utc_now() -> datetime:
    """Now, as the store keeps times: UTC without a time zone."""
    return datetime.now(timezone.utc).replace(tzinfo=None)


def db_error(exc: SQLAlchemyError, url: URL | None = None) -> StoreError:
    """A database error as a :class:`StoreError`, with a hint at the likely cause.

    Args:
        url: the store's URL: for a SQLite file, an I/O error on a file system with
            (almost) no space left is reported as a full disk, which is what it is.
    """
    detail = (str(getattr(exc, "orig", None) or exc).splitlines() or ["?"])[0]
    lowered = detail.lower()
    wait = f"{backends.TIMEOUT_VARIABLE} (now {backends.timeout_seconds_or_default():g} s)"
    if "locked" in lowered or "busy" in lowered or "lock timeout" in lowered:
        message = f"the database stayed locked by another process for longer than {wait}: {detail}"
        hint = f"retry when the other process is done, or wait longer: {backends.TIMEOUT_VARIABLE}=SECONDS"
    elif "statement timeout" in lowered:
        message = f"a database statement ran longer than {backends.STATEMENT_TIMEOUT_VARIABLE} allows: {detail}"
        hint = f"check the server's load, or allow more: {backends.STATEMENT_TIMEOUT_VARIABLE}=SECONDS (0: no limit)"
    elif "timeout expired" in lowered or "timed out" in lowered:
        message = f"the database server did not answer within {wait}: {detail}"
        hint = f"check the --db URL's host and port and that the server is running; {backends.TIMEOUT_VARIABLE}=SECONDS waits longer"
    elif "readonly" in lowered or "read-only" in lowered:
        message = f"the store is read-only: {detail}"
        hint = "the database file, its directory or its file system is not writable: check permissions and mounts (reading works: `llcps db status`)"
    elif "disk is full" in lowered or "no space" in lowered or ("i/o error" in lowered and _disk_full(url)):
        message = f"the disk holding the store is full: {detail}"
        hint = "free space on that file system (or move the store), then run the command again; what was committed is kept"
    elif "permission" in lowered or "unable to open" in lowered:
        message = f"database error: {detail}"
        hint = "the database file or its directory cannot be opened for writing: check permissions, or whether the file system is read-only"
    elif "connect" in lowered:
        message = f"database error: {detail}"
        hint = "check the --db URL and that the database server is running"
    else:
        message = f"database error: {detail}"
        hint = "check `llcps db status`"
    return StoreError(message, hint=hint)


def _disk_full(url: URL | None) -> bool:
    """Whether the file system of the SQLite store at ``url`` has (almost) no space left."""
    path = backends.sqlite_path(url) if url is not None else None
    if path is None:
        return False
    try:
        stats = os.statvfs(path.parent)
    except OSError:
        return False
    return stats.f_bavail * stats.f_frsize < FULL_BELOW_BYTES


#: Free space under which a SQLite I/O error is taken for a full disk (SQLite needs a
#: few pages for its write-ahead log and index; under 1 MiB it often cannot get them).
FULL_BELOW_BYTES = 2**20


class Transactions:
    """An engine, the URL it was made from, and read and write scopes on it."""

    def __init__(self, engine: Engine, url: URL) -> None:
        self._engine = engine
        self._url = url

    @property
    def url(self) -> str:
        """The database URL, password hidden."""
        return self._url.render_as_string(hide_password=True)

    @property
    def engine(self) -> Engine:
        """The SQLAlchemy engine, for tools that need raw access (benchmarks, exports)."""
        return self._engine

    @contextmanager
    def _read(self) -> Iterator[Connection]:
        try:
            with self._engine.connect() as conn:
                yield conn
        except SQLAlchemyError as exc:
            raise db_error(exc, self._url) from exc
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:  # a JSON column's text, decoded as rows are read
            raise StoreError(f"a stored JSON value is malformed ({exc})", hint=CHANGED_HINT) from None
        except (ValueError, TypeError, OverflowError) as exc:  # a value the driver cannot convert (a time that is not one)
            raise StoreError(f"a stored value is malformed ({type(exc).__name__}: {str(exc)[:120]})", hint=CHANGED_HINT) from None

    @contextmanager
    def _write(self) -> Iterator[Connection]:
        """One transaction that takes the write lock up front (SQLite: BEGIN IMMEDIATE).

        The :class:`StoreError` a database error becomes has that error as its ``__cause__``.
        """
        try:
            with self._engine.connect() as conn:
                conn.execution_options(**{backends.WRITE_OPTION: True})
                with conn.begin():
                    yield conn
        except SQLAlchemyError as exc:
            raise db_error(exc, self._url) from exc
        except (ValueError, TypeError, OverflowError) as exc:  # a stored value read on the way, as in _read
            raise StoreError(f"a stored value is malformed ({type(exc).__name__}: {str(exc)[:120]})", hint=CHANGED_HINT) from None
