"""Counting models past FULL_FIT_TRIALS (llcps.models.schedule): bins and calibration
fitted on the first trials, the rest counted; a fit brought up by counting, in memory or
from the store, equals a fit of the whole training set."""

from __future__ import annotations

import numpy as np
import pytest

from llcps.errors import LlcpsError
from llcps.models import fit_or_load, persistence, schedule
from llcps.models.registry import world_model_entry
from llcps.models.synthetic import synthetic_changes, synthetic_trials

from tests.test_models_examples import add_toy_trials
from tests.test_models_store import add_toy_trials as add_trials_without_changes


#: The schedule's threshold in these tests: small, so that a few hundred toy trials pass it.
SMALL = 64


@pytest.fixture(autouse=True)
def small_schedule(monkeypatch):
    monkeypatch.setattr(schedule, "FULL_FIT_TRIALS", SMALL)
    persistence.clear_fits()


@pytest.fixture(scope="module")
def toy():
    records = synthetic_trials(300, seed=5)
    return records, synthetic_changes(records, seed=5)


@pytest.fixture(scope="module")
def candidates():
    return [r.model_input for r in synthetic_trials(60, seed=99)]


def goal_query():
    """Every candidate of a toy failure, as a goal query (the life bench's)."""
    from llcps.bench.life import _query

    return _query()[0]


def nb(records, changes):
    return world_model_entry("nb")(0).fit(records, changes)


def assert_same_predictions(a, b, candidates, query):
    np.testing.assert_allclose(a.predict_proba(candidates), b.predict_proba(candidates), rtol=1e-12, atol=0)
    np.testing.assert_allclose(a.predict_goal(query), b.predict_goal(query), rtol=1e-12, atol=0)


def test_the_schedule_fits_bins_on_all_trials_up_to_the_threshold_then_on_each_doubling():
    assert [schedule.bins_trials(n) for n in (0, 1, SMALL, SMALL + 1, 2 * SMALL - 1, 2 * SMALL, 5 * SMALL)] == [
        0, 1, SMALL, SMALL, SMALL, 2 * SMALL, 4 * SMALL,
    ]


def test_a_fit_past_the_threshold_has_the_bins_of_its_first_trials_and_the_counts_of_all(toy, candidates):
    records, changes = toy
    whole = nb(records, changes)  # 300 trials: bins of the first 256
    first = nb(records[:256], changes)
    assert (whole.n_trials, whole.bins, whole.goal.trials, whole.goal.bins) == (300, 256, 300, 256)
    assert np.array_equal(whole.encoder.params()["mean"], first.encoder.params()["mean"])
    for k, sub in whole.goal.learner.subs.items():
        assert np.array_equal(sub.thresholds, first.goal.learner.subs[k].thresholds)
        assert np.array_equal(sub.platt, first.goal.learner.subs[k].platt)
    assert whole.outcome_sum.sum() > first.outcome_sum.sum()  # the last 44 trials are counted
    assert whole.goal.n_examples > first.goal.n_examples
    assert not np.allclose(whole.predict_proba(candidates), first.predict_proba(candidates))
    assert not np.allclose(whole.predict_goal(goal_query()), first.predict_goal(goal_query()))
    # Omega's counts are those of all 300 trials, binarized at the first 256's means
    from llcps.models.features import encode_inputs, outcome_matrix

    x = (whole.encoder.transform(encode_inputs(records)) > 0).astype(float)
    y = outcome_matrix(records)[:, whole.learned].astype(float)
    np.testing.assert_allclose(whole.ones, y.T @ x, rtol=1e-12)
    np.testing.assert_allclose(whole.outcome_sum, outcome_matrix(records).sum(axis=0))
    # every stratum's counts are those of all 300 trials' examples, in the first 256's bins
    from llcps.models.families import action_stratum_of
    from llcps.models.goal import examples_of

    examples = examples_of(records, changes)
    strata = action_stratum_of(examples.features)
    assert whole.goal.learner.subs
    for k, sub in whole.goal.learner.subs.items():
        rows = strata == k
        x, y, w = sub._bits(examples.features[rows]), examples.labels[rows].astype(float), examples.weights[rows]
        np.testing.assert_allclose(sub.ones, np.stack([(w * (1 - y)) @ x, (w * y) @ x]), rtol=1e-12)
        np.testing.assert_allclose(sub.class_weight, [w @ (1 - y), w @ y], rtol=1e-12)
        np.testing.assert_allclose(whole.goal.learner.stratum_sums[k], [w @ y, w.sum()], rtol=1e-12)


