"""Held-out evaluation: a seeded split, per-bit metrics and the majority baseline."""

from __future__ import annotations

import numpy as np
import pytest

from llcps.domain import OUTCOME_NAMES
from llcps.errors import LlcpsError
from llcps.models.evaluation import evaluate, label_metrics, split
from llcps.models.synthetic import synthetic_trials


@pytest.fixture(scope="module")
def trials():
    return synthetic_trials(400, seed=31)


def test_split_is_seeded_disjoint_and_sized():
    train, test = split(100, seed=1, test_fraction=0.25)
    assert len(test) == 25 and len(train) == 75
    assert set(train).isdisjoint(test) and set(train) | set(test) == set(range(100))
    again = split(100, seed=1, test_fraction=0.25)
    assert np.array_equal(again[1], test)
    assert not np.array_equal(split(100, seed=2, test_fraction=0.25)[1], test)


@pytest.mark.parametrize("n, fraction", [(1, 0.25), (0, 0.25), (10, 0.0), (10, 1.0)])
def test_split_refuses_what_cannot_be_split(n, fraction):
    with pytest.raises(LlcpsError):
        split(n, seed=0, test_fraction=fraction)


def test_label_metrics_against_hand_computed_values():
    truth = np.array([1, 0, 1, 1, 0])
    proba = np.array([0.9, 0.2, 0.4, 0.8, 0.6])
    metrics = label_metrics("positive_touching", truth, proba, train_truth=np.array([0, 0, 1]))
    # predictions at 0.5: 1 0 0 1 1 -> tp=2 fp=1 fn=1
    assert metrics.accuracy == pytest.approx(3 / 5)
    assert metrics.f1 == pytest.approx(2 / 3)
    assert metrics.brier == pytest.approx(np.mean((proba - truth) ** 2))
    # training majority is 0: accuracy 2/5, F1 0, Brier against frequency 1/3
    assert metrics.baseline_accuracy == pytest.approx(2 / 5)
    assert metrics.baseline_f1 == 0
    assert metrics.baseline_brier == pytest.approx(np.mean((1 / 3 - truth) ** 2))
    assert metrics.both_classes


@pytest.mark.parametrize("name", ["nb", "nn"])
def test_paper_models_beat_the_baseline_on_learnable_trials(trials, name):
    report = evaluate(name, trials, seed=0)
    assert (report.n_train, report.n_test) == (300, 100)
    assert [m.label for m in report.labels] == list(OUTCOME_NAMES)
    assert report.beats_baseline_f1()
    assert report.mean("brier") < report.mean("baseline_brier")
    assert report.as_json()["labels"][0]["label"] == OUTCOME_NAMES[0]


def test_evaluation_is_deterministic_for_a_seed(trials):
    assert evaluate("nb", trials, seed=4) == evaluate("nb", trials, seed=4)


def test_random_model_does_not_beat_the_baseline_brier(trials):
    report = evaluate("random", trials, seed=0)
    assert report.mean("brier") > report.mean("baseline_brier")
