"""The README's commands, exactly as written, on a temporary store: what a newcomer types
from a fresh clone works and says what it does."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest
from test_experiments_report import synthetic_table
from typer.testing import CliRunner

from llcps.analysis.results import ResultsTable
from llcps.cli.main import app
from llcps.sim.render import CAPTION_HEIGHT, captioned
from llcps.store import Store

runner = CliRunner()


def llcps(*args: str) -> Any:  # click Result
    """One command as the README writes it (the store is ./llcps.db of the current directory)."""
    return runner.invoke(app, list(args))


def ok(*args: str) -> Any:
    result = llcps(*args)
    assert result.exit_code == 0, (args, result.stdout, result.stderr)
    return result


@pytest.fixture(scope="module")
def readme_dir(tmp_path_factory: pytest.TempPathFactory, readme_pretrained: Path) -> Iterator[Path]:
    """A directory after the README's first commands: db init, pretrain (a copy of the
    run's ``readme_pretrained`` store), solve scenario2."""
    where = tmp_path_factory.mktemp("readme")
    shutil.copyfile(readme_pretrained, where / "llcps.db")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(where)
        solved = json.loads(ok("solve", "scenario2", "--model", "nb", "--measure", "most-positive-changes", "--json").stdout)
        assert solved["status"] == "solved" and solved["learned_operators"], solved
        yield where


@pytest.fixture
def in_readme_dir(readme_dir: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(readme_dir)
    return readme_dir


@pytest.mark.slow
def test_solve_a_shown_file(in_readme_dir: Path) -> None:
    """`llcps scenario show scenario2 --format toml > my.toml; llcps solve my.toml`."""
    (in_readme_dir / "my.toml").write_text(ok("scenario", "show", "scenario2", "--format", "toml").stdout)
    solved = json.loads(ok("solve", "my.toml", "--json").stdout)
    assert solved["scenario"] == "my" and solved["status"] == "solved"


@pytest.mark.slow
def test_inspect_model_after_a_solve_prints_metrics_and_how_to_rank(in_readme_dir: Path) -> None:
    """`llcps inspect model --scenario scenario2` after the solve: the plan now succeeds, so
    the metrics come with a note instead of a ranking, and the hint's commands rank."""
    shown = ok("inspect", "model", "--scenario", "scenario2")
    assert "held-out trials" in shown.stdout and "nb / " not in shown.stdout
    assert "no candidates ranked: the plan for scenario2's novelty condition succeeds on 'main'" in shown.stderr
    assert "llcps db branch before --at pretrain" in shown.stderr
    as_json = json.loads(ok("inspect", "model", "--scenario", "scenario2", "--json").stdout)
    assert as_json["evaluations"] and "succeeds" in as_json["ranking_note"] and "scenario" not in as_json
    ok("db", "branch", "before", "--at", "pretrain")
    ranked = ok("--branch", "before", "inspect", "model", "--scenario", "scenario2", "--limit", "1")
    assert "nb / most-positive-changes" in ranked.stdout and "no candidates ranked" not in ranked.stderr


@pytest.mark.slow
def test_a_solve_run_lasts_as_long_as_its_episode(in_readme_dir: Path) -> None:
    """`llcps inspect runs`: a solve's run starts with the command, so it lasts at least as
    long as its episode (which counts the model fit)."""
    runs = {r["id"]: r for r in json.loads(ok("inspect", "runs", "--json").stdout)}
    episodes = json.loads(ok("inspect", "episodes", "--json").stdout)
    assert episodes
    for episode in episodes:
        run = runs[episode["run_id"]]
        assert run["seconds"] >= episode["summary"]["wall_seconds"] - 0.01, (run, episode)


@pytest.mark.slow
def test_pretrain_again_is_skipped_and_at_pretrain_sees_only_pretraining(in_readme_dir: Path) -> None:
    """`make run` twice: the second `llcps pretrain --trials 200 --seed 1` stores nothing, and
    after more pretraining (--again, 20 trials) `llcps db branch fresh --at pretrain` still
    forks after the first 200 trials: no exploration trial, no learned operator."""
    with Store.open("llcps.db") as store:
        before = store.count_visible_trials("main")
    again = ok("pretrain", "--trials", "200", "--seed", "1")
    assert "pretraining with --trials 200 --seed 1 is already on branch main (run 1): skipped; --again to add more" in again.stderr
    ok("db", "branch", "twice")
    ok("--branch", "twice", "pretrain", "--trials", "20", "--seed", "1", "--again", "--model", "nb")
    with Store.open("llcps.db") as store:
        assert store.count_visible_trials("main") == before
        assert store.count_visible_trials("twice") == before + 20
    ok("db", "branch", "fresh", "--from", "twice", "--at", "pretrain")
    with Store.open("llcps.db") as store:
        seen = store.visible_trials("fresh")
        assert len(seen) == 200 and {t.source for t in seen} == {"pretrain"}
        assert not store.visible_operators("fresh") and store.visible_operators("twice")
    knowledge = json.loads(ok("--branch", "fresh", "inspect", "knowledge", "--json").stdout)
    assert knowledge["learned_operators"] == []


# --- no physics -------------------------------------------------------------------------


def test_experiment_report_reads_the_default_results_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`llcps experiment report --html`: without results/paper it names what to pass; with it
    it writes report.html there and says that films need --from-db."""
    monkeypatch.chdir(tmp_path)
    missing = llcps("experiment", "report", "--html")
    assert missing.exit_code == 2 and "Traceback" not in missing.output
    lines = missing.stderr.splitlines()
    assert any(line.startswith("error: no results directory given, and results/paper holds no results.csv") for line in lines)
    assert any(line.startswith("hint: ") and "--from-db" in line for line in lines)
    assert not (tmp_path / "results").exists()
    table = ResultsTable([dataclasses.replace(row, preset="paper") for row in synthetic_table(seeds=2).rows])
    (tmp_path / "results" / "paper").mkdir(parents=True)
    table.write_csv(tmp_path / "results" / "paper" / "results.csv")
    done = ok("experiment", "report", "--html")
    assert (tmp_path / "results" / "paper" / "report.html").is_file()
    assert "report.html has no films" in done.stderr and "--from-db" in done.stderr
    both = llcps("experiment", "report", "results/paper", "--from-db")
    assert both.exit_code == 2 and "not both" in both.stderr


def test_a_long_caption_stays_within_the_frame() -> None:
    """The replay GIF's caption: a line wider than the frame is drawn smaller or cut, never
    past the right edge."""
    frame = np.zeros((300, 400, 3), dtype=np.uint8)
    long = "remove_from_container(ball, cup) · rate 0.0625 m/s · 0.05 m · left · and a great deal more"
    image = np.asarray(captioned(frame, ("trial 4242 · explore · scenario3", long)))
    band = image[300:, :, :]
    assert band.shape[0] == CAPTION_HEIGHT
    ink = np.nonzero((band < 200).any(axis=2).any(axis=0))[0]
    assert ink.size and ink.max() < 400 - 3  # the right margin stays blank
    short = np.asarray(captioned(frame, ("trial 1", "push(cube)")))
    assert (short[300:] < 200).any()
