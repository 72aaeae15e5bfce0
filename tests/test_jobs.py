"""The jobs: plain functions the CLI and the API both call, on a store URL or an open store."""

from __future__ import annotations

import io
import json
import os
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest
from store_writer import sample_trial

import llcps.jobs
from llcps.errors import LlcpsError
from llcps.jobs import cache, db, inspect, scenario
from llcps.jobs._common import opened
from llcps.store import Store

JOB_MODULES = sorted(f"llcps.jobs.{m.name}" for m in pkgutil.iter_modules(llcps.jobs.__path__))


def test_every_job_module_imports_without_the_cli_or_the_simulator() -> None:
    code = (
        "import importlib, sys;"
        f"[importlib.import_module(m) for m in {JOB_MODULES!r}];"
        "print(sorted(m for m in ('typer', 'rich', 'click', 'torch', 'pybullet', 'llcps.cli', 'llcps.api') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env={**os.environ})
    assert out.stdout.strip() == "[]"


def test_a_job_leaves_an_open_store_open_and_closes_its_own(tmp_path: Path) -> None:
    path = str(tmp_path / "llcps.db")
    with Store.open(path, create=True) as store:
        with opened(store) as same:
            assert same is store
        assert db.list_branches(store=store)[0].name == "main"  # still usable
    with opened(tmp_path / "llcps.db") as own:
        assert own.current_branch() == "main"


def test_db_jobs_on_a_url(tmp_path: Path) -> None:
    url = str(tmp_path / "jobs.db")
    created = db.init_store(store=url)
    assert not created.upgraded and created.current_branch == "main" and created.url.endswith("jobs.db")
    again = db.init_store(store=url)
    assert again.before == again.after == created.after and not again.upgraded
    with Store.open(url) as store:
        store.add_trials([sample_trial(i) for i in range(3)])
    info = db.create_branch(store=url, name="exp", at="pretrain")
    assert (info.parent, info.visible_trials) == ("main", 3)
    assert [b.name for b in db.list_branches(store=url)] == ["main", "exp"]
    assert db.checkout_branch(store=url, name="exp").name == "exp"
    assert db.store_status(store=url).current_branch == "exp"
    assert db.reset_branch(store=url, to="empty").dry_run
    buffer = io.StringIO()
    result = db.export_trials(store=url, out=buffer, branch="main", fmt="jsonl")
    assert (result.branch, result.count, result.out) == ("main", 3, None)
    assert [json.loads(line)["id"] for line in buffer.getvalue().splitlines()] == [1, 2, 3]
    with pytest.raises(LlcpsError, match="writes a binary file"):
        db.export_trials(store=url, out=io.StringIO(), fmt="parquet")
    with pytest.raises(LlcpsError):
        db.delete_branch(store=url, name="exp", dry_run=False)  # the current branch
    db.checkout_branch(store=url, name="main")
    assert not db.delete_branch(store=url, name="exp", dry_run=False).dry_run
    assert db.compact_store(store=url).url


def test_inspect_and_cache_jobs_on_an_open_store(tmp_path: Path) -> None:
    with Store.open(str(tmp_path / "llcps.db"), create=True) as store:
        run = store.start_run(command="pretrain", seed=1, config={"n": 4}, branch="main")
        store.add_trials([sample_trial(i, run_id=run) for i in range(4)])
        store.finish_run(run, status="ok")
        trials = inspect.list_trials(store=store, limit=2)
        assert trials.branch == "main" and [t.id for t in trials.trials] == [3, 4]  # the newest two, oldest first
        runs = inspect.list_runs(store=store, all_branches=True)
        assert runs.branch is None and runs.runs[0].activity["pretrain"] == 4
        assert runs.runs[0].as_json()["activity"] == {"episodes": 0, "trials": 4, "pretrain": 4}
        assert inspect.list_episodes(store=store).episodes == ()
        kb = inspect.knowledge(store=store)
        assert "(define (domain" in kb.domain and kb.operators and kb.as_json()["branch"] == "main"
        with pytest.raises(LlcpsError, match="--variant needs --scenario"):
            inspect.inspect_model(store=store, variant=3)
        assert cache.limit_cache(store=store, max_bytes=10**6).max_bytes == 10**6
        assert cache.prune_cache(store=store, dry_run=True).removed == 0
        assert cache.cache_status(store=store).entries == 0


def test_scenario_jobs() -> None:
    listed = scenario.list_scenarios()
    assert [s.name for s in listed][:3] == ["scenario1", "scenario2", "scenario3"]
    assert listed[0].as_json()["goal"] == list(listed[0].goal)
    assert "scenario2" in scenario.show_scenario(name="scenario2")
    assert json.loads(scenario.show_scenario(name="scenario2", fmt="json"))["name"] == "scenario2"
    assert scenario.scenario_ref(listed[1].alias or "scenario2") == "scenario2"
