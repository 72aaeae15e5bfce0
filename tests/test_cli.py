"""The `llcps db` and `llcps inspect trials` commands, as a user runs them."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import sqlite3
import subprocess
import sys
from contextlib import closing
from pathlib import Path

import pytest
from make_store_fixtures import make as make_store
from store_writer import sample_trial
from typer.testing import CliRunner

from llcps.cli.main import app
from llcps.domain import OUTCOME_NAMES
from llcps.store import Store, migrations
from llcps.store.tables import VERSION_TABLE


runner = CliRunner()
HEAD = migrations.head_revision()


def llcps(db: Path | str, *args: str, env: dict[str, str] | None = None):  # noqa: ANN201 - click Result
    return runner.invoke(app, ["--db", str(db), *args], env=env)


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _fill(location: str) -> str:
    with Store.open(location, create=True) as store:
        store.add_trials([sample_trial(i, scenario="scenario1" if i % 2 else None) for i in range(4)])
        store.add_trials([sample_trial(10 + i, source="exploration", scenario="scenario2", solved=i == 2) for i in range(3)])
    return location


@pytest.fixture
def db(store_url: str) -> str:
    """A store with pretraining and exploration trials on main (on each backend)."""
    return _fill(store_url)


@pytest.fixture
def sqlite_db(tmp_path: Path) -> Path:
    """The same store as a SQLite file, for tests that compare the file's bytes."""
    return Path(_fill(str(tmp_path / "llcps.db")))


def _contents(db: str | Path) -> object:
    """What a store holds: the file's digest (SQLite), else its branches and trials."""
    if "://" not in str(db):
        return _digest(Path(db))
    with Store.open(str(db)) as store:
        return [(b.name, b.fork_point, [t.id for t in store.visible_trials(b.name)]) for b in store.list_branches()]


def test_acceptance_flow(store_url: str) -> None:
    """Acceptance 2: init, branch, list --json, checkout, status."""
    db = store_url
    result = llcps(db, "db", "init")
    assert result.exit_code == 0, result.output
    assert f"schema {HEAD}" in result.stderr and result.stdout == ""
    assert llcps(db, "db", "init").exit_code == 0  # idempotent
    result = llcps(db, "db", "branch", "exp", "--from", "main")
    assert result.exit_code == 0 and "created branch exp from main" in result.stderr
    listed = json.loads(llcps(db, "db", "list", "--json").stdout)
    assert [(b["name"], b["parent"], b["fork_point"], b["own_trials"], b["visible_trials"], b["is_current"]) for b in listed] == [
        ("main", None, 0, 0, 0, True),
        ("exp", "main", 0, 0, 0, False),
    ]
    assert llcps(db, "db", "checkout", "exp").exit_code == 0
    status = json.loads(llcps(db, "db", "status", "--json").stdout)
    assert (status["current_branch"], status["branch"], status["revision"], status["up_to_date"]) == ("exp", "exp", HEAD, True)
    text = llcps(db, "db", "status")
    assert text.exit_code == 0 and "current branch" in text.stdout and "exp" in text.stdout and HEAD in text.stdout


def test_inspect_trials_json_and_filters(db: str) -> None:
    trials = json.loads(llcps(db, "inspect", "trials", "--json", "--limit", "0").stdout)
    assert [t["id"] for t in trials] == list(range(1, 8))
    for key in ("id", "branch", "source", "action", "rate", "movement_magnitude", "orientation", "arguments", "features", "outcome", "solved", "sim_steps", "wall_seconds", "seed"):
        assert key in trials[0]
    assert set(trials[0]["outcome"]) == set(OUTCOME_NAMES)
    assert len(trials[0]["features"]) == len(trials[0]["arguments"])

    def ids(*args: str) -> list[int]:
        result = llcps(db, "inspect", "trials", "--json", *args)
        assert result.exit_code == 0, result.output
        return [t["id"] for t in json.loads(result.stdout)]

    assert ids("--source", "exploration") == [5, 6, 7]
    assert ids("--solved") == [7]
    assert ids("--unsolved", "--scenario", "scenario2") == [5, 6]
    assert ids("--limit", "2") == [6, 7]
    assert ids("--scenario", "container") == ids("--scenario", "scenario2") == [5, 6, 7]  # an alias is the scenario
    unknown = llcps(db, "inspect", "trials", "--scenario", "nowhere")
    assert unknown.exit_code == 2 and "unknown scenario 'nowhere'" in unknown.stderr and "scenario2 (container)" in unknown.stderr
    table = llcps(db, "inspect", "trials")
    assert table.exit_code == 0 and "trials visible on main (7 shown)" in table.stdout


