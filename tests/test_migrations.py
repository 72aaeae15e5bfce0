"""Schema revisions: old stores upgrade, newer and foreign files are refused untouched."""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import sqlite3
import subprocess
import sys
import zipfile
from contextlib import closing
from pathlib import Path

import numpy as np
import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from make_store_fixtures import make as make_store
from store_writer import sample_trial

from llcps import provenance
from llcps.domain import OUTCOME_NAMES
from llcps.errors import StoreError
from llcps.store import Store, migrations
from llcps.store.tables import VERSION_TABLE, Base, Trial


PAST_REVISIONS = migrations.known_revisions()[:-1]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_revisions_are_a_line_from_0001() -> None:
    revisions = migrations.known_revisions()
    # Ids are reserved per line of work, so the chain holds them in the order the work was
    # merged (0004 follows 0006): a store already at an earlier head still gets every later one.
    assert revisions[0] == "0001" and len(set(revisions)) == len(revisions)
    assert set(revisions) >= {"0001", "0002", "0003", "0004", "0005", "0006"}
    assert migrations.head_revision() == revisions[-1]
    assert (migrations.migrations_dir() / "env.py").is_file()


@pytest.mark.parametrize("revision", PAST_REVISIONS)
def test_old_store_upgrades_to_head_and_reads_and_writes(tmp_path: Path, revision: str) -> None:
    db = make_store(revision, tmp_path)  # Alembic up to the revision, rows written with plain SQL
    with pytest.raises(StoreError, match="older") as info:
        Store.open(str(db))
    assert "llcps db upgrade" in (info.value.hint or "")
    with Store.open(str(db), allow_outdated=True) as store:
        assert store.status().revision == revision  # status works on an outdated store
        assert store.upgrade() == (revision, migrations.head_revision())
    with Store.open(str(db)) as store:
        old = store.visible_trials("main")
        assert [(t.source, t.spec.action, t.outcome.bits()) for t in old] == [
            ("pretrain", "push", (0, 0, 0, 0, 1, 0)),
            ("exploration", "push_together", (0, 0, 1, 0, 0, 1)),
        ]
        assert old[1].features[1].shape == "sphere" and old[1].scenario == "scenario2" and old[1].episode_id is not None
        assert store.get_snapshot(old[0].snapshot_id).state == b"\x00state"  # type: ignore[arg-type]
        new_id = store.add_trial(sample_trial(1, source="plan"))
        assert new_id > old[-1].id
        store.create_branch("after-upgrade", at="pretrain")
        store.add_operator(branch="main", name="op", pddl="(:action op)", definition={}, scenario=None, episode_id=None)
        assert store.count_visible_trials("after-upgrade") == 1
        assert [o.name for o in store.visible_operators("main")] == ["op"]
        store.add_operator_execution(branch="main", operator="op", success=True, trial_id=new_id)
        assert [(c.operator, c.successes, c.failures) for c in store.operator_experience("main")] == [("op", 1, 0)]
    with closing(sqlite3.connect(db)) as conn:
        assert conn.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
        assert conn.execute("PRAGMA foreign_key_check").fetchall() == []


def test_head_schema_matches_the_typed_models(sqlite_store: Store) -> None:
    store = sqlite_store
    with store.engine.connect() as conn:
        context = MigrationContext.configure(conn, opts={"version_table": VERSION_TABLE, "compare_type": True})
        assert compare_metadata(context, Base.metadata) == []
    outcome_columns = [c for c in Trial.__table__.columns.keys() if c in OUTCOME_NAMES]
    assert tuple(outcome_columns) == OUTCOME_NAMES


def test_newer_store_is_refused_untouched(tmp_path: Path) -> None:
    db = tmp_path / "newer.db"
    Store.open(str(db), create=True).close()
    with closing(sqlite3.connect(db)) as conn, conn:
        conn.execute(f"UPDATE {VERSION_TABLE} SET version_num = '9999'")
    before = _digest(db)
    for kwargs in ({}, {"allow_outdated": True}, {"create": True}):
        with pytest.raises(StoreError, match="newer than this llcps") as info:
            Store.open(str(db), **kwargs)
        assert "upgrade the llcps package" in (info.value.hint or "") and "llcps db upgrade" in (info.value.hint or "")
    assert _digest(db) == before


