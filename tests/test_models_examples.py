"""Goal examples encoded once and kept in the store: a fit that reads them equals one
that encodes every trial, a fork reads its parent's, and stored bytes are checked."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from llcps.errors import LlcpsError
from llcps.models import fit_or_load
from llcps.models.naive_bayes import NaiveBayesModel
from llcps.models.persistence import clear_fits, model_code, stored_examples
from llcps.models.relational import ExampleTable, pack_examples, unpack_examples
from llcps.models.synthetic import synthetic_changes, synthetic_trials
from llcps.trial_records import TrialRecord


def add_toy_trials(store, n, *, seed, branch="main"):
    made = synthetic_trials(n, seed=seed)
    changes = synthetic_changes(made, seed=seed)
    records = [
        TrialRecord(
            branch=branch, source="pretrain", spec=r.spec, features=r.features, outcome=r.outcome,
            solved=False, sim_steps=0, wall_seconds=0.0, seed=seed,
        )
        for r in made
    ]
    store.add_trials(records, changes=[changes[r.id] for r in made])


def goal_arrays(model):
    arrays, meta = model.goal.export()
    return {k: v for k, v in arrays.items()}, meta


def assert_same_goal(a, b):
    (arrays_a, meta_a), (arrays_b, meta_b) = goal_arrays(a), goal_arrays(b)
    assert meta_a == meta_b
    assert arrays_a.keys() == arrays_b.keys()
    for key in arrays_a:
        assert np.array_equal(arrays_a[key], arrays_b[key]), key


def test_examples_round_trip_exactly():
    records = synthetic_trials(30, seed=3)
    changes = synthetic_changes(records, seed=3)
    table = ExampleTable()
    table.encode(records, changes)
    assert table.encoded
    for trial_id, examples in table.encoded.items():
        back = unpack_examples(pack_examples(examples), trial_id)
        for field in ("features", "labels", "weights", "trial_ids"):
            assert np.array_equal(getattr(back, field), getattr(examples, field))
            assert getattr(back, field).dtype == getattr(examples, field).dtype


@pytest.mark.parametrize(
    "damage",
    [
        lambda b: b[:5],
        lambda b: b[:-1],
        lambda b: b"XXXX" + b[4:],
        lambda b: b[:-8] + np.array([-1.0]).tobytes(),  # a negative weight
        lambda b: b[:-8] + np.array([np.nan]).tobytes(),
    ],
    ids=["truncated-header", "short", "magic", "negative-weight", "nan-weight"],
)
def test_damaged_example_bytes_are_refused(damage):
    records = synthetic_trials(5, seed=4)
    table = ExampleTable()
    examples = table.encode(records, synthetic_changes(records, seed=4))
    one = next(iter(table.encoded.values()))
    assert len(examples)
    with pytest.raises(LlcpsError):
        unpack_examples(damage(pack_examples(one)), 1)


def test_a_fit_reading_stored_examples_equals_one_encoding_every_trial(store):
    clear_fits()
    add_toy_trials(store, 60, seed=1)
    fit_or_load(store, "main", "nb", 0)
    kept = stored_examples(store, "main")
    assert len(kept) == 60  # every trial with a change was kept once
    add_toy_trials(store, 25, seed=2)
    clear_fits()
    grown = fit_or_load(store, "main", "nb", 0)  # reads 60 trials' examples, encodes 25
    assert len(stored_examples(store, "main")) == 85
    fresh = NaiveBayesModel(0).fit(store.visible_trials("main"), store.visible_changes("main"))
    assert_same_goal(grown, fresh)


def test_a_fork_reads_its_parents_examples_up_to_the_fork(store):
    clear_fits()
    add_toy_trials(store, 40, seed=1)
    fit_or_load(store, "main", "nb", 0)
    store.create_branch("fork", from_branch="main")
    add_toy_trials(store, 10, seed=2)  # on main, after the fork: the fork does not see them
    fit_or_load(store, "main", "nb", 0)
    add_toy_trials(store, 15, seed=3, branch="fork")
    assert len(stored_examples(store, "fork")) == 40
    clear_fits()
    forked = fit_or_load(store, "fork", "nb", 0)
    assert len(stored_examples(store, "fork")) == 55
    fresh = NaiveBayesModel(0).fit(store.visible_trials("fork"), store.visible_changes("fork"))
    assert_same_goal(forked, fresh)


def test_tampered_stored_examples_are_encoded_again(store, caplog):
    clear_fits()
    add_toy_trials(store, 20, seed=1)
    fit_or_load(store, "main", "nb", 0)
    victim = min(stored_examples(store, "main"))
    store.save_examples(model_code(), {victim: b"LGX1" + b"\xff" * 40})
    add_toy_trials(store, 3, seed=2)
    clear_fits()
    with caplog.at_level(logging.WARNING):
        grown = fit_or_load(store, "main", "nb", 0)
    assert "unusable" in caplog.text
    fresh = NaiveBayesModel(0).fit(store.visible_trials("main"), store.visible_changes("main"))
    assert_same_goal(grown, fresh)
    assert victim in stored_examples(store, "main")  # encoded again and kept
