"""Trials as columns and the packed blocks they are kept in: a branch's visible set read
as columns is the visible set read as records, trial for trial and field for field,
through forks inside a block, resets, and blocks that were damaged or went stale."""

from __future__ import annotations

import sqlite3
from contextlib import closing
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sqlalchemy import func, select
from store_writer import sample_trial

from llcps.api import columns_frame, trial_frame
from llcps.errors import StoreError
from llcps.store import Store, trial_blocks
from llcps.store.tables import TrialBlockRow
from llcps.store.trial_blocks import BlockError, from_records, pack, unpack

#: Trials per block in these tests: small, so a few dozen trials make several blocks.
SMALL = 8


@pytest.fixture(autouse=True)
def small_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(trial_blocks, "BLOCK", SMALL)


def _blocks(store: Store) -> list[tuple[int, int, int]]:
    with store._read() as conn:
        return [tuple(r) for r in conn.execute(select(TrialBlockRow.branch_id, TrialBlockRow.first_id, TrialBlockRow.last_id).order_by(TrialBlockRow.id))]


def assert_same(store: Store, branch: str, **filters: object) -> int:
    """The branch's visible set as columns gives the DataFrame its records give; returns its size."""
    records = store.visible_trials(branch, **filters)
    from_columns = columns_frame(store.visible_columns(branch, **filters))
    pd.testing.assert_frame_equal(from_columns, trial_frame(store, records), check_categorical=True)
    return len(records)


def _fill(store: Store, new_trial, branch: str, seeds: range, **overrides: object) -> None:
    for start in range(seeds.start, seeds.stop, 5):  # batches and single commits alike
        batch = [new_trial(s, branch=branch, **overrides) for s in range(start, min(start + 5, seeds.stop))]
        if len(batch) == 1:
            store.add_trial(batch[0])
        else:
            store.add_trials(batch)


def test_columns_equal_records_through_forks_inside_blocks(store: Store, new_trial) -> None:
    _fill(store, new_trial, "main", range(0, 21))
    store.create_branch("child", from_branch="main", at=13)  # inside main's second block
    _fill(store, new_trial, "child", range(100, 119), source="exploration", scenario="scenario2")
    _fill(store, new_trial, "main", range(21, 30))  # after the fork: child must not see them
    store.create_branch("grandchild", from_branch="child", at=max(t.id for t in store.visible_trials("child")) - 3)
    _fill(store, new_trial, "grandchild", range(200, 211), source="exploration", scenario="scenario3")
    assert len(_blocks(store)) >= 5  # main 3, child 2, grandchild 1: blocks were written as trials came
    assert [assert_same(store, b) for b in ("main", "child", "grandchild")] == [30, 13 + 19, 13 + 16 + 11]
    assert assert_same(store, "grandchild", source="exploration") == 27
    assert assert_same(store, "grandchild", scenario="scenario2", solved=False) >= 1
    assert assert_same(store, "main", scenario="nowhere") == 0


def test_a_reset_drops_the_blocks_it_cuts_and_later_trials_seal_again(store: Store, new_trial) -> None:
    _fill(store, new_trial, "main", range(0, 10))
    store.create_branch("b", from_branch="main")
    _fill(store, new_trial, "b", range(10, 30), source="exploration")
    before = _blocks(store)
    store.reset_branch("b", to="pretrain", dry_run=False)  # keeps none of b's own (exploration) trials
    branch_b = {bid for bid, _, _ in before} - {bid for bid, _, _ in _blocks(store)}
    assert branch_b and all(bid not in branch_b for bid, _, _ in _blocks(store))
    assert assert_same(store, "b") == 10
    _fill(store, new_trial, "b", range(30, 50), source="exploration")
    assert any(bid in branch_b for bid, _, _ in _blocks(store))
    assert assert_same(store, "b") == 30
    store.delete_branch("b", dry_run=False)
    assert all(bid not in branch_b for bid, _, _ in _blocks(store))


def test_the_pandas_frame_reads_columns(tmp_path: Path, new_trial) -> None:
    import llcps

    with Store.open(str(tmp_path / "s.db"), create=True) as store:
        _fill(store, new_trial, "main", range(0, 20))
        expected = trial_frame(store, store.visible_trials("main"))
    with llcps.open(tmp_path / "s.db") as wb:
        pd.testing.assert_frame_equal(wb.trials(), expected)
        assert len(wb.trials(solved=True)) == int(expected["solved"].sum())


def _raw(path: Path, sql: str, *args: object) -> None:
    with closing(sqlite3.connect(path)) as conn, conn:
        conn.execute(sql, args)


