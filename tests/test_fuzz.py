"""Fuzzing the store: Hypothesis damages one row of a real store (a snapshot's physics state
or scene, a trial's features or columns, an operator, a world model, a run, an episode, a
branch, a setting, a physics cache entry) and runs the commands that read it. Each command
must either work (exit 0, or 1 where 1 has its documented meaning) or fail with one
``error:`` line, one ``hint:`` line and exit code 2, leaving the store as it was: never a
traceback, an internal error, a crash, a hang or runaway memory (the Python heap of one
command stays under :data:`PEAK_BYTES`). Damage is of every kind a column can take:
bytes overwritten, a value of another type or out of range, JSON nested too deeply, text
too large, control characters.

The example count is fixed and the search derandomized, so CI runs the same cases.
"""

from __future__ import annotations

import json
import math
import random
import shutil
import sqlite3
import tracemalloc
import zlib
from contextlib import closing
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from llcps.cli.main import app
from llcps.domain import ControllerParams, fluent
from llcps.trial_records import TrialSpec
from llcps.models.persistence import fit_or_load
from llcps.cps.pretraining import pretrain
from llcps.store import Store
from llcps.symbolic.operators import learn_operator

#: Examples Hypothesis runs per damaged table (each copies the store, damages one row, runs
#: that table's readers): 60 in all.
FUZZ_EXAMPLES = {"snapshots": 14, "trials": 12, "operators": 8, "world_models": 8, "episodes": 6, "branches": 8, "settings": 6,
                 "trial_changes": 8, "operator_executions": 8, "runs": 8, "physics_cache": 8}

#: Most Python heap one command may take on a damaged store (tracemalloc's peak).
PEAK_BYTES = 256 * 2**20

runner = CliRunner()

#: What each damaged table is read by: (command, exit codes that mean success); ``{row}`` is
#: the damaged row's id (trial i of the template started from snapshot i).
READERS: dict[str, list[tuple[list[str], set[int]]]] = {
    "snapshots": [(["replay", "{row}"], {0, 1})],
    "trials": [(["inspect", "trials", "--limit", "0"], {0}), (["db", "status"], {0}), (["replay", "{row}"], {0, 1}),
               (["inspect", "model", "--model", "nb"], {0})],
    "operators": [(["inspect", "knowledge"], {0}), (["solve", "scenario3", "--condition", "original", "--budget", "0", "--model", "nb"], {0, 1})],
    "world_models": [(["solve", "scenario3", "--condition", "original", "--budget", "0", "--model", "nb"], {0, 1})],
    "episodes": [(["inspect", "runs", "--all"], {0}), (["inspect", "runs"], {0}), (["inspect", "episodes"], {0})],
    "branches": [(["db", "status"], {0}), (["db", "list"], {0}), (["inspect", "trials"], {0})],
    "settings": [(["db", "status"], {0}), (["inspect", "trials"], {0}), (["cache", "status"], {0})],
    "runs": [(["inspect", "runs", "--all"], {0}), (["db", "status"], {0}), (["db", "delete", "exp", "--yes"], {0})],
    "physics_cache": [(["cache", "status"], {0}), (["cache", "prune", "--dry-run"], {0})],
    "trial_changes": [(["db", "status"], {0}), (["inspect", "model", "--model", "nb"], {0})],
    "operator_executions": [(["inspect", "knowledge"], {0}),
                            (["solve", "scenario3", "--condition", "original", "--budget", "0", "--model", "nb"], {0, 1})],
}  # fmt: skip

