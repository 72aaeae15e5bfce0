"""Branches: git-like lines of experience over one store, their forks and their removal.

A branch sees its own rows and what its parent saw up to its fork point
(:mod:`llcps.store.visibility` holds that algebra apart from any database); here it
becomes queries. Deleting a branch, or resetting it to its pretraining or to nothing,
removes what it owns (trials and their changes, episodes, operators and their
executions, world models) and is refused while a child branch still sees any of it.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any, Callable, Mapping, Sequence

from sqlalchemy import URL, ColumnElement, Connection, Engine, and_, delete, func, insert, or_, select, update

from llcps.domain import check_id
from llcps.errors import LlcpsError, StoreError
from llcps.store import visibility, writers
from llcps.store.records import BranchChange, BranchInfo
from llcps.store.settings import SettingQueries
from llcps.store.tables import MAX_BRANCH_NAME, Branch, Episode, Operator, OperatorExecution, Run, Trial, TrialBlockRow, TrialChangeRow, TrialExamplesRow, WorldModel
from llcps.store.transactions import CHANGED_HINT, utc_now
from llcps.store.trials import iso_timestamp
from llcps.store.visibility import Link


#: The root branch every store starts with.
MAIN_BRANCH = "main"

CURRENT_BRANCH_KEY = "current_branch"

#: ``at=`` / ``to=`` value meaning "the pretraining point": the last trial of the first
#: unbroken run of pretraining trials a branch sees (:meth:`BranchQueries._pretrain_point`).
PRETRAIN = "pretrain"

RESET_TARGETS: tuple[str, ...] = (PRETRAIN, "empty")

_WHITESPACE = re.compile(r"\s")


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


class BranchQueries(SettingQueries):
    """Branches, the current branch, and the visibility chains every other query reads through."""

    def __init__(self, engine: Engine, url: URL) -> None:
        super().__init__(engine, url)
        self._branch_ids: dict[str, int] = {}  # name -> id, for writing trials; dropped when a branch goes
        # branch id -> the last trial id this process saw packed in a block (a hint for
        # llcps.store.training_set.seal_blocks; emptied when trials go)
        self._sealed: dict[int, int] = {}
        self._packs_blocks = True  # False for an outdated store opened as it is (llcps.store.store)
        self._forks_checked: set[tuple[int, int, int]] = set()  # (branch id, parent id, fork point) within the parent's head

    def _branches(self, conn: Connection) -> list[Any]:
        rows = list(conn.execute(select(Branch.id, Branch.name, Branch.parent_id, Branch.fork_point, Branch.created_at).order_by(Branch.id)))
        for r in rows:
            if not isinstance(r.name, str) or not isinstance(r.fork_point, int) or not isinstance(r.parent_id, int | None):
                raise StoreError(f"branch row {r.id} is malformed (name {r.name!r}, parent {r.parent_id!r}, fork point {r.fork_point!r})", hint=CHANGED_HINT)
        return rows

    def _chain(self, conn: Connection, name: str, rows: list[Any] | None = None) -> list[Link]:
        tree = visibility.Tree(self._branches(conn) if rows is None else rows)
        links = tree.chain(name)
        for link in links:
            self._check_fork(conn, tree, tree.by_id[link.branch_id])
        return links

    def _check_fork(self, conn: Connection, tree: visibility.Tree, row: Any) -> None:
        """Refuse a branch whose fork point lies beyond its parent's last visible trial:
        every fork llcps makes is at a trial the parent sees (or 0), so a later one is
        a changed row, and the branch would see the parent's trials still to come.
        Checked once per row and :class:`Store`."""
        if row.parent_id is None or row.fork_point == 0:
            return
        key = (row.id, row.parent_id, row.fork_point)
        if key in self._forks_checked:
            return
        parent = tree.by_id[row.parent_id]
        head = self._max_visible(conn, tree.chain(parent.name))
        if row.fork_point > head:
            raise StoreError(
                f"branch {row.name!r} forks from {parent.name!r} at trial {row.fork_point}, beyond {parent.name!r}'s last trial ({head})",
                hint=CHANGED_HINT,
            )
        self._forks_checked.add(key)

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

    def _min_visible(self, conn: Connection, chain: Sequence[Link], *extra: ColumnElement[bool]) -> int | None:
        found: list[int] = []
        for link in chain:
            stmt = select(func.min(Trial.id)).where(Trial.branch_id == link.branch_id, *extra)
            if link.limit is not None:
                stmt = stmt.where(Trial.id <= link.limit)
            value = conn.scalar(stmt)
            if value is not None:
                found.append(int(value))
        return min(found) if found else None

    def _pretrain_point(self, conn: Connection, chain: Sequence[Link]) -> int:
        """The paper's "reset to the pretraining data": the last trial of the first unbroken
        run of pretraining trials the chain sees, in id order (0 when it sees none).

        A trial of any other source (plan, exploration, replay) ends the run, so a branch
        forked here sees no exploration trial, nor an operator or model learned after
        one, even when more pretraining came later (``make run`` run twice).
        """
        first = self._min_visible(conn, chain, Trial.source == PRETRAIN)
        if first is None:
            return 0
        other = self._min_visible(conn, chain, Trial.source != PRETRAIN, Trial.id > first)
        if other is None:
            return self._max_visible(conn, chain, Trial.source == PRETRAIN)
        return self._max_visible(conn, chain, Trial.source == PRETRAIN, Trial.id < other)

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
                the parent's pretraining point (the last trial of the first unbroken
                run of pretraining trials it sees; 0 if it sees none), or
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
            conn.execute(insert(Branch).values(name=name, parent_id=chain[0].branch_id, fork_point=fork, created_at=utc_now()))
            return self._info(conn, name)

    def _fork_point(self, conn: Connection, chain: Sequence[Link], at: int | str | None) -> int:
        if at is None:
            return self._max_visible(conn, chain)
        if isinstance(at, str):
            if at == PRETRAIN:
                return self._pretrain_point(conn, chain)
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
            keep = self._pretrain_point(conn, chain)
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
            writers=tuple(writers.writers(conn, name)),
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
        conn.execute(delete(TrialExamplesRow).where(TrialExamplesRow.trial_id.in_(trial_ids)))
        held = select(Trial.id).where(
            clauses["trial"], Trial.branch_id == TrialBlockRow.branch_id, Trial.id.between(TrialBlockRow.first_id, TrialBlockRow.last_id)
        )
        conn.execute(delete(TrialBlockRow).where(held.exists()))
        self._sealed.clear()
        conn.execute(delete(Trial).where(clauses["trial"]))
        conn.execute(delete(Episode).where(clauses["episode"]))

    def delete_branch(self, name: str, *, dry_run: bool, force: bool = False) -> BranchChange:
        """Remove a branch and everything it owns.

        Refused for ``main``, the current branch, branches with children and (without
        ``force``) a branch a live process writes to (:mod:`llcps.store.writers`).
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
            self._stop_writers(conn, change, force=force)
            self._apply_removal(conn, clauses)
            conn.execute(delete(Branch).where(Branch.id == clauses["branch_id"]))
        self._branch_ids.pop(name, None)
        return _applied(change)

    @staticmethod
    def _stop_writers(conn: Connection, change: BranchChange, *, force: bool) -> None:
        """Refuse a removal from a branch a live process writes to; with ``force``, mark
        those runs (and their running episodes) ``aborted``: their process fails at its
        next write, and what it wrote so far goes with the removal."""
        live = [w for w in change.writers if w.live and not w.this_process]  # this process knows what it does
        stale = [w.run_id for w in change.writers if not w.live]
        if stale:  # left running by a process that is gone: it ended, unrecorded
            conn.execute(update(Run).where(Run.id.in_(stale), Run.status == "running").values(status="abandoned"))
        if not live:
            return
        if not force:
            raise StoreError(
                f"branch {change.branch!r} is being written to: {'; '.join(w.describe() for w in live)}",
                hint="wait for it to finish (or stop it), then run this again; --force does it now: that command fails at "
                f"its next write, and what it wrote so far goes too ({change.summary.split(' from branch')[0].replace('would remove ', '')})",
            )
        ids = [w.run_id for w in live]
        conn.execute(update(Run).where(Run.id.in_(ids), Run.status == "running").values(status="aborted", finished_at=utc_now()))
        conn.execute(update(Episode).where(Episode.run_id.in_(ids), Episode.status == "running").values(status="aborted", finished_at=utc_now()))

    def reset_branch(self, name: str | None, *, to: str = PRETRAIN, dry_run: bool, force: bool = False) -> BranchChange:
        """Drop a branch's own experience after a point.

        Args:
            name: the branch (None: the current one).
            to: ``"pretrain"`` keeps its own trials up to its pretraining point (the
                last trial of the first unbroken run of pretraining trials it sees)
                and operators/models with a watermark up to it;
                ``"empty"`` removes all it owns.
            dry_run: only count what would go.
            force: reset even while a live process writes to the branch (see :meth:`delete_branch`).
        """
        if to not in RESET_TARGETS:
            raise LlcpsError(f"unknown reset target {to!r}", hint=f"use one of: {', '.join(RESET_TARGETS)}")
        with self._write() as conn:
            name = self._name(conn, name)
            change, clauses = self._removal(conn, name, "reset", to)
            if not dry_run:
                self._stop_writers(conn, change, force=force)
                self._apply_removal(conn, clauses)
        return change if dry_run else _applied(change)

    def _branch_id(self, conn: Connection, name: str) -> int:
        bid = self._branch_ids.get(name)
        if bid is None:
            bid = self._chain(conn, name)[0].branch_id
            self._branch_ids[name] = bid
        return bid


def _applied(change: BranchChange) -> BranchChange:
    return dataclasses.replace(change, dry_run=False)