def test_extending_a_fit_equals_fitting_the_whole_set(toy, candidates):
    records, changes = toy
    query = goal_query()
    whole = nb(records, changes)
    step = nb(records[:260], changes)
    step.extend(records[260:281], changes).extend(records[281:], changes)
    assert (step.n_trials, step.goal.trials, step.goal.n_examples) == (300, 300, whole.goal.n_examples)
    assert_same_predictions(step, whole, candidates, query)
    for k, sub in whole.goal.learner.subs.items():
        np.testing.assert_allclose(step.goal.learner.subs[k].ones, sub.ones, rtol=1e-12)
    # the stored form keeps the counts: a loaded fit extends as the one in memory does
    stored = step.to_artifact()
    loaded = world_model_entry("nb").load(*stored, 0)
    assert_same_predictions(loaded, step, candidates, query)
    # within an episode, a grown set is counted too
    updated = nb(records[:260], changes).update(records, changes)
    np.testing.assert_allclose(updated.predict_proba(candidates), whole.predict_proba(candidates), rtol=1e-12, atol=0)
    loaded = world_model_entry("nb").load(*nb(records[:260], changes).to_artifact(), 0).update(records, changes)
    np.testing.assert_allclose(loaded.predict_proba(candidates), whole.predict_proba(candidates), rtol=1e-12, atol=0)
    # a caller that leaves a learned trial out gets the fit of the set it gives, not a count on top
    without = [r for r in records if r.id != records[10].id]
    left_out = nb(records[:260], changes).update(without, changes)
    np.testing.assert_allclose(left_out.predict_proba(candidates), nb(without, changes).predict_proba(candidates), rtol=1e-12, atol=0)


def test_a_fit_cannot_be_extended_into_bins_of_its_own_nor_an_unscheduled_model(toy):
    records, changes = toy
    small = nb(records[:100], changes)  # bins of 64; 300 trials need bins of 256
    assert not small.can_extend(300) and small.can_extend(127)
    with pytest.raises(LlcpsError, match="cannot count"):
        small.extend(records[100:], changes)
    unscheduled = world_model_entry("random")(0).fit(records[:100], changes)
    assert not unscheduled.can_extend(101)


@pytest.mark.parametrize("name", ["logreg", "forest"])
def test_a_scheduled_model_that_does_not_count_keeps_its_learner_and_counts_its_rates(toy, candidates, name):
    records, changes = toy
    query = goal_query()
    entry = world_model_entry(name)
    whole = entry(0).fit(records, changes)
    first = entry(0).fit(records[:256], changes)
    assert (whole.n_trials, whole.bins, whole.goal.bins) == (300, 256, 256)
    # the learners are those of the first 256 trials: where a bit is learned, Omega is theirs
    learned = whole.learned
    np.testing.assert_array_equal(whole.predict_proba(candidates)[:, learned], first.predict_proba(candidates)[:, learned])
    # the rates and priors count every trial
    from llcps.models.features import outcome_matrix

    np.testing.assert_allclose(whole.outcome_sum, outcome_matrix(records).sum(axis=0))
    assert whole.goal.n_examples > first.goal.n_examples
    # brought up by extend, in batches, it is the fit of the whole set
    step = entry(0).fit(records[:260], changes).extend(records[260:281], changes).extend(records[281:], changes)
    assert_same_predictions(step, whole, candidates, query)
    # and within an episode, a grown set refits nothing
    updated = entry(0).fit(records[:260], changes).update(records, changes)
    np.testing.assert_allclose(updated.predict_proba(candidates), whole.predict_proba(candidates), rtol=1e-12, atol=0)


def test_tampered_counts_are_rejected(toy):
    from llcps.models.artifact import pack_arrays, unpack_arrays

    records, changes = toy
    artifact, meta = nb(records, changes).to_artifact()
    arrays = dict(unpack_arrays(artifact))
    key = next(k for k in arrays if k.endswith("nb/ones") and k.startswith("goal/"))
    arrays[key] = arrays[key] + 1e6  # more rows with a bit set than rows of its class
    data = pack_arrays(arrays)
    import hashlib

    with pytest.raises(LlcpsError, match="counts"):
        world_model_entry("nb").load(data, {**meta, "sha256": hashlib.sha256(data).hexdigest()}, 0)


def fresh_fit(store, branch):
    return world_model_entry("nb")(0).fit(store.visible_trials(branch), store.visible_changes(branch))


def no_fit(*args, **kwargs):
    raise AssertionError("a fit was run where the stored model should have been extended")


def test_fit_or_load_counts_the_new_trials_into_the_stored_model(store, candidates, monkeypatch):
    query = goal_query()
    add_toy_trials(store, 150, seed=1)
    fit_or_load(store, "main", "nb", 0)
    add_toy_trials(store, 20, seed=2)
    with monkeypatch.context() as m:
        m.setattr(persistence, "_fit", no_fit)
        extended = fit_or_load(store, "main", "nb", 0)
    assert extended.n_trials == 170 == store.count_visible_trials("main")
    stored = store.latest_world_model("main", "nb", 0)
    assert stored.watermark == store.max_visible_trial_id("main") and stored.meta["changes"] == 170
    assert_same_predictions(extended, fresh_fit(store, "main"), candidates, query)
    # a fork starts from its parent's model and counts its own trials into it
    store.create_branch("child", from_branch="main")
    add_toy_trials(store, 30, seed=3, branch="child")
    with monkeypatch.context() as m:
        m.setattr(persistence, "_fit", no_fit)
        child = fit_or_load(store, "child", "nb", 0)
    assert child.n_trials == 200
    assert_same_predictions(child, fresh_fit(store, "child"), candidates, query)
    assert store.latest_world_model("main", "nb", 0).id == stored.id  # the parent never sees the child's model
    # a set that doubles past its bins is fitted again, on the bins of its first 256 trials
    add_toy_trials(store, 60, seed=4, branch="child")
    refitted = fit_or_load(store, "child", "nb", 0)
    assert (refitted.n_trials, refitted.bins) == (260, 256)


