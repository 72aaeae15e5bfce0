"""Progress, films and provenance as a researcher meets them: a real episode's phases and
film (rendering never in the stored times), the progress display, and where runs ran
shown by ``inspect runs`` and ``experiment report``."""

from __future__ import annotations

import io
import json
import socket
import time
from pathlib import Path
from typing import Iterator

import pytest
from PIL import Image
from rich.console import Console
from typer.testing import CliRunner

import llcps
from llcps.cli import _progress
from llcps.cli.main import app
from llcps.cps.episode import SolveConfig, solve
from llcps.cps.film import FILM_EVERY, FILM_SIZE, episode_shots
from llcps.cps.replay import replay
from llcps.experiments.design import Cell, Sequence
from llcps.cps.pretraining import pretrain
from llcps.sim.render import CAPTION_HEIGHT
from llcps.store import Store

runner = CliRunner()


@pytest.fixture(scope="module")
def episode(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, object]]:
    """One real solve of scenario3's novelty with a GIF, its progress calls timed."""
    folder = tmp_path_factory.mktemp("film")
    db, gif = folder / "film.db", folder / "episode.gif"
    calls: list[tuple[float, str, int, int]] = []
    with Store.open(str(db), create=True) as store:
        pretrain(store, branch="main", n=3, seed=5)
        started = time.perf_counter()
        result = solve(
            store,
            branch=None,
            config=SolveConfig(scenario="scenario3", budget=4, seed=0),
            gif=gif,
            progress=lambda phase, done, total: calls.append((time.perf_counter() - started, phase, done, total)),
        )
    yield {"db": db, "gif": gif, "calls": calls, "result": result}


def test_solve_reports_its_phases_in_order(episode: dict[str, object]) -> None:
    calls = episode["calls"]
    result = episode["result"]
    phases = [c[1] for c in calls]  # type: ignore[union-attr]
    assert phases[0] == "fit world model nb" and phases[1] == "plan"
    first_render = phases.index("render")
    assert all(p in ("fit world model nb", "plan", "explore", "re-plan") for p in phases[:first_render])
    assert set(phases[first_render:]) <= {"render", "write GIF"} and phases[-1] == "write GIF"
    # exploration: from its first report on (a re-plan before it is plan repair, total unknown)
    first_explore = phases.index("explore")
    explore = [c for c in calls[first_explore:] if c[1] in ("explore", "re-plan")]  # type: ignore[index]
    assert result.exploration_trials > 0 and explore  # type: ignore[attr-defined]
    assert {c[3] for c in explore} == {min(4, result.candidates)}  # type: ignore[attr-defined]
    assert [c[2] for c in explore] == sorted(c[2] for c in explore)
    assert explore[-1][2] == result.exploration_trials  # type: ignore[attr-defined]
    frames = [c for c in calls if c[1] == "render"]  # type: ignore[union-attr]
    assert frames[-1][2] == frames[-1][3] > 0


def test_rendering_is_not_in_the_stored_wall_time(episode: dict[str, object]) -> None:
    calls, result = episode["calls"], episode["result"]
    render_started = next(c[0] for c in calls if c[1] == "render")  # type: ignore[union-attr]
    rendering = calls[-1][0] - render_started  # type: ignore[index]
    assert rendering > 0.5
    assert result.wall_seconds <= render_started  # type: ignore[attr-defined]
    with Store.open(str(episode["db"])) as store:
        (stored,) = store.list_episodes()
    assert stored.summary["wall_seconds"] == round(result.wall_seconds, 4)  # type: ignore[attr-defined]


def test_the_film_is_the_plan_the_resolution_and_its_plan_captioned(episode: dict[str, object]) -> None:
    result = episode["result"]
    with Store.open(str(episode["db"])) as store:
        shots = episode_shots(store, result.episode_id)  # type: ignore[attr-defined]
    phases = [s.phase for s in shots]
    assert phases[0] == "plan" and all(s.trial.source == "plan" for s in shots if s.phase in ("plan", "re-plan"))
    if result.status == "solved" and result.exploration_trials:  # type: ignore[attr-defined]
        resolving = [s.trial.id for s in shots if s.phase == "explore"]
        assert resolving == [result.resolving_trial_id]  # type: ignore[attr-defined]
    gif = Image.open(episode["gif"])
    assert gif.size == (FILM_SIZE[0], FILM_SIZE[1] + CAPTION_HEIGHT)
    steps = sum(s.trial.sim_steps for s in shots)
    assert gif.n_frames >= steps // FILM_EVERY // 2  # identical frames may merge
    gif.seek(0)
    band = gif.convert("RGB").crop((0, FILM_SIZE[1], FILM_SIZE[0], FILM_SIZE[1] + CAPTION_HEIGHT))
    assert len(band.getcolors(1 << 16)) > 2  # the caption's text is drawn in the band


