"""``pretrain`` writes random interactions to the store as replayable trials."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from llcps.cli.main import app
from llcps.errors import LlcpsError
from llcps.cps.pretraining import pretrain
from llcps.sim.trial import run_trial
from llcps.sim.world import World
from llcps.store import Store


def rows(store: Store) -> list[tuple]:
    return [
        (t.seed, t.spec, t.features, t.outcome, t.sim_steps, t.source, t.solved) for t in store.visible_trials(None)
    ]


def test_pretrain_stores_trials_that_replay_exactly(sqlite_store) -> None:
    store = sqlite_store
    summary = pretrain(store, branch=None, n=3, seed=5)
    assert summary.trials == 3 and summary.branch == "main"
    trials = store.visible_trials(None)
    assert [t.id for t in trials] == summary.trial_ids
    assert {t.source for t in trials} == {"pretrain"}
    assert sum(summary.action_counts.values()) == 3
    assert summary.sim_steps == sum(t.sim_steps for t in trials)
    trial = trials[-1]
    snap = store.get_snapshot(trial.snapshot_id)
    with World.from_scene(snap.scene) as world:
        world.restore_serialized(snap.state)
        again = run_trial(world, trial.spec)
    assert (again.outcome, again.sim_steps, again.features) == (trial.outcome, trial.sim_steps, trial.features)


def test_the_same_seed_writes_the_same_trials(tmp_path) -> None:
    out = []
    for name in ("a.db", "b.db"):
        with Store.open(str(tmp_path / name), create=True) as store:
            pretrain(store, branch=None, n=2, seed=9, control_loop_every=0)
            out.append(rows(store))
    assert out[0] == out[1]


def test_two_workers_write_the_same_trials_as_one(tmp_path) -> None:
    out = []
    for workers in (1, 2):
        with Store.open(str(tmp_path / f"w{workers}.db"), create=True) as store:
            summary = pretrain(store, branch=None, n=5, seed=4, control_loop_every=0, workers=workers)
            snapshots = [store.get_snapshot(t.snapshot_id) for t in store.visible_trials(None)]
            changes = store.visible_changes(None)
            out.append((rows(store), [(s.scene, s.state) for s in snapshots], sorted(changes.items()), summary.outcome_counts))
    assert out[0] == out[1]


def test_a_negative_count_is_refused(sqlite_store) -> None:
    store = sqlite_store
    with pytest.raises(LlcpsError):
        pretrain(store, branch=None, n=-1, seed=0)


def test_cli_prints_one_json_document(tmp_path) -> None:
    db = str(tmp_path / "cli.db")
    runner = CliRunner()
    done = runner.invoke(app, ["--db", db, "pretrain", "--trials", "1", "--seed", "2", "--create", "--json"])
    assert done.exit_code == 0, done.output
    summary = json.loads(done.stdout)
    assert summary["trials"] == 1 and len(summary["trial_ids"]) == 1
    assert set(summary["outcome_counts"]) == {
        "positive_visibility",
        "negative_visibility",
        "positive_reachability",
        "negative_reachability",
        "positive_touching",
        "negative_touching",
    }
    bad = runner.invoke(app, ["--db", db, "pretrain", "--n", "-3"])
    assert bad.exit_code == 2


def test_the_same_pretraining_again_is_skipped_unless_again(tmp_path) -> None:
    """`make run` twice: the second `pretrain --trials N --seed S` finds the first on the
    branch, runs nothing and says so; the models are fitted (or loaded) as before.
    --again, or another seed, runs the interactions."""
    db = str(tmp_path / "twice.db")
    runner = CliRunner()

    def run(*args: str):  # noqa: ANN202 - click Result
        result = runner.invoke(app, ["--db", db, "pretrain", "--trials", "2", "--model", "nb", *args])
        assert result.exit_code == 0, result.output
        return result

    first = json.loads(run("--seed", "1", "--create", "--json").stdout)
    assert first["skipped"] is False
    second = run("--seed", "1")
    assert (
        f"pretraining with --trials 2 --seed 1 is already on branch main (run {first['run_id']}): skipped; --again to add more"
        in second.stderr
    )
    assert "world models fitted" in second.stdout
    again = json.loads(run("--seed", "1", "--json").stdout)
    assert again["skipped"] is True and again["run_id"] == first["run_id"] and again["trial_ids"] == first["trial_ids"]
    assert again["outcome_counts"] == first["outcome_counts"] and again["models"][0]["trials"] == 2
    with Store.open(db) as store:
        assert store.count_visible_trials("main") == 2
    assert json.loads(run("--seed", "1", "--again", "--json").stdout)["skipped"] is False
    assert json.loads(run("--seed", "2", "--json").stdout)["skipped"] is False
    with Store.open(db) as store:
        assert store.count_visible_trials("main") == 6
        assert [r.config["n"] for r in store.list_runs() if r.command == "pretrain"] == [2, 2, 2]
