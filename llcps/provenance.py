"""Where a run ran: llcps version and commit, library versions, Python, host, CPU count.

Every run in the store records this, so a result can be traced to the code and the
machine that made it, and two runs can be told apart when their numbers differ.
Collecting it imports none of the libraries it names (their installed metadata is
read), and the git commit is looked up once per process.
"""

from __future__ import annotations

import os
import platform
import socket
import subprocess
from dataclasses import asdict, dataclass
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any, Mapping

from llcps._version import __version__

#: Distribution name of each library whose version a run records, by record field.
LIBRARIES: Mapping[str, str] = {
    "pybullet_version": "pybullet",
    "torch_version": "torch",
    "sklearn_version": "scikit-learn",
    "numpy_version": "numpy",
}

_GIT_TIMEOUT_SECONDS = 5.0


@dataclass(frozen=True)
class Provenance:
    """The environment of one run (each field None when unknown, e.g. for runs stored before it was kept).

    Attributes:
        llcps_version: the llcps package version.
        git_commit: the commit of llcps's source tree, when llcps runs from a git
            checkout (None for an installed wheel).
        git_dirty: whether that tree had uncommitted changes to tracked files.
    """

    llcps_version: str | None = None
    git_commit: str | None = None
    git_dirty: bool | None = None
    python_version: str | None = None
    pybullet_version: str | None = None
    torch_version: str | None = None
    sklearn_version: str | None = None
    numpy_version: str | None = None
    host: str | None = None
    cpu_count: int | None = None

    def as_json(self) -> dict[str, Any]:
        return asdict(self)

    @property
    def commit_text(self) -> str:
        """The commit, short, with ``+dirty`` when the tree had changes; ``-`` when unknown."""
        if not self.git_commit:
            return "-"
        return self.git_commit[:12] + ("+dirty" if self.git_dirty else "")

    def summary(self) -> str:
        """One line for people: ``llcps 0.1.0 (abc123) · Python 3.11.2 · pybullet 3.2.7 · ...``."""
        parts = [f"llcps {self.llcps_version or '?'}" + (f" ({self.commit_text})" if self.git_commit else "")]
        parts.append(f"Python {self.python_version or '?'}")
        for field, dist in LIBRARIES.items():
            parts.append(f"{dist} {getattr(self, field) or '?'}")
        parts.append(f"host {self.host or '?'} ({self.cpu_count if self.cpu_count is not None else '?'} CPUs)")
        return " · ".join(parts)


def _version(distribution: str) -> str | None:
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return None


def cpu_count() -> int:
    """CPUs this process may run on (its affinity where the OS tells, else all)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def source_tree() -> Path | None:
    """The git checkout llcps runs from, or None (an installed wheel has none)."""
    root = Path(__file__).resolve().parent.parent
    if (root / ".git").exists() and (root / "pyproject.toml").is_file():
        return root
    return None


def _git(root: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(
            ["git", "-C", str(root), *args],
            capture_output=True,
            text=True,
            timeout=_GIT_TIMEOUT_SECONDS,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout if done.returncode == 0 else None


@lru_cache(maxsize=1)
def git_state() -> tuple[str | None, bool | None]:
    """(commit, dirty) of llcps's source tree; (None, None) outside a checkout or without git."""
    root = source_tree()
    if root is None:
        return None, None
    head = _git(root, "rev-parse", "HEAD")
    if head is None or not head.strip():
        return None, None
    status = _git(root, "status", "--porcelain", "--untracked-files=no")
    return head.strip(), (None if status is None else bool(status.strip()))


@lru_cache(maxsize=1)
def current() -> Provenance:
    """The provenance of this process (computed once)."""
    commit, dirty = git_state()
    return Provenance(
        llcps_version=__version__,
        git_commit=commit,
        git_dirty=dirty,
        python_version=platform.python_version(),
        **{field: _version(dist) for field, dist in LIBRARIES.items()},
        host=socket.gethostname(),
        cpu_count=cpu_count(),
    )


#: Field names, in order (the columns of the ``runs`` table that hold them).
FIELDS: tuple[str, ...] = tuple(Provenance.__dataclass_fields__)
