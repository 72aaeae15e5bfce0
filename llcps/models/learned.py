"""What every learned world model shares: Table-1 encoding, the label prior for
bits it cannot learn, and the artifact layout of encoder + prior + model arrays.

A bit with a single class in the training set (the paper's 4-trial "no a priori
training" case has mostly such bits; with 0 trials every bit is one) is not given to
the learner: the model predicts its Laplace-smoothed frequency instead. That keeps
degenerate fits finite and honest: never certainty from a handful of trials.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

from llcps.domain import OUTCOME_NAMES
from llcps.trial_records import TrialRecord, WorldModelInput
from llcps.training import TrainingSet
from llcps.models.artifact import array
from llcps.models.base import WorldModel, label_prior, learnable_labels, prior_of_counts
from llcps.models.schedule import bins_trials
from llcps.models.features import (
    CONTINUOUS_COLUMNS,
    ENCODED_FEATURE_NAMES,
    FeatureEncoder,
    TrialTable,
    encode_inputs,
    outcome_matrix,
)

N_LABELS = len(OUTCOME_NAMES)
N_FEATURES = len(ENCODED_FEATURE_NAMES)


class EncodedWorldModel(WorldModel):
    """A world model that learns from encoded features (see the module docstring)."""

    def __init__(self, seed: int) -> None:
        super().__init__(seed)
        self.encoder = FeatureEncoder().fit(encode_inputs([]))
        self.prior = label_prior(outcome_matrix([]))
        self.learned = learnable_labels(outcome_matrix([]))
        #: Per Omega bit, how many trials learned from had it set (the prior's counts).
        self.outcome_sum = np.zeros(N_LABELS)
        self._table = TrialTable()
        #: The trials learned, where this process saw them: a training set's base and
        #: watermark, then the ids of the trials after its base, in order (a plain sequence:
        #: base 0). None: a stored fit brought up by :meth:`extend`, whose trials are
        #: those its branch saw, as the caller's first update shows.
        self._learned: _Learned | None = (0, 0, [])

    def _fit_outcome(self, records: Sequence[TrialRecord]) -> None:
        """Fit the encoder and the learner on every trial in ``records`` (a scheduled model:
        on the first :func:`~llcps.models.schedule.bins_trials` of them, the rest counted)."""
        raw, outcomes = self._table.encode(records)
        bins = bins_trials(len(raw)) if self.scheduled else len(raw)
        self.n_trials = self.bins = bins
        self.encoder = FeatureEncoder()
        features = self.encoder.fit_transform(raw[:bins])
        self.outcome_sum = outcomes[:bins].sum(axis=0, dtype=np.float64)
        self.prior = prior_of_counts(self.outcome_sum, bins)
        self.learned = learnable_labels(outcomes[:bins])
        self._reset()
        if self.learned.any():
            self._fit_encoded(features, outcomes[:bins])
        if bins < len(raw):
            self._count(raw[bins:], outcomes[bins:])
        base, watermark, rest = _split(records)
        self._learned = (base, watermark, _ids(rest))

    def _extend_outcome(self, records: Sequence[TrialRecord]) -> None:
        self._count(encode_inputs(records), outcome_matrix(records))
        self._learned = None

    def _count(self, raw: np.ndarray, outcomes: np.ndarray) -> None:
        """Add the counts of more trials, encoded by the fit's encoder, to the prior and
        (a counting model) the learner; the learnable bits stay the fit's."""
        self.outcome_sum = self.outcome_sum + outcomes.sum(axis=0, dtype=np.float64)
        self.n_trials += len(raw)
        self.prior = prior_of_counts(self.outcome_sum, self.n_trials)
        if self.counting and self.learned.any() and len(raw):
            self._extend_encoded(self.encoder.transform(raw), outcomes)

    def _extend_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        """Add the counts of more encoded trials to the learner's (a counting model only)."""
        raise NotImplementedError(f"world model {self.name!r} does not count")

    def _update_outcome(self, records: Sequence[TrialRecord]) -> None:
        """Count the new trials if the model is scheduled and the grown set keeps its bins
        (:mod:`llcps.models.schedule`); else continue from the current fit if the learner
        can (:meth:`_can_continue`); else refit.

        A continued learner keeps the encoder of its last full fit, so its inputs mean what
        they meant when it was trained; the label prior and the learnable bits follow the
        grown set.
        """
        # the set the model learned, given again (the hedge's model side, after a trial of
        # the other side), teaches a learner that refits nothing new
        grows = len(records) > self.n_trials or (len(records) == self.n_trials and not self._can_continue())
        if self.scheduled and grows and bins_trials(len(records)) == self.bins:
            fresh = self._grown(records)
            if fresh is not None:
                if len(fresh):
                    self._count(encode_inputs(fresh), outcome_matrix(fresh))
                return
            self._fit_outcome(records)
            return
        if not (self.learned.any() and self._can_continue()):
            self._fit_outcome(records)
            return
        raw, outcomes = self._table.encode(records)
        self._continue_encoded(self.encoder.transform(raw), outcomes)
        self.n_trials = len(raw)
        self.prior = label_prior(outcomes)
        self.learned = learnable_labels(outcomes)

    def _grown(self, records: Sequence[TrialRecord]) -> Sequence[TrialRecord] | None:
        """The trials of ``records`` after those learned, if ``records`` grew from them (a
        caller may leave trials out), now learned too; else None.

        A :class:`~llcps.training.TrainingSet` whose base is the one learned from is
        compared by its tail alone, so its base is never read.
        """
        base, watermark, rest = _split(records)
        learned = self._learned
        if learned is None:  # a stored fit: the first n_trials of the set are its trials
            if self.n_trials < base:
                base, watermark, rest = 0, 0, list(records)
            learned = (base, watermark, _ids(rest[: self.n_trials - base]))
        elif learned[:2] != (base, watermark) and learned[0] == 0:  # learned from a plain sequence
            base, watermark, rest = 0, 0, list(records)
        known = learned[2]
        if learned[:2] != (base, watermark) or _ids(rest[: len(known)]) != known or None in known:
            return None
        fresh = rest[len(known) :]
        ids = _ids(fresh)
        if None in ids:
            return None
        self._learned = (base, watermark, known + ids)
        return fresh

    def _can_continue(self) -> bool:
        """Whether the learner can train further from its fitted state (:meth:`_continue_encoded`)."""
        return False

    def _continue_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        """Train the fitted learner further on the grown set (encoded as for :meth:`_fit_encoded`)."""
        raise NotImplementedError

    def predict_proba(self, candidates: Sequence[WorldModelInput | TrialRecord]) -> np.ndarray:
        """P(bit = 1) per candidate; bits not learned get the training prior."""
        raw = encode_inputs(candidates)
        proba = np.tile(self.prior, (len(raw), 1))
        if self.learned.any() and len(raw):
            predicted = self._predict_encoded(self.encoder.transform(raw))
            proba[:, self.learned] = predicted[:, self.learned]
        return np.clip(proba, 0.0, 1.0)

    @abstractmethod
    def _reset(self) -> None:
        """Forget the learner's fitted state."""

    @abstractmethod
    def _fit_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        """Fit on encoded float32 features (n, d) and 0/1 outcomes (n, 6); the bits to
        learn are ``self.learned`` (each has both classes)."""

    @abstractmethod
    def _predict_encoded(self, features: np.ndarray) -> np.ndarray:
        """(m, 6) probabilities; only the ``self.learned`` columns are used."""

    @abstractmethod
    def _export_learner(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """The learner's fitted state (arrays, JSON-able meta)."""

    @abstractmethod
    def _import_learner(self, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> None:
        """Restore :meth:`_export_learner` output into this (encoder-ready) instance."""

    def _export(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        arrays, meta = self._export_learner() if self.learned.any() else ({}, {})
        encoder = self.encoder.params()
        arrays = {
            **arrays,
            "encoder/mean": encoder["mean"],
            "encoder/scale": encoder["scale"],
            "prior": self.prior,
            "outcome_sum": self.outcome_sum,
            "learned": self.learned,
        }
        learned = [name for name, ok in zip(OUTCOME_NAMES, self.learned) if ok]
        return arrays, {**meta, "feature_names": list(ENCODED_FEATURE_NAMES), "learned": learned}

    @classmethod
    def _import(cls, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any], seed: int) -> EncodedWorldModel:
        model = cls(seed)
        width = len(CONTINUOUS_COLUMNS)
        model.encoder = FeatureEncoder.from_params(
            {"mean": array(arrays, "encoder/mean", (width,)), "scale": array(arrays, "encoder/scale", (width,))}
        )
        prior = array(arrays, "prior", (N_LABELS,))
        if np.any((prior <= 0) | (prior >= 1)):
            raise ValueError("label prior must lie strictly inside (0, 1)")
        model.prior = prior.astype(np.float64)
        outcome_sum = array(arrays, "outcome_sum", (N_LABELS,)).astype(np.float64)
        if np.any(outcome_sum < 0):
            raise ValueError("Omega bit counts must not be negative")
        model.outcome_sum = outcome_sum
        model._learned = None  # the trials its branch saw, as the caller's first update will show
        model.learned = array(arrays, "learned", (N_LABELS,), kind="b").astype(bool)
        if model.learned.any():
            model._import_learner(arrays, meta)
        return model


#: What a model learned: (base, watermark, ids) as :func:`_split` gives them.
_Learned = tuple[int, int, list[int | None]]


def _ids(records: Sequence[TrialRecord]) -> list[int | None]:
    return [getattr(r, "id", None) for r in records]


def _split(records: Sequence[TrialRecord]) -> tuple[int, int, Sequence[TrialRecord]]:
    """(base, watermark, rest): a training set's base (how many trials, up to which id),
    left unread, and its trials after it; a plain sequence is all rest."""
    if isinstance(records, TrainingSet):
        return records.base, records.watermark, records.tail
    return 0, 0, records


class SklearnPerLabelModel(EncodedWorldModel):
    """One scikit-learn binary classifier per learnable Omega bit.

    Subclasses name the estimator and the fitted attributes that fully determine its
    ``predict_proba``; those attributes are exported as arrays and set back on a
    fresh estimator when loading (shapes checked against :attr:`state_shapes`, where
    ``"d"`` is the encoded width).
    """

    state_shapes: ClassVar[Mapping[str, tuple[int | str, ...]]]
    #: dtype kind of each state attribute that is not a float array.
    state_kinds: ClassVar[Mapping[str, str]] = {"classes_": "iu"}

    @abstractmethod
    def _make_estimator(self) -> Any:
        """A fresh, unfitted estimator for one bit."""

    def _reset(self) -> None:
        self._estimators: dict[int, Any] = {}

    def _fit_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        for j in np.flatnonzero(self.learned):
            self._estimators[int(j)] = self._make_estimator().fit(features, outcomes[:, j])

    def _predict_encoded(self, features: np.ndarray) -> np.ndarray:
        proba = np.zeros((len(features), N_LABELS))
        for j, estimator in self._estimators.items():
            proba[:, j] = estimator.predict_proba(features)[:, 1]
        return proba

    def _export_learner(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        arrays = {
            f"label{j}/{attr}": np.asarray(getattr(estimator, attr))
            for j, estimator in self._estimators.items()
            for attr in self.state_shapes
        }
        return arrays, {}

    def _import_learner(self, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> None:
        self._reset()
        for j in np.flatnonzero(self.learned):
            estimator = self._make_estimator()
            for attr, shape in self.state_shapes.items():
                want = tuple(N_FEATURES if size == "d" else size for size in shape)
                value = array(arrays, f"label{j}/{attr}", want, kind=self.state_kinds.get(attr, "f"))
                setattr(estimator, attr, value)
            if list(estimator.classes_) != [0, 1]:
                raise ValueError(f"label {j} classifier must have classes [0, 1]")
            estimator.n_features_in_ = N_FEATURES
            self._estimators[int(j)] = estimator
