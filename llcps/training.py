"""What an episode learns from: a branch's trials and their changes, read from the store
only when something needs them, then the episode's own (:class:`TrainingSet`,
:class:`TrainingChanges`; ``Store.training_set`` takes them). An episode that counts its
new trials into a stored model never reads the trials before them, so what it reads does
not grow with the store."""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Callable, Iterable, Iterator, MutableMapping, Sequence
from typing import Any, overload

from llcps.trial_records import TrialChange, TrialRecord


def _record_id(record: TrialRecord) -> int:
    return record.id if record.id is not None else 0


class _Once:
    """What a loader returns, loaded on first use and kept (shared by a set's views)."""

    def __init__(self, load: Callable[[], Any]) -> None:
        self._load: Callable[[], Any] | None = load
        self._value: Any = None

    @property
    def loaded(self) -> bool:
        return self._load is None

    def get(self) -> Any:
        if self._load is not None:
            self._value = self._load()
            self._load = None
        return self._value


class TrainingSet(Sequence[TrialRecord]):
    """A branch's trials in id order, as an episode learns from them: the ``base`` trials
    its branch saw when the episode started (ids up to ``watermark``), read from the
    store only when something needs them, then the trials appended since (the ``tail``).

    An episode far into a life counts its new trials into a stored model, which never
    reads the trials before them; so what an episode reads does not grow with the store.
    Records are in increasing id order, the tail's ids above the watermark.

    Args:
        base: how many trials the branch saw (ids up to ``watermark``).
        watermark: the largest of their ids (0 if none).
        load: returns those ``base`` trials in id order.
    """

    def __init__(self, base: int, watermark: int, load: Callable[[], list[TrialRecord]]) -> None:
        self.base = base
        self.watermark = watermark
        self._prefix = _Once(load)
        self.tail: list[TrialRecord] = []

    @classmethod
    def of(cls, records: Sequence[TrialRecord]) -> TrainingSet:
        """A set whose base is ``records`` (in id order), already in memory."""
        held = list(records)
        return cls(len(held), _record_id(held[-1]) if held else 0, lambda: held)

    def prefix(self) -> list[TrialRecord]:
        """The base trials (read now if not yet)."""
        records: list[TrialRecord] = self._prefix.get()
        return records

    def append(self, record: TrialRecord) -> None:
        self.tail.append(record)

    def without(self, trial_ids: Iterable[int]) -> TrainingSet:
        """The same set with the tail's trials of ``trial_ids`` left out (the base is shared)."""
        left_out = set(trial_ids)
        view = TrainingSet(self.base, self.watermark, lambda: [])
        view._prefix = self._prefix
        view.tail = [r for r in self.tail if r.id not in left_out]
        return view

    def position_after(self, trial_id: int) -> int:
        """How many records have an id up to ``trial_id`` (the index of the first above it)."""
        if trial_id >= self.watermark:
            return self.base + bisect_right(self.tail, trial_id, key=_record_id)
        return bisect_right(self.prefix(), trial_id, key=_record_id)

    def __len__(self) -> int:
        return self.base + len(self.tail)

    @overload
    def __getitem__(self, index: int) -> TrialRecord: ...

    @overload
    def __getitem__(self, index: slice) -> Sequence[TrialRecord]: ...

    def __getitem__(self, index: int | slice) -> TrialRecord | Sequence[TrialRecord]:
        if isinstance(index, slice):
            start, stop, step = index.indices(len(self))
            if step == 1 and start >= self.base:
                return self.tail[start - self.base : max(start, stop) - self.base]
            return list(self)[index]
        position = index + len(self) if index < 0 else index
        if not 0 <= position < len(self):
            raise IndexError("training set index out of range")
        return self.tail[position - self.base] if position >= self.base else self.prefix()[position]

    def __iter__(self) -> Iterator[TrialRecord]:
        if self.base:
            yield from self.prefix()
        yield from self.tail


def position_after(records: Sequence[TrialRecord], trial_id: int) -> int:
    """How many of ``records`` (in id order) have an id up to ``trial_id``; a
    :class:`TrainingSet` answers without reading its base when ``trial_id`` is past it."""
    if isinstance(records, TrainingSet):
        return records.position_after(trial_id)
    return bisect_right(records, trial_id, key=_record_id)


class TrainingChanges(MutableMapping[int, TrialChange]):
    """The known symbolic changes of a :class:`TrainingSet`'s trials, by trial id: the
    base's (``base`` of them, for ids up to ``watermark``) read from the store only when
    one is looked up, then the ones set since (for ids above it)."""

    def __init__(self, base: int, watermark: int, load: Callable[[], dict[int, TrialChange]]) -> None:
        self.base = base
        self.watermark = watermark
        self._prefix = _Once(load)
        self.tail: dict[int, TrialChange] = {}

    def prefix(self) -> dict[int, TrialChange]:
        """The base's changes (read now if not yet)."""
        changes: dict[int, TrialChange] = self._prefix.get()
        return changes

    def __getitem__(self, trial_id: int) -> TrialChange:
        if trial_id > self.watermark:
            return self.tail[trial_id]
        return self.prefix()[trial_id]

    def __contains__(self, trial_id: object) -> bool:
        if isinstance(trial_id, int) and trial_id > self.watermark:
            return trial_id in self.tail
        return trial_id in self.prefix()

    def __setitem__(self, trial_id: int, change: TrialChange) -> None:
        if trial_id <= self.watermark:
            raise KeyError(f"trial {trial_id} is in the set's base: its change is the store's")
        self.tail[trial_id] = change

    def __delitem__(self, trial_id: int) -> None:
        del self.tail[trial_id]

    def __len__(self) -> int:
        return self.base + len(self.tail)

    def __iter__(self) -> Iterator[int]:
        if self.base:
            yield from self.prefix()
        yield from self.tail