def test_the_life_bench_charges_an_episode_that_counts_its_share_of_the_full_fit(tmp_path):
    from llcps.bench import life

    early, late = life.live((3, 10), path=tmp_path / "life.db")
    assert (early.trials, late.trials) == (30, 100)
    assert early.refit == 0.0  # 20 trials before it: its own fit is a full fit
    assert late.refit > 0.0  # 90 before it, past the threshold: it counts, and pays a share
    assert late.overhead == pytest.approx(late.fit + late.rank + late.store + late.update + late.refit)
    assert late.update > 0.0  # each trial brings the model up to it


def test_trials_written_while_a_fit_reads_are_not_counted_twice(store, candidates, monkeypatch):
    add_toy_trials(store, 150, seed=1)
    fit_or_load(store, "main", "nb", 0)
    add_toy_trials(store, 10, seed=2)
    count = store.count_visible_trials

    def count_after_another_writer(branch, *args, **kwargs):  # another process writes after the watermark was read
        monkeypatch.setattr(store, "count_visible_trials", count)
        add_trials_without_changes(store, 5, seed=3)  # so that the count of changes does not tell
        return count(branch, *args, **kwargs)

    monkeypatch.setattr(store, "count_visible_trials", count_after_another_writer)
    fit_or_load(store, "main", "nb", 0)
    stored = store.latest_world_model("main", "nb", 0)  # what it learned is what its watermark says
    assert stored.meta["n_trials"] == len([r for r in store.visible_trials("main") if r.id <= stored.watermark]) == 160
    latest = fit_or_load(store, "main", "nb", 0)  # counts from whatever the first call stored
    assert latest.n_trials == 165 == store.count_visible_trials("main")
    assert_same_predictions(latest, fresh_fit(store, "main"), candidates, goal_query())


def test_the_network_learns_a_grown_set_by_a_warm_start_beside_a_bounded_replay(toy, candidates):
    from llcps.models.artifact import pack_arrays, unpack_arrays
    from llcps.models.features import outcome_matrix
    from llcps.models.neural import REPLAY_ROWS

    records, changes = toy
    entry = world_model_entry("nn")
    first = entry(0).fit(records[:260], changes)  # bins of the first 256 trials
    step = entry(0).fit(records[:260], changes)
    for start in range(260, 300, 10):
        step.extend(records[start : start + 10], changes)
    assert (step.n_trials, step.goal.trials) == (300, 300)
    assert len(step.replay["priority"]) <= REPLAY_ROWS and len(step.goal.learner.replay["priority"]) <= REPLAY_ROWS
    assert not np.allclose(step.predict_proba(candidates), first.predict_proba(candidates))  # it learned
    again = entry(0).fit(records[:260], changes)
    for start in range(260, 300, 10):
        again.extend(records[start : start + 10], changes)
    np.testing.assert_array_equal(again.predict_proba(candidates), step.predict_proba(candidates))  # deterministic
    # held out, it is within a tenth of a fit of the whole set (Brier score)
    held = synthetic_trials(500, seed=77)
    truth = outcome_matrix(held)
    whole = entry(0).fit(records, changes)
    brier = [float(((m.predict_proba(held) - truth) ** 2).mean()) for m in (step, whole)]
    assert abs(brier[0] - brier[1]) <= 0.1 * brier[1], brier
    # the replay is stored with the weights, and checked when read
    artifact, meta = step.to_artifact()
    loaded = entry.load(artifact, meta, 0)
    np.testing.assert_array_equal(loaded.predict_proba(candidates), step.predict_proba(candidates))
    arrays = dict(unpack_arrays(artifact))
    arrays["goal/replay/labels"] = arrays["goal/replay/labels"] + 2
    data = pack_arrays(arrays)
    import hashlib

    with pytest.raises(LlcpsError, match="replayed"):
        entry.load(data, {**meta, "sha256": hashlib.sha256(data).hexdigest()}, 0)


@pytest.mark.parametrize("name", ["logreg", "nn"])
def test_fit_or_load_brings_a_stored_model_of_any_scheduled_kind_up_without_a_fit(store, candidates, monkeypatch, name):
    add_toy_trials(store, 150, seed=1)
    fit_or_load(store, "main", name, 0)
    add_toy_trials(store, 20, seed=2)
    with monkeypatch.context() as m:
        m.setattr(persistence, "_fit", no_fit)
        extended = fit_or_load(store, "main", name, 0)
    assert extended.n_trials == 170 == store.latest_world_model("main", name, 0).meta["n_trials"]
    if name == "logreg":  # it only counts its rates and priors: the fit of the whole set
        fresh = world_model_entry(name)(0).fit(store.visible_trials("main"), store.visible_changes("main"))
        assert_same_predictions(extended, fresh, candidates, goal_query())
