"""Table 1 as numbers: the world model's input encoding and Table 2's targets.

Two stages, as in the paper's preprocessing. :func:`encode_inputs` turns trials or
candidates into a *raw table* (one row each, columns :data:`FEATURE_COLUMNS`):
categorical values as integer codes into the fixed category tuples of
:mod:`llcps.domain`, continuous values as floats, and NaN for the continuous values of
a missing second argument. :class:`FeatureEncoder` then one-hot encodes the categories
(categories fixed from the domain, so every encoding has the same columns whatever
the training set holds: blocks set by indexing, which need no fitting) and
standardizes the continuous columns (scikit-learn's ``StandardScaler`` over the
training set). A missing second argument becomes the category ``none`` and zeros in
standardized space, i.e. the training mean: it carries no continuous signal. The
encoding is what scikit-learn's ``OneHotEncoder`` and ``ColumnTransformer`` give, bit
for bit, without their per-call overhead: an agent refits the encoder after every
trial, and in a ``ColumnTransformer`` that cost more CPU than the naive Bayes fit.
"""

from __future__ import annotations

import operator
import warnings
from typing import Mapping, Protocol, Sequence

import numpy as np
from sklearn import config_context
from sklearn.preprocessing import StandardScaler

from llcps.domain import ACTIONS, COLORS, ORIENTATIONS, OUTCOME_NAMES, SHAPES, EntityFeatures
from llcps.trial_records import StoredFeatures, TrialRecord, TrialSpec
from llcps.errors import LlcpsError

#: The category a missing argument slot takes (second slot of a one-argument action).
NONE = "none"

#: Argument slots encoded per input; every action of Table 1 takes one or two.
ARGUMENT_SLOTS = 2

_ENTITY_CONTINUOUS: tuple[str, ...] = ("volume", "vector_magnitude", "unit_x", "unit_y", "unit_z")


def _slot_columns(slot: int) -> tuple[str, ...]:
    return (f"arg{slot}_shape", f"arg{slot}_color") + tuple(f"arg{slot}_{name}" for name in _ENTITY_CONTINUOUS)


#: Columns of the raw table, in order.
FEATURE_COLUMNS: tuple[str, ...] = (
    "action",
    "orientation",
    "rate",
    "movement_magnitude",
    *_slot_columns(0),
    *_slot_columns(1),
)

#: Category tuples of each categorical raw column; a code is an index into its tuple.
CATEGORIES: Mapping[str, tuple[str, ...]] = {
    "action": ACTIONS,
    "orientation": ORIENTATIONS,
    "arg0_shape": SHAPES,
    "arg0_color": COLORS,
    "arg1_shape": SHAPES + (NONE,),
    "arg1_color": COLORS + (NONE,),
}

CATEGORICAL_COLUMNS: tuple[str, ...] = tuple(CATEGORIES)
CONTINUOUS_COLUMNS: tuple[str, ...] = tuple(c for c in FEATURE_COLUMNS if c not in CATEGORIES)

_CATEGORICAL_INDEX = [FEATURE_COLUMNS.index(c) for c in CATEGORICAL_COLUMNS]
_CONTINUOUS_INDEX = [FEATURE_COLUMNS.index(c) for c in CONTINUOUS_COLUMNS]

#: Names of the encoded columns, in the order :meth:`FeatureEncoder.transform` returns them.
ENCODED_FEATURE_NAMES: tuple[str, ...] = tuple(
    f"{column}={value}" for column, values in CATEGORIES.items() for value in values
) + CONTINUOUS_COLUMNS

_ACTION_CODE = {v: i for i, v in enumerate(ACTIONS)}
_ORIENTATION_CODE = {v: i for i, v in enumerate(ORIENTATIONS)}
_SHAPE_CODE = {v: i for i, v in enumerate(SHAPES)}
_COLOR_CODE = {v: i for i, v in enumerate(COLORS)}
_NONE_SHAPE, _NONE_COLOR = len(SHAPES), len(COLORS)
_MISSING_SLOT = (float(_NONE_SHAPE), float(_NONE_COLOR)) + (float("nan"),) * len(_ENTITY_CONTINUOUS)
_entity_continuous = operator.attrgetter(*_ENTITY_CONTINUOUS)
_outcome_bits = operator.attrgetter(*OUTCOME_NAMES)

