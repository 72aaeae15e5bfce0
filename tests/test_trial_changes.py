"""Trial changes in the store: written with their trial, read back checked, visible as
their trial is, carried by payloads, and recovered for older stores by replay."""

from __future__ import annotations

import json
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import update
from typer.testing import CliRunner

from llcps.cli.main import app
from llcps.cps.backfill import backfill_changes
from llcps.domain import fluent
from llcps.trial_records import Body, TrialChange
from llcps.errors import LlcpsError, StoreError
from llcps.experiments.transfer import export_branches, import_payload
from llcps.cps.pretraining import random_trial
from llcps.sim.world import World
from llcps.store import Store, migrations
from llcps.store import backends
from llcps.store.trial_changes import pack_atoms
from llcps.store.tables import Trial, TrialChangeRow

BODIES = (
    Body("cube", "object", "box", (0.37, -0.33, 0.0), (0.43, -0.27, 0.06), (0.4, -0.3, 0.03)),
    Body("bucket", "container", "cylinder", (0.27, -0.72, -0.45), (0.53, -0.46, -0.21), (0.4, -0.59, -0.33)),
    Body("table", "table", None, (-0.3, -0.45, -0.45), (1.05, 0.45, 0.0), (0.375, 0.0, -0.225)),
)


def _packed_body(name: str, kind: str, shape: str, *, lo: float = 0.0) -> bytes:
    """One body in the layout of ``pack_bodies``, whatever its fields (to damage a row with)."""
    return b"\x01\x01\x00" + struct.pack("<9d", lo, 0, 0, 1, 1, 1, 0.5, 0.5, 0.5) + "\x1f".join((name, kind, shape)).encode()


def change(k: int = 0) -> TrialChange:
    before = {fluent("on", "cube", "table"), fluent("touching", "cube", "table"), fluent("visible", "cube")}
    after = {fluent("in", "cube", "bucket"), fluent("touching", "bucket", "cube"), fluent("visible", "cube")}
    if k % 2:
        after = set(before)
    return TrialChange.between(before, after, BODIES)


def test_a_change_is_stored_with_its_trial_and_read_back(store: Store, new_trial) -> None:
    trial_id = store.add_trial(new_trial(1), change=change())
    stored = store.get_change(trial_id)
    assert stored is not None and stored.trial_id == trial_id and stored.source == "recorded"
    assert stored.added == {("in", "cube", "bucket"), ("touching", "bucket", "cube")}
    assert stored.deleted == {("on", "cube", "table"), ("touching", "cube", "table")}
    assert stored.bodies == BODIES and stored.before == change().before
    ids = store.add_trials([new_trial(2), new_trial(3), new_trial(4)], changes=[change(1), None, change(0)])
    visible = store.visible_changes("main")
    assert sorted(visible) == [trial_id, ids[0], ids[2]]
    assert not visible[ids[0]].added and store.get_change(ids[1]) is None
    assert store.count_visible_changes("main") == 3
    assert store.change_counts() == {"recorded": 3, "replayed": 0, "unknown": 0, "missing": 1}
    assert store.status().changes == {"recorded": 3, "replayed": 0, "unknown": 0, "missing": 1}


def test_changes_follow_their_trials_branches(store: Store, new_trial) -> None:
    first = store.add_trial(new_trial(1), change=change())
    store.create_branch("side", from_branch="main")
    side = store.add_trial(new_trial(2, branch="side"), change=change(1))
    later = store.add_trial(new_trial(3), change=change())
    assert sorted(store.visible_changes("main")) == [first, later]
    assert sorted(store.visible_changes("side")) == [first, side]
    assert sorted(store.visible_changes("side", after_id=first)) == [side]
    store.delete_branch("side", dry_run=False)
    assert store.get_change(side) is None and store.get_change(first) is not None


def test_a_change_count_mismatch_writes_nothing(store: Store, new_trial) -> None:
    with pytest.raises(LlcpsError, match="change"):
        store.add_trials([new_trial(1), new_trial(2)], changes=[change()])
    assert store.count_visible_trials("main") == 0