def test_branch_visibility_through_the_cli(db: str) -> None:
    assert llcps(db, "db", "branch", "fresh", "--at", "pretrain").exit_code == 0
    assert llcps(db, "db", "branch", "early", "--at", "2", "--json").exit_code == 0
    with Store.open(str(db)) as store:
        store.add_trial(sample_trial(99, branch="fresh", source="exploration"))
    fresh = json.loads(llcps(db, "--branch", "fresh", "inspect", "trials", "--json", "--limit", "0").stdout)
    assert [(t["id"], t["branch"]) for t in fresh] == [(1, "main"), (2, "main"), (3, "main"), (4, "main"), (8, "fresh")]
    early = json.loads(llcps(db, "inspect", "trials", "--json", env={"LLCPS_BRANCH": "early"}).stdout)
    assert [t["id"] for t in early] == [1, 2]
    listed = {b["name"]: b for b in json.loads(llcps(db, "db", "list", "--json").stdout)}
    assert (listed["fresh"]["fork_point"], listed["fresh"]["own_trials"], listed["fresh"]["visible_trials"]) == (4, 1, 5)


def test_db_compact_reports_the_sizes(sqlite_db: Path) -> None:
    done = llcps(sqlite_db, "db", "compact", "--json")
    assert done.exit_code == 0, done.output
    sizes = json.loads(done.stdout)
    assert sizes["before"] >= sizes["after"] > 0 and sizes["freed"] == sizes["before"] - sizes["after"]
    said = llcps(sqlite_db, "db", "compact")
    assert said.exit_code == 0 and "compacted" in said.output and "B -> " in said.output
    assert [t.id for t in Store.open(str(sqlite_db)).visible_trials("main")] == list(range(1, 8))


def test_reset_and_delete_need_yes(db: str) -> None:
    assert llcps(db, "db", "branch", "exp").exit_code == 0
    with Store.open(str(db)) as store:
        store.add_trial(sample_trial(50, branch="exp", source="exploration"))
    before = _contents(db)
    dry = llcps(db, "--branch", "exp", "db", "reset", "--to", "empty", "--json")
    assert dry.exit_code == 0 and json.loads(dry.stdout)["trials"] == 1 and json.loads(dry.stdout)["dry_run"] is True
    assert "would remove 1 trial(s)" in dry.stderr and "--yes" in dry.stderr
    assert _contents(db) == before
    done = llcps(db, "--branch", "exp", "db", "reset", "--to", "empty", "--yes", "--json")
    assert done.exit_code == 0 and json.loads(done.stdout)["dry_run"] is False
    refused = llcps(db, "db", "reset", "--yes")  # exp forked after main's exploration trials
    assert refused.exit_code == 2 and "exp" in refused.stderr
    dry_delete = llcps(db, "db", "delete", "exp")
    assert dry_delete.exit_code == 0 and "would remove 0 trial(s)" in dry_delete.stderr and "error" not in dry_delete.stderr
    assert llcps(db, "db", "delete", "exp", "--yes").exit_code == 0
    reset_main = llcps(db, "db", "reset", "--yes")
    assert reset_main.exit_code == 0 and "removed 3 trial(s)" in reset_main.stderr  # back to the 4 pretraining trials
    assert [b["name"] for b in json.loads(llcps(db, "db", "list", "--json").stdout)] == ["main"]
    assert [t["source"] for t in json.loads(llcps(db, "inspect", "trials", "--json").stdout)] == ["pretrain"] * 4


