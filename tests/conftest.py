"""Shared fixtures. Keep this small: one fixture per idea.

Store tests run on SQLite and on PostgreSQL: ``store_url`` (and ``store``, ``db_url``)
are parametrized over both backends. The PostgreSQL cases need a server named by
``LLCPS_TEST_POSTGRES_URL``; ``make test`` starts a throwaway one (tests/services.sh).
Without it they are skipped with that reason, and the summary line counts them.

The run ends with its budget (``pytest_terminal_summary``): the wall time against the
25 minutes ``make test`` may take, and the slowest tests as a share of their timeout,
with a warning for any test over a third of it (split it: see tests/test_scenarios.py).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
import uuid
from collections import Counter
from pathlib import Path
from typing import Any, Iterator

import pytest

FIXTURES = Path(__file__).parent / "fixtures"
sys.path.insert(0, str(FIXTURES))

from store_writer import sample_trial  # noqa: E402

import llcps.models  # noqa: E402
import llcps.scenarios  # noqa: E402
import llcps.sim  # noqa: E402
import llcps.symbolic  # noqa: E402
from llcps.store import Store  # noqa: E402

POSTGRES_URL = os.environ.get("LLCPS_TEST_POSTGRES_URL")

# Physics cache seals under a secret of this test process (and the commands it starts), never the user's.
os.environ["LLCPS_CACHE_KEY"] = str(Path(tempfile.mkdtemp(prefix="llcps-test-key-")) / "physics-cache.key")
# Off a terminal (CliRunner, subprocess pipes) progress lines begin after one heartbeat
# interval; a long one keeps the tests' stderr independent of the machine's speed (the
# tests of the heartbeat set their own), and a user's LLCPS_QUIET does not reach them.
os.environ["LLCPS_HEARTBEAT_SECONDS"] = "3600"
os.environ.pop("LLCPS_QUIET", None)


def _postgres_unavailable() -> str | None:
    if not POSTGRES_URL:
        return "no PostgreSQL server: run `make test` (tests/services.sh starts one) or set LLCPS_TEST_POSTGRES_URL"
    try:
        import psycopg  # noqa: F401
    except ImportError:
        return "psycopg is not installed: pip install -e '.[dev]'"
    return None


POSTGRES_SKIP = _postgres_unavailable()

#: The backends every store test runs on.
BACKENDS = [
    pytest.param("sqlite", id="sqlite"),
    pytest.param(
        "postgresql",
        id="postgresql",
        marks=[pytest.mark.postgresql, pytest.mark.skipif(POSTGRES_SKIP is not None, reason=POSTGRES_SKIP or "")],
    ),
]


def fresh_postgres_url() -> str:
    """A URL whose search_path is a new, empty schema: a fresh database for one test."""
    from sqlalchemy import create_engine, make_url, text

    assert POSTGRES_URL is not None
    schema = f"t_{uuid.uuid4().hex[:12]}"
    engine = create_engine(POSTGRES_URL)
    with engine.begin() as conn:
        conn.execute(text(f"CREATE SCHEMA {schema}"))
    engine.dispose()
    url = make_url(POSTGRES_URL).update_query_dict({"options": f"-csearch_path={schema}"})
    return url.render_as_string(hide_password=False)


def new_store_url(backend: str, directory: Path, name: str = "llcps.db") -> str:
    """Where a new store of ``backend`` can be made: a file path or a fresh schema's URL."""
    return str(directory / name) if backend == "sqlite" else fresh_postgres_url()


@pytest.fixture(params=BACKENDS)
def store_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """A location for a new store, on each backend (no store there yet)."""
    return new_store_url(request.param, tmp_path)


@pytest.fixture
def store(store_url: str) -> Iterator[Store]:
    """A fresh experience store with a `main` branch, on each backend."""
    with Store.open(store_url, create=True) as opened:
        yield opened


@pytest.fixture
def sqlite_store(tmp_path: Path) -> Iterator[Store]:
    """A fresh SQLite store, for tests whose subject is not the store (simulation, models)."""
    with Store.open(str(tmp_path / "llcps.db"), create=True) as opened:
        yield opened


@pytest.fixture
def fresh_caches() -> Iterator[None]:
    """The test starts with nothing remembered by the process: idle engines and their IK
    solutions, trusted states, scenario files, remembered fits (what a new process knows).
    Use it where a test counts what is computed, or make it autouse in a module."""
    from llcps.models import persistence
    from llcps.sim import caches
    from llcps.symbolic import knowledge_base, pddl_domain

    for clear in (caches.clear_caches, knowledge_base.clear_caches, pddl_domain.clear_caches, llcps.scenarios.clear_caches, persistence.clear_fits):
        clear()
    yield


