"""World models on their branch of a real SQLite store: fitted once per training set,
reused while current, refitted when trials arrive, and never trusted blindly."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from llcps.trial_records import TrialRecord
from llcps.errors import LlcpsError
from llcps.models import fit_or_load
from llcps.models.synthetic import synthetic_trials


def add_toy_trials(store, n, *, seed, branch="main"):
    store.add_trials(
        [
            TrialRecord(
                branch=branch,
                source="pretrain",
                spec=r.spec,
                features=r.features,
                outcome=r.outcome,
                solved=False,
                sim_steps=0,
                wall_seconds=0.0,
                seed=seed,
            )
            for r in synthetic_trials(n, seed=seed)
        ]
    )


@pytest.fixture
def candidates():
    return [r.model_input for r in synthetic_trials(40, seed=99)]


def stored_ids(store, branch, name, seed=0):
    latest = store.latest_world_model(branch, name, seed)
    return None if latest is None else (latest.id, latest.watermark)


@pytest.mark.parametrize("name", ["nb", "nn"])
def test_fit_once_then_load_until_new_trials(store, candidates, name):
    add_toy_trials(store, 120, seed=1)
    first = fit_or_load(store, "main", name, 0)
    saved = stored_ids(store, "main", name)
    assert saved == (saved[0], store.max_visible_trial_id("main"))
    again = fit_or_load(store, "main", name, 0)
    assert stored_ids(store, "main", name) == saved  # loaded, not refitted
    assert np.array_equal(again.predict_proba(candidates), first.predict_proba(candidates))
    add_toy_trials(store, 10, seed=2)
    refit = fit_or_load(store, "main", name, 0)
    assert stored_ids(store, "main", name)[1] == store.max_visible_trial_id("main") > saved[1]
    assert refit.n_trials == 130


def test_a_model_stored_by_other_model_code_is_refitted(store, candidates, monkeypatch):
    from llcps.models import persistence

    add_toy_trials(store, 60, seed=1)
    first = fit_or_load(store, "main", "nb", 0)
    saved = stored_ids(store, "main", "nb")
    assert store.latest_world_model("main", "nb", 0).meta["code"] == persistence.model_code()
    fit_or_load(store, "main", "nb", 0)
    assert stored_ids(store, "main", "nb") == saved  # same code: loaded
    monkeypatch.setattr(persistence, "model_code", lambda: "another-release")
    persistence.clear_fits()
    again = fit_or_load(store, "main", "nb", 0)
    latest = store.latest_world_model("main", "nb", 0)
    assert latest.id != saved[0] and latest.watermark == saved[1] and latest.meta["code"] == "another-release"
    assert np.array_equal(again.predict_proba(candidates), first.predict_proba(candidates))


def test_the_model_code_digest_covers_the_models_package():
    from llcps.models import persistence

    code = persistence.model_code()
    assert len(code) == 16 and int(code, 16) >= 0
    assert persistence.model_code() == code  # one value per process


def test_empty_branch_fits_the_prior(store, candidates):
    model = fit_or_load(store, "main", "nb", 0)
    assert np.array_equal(model.predict_proba(candidates), np.full((len(candidates), 6), 0.5))
    assert stored_ids(store, "main", "nb")[1] == 0


def test_stale_caller_records_are_replaced_by_the_store(store):
    add_toy_trials(store, 30, seed=1)
    stale = store.visible_trials("main")[:10]
    assert fit_or_load(store, "main", "nb", 0, records=stale).n_trials == 30


def test_a_child_branch_reuses_its_parents_model_at_the_fork(store):
    add_toy_trials(store, 50, seed=1)
    fit_or_load(store, "main", "nb", 0)
    parent = stored_ids(store, "main", "nb")
    store.create_branch("child", from_branch="main")
    fit_or_load(store, "child", "nb", 0)
    assert stored_ids(store, "child", "nb") == parent
    add_toy_trials(store, 5, seed=2, branch="child")
    fit_or_load(store, "child", "nb", 0)
    assert stored_ids(store, "child", "nb")[0] != parent[0]
    assert stored_ids(store, "main", "nb") == parent  # the parent never sees the child's model


def test_a_tampered_stored_model_is_refitted_not_executed(store, candidates, caplog):
    add_toy_trials(store, 60, seed=1)
    honest = fit_or_load(store, "main", "nb", 0)
    artifact = honest.to_artifact()[0]
    meta = store.latest_world_model("main", "nb", 0).meta  # current in every respect but its bytes
    watermark = store.max_visible_trial_id("main")
    store.save_world_model(
        branch="main", name="nb", seed=0, watermark=watermark, artifact=b"\x80\x04cos\nsystem\n", meta=meta
    )
    with caplog.at_level(logging.WARNING, logger="llcps.models.persistence"):
        model = fit_or_load(store, "main", "nb", 0)
    assert "unusable" in caplog.text
    assert np.array_equal(model.predict_proba(candidates), honest.predict_proba(candidates))
    latest = store.latest_world_model("main", "nb", 0)
    assert latest.artifact == artifact  # the refit replaced the tampered row as the latest


@pytest.mark.parametrize("name", ["nb", "nn"])
def test_a_process_fits_one_training_set_once_across_stores(tmp_path, candidates, monkeypatch, name):
    """Two stores holding the same trials: the second gets a copy of the first's fit, the
    same model (artifact bytes) a fit gives; another seed or one more trial fits again."""
    from llcps.models import persistence
    from llcps.models.registry import world_model_entry
    from llcps.store import Store

    cls = world_model_entry(name).model_class()
    fits = []
    real_fit = cls.fit
    monkeypatch.setattr(cls, "fit", lambda self, *a, **k: (fits.append(self.seed), real_fit(self, *a, **k))[1])
    persistence.clear_fits()
    stores = [Store.open(str(tmp_path / f"{i}.db"), create=True) for i in range(2)]
    try:
        for store in stores:
            add_toy_trials(store, 40, seed=1)
        first = fit_or_load(stores[0], "main", name, 0)
        second = fit_or_load(stores[1], "main", name, 0)
        assert fits == [0]
        assert second is not first and second.to_artifact()[0] == first.to_artifact()[0]
        assert stores[1].latest_world_model("main", name, 0).artifact == first.to_artifact()[0]  # stored all the same
        assert np.array_equal(second.predict_proba(candidates), first.predict_proba(candidates))
        fit_or_load(stores[1], "main", name, 1)
        add_toy_trials(stores[0], 1, seed=2)
        assert fit_or_load(stores[0], "main", name, 0).n_trials == 41
        assert fits == [0, 1, 0]
    finally:
        for store in stores:
            store.close()


def test_a_remembered_fit_is_not_reused_for_other_trials_of_the_same_count_and_ids(tmp_path, candidates, monkeypatch):
    """The memo compares training sets by digest only when their size and last id agree:
    two stores with 40 trials of the same ids but other content each get their own fit,
    and changing the copy a fit hands out leaves the remembered one as it was."""
    from llcps.models import persistence
    from llcps.models.registry import world_model_entry
    from llcps.store import Store

    cls = world_model_entry("nb").model_class()
    fits = []
    real_fit = cls.fit
    monkeypatch.setattr(cls, "fit", lambda self, *a, **k: (fits.append(self.seed), real_fit(self, *a, **k))[1])
    persistence.clear_fits()
    with Store.open(str(tmp_path / "a.db"), create=True) as a, Store.open(str(tmp_path / "b.db"), create=True) as b:
        add_toy_trials(a, 40, seed=1)
        add_toy_trials(b, 40, seed=3)
        first = fit_or_load(a, "main", "nb", 0)
        before = first.predict_proba(candidates)
        other = fit_or_load(b, "main", "nb", 0)
        assert fits == [0, 0]
        assert not np.array_equal(other.predict_proba(candidates), before)
        first.update(b.visible_trials("main"))  # the caller's copy moves on
        again = persistence._fit(
            world_model_entry("nb"), 0, a.visible_trials("main"), a.visible_changes("main"), True
        )
        assert fits == [0, 0] and np.array_equal(again.predict_proba(candidates), before)


@pytest.mark.parametrize("name", ["nb", "nn"])
def test_a_model_fitted_without_its_goal_head_predicts_the_same_omega_and_is_refitted_when_the_head_is_asked_for(
    tmp_path, candidates, monkeypatch, name
):
    from llcps.models import persistence
    from llcps.models.registry import world_model_entry
    from llcps.store import Store

    cls = world_model_entry(name).model_class()
    fits: list[bool] = []
    real_fit = cls.fit
    monkeypatch.setattr(cls, "fit", lambda self, *a, **k: (fits.append(k.get("goal", True)), real_fit(self, *a, **k))[1])
    persistence.clear_fits()
    with Store.open(str(tmp_path / "goal.db"), create=True) as store:
        add_toy_trials(store, 30, seed=1)
        bare = fit_or_load(store, "main", name, 0, goal=False)
        artifact, meta = bare.to_artifact()
        assert meta["goal"] is False and not any(k.startswith("goal_") for k in meta)
        with pytest.raises(LlcpsError, match="without its goal-aware head"):
            bare.predict_goal(None)
        assert fit_or_load(store, "main", name, 0, goal=False).has_goal is False  # loaded, not refitted
        assert fits == [False]
        full = fit_or_load(store, "main", name, 0)  # the stored model lacks the head: fitted again
        assert fits == [False, True] and full.has_goal
        assert np.array_equal(full.predict_proba(candidates), bare.predict_proba(candidates))
        assert fit_or_load(store, "main", name, 0, goal=False).has_goal  # a model with the head serves either
        assert fits == [False, True]
        again = cls.from_artifact(artifact, meta, 0)
        assert again.has_goal is False and np.array_equal(again.predict_proba(candidates), bare.predict_proba(candidates))
        with pytest.raises(LlcpsError, match="goal flag"):
            cls.from_artifact(artifact, {**meta, "goal": "yes"}, 0)