#: scikit-learn settings for the encoder's calls: the raw table is built and checked
#: here, so per-call input validation (most of a call's cost) is skipped.
_SKLEARN_CONFIG = {"assume_finite": True, "skip_parameter_validation": True}


class ModelInput(Protocol):
    """Anything with a trial spec and its arguments' features: a candidate
    (:class:`~llcps.trial_records.WorldModelInput`) or a stored trial
    (:class:`~llcps.trial_records.TrialRecord`)."""

    @property
    def spec(self) -> TrialSpec: ...

    @property
    def features(self) -> tuple[EntityFeatures, ...]: ...


def _slot(entity: EntityFeatures) -> tuple[float, ...]:
    return (_SHAPE_CODE[entity.shape], _COLOR_CODE[entity.color], *_entity_continuous(entity))


def _stored_slots(stored: StoredFeatures) -> tuple[tuple[float, ...], tuple[float, ...]]:
    names, numbers = stored.names, stored.numbers
    first = (_SHAPE_CODE[names[0]], _COLOR_CODE[names[1]], *numbers[:5])
    return first, ((_SHAPE_CODE[names[2]], _COLOR_CODE[names[3]], *numbers[5:10]) if len(names) == 2 * ARGUMENT_SLOTS else _MISSING_SLOT)


def _row(item: ModelInput) -> tuple[float, ...]:
    spec = item.spec
    # A trial read from a store: its names and numbers, without building EntityFeatures.
    stored = item.stored_features if isinstance(item, TrialRecord) else None
    count = len(stored) if stored is not None else len(item.features)
    if count != len(spec.arguments) or count == 0:
        raise LlcpsError(
            f"{spec.label} has {len(spec.arguments)} argument(s) but {count} feature mapping(s)",
            hint="give one EntityFeatures per argument, in argument order",
        )
    if stored is not None:
        first, second = _stored_slots(stored)
    else:
        entities = item.features
        first, second = _slot(entities[0]), (_slot(entities[1]) if count == ARGUMENT_SLOTS else _MISSING_SLOT)
    params = spec.params
    return (
        _ACTION_CODE[spec.action],
        _ORIENTATION_CODE[params.orientation],
        params.rate,
        params.movement_magnitude,
        *first,
        *second,
    )


def encode_inputs(inputs: Sequence[ModelInput]) -> np.ndarray:
    """The raw table of world-model inputs (trials or candidates).

    Args:
        inputs: candidates or stored trials.

    Returns:
        A float64 array (n, len(FEATURE_COLUMNS)): categorical columns hold integer
        codes into :data:`CATEGORIES`, continuous columns their values, and a missing
        second argument NaN in its continuous columns.

    Raises:
        LlcpsError: an entity shape or color outside Table 1's categories, or a
            feature count that does not match the arguments.
    """
    try:
        rows = [_row(item) for item in inputs]
    except KeyError as exc:
        raise LlcpsError(
            f"unknown category {exc.args[0]!r} in a world-model input",
            hint=f"shapes are {', '.join(SHAPES)}; colors are {', '.join(COLORS)}",
        ) from None
    if not rows:
        return np.empty((0, len(FEATURE_COLUMNS)), dtype=np.float64)
    return np.array(rows, dtype=np.float64)


def outcome_matrix(records: Sequence[object]) -> np.ndarray:
    """The six Omega bits of each trial, in OUTCOME_NAMES order.

    Args:
        records: stored trials (anything with an ``outcome``).

    Returns:
        A uint8 array (n, 6) of 0/1.
    """
    if not records:
        return np.empty((0, len(OUTCOME_NAMES)), dtype=np.uint8)
    return np.array([_outcome_bits(r.outcome) for r in records], dtype=np.uint8)  # type: ignore[attr-defined]