@pytest.fixture(scope="session")
def readme_pretrained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store after the README's first commands, `llcps db init` and `llcps pretrain
    --trials 200 --seed 1`: 200 real random interactions. It is made once per test run
    and shared by the xdist workers (one pretraining instead of one per module that needs
    it), so it is read only: tests copy it (``shutil.copyfile``) and use the copy."""
    from filelock import FileLock
    from typer.testing import CliRunner

    from llcps.cli.main import app

    shared = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        shared = shared.parent  # the run's directory, above each worker's own
    path = shared / "readme-pretrained.db"
    with FileLock(str(path) + ".lock"):
        if not path.exists():
            making = shared / "readme-pretrained.making.db"
            making.unlink(missing_ok=True)
            for args in (("db", "init"), ("pretrain", "--trials", "200", "--seed", "1")):
                result = CliRunner().invoke(app, ["--db", str(making), *args])
                assert result.exit_code == 0, (args, result.stdout, result.stderr)
            assert not Path(f"{making}-wal").exists(), "the store was left open"
            making.rename(path)
    return path


@pytest.fixture
def new_trial():  # noqa: ANN201 - returns the sample_trial factory
    """``new_trial(seed, branch=..., source=..., **overrides) -> TrialRecord``."""
    return sample_trial


#: The wall time ``make test`` may take on an idle machine, in minutes.
SUITE_BUDGET_MINUTES = 25
#: The share of its timeout no test should need: what a loaded machine multiplies stays under it.
TEST_BUDGET_SHARE = 1 / 3
#: Tests listed in the budget, slowest first.
BUDGET_LISTED = 5
_STARTED = pytest.StashKey[float]()


def pytest_sessionstart(session: pytest.Session) -> None:
    session.config.stash[_STARTED] = time.perf_counter()


def _timeout(item: pytest.Item) -> float | None:
    """The item's timeout under pytest-timeout: its ``timeout`` mark, else --timeout, else the ini's."""
    marker = item.get_closest_marker("timeout")
    if marker is not None:
        value = marker.args[0] if marker.args else marker.kwargs.get("timeout")
    else:
        value = item.config.getoption("timeout", None) or item.config.getini("timeout")
    try:
        seconds = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return seconds if seconds > 0 else None


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Each test carries its timeout to its reports (from an xdist worker too), for the budget."""
    for item in items:
        item.user_properties.append(("timeout", _timeout(item)))


def pytest_report_header(config: pytest.Config) -> str:
    return f"postgresql: {'tests run at ' + POSTGRES_URL if POSTGRES_SKIP is None else 'tests skipped: ' + POSTGRES_SKIP}"


def pytest_terminal_summary(terminalreporter: Any, config: pytest.Config) -> None:
    """Say how many PostgreSQL cases ran, so a log shows they were not skipped; then the budget."""
    _postgres_summary(terminalreporter)
    if not hasattr(config, "workerinput") and _STARTED in config.stash:
        _budget_summary(terminalreporter, time.perf_counter() - config.stash[_STARTED])


def _budget_summary(terminalreporter: Any, wall: float) -> None:
    """The run's wall time against :data:`SUITE_BUDGET_MINUTES`, and the tests that took the
    largest share of their timeout (setup, call and teardown together, as pytest-timeout
    counts them); a warning, never a failure, for each over :data:`TEST_BUDGET_SHARE`."""
    seconds: dict[str, float] = {}
    timeouts: dict[str, float | None] = {}
    for reports in terminalreporter.stats.values():
        for report in reports:
            if isinstance(report, pytest.TestReport):
                seconds[report.nodeid] = seconds.get(report.nodeid, 0.0) + report.duration
                timeouts[report.nodeid] = dict(report.user_properties).get("timeout")
    if not seconds:
        return
    budget = SUITE_BUDGET_MINUTES * 60
    write = terminalreporter.write_line
    terminalreporter.write_sep("-", "test budget")
    write(
        f"wall time {wall / 60:.1f} min of the {SUITE_BUDGET_MINUTES} min `make test` may take on an idle machine "
        f"({wall / budget:.0%}); {len(seconds)} tests",
        yellow=wall > budget,
    )

    # A file runs on one worker (--dist loadfile): its sum, and the sum of all over the
    # workers, tell a long file at the end from too much work in all.
    files: dict[str, float] = {}
    for nodeid, took in seconds.items():
        files[nodeid.split("::")[0]] = files.get(nodeid.split("::")[0], 0.0) + took
    workers = getattr(terminalreporter.config.option, "numprocesses", None)
    workers = workers if isinstance(workers, int) and workers > 0 else 1
    write(f"tests' time in all {sum(files.values()) / 60:.1f} min, {sum(files.values()) / 60 / workers:.1f} min per worker ({workers}); the longest files:")
    for name in sorted(files, key=files.__getitem__, reverse=True)[:BUDGET_LISTED]:
        write(f"{files[name]:7.1f} s  {name}")

    def share(nodeid: str) -> float:
        limit = timeouts[nodeid]
        return seconds[nodeid] / limit if limit else 0.0

    ranked = sorted(seconds, key=lambda nodeid: (share(nodeid), seconds[nodeid]), reverse=True)
    for nodeid in ranked[:BUDGET_LISTED]:
        limit = timeouts[nodeid]
        of = f"{share(nodeid):4.0%} of its {limit:.0f} s timeout" if limit else "no timeout"
        write(f"{seconds[nodeid]:7.1f} s  {of}  {nodeid}")
    over = [nodeid for nodeid in ranked if share(nodeid) > TEST_BUDGET_SHARE]
    for nodeid in over:
        write(
            f"warning: {nodeid} took {seconds[nodeid]:.1f} s, over a third of its {timeouts[nodeid]:.0f} s timeout: "
            "a loaded machine can push it past; split it (see tests/test_scenarios.py)",
            yellow=True,
        )
    if wall > budget:
        write(f"warning: the run took {wall / 60:.1f} min, over the {SUITE_BUDGET_MINUTES} min budget", yellow=True)


def _postgres_summary(terminalreporter: Any) -> None:
    counts: Counter[str] = Counter()
    for outcome in ("passed", "failed", "error", "skipped"):
        for report in terminalreporter.stats.get(outcome, []):
            if "postgresql" in getattr(report, "keywords", {}) and getattr(report, "when", "call") in ("call", "setup"):
                counts[outcome] += 1
    if counts:
        terminalreporter.write_line(
            f"PostgreSQL cases: {counts['passed']} run and passed, {counts['failed'] + counts['error']} failed, "
            f"{counts['skipped']} skipped" + (f" ({POSTGRES_SKIP})" if counts["skipped"] and POSTGRES_SKIP else "")
        )
