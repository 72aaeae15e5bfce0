"""Stored rows that are not what llcps writes, servers that do not answer, writers that are
live or gone, signals and read-only stores: each one ``error:`` and one ``hint:`` line,
exit code 2 (130 for a signal), and the store as it was (a dump of every table before and
after), on SQLite and on PostgreSQL where the store is involved (docs/reliability.md)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
import tracemalloc
from contextlib import closing
from datetime import datetime
from pathlib import Path
from typing import Any, Iterator

import pytest
from conftest import BACKENDS, new_store_url
from fixtures.store_writer import sample_trial
from sqlalchemy import create_engine, insert, text, update
from sqlalchemy.pool import NullPool
from typer.testing import CliRunner

from llcps.cli.main import app
from llcps.store import Store
from llcps.store import backends
from llcps.store.model_artifacts import MAX_MODEL_BYTES
from llcps.store.tables import Base, Branch, Episode, OperatorExecution, PhysicsCacheEntry, Run, Setting
from llcps.store.writers import STALE_AFTER

runner = CliRunner()

#: Deeper than any JSON llcps writes, shallower than the decoder's recursion limit.
DEEP = 200


def llcps(url: str, *args: str, env: dict[str, str] | None = None):  # noqa: ANN201 - click Result
    return runner.invoke(app, ["--db", url, *args], env=env)


def assert_one_error(result, *needles: str) -> None:  # noqa: ANN001
    assert result.exit_code == 2, (result.exit_code, result.output)
    lines = [line for line in result.stderr.splitlines() if line.startswith(("error: ", "hint: "))]
    assert [line.split(":", 1)[0] for line in lines] == ["error", "hint"], result.stderr
    assert "Traceback" not in result.output and "internal error" not in result.output, result.output
    for needle in needles:
        assert needle in result.stderr, (needle, result.stderr)


def dump(url: str) -> dict[str, list[tuple[Any, ...]]]:
    """Every row of every llcps table, in key order: the store's content, backend-neutral."""
    engine = create_engine(backends.resolve_url(url))  # the raw values: no decoding by llcps
    try:
        with engine.connect() as conn:
            return {
                table.name: [
                    tuple(repr(v) for v in row)
                    for row in conn.execute(text(f"SELECT * FROM {table.name} ORDER BY {', '.join(c.name for c in table.primary_key.columns)}"))
                ]
                for table in Base.metadata.sorted_tables
            }
    finally:
        engine.dispose()


def change(url: str, statement: Any) -> None:
    """Run ``statement`` on the store directly, as someone changing it outside llcps."""
    engine = backends.make_engine(backends.resolve_url(url), pooled=False, foreign_keys=False)
    try:
        with engine.begin() as conn:
            conn.execute(statement)
    finally:
        engine.dispose()