class TrialTable:
    """Raw table and outcomes of a growing list of trials, encoded once per trial.

    The lifelong training set only grows: an agent refits on the same records plus a
    few new ones. Records are frozen, so a record object seen before (the same object,
    at the same position) has the same row; only the new tail is encoded.
    """

    def __init__(self) -> None:
        self._records: tuple[object, ...] = ()
        self._raw = encode_inputs([])
        self._outcomes = outcome_matrix([])

    def __deepcopy__(self, memo: dict[int, object]) -> TrialTable:
        """A copy that shares the records and arrays: records are frozen and the arrays are
        replaced, never changed in place. Copying ten thousand records was a third of a
        fit's time (a fit is remembered as a copy)."""
        copied = TrialTable()
        copied._records, copied._raw, copied._outcomes = self._records, self._raw, self._outcomes
        return copied

    def encode(self, records: Sequence[ModelInput]) -> tuple[np.ndarray, np.ndarray]:
        """Return (raw table, outcome matrix) of ``records``, reusing the known prefix."""
        known = len(self._records)
        if not (known <= len(records) and all(map(operator.is_, self._records, records[:known]))):
            known = 0
        fresh = records[known:]
        if known == 0:
            raw, outcomes = encode_inputs(records), outcome_matrix(records)
        elif fresh:
            raw = np.concatenate([self._raw, encode_inputs(fresh)])
            outcomes = np.concatenate([self._outcomes, outcome_matrix(fresh)])
        else:
            raw, outcomes = self._raw, self._outcomes
        self._records, self._raw, self._outcomes = tuple(records), raw, outcomes
        return raw, outcomes


#: Width of each categorical column's one-hot block, in CATEGORICAL_COLUMNS order.
_CATEGORY_SIZES = np.array([len(values) for values in CATEGORIES.values()])
#: Where each categorical column's block starts in the encoded row.
_CATEGORY_OFFSETS = np.concatenate([[0], np.cumsum(_CATEGORY_SIZES)[:-1]])
_N_ONE_HOT = int(_CATEGORY_SIZES.sum())


def _one_hot(codes: np.ndarray) -> np.ndarray:
    """One-hot blocks of integer category codes (n, len(CATEGORICAL_COLUMNS)), float64.

    Raises:
        LlcpsError: a code that is not an integer index into its category tuple.
    """
    valid = (codes >= 0) & (codes < _CATEGORY_SIZES) & (codes == np.floor(codes))
    if not valid.all():
        row, col = np.argwhere(~valid)[0]
        raise LlcpsError(f"unknown {CATEGORICAL_COLUMNS[col]} code {codes[row, col]!r} in row {row} of a raw feature table")
    out = np.zeros((len(codes), _N_ONE_HOT))
    out[np.arange(len(codes))[:, None], _CATEGORY_OFFSETS + codes.astype(np.int64)] = 1.0
    return out


