"""Where a command writes: checked before it does any work, and written safely.

A solve that runs for minutes and then cannot write its GIF, or an export that
fails half-way into a file, wastes the work and hides the cause behind a traceback.
These checks run first: the directory must exist (nothing is created silently), the
file must be creatable there (a probe file is made and removed), and the extension
must be one the writer knows. Then every file is written by :func:`written_atomically`:
a temporary file beside the target, renamed over it.
"""

from __future__ import annotations

import os
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Iterator

from llcps.errors import LlcpsError

#: Extensions of the GIFs that ``--gif`` writes.
GIF_SUFFIXES: tuple[str, ...] = (".gif",)


def check_output_file(path: str | Path, *, what: str, suffixes: tuple[str, ...] = ()) -> Path:
    """Make sure a file can be written at ``path`` (without writing it).

    Args:
        what: how the user named the path, e.g. ``"--gif"``.
        suffixes: accepted extensions (lower case, with the dot); empty accepts any.

    Raises:
        LlcpsError: wrong extension, a directory, a missing or unwritable directory,
            or an existing file that cannot be written.
    """
    path = Path(path).expanduser()
    if suffixes and path.suffix.lower() not in suffixes:
        raise LlcpsError(
            f"{what} {path} has an extension llcps cannot write",
            hint=f"use a file name ending in {' or '.join(suffixes)}",
        )
    if path.is_dir():
        raise LlcpsError(f"{what} {path} is a directory", hint=f"pass a file path, e.g. {path / ('out' + (suffixes[0] if suffixes else ''))}")
    parent = path.absolute().parent
    if not parent.is_dir():
        raise LlcpsError(f"{what}: directory {parent} does not exist", hint=f"create it first or choose another {what}")
    if _written_directly(path):  # /dev/stdout, /dev/full: written in place
        try:
            with path.open("ab"):
                pass
        except OSError as exc:
            raise LlcpsError(f"{what}: cannot write {path}: {exc.strerror or exc}", hint=f"choose another {what}") from None
        return path
    if path.is_file() and not path.is_symlink() and not os.access(path, os.W_OK):
        raise LlcpsError(f"{what}: cannot write {path}: Permission denied", hint=f"choose another {what}")
    _probe_directory(parent, what)  # anything else is written beside it and renamed over it
    return path


def check_output_dir(path: str | Path, *, what: str) -> Path:
    """Make sure files can be written into directory ``path`` (which may be created).

    The directory itself, or its nearest existing ancestor, must be a writable directory.
    """
    path = Path(path).expanduser()
    existing = path.absolute()
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise LlcpsError(f"{what} {path}: {existing} is not a directory", hint=f"choose another {what}")
    _probe_directory(existing, what)
    return path


def _probe_directory(directory: Path, what: str) -> None:
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".llcps-write-check-")
    except OSError as exc:
        raise LlcpsError(
            f"{what}: cannot write into directory {directory}: {exc.strerror or exc}", hint=f"choose another {what}"
        ) from None
    os.close(fd)
    os.unlink(probe)


def write_error(path: str | Path, exc: OSError, *, what: str) -> LlcpsError:
    """An error for a write that failed after the checks passed (a full disk, /dev/full)."""
    return LlcpsError(f"{what}: writing {path} failed: {exc.strerror or exc}", hint=f"free some space or choose another {what}")


#: Directories whose files (``/dev/stdout``, ``/dev/full``, ``/proc/self/fd/1``) a path may
#: name to be written in place: the system's, where no user can plant a link (``/dev/shm``,
#: which anyone may write, is not one of them).
SYSTEM_DIRECTORIES: frozenset[str] = frozenset({"/dev", "/dev/fd", "/proc/self/fd"})


def _written_directly(path: Path) -> bool:
    """Whether ``path`` names a stream or device of the system (written in place, never renamed over)."""
    return str(path.absolute().parent) in SYSTEM_DIRECTORIES


@contextmanager
def written_atomically(path: str | Path, *, what: str) -> Iterator[Path]:
    """A temporary path to write that becomes ``path`` only when the block succeeds.

    Every file llcps writes goes through here. The file is written beside ``path`` and
    renamed over it at the end, so a failed write leaves no half-written file (and an
    existing one untouched), and a symbolic link at ``path`` is replaced, never written
    through: a link planted in a shared directory cannot make llcps overwrite its target.
    Only a stream or device of the system (a path in :data:`SYSTEM_DIRECTORIES`:
    ``/dev/stdout``, ``/dev/full``) is yielded as it is and written in place.

    Raises:
        LlcpsError: writing failed (see :func:`write_error`).
    """
    path = Path(path)
    try:
        if _written_directly(path):
            yield path
            return
        try:
            st = path.lstat()
        except FileNotFoundError:
            st = None
        if st is not None and stat.S_ISDIR(st.st_mode):
            raise IsADirectoryError(21, "Is a directory")
        keep = st is not None and stat.S_ISREG(st.st_mode)  # a regular file keeps its mode; a link's target is never read
        mode = stat.S_IMODE(st.st_mode) if keep else 0o666 & ~_umask()  # type: ignore[union-attr]
        fd, tmp = tempfile.mkstemp(dir=path.absolute().parent, prefix=f".{path.name}.", suffix=".part")
        os.close(fd)
        try:
            yield Path(tmp)
            os.chmod(tmp, mode)  # mkstemp's 0600 would make the file private
            os.replace(tmp, path)  # replaces a link at path itself, not its target
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    except OSError as exc:
        raise write_error(path, exc, what=what) from None


@contextmanager
def replaced_atomically(path: str | Path, *, what: str) -> Iterator[IO[str]]:
    """A text file that becomes ``path`` only when the block succeeds (see :func:`written_atomically`)."""
    with written_atomically(path, what=what) as target, target.open("w", newline="", encoding="utf-8") as fh:
        yield fh


def write_text(path: str | Path, text: str, *, what: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through :func:`written_atomically`; returns ``path``."""
    with replaced_atomically(path, what=what) as fh:
        fh.write(text)
    return Path(path)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
