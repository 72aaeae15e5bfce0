"""World models on real pretraining trials: random interactions run in PyBullet
(``llcps.sim.sampler``), not the toy rules the other model tests use."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from llcps.domain import ACTIONS
from llcps.trial_records import TrialRecord
from llcps.models import PAPER_MODELS, WORLD_MODELS, load_world_model, make_world_model
from llcps.models.evaluation import evaluate
from llcps.store import Store


def pretraining_trials(n: int, *, seed: int) -> list[TrialRecord]:
    """``n`` random interactions, each from a freshly sampled and settled scene."""
    from llcps.sim.sampler import sample_interaction
    from llcps.sim.trial import run_trial
    from llcps.sim.world import World

    rng = np.random.default_rng(seed)
    world = World(visuals=False)
    records = []
    try:
        for index in range(n):
            _, spec = sample_interaction(rng, world=world)
            trial = run_trial(world, spec)
            records.append(
                TrialRecord(
                    id=index + 1,
                    branch="main",
                    source="pretrain",
                    spec=trial.spec,
                    features=trial.features,
                    outcome=trial.outcome,
                    solved=False,
                    sim_steps=trial.sim_steps,
                    wall_seconds=trial.wall_seconds,
                    seed=seed,
                )
            )
    finally:
        world.close()
    return records


@pytest.fixture(scope="module")
def real_trials():
    return pretraining_trials(16, seed=5)


@pytest.mark.parametrize("name", list(WORLD_MODELS))
def test_models_fit_real_trials_and_round_trip(real_trials, name):
    by_action = {}
    for record in real_trials:
        by_action.setdefault(record.spec.action, record)
    first_of_each = [by_action[a] for a in ACTIONS if a in by_action]  # the "no a priori training" set
    for training in (first_of_each, real_trials):
        model = make_world_model(name, 3).fit(training)
        proba = model.predict_proba(real_trials)
        assert proba.shape == (len(real_trials), 6)
        assert np.all(np.isfinite(proba)) and np.all((proba >= 0) & (proba <= 1))
        artifact, meta = model.to_artifact()
        assert np.array_equal(load_world_model(artifact, meta, seed=3).predict_proba(real_trials), proba)


@pytest.mark.slow
def test_paper_models_beat_the_majority_baseline_on_200_pretraining_trials(readme_pretrained: Path, tmp_path: Path) -> None:
    """The paper's pretraining size (the README's `llcps pretrain --trials 200 --seed 1`):
    some model beats the baseline's F1 on a bit with both classes."""
    with Store.open(str(shutil.copyfile(readme_pretrained, tmp_path / "llcps.db"))) as store:
        trials = store.visible_trials("main", source="pretrain")
    assert len(trials) == 200
    reports = [evaluate(name, trials, seed=1) for name in PAPER_MODELS]
    assert any(report.beats_baseline_f1() for report in reports)
    assert any(report.mean("brier") < report.mean("baseline_brier") for report in reports)