def test_replay_film_reports_frames(episode: dict[str, object], tmp_path: Path) -> None:
    calls: list[tuple[str, int, int]] = []
    with Store.open(str(episode["db"])) as store:
        trial = store.visible_trials(None, source="plan")[0]
        report = replay(store, trial.id, gif=tmp_path / "t.gif", progress=lambda *c: calls.append(c))
    assert report.matches
    rendered = [c for c in calls if c[0] == "render"]
    assert rendered[-1][1] == rendered[-1][2] == trial.sim_steps // FILM_EVERY + 2
    assert Image.open(tmp_path / "t.gif").size[1] == FILM_SIZE[1] + CAPTION_HEIGHT


def test_progress_display_shows_phase_counts_and_eta(monkeypatch: pytest.MonkeyPatch) -> None:
    screen = io.StringIO()
    monkeypatch.setattr(_progress, "err_console", Console(file=screen, force_terminal=True, width=120))
    with _progress.progress_display("solve", "loading the simulator") as progress:
        time.sleep(0.25)
        progress("plan")
        time.sleep(0.25)
        for done in range(4):
            progress("explore", done, 10)
            time.sleep(0.15)
        progress("re-plan", 4, 10)
        time.sleep(0.15)
    text = screen.getvalue()
    assert "solve: loading the simulator" in text and "solve: plan" in text
    assert "solve: explore" in text and "3/10" in text and "solve: re-plan" in text and "eta" in text


# -- provenance, shown -----------------------------------------------------------------------


def test_inspect_runs_and_episodes_show_what_ran_where(episode: dict[str, object]) -> None:
    db = str(episode["db"])
    runs = json.loads(runner.invoke(app, ["--db", db, "inspect", "runs", "--json"]).stdout)
    assert [r["command"] for r in runs] == ["pretrain", "solve"]
    assert runs[1]["provenance"]["host"] == socket.gethostname() and runs[1]["provenance"]["llcps_version"] == llcps.__version__
    assert runs[1]["activity"]["episodes"] == 1 and runs[0]["activity"]["pretrain"] == 3
    assert runs[1]["config"]["model_seed"] == runs[1]["config"]["seed"] == 0  # --model-seed defaults to --seed
    table = runner.invoke(app, ["--db", db, "inspect", "runs"]).stdout
    assert "host" in table and socket.gethostname() in table and "pretrain" in table
    episodes = json.loads(runner.invoke(app, ["--db", db, "inspect", "episodes", "--json"]).stdout)
    assert [e["scenario"] for e in episodes] == ["scenario3"] and episodes[0]["run_id"] == runs[1]["id"]
    compared = json.loads(runner.invoke(app, ["--db", db, "inspect", "runs", "--compare", "1", "2", "--json"]).stdout)
    assert {"command", "seed", "pretrain trials"} <= set(compared["differences"]) and "host" not in compared["differences"]
    missing = runner.invoke(app, ["--db", db, "inspect", "runs", "--compare", "1", "99"])
    assert missing.exit_code == 2 and "unknown run 99" in missing.stderr


def test_experiment_report_prints_and_keeps_the_provenance(tmp_path: Path) -> None:
    db = tmp_path / "exp.db"
    with Store.open(str(db), create=True) as store:
        for condition in ("update", "reset"):
            seq = Sequence("smoke", Cell("nb", "most-changes", 4, condition), 0)
            for scenario in ("scenario1", "scenario2", "scenario3"):
                branch = seq.episode_branch(scenario)
                if branch not in {b.name for b in store.list_branches()}:
                    store.create_branch(branch, from_branch="main", at=0)
                run = store.start_run(command="experiment run --preset smoke", seed=0, config={}, branch=branch)
                episode = store.start_episode(run_id=run, branch=branch, scenario=scenario, condition="novelty", model="nb", measure="most-changes", seed=0)
                summary = {"solved": False, "exploration_trials": 5, "sim_seconds": 1.0, "wall_seconds": 2.0, "status": "budget_exhausted"}
                store.finish_episode(episode, status="budget_exhausted", summary=summary)
                store.finish_run(run, status="budget_exhausted")
    out = tmp_path / "report"
    done = runner.invoke(app, ["--db", str(db), "experiment", "report", "--from-db", "--out-dir", str(out)])
    assert done.exit_code == 0, done.output
    line = next(ln for ln in done.stderr.splitlines() if ln.startswith("provenance: "))
    assert f"llcps {llcps.__version__}" in line and socket.gethostname() in line and "6 run(s)" in line
    assert "## Where it ran" in (out / "report.md").read_text() and (out / "provenance.json").is_file()
    results = (out / "results.csv").read_text().splitlines()
    solved = results[0].split(",").index("solved")
    assert {line.split(",")[solved] for line in results[1:]} == {"false"}  # booleans as every export writes them
    again = runner.invoke(app, ["experiment", "report", str(out), "--json"])  # from the directory alone
    assert again.exit_code == 0 and json.loads(again.stdout)["provenance"][0]["runs"] == 6