@pytest.fixture(params=BACKENDS)
def filled(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """A store with six synthetic trials on main, a branch ``exp`` forked after three, a run
    with an episode and two operator executions; on each backend."""
    url = new_store_url(request.param, tmp_path)
    with Store.open(url, create=True) as store:
        for seed in range(3):
            store.add_trial(sample_trial(seed))
        store.create_branch("exp")
        for seed in range(3, 6):
            store.add_trial(sample_trial(seed))
        run = store.start_run(command="solve", seed=0, config={"scenario": "scenario3"}, branch="main")
        episode = store.start_episode(run_id=run, branch="main", scenario="scenario3", condition="novelty", model="nb", measure="goal-directed", seed=0)
        for success in (False, True):
            store.add_operator_execution(branch="main", operator="remove_from_container", success=success,
                                         context=[("in", "?o", "?c")], episode_id=episode)  # fmt: skip
        store.finish_episode(episode, status="solved", summary={"exploration_trials": 1})
        store.finish_run(run, status="solved")
    return url


def _nested(depth: int) -> Any:
    value: Any = ["in", "?o", "?c"]
    for _ in range(depth):
        value = [value]
    return value


# ------------------------------------------------------------------------ class 2: stored rows

JSON_READERS = [
    pytest.param(OperatorExecution, "context", ["solve", "scenario3", "--budget", "0", "--model", "nb"], id="operator_executions-solve"),
    pytest.param(Run, "config", ["inspect", "runs"], id="runs-inspect"),
    pytest.param(Episode, "summary", ["inspect", "episodes"], id="episodes-inspect"),
]


@pytest.mark.parametrize(("table", "column", "command"), JSON_READERS)
def test_deeply_nested_json_is_refused_before_anything_is_written(filled: str, table: Any, column: str, command: list[str]) -> None:
    """A JSON value nested ``DEEP`` levels in any JSON column: one error naming the limit,
    and nothing written (``solve`` used to store a refitted world model before it failed)."""
    change(filled, update(table).where(table.id == 1).values({column: _nested(DEEP)}))
    before = dump(filled)
    assert_one_error(llcps(filled, *command), "nested deeper than 64 levels")
    assert dump(filled) == before


def test_an_oversized_world_model_is_refused_unread(tmp_path: Path) -> None:
    """A world model larger than MAX_MODEL_BYTES is refused from its length alone: reading it
    costs no more memory than a small one (an 800 MB model made `solve` peak at 3.3 GB)."""
    url = str(tmp_path / "llcps.db")
    with Store.open(url, create=True) as store:
        store.add_trial(sample_trial(0))
        store.save_world_model(branch="main", name="nb", seed=0, watermark=1, artifact=b"x", meta={})
    with closing(sqlite3.connect(url)) as conn, conn:
        conn.execute("UPDATE world_models SET artifact = zeroblob(?)", (MAX_MODEL_BYTES + 1,))
    before = dump(url)
    with Store.open(url) as store:
        tracemalloc.start()
        with pytest.raises(Exception, match="more than the 67,108,864 a world model may") as caught:
            store.latest_world_model("main", "nb", 0)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert type(caught.value).__name__ == "StoreError"
    assert peak < 8 * 2**20, peak
    assert dump(url) == before


def test_a_fork_point_beyond_its_parents_head_is_refused(filled: str) -> None:
    """A branch whose fork point lies past its parent's last trial would see trials its parent
    adds later: its training set would grow under it."""
    change(filled, update(Branch).where(Branch.name == "exp").values(fork_point=10**6))
    before = dump(filled)
    assert_one_error(llcps(filled, "--branch", "exp", "inspect", "trials"), "beyond 'main''s last trial (6)")
    assert dump(filled) == before
    assert llcps(filled, "inspect", "trials").exit_code == 0  # main itself is intact


@pytest.mark.parametrize(
    ("values", "needle"),
    [
        pytest.param({"size": -(10**9)}, "size or hits are out of range", id="negative-size"),
        pytest.param({"last_used": "not a time"}, "time of use that is not a time", id="last-used"),
    ],
)
def test_a_changed_physics_cache_row_is_refused(filled: str, values: dict[str, Any], needle: str) -> None:
    now = datetime(2026, 1, 1)
    change(filled, insert(PhysicsCacheEntry).values(key="k" * 64, result=b"{}", end_state=b"", sha256="0" * 64, size=10, hits=0,
                                                    created_at=now, last_used=now))  # fmt: skip
    if "last_used" in values:  # text SQLAlchemy would not bind as a time
        if filled.startswith("postgresql"):
            pytest.skip("PostgreSQL keeps last_used as a timestamp: it cannot hold text")
        with closing(sqlite3.connect(filled)) as conn, conn:
            conn.execute("UPDATE physics_cache SET last_used = ?", (values["last_used"],))
    else:
        change(filled, update(PhysicsCacheEntry).values(values))
    before = dump(filled)
    assert_one_error(llcps(filled, "cache", "status"), needle, "cache prune --to 0")
    assert dump(filled) == before
    result = llcps(filled, "cache", "prune", "--to", "0")  # the hint works: the changed entry goes
    assert result.exit_code == 0, result.output
    assert llcps(filled, "cache", "status").exit_code == 0


def test_a_junk_cache_bound_is_refused(filled: str) -> None:
    change(filled, insert(Setting).values(key="physics_cache_max_bytes", value="lots"))
    before = dump(filled)
    assert_one_error(llcps(filled, "cache", "status"), "'lots', not a number of bytes", "llcps cache limit")
    assert dump(filled) == before


def test_control_characters_in_stored_names_are_printed_escaped(filled: str) -> None:
    """An ESC sequence in a branch name never reaches the terminal, and a newline does not forge a row."""
    change(filled, update(Branch).where(Branch.name == "exp").values(name="x\x1b[2J\x1b[31mred\nmain  forged"))
    before = dump(filled)
    result = llcps(filled, "db", "list")
    assert result.exit_code == 0, result.output
    assert "\x1b" not in result.stdout and "\\x1b[2J\\x1b[31mred\\nmain  forged" in result.stdout
    assert not any(line.lstrip("│ ").startswith("main  forged") for line in result.stdout.splitlines())
    assert dump(filled) == before


# ------------------------------------------------------------------------ class 3: servers that do not answer


@pytest.fixture
def silent_server() -> Iterator[int]:
    """A TCP port that accepts connections and never says a word."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    accepted: list[socket.socket] = []
    stop = threading.Event()

    def serve() -> None:
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                accepted.append(server.accept()[0])
            except OSError:
                continue

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield server.getsockname()[1]
    stop.set()
    thread.join()
    for conn in accepted:
        conn.close()
    server.close()


def test_a_server_that_never_answers_is_one_error(silent_server: int) -> None:
    pytest.importorskip("psycopg")
    result = llcps(f"postgresql+psycopg://llcps@127.0.0.1:{silent_server}/llcps", "db", "status", env={"LLCPS_DB_TIMEOUT": "2"})
    assert_one_error(result, "did not answer within LLCPS_DB_TIMEOUT (now 2 s)", "LLCPS_DB_TIMEOUT=SECONDS")


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_lock_held_by_another_session_is_one_error(backend: str, tmp_path: Path) -> None:
    url = new_store_url(backend, tmp_path)
    Store.open(url, create=True).close()
    before = dump(url)
    if backend == "sqlite":
        holder: Any = sqlite3.connect(url, isolation_level=None)
        holder.execute("BEGIN IMMEDIATE")
    else:  # a session-level lock: it outlives transactions, so the session itself must end
        holder = create_engine(url, poolclass=NullPool).connect()
        holder.execute(text("SELECT pg_advisory_lock(:key)"), {"key": backends.WRITER_LOCK})
    try:
        result = llcps(url, "db", "branch", "exp", env={"LLCPS_DB_TIMEOUT": "1"})
    finally:
        holder.close()
    assert_one_error(result, "locked by another process for longer than LLCPS_DB_TIMEOUT (now 1 s)", "LLCPS_DB_TIMEOUT=SECONDS")
    assert dump(url) == before


def test_a_timeout_that_is_not_a_number_is_refused(tmp_path: Path) -> None:
    url = str(tmp_path / "x.db")
    Store.open(url, create=True).close()
    assert_one_error(llcps(url, "db", "status", env={"LLCPS_DB_TIMEOUT": "soon"}), "LLCPS_DB_TIMEOUT='soon'")


# ------------------------------------------------------------------------ class 4: live writers


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


@pytest.fixture
def other_process() -> Iterator[int]:
    """The pid of another live process on this host (a writer's stand-in)."""
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    yield child.pid
    child.kill()
    child.wait()


def _writer(url: str, command: str, pid: int) -> int:
    """A run on ``exp`` as another process on this host would have started it."""
    with Store.open(url) as store:
        run = store.start_run(command=command, seed=0, config={}, branch="exp")
    change(url, update(Run).where(Run.id == run).values(pid=pid))
    return run


def test_deleting_a_branch_with_a_live_writer_is_refused(filled: str, other_process: int) -> None:
    """A run on ``exp`` whose process is alive blocks ``db delete exp --yes``; a run whose
    process is gone is stale, blocks nothing, and is marked abandoned."""
    run = _writer(filled, "solve scenario1", other_process)
    before = dump(filled)
    result = llcps(filled, "db", "delete", "exp", "--yes")
    assert_one_error(result, f"branch 'exp' is being written to: run {run} (solve scenario1, pid {other_process}", "--force")
    assert dump(filled) == before
    status = llcps(filled, "db", "status", "--json")
    assert [(w["run_id"], w["live"]) for w in json.loads(status.stdout)["writers"]] == [(run, True)]

    change(filled, update(Run).where(Run.id == run).values(pid=_dead_pid()))  # the writer was killed
    status = llcps(filled, "db", "status")
    assert "stale writer on exp" in status.stdout and "is gone" in status.stdout, status.stdout
    result = llcps(filled, "db", "delete", "exp", "--yes")
    assert result.exit_code == 0, result.output
    with Store.open(filled) as store:
        assert store.get_run(run).status == "abandoned"


def test_force_deletes_a_branch_with_a_live_writer_and_aborts_its_run(filled: str, other_process: int) -> None:
    run = _writer(filled, "pretrain", other_process)
    result = llcps(filled, "db", "delete", "exp", "--yes", "--force")
    assert result.exit_code == 0, result.output
    assert "aborted live writer(s): run" in result.stderr
    with Store.open(filled) as store:
        assert store.get_run(run).status == "aborted"


def test_a_heartbeat_older_than_the_stale_bound_is_stale(filled: str) -> None:
    with Store.open(filled) as store:
        run = store.start_run(command="solve", seed=0, config={}, branch="exp")
    old = datetime(2000, 1, 1)
    change(filled, update(Run).where(Run.id == run).values(host="elsewhere", heartbeat_at=old))
    status = json.loads(llcps(filled, "db", "status", "--json").stdout)
    (writer,) = status["writers"]
    assert writer["live"] is False and "from another host" in writer["reason"], writer
    assert STALE_AFTER.total_seconds() >= 60


# ------------------------------------------------------------------------ class 5: signals and read-only stores

LLCPS = [sys.executable, "-c", "from llcps.cli.main import main; main()"]


def test_sigterm_marks_a_pretrain_run_interrupted(tmp_path: Path) -> None:
    db = tmp_path / "llcps.db"
    Store.open(str(db), create=True).close()
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1]), "LLCPS_QUIET": "1"}
    proc = subprocess.Popen([*LLCPS, "--db", str(db), "pretrain", "--trials", "200"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and proc.poll() is None:  # wait for the first stored trial
            with closing(sqlite3.connect(f"{db.as_uri()}?mode=ro", uri=True)) as conn:
                if conn.execute("SELECT count(*) FROM trials").fetchone()[0] > 0:
                    break
            time.sleep(0.2)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    with Store.open(str(db)) as store:
        (run,) = store.list_runs()
        assert run.status == "interrupted"
        assert store.max_visible_trial_id("main") > 0  # completed trials are kept


def _as_other_user() -> list[str]:
    """A command prefix that drops root (whom no file mode stops), or nothing."""
    if os.geteuid() != 0:
        return []
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("running as root without setpriv: file modes cannot make a store read-only")
    return [setpriv, "--reuid=65534", "--regid=65534", "--clear-groups"]


def test_a_read_only_store_is_read_and_a_write_says_read_only(filled: str) -> None:
    if not filled.startswith("/"):
        pytest.skip("file modes: SQLite only")
    prefix = _as_other_user()
    directory = Path(tempfile.mkdtemp(prefix="llcps-ro-"))
    try:
        db = directory / "llcps.db"
        shutil.copy(filled, db)
        before = dump(str(db))
        db.chmod(0o444)
        directory.chmod(0o555)  # no write-ahead log index can be made here: read with immutable=1
        env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1]), "HOME": str(directory)}
        cwd = str(directory)

        def run(*args: str) -> subprocess.CompletedProcess[str]:
            return subprocess.run([*prefix, *LLCPS, "--db", str(db), *args], env=env, cwd=cwd, capture_output=True, text=True, timeout=120)

        for reader in (["db", "status"], ["db", "list"], ["inspect", "runs"], ["inspect", "trials"]):
            done = run(*reader)
            assert done.returncode == 0, (reader, done.stderr)
        done = run("db", "branch", "more")
        assert done.returncode == 2, done.stderr
        assert done.stderr.startswith("error: the store is read-only") and done.stderr.count("\n") == 2, done.stderr
        assert "hint: " in done.stderr
        directory.chmod(0o755)
        assert dump(str(db)) == before
    finally:
        directory.chmod(0o755)
        shutil.rmtree(directory)
