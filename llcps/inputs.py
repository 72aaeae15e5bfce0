"""Reading a file a user names: a regular file, read under a byte cap.

A path on the command line can name anything: ``/dev/zero`` (read forever), a FIFO
(an ``open`` that waits for a writer that never comes), a directory, a file of
gigabytes. :func:`read_user_file` opens without blocking, checks on the open file
that it is a regular file, and reads one byte past the cap to know it was exceeded,
so every such path is one error before any work. Every file llcps reads on a user's
word goes through here (scenario files, results files); ``--db`` is checked with
:func:`check_regular_file` before SQLite opens it.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from llcps.errors import LlcpsError


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _not_regular(path: Path, what: str, mode: int, hint: str) -> LlcpsError:
    return LlcpsError(f"{what} {path} is {_kind(mode)}, not a regular file", hint=hint)


def check_regular_file(path: str | Path, *, what: str, hint: str) -> None:
    """Fail unless ``path`` (if it exists) is a regular file; never opens it.

    Raises:
        LlcpsError: a directory, device, FIFO or socket.
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise LlcpsError(f"cannot read {what} {path}: {exc.strerror or exc}", hint=hint) from None
    if not stat.S_ISREG(mode):
        raise _not_regular(path, what, mode, hint)


def read_user_file(path: str | Path, *, what: str, max_bytes: int, hint: str) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes`` of them.

    Args:
        what: how the error names the file, e.g. ``"scenario file"``.
        max_bytes: the documented cap (see :mod:`llcps.limits`).
        hint: what the user should pass instead.

    Raises:
        LlcpsError: missing, unreadable, not a regular file, or larger than the cap.
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise LlcpsError(f"no {what} {path}", hint=hint) from None
    except IsADirectoryError:
        raise LlcpsError(f"{what} {path} is a directory, not a regular file", hint=hint) from None
    except OSError as exc:
        raise LlcpsError(f"cannot read {what} {path}: {exc.strerror or exc}", hint=hint) from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise _not_regular(path, what, mode, hint)
        with os.fdopen(fd, "rb", closefd=False) as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise LlcpsError(f"cannot read {what} {path}: {exc.strerror or exc}", hint=hint) from None
    finally:
        os.close(fd)
    if len(data) > max_bytes:
        raise LlcpsError(f"{what} {path} is larger than the {max_bytes:,} bytes allowed", hint=hint)
    return data


def read_user_text(path: str | Path, *, what: str, max_bytes: int, hint: str) -> str:
    """:func:`read_user_file` decoded as UTF-8 (an error names the file)."""
    data = read_user_file(path, what=what, max_bytes=max_bytes, hint=hint)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise LlcpsError(f"{what} {path} is not UTF-8 text: {exc.reason} at byte {exc.start}", hint=hint) from None


__all__ = ["check_regular_file", "read_user_file", "read_user_text"]