def test_export_csv_jsonl_and_parquet_hold_the_same_flat_rows(db: str, tmp_path: Path) -> None:
    result = llcps(db, "db", "export")
    assert result.exit_code == 0 and "exported 7 trial(s)" in result.stderr
    rows = list(csv.DictReader(io.StringIO(result.stdout)))
    assert [int(r["id"]) for r in rows] == list(range(1, 8))
    nested = json.loads(llcps(db, "inspect", "trials", "--json", "--limit", "0").stdout)
    for row, trial in zip(rows, nested):
        assert row["arg0"] == trial["arguments"][0]
        assert float(row["arg0_vector_magnitude"]) == trial["features"][0]["vector_magnitude"]
        # booleans are true/false, like JSON's, for the outcome bits and solved alike
        assert [row[name] for name in OUTCOME_NAMES] == ["true" if trial["outcome"][name] else "false" for name in OUTCOME_NAMES]
        assert row["solved"] == ("true" if trial["solved"] else "false")
        assert (row["arg1"] == "") == (len(trial["arguments"]) == 1)
    out = tmp_path / "trials.jsonl"
    assert llcps(db, "db", "export", "--format", "jsonl", "--out", str(out)).exit_code == 0
    flat = [json.loads(line) for line in out.read_text().splitlines()]
    assert [list(r) for r in flat] == [list(rows[0])] * len(rows)  # the same columns, in the same order
    for line, trial in zip(flat, nested):
        assert [line[name] for name in OUTCOME_NAMES] == [bool(trial["outcome"][name]) for name in OUTCOME_NAMES]
        assert line["solved"] is trial["solved"] and line["rate"] == trial["rate"]
        assert (line["arg1"] is None) == (len(trial["arguments"]) == 1)
    parquet = tmp_path / "trials.parquet"
    assert llcps(db, "db", "export", "--format", "parquet", "--out", str(parquet)).exit_code == 0
    import pyarrow.parquet as pq

    table = pq.read_table(parquet)
    assert table.column_names == list(rows[0]) and table.num_rows == 7
    assert table.column("solved").to_pylist() == [t["solved"] for t in nested]
    assert table.column("positive_touching").to_pylist() == [bool(t["outcome"]["positive_touching"]) for t in nested]
    assert table.column("arg0_shape").to_pylist() == [t["features"][0]["shape"] for t in nested]


def test_export_filters_by_source_scenario_and_episode(db: str, tmp_path: Path) -> None:
    def ids(*args: str) -> list[int]:
        result = llcps(db, "db", "export", "--format", "jsonl", *args)
        assert result.exit_code == 0, result.output
        return [json.loads(line)["id"] for line in result.stdout.splitlines()]

    assert ids("--source", "exploration") == [5, 6, 7]
    assert ids("--scenario", "scenario1") == [2, 4]
    assert ids("--source", "pretrain", "--scenario", "scenario2") == []
    with Store.open(str(db)) as store:
        run = store.start_run(command="t", seed=0, config={}, branch="main")
        episode = store.start_episode(run_id=run, branch="main", scenario="scenario2", condition="novelty", model="nb", measure="m", seed=0)
        store.add_trials([sample_trial(30 + i, source="exploration", episode_id=episode, run_id=run) for i in range(2)])
    assert ids("--episode", str(episode)) == [8, 9]
    refused = llcps(db, "db", "export", "--format", "parquet")
    assert refused.exit_code == 2 and "--out" in refused.stderr and refused.stdout == ""


def test_upgrade_command_on_an_old_store(tmp_path: Path) -> None:
    db = make_store("0001", tmp_path)
    refused = llcps(db, "inspect", "trials")
    assert refused.exit_code == 2 and "llcps db upgrade" in refused.stderr
    status = json.loads(llcps(db, "db", "status", "--json").stdout)
    assert (status["revision"], status["up_to_date"], status["visible_trials"]) == ("0001", False, 2)
    upgraded = llcps(db, "db", "upgrade", "--json")
    assert upgraded.exit_code == 0
    report = json.loads(upgraded.stdout)
    assert (report["from"], report["to"], report["changed"]) == ("0001", HEAD, True)
    # the old store's snapshot holds no real physics state: its trials' changes are unknown
    assert (report["changes"]["trials"], report["changes"]["replayed"], report["changes"]["unknown"]) == (2, 0, 2)
    assert len(json.loads(llcps(db, "inspect", "trials", "--json").stdout)) == 2


def _newer(path: Path) -> None:
    Store.open(str(path), create=True).close()
    with closing(sqlite3.connect(path)) as conn, conn:
        conn.execute(f"UPDATE {VERSION_TABLE} SET version_num = 'ffff'")


def _foreign(path: Path) -> None:
    with closing(sqlite3.connect(path)) as conn:
        conn.execute("CREATE TABLE t (x)")


