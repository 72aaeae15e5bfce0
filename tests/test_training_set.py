"""An episode's training set (llcps.training.TrainingSet): the trials its branch saw,
read from the store only when something needs them, then the episode's own. An episode
that counts its new trials into a stored model never reads the ones before them, and
learns exactly what it learns from the whole set read at once."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from llcps.cps.episode import SolveConfig, solve
from llcps.cps.pretraining import pretrain
from llcps.errors import StoreError
from llcps.models import fit_or_load, persistence, schedule
from llcps.models.synthetic import synthetic_changes, synthetic_trials
from llcps.store import Store
from llcps.training import TrainingChanges, TrainingSet, position_after

from tests.test_models_counting import SMALL, assert_same_predictions, goal_query
from tests.test_models_examples import add_toy_trials


class Loads:
    """A loader that counts its calls."""

    def __init__(self, value):
        self.value, self.calls = value, 0

    def __call__(self):
        self.calls += 1
        return self.value


def toy_records(n, seed, start_id):
    return synthetic_trials(n, seed=seed, start_id=start_id)


def test_a_training_set_reads_its_base_only_when_something_needs_it():
    base = toy_records(5, 1, 1)
    load = Loads(base)
    records = TrainingSet(5, 5, load)
    tail = toy_records(3, 2, 6)
    for r in tail:
        records.append(r)
    view = records.without({7})
    assert len(records) == 8 and len(view) == 7
    assert records[-1] is tail[-1] and records[5] is tail[0]
    assert list(records[5:]) == tail and list(view[5:]) == [tail[0], tail[2]]
    assert position_after(records, 5) == 5 and position_after(records, 7) == 7 and position_after(view, 8) == 7
    assert load.calls == 0
    assert list(records) == base + tail and records[0] is base[0] and list(records[3:6]) == base[3:] + tail[:1]
    assert list(view) == base + [tail[0], tail[2]]
    assert position_after(records, 2) == 2
    assert load.calls == 1  # read once, shared with the view
    with pytest.raises(IndexError):
        records[8]


def test_training_changes_read_their_base_only_for_a_trial_of_it():
    records = toy_records(6, 3, 1)
    made = synthetic_changes(records, seed=3)
    load = Loads({i: c for i, c in made.items() if i <= 4})
    changes = TrainingChanges(len(load.value), 4, load)
    changes[5] = made[5]
    assert 5 in changes and 6 not in changes and changes[5] is made[5] and len(changes) == len(load.value) + 1
    assert load.calls == 0
    assert changes[2] is made[2] and dict(changes) == {i: c for i, c in made.items() if i <= 5}
    assert load.calls == 1
    with pytest.raises(KeyError, match="base"):
        changes[3] = made[3]


def test_a_stores_training_set_is_what_its_branch_sees_when_taken(store):
    add_toy_trials(store, 40, seed=1)
    records, changes = store.training_set("main")
    add_toy_trials(store, 5, seed=2)  # written after: not in the set's base
    seen = [r for r in store.visible_trials("main") if r.id <= records.watermark]
    assert len(records) == 40 and [r.id for r in records] == [r.id for r in seen] and records.watermark == seen[-1].id
    assert dict(changes) == {i: c for i, c in store.visible_changes("main").items() if i <= records.watermark}


def test_a_training_set_refuses_a_branch_whose_trials_changed_under_it(sqlite_store):
    add_toy_trials(sqlite_store, 20, seed=1)
    records, _ = sqlite_store.training_set("main")
    with sqlite_store.engine.begin() as conn:  # another process deletes a trial
        conn.exec_driver_sql("DELETE FROM trial_changes WHERE trial_id = 3")
        conn.exec_driver_sql("DELETE FROM trials WHERE id = 3")
    with pytest.raises(StoreError, match="19 trials up to trial .* not the 20"):
        list(records)


@pytest.fixture
def small_schedule(monkeypatch):
    monkeypatch.setattr(schedule, "FULL_FIT_TRIALS", SMALL)
    persistence.clear_fits()


def guard_reads(store, monkeypatch):
    """Make ``store`` refuse to read a branch's trials or changes from the start."""
    for name in ("visible_trials", "visible_changes"):
        read = getattr(store, name)

        def only_after(branch, *args, _read=read, _name=name, **kwargs):
            if kwargs.get("after_id") is None:
                raise AssertionError(f"{_name} read {branch}'s trials from the start")
            return _read(branch, *args, **kwargs)

        monkeypatch.setattr(store, name, only_after)


