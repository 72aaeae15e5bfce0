"""What every job shares: the store it works on, and the shape of its progress callback."""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Callable, Iterator, Union

from llcps.store import Store

#: The store a job works on: an open :class:`Store` (left open) or a SQLite path / SQLAlchemy URL
#: (opened for the job and closed when it ends).
StoreRef = Union[Store, str, "os.PathLike[str]"]

#: ``progress(phase, done=0, total=None)``: the phase a job is in and, when it has a size, its
#: counts (the CLI's progress display is one).
Progress = Callable[..., None]


def no_progress(phase: str, done: int = 0, total: int | None = None) -> None:
    """The progress callback of a job nobody watches."""


@contextmanager
def opened(store: StoreRef, *, create: bool = False, allow_outdated: bool = False) -> Iterator[Store]:
    """The store ``store`` names, open for the block (see :meth:`Store.open`).

    An open :class:`Store` is used as it is and left open: its owner closes it.
    """
    if isinstance(store, Store):
        yield store
        return
    with Store.open(os.fspath(store), create=create, allow_outdated=allow_outdated) as own:
        yield own