@pytest.mark.parametrize(
    ("column", "value", "message"),
    [
        ("added", b"\x01in\x1f\x1fbucket", "malformed atom"),  # an empty name
        ("added", b"\x01in\x1fa\x1fb\x1fc", "malformed atom"),  # four names
        ("added", b"\x01in\x1fcube\x1fbucket\x1e", "malformed atom"),  # an empty atom
        ("added", b"\x01\xff\xfe", "atoms are malformed"),  # not UTF-8
        ("before", b"\x02visible\x1fcube", "atoms are malformed"),  # an unknown layout
        ("before", b"\x00not json", "atoms are malformed"),  # text kept by the upgrade, never a list of atoms
        ("before", b"", "atoms are malformed"),
        ("bodies", _packed_body("cube", "spaceship", ""), "malformed body"),
        ("bodies", _packed_body("cube", "object", "cube"), "malformed body"),
        ("bodies", _packed_body("", "object", "box"), "malformed body"),
        ("bodies", _packed_body("cube", "object", "box", lo=float("nan")), "malformed body"),
        ("bodies", _packed_body("cube", "object", "box")[:-4], "bodies are malformed"),  # the shape cut off
        ("bodies", _packed_body("cube", "object", "box")[:40], "bodies are malformed"),  # numbers cut short
        ("bodies", b"\x02" + _packed_body("cube", "object", "box")[1:], "bodies are malformed"),  # an unknown layout
        ("bodies", b"\x00[{\"name\": 1}]", "bodies are malformed"),  # JSON kept by the upgrade, never a list of bodies
        ("bodies", b"", "bodies are malformed"),
        ("source", "guessed", "unknown source"),
        ("deleted", pack_atoms({("visible", "ghost")}), "inconsistent"),
    ],
)
def test_a_damaged_change_row_is_one_clear_error(store: Store, new_trial, column: str, value, message: str) -> None:
    trial_id = store.add_trial(new_trial(1), change=change())
    with store.engine.begin() as conn:
        conn.execute(update(TrialChangeRow).where(TrialChangeRow.trial_id == trial_id).values({column: value}))
    with pytest.raises(LlcpsError, match=message):
        store.visible_changes("main")


def test_payloads_carry_changes_onto_the_new_trial_ids(store: Store, tmp_path: Path, new_trial) -> None:
    store.create_branch("work", from_branch="main")
    ids = store.add_trials([new_trial(i, branch="work") for i in range(3)], changes=[change(0), None, change(1)])
    payload = export_branches(store, ["work"], snapshots=False, provenance=False)
    assert [c.trial_id for c in payload.changes] == [ids[0], ids[2]]
    with Store.open(str(tmp_path / "dest.db"), create=True) as dest:
        dest.add_trials([new_trial(50 + i) for i in range(4)])  # other ids
        mapping = import_payload(dest, payload)
        moved = dest.visible_changes("work")
        assert sorted(moved) == [mapping.trials[ids[0]], mapping.trials[ids[2]]]
        assert moved[mapping.trials[ids[0]]].added == change(0).added


# ------------------------------------------------------------------------------- backfill
def _store_at(path: Path, revision: str) -> Store:
    """A store built by Alembic up to ``revision`` (the schema before trial changes)."""
    backends.create_sqlite_file(path)
    engine = backends.make_engine(backends.resolve_url(str(path)), pooled=False)
    with engine.connect() as conn, conn.begin():
        migrations.upgrade(conn, revision)
    engine.dispose()
    return Store.open(str(path), allow_outdated=True)


def _real_trial(store: Store, new_trial, seed: int):
    """A pretraining trial simulated for real, stored with its start state (no change row)."""
    with World() as world:
        done = random_trial(world, seed)
    snapshot = store.put_snapshot(scene=done.scene.to_dict(), state=done.state)
    r = done.result
    record = new_trial(seed, spec=r.spec, features=r.features, outcome=r.outcome, sim_steps=r.sim_steps, solved=False, snapshot_id=snapshot)
    return store.add_trial(record), r


def _before_changes() -> str:
    """The revision just before trial changes (0004) in the chain."""
    return migrations.known_revisions()[migrations.known_revisions().index("0004") - 1]


