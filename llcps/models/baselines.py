"""Baselines to judge the paper's two models against.

``random`` is no model at all: it gives every candidate pseudo-random scores, so any
measure orders candidates at random (a seeded order). ``logreg`` (a linear model) and
``forest`` (a non-linear ensemble) are ordinary scikit-learn multi-label learners.
"""

from __future__ import annotations

from typing import Any, ClassVar, Mapping, Sequence

import numpy as np
from sklearn.ensemble import RandomForestClassifier
from scipy.special import expit
from sklearn.linear_model import LogisticRegression

from llcps.trial_records import TrialRecord, WorldModelInput
from llcps.models.artifact import array
from llcps.models.base import WorldModel
from llcps.models.features import encode_inputs
from llcps.models.goal import GoalLearner, Standardizer, StratifiedLearner
from llcps.models.relational import N_GOAL_FEATURES, GoalQuery, encode_queries
from llcps.models.learned import N_FEATURES, N_LABELS, EncodedWorldModel, SklearnPerLabelModel

_U64 = np.uint64
_MASK64 = (1 << 64) - 1


def _splitmix64(x: np.ndarray) -> np.ndarray:
    """The SplitMix64 finalizer, elementwise on uint64 (wrapping arithmetic)."""
    z = x + _U64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> _U64(30))) * _U64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> _U64(27))) * _U64(0x94D049BB133111EB)
    return z ^ (z >> _U64(31))


def _hash_rows(raw: np.ndarray, seed: int) -> np.ndarray:
    """(n, 6) uniform values in [0, 1): SplitMix64 of the seed and each row's float64 bits."""
    raw = np.ascontiguousarray(raw, dtype=np.float64)
    state = np.full(len(raw), seed & _MASK64, dtype=np.uint64)
    for column in raw.view(np.uint64).T:
        state = _splitmix64(state ^ column)
    bits = np.stack([_splitmix64(state ^ _U64(j)) for j in range(N_LABELS)], axis=1)
    return (bits >> _U64(11)).astype(np.float64) * 2.0**-53