def test_counting_updates_never_read_the_base_and_learn_what_the_whole_set_teaches(store, small_schedule, monkeypatch):
    add_toy_trials(store, 150, seed=1)
    fit_or_load(store, "main", "nb", 0)
    add_toy_trials(store, 10, seed=2)  # the episode before: counted at this one's start
    whole = list(store.visible_trials("main"))
    whole_changes = dict(store.visible_changes("main"))
    eager = fit_or_load(store, "main", "nb", 0, records=whole, changes=whole_changes)
    persistence.clear_fits()
    guard_reads(store, monkeypatch)
    records, changes = store.training_set("main")
    for name in ("count_visible_trials", "count_visible_changes"):  # the set has counted them
        monkeypatch.setattr(store, name, lambda *args, _name=name, **kwargs: pytest.fail(f"{_name} counted again"))
    lazy = fit_or_load(store, "main", "nb", 0, records=records, changes=changes)
    made = synthetic_trials(6, seed=7)
    made_changes = synthetic_changes(made, seed=7)
    for k, record in enumerate(made):
        trial_id = store.add_trial(replace(record, id=None), change=made_changes[record.id])
        stored, change = replace(record, id=trial_id), replace(made_changes[record.id], trial_id=trial_id)
        records.append(stored)
        whole.append(stored)
        changes[trial_id] = whole_changes[trial_id] = change
        left_out = {trial_id} if k == 2 else set()  # as the hedge leaves the other side's trial out
        lazy.update(records.without(left_out), changes)
        eager.update([r for r in whole if r.id not in left_out], whole_changes)
        assert lazy.n_trials == eager.n_trials
        assert_same_predictions(lazy, eager, [r.model_input for r in synthetic_trials(20, seed=9)], goal_query())
    assert lazy.n_trials == 150 + 10 + 6  # the trial left out at one update learned at the next
    assert lazy.bins == SMALL * 2


def test_an_update_after_a_trial_left_out_comes_back_learns_the_set_as_given(store, small_schedule):
    add_toy_trials(store, 150, seed=1)
    records, changes = store.training_set("main")
    model = fit_or_load(store, "main", "nb", 0, records=records, changes=changes)
    made = synthetic_trials(2, seed=7)
    made_changes = synthetic_changes(made, seed=7)
    ids = []
    for record in made:
        trial_id = store.add_trial(replace(record, id=None), change=made_changes[record.id])
        records.append(replace(record, id=trial_id))
        changes[trial_id] = replace(made_changes[record.id], trial_id=trial_id)
        ids.append(trial_id)
    model.update(records.without({ids[0]}), changes)  # learns the second trial, not the first
    assert model.n_trials == 151
    model.update(records, changes)  # the first is back: not a set grown from the one learned
    refit = fit_or_load(store, "main", "nb", 0)
    np.testing.assert_allclose(model.outcome_sum, refit.outcome_sum)
    assert model.n_trials == refit.n_trials == 152


def test_an_episode_past_the_schedule_reads_only_its_new_trials_and_explores_as_if_it_read_them_all(
    tmp_path: Path, monkeypatch
):
    monkeypatch.setattr(schedule, "FULL_FIT_TRIALS", 10)
    persistence.clear_fits()
    path = tmp_path / "life.db"
    config = SolveConfig(scenario="scenario1", budget=8, seed=1)
    with Store.open(str(path), create=True) as store:
        pretrain(store, branch="main", n=21, seed=2)  # past 20 trials: bins of 20, counted up to 39
        fit_or_load(store, "main", config.model, config.fit_seed)
    shutil.copy(path, tmp_path / "eager.db")
    with Store.open(str(path)) as store:
        guard_reads(store, monkeypatch)
        lazy = solve(store, branch="main", config=config)
        monkeypatch.undo()
        monkeypatch.setattr(schedule, "FULL_FIT_TRIALS", 10)
        lazy_trials = [(r.spec, r.outcome) for r in store.visible_trials("main", episode=lazy.episode_id)]
    persistence.clear_fits()
    with Store.open(str(tmp_path / "eager.db")) as store:
        taken = store.training_set

        def read_at_once(branch):  # the base read when the set is taken, as before sets were lazy
            records, changes = taken(branch)
            return TrainingSet.of(list(records)), changes

        monkeypatch.setattr(store, "training_set", read_at_once)
        eager = solve(store, branch="main", config=config)
        eager_trials = [(r.spec, r.outcome) for r in store.visible_trials("main", episode=eager.episode_id)]
    assert lazy.status == eager.status and lazy.exploration_trials == eager.exploration_trials > 0
    assert lazy_trials == eager_trials
