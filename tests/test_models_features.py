"""Table-1 encoding: fixed one-hot columns from the domain, standardized continuous
features, the ``none`` slot of one-argument actions, and safe encoder parameters."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from llcps.domain import ACTIONS, COLORS, ORIENTATIONS, SHAPES, ControllerParams
from llcps.trial_records import TrialSpec, WorldModelInput
from llcps.errors import LlcpsError
from llcps.models.features import (
    CONTINUOUS_COLUMNS,
    ENCODED_FEATURE_NAMES,
    FEATURE_COLUMNS,
    FeatureEncoder,
    TrialTable,
    encode_inputs,
    outcome_matrix,
)
from llcps.models.synthetic import synthetic_trials


@pytest.fixture(scope="module")
def trials():
    return synthetic_trials(300, seed=3)


def column(name):
    return ENCODED_FEATURE_NAMES.index(name)


def test_encoded_columns_are_fixed_by_the_domain():
    expected_one_hot = (
        len(ACTIONS) + len(ORIENTATIONS) + 2 * (len(SHAPES) + len(COLORS)) + 2  # + the two "none" categories
    )
    assert len(ENCODED_FEATURE_NAMES) == expected_one_hot + len(CONTINUOUS_COLUMNS)
    assert len(FEATURE_COLUMNS) == 4 + 2 * 7
    # a training set holding a single action still encodes every action's column
    push_only = [r for r in synthetic_trials(50, seed=4) if r.spec.action == "push"]
    encoded = FeatureEncoder().fit_transform(encode_inputs(push_only))
    assert encoded.shape == (len(push_only), len(ENCODED_FEATURE_NAMES))
    assert encoded.dtype == np.float32


def test_one_hot_blocks_mark_exactly_the_input_categories(trials):
    encoded = FeatureEncoder().fit_transform(encode_inputs(trials))
    for row, trial in zip(encoded, trials):
        assert row[column(f"action={trial.spec.action}")] == 1
        assert row[column(f"orientation={trial.spec.params.orientation}")] == 1
        assert row[column(f"arg0_shape={trial.features[0].shape}")] == 1
        assert row[column(f"arg0_color={trial.features[0].color}")] == 1
    one_hot = len(ENCODED_FEATURE_NAMES) - len(CONTINUOUS_COLUMNS)
    assert np.array_equal(encoded[:, :one_hot].sum(axis=1), np.full(len(trials), 6.0))


def test_missing_second_argument_is_none_and_zero(trials):
    encoded = FeatureEncoder().fit_transform(encode_inputs(trials))
    single = np.array([len(t.features) == 1 for t in trials])
    assert single.any() and (~single).any()
    assert np.all(encoded[single, column("arg1_shape=none")] == 1)
    assert np.all(encoded[single, column("arg1_color=none")] == 1)
    arg1 = [column(name) for name in CONTINUOUS_COLUMNS if name.startswith("arg1_")]
    assert np.all(encoded[np.ix_(single, arg1)] == 0)
    assert np.all(encoded[~single, column("arg1_shape=none")] == 0)


def test_continuous_features_are_standardized_over_the_training_set(trials):
    encoded = FeatureEncoder().fit_transform(encode_inputs(trials))
    two_args = np.array([len(t.features) == 2 for t in trials])
    for name in CONTINUOUS_COLUMNS:
        values = encoded[two_args if name.startswith("arg1_") else slice(None), column(name)].astype(np.float64)
        assert abs(values.mean()) < 1e-5, name
        assert abs(values.std() - 1) < 1e-4, name


def test_transform_uses_the_training_statistics(trials):
    encoder = FeatureEncoder().fit(encode_inputs(trials[:100]))
    shifted = [
        dataclasses.replace(t, spec=dataclasses.replace(t.spec, params=dataclasses.replace(t.spec.params, rate=5.0)))
        for t in trials[100:110]
    ]
    encoded = encoder.transform(encode_inputs(shifted))
    assert np.all(encoded[:, column("rate")] > 3)  # far above the training mean, not re-centred


def test_encoder_parameters_round_trip(trials):
    encoder = FeatureEncoder().fit(encode_inputs(trials))
    params = encoder.params()
    assert set(params) == {"mean", "scale"}
    restored = FeatureEncoder.from_params(params)
    assert np.array_equal(restored.transform(encode_inputs(trials)), encoder.transform(encode_inputs(trials)))
    with pytest.raises(LlcpsError):
        FeatureEncoder.from_params({"mean": params["mean"], "scale": np.zeros_like(params["scale"])})
    with pytest.raises(LlcpsError):
        FeatureEncoder.from_params({"mean": params["mean"][:3], "scale": params["scale"]})


def test_empty_and_unobserved_columns_keep_identity_scaling():
    empty = FeatureEncoder().fit(encode_inputs([]))
    assert np.array_equal(empty.params()["mean"], np.zeros(len(CONTINUOUS_COLUMNS)))
    push_only = [r for r in synthetic_trials(40, seed=5) if r.spec.action == "push"]
    encoder = FeatureEncoder().fit(encode_inputs(push_only))
    params = encoder.params()
    assert np.all(np.isfinite(params["mean"])) and np.all(params["scale"] > 0)
    assert np.all(np.isfinite(encoder.transform(encode_inputs(synthetic_trials(40, seed=6)))))


def test_unknown_category_and_feature_count_mismatch_are_project_errors(trials):
    trial = trials[0]
    odd = dataclasses.replace(trial, features=(dataclasses.replace(trial.features[0], shape="torus"),) + trial.features[1:])
    with pytest.raises(LlcpsError, match="torus"):
        encode_inputs([odd])
    two = WorldModelInput(
        spec=TrialSpec("push_together", ("a", "b"), ControllerParams(0.1, 0.05, "left")), features=trial.features[:1]
    )
    with pytest.raises(LlcpsError, match="feature mapping"):
        encode_inputs([two])


def test_outcome_matrix_follows_outcome_names(trials):
    matrix = outcome_matrix(trials)
    assert matrix.shape == (len(trials), 6)
    assert [tuple(row) for row in matrix] == [t.outcome.bits() for t in trials]
    assert outcome_matrix([]).shape == (0, 6)


def test_trial_table_reuses_rows_of_a_growing_training_set(trials):
    table = TrialTable()
    records = list(trials[:100])
    first_raw, _ = table.encode(records)
    records += trials[100:150]
    raw, outcomes = table.encode(records)
    assert np.array_equal(raw[:100], first_raw, equal_nan=True)
    assert np.array_equal(raw, encode_inputs(records), equal_nan=True)
    assert np.array_equal(outcomes, outcome_matrix(records))
    # a different list (not an extension) is encoded afresh
    other = list(trials[150:200])
    assert np.array_equal(table.encode(other)[0], encode_inputs(other), equal_nan=True)


def _sklearn_reference():
    """The encoding as scikit-learn's OneHotEncoder and ColumnTransformer give it."""
    from sklearn.compose import ColumnTransformer
    from sklearn.preprocessing import OneHotEncoder, StandardScaler

    from llcps.models.features import CATEGORICAL_COLUMNS, CATEGORIES

    categories = [np.arange(len(values), dtype=np.float64) for values in CATEGORIES.values()]
    return ColumnTransformer(
        [
            ("categorical", OneHotEncoder(categories=categories, sparse_output=False), [FEATURE_COLUMNS.index(c) for c in CATEGORICAL_COLUMNS]),
            ("continuous", StandardScaler(), [FEATURE_COLUMNS.index(c) for c in CONTINUOUS_COLUMNS]),
        ],
        sparse_threshold=0.0,
    )


