"""``llcps db``: create, migrate, branch, compact and export the experience store."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from llcps.errors import LlcpsError
from llcps.jobs._common import Progress, StoreRef, no_progress, opened
from llcps.store import PRETRAIN, BranchChange, BranchInfo, CompactResult, StoreStatus

if TYPE_CHECKING:
    from llcps.cps.backfill import BackfillReport


@dataclass(frozen=True)
class InitResult:
    """A store made ready: its schema revision before (None: a new store) and after."""

    url: str
    before: str | None
    after: str
    current_branch: str

    @property
    def upgraded(self) -> bool:
        """An existing store was migrated to a newer revision."""
        return self.before not in (None, self.after)


@dataclass(frozen=True)
class UpgradeResult:
    """A migration to the newest schema, and the trial changes recovered afterwards."""

    before: str | None
    after: str
    changes: BackfillReport

    @property
    def changed(self) -> bool:
        return self.before != self.after

    def as_json(self) -> dict[str, Any]:
        return {"from": self.before, "to": self.after, "changed": self.changed, "changes": self.changes.as_json()}


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote: the branch, how many trials, and the file (None: a stream)."""

    branch: str
    count: int
    out: Path | None


def init_store(*, store: StoreRef) -> InitResult:
    """Create the store with a ``main`` branch, or migrate an existing one to the newest schema."""
    with opened(store, create=True, allow_outdated=True) as s:
        before = s.revision
        after = s.init()
        return InitResult(url=s.url, before=before, after=after, current_branch=s.current_branch())


def store_status(*, store: StoreRef, branch: str | None = None) -> StoreStatus:
    """URL, schema revision, current branch and the trial counts ``branch`` (None: the current one) sees.

    An outdated store is read too (the status says so).
    """
    with opened(store, allow_outdated=True) as s:
        return s.status(branch)


def list_branches(*, store: StoreRef) -> list[BranchInfo]:
    """Every branch with its parent, fork point, own and visible trial counts."""
    with opened(store) as s:
        return s.list_branches()


def create_branch(*, store: StoreRef, name: str, parent: str | None = None, at: int | str | None = None) -> BranchInfo:
    """A branch ``name`` that sees ``parent``'s trials (None: the current branch) up to ``at``:
    a trial id, ``"pretrain"`` (its pretraining point: the end of the first unbroken run of
    pretraining trials it sees) or None (its latest trial)."""
    with opened(store) as s:
        return s.create_branch(name, from_branch=parent, at=at)


def checkout_branch(*, store: StoreRef, name: str) -> BranchInfo:
    """Make branch ``name`` the current one."""
    with opened(store) as s:
        return s.checkout(name)


def reset_branch(*, store: StoreRef, branch: str | None = None, to: str = PRETRAIN, dry_run: bool = True, force: bool = False) -> BranchChange:
    """Drop the own experience of ``branch`` (None: the current branch) after ``to``
    (``pretrain`` or ``empty``); with ``dry_run``, only say what would go. Refused while
    a live process writes to the branch, unless ``force`` (that process then fails)."""
    with opened(store) as s:
        name = s.resolve_branch(branch).name
        return s.reset_branch(name, to=to, dry_run=dry_run, force=force)


def delete_branch(*, store: StoreRef, name: str, dry_run: bool = True, force: bool = False) -> BranchChange:
    """Delete branch ``name`` and everything it owns; with ``dry_run``, only say what would go.
    Refused while a live process writes to the branch, unless ``force`` (that process then fails)."""
    with opened(store) as s:
        return s.delete_branch(name, dry_run=dry_run, force=force)


def upgrade_store(*, store: StoreRef, replay_changes: bool = True, progress: Progress | None = None) -> UpgradeResult:
    """Migrate the store to the newest schema revision, then give every trial its symbolic
    change (replayed from its start state with ``replay_changes``, else marked unknown)."""
    report = progress or no_progress
    with opened(store, allow_outdated=True) as s:
        before, after = s.upgrade(progress=lambda revision, done, total: report(f"migrating to schema {revision}", done, total))
        from llcps.cps.backfill import backfill_changes  # PyBullet loads only when there is work

        changes = backfill_changes(
            s, replay=replay_changes, progress=lambda done, total: report("replaying trials for their changes", done, total)
        )
    return UpgradeResult(before=before, after=after, changes=changes)


def compact_store(*, store: StoreRef) -> CompactResult:
    """Give the space of removed rows back to the disk (SQLite VACUUM; PostgreSQL marks it for reuse)."""
    with opened(store) as s:
        return s.compact()


def export_trials(
    *,
    store: StoreRef,
    out: Path | TextIO,
    branch: str | None = None,
    fmt: str = "csv",
    source: str | None = None,
    scenario: str | None = None,
    episode: int | None = None,
) -> ExportResult:
    """Write the trials ``branch`` (None: the current branch) sees, in id order, one flat row
    each, to the file or text stream ``out`` as ``fmt`` (csv, jsonl or parquet; parquet needs a file).

    ``source``, ``scenario`` (a name or its alias) and ``episode`` keep only matching trials.
    """
    from llcps.outputs import check_output_file
    from llcps.store.export import BINARY_FORMATS
    from llcps.store.export import export_trials as write_trials

    path = Path(out) if isinstance(out, (str, Path)) else None
    if fmt in BINARY_FORMATS and path is None:
        raise LlcpsError(f"--format {fmt} writes a binary file", hint="pass --out FILE")
    if scenario is not None:
        from llcps.scenarios import get_scenario

        scenario = get_scenario(scenario).name
    if path is not None:
        check_output_file(path, what="--out")
    with opened(store) as s:
        name = s.resolve_branch(branch).name
        count = write_trials(
            s, branch=name, fmt=fmt, out=out if path is None else path, source=source, scenario=scenario, episode=episode, what="--out"
        )
    return ExportResult(branch=name, count=count, out=path)