def test_an_older_store_upgrades_and_its_changes_are_replayed_or_marked_unknown(tmp_path: Path, new_trial) -> None:
    path = tmp_path / "old.db"
    previous = _before_changes()
    with _store_at(path, previous) as old:
        assert old.revision == previous
        replayable, result = _real_trial(old, new_trial, 21)
        mismatched, _ = _real_trial(old, new_trial, 22)
        no_state = old.add_trial(new_trial(3))
        with old.engine.begin() as conn:  # a stored trial whose record the physics no longer gives
            conn.execute(update(Trial).where(Trial.id == mismatched).values(sim_steps=Trial.sim_steps + 1))
        old.upgrade()
    with Store.open(str(path)) as store:
        assert store.change_counts()["missing"] == 3
        seen = []
        report = backfill_changes(store, progress=lambda done, total: seen.append((done, total)))
        assert (report.replayed, report.mismatched, report.no_snapshot) == (1, 1, 1)
        assert report.mismatched_ids == [mismatched] and seen[-1] == (3, 3)
        change_ = store.get_change(replayable)
        assert change_ is not None and change_.source == "replayed"
        assert change_.after == result.after and change_.before == result.before
        assert store.get_change(mismatched) is None and store.get_change(no_state) is None
        assert store.change_counts() == {"recorded": 0, "replayed": 1, "unknown": 2, "missing": 0}
        assert backfill_changes(store).total == 0  # nothing left to do
        with pytest.raises(StoreError):
            store.put_changes([(replayable, None)])  # a change is recorded once


def test_db_upgrade_backfills_with_a_summary(tmp_path: Path, new_trial) -> None:
    path = tmp_path / "old.db"
    with _store_at(path, _before_changes()) as old:
        old.add_trial(new_trial(1))
    done = CliRunner().invoke(app, ["--db", str(path), "db", "upgrade", "--json"])
    assert done.exit_code == 0, done.output
    data = json.loads(done.stdout)
    assert data["to"] == migrations.head_revision() and data["changes"]["unknown_no_snapshot"] == 1
    again = CliRunner().invoke(app, ["--db", str(path), "db", "status", "--json"])
    assert json.loads(again.stdout)["changes"] == {"recorded": 0, "replayed": 0, "unknown": 1, "missing": 0}


def test_new_trials_of_pretraining_and_solving_record_their_change(store: Store) -> None:
    from llcps.cps.pretraining import pretrain

    summary = pretrain(store, branch=None, n=2, seed=4, control_loop_every=0)
    changes = store.visible_changes(None)
    assert sorted(changes) == summary.trial_ids
    for trial in store.visible_trials(None):
        c = changes[trial.id]
        assert c.source == "recorded" and {b.name for b in c.bodies} >= set(trial.spec.arguments)
        assert {"table", "floor"} <= {b.name for b in c.bodies}
        kinds = np.array([b.kind for b in c.bodies])
        assert {"table", "floor"} <= set(kinds)


def test_the_training_digest_reads_changes_as_stored_and_sees_every_field(store: Store, new_trial) -> None:
    from llcps.models.persistence import training_digest

    made = [new_trial(k) for k in range(4)]
    ids = store.add_trials(made, changes=[change(k) for k in range(4)])
    read, read_changes = store.visible_trials("main"), store.visible_changes("main")
    made = [replace(m, id=i) for m, i in zip(made, ids)]
    made_changes = {i: replace(change(k), trial_id=i) for k, i in enumerate(ids)}
    digest = training_digest(made, made_changes)
    assert training_digest(read, read_changes) == digest
    first = made_changes[ids[0]]
    cube = first.bodies[0]
    nudged = replace(first, bodies=(replace(cube, centre=(cube.centre[0] + 1e-12, *cube.centre[1:])), *first.bodies[1:]))
    assert training_digest(made, {**made_changes, ids[0]: nudged}) != digest
    seen = replace(first, before=first.before | {fluent("visible", "bucket")})
    assert training_digest(made, {**made_changes, ids[0]: seen}) != digest
    assert training_digest(made, {i: c for i, c in made_changes.items() if i != ids[0]}) != digest
