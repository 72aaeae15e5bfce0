"""Trials survive a killed writer, and concurrent writers neither fail nor lose trials
(on SQLite and on PostgreSQL)."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
from contextlib import closing
from pathlib import Path

import pytest
from sqlalchemy import select
from store_writer import sample_trial

from llcps.store import Store
from llcps.store.tables import Trial

WRITER = Path(__file__).parent / "fixtures" / "store_writer.py"


def _writer(db: str, branch: str, count: int, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, str(WRITER), str(db), branch, str(count), *extra],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _stored_ids(db: str) -> set[int]:
    if "://" not in db:  # SQLite: the file itself must be intact
        with closing(sqlite3.connect(db)) as conn:
            assert conn.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
    with Store.open(db) as store, store.engine.connect() as conn:
        return set(conn.scalars(select(Trial.id)))


@pytest.mark.parametrize("kill_after", [1, 150])
def test_kill_9_keeps_every_returned_trial(store_url: str, kill_after: int) -> None:
    db = store_url
    Store.open(db, create=True).close()
    child = _writer(db, "main", 0)
    assert child.stdout is not None
    returned = [int(child.stdout.readline()) for _ in range(kill_after)]
    os.kill(child.pid, signal.SIGKILL)  # mid-loop, quite possibly mid-transaction
    returned += [int(line) for line in child.stdout.read().split()]  # ids printed before the kill
    assert child.wait() == -signal.SIGKILL
    stored = _stored_ids(db)
    assert set(returned) <= stored
    assert len(stored) - len(returned) <= 1  # at most the commit that was cut off before printing
    with Store.open(db) as store:  # the store opens and reads normally afterwards
        assert store.count_visible_trials("main") == len(stored)
        assert store.add_trial(sample_trial(10**6)) > max(stored)


def test_two_concurrent_writers_both_finish_and_lose_nothing(store_url: str) -> None:
    db = store_url
    with Store.open(db, create=True) as store:
        store.create_branch("exp")
    count = 400
    writers = [_writer(db, branch, count, "--wait") for branch in ("main", "exp")]
    for writer in writers:  # both have the store open; release them together
        assert writer.stdout is not None and writer.stdout.readline().strip() == "ready"
    for writer in writers:
        assert writer.stdin is not None
        writer.stdin.write("go\n")
        writer.stdin.flush()
    for writer in writers:
        writer.stdin.close()  # type: ignore[union-attr]
    # A few KB each: sequential reads cannot fill a pipe and stall the other writer.
    outputs = [(w.stdout.read(), w.stderr.read(), w.wait()) for w in writers]  # type: ignore[union-attr]
    for _, err, code in outputs:
        assert code == 0, err
        assert "locked" not in err.lower()
    ids = [[int(line) for line in out.split()] for out, _, _ in outputs]
    assert [len(i) for i in ids] == [count, count]
    assert not set(ids[0]) & set(ids[1])
    assert _stored_ids(db) == set(ids[0]) | set(ids[1])
    with Store.open(db) as store:
        assert [t.id for t in store.visible_trials("exp")] == ids[1]
        assert [t.id for t in store.visible_trials("main")] == ids[0]
