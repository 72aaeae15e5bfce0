"""Revision 0006: features move from JSON into one packed value, trials gain the cache
columns and the physics cache appears, on a store built by Alembic at the revision before."""

from __future__ import annotations

import json
import sqlite3
from contextlib import closing
from dataclasses import replace
from pathlib import Path

from make_store_fixtures import make as make_store

from llcps.domain import EntityFeatures
from llcps.store import Store, migrations
from llcps.store import physics_cache as pc
from llcps.store.trials import unpack_features

BEFORE = migrations.known_revisions()[migrations.known_revisions().index("0006") - 1]


def test_upgrade_packs_features_and_keeps_ids_growing(tmp_path: Path) -> None:
    db = make_store(BEFORE, tmp_path)  # two trials, written with plain SQL at the old revision
    with closing(sqlite3.connect(db)) as conn, conn:
        # trials 3..7 were written and deleted: AUTOINCREMENT must not hand their ids out again after the rebuild
        conn.execute("UPDATE sqlite_sequence SET seq = 7 WHERE name = 'trials'")
    with Store.open(str(db), allow_outdated=True) as store:
        assert store.upgrade() == (BEFORE, migrations.head_revision())
    with closing(sqlite3.connect(db)) as conn:
        columns = {row[1]: row[2] for row in conn.execute("PRAGMA table_info(trials)")}
        assert columns["features"] == "BLOB" and {"cache_hit", "simulation_wall_seconds"} <= set(columns)
        rows = conn.execute("SELECT features, cache_hit, simulation_wall_seconds FROM trials ORDER BY id").fetchall()
        assert [(unpack_features(f), hit, s) for f, hit, s in rows] == [
            ((EntityFeatures("box", 0.001, "red", 0.6, 0.8, 0.6, 0.0),), 0, None),
            ((EntityFeatures("cylinder", 0.002, "blue", 0.5, 1.0, 0.0, 0.0), EntityFeatures("sphere", 0.0005, "green", 0.7, 0.0, 1.0, 0.0)), 0, None),
        ]
        assert conn.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
    with Store.open(str(db)) as store:
        old = store.visible_trials("main")
        assert [len(t.features) for t in old] == [1, 2] and old[1].features[1].shape == "sphere"
        assert old[1].features[0].vector_magnitude == 0.5 and not any(t.cache_hit for t in old)
        assert store.add_trial(replace(old[1], id=None, created_at=None)) == 8
        assert pc.status(store).entries == 0


def test_downgrade_gives_the_features_back_as_json(tmp_path: Path) -> None:
    db = make_store(BEFORE, tmp_path)
    with Store.open(str(db), allow_outdated=True) as store:
        store.upgrade()
        engine = store.engine
        with engine.connect() as conn:
            before = [(t.spec.action, t.features) for t in store.visible_trials("main")]
            with conn.begin():
                migrations.upgrade(conn, "head")  # a no-op at head
    from alembic import command

    from llcps.store import backends

    plain = backends.make_engine(backends.resolve_url(str(db)), foreign_keys=False, pooled=False)
    with plain.connect() as conn, conn.begin():
        command.downgrade(migrations.alembic_config(conn), BEFORE)
    plain.dispose()
    with closing(sqlite3.connect(db)) as conn:
        features = [json.loads(row[0]) for row in conn.execute("SELECT features FROM trials ORDER BY id")]
        assert features == [[f.as_dict() for f in trial_features] for _, trial_features in before]
        assert "physics_cache" not in {row[0] for row in conn.execute("SELECT name FROM sqlite_master")}
    assert len(before) == 2