class NoLearning(GoalLearner):
    """The random model's goal head learns nothing (it is never asked to predict)."""

    name: ClassVar[str] = "random"

    def fit(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        return None

    def predict(self, features: np.ndarray) -> np.ndarray:
        return _hash_rows(features, self.seed)[:, 0]

    def export(self) -> dict[str, np.ndarray]:
        return {}

    def load(self, arrays: Mapping[str, np.ndarray]) -> None:
        return None


class RandomModel(WorldModel):
    """No model: a seeded pseudo-random score per candidate and bit.

    The score hashes the seed with the candidate's raw Table-1 row, so a candidate
    keeps its score however the candidate list is filtered or reordered, and the
    exploration order stays one fixed random permutation across refits.
    Candidates with identical features get identical scores; the measure's seeded
    tie-break orders those.
    """

    name: ClassVar[str] = "random"

    def _fit_outcome(self, records: Sequence[TrialRecord]) -> None:
        """Nothing to learn; remembers only how many trials it was given."""
        self.n_trials = len(records)

    def _goal_learner(self) -> GoalLearner:
        return NoLearning(self.seed)

    def predict_goal(self, query: GoalQuery) -> np.ndarray:
        """Uniform pseudo-random values in [0, 1), a function of (seed, encoded candidate-atom row)."""
        n, k = len(query.candidates), len(query.atoms)
        if n == 0 or k == 0:
            return np.zeros((n, k))
        return _hash_rows(encode_queries(query), self.seed)[:, 0].reshape(n, k)

    def predict_proba(self, candidates: Sequence[WorldModelInput | TrialRecord]) -> np.ndarray:
        """Uniform pseudo-random values in [0, 1), a function of (seed, candidate)."""
        return _hash_rows(encode_inputs(candidates), self.seed)

    def _export(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        return {}, {}

    @classmethod
    def _import(cls, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any], seed: int) -> RandomModel:
        if arrays:
            raise ValueError("the random model's artifact holds no arrays")
        return cls(seed)


class LogisticRegressionModel(SklearnPerLabelModel):
    """L2-regularized logistic regression, one per Omega bit."""

    name: ClassVar[str] = "logreg"
    scheduled: ClassVar[bool] = True

    state_shapes: ClassVar[Mapping[str, tuple[int | str, ...]]] = {
        "classes_": (2,),
        "coef_": (1, "d"),
        "intercept_": (1,),
    }

    def _make_estimator(self) -> Any:
        return LogisticRegression(C=1.0, max_iter=1000)

    def _goal_learner(self) -> GoalLearner:
        return StratifiedLearner(self.seed, LogisticGoal)


class LogisticGoal(GoalLearner):
    """Weighted L2 logistic regression on standardized (candidate, atom) rows."""

    name: ClassVar[str] = "logreg"
    scheduled: ClassVar[bool] = True

    def __init__(self, seed: int) -> None:
        super().__init__(seed)
        self.scaler = Standardizer()
        self.coef = np.zeros(N_GOAL_FEATURES)
        self.intercept = 0.0

    def fit(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        self.scaler.fit(features, weights)
        estimator = LogisticRegression(C=1.0, max_iter=1000)
        estimator.fit(self.scaler.transform(features), labels, sample_weight=weights)
        self.coef = estimator.coef_[0].astype(np.float64)
        self.intercept = float(estimator.intercept_[0])

    def predict(self, features: np.ndarray) -> np.ndarray:
        return expit(self.scaler.transform(features).astype(np.float64) @ self.coef + self.intercept)

    def export(self) -> dict[str, np.ndarray]:
        return {**self.scaler.export("scaler"), "coef": self.coef, "intercept": np.array([self.intercept])}

    def load(self, arrays: Mapping[str, np.ndarray]) -> None:
        self.scaler.load(arrays, "scaler")
        self.coef = array(arrays, "coef", (N_GOAL_FEATURES,)).astype(np.float64)
        self.intercept = float(array(arrays, "intercept", (1,))[0])


class RandomForestModel(EncodedWorldModel):
    """A multi-output random forest over the learnable Omega bits.

    Trees are awkward to export as plain arrays without relying on scikit-learn
    internals, so the artifact holds the encoded training set instead and loading
    refits deterministically (same data, same seed, one job: the same trees).
    """

    name: ClassVar[str] = "forest"
    scheduled: ClassVar[bool] = True
    n_estimators: ClassVar[int] = 100

    def _goal_learner(self) -> GoalLearner:
        return ForestGoal(self.seed)

    def _reset(self) -> None:
        self._forest: RandomForestClassifier | None = None
        self._train: tuple[np.ndarray, np.ndarray] | None = None

    def _fit_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        self._train = (features, outcomes)
        targets = outcomes[:, self.learned]
        if targets.shape[1] == 1:  # one learnable bit: a single-output forest takes y as a vector
            targets = targets[:, 0]
        self._forest = RandomForestClassifier(
            n_estimators=self.n_estimators, random_state=self.seed & 0xFFFFFFFF, n_jobs=1
        ).fit(features, targets)

    def _predict_encoded(self, features: np.ndarray) -> np.ndarray:
        assert self._forest is not None
        per_label = self._forest.predict_proba(features)
        if not isinstance(per_label, list):
            per_label = [per_label]
        proba = np.zeros((len(features), N_LABELS))
        for j, label_proba in zip(np.flatnonzero(self.learned), per_label):
            proba[:, j] = label_proba[:, 1]
        return proba

    def _export_learner(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        assert self._train is not None
        features, outcomes = self._train
        return {"train/features": features, "train/outcomes": outcomes}, {"refit_on_load": True}

    def _import_learner(self, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> None:
        features = array(arrays, "train/features", (None, N_FEATURES)).astype(np.float32, copy=False)
        outcomes = array(arrays, "train/outcomes", (len(features), N_LABELS), kind="iub")
        if not np.isin(outcomes, (0, 1)).all():
            raise ValueError("training outcomes must be 0/1")
        if not np.array_equal(outcomes.min(axis=0) != outcomes.max(axis=0), self.learned):
            raise ValueError("training outcomes disagree with the learned-bit mask")
        self._reset()
        self._fit_encoded(features, outcomes.astype(np.uint8))


class ForestGoal(GoalLearner):
    """A weighted random forest on raw (candidate, atom) rows.

    As for Omega, the artifact holds the training rows and loading refits them (same
    rows, same seed, one job: the same trees).
    """

    name: ClassVar[str] = "forest"
    scheduled: ClassVar[bool] = True
    n_estimators: ClassVar[int] = 100
    #: Leaves hold at least this many examples: probabilities, not memorized labels.
    min_samples_leaf: ClassVar[int] = 3

    def __init__(self, seed: int) -> None:
        super().__init__(seed)
        self._forest: RandomForestClassifier | None = None
        self._train: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def fit(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        features = features.astype(np.float32)
        self._train = (features, labels.astype(np.uint8), weights.astype(np.float64))
        self._forest = RandomForestClassifier(
            n_estimators=self.n_estimators,
            min_samples_leaf=self.min_samples_leaf,
            random_state=self.seed & 0xFFFFFFFF,
            n_jobs=1,
        ).fit(features, labels, sample_weight=weights)

    def predict(self, features: np.ndarray) -> np.ndarray:
        assert self._forest is not None
        return self._forest.predict_proba(features.astype(np.float32))[:, 1].astype(np.float64)

    def export(self) -> dict[str, np.ndarray]:
        assert self._train is not None
        features, labels, weights = self._train
        return {"train/features": features, "train/labels": labels, "train/weights": weights}

    def load(self, arrays: Mapping[str, np.ndarray]) -> None:
        features = array(arrays, "train/features", (None, N_GOAL_FEATURES))
        labels = array(arrays, "train/labels", (len(features),), kind="iub")
        weights = array(arrays, "train/weights", (len(features),))
        if not np.isin(labels, (0, 1)).all() or len(np.unique(labels)) != 2 or np.any(weights <= 0):
            raise ValueError("training labels must be 0/1 with both classes, weights positive")
        self.fit(features, labels, weights)
