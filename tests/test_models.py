"""World models: every registered model fits on degenerate and ordinary training sets,
is deterministic for a seed, round-trips through its artifact, and refuses tampered ones.

The training data is the seeded toy of ``llcps.models.synthetic`` (learnable rules,
no physics); tests on stored simulator trials live in test_models_store.py.
"""

from __future__ import annotations

import hashlib
import io
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from llcps.domain import ACTIONS, OUTCOME_NAMES
from llcps.errors import LlcpsError, UnknownNameError
from llcps.models import WORLD_MODELS, load_world_model, make_world_model
from llcps.models.artifact import pack_arrays, unpack_arrays
from llcps.models.base import label_prior
from llcps.models.features import encode_inputs, outcome_matrix
from llcps.models.synthetic import synthetic_trials

MODELS = list(WORLD_MODELS)


@pytest.fixture(scope="module")
def trials():
    return synthetic_trials(200, seed=11)


@pytest.fixture(scope="module")
def candidates():
    return [record.model_input for record in synthetic_trials(60, seed=12)]


def one_per_action(records):
    """The paper's "no a priori training" set: one trial of each action."""
    return [next(r for r in records if r.spec.action == action) for action in ACTIONS]


def training_set(trials, size):
    return {0: [], 4: one_per_action(trials), 200: trials}[size]


@pytest.fixture(scope="module")
def fitted(trials):
    """Each model fitted once per training-set size (NN fits take a moment)."""
    cache = {}

    def get(name, size, seed=0):
        key = (name, size, seed)
        if key not in cache:
            cache[key] = make_world_model(name, seed).fit(training_set(trials, size))
        return cache[key]

    return get


@pytest.mark.parametrize("size", [0, 4, 200])
@pytest.mark.parametrize("name", MODELS)
def test_fit_predicts_probabilities(fitted, candidates, name, size):
    proba = fitted(name, size).predict_proba(candidates)
    assert proba.shape == (len(candidates), len(OUTCOME_NAMES))
    assert proba.dtype == np.float64
    assert np.all(np.isfinite(proba))
    assert np.all((proba >= 0) & (proba <= 1))
    assert fitted(name, size).predict_proba([]).shape == (0, len(OUTCOME_NAMES))


@pytest.mark.parametrize("name", [n for n in MODELS if n != "random"])
def test_degenerate_training_sets_predict_the_smoothed_prior(fitted, trials, candidates, name):
    assert np.array_equal(fitted(name, 0).predict_proba(candidates), np.full((len(candidates), 6), 0.5))
    four = outcome_matrix(one_per_action(trials))
    single_class = four.min(axis=0) == four.max(axis=0)
    assert single_class.any()  # the fixture really is degenerate
    proba = fitted(name, 4).predict_proba(candidates)
    assert np.allclose(proba[:, single_class], label_prior(four)[single_class])


@pytest.mark.parametrize("name", MODELS)
def test_same_seed_same_data_same_predictions(fitted, trials, candidates, name):
    again = make_world_model(name, 0).fit(trials)
    assert np.array_equal(again.predict_proba(candidates), fitted(name, 200).predict_proba(candidates))


@pytest.mark.parametrize("name", ["nn", "forest", "random"])
def test_seed_changes_stochastic_models(fitted, candidates, name):
    assert not np.array_equal(
        fitted(name, 200, seed=1).predict_proba(candidates), fitted(name, 200).predict_proba(candidates)
    )


@pytest.mark.parametrize("size", [0, 4, 200])
@pytest.mark.parametrize("name", MODELS)
def test_artifact_round_trip_gives_identical_predictions(fitted, candidates, name, size):
    model = fitted(name, size)
    artifact, meta = model.to_artifact()
    assert isinstance(artifact, bytes)
    assert meta["model"] == name and meta["n_trials"] == size
    loaded = load_world_model(artifact, meta, seed=0)
    assert type(loaded) is type(model)
    assert loaded.n_trials == size
    assert np.array_equal(loaded.predict_proba(candidates), model.predict_proba(candidates))
    assert model.to_artifact()[0] == artifact  # the same model always writes the same bytes