class FeatureEncoder:
    """One-hot categories and standardized continuous features (Table 1 -> R^d).

    The only fitted state is the scaler's mean and scale, which :meth:`params`
    exports as plain arrays and :meth:`from_params` restores, so a stored model
    carries its encoding without pickling anything.
    """

    def __init__(self) -> None:
        self._scaler = StandardScaler()
        self._fitted = False

    @property
    def n_features(self) -> int:
        return len(ENCODED_FEATURE_NAMES)

    def fit(self, table: np.ndarray) -> FeatureEncoder:
        """Learn the continuous columns' mean and scale from a raw table.

        An empty table, or a column never observed (a second argument no training
        trial had), keeps mean 0 and scale 1.
        """
        self.fit_transform(table)
        return self

    def fit_transform(self, table: np.ndarray) -> np.ndarray:
        """:meth:`fit`, then :meth:`transform` the same table (one pass)."""
        table = _check_table(table)
        if len(table) == 0:
            self._set_scaler(np.zeros(len(CONTINUOUS_COLUMNS)), np.ones(len(CONTINUOUS_COLUMNS)))
            return self.transform(table)
        with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"), config_context(**_SKLEARN_CONFIG):
            warnings.simplefilter("ignore", RuntimeWarning)
            encoded = self._encode(table, self._scaler.fit_transform(table[:, _CONTINUOUS_INDEX]))
        scaler = self._scaler
        if np.all(np.isfinite(scaler.mean_)) and np.all(scaler.scale_ > 0):
            self._fitted = True
            return _finish(encoded)
        self._set_scaler(scaler.mean_, scaler.scale_)
        return self.transform(table)

    def transform(self, table: np.ndarray) -> np.ndarray:
        """Encode a raw table as float32 (n, len(ENCODED_FEATURE_NAMES))."""
        if not self._fitted:
            raise LlcpsError("the feature encoder is not fitted", hint="fit the world model first")
        table = _check_table(table)
        if len(table) == 0:
            return np.empty((0, self.n_features), dtype=np.float32)
        with config_context(**_SKLEARN_CONFIG):
            return _finish(self._encode(table, self._scaler.transform(table[:, _CONTINUOUS_INDEX])))

    @staticmethod
    def _encode(table: np.ndarray, scaled: np.ndarray) -> np.ndarray:
        """The one-hot blocks, then the scaled continuous columns."""
        return np.hstack([_one_hot(table[:, _CATEGORICAL_INDEX]), scaled])

    def params(self) -> dict[str, np.ndarray]:
        """The fitted state as plain float64 arrays (for safe persistence)."""
        scaler = self._scaler
        return {"mean": scaler.mean_.copy(), "scale": scaler.scale_.copy()}

    @classmethod
    def from_params(cls, params: Mapping[str, np.ndarray]) -> FeatureEncoder:
        """Rebuild a fitted encoder from :meth:`params` output.

        Raises:
            LlcpsError: missing, mis-shaped or non-finite parameters.
        """
        width = len(CONTINUOUS_COLUMNS)
        arrays = {}
        for key in ("mean", "scale"):
            value = np.asarray(params.get(key) if key in params else None)
            if value.shape != (width,) or value.dtype.kind != "f" or not np.all(np.isfinite(value)):
                raise LlcpsError(f"feature encoder parameter {key!r} must be {width} finite floats")
            arrays[key] = value.astype(np.float64)
        if np.any(arrays["scale"] <= 0):
            raise LlcpsError("feature encoder scale must be positive")
        return cls()._set_scaler(arrays["mean"], arrays["scale"])

    def _set_scaler(self, mean: np.ndarray, scale: np.ndarray) -> FeatureEncoder:
        """Install mean/scale, sanitizing columns no trial observed (NaN) to 0/1."""
        if not hasattr(self._scaler, "mean_"):
            # Fitting on one row sets the scaler's fitted attributes; its statistics
            # are overwritten just below.
            self._scaler.fit(np.zeros((1, len(CONTINUOUS_COLUMNS))))
        mean = np.where(np.isfinite(mean), mean, 0.0)
        scale = np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)
        scaler = self._scaler
        scaler.mean_, scaler.scale_, scaler.var_ = mean, scale, scale**2
        self._fitted = True
        return self


def _finish(encoded: np.ndarray) -> np.ndarray:
    """A missing argument's NaN continuous values become 0 (the mean); float32."""
    return np.nan_to_num(encoded, nan=0.0, copy=False).astype(np.float32, copy=False)


def _check_table(table: np.ndarray) -> np.ndarray:
    table = np.asarray(table, dtype=np.float64)
    if table.ndim != 2 or table.shape[1] != len(FEATURE_COLUMNS):
        raise LlcpsError(f"a raw feature table has {len(FEATURE_COLUMNS)} columns, got shape {table.shape}")
    return table