#: Columns damaged, per table (JSON columns get JSON-shaped damage too).
COLUMNS: dict[str, list[str]] = {
    "snapshots": ["state", "scene"],
    "trials": ["features", "arguments", "extra", "rate", "action", "orientation", "sim_steps", "seed", "positive_touching", "source"],
    "operators": ["definition"],
    "world_models": ["artifact", "meta"],
    "episodes": ["summary", "status", "scenario"],
    "branches": ["name", "fork_point", "parent_id"],
    "settings": ["value"],
    "runs": ["config", "command", "status", "branch", "host", "pid", "heartbeat_at", "started_at"],
    "physics_cache": ["size", "last_used", "hits", "result"],
    "trial_changes": ["before", "added", "deleted", "bodies", "source"],
    "operator_executions": ["operator", "success", "context", "watermark"],
}
JSON_COLUMNS = {"scene", "arguments", "extra", "definition", "meta", "summary", "context", "config"}
#: Text columns a name or a setting is read from: control characters are tried there.
TEXT_COLUMNS = {"name", "value", "command", "status", "branch", "host", "scenario", "source", "action", "orientation"}
#: Packed binary values: their bytes are flipped as bytes.
BINARY_COLUMNS = {"features", "before", "added", "deleted", "bodies"}


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real store: pretraining trials with snapshots, a fitted model, an operator, an episode."""
    path = tmp_path_factory.mktemp("fuzz") / "template.db"
    with Store.open(str(path), create=True) as store:
        pretrain(store, branch="main", n=3, seed=0, control_loop_every=0)
        fit_or_load(store, "main", "nb", 0)
        spec = TrialSpec("push", ("cup",), ControllerParams(1.0, 0.3, "left"))
        learned = learn_operator(
            spec=spec,
            before=frozenset({fluent("in", "ball", "cup"), fluent("reachable", "cup")}),
            after=frozenset({fluent("reachable", "cup")}),
            objects={"cup": "container", "ball": "item"},
        )
        store.create_branch("exp")
        writer = store.start_run(command="solve", seed=0, config={}, branch="exp")  # left running: a stale writer once this process is gone
        assert writer
        run = store.start_run(command="solve", seed=0, config={}, branch="main")
        episode = store.start_episode(run_id=run, branch="main", scenario="scenario3", condition="novelty", model="nb", measure="most-changes", seed=0)
        store.add_operator(branch="main", name=learned.name, pddl=learned.to_pddl(), definition={"operator": learned.to_json(), "refinement": None},
                           scenario="scenario3", episode_id=episode)  # fmt: skip
        for success in (False, True):
            store.add_operator_execution(branch="main", operator="remove_from_container", success=success,
                                         context=[("in", "?o", "?c"), ("reachable", "?c")], episode_id=episode)  # fmt: skip
        store.finish_episode(episode, status="solved", summary={"exploration_trials": 1, "sim_seconds": 1.0, "wall_seconds": 2.0})
        store.finish_run(run, status="solved")
    with closing(sqlite3.connect(path)) as conn, conn:
        conn.execute("UPDATE runs SET pid = 2147483647 WHERE status = 'running'")  # a process that is gone
        for n in range(2):
            conn.execute(
                "INSERT INTO physics_cache (key, result, end_state, sha256, size, hits, created_at, last_used)"
                " VALUES (?, ?, ?, ?, ?, 0, '2026-01-01 00:00:00.000000', ?)",
                (f"{n:064x}", b"{}", b"", "0" * 64, 2 + n, f"2026-01-0{n + 1} 00:00:00.000000"),
            )
        conn.execute("INSERT INTO settings (key, value) VALUES ('physics_cache_max_bytes', '2147483648')")
    return path


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats() | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=8,
)


def _mutate_json(value: Any, data: st.DataObject) -> Any:
    """Replace one node of a JSON value (reached by a random path) with a random one."""
    if isinstance(value, dict) and value and data.draw(st.booleans()):
        key = data.draw(st.sampled_from(sorted(value)))
        return {**value, key: _mutate_json(value[key], data)}
    if isinstance(value, list) and value and data.draw(st.booleans()):
        i = data.draw(st.integers(0, len(value) - 1))
        return [*value[:i], _mutate_json(value[i], data), *value[i + 1 :]]
    return data.draw(json_values)


def _flip(raw: bytes, rng: random.Random) -> bytes:
    """Overwrite 1-8 bytes at places spread over the whole value (or truncate it)."""
    damaged = bytearray(raw)
    if damaged and rng.random() < 0.15:
        return bytes(damaged[: rng.randrange(len(damaged))])
    for _ in range(rng.randint(1, 8)):
        at = rng.randrange(len(damaged)) if damaged else 0
        damaged[at : at + 1] = bytes([rng.randrange(256)])
    return bytes(damaged)


def _damage(db: Path, table: str, column: str, data: st.DataObject) -> tuple[Any, str]:
    """Damage ``table.column`` of one row; returns its key and a description for failure messages."""
    with closing(sqlite3.connect(db)) as conn, conn:
        key = {"settings": "key", "trial_changes": "trial_id", "physics_cache": "key"}.get(table, "id")
        ids = [r[0] for r in conn.execute(f"SELECT {key} FROM {table} ORDER BY {key}")]
        rng = data.draw(st.randoms(use_true_random=False), label="where")  # rows and bytes spread evenly
        row = rng.choice(ids)
        old = conn.execute(f"SELECT {column} FROM {table} WHERE {key} = ?", (row,)).fetchone()[0]
        kinds = ["bytes", "value", "large"] + (["json", "deep"] if column in JSON_COLUMNS else []) + (["control"] if column in TEXT_COLUMNS else [])
        how = data.draw(st.sampled_from(kinds))
        if column in ("state", "artifact") and how == "bytes":
            inner = data.draw(st.booleans()) and column == "state"
            new: Any = zlib.compress(_flip(zlib.decompress(old), rng)) if inner else _flip(bytes(old), rng)
        elif how == "bytes" and column in BINARY_COLUMNS:
            new = _flip(bytes(old), rng)
        elif how == "bytes":
            text = old if isinstance(old, (bytes, str)) else str(old)
            raw = text.encode() if isinstance(text, str) else text
            new = _flip(raw, rng).decode("utf-8", errors="replace") if raw else "\x00"
        elif how == "json":
            new = json.dumps(_mutate_json(json.loads(old), data))
        elif how == "deep":  # nested past any bound a reader may have, up to the decoder's recursion limit and beyond
            depth = data.draw(st.sampled_from([65, 900, 5000, 100_000]))
            new = "[" * depth + "]" * depth
        elif how == "large":  # far larger than anything llcps writes there
            size = data.draw(st.sampled_from([2**16, 2**22 + 1, 2**24]))
            new = data.draw(st.sampled_from(["text", "blob", "number"]))
            new = {"text": "x" * size, "blob": b"\x00" * size, "number": float(2**size) if size < 1024 else 10.0**308}[new]
        elif how == "control":  # a terminal escape and a line break inside a name
            new = data.draw(st.sampled_from(["x\x1b[2J\x1b[31mred", "main\nmain  forged", "\x00nul", "tab\there", "\u202eevil"]))
        else:
            new = data.draw(st.none() | st.integers(-(2**63), 2**63 - 1) | st.floats() | st.text(max_size=12) | st.binary(max_size=12))
            if isinstance(new, float) and math.isnan(new):
                new = None  # SQLite stores NaN as NULL anyway
        try:
            conn.execute(f"UPDATE {table} SET {column} = ? WHERE {key} = ?", (new, row))
        except sqlite3.IntegrityError:  # NOT NULL or UNIQUE: damage that SQLite itself refuses
            new = data.draw(st.text(min_size=1, max_size=12), label="not null")
            conn.execute(f"UPDATE {table} SET {column} = ? WHERE {key} = ?", (new, row))
        if data.draw(st.booleans()):  # a tamperer who also rewrites the content hash
            if table == "snapshots":
                scene, state = conn.execute("SELECT scene, state FROM snapshots WHERE id = ?", (row,)).fetchone()
                try:
                    sha = Store.snapshot_hash(json.loads(scene), bytes(state) if isinstance(state, bytes) else str(state).encode())
                except (ValueError, TypeError):
                    sha = "0" * 64
                conn.execute("UPDATE snapshots SET sha256 = ? WHERE id = ?", (sha, row))
            elif table == "world_models" and column == "artifact" and isinstance(new, bytes):
                import hashlib

                meta = json.loads(conn.execute("SELECT meta FROM world_models WHERE id = ?", (row,)).fetchone()[0])
                meta["sha256"] = hashlib.sha256(new).hexdigest()
                conn.execute("UPDATE world_models SET meta = ?, sha256 = ? WHERE id = ?", (json.dumps(meta), meta["sha256"], row))
    return row, f"{table}.{column} of row {row} ({how}): {new!r:.200}"


def _dump(db: Path) -> list[str]:
    """The store's content, as SQL (SQLite's own dump)."""
    with closing(sqlite3.connect(db)) as conn:
        return list(conn.iterdump())


@pytest.mark.parametrize("table", sorted(FUZZ_EXAMPLES))
def test_a_damaged_row_gives_a_result_or_one_clean_error(template: Path, tmp_path: Path, table: str) -> None:
    @settings(
        max_examples=FUZZ_EXAMPLES[table],
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(data=st.data())
    def damaged(data: st.DataObject) -> None:
        column = data.draw(st.sampled_from(COLUMNS[table]), label="column")
        db = tmp_path / "fuzz.db"
        shutil.copy(template, db)
        row, damage = _damage(db, table, column, data)
        codes = []
        for template_args, ok in READERS[table]:
            args = [a.format(row=row) for a in template_args]
            before = _dump(db)
            tracemalloc.start()
            try:
                result = runner.invoke(app, ["--db", str(db), *args])
                peak = tracemalloc.get_traced_memory()[1]
            finally:
                tracemalloc.stop()
            codes.append(result.exit_code)
            where = f"llcps {' '.join(args)} after damaging {damage}"
            assert result.exception is None or isinstance(result.exception, SystemExit), (where, result.exception)
            assert "Traceback" not in result.output and "internal error" not in result.output, (where, result.output)
            assert "\x1b" not in result.stdout, (where, "a control character reached the terminal")
            assert peak < PEAK_BYTES, (where, f"{peak:,} bytes of Python heap")
            if result.exit_code in ok:
                continue
            assert result.exit_code == 2, (where, result.exit_code, result.output)
            lines = [line for line in result.stderr.splitlines() if line.startswith(("error: ", "hint: "))]
            assert [line.split(":", 1)[0] for line in lines] == ["error", "hint"], (where, result.stderr)
            assert _dump(db) == before, (where, "a command that failed changed the store")
        event(f"{table}.{column}: exit codes {codes}")

    damaged()
