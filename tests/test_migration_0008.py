"""Revision 0008: a change's states and bodies move from JSON into packed values, on a store
built by Alembic at the revision before; a value that does not convert stays refused, and the
downgrade gives every value back."""

from __future__ import annotations

import json
import sqlite3
from contextlib import closing
from pathlib import Path

import pytest
from make_store_fixtures import make as make_store

from llcps.trial_records import Body
from llcps.errors import LlcpsError
from llcps.store import Store, migrations
from llcps.store import backends

BEFORE = migrations.known_revisions()[migrations.known_revisions().index("0008") - 1]
BODIES = [
    {"name": "cube", "kind": "object", "shape": "box", "lo": [0.37, -0.33, 0], "hi": [0.43, -0.27, 0.06], "centre": [0.4, -0.3, 0.03]},
    {"name": "table", "kind": "table", "shape": None, "lo": [-0.3, -0.45, -0.45], "hi": [1.05, 0.45, 0.0], "centre": [0.375, 0.0, -0.225]},
]
BEFORE_STATE = [["on", "cube", "table"], ["touching", "cube", "table"], ["visible", "cube"]]
ADDED = [["in", "cube", "bucket"]]
DELETED = [["on", "cube", "table"]]
DAMAGED = '[{"name": 1}]'
DAMAGED_ATOMS = '[["in", 3, "x"]]'


def _old_store(tmp_path: Path) -> Path:
    """A store at the revision before, its two trials with a change each (the second's
    bodies and added atoms damaged)."""
    db = make_store(BEFORE, tmp_path)
    with closing(sqlite3.connect(db)) as conn, conn:
        for trial_id, added, bodies in ((1, json.dumps(ADDED), json.dumps(BODIES)), (2, DAMAGED_ATOMS, DAMAGED)):
            conn.execute(
                "INSERT INTO trial_changes (trial_id, source, before, added, deleted, bodies) VALUES (?, 'recorded', ?, ?, ?, ?)",
                (trial_id, json.dumps(BEFORE_STATE), added, json.dumps(DELETED), bodies),
            )
    return db


def test_upgrade_packs_bodies_and_keeps_a_damaged_value_refused(tmp_path: Path) -> None:
    db = _old_store(tmp_path)
    with Store.open(str(db), allow_outdated=True) as store:
        assert store.upgrade() == (BEFORE, migrations.head_revision())
    with closing(sqlite3.connect(db)) as conn:
        columns = {row[1]: row[2] for row in conn.execute("PRAGMA table_info(trial_changes)")}
        assert [columns[c] for c in ("before", "added", "deleted", "bodies")] == ["BLOB"] * 4
        assert conn.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
        assert conn.execute("PRAGMA foreign_key_check").fetchall() == []
    with Store.open(str(db)) as store:
        change = store.get_change(1)
        assert change is not None and change.bodies == tuple(Body.from_dict(b) for b in BODIES)
        assert change.bodies[1].shape is None and change.bodies[0].lo == (0.37, -0.33, 0.0)
        assert change.before == {tuple(a) for a in BEFORE_STATE} and change.deleted == {tuple(a) for a in DELETED}
        assert change.added == {("in", "cube", "bucket")}
        with pytest.raises(LlcpsError, match="malformed"):
            store.get_change(2)


def test_downgrade_gives_every_value_back(tmp_path: Path) -> None:
    db = _old_store(tmp_path)
    with Store.open(str(db), allow_outdated=True) as store:
        store.upgrade()
    from alembic import command

    plain = backends.make_engine(backends.resolve_url(str(db)), foreign_keys=False, pooled=False)
    with plain.connect() as conn, conn.begin():
        command.downgrade(migrations.alembic_config(conn), BEFORE)
    plain.dispose()
    with closing(sqlite3.connect(db)) as conn:
        rows = {row[0]: row[1:] for row in conn.execute("SELECT trial_id, before, added, deleted, bodies FROM trial_changes")}
    before, added, deleted, bodies = rows[1]
    assert (json.loads(before), json.loads(added), json.loads(deleted)) == (BEFORE_STATE, ADDED, DELETED)
    assert json.loads(bodies) == [{**b, "lo": [float(v) for v in b["lo"]]} for b in BODIES]
    assert rows[2][1] == DAMAGED_ATOMS and rows[2][3] == DAMAGED