@pytest.mark.parametrize("n", [1, 4, 300])
def test_encoding_is_scikit_learns_bit_for_bit(trials, n):
    train, test = encode_inputs(trials[:n]), encode_inputs(trials[-50:])
    reference = _sklearn_reference()
    expected_fit = np.nan_to_num(reference.fit_transform(train), nan=0.0).astype(np.float32)
    expected_test = np.nan_to_num(reference.transform(test), nan=0.0).astype(np.float32)
    encoder = FeatureEncoder()
    fitted = encoder.fit_transform(train)
    assert fitted.tobytes() == expected_fit.tobytes()
    assert encoder.transform(test).tobytes() == expected_test.tobytes()
    assert FeatureEncoder.from_params(encoder.params()).transform(test).tobytes() == expected_test.tobytes()


@pytest.mark.parametrize("code", [-1.0, 0.5, 99.0, float("nan")])
def test_a_category_code_outside_its_tuple_is_a_project_error(trials, code):
    table = encode_inputs(trials[:5])
    encoder = FeatureEncoder().fit(table)
    table[2, FEATURE_COLUMNS.index("orientation")] = code
    with pytest.raises(LlcpsError, match="orientation"):
        encoder.transform(table)
    with pytest.raises(LlcpsError, match="orientation"):
        FeatureEncoder().fit_transform(table)