BAD_INPUT = {
    "missing directory": ("{tmp}/missing/llcps.db", ["db", "init"], None),
    "database path is a directory": ("{tmp}", ["db", "status"], None),
    "not a database": ("{tmp}/notes.db", ["db", "init"], lambda p: p.write_text("just text\n")),
    "foreign sqlite": ("{tmp}/other.db", ["db", "init"], _foreign),
    "newer schema": ("{tmp}/newer.db", ["db", "upgrade"], _newer),
    "unknown branch checkout": ("{db}", ["db", "checkout", "nope"], None),
    "unknown --branch": ("{db}", ["--branch", "nope", "inspect", "trials"], None),
    "unknown --from": ("{db}", ["db", "branch", "x", "--from", "nope"], None),
    "empty branch name": ("{db}", ["db", "branch", ""], None),
    "whitespace branch name": ("{db}", ["db", "branch", "   "], None),
    "slash in branch name": ("{db}", ["db", "branch", "a/b"], None),
    "dotdot in branch name": ("{db}", ["db", "branch", "a..b"], None),
    "long branch name": ("{db}", ["db", "branch", "b" * 101], None),
    "bad fork point": ("{db}", ["db", "branch", "x", "--at", "nine"], None),
    "invisible fork point": ("{db}", ["db", "branch", "x", "--at", "999"], None),
    "delete main": ("{db}", ["db", "delete", "main", "--yes"], None),
    "missing export directory": ("{db}", ["db", "export", "--out", "{tmp}/nowhere/x.csv"], None),
    "missing store": ("{tmp}/absent.db", ["inspect", "trials"], None),
}


@pytest.mark.parametrize("case", list(BAD_INPUT))
def test_bad_input_is_one_error_line_and_changes_nothing(sqlite_db: Path, tmp_path: Path, case: str) -> None:
    db = sqlite_db
    location, args, make = BAD_INPUT[case]
    assert llcps(db, "db", "branch", "exp").exit_code == 0
    target = Path(location.format(tmp=tmp_path, db=db))
    if make is not None:
        make(target)
    files = sorted(p for p in tmp_path.rglob("*") if p.is_file())
    digests = {p: _digest(p) for p in files}
    result = llcps(target, *[a.format(tmp=tmp_path) for a in args])
    assert result.exit_code == 2, result.output
    lines = result.stderr.splitlines()
    assert lines[0].startswith("error: ") and len([ln for ln in lines if ln.startswith("error:")]) == 1, result.stderr
    assert all(ln.startswith(("error: ", "hint: ")) for ln in lines), result.stderr
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert result.stdout == ""
    assert sorted(p for p in tmp_path.rglob("*") if p.is_file()) == files  # nothing created
    assert {p: _digest(p) for p in files} == digests  # nothing changed


def test_loading_the_commands_leaves_the_heavy_libraries_alone() -> None:
    """Every command module loads at start: the simulator, the runner, numpy and the scenario
    files load inside the commands that need them, so light commands start fast."""
    heavy = (
        *("pybullet", "scipy", "numpy", "torch", "sklearn", "pydantic", "lark", "llcps.sim", "llcps.experiments.runner"),
        *("gymnasium", "stable_baselines3", "sb3_contrib", "llcps.gym"),
    )
    code = f"import sys, llcps, llcps.cli.main, llcps.scenarios as s; print(sorted(m for m in {heavy!r} if m in sys.modules), 'llcps.scenarios.loader' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env={**os.environ})
    assert out.stdout.strip() == "[] False"


def test_the_physics_cache_commands_leave_the_simulator_alone() -> None:
    """`llcps cache status|prune|limit` read store tables only: the store's cache module
    does not load the simulator (pybullet, scipy) it never runs."""
    code = "import sys, llcps.store.physics_cache; print(sorted(m for m in ('pybullet', 'scipy', 'llcps.sim.robot') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env={**os.environ})
    assert out.stdout.strip() == "[]"


def test_console_script_errors_without_traceback(tmp_path: Path) -> None:
    script = Path(sys.executable).with_name("llcps")
    env = {**os.environ, "LLCPS_DB": str(tmp_path / "missing" / "x.db")}
    result = subprocess.run([str(script), "db", "status"], capture_output=True, text=True, env=env)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.splitlines()[-2:] == [
        f"error: directory {tmp_path / 'missing'} does not exist",
        "hint: create it first or choose another --db path",
    ]
    assert result.stdout == ""
    made = subprocess.run([str(script), "--db", str(tmp_path / "ok.db"), "db", "init", "--json"], capture_output=True, text=True)
    assert made.returncode == 0 and json.loads(made.stdout)["current_branch"] == "main"