@pytest.mark.parametrize(
    "damage",
    [
        "UPDATE trial_blocks SET data = x'00' WHERE id = 1",
        "UPDATE trial_blocks SET data = substr(data, 1, length(data) - 8) WHERE id = 1",
        "UPDATE trial_blocks SET trials = 7 WHERE id = 1",
        "UPDATE trial_blocks SET first_id = last_id + 1 WHERE id = 1",
        "DELETE FROM trials WHERE id = 3",  # a trial of the block gone outside llcps: the block is stale
        "INSERT INTO trial_blocks (branch_id, first_id, last_id, trials, data) SELECT branch_id, first_id, last_id, trials, data FROM trial_blocks WHERE id = 1",
    ],
)
def test_a_damaged_or_stale_block_is_not_used(tmp_path: Path, new_trial, damage: str) -> None:
    path = tmp_path / "s.db"
    with Store.open(str(path), create=True) as store:
        _fill(store, new_trial, "main", range(0, 20))
    _raw(path, "PRAGMA foreign_keys = OFF")
    _raw(path, damage)
    with Store.open(str(path)) as store:
        assert assert_same(store, "main") == (19 if damage.startswith("DELETE") else 20)


def test_a_malformed_row_is_named_as_before_and_writes_go_on(tmp_path: Path, new_trial) -> None:
    path = tmp_path / "s.db"
    with Store.open(str(path), create=True) as store:
        _fill(store, new_trial, "main", range(0, 3))
    _raw(path, "UPDATE trials SET action = 'fly' WHERE id = 2")
    with Store.open(str(path)) as store:
        _fill(store, new_trial, "main", range(3, 20))  # the blocks that would hold trial 2 are not written
        assert not _blocks(store)
        for read in (store.visible_trials, store.visible_columns):
            with pytest.raises(StoreError, match="stored trial 2 is malformed"):
                read("main")


def _one_block() -> tuple[bytes, np.ndarray]:
    records = [sample_trial(s) for s in range(SMALL)]
    for i, r in enumerate(records):
        object.__setattr__(r, "id", i + 1)
    columns = from_records(records, {"main": 1})
    return pack(columns), columns.id


def test_a_block_round_trips() -> None:
    data, ids = _one_block()
    columns = unpack(data, 1)
    assert np.array_equal(columns.id, ids) and pack(columns) == data


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_any_damage_to_a_block_is_refused_or_read_within_bounds(data: st.DataObject) -> None:
    packed, _ = _one_block()
    at = data.draw(st.integers(0, len(packed) - 1))
    kind = data.draw(st.sampled_from(["flip", "cut", "grow"]))
    if kind == "flip":
        damaged = packed[:at] + bytes([packed[at] ^ data.draw(st.integers(1, 255))]) + packed[at + 1 :]
    elif kind == "cut":
        damaged = packed[:at]
    else:
        damaged = packed + data.draw(st.binary(min_size=1, max_size=64))
    try:
        columns = unpack(damaged, 1)
    except BlockError:
        return
    assert len(columns) == SMALL and np.isfinite(columns.rate).all()  # a flip in a value it cannot check


def test_a_read_decodes_only_the_rows_after_the_last_block(store: Store, new_trial, monkeypatch: pytest.MonkeyPatch) -> None:
    _fill(store, new_trial, "main", range(0, 3 * SMALL + 5))
    decoded: list[int] = []
    real = trial_blocks.from_records
    monkeypatch.setattr(trial_blocks, "from_records", lambda records, ids: decoded.append(len(records)) or real(records, ids))
    assert len(store.visible_columns("main")) == 3 * SMALL + 5 and decoded == [5]


def test_blocks_are_sealed_in_the_writing_transaction(store: Store, new_trial) -> None:
    _fill(store, new_trial, "main", range(0, 2 * SMALL + 3))
    with store._read() as conn:
        held = conn.scalar(select(func.sum(TrialBlockRow.trials)))
    assert held == 2 * SMALL and [(last - first) >= SMALL - 1 for _, first, last in _blocks(store)] == [True, True]


def test_trials_stored_before_blocks_existed_are_packed_a_block_per_write(tmp_path: Path, new_trial) -> None:
    path = tmp_path / "s.db"
    with Store.open(str(path), create=True) as store:
        _fill(store, new_trial, "main", range(0, 3 * SMALL + 2))
    _raw(path, "DELETE FROM trial_blocks")  # as a store upgraded to revision 0011 has them
    with Store.open(str(path)) as store:
        counts = []
        for seed in range(100, 104):
            store.add_trial(new_trial(seed))
            counts.append(len(_blocks(store)))
            assert_same(store, "main")
    assert counts == [1, 2, 3, 3]
