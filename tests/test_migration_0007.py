"""Revision 0007: physics cache entries gain a seal; entries stored before carry none,
are checked when next read, and are sealed once they pass."""

from __future__ import annotations

import sqlite3
import zlib
from contextlib import closing
from datetime import datetime
from pathlib import Path

from make_store_fixtures import make as make_store

from llcps.domain import ControllerParams, EntityFeatures
from llcps.trial_records import Outcome, TrialSpec
from llcps.sim.cache import encode_result
from llcps.sim.trial import TrialResult
from llcps.store import Store, migrations
from llcps.store import physics_cache as pc

BEFORE = migrations.known_revisions()[migrations.known_revisions().index("0007") - 1]
STATE = zlib.compress(b"BULLET-state" + bytes(200))
RESULT = TrialResult(
    spec=TrialSpec("push", ("block",), ControllerParams(0.4, 0.15, "left")),
    features=(EntityFeatures("box", 0.001, "red", 0.6, 0.8, 0.6, 0.0),),
    before=frozenset({("visible", "block")}),
    after=frozenset({("visible", "block")}),
    outcome=Outcome.between({("visible", "block")}, {("visible", "block")}),
    sim_steps=10,
    wall_seconds=0.5,
)


def test_an_entry_stored_before_seals_is_checked_once_then_sealed(tmp_path: Path) -> None:
    db = make_store(BEFORE, tmp_path)
    result = encode_result(RESULT)
    with closing(sqlite3.connect(db)) as conn, conn:
        conn.execute(
            "INSERT INTO physics_cache (key, result, end_state, sha256, size, hits, created_at, last_used) VALUES (?, ?, ?, ?, ?, 0, ?, ?)",
            ("k" * 64, result, STATE, pc.content_hash(result, STATE), len(result) + len(STATE), datetime(2026, 1, 1), datetime(2026, 1, 1)),
        )
    with Store.open(str(db), allow_outdated=True) as store:
        assert store.upgrade() == (BEFORE, migrations.head_revision())
    with closing(sqlite3.connect(db)) as conn:
        assert conn.execute("SELECT seal FROM physics_cache").fetchall() == [(None,)]
    checked: list[bytes] = []
    with Store.open(str(db)) as store:
        for _ in range(2):
            cache = pc.StorePhysicsCache(store.engine, key_file=tmp_path / "k.key")
            got = cache.get("k" * 64, check=checked.append, trust=lambda state: None)
            cache.flush()
            assert got is not None and got.result == RESULT and got.end_state == STATE
    assert checked == [STATE]  # the first read checked it and sealed it; the second trusted the seal