def _foreign_sqlite(path: Path) -> None:
    with closing(sqlite3.connect(path)) as conn, conn:
        conn.execute("CREATE TABLE notes (body TEXT)")
        conn.execute("INSERT INTO notes VALUES ('mine')")


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (_foreign_sqlite, "SQLite database but not an llcps store"),
        (lambda p: p.write_text("name,value\na,1\n"), "not a SQLite database"),
        (lambda p: p.write_bytes(b""), "not a SQLite database"),
        (lambda p: p.write_bytes(b"SQLite format 3\x00" + b"\x00" * 10), "not a SQLite database"),
    ],
    ids=["foreign-sqlite", "csv", "empty", "truncated-header"],
)
@pytest.mark.parametrize("create", [False, True])
def test_files_that_are_not_llcps_stores_are_left_untouched(tmp_path: Path, make, message: str, create: bool) -> None:  # noqa: ANN001
    path = tmp_path / "other.db"
    make(path)
    before = _digest(path)
    with pytest.raises(StoreError, match=message):
        Store.open(str(path), create=create)
    assert _digest(path) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.db"]


def test_sqlite_with_llcps_id_but_foreign_tables_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "odd.db"
    _foreign_sqlite(path)
    with closing(sqlite3.connect(path)) as conn, conn:
        conn.execute("PRAGMA application_id = 1280066384")
    before = _digest(path)
    with pytest.raises(StoreError, match="not an llcps store"):
        Store.open(str(path), create=True)
    assert _digest(path) == before


def test_locations_that_cannot_hold_a_store(tmp_path: Path) -> None:
    with pytest.raises(StoreError, match="does not exist") as info:
        Store.open(str(tmp_path / "missing" / "llcps.db"), create=True)
    assert info.value.hint and not (tmp_path / "missing").exists()
    with pytest.raises(StoreError, match="no llcps database") as info:
        Store.open(str(tmp_path / "absent.db"))
    assert "db init" in (info.value.hint or "") and not (tmp_path / "absent.db").exists()
    with pytest.raises(StoreError, match="is a directory"):
        Store.open(str(tmp_path), create=True)
    with pytest.raises(StoreError, match="cannot parse database URL"):
        Store.open("postgresql+psycopg://user@host:notaport/db")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root reads any file")
def test_unreadable_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "locked.db"
    Store.open(str(path), create=True).close()
    path.chmod(0)
    try:
        with pytest.raises(StoreError, match="cannot read"):
            Store.open(str(path))
    finally:
        path.chmod(0o644)


def test_in_memory_store_works() -> None:
    with Store.open("sqlite://", create=True) as store:
        store.add_trial(sample_trial(1))
        assert store.count_visible_trials("main") == 1


