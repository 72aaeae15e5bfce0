"""The lifelong training set: the trials a branch sees, and their symbolic changes.

Every trial the robot executes is written here (with the change it made to the
symbolic state, in the same transaction) and read back through its branch's
visibility chain: a model refit loads the whole visible set, so reading is the hot
path (see :meth:`TrialQueries._read_by_link`). Rows become records in
:mod:`llcps.store.trials` and :mod:`llcps.store.trial_changes`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable, Sequence

from sqlalchemy import ColumnElement, Connection, bindparam, delete, func, insert, select
from sqlalchemy.exc import IntegrityError

from llcps.domain import check_id
from llcps.trial_records import TrialChange, TrialRecord
from llcps.training import TrainingChanges, TrainingSet, position_after
from llcps.errors import LlcpsError, StoreError
from llcps.store import backends, visibility
from llcps.store.branches import BranchQueries
from llcps.store.tables import Trial, TrialBlockRow, TrialChangeRow, TrialExamplesRow
from llcps.store.transactions import utc_now
from llcps.store.trial_changes import CHANGE_COLUMNS, UNKNOWN, ChangeDecoder, change_row
from llcps.store.trials import TRIAL_COLUMNS, TrialDecoder, gc_paused, trial_row
from llcps.store.visibility import Link

if TYPE_CHECKING:  # numpy loads with the blocks, when trials are written or read as columns
    from llcps.store.trial_blocks import TrialColumns


_INSERT_TRIAL = insert(Trial)
_INSERT_TRIALS = insert(Trial).returning(Trial.id, sort_by_parameter_order=True)


def _trial_id(record: TrialRecord) -> int:
    return record.id  # type: ignore[return-value]


def _change_id(change: TrialChange) -> int:
    return change.trial_id  # type: ignore[return-value]


def seal_blocks(conn: Connection, branch_ids: Sequence[int], trial_ids: Sequence[int], sealed: dict[int, int] | None = None) -> None:
    """Pack the full blocks of the branches just written to (:mod:`llcps.store.trial_blocks`),
    in the transaction that wrote trials ``trial_ids`` to branches ``branch_ids`` (in pairs).

    Args:
        sealed: branch id -> the last trial id known to be in a block, kept between calls
            by the caller: a hint that spares a durable single-trial write the query for
            it. Another process may have packed more since, which only makes the next
            look come sooner; a removal of trials must empty it.
    """
    from llcps.store import trial_blocks

    newest: dict[int, int] = {}
    for branch_id, trial_id in zip(branch_ids, trial_ids, strict=True):
        newest[branch_id] = max(newest.get(branch_id, 0), trial_id)
    for branch_id, trial_id in newest.items():
        hint = None if sealed is None else sealed.get(branch_id)
        if hint is not None and trial_id - hint < trial_blocks.BLOCK:
            continue
        last = _seal_branch(conn, branch_id, trial_id, most=len(trial_ids) // trial_blocks.BLOCK + 1)
        if sealed is not None:
            sealed[branch_id] = last


_LAST_BLOCK = (
    select(TrialBlockRow.last_id)
    .where(TrialBlockRow.branch_id == bindparam("branch_id"))
    .order_by(TrialBlockRow.first_id.desc())
    .limit(1)
)


def _seal_branch(conn: Connection, branch_id: int, newest: int, *, most: int) -> int:
    """Pack full blocks of the branch's trials after its last block
    (:mod:`llcps.store.trial_blocks`), at most ``most``, in the transaction that stored
    them (the newest of them ``newest``).

    One more block than a transaction's trials fill keeps up with any writer, and
    packs the trials of a store made before blocks existed one block per
    transaction, so that no single write carries them all.

    A trial the decoder refuses leaves its block unpacked: reads then go to the rows,
    and name the trial as they always did.
    """
    from llcps.store import trial_blocks

    last = conn.scalar(_LAST_BLOCK, {"branch_id": branch_id})
    if last is None:  # no block yet: from before the branch's first trial
        last = (conn.scalar(select(func.min(Trial.id)).where(Trial.branch_id == branch_id)) or 1) - 1
    if newest - last < trial_blocks.BLOCK:  # fewer ids than a block since the last one: no count needed
        return last
    pending = conn.scalar(select(func.count()).select_from(Trial).where(Trial.branch_id == branch_id, Trial.id > last)) or 0
    names = {branch_id: str(branch_id)}
    while pending >= trial_blocks.BLOCK and most > 0:
        most -= 1
        rows = conn.execute(
            select(*TRIAL_COLUMNS).where(Trial.branch_id == branch_id, Trial.id > last).order_by(Trial.id).limit(trial_blocks.BLOCK)
        )
        try:
            with gc_paused():
                columns = trial_blocks.from_records(TrialDecoder(names).decode_result(rows), {str(branch_id): branch_id})
        except StoreError:
            return last
        first, last = int(columns.id[0]), int(columns.id[-1])
        conn.execute(
            insert(TrialBlockRow).values(branch_id=branch_id, first_id=first, last_id=last, trials=len(columns), data=trial_blocks.pack(columns))
        )
        pending -= len(columns)
    return last


class TrialQueries(BranchQueries):
    """Writing trials and their changes, and reading what a branch sees of them."""

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
        now = utc_now()
        try:
            with self._write() as conn:
                rows = [trial_row(t, branch_id=self._branch_id(conn, t.branch), created_at=now) for t in trials]
                if len(rows) == 1:
                    ids = [conn.execute(_INSERT_TRIAL, rows[0]).inserted_primary_key[0]]
                else:
                    ids = list(conn.execute(_INSERT_TRIALS, rows).scalars())
                if changes is not None:
                    self._insert_changes(conn, [(i, c) for i, c in zip(ids, changes) if c is not None])
                if self._packs_blocks:
                    seal_blocks(conn, [row["branch_id"] for row in rows], ids, self._sealed)
                return ids
        except StoreError as exc:  # raised from the database's error, its __cause__
            if isinstance(exc.__cause__, IntegrityError) and backends.violates_foreign_key(exc.__cause__):
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

    def visible_columns(
        self,
        branch: str | None,
        *,
        source: str | None = None,
        scenario: str | None = None,
        solved: bool | None = None,
        episode: int | None = None,
    ) -> TrialColumns:
        """The trials ``branch`` sees (None: the current branch), in id order, as columns:
        what :meth:`visible_trials` gives, without a Python object per trial.

        Each link of the branch's chain is read as its packed blocks
        (:mod:`llcps.store.trial_blocks`) and the rows after them. A block that fails its
        checks, or whose trial count no longer matches the rows in its range, is not used:
        that link is read from its rows from there on.

        Args:
            source, scenario, solved, episode: keep only trials with these values.
        """
        import numpy as np

        from llcps.store import trial_blocks

        if episode is not None:
            check_id(episode, "episode")
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            decoder = TrialDecoder({link.branch_id: link.name for link in chain})
            branch_ids = {link.name: link.branch_id for link in chain}
            parts: list[TrialColumns] = []
            with gc_paused():
                for link in chain[::-1]:  # the oldest ancestor's trials first
                    packed, sealed = self._read_blocks(conn, link) if self._packs_blocks else ([], 0)
                    parts += packed
                    rows = select(*TRIAL_COLUMNS).where(Trial.branch_id == link.branch_id, Trial.id > sealed)
                    if link.limit is not None:
                        rows = rows.where(Trial.id <= link.limit)
                    parts.append(trial_blocks.from_records(decoder.decode_result(conn.execute(rows.order_by(Trial.id))), branch_ids))
        columns = replace(trial_blocks.concat(parts), branch_names=tuple((link.branch_id, link.name) for link in chain))
        if len(columns) > 1 and not (columns.id[1:] > columns.id[:-1]).all():  # links whose id ranges overlap
            columns = columns.where(np.argsort(columns.id, kind="stable"))
        keep = np.ones(len(columns), dtype=bool)
        for field, value in (("source", source), ("scenario", scenario)):
            if value is not None:
                keep &= columns.codes_of(field, value)
        if solved is not None:
            keep &= columns.bit(trial_blocks.SOLVED_BIT) == solved
        if episode is not None:
            keep &= columns.episode_id == episode
        return columns if keep.all() else columns.where(keep)

    @staticmethod
    def _read_blocks(conn: Connection, link: Link) -> tuple[list[TrialColumns], int]:
        """A link's usable blocks, in id order, cut at its limit, and the last trial id they cover (0: none)."""
        from llcps.store import trial_blocks
        query = select(TrialBlockRow.first_id, TrialBlockRow.last_id, TrialBlockRow.trials, TrialBlockRow.data).where(
            TrialBlockRow.branch_id == link.branch_id
        )
        if link.limit is not None:
            query = query.where(TrialBlockRow.first_id <= link.limit)
        parts: list[TrialColumns] = []
        sealed = 0
        for first, last, trials, data in conn.execute(query.order_by(TrialBlockRow.first_id)):
            if not (isinstance(first, int) and isinstance(last, int) and sealed < first <= last):
                break
            try:
                columns = trial_blocks.unpack(data, link.branch_id)
            except trial_blocks.BlockError:
                break
            if len(columns) != trials or len(columns) == 0 or columns.id[0] != first or columns.id[-1] != last:
                break
            rows = conn.scalar(select(func.count()).select_from(Trial).where(Trial.branch_id == link.branch_id, Trial.id.between(first, last)))
            if rows != trials:  # trials deleted or added in its range outside llcps
                break
            parts.append(columns if link.limit is None or last <= link.limit else columns.where(columns.id <= link.limit))
            sealed = last if link.limit is None else min(last, link.limit)
        return parts, sealed

    def training_set(self, branch: str | None) -> tuple[TrainingSet, TrainingChanges]:
        """What ``branch`` sees now, as an episode learns from it: its trials and their
        known changes, each read from the store only when something needs them (an
        episode that counts its new trials into a stored model never does).

        Raises:
            StoreError (when they are read): trials or changes up to the set's watermark
                were deleted or added since it was taken (the branch changed under it).
        """
        with self._read() as conn:
            name = self._name(conn, branch)
            chain = self._chain(conn, name)
            watermark = self._max_visible(conn, chain)
            trials = self._count(conn, chain, Trial.id <= watermark)
            changes = self._count_changes(conn, chain, Trial.id <= watermark)

        def changed(what: str, expected: int, found: int) -> StoreError:
            return StoreError(
                f"branch {name!r} now has {found} {what} up to trial {watermark}, not the {expected} it had when the episode started",
                hint="another process deleted or backfilled trials of the branch meanwhile; run again",
            )

        def load_trials() -> list[TrialRecord]:
            records = self.visible_trials(name)
            end = position_after(records, watermark)
            if end != trials:
                raise changed("trials", trials, end)
            return records[:end]

        def load_changes() -> dict[int, TrialChange]:
            found = {i: c for i, c in self.visible_changes(name).items() if i <= watermark}
            if len(found) != changes:
                raise changed("known changes", changes, len(found))
            return found

        return TrainingSet(trials, watermark, load_trials), TrainingChanges(changes, watermark, load_changes)

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

    # ------------------------------------------------------ encoded examples

    def visible_examples(self, branch: str | None, code: str) -> dict[int, bytes]:
        """The stored encoded goal examples of the trials ``branch`` sees, by trial id,
        of those encoded by model code ``code`` (the bytes are untrusted: the model
        layer that reads them validates them)."""
        with self._read() as conn:
            chain = self._chain(conn, self._name(conn, branch))
            rows = conn.execute(
                select(TrialExamplesRow.trial_id, TrialExamplesRow.data)
                .join(Trial, Trial.id == TrialExamplesRow.trial_id)
                .where(visibility.clause(chain, Trial.branch_id, Trial.id), TrialExamplesRow.code == code)
            ).all()
        return {int(trial_id): data for trial_id, data in rows if isinstance(data, (bytes, bytearray, memoryview))}

    def save_examples(self, code: str, examples: dict[int, bytes]) -> None:
        """Keep trials' encoded goal examples (replacing what other code encoded for them).

        Derived data: a concurrent writer that kept the same trial's examples first wins.
        """
        if not examples:
            return
        rows = [{"trial_id": int(trial_id), "code": code, "data": bytes(data)} for trial_id, data in examples.items()]
        try:
            with self._write() as conn:
                ids = [row["trial_id"] for row in rows]
                for start in range(0, len(ids), 5_000):
                    conn.execute(delete(TrialExamplesRow).where(TrialExamplesRow.trial_id.in_(ids[start : start + 5_000])))
                conn.execute(insert(TrialExamplesRow), rows)
        except StoreError as exc:
            if not isinstance(exc.__cause__, IntegrityError):
                raise
            # another process kept them meanwhile (or a trial is gone): nothing to keep

    def get_change(self, trial_id: int) -> TrialChange | None:
        """One trial's symbolic change; None when it is unknown or not recorded."""
        with self._read() as conn:
            row = conn.execute(select(*CHANGE_COLUMNS).where(TrialChangeRow.trial_id == trial_id)).first()
        return None if row is None else ChangeDecoder().decode(row)

    def count_visible_changes(self, branch: str | None) -> int:
        """How many trials ``branch`` sees have a known change (part of a fitted model's identity)."""
        with self._read() as conn:
            return self._count_changes(conn, self._chain(conn, self._name(conn, branch)))

    @staticmethod
    def _count_changes(conn: Connection, chain: Sequence[Link], *extra: ColumnElement[bool]) -> int:
        stmt = (
            select(func.count())
            .select_from(TrialChangeRow)
            .join(Trial, Trial.id == TrialChangeRow.trial_id)
            .where(visibility.clause(chain, Trial.branch_id, Trial.id), TrialChangeRow.source != UNKNOWN, *extra)
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
