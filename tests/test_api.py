"""The pandas API: llcps.open(...) and its DataFrames, against real stores."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Iterator

import pandas as pd
import pytest
from store_writer import sample_trial
from typer.testing import CliRunner

import llcps
from llcps.api import EPISODE_COLUMNS, OPERATOR_COLUMNS, RUN_COLUMNS
from llcps.cli.main import app
from llcps.domain import OUTCOME_NAMES
from llcps.store import Store
from llcps.store import flat
from llcps.store.flat import ColumnSource, Column, register_trial_columns, trial_columns

DOCS = Path(__file__).parents[1] / "docs"
EXPECTED_DTYPES = {"int": "int64", "nullable_int": "Int64", "float": "float64", "bool": "bool", "string": "string", "category": "category", "timestamp": "datetime64[ns]"}


def build_store(path: Path) -> Path:
    """Pretraining, two solved-or-not episodes with exploration, a learned operator, three runs."""
    with Store.open(str(path), create=True) as store:
        pre = store.start_run(command="pretrain", seed=1, config={"n": 6}, branch="main")
        store.add_trials([sample_trial(i, run_id=pre) for i in range(6)])
        store.finish_run(pre, status="ok")
        for n, scenario in enumerate(("scenario1", "scenario2")):
            run = store.start_run(command="solve", seed=n, config={"scenario": scenario}, branch="main")
            episode = store.start_episode(run_id=run, branch="main", scenario=scenario, condition="novelty", model="nb", measure="goal-directed", seed=n)
            plan = [sample_trial(100 + 10 * n, source="plan", scenario=scenario, run_id=run, episode_id=episode)]
            explore = [
                sample_trial(200 + 10 * n + k, source="exploration", scenario=scenario, run_id=run, episode_id=episode, solved=k == 2 + n)
                for k in range(3 + n)
            ]
            ids = store.add_trials(plan + explore)
            store.add_operator(branch="main", name=f"op{n}", pddl=f"(:action op{n})", definition={}, scenario=scenario, episode_id=episode)
            summary = {"exploration_trials": len(explore), "plan_trials": 1, "candidates": 467, "sim_seconds": 1.5 * (n + 1),
                       "wall_seconds": 2.0, "resolving_trial_id": ids[-1], "failed_action": "(push cube)", "learned_operators": ["x"]}  # fmt: skip
            store.finish_episode(episode, status="solved", summary=summary)
            store.finish_run(run, status="solved")
    return path


@pytest.fixture
def db(tmp_path: Path) -> Iterator[Path]:
    yield build_store(tmp_path / "llcps.db")


def test_trials_have_the_documented_columns_and_dtypes(db: Path) -> None:
    with llcps.open(db) as wb:
        trials = wb.trials()
    columns = trial_columns()
    assert list(trials.columns) == [c.name for c in columns]
    for c in columns:
        assert str(trials[c.name].dtype) == EXPECTED_DTYPES[c.kind], c.name
    assert len(trials) == 6 + 4 + 5
    assert list(trials["action"].cat.categories[:4]) == ["push", "push_together", "remove_from_container", "place_in_container"]
    one_argument = trials[trials.action == "push"]
    assert one_argument["arg1"].isna().all() and one_argument["arg1_volume"].isna().all()
    assert trials["arg0_volume"].notna().all()


def test_trials_agree_row_for_row_with_inspect_trials_json(db: Path) -> None:
    result = CliRunner().invoke(app, ["--db", str(db), "inspect", "trials", "--json", "--limit", "0"])
    nested = json.loads(result.stdout)
    with llcps.open(db) as wb:
        trials = wb.trials()
    assert trials["id"].tolist() == [t["id"] for t in nested]
    for row, trial in zip(trials.itertuples(index=False), nested):
        row = row._asdict()
        for key in ("branch", "source", "action", "rate", "movement_magnitude", "orientation", "solved", "sim_steps", "wall_seconds", "seed"):
            assert row[key] == trial[key], key
        assert (None if pd.isna(row["scenario"]) else row["scenario"]) == trial["scenario"]
        assert (None if pd.isna(row["episode_id"]) else row["episode_id"]) == trial["episode_id"]
        for name in OUTCOME_NAMES:
            assert row[name] is bool(trial["outcome"][name]) or row[name] == bool(trial["outcome"][name])
        for slot, (argument, features) in enumerate(zip(trial["arguments"], trial["features"])):
            assert row[f"arg{slot}"] == argument
            for key, value in features.items():
                assert row[f"arg{slot}_{key}"] == value, f"arg{slot}_{key}"
        assert pd.Timestamp(trial["created_at"]) == row["created_at"]


def test_filters_episodes_runs_and_operators(db: Path) -> None:
    with llcps.open(db) as wb:
        assert wb.trials(source="exploration")["id"].tolist() == list(range(8, 11)) + list(range(12, 16))
        assert set(wb.trials(scenario="scenario2")["scenario"]) == {"scenario2"}
        assert wb.trials(episode=1)["source"].tolist() == ["plan", "exploration", "exploration", "exploration"]
        assert wb.trials(solved=True)["id"].tolist() == [10, 15]
        episodes = wb.episodes()
        runs = wb.runs()
        operators = wb.operators()
        compared = wb.compare_runs(2, 3)
    assert list(episodes.columns) == list(EPISODE_COLUMNS)
    assert episodes["exploration_trials"].tolist() == [3, 4] and episodes["solved"].tolist() == [True, True]
    assert episodes["resolving_trial_id"].tolist() == [10, 15] and str(episodes["started_at"].dtype) == "datetime64[ns]"
    assert list(runs.columns) == list(RUN_COLUMNS) and runs["command"].tolist() == ["pretrain", "solve", "solve"]
    assert (runs["python_version"] == ".".join(map(str, sys.version_info[:3]))).all()
    assert runs["cpu_count"].min() >= 1 and runs["host"].notna().all() and runs["numpy_version"].notna().all()
    assert list(operators.columns) == list(OPERATOR_COLUMNS) and operators["name"].tolist() == ["op0", "op1"]
    differ = set(compared.loc[~compared["same"], "field"])
    assert {"seed", "config.scenario", "trials", "exploration trials"} <= differ and "host" not in differ and "command" not in differ


def test_a_new_column_source_plugs_into_frames_and_exports(db: Path, tmp_path: Path) -> None:
    """Where a trial records more (say its symbolic change), a column source adds the columns."""
    source = ColumnSource(
        "test-change",
        (Column("change_size", "nullable_int", "atoms changed"),),
        lambda store, records: [{"change_size": r.id % 3} if r.source == "exploration" else {} for r in records],
    )
    before = list(flat.TRIAL_COLUMN_SOURCES)
    register_trial_columns(source)
    try:
        with llcps.open(db) as wb:
            trials = wb.trials()
        assert list(trials.columns)[-1] == "change_size" and str(trials["change_size"].dtype) == "Int64"
        explored = trials[trials.source == "exploration"]
        assert (explored["change_size"] == explored["id"] % 3).all() and trials.loc[trials.source != "exploration", "change_size"].isna().all()
        out = tmp_path / "t.parquet"
        assert CliRunner().invoke(app, ["--db", str(db), "db", "export", "--format", "parquet", "--out", str(out)]).exit_code == 0
        assert pd.read_parquet(out)["change_size"].tolist()[-1] == explored["change_size"].tolist()[-1]
        with pytest.raises(ValueError, match="already exist"):
            register_trial_columns(ColumnSource("other", (Column("solved", "bool", "x"),), lambda s, r: []))
    finally:
        flat.TRIAL_COLUMN_SOURCES[:] = before


def test_parquet_export_reads_back_as_the_api_frame(db: Path, tmp_path: Path) -> None:
    out = tmp_path / "t.parquet"
    assert CliRunner().invoke(app, ["--db", str(db), "db", "export", "--format", "parquet", "--out", str(out)]).exit_code == 0
    exported = pd.read_parquet(out)
    with llcps.open(db) as wb:
        frame = wb.trials()
    assert list(exported.columns) == list(frame.columns)
    for name in ("id", "solved", *OUTCOME_NAMES, "rate", "arg0"):
        assert exported[name].tolist() == frame[name].tolist(), name


def test_importing_llcps_stays_cheap_and_the_api_never_loads_the_cli() -> None:
    code = (
        "import sys, llcps; heavy = ('pandas', 'typer', 'rich', 'sqlalchemy', 'torch', 'pybullet');"
        "print(sorted(m for m in heavy if m in sys.modules));"
        "import llcps.api; print(sorted(m for m in ('typer', 'rich', 'torch', 'pybullet') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env={**os.environ})
    assert out.stdout.split("\n")[:2] == ["[]", "[]"]


def _python_blocks(markdown: str) -> str:
    return "\n".join(re.findall(r"```python\n(.*?)```", markdown, flags=re.S))


def test_the_api_guide_example_runs(tmp_path: Path) -> None:
    """docs/api.md's notebook-style example, executed against a small store."""
    build_store(tmp_path / "llcps.db")
    code = _python_blocks((DOCS / "api.md").read_text(encoding="utf-8"))
    assert "llcps.open(" in code and "savefig" in code
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, env={**os.environ, "MPLBACKEND": "Agg"}, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "exploration_per_scenario.png").stat().st_size > 5_000
    assert "scenario2" in done.stdout


def test_the_main_jobs_run_from_python(tmp_path: Path) -> None:
    """pretrain, solve and replay through the Workbench, in real physics."""
    from llcps.errors import LlcpsError

    with llcps.open(tmp_path / "jobs.db", create=True) as wb:
        summary, fitted = wb.pretrain(trials=2, seed=3, models=["random"])
        assert summary.trials == 2 and [(f.name, f.trials) for f in fitted] == [("random", 2)]
        result = wb.solve("scenario3", model="random", budget=1, seed=2)
        assert result.status in ("solved", "budget_exhausted") and result.exploration_trials <= 1
        trials = wb.trials()
        assert trials["source"].tolist()[:2] == ["pretrain", "pretrain"] and (trials["episode_id"] == result.episode_id).sum() >= 1
        last = int(trials["id"].iloc[-1])
        assert wb.replay(last).matches
        assert wb.episodes()["id"].tolist() == [result.episode_id]
        with pytest.raises(LlcpsError, match="bad solve setting"):
            wb.solve("scenario3", budgets=3)