def test_wheel_ships_the_migrations(tmp_path: Path) -> None:
    """A non-editable install must find migrations/ (packaged through the llcps/_migrations symlink)."""
    root = Path(__file__).parents[1]
    source = tmp_path / "src"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(root / name, source / name)
    for name in ("llcps", "migrations"):
        shutil.copytree(root / name, source / name, symlinks=True, ignore=shutil.ignore_patterns("__pycache__"))
    assert (source / "llcps" / "_migrations").is_symlink()
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "--no-build-isolation", "-w", str(tmp_path / "dist"), "-q"],
        check=True,
    )
    (wheel,) = (tmp_path / "dist").glob("llcps-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    shipped = {n.removeprefix("llcps/_migrations/") for n in names if n.startswith("llcps/_migrations/")}
    expected = {p.relative_to(root / "migrations").as_posix() for p in (root / "migrations").rglob("*") if p.suffix in (".py", ".mako")}
    assert expected <= shipped
    target = tmp_path / "installed"
    with zipfile.ZipFile(wheel) as zf:
        zf.extractall(target)
    check = "from llcps.store import Store; s = Store.open('w.db', create=True); import llcps; print(llcps.__file__, s.revision)"
    out = subprocess.run([sys.executable, "-c", check], cwd=tmp_path, env={"PYTHONPATH": str(target)}, capture_output=True, text=True, check=True)
    assert out.stdout.split() == [str(target / "llcps" / "__init__.py"), migrations.head_revision()]


def test_runs_stored_before_provenance_upgrade_and_new_runs_record_it(tmp_path: Path) -> None:
    """0005: runs gain their provenance; a run stored at 0002 keeps its fields and has none."""
    db = make_store("0002", tmp_path)
    with closing(sqlite3.connect(db)) as conn:
        assert "host" not in {row[1] for row in conn.execute("PRAGMA table_info(runs)")}
    with Store.open(str(db), allow_outdated=True) as store:
        assert store.upgrade() == ("0002", migrations.head_revision())
    with Store.open(str(db)) as store:
        (old,) = store.list_runs()
        assert (old.command, old.seed, old.status, old.llcps_version) == ("llcps solve scenario2", 12, "ok", "0.1.0")
        assert old.provenance.host is None and old.provenance.git_commit is None and old.provenance.cpu_count is None
        new_id = store.start_run(command="test", seed=1, config={}, branch="main")
        new = store.get_run(new_id)
    env = provenance.current()
    assert new.provenance == env
    assert env.python_version == platform.python_version() and env.cpu_count >= 1 and env.host
    assert env.numpy_version == np.__version__ and env.pybullet_version and env.torch_version and env.sklearn_version


def test_a_revision_is_named_with_its_place_in_the_chain() -> None:
    """Revision ids are names, not an order: `db upgrade` says where each sits in the chain."""
    from llcps.store.migrations import head_revision, known_revisions, revision_label

    chain = known_revisions()
    assert revision_label(head_revision()) == f"{head_revision()} ({len(chain)} of {len(chain)})"
    assert revision_label(chain[0]) == f"{chain[0]} (1 of {len(chain)})"
    assert revision_label("not-a-revision") == "not-a-revision"


def test_a_new_store_is_a_copy_of_the_migrated_schema_dated_now(tmp_path: Path) -> None:
    from datetime import datetime

    from llcps.store import backends, utc_now
    from llcps.store.store import _new_store_image

    migrated = tmp_path / "migrated.db"
    backends.create_sqlite_file(migrated)  # an empty store file: opening it runs every migration
    Store.open(str(migrated), create=True).close()
    _new_store_image()  # made before the clock is read, as in a process that made stores before
    before = utc_now()
    copied = tmp_path / "copied.db"
    with Store.open(str(copied), create=True) as store:
        assert store.revision == migrations.head_revision()
        store.create_branch("b", from_branch="main", at=0)  # it is a working store

    def contents(path: Path) -> tuple[list, list, list]:
        with closing(sqlite3.connect(path)) as conn:
            # Alembic's batch migrations write a table's constraints in no fixed order
            schema = sorted((kind, name, sorted(line.strip(" \t,") for line in (sql or "").splitlines()))
                            for kind, name, sql in conn.execute("SELECT type, name, sql FROM sqlite_master"))
            settings = sorted(conn.execute("SELECT key, value FROM settings").fetchall())
            main = conn.execute("SELECT id, name, parent_id, fork_point, created_at FROM branches WHERE name = 'main'").fetchall()
        return schema, settings, main

    schema, settings, main = contents(copied)
    assert (schema, settings) == contents(migrated)[:2]
    assert [row[:4] for row in main] == [row[:4] for row in contents(migrated)[2]] == [(1, "main", None, 0)]
    assert datetime.fromisoformat(main[0][4]) >= before  # dated when it was made, not when the image was


def test_a_creator_that_loses_the_race_leaves_the_winners_store_as_it_is(tmp_path: Path, monkeypatch) -> None:
    from llcps.store import backends

    path = tmp_path / "raced.db"
    with Store.open(str(path), create=True) as store:
        store.create_branch("winners", from_branch="main", at=0)
        dated = {b.name: b.created_at for b in store.list_branches()}
    before = path.read_bytes()
    assert backends.create_sqlite_file(path) is False  # the file is there by the time it links
    assert path.read_bytes() == before
    # both creators found no file; the winner's store is there when the loser links
    monkeypatch.setattr(backends, "check_sqlite_file", lambda *args, **kwargs: False)
    with Store.open(str(path), create=True) as store:
        assert {b.name: b.created_at for b in store.list_branches()} == dated
