"""Lives: the life file's schema, the paired draws, the metrics worked by hand, a tiny life
run end to end (killed and resumed), and the `paper` life against the `lifelong` preset."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Iterator

import pytest
from test_experiments_runner import _alive, _children, _has_branch, _llcps, store_signature
from typer.testing import CliRunner

from llcps.analysis.lives import COLUMNS, LifeRow, life_metrics
from llcps.cli.main import app
from llcps.errors import LlcpsError
from llcps.experiments.life import draw_life, life_condition, life_from_data, load_life, pretrain_branch
from llcps.experiments.presets import PRESETS
from llcps.experiments.runner import LifeTask, PretrainTask, SequenceTask, plan_life_tasks, plan_tasks, run_lives
from llcps.store import Store

TINY = """
name = "tiny"
families = ["scenario1", "scenario2"]
episodes = 4
p_recur = 0.5
conditions = ["update", "reset"]
budget = 3
[variants]
draw = "random"
range = [5000, 5010]
[pretraining]
count = 8
"""


def _file(tmp_path: Path, text: str, name: str = "life.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# -- the schema ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "change, field, reason",
    [
        ("p_recur = 1.5", "p_recur", "less than or equal to 1"),
        ("episodes = 0", "episodes", "greater than or equal to 1"),
        ('conditions = ["update", "sometimes"]', "conditions", "unknown condition 'sometimes'"),
        ('probes = ["scenario9"]', "probes", "not one of the life's families"),
        ("probes = 2", "probes", "leave none of the 2 families"),
        ('families = ["nowhere"]', "families", "unknown scenario 'nowhere'"),
        ("budget = -1", "budget", "'whole' or a number"),
        ('colour = "red"', "colour", "unknown key"),
        ('[variants]\ndraw = "sometimes"', "variants.draw", "canonical"),
        ("[pretraining]\ncount = 0", "pretraining.count", "greater than or equal to 1"),
    ],
)
def test_a_bad_life_file_is_one_error_naming_file_and_field(tmp_path: Path, change: str, field: str, reason: str) -> None:
    import tomllib

    data = tomllib.loads(TINY)
    patch = tomllib.loads(change)
    for key, value in patch.items():
        data[key] = {**data.get(key, {}), **value} if isinstance(value, dict) else value
    with pytest.raises(LlcpsError) as caught:
        life_from_data("mine.toml", data)
    assert caught.value.message.startswith(f"mine.toml: {field}: ") and reason in caught.value.message


def test_bad_life_input_exits_2_with_one_error_line(tmp_path: Path) -> None:
    bad = _file(tmp_path, TINY.replace("p_recur = 0.5", "p_recur = 2"))
    broken = _file(tmp_path, "name = [", "broken.toml")
    runner = CliRunner()
    for argv, error in (
        (["life", "show", str(bad)], f"{bad}: p_recur:"),
        (["life", "show", str(broken)], "not a TOML file"),
        (["life", "show", "nosuch"], "unknown life 'nosuch'"),
        (["life", "run", "paper", "--episodes", "9"], "--episodes must be from 1 to the life's 3"),
        (["life", "run", "paper", "--conditions", "update,never"], "unknown life condition 'never'"),
    ):
        result = runner.invoke(app, ["--db", str(tmp_path / "none.db"), *argv])
        assert result.exit_code == 2, (argv, result.output)
        assert error in result.stderr and "Traceback" not in result.output
    assert not (tmp_path / "none.db").exists()  # checked before a store is opened


def test_the_shipped_lives_load_and_default_uses_every_shipped_family() -> None:
    from llcps.scenarios import shipped_names

    default = load_life("default")
    assert default.family_names == tuple(shipped_names())
    assert (default.episodes, default.p_recur, default.probes) == (40, 0.6, 2)
    assert set(default.conditions) == {"update", "reset", "scratch", "random"}
    paper = load_life("paper")
    assert paper.family_names == ("scenario1", "scenario2", "scenario3")


def test_the_held_out_judge_holds_every_held_out_family_back_as_probes(monkeypatch: pytest.MonkeyPatch) -> None:
    from llcps.scenarios import shipped_names

    root = Path(__file__).parent.parent
    monkeypatch.chdir(root)  # the file names its families from the repository's root
    life = load_life("docs/lives/heldout.toml")
    held_out = {path.stem for path in (root / "docs" / "heldout").glob("*.toml")}
    assert set(life.family_names) == set(shipped_names()) | held_out and set(life.probes) == held_out
    quarter = life.episodes - life.episodes // 4
    for seed in range(10):
        draw = draw_life(life, seed)
        firsts = {e.family: e.index for e in draw.episodes if e.first_encounter}
        assert set(firsts) >= held_out and all(firsts[f] >= quarter for f in held_out)


# -- the draws -----------------------------------------------------------------------------
def test_a_lifes_seed_fixes_its_episodes_and_every_condition_gets_the_same_list() -> None:
    life = load_life("default")
    assert draw_life(life, 7) == draw_life(life, 7)
    assert [e.family for e in draw_life(life, 7).episodes] != [e.family for e in draw_life(life, 8).episodes]
    tasks = [t for t in plan_life_tasks(life, [3, 4]) if isinstance(t, LifeTask)]
    for seed in (3, 4):
        lists = {t.condition.name: t.episodes for t in tasks if t.seed == seed}
        assert set(lists) == set(life.conditions)
        assert len(set(lists.values())) == 1  # identical episode lists: paired lives
    # Updating conditions re-solve after the life; reset does not; scratch has no pretraining.
    by = {t.condition.name: t for t in tasks if t.seed == 3}
    assert by["update"].after and not by["reset"].after and by["scratch"].pretrain is None


def test_an_ordering_runs_as_a_condition() -> None:
    from llcps.cps.orderings import ORDERINGS

    life = load_life("default").with_conditions(["update", "reset", "ranked"])
    tasks = {t.condition.name: t for t in plan_life_tasks(life, [0]) if isinstance(t, LifeTask)}
    assert tasks["ranked"].ordering == "ranked" and tasks["ranked"].condition.carry == "update"
    assert tasks["update"].ordering == tasks["reset"].ordering == ORDERINGS.default
    assert tasks["ranked"].episodes == tasks["update"].episodes and tasks["ranked"].label == "life-default-ranked-l0"


def test_every_ordering_runs_as_a_condition_under_a_branch_safe_name() -> None:
    from llcps.cps.orderings import ORDERINGS, PAPER_ORDERING
    from llcps.experiments.life import LIFE_CONDITIONS, condition_names

    named = {n: life_condition(n).ordering for n in condition_names() if n not in LIFE_CONDITIONS}
    assert sorted(named.values()) == sorted(ORDERINGS)  # case-based and trial-and-error too
    # The random order is the random model ranked, whatever the life explores in.
    for ordering in (None, "hedged", "trial-and-error"):
        assert replace(load_life("default"), ordering=ordering).ordering_for(life_condition("random")) == PAPER_ORDERING
    life = load_life("default").with_conditions(["update", "case_based", "trial_and_error"])
    tasks = {t.condition.name: t for t in plan_life_tasks(life, [0]) if isinstance(t, LifeTask)}
    assert tasks["case_based"].ordering == "case-based" and tasks["trial_and_error"].ordering == "trial-and-error"
    assert tasks["case_based"].label == "life-default-case_based-l0"
    with pytest.raises(LlcpsError):
        life_condition("case-based")  # a condition names branches: '_' for '-'


def test_the_draw_holds_probes_back_and_marks_first_encounters() -> None:
    life = load_life("default")
    quarter = life.episodes - life.episodes // 4
    for seed in range(20):
        draw = draw_life(life, seed)
        assert len(draw.episodes) == life.episodes and len(draw.probes) == 2
        seen: set[str] = set()
        for e in draw.episodes:
            assert e.first_encounter == (e.family not in seen)
            seen.add(e.family)
            if e.probe and e.first_encounter:
                assert e.index >= quarter
            assert e.probe == (e.family in draw.probes)
        assert set(draw.probes) <= seen  # every probe is met in the last quarter
        assert {f for f, _ in draw.after} == seen
        for family, variant in draw.after:  # a fresh variant: not one the life solved
            assert variant not in {e.variant for e in draw.episodes if e.family == family}
    cut = life.with_episodes(10)
    assert draw_life(cut, 5).episodes == draw_life(life, 5).episodes[:10]


def test_original_condition_episodes_are_drawn_among_recurrences_only() -> None:

    life = replace(load_life("default"), original_share=0.5)
    episodes = [e for seed in range(5) for e in draw_life(life, seed).episodes]
    originals = [e for e in episodes if e.condition == "original"]
    recurrences = [e for e in episodes if not e.first_encounter]
    assert originals and not any(e.first_encounter for e in originals)
    assert 0.3 < len(originals) / len(recurrences) < 0.7
    assert all(e.condition == "novelty" for e in draw_life(load_life("default"), 0).episodes)


def test_the_paper_life_plans_the_lifelong_presets_episodes() -> None:
    """Same pretraining, model, measure, budget, refits, scenes and branch structure, seed by seed."""
    preset = PRESETS["lifelong"]
    life = load_life("paper")
    seeds = [0, 1, 2]
    sequences = {(t.sequence.seed, t.sequence.cell.condition): t for t in plan_tasks(preset, seeds) if isinstance(t, SequenceTask)}
    pretraining = [t for t in plan_tasks(preset, seeds) if isinstance(t, PretrainTask)]
    ours = plan_life_tasks(life, seeds)
    assert [(t.seed, t.pool) for t in ours if isinstance(t, PretrainTask)] == [(t.seed, t.pool) for t in pretraining]
    for task in (t for t in ours if isinstance(t, LifeTask)):
        seq = sequences[(task.seed, task.condition.name)]
        assert (task.model, task.measure, task.budget, task.refit_every, task.ordering) == (
            seq.sequence.cell.model, seq.sequence.cell.measure, seq.budget, seq.refit_every, seq.ordering,
        )  # fmt: skip
        assert [(e.family, e.variant, e.condition) for e in task.episodes] == [(s, 0, "novelty") for s in seq.sequence.scenarios]
        # update: one branch for the whole sequence; reset: each episode on its own fork of the pretraining
        assert len(task.branches) == len(seq.branches) and not task.after


# -- the metrics, worked by hand -----------------------------------------------------------
def _row(life: int, condition: str, episode: int, family: str, first: bool, n: int, solved: bool = True, **kw: Any) -> LifeRow:
    return LifeRow(
        life=life, condition=condition, episode=episode, family=family, variant=0, first_encounter=first, probe=False,
        episode_condition=kw.get("episode_condition", "novelty"), exploration_trials=n, solved=solved, censored=not solved,
        wall_seconds=1.0, sim_seconds=1.0, tau=9, phase=kw.get("phase", "life"),
    )  # fmt: skip


def hand_rows() -> list[LifeRow]:
    """Two lives of A, B, A, B and B, A, B, A; tau 9, so AUC_k = (10 - min(N, 9)) / 10."""
    rows = []
    order = {0: ["A", "B", "A", "B"], 1: ["B", "A", "B", "A"]}
    counts = {  # (N, solved) per episode
        ("update", 0): [(4, True), (9, False), (0, True), (2, True)],
        ("reset", 0): [(4, True), (9, False), (4, True), (6, True)],
        ("update", 1): [(2, True), (4, True), (1, True), (0, True)],
        ("reset", 1): [(2, True), (6, True), (3, True), (4, True)],
    }
    for (condition, life), values in counts.items():
        for k, (n, solved) in enumerate(values):
            rows.append(_row(life, condition, k, order[life][k], k < 2, n, solved))
    after = {(0, "A"): (1, True), (0, "B"): (9, False), (1, "A"): (0, True), (1, "B"): (2, True)}
    for (life, family), (n, solved) in after.items():
        rows.append(_row(life, "update", -1, family, False, n, solved, phase="after"))
        original = 1 if (life, family) == (1, "B") else 0
        rows.append(_row(life, "update", -1, family, False, original, True, phase="after", episode_condition="original"))
    return rows


def test_the_metrics_of_a_hand_made_life_table() -> None:
    metrics = life_metrics(hand_rows())
    update = next(c for c in metrics.conditions if c.condition == "update")
    assert [c.condition for c in metrics.conditions] == ["update", "reset"]
    # AUC per life: update 0.625 and 0.825, reset 0.425 and 0.625 (the censored episode counts as tau: 0.1)
    assert update.auc_life.value == pytest.approx(0.725)
    assert update.auc_difference.value == pytest.approx(0.2)
    # FT: first encounters 0.525 against 0.475; recurrences 0.925 against 0.575
    assert update.ft_first.value == pytest.approx(0.05 / 0.525)
    assert update.ft_recurrence.value == pytest.approx(0.35 / 0.425)
    # NRP over the last episode: 0.9 / 0.5; curve ratio (1/3) / (5/3)
    assert metrics.last == 1 and update.nrp.value == pytest.approx(1.8)
    assert update.curve_ratio.value == pytest.approx(0.2)
    # Forgetting: life 0 (1.0-0.9 + 0.8-0.1)/2 = 0.4, life 1 (0.9-0.8 + 1.0-1.0)/2 = 0.05; originals 3 of 4 at 0
    assert update.forgetting.value == pytest.approx(0.225)
    assert (update.originals_kept, update.originals) == (3, 4)
    assert update.auc_life.low <= update.auc_life.value <= update.auc_life.high
    curve = {(p.condition, p.episode): p for p in metrics.curve}
    assert curve[("update", 1)].mean == pytest.approx(6.5) and curve[("update", 1)].km_median == 4
    family_a = next(f for f in metrics.families if f.family == "A")
    assert (family_a.auc, family_a.auc_reset) == (pytest.approx(0.8), pytest.approx(0.55))
    assert family_a.difference.value == pytest.approx(0.25)
    # Family A's forgetting: life 0 1.0-0.9, life 1 1.0-1.0; family B: 0.7 and 0.1
    assert family_a.forgetting.value == pytest.approx(0.05)
    assert next(f for f in metrics.families if f.family == "B").forgetting.value == pytest.approx(0.4)
    assert math.isnan(next(c for c in metrics.conditions if c.condition == "reset").ft_first.value)


def test_the_report_writes_every_file_and_column(tmp_path: Path) -> None:
    from llcps.report.lives import write_life_report

    rows = hand_rows()
    paths = write_life_report(rows, life_metrics(rows), tmp_path / "rep", life="hand", html=True)
    with paths.episodes.open() as fh:
        table = list(csv.DictReader(fh))
    assert list(table[0]) == list(COLUMNS) and len(table) == 16
    assert json.loads(paths.metrics_json.read_text())["conditions"][0]["condition"] == "update"
    text = paths.markdown.read_text()
    assert "FT first encounters" in text and "learning_curve.png" in text
    assert paths.html is not None and "data:image/png;base64," in paths.html.read_text()


# -- a tiny life in physics ----------------------------------------------------------------
@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Store, Path]]:
    """One tiny life (2 families, 4 episodes, budget 3) under update and reset, uninterrupted."""
    directory = tmp_path_factory.mktemp("tiny")
    path = _file(directory, TINY, "tiny.toml")
    with Store.open(str(directory / "ref.db"), create=True) as store:
        summary = run_lives(store, load_life(str(path)), lives=1, workers=1)
        assert summary.status == "ok" and summary.done == 3
        yield store, path


def test_a_tiny_life_stores_each_episode_with_its_place_in_the_life(tiny: tuple[Store, Path]) -> None:
    store, path = tiny
    life = load_life(str(path))
    draw = draw_life(life, 0)
    for condition in ("update", "reset"):
        stored = sorted(
            (e for e in store.list_episodes() if e.summary.get("life", {}).get("condition") == condition), key=lambda e: e.id
        )
        places = [e.summary["life"] for e in stored if e.summary["life"]["phase"] == "life"]
        assert [(p["episode"], p["family"], p["variant"], p["first_encounter"]) for p in places] == [
            (e.index, e.family, e.variant, e.first_encounter) for e in draw.episodes
        ]
    after = [e for e in store.list_episodes() if e.summary.get("life", {}).get("phase") == "after"]
    assert len(after) == 2 * len(draw.after)  # update only: a fresh variant and the original, per family
    assert pretrain_branch(life, 0) in store.branch_names()


@pytest.mark.slow
def test_a_killed_life_run_resumes_without_duplicate_or_lost_episodes(tiny: tuple[Store, Path], tmp_path: Path) -> None:
    ref, path = tiny
    db, out = tmp_path / "killed.db", tmp_path / "report"
    args = ("--db", str(db), "life", "run", str(path), "--lives", "1", "--workers", "1", "--out-dir", str(out), "--create")
    first = pretrain_branch(load_life(str(path)), 0)
    child = subprocess.Popen(_llcps(*args), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 240
        while True:  # kill -9 once the pretraining is imported, with the lives in flight
            assert child.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline, "the pretraining was never imported"
            if _has_branch(db, first):
                break
            time.sleep(0.2)
        workers = _children(child.pid)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.kill()
        child.wait()
    deadline = time.monotonic() + 30
    while any(_alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    done = subprocess.run(_llcps(*args, "--json"), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    data = json.loads(done.stdout)
    assert data["run"]["tasks_skipped"] >= 1 and data["run"]["tasks_skipped"] + data["run"]["tasks_done"] == 3
    with Store.open(str(db)) as store:
        assert store_signature(store, "life-") == store_signature(ref, "life-")  # each episode once, as uninterrupted
    with (out / "episodes.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert list(table[0]) == list(COLUMNS)
    assert sorted((r["condition"], int(r["episode"])) for r in table) == sorted((c, k) for c in ("update", "reset") for k in range(4))
    assert all(r[c] != "" for r in table for c in COLUMNS if c != "status")


@pytest.mark.slow
def test_the_paper_life_solves_the_lifelong_presets_episodes(tmp_path: Path) -> None:
    """Seed 0 of the `lifelong` preset and life 0 of `paper`, both on their first two scenarios
    and cut to 8 pretraining interactions and 5 trials per episode (the plan above checks the
    real settings): the same trials, episode by episode, update carrying scenario 1 into 2."""

    from llcps.experiments.runner import run_experiment

    first_two = ["scenario1", "scenario2"]
    preset = replace(PRESETS["lifelong"], pretrain_sizes=(8,), pretrain_pool=8, budget=5).with_scenarios(first_two)
    life = replace(load_life("paper").with_episodes(2), pretrain_count=8, budget=5)
    with Store.open(str(tmp_path / "both.db"), create=True) as store:
        assert run_experiment(store, preset=preset, seeds=[0], workers=1).status == "ok"
        assert run_lives(store, life, lives=[0], workers=1).status == "ok"
        theirs_all, ours_all = store_signature(store, "exp-lifelong-"), store_signature(store, "life-paper-")
    sequences = {s.cell.condition: s for s in preset.sequences([0])}
    update, ours = theirs_all[sequences["update"].branch_name], ours_all["life-paper-update-l0"]
    assert len(update["episodes"]) == 2 and update["own"]
    assert (update["own"], update["episodes"], update["seen_at_fork"]) == (ours["own"], ours["episodes"], ours["seen_at_fork"])
    for index, scenario in enumerate(sequences["reset"].scenarios):
        theirs, ours = theirs_all[sequences["reset"].episode_branch(scenario)], ours_all[f"life-paper-reset-l0-e{index}"]
        assert (theirs["own"], theirs["episodes"]) == (ours["own"], ours["episodes"])


def test_the_api_reads_a_lifes_episodes(tiny: tuple[Store, Path]) -> None:
    from llcps.api import LIFE_COLUMNS, Workbench

    store, path = tiny
    wb = Workbench(store)
    lives = wb.lives(str(path))
    assert list(lives.columns) == list(LIFE_COLUMNS) == list(COLUMNS)
    life = lives[lives["phase"] == "life"]
    assert sorted(zip(life["condition"], life["episode"])) == sorted((c, k) for c in ("update", "reset") for k in range(4))
    assert (lives["censored"] == ~lives["solved"]).all()
    episodes = wb.episodes()
    mine = episodes[episodes["life_name"] == "tiny"]
    assert len(mine) == len(lives) and set(mine["life_condition"]) == {"update", "reset"}
    assert mine.loc[mine["life_episode"] == 0, "first_encounter"].all()


def test_a_stored_life_with_other_episodes_is_refused(tiny: tuple[Store, Path], tmp_path: Path) -> None:
    """An edited life file under the same name would pass for the stored lives: refused before anything runs."""
    store, path = tiny
    edited = load_life(str(_file(tmp_path, TINY.replace("range = [5000, 5010]", "range = [6000, 6010]"), "tiny.toml")))
    with pytest.raises(LlcpsError, match="other episodes than this run draws"):
        run_lives(store, edited, lives=1, workers=1)
    again = run_lives(store, load_life(str(path)), lives=1, workers=1)  # the same file: everything is stored
    assert (again.done, again.skipped, again.status) == (0, 3, "ok")


def test_life_list_and_show_as_json() -> None:
    runner = CliRunner()
    listed = runner.invoke(app, ["life", "list", "--json"])
    assert listed.exit_code == 0 and {"paper", "default"} <= {item["name"] for item in json.loads(listed.stdout)}
    shown = runner.invoke(app, ["life", "show", "default", "--life", "4", "--json"])
    assert shown.exit_code == 0
    data = json.loads(shown.stdout)
    expected = draw_life(load_life("default"), 4)
    assert [e["family"] for e in data["episodes"]] == [e.family for e in expected.episodes]
    assert data["probes"] == list(expected.probes) and 'name = "default"' in data["file"]


def test_scratch_starts_from_nothing_and_needs_no_pretraining(tmp_path: Path) -> None:
    life = load_life(str(_file(tmp_path, TINY.replace('conditions = ["update", "reset"]', 'conditions = ["scratch"]'))))
    life = life.with_episodes(2)
    assert not any(isinstance(t, PretrainTask) for t in plan_life_tasks(life, [0]))
    with Store.open(str(tmp_path / "scratch.db"), create=True) as store:
        summary = run_lives(store, life, lives=1, workers=1)
        assert (summary.status, summary.done) == ("ok", 1)
        branch = store.resolve_branch("life-tiny-scratch-l0")
        assert (branch.parent, branch.fork_point) == ("main", 0)
        assert not [t for t in store.visible_trials("life-tiny-scratch-l0") if t.source == "pretrain"]
        assert len([e for e in store.list_episodes() if e.summary.get("life", {}).get("phase") == "life"]) == 2


def test_a_life_in_the_rl_ordering_wants_a_policy_where_it_starts_before_anything_runs(sqlite_store: Store) -> None:
    life = load_life("default").with_episodes(2).with_conditions(["rl"])
    with pytest.raises(LlcpsError, match="pretraining branches first"):
        run_lives(sqlite_store, life, lives=1)
    sqlite_store.create_branch(pretrain_branch(life, 0), from_branch="main", at=0)
    with pytest.raises(LlcpsError, match="needs a trained policy") as refused:
        run_lives(sqlite_store, life, lives=1)
    assert "rl import" in (refused.value.hint or "")
    assert sqlite_store.list_runs() == [] and not any(b.startswith("life-") for b in sqlite_store.branch_names())


def test_life_report_reports_the_conditions_named_and_refuses_one_not_stored(tiny: tuple[Store, Path], tmp_path: Path) -> None:
    store, path = tiny
    db = str(path.parent / "ref.db")
    runner = CliRunner()
    only = runner.invoke(app, ["--db", db, "life", "report", str(path), "--conditions", "update", "--out-dir", str(tmp_path / "u"), "--json"])
    assert only.exit_code == 0, only.output
    with (tmp_path / "u" / "episodes.csv").open() as fh:
        assert {r["condition"] for r in csv.DictReader(fh)} == {"update"}
    assert [c["condition"] for c in json.loads(only.stdout)["conditions"]] == ["update"]
    before = store_signature(store, "life-")
    bad = runner.invoke(app, ["--db", db, "life", "report", str(path), "--conditions", "update,case_based", "--out-dir", str(tmp_path / "b")])
    assert bad.exit_code == 2
    assert "no episode of life 'tiny' under case_based" in bad.output and "stored conditions: reset, update" in bad.output
    assert not (tmp_path / "b").exists() and store_signature(store, "life-") == before