class _Exploit:
    """A pickle payload that would create a file when unpickled."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.touch, (self.path,))


def _with_checksum(meta, data):
    return {**meta, "sha256": hashlib.sha256(data).hexdigest()}


def _object_array_npz(marker: Path) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        with archive.open("prior.npy", "w") as member:
            np.lib.format.write_array(member, np.array([_Exploit(marker)], dtype=object), allow_pickle=True)
    return buffer.getvalue()


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("attack", ["pickle", "object-array", "flipped-byte", "truncated", "wrong-model", "garbage"])
def test_tampered_artifact_is_rejected_and_never_executed(fitted, tmp_path, name, attack):
    artifact, meta = fitted(name, 200).to_artifact()
    marker = tmp_path / "executed"
    if attack == "pickle":
        data = pickle.dumps(_Exploit(marker))
        meta = _with_checksum(meta, data)  # even with a matching checksum
    elif attack == "object-array":
        data = _object_array_npz(marker)
        meta = _with_checksum(meta, data)
    elif attack == "flipped-byte":
        data = bytearray(artifact)
        data[len(data) // 2] ^= 0xFF
        data = bytes(data)
    elif attack == "truncated":
        data = artifact[: len(artifact) // 2]
        meta = _with_checksum(meta, data)
    elif attack == "wrong-model":
        other = next(n for n in MODELS if n != name)
        data, meta = artifact, {**meta, "model": other}
    else:
        data = b"\x00garbage" * 10
        meta = _with_checksum(meta, data)
    with pytest.raises(LlcpsError) as excinfo:
        load_world_model(data, meta, seed=0)
    assert "artifact" in str(excinfo.value) or "world model" in str(excinfo.value)
    assert not marker.exists()


def test_any_flipped_bit_is_rejected_or_harmless_even_with_a_matching_checksum(fitted, candidates):
    model = fitted("nb", 200)
    artifact, meta = model.to_artifact()
    expected = model.predict_proba(candidates)
    rejected = 0
    for position in range(0, len(artifact), 37):
        data = bytearray(artifact)
        data[position] ^= 0x01
        try:
            loaded = load_world_model(bytes(data), _with_checksum(meta, bytes(data)), seed=0)
        except LlcpsError:
            rejected += 1
        else:  # the flip hit zip bookkeeping (a version field, a timestamp), not the arrays
            assert np.array_equal(loaded.predict_proba(candidates), expected)
    assert rejected > len(artifact) // 37 // 2


def test_artifact_arrays_with_wrong_shapes_are_rejected(fitted):
    artifact, meta = fitted("nb", 200).to_artifact()
    arrays = unpack_arrays(artifact)
    data = pack_arrays({**arrays, "prior": np.full(5, 0.5)})
    with pytest.raises(LlcpsError, match="'prior' has shape"):
        load_world_model(data, _with_checksum(meta, data), seed=0)


def test_unknown_model_name_lists_the_known_ones():
    with pytest.raises(UnknownNameError) as excinfo:
        make_world_model("svm", 0)
    assert all(name in str(excinfo.value) for name in MODELS)


def test_naive_bayes_matches_sklearn_bernoulli_nb(fitted, trials, candidates):
    from sklearn.naive_bayes import BernoulliNB

    model = fitted("nb", 200)
    features = model.encoder.transform(encode_inputs(trials))
    queries = model.encoder.transform(encode_inputs(candidates))
    outcomes = outcome_matrix(trials)
    expected = np.column_stack(
        [BernoulliNB(alpha=1.0, binarize=0.0).fit(features, outcomes[:, j]).predict_proba(queries)[:, 1] for j in range(6)]
    )
    assert np.allclose(model.predict_proba(candidates), expected, rtol=0, atol=1e-12)


def test_random_model_scores_follow_the_candidate_not_its_position(candidates):
    model = make_world_model("random", 5).fit([])
    proba = model.predict_proba(candidates)
    reordered = model.predict_proba(candidates[::-1][:20])
    assert np.array_equal(reordered, proba[::-1][:20])
    assert len(np.unique(proba[:, 0])) == len(candidates)


def test_learned_models_beat_the_frequency_prior_on_held_out_toy_trials():
    train, test = synthetic_trials(600, seed=21), synthetic_trials(300, seed=22)
    truth = outcome_matrix(test)
    prior_brier = np.mean((outcome_matrix(train).mean(axis=0) - truth) ** 2)
    for name in ("nb", "nn", "logreg", "forest"):
        proba = make_world_model(name, 0).fit(train).predict_proba(test)
        assert np.mean((proba - truth) ** 2) < prior_brier, name


def test_importing_the_package_stays_light():
    code = "import sys, llcps.models; print(any(m in sys.modules for m in ('torch', 'sklearn', 'typer', 'rich')))"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
    assert out.strip() == "False"


@pytest.mark.parametrize("name", [n for n in MODELS if n != "nn"])
def test_update_of_the_other_models_is_a_refit(trials, candidates, name):
    grown = make_world_model(name, 0).fit(trials[:150]).update(trials)
    assert np.array_equal(grown.predict_proba(candidates), make_world_model(name, 0).fit(trials).predict_proba(candidates))


def test_network_update_continues_from_its_weights_deterministically(trials, candidates):
    from llcps.models.neural import NeuralNetworkModel

    def grown():
        model = make_world_model("nn", 0).fit(trials[:150])
        encoder = model.encoder.params()
        before = model.predict_proba(candidates)
        model.update(trials)
        return model, encoder, before

    model, encoder, before = grown()
    again, _, _ = grown()
    after = model.predict_proba(candidates)
    assert np.array_equal(after, again.predict_proba(candidates))  # the same seed and data, bit for bit
    assert not np.array_equal(after, before)  # it trained on the new trials
    assert not np.array_equal(after, make_world_model("nn", 0).fit(trials).predict_proba(candidates))  # not a refit
    assert 0 < model.training_log["steps"] <= NeuralNetworkModel.update_steps
    assert model.n_trials == len(trials)
    assert all(np.array_equal(encoder[k], v) for k, v in model.encoder.params().items())  # inputs keep their meaning
    # the new trials are learned: lower loss on them than before the update
    new = outcome_matrix(trials[150:])
    assert np.mean((model.predict_proba(trials[150:]) - new) ** 2) < np.mean(
        (make_world_model("nn", 0).fit(trials[:150]).predict_proba(trials[150:]) - new) ** 2
    )


def test_update_of_an_unfitted_network_is_a_fit(trials, candidates):
    fresh = make_world_model("nn", 0).update(trials)
    assert np.array_equal(fresh.predict_proba(candidates), make_world_model("nn", 0).fit(trials).predict_proba(candidates))
