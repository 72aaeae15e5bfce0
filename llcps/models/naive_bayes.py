"""Model 2 of the paper: Bernoulli naive Bayes, one classifier per Omega bit.

Each classifier is exactly scikit-learn's ``BernoulliNB(alpha=1.0, binarize=0.0)``
(tests/test_models.py checks agreement to 1e-12 on fit and predict), computed for
all six bits at once: one matrix product gives every bit's feature counts, where
six separate ``BernoulliNB.fit`` calls spend most of their time validating input.
That keeps a refit on 10,000 trials within the agent's refit budget.

Each encoded feature is binarized at 0: one-hot columns stay as they are, a
standardized continuous feature becomes "above the training mean". Laplace
smoothing (alpha = 1) keeps unseen feature values from zeroing a class.
"""

from __future__ import annotations

from typing import Any, ClassVar, Mapping

import numpy as np
from scipy.special import expit

from llcps.models.base import array
from llcps.models.learned import N_FEATURES, N_LABELS, EncodedWorldModel


def _binarize(features: np.ndarray) -> np.ndarray:
    """1 where a feature is above 0 (present / above the training mean), else 0."""
    return (features > 0).astype(np.float64)


class NaiveBayesModel(EncodedWorldModel):
    """Paper model 2: multi-label Bernoulli naive Bayes.

    Fitted state, per learnable bit k and class c in (0, 1):
    ``feature_log_prob[k, c, i] = log P(feature i = 1 | bit k = c)`` and
    ``class_log_prior[k, c] = log P(bit k = c)``.
    """

    name: ClassVar[str] = "nb"
    alpha: ClassVar[float] = 1.0

    def _reset(self) -> None:
        self.feature_log_prob = np.zeros((0, 2, N_FEATURES))
        self.class_log_prior = np.zeros((0, 2))

    def _fit_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        x = _binarize(features)
        y = outcomes[:, self.learned].astype(np.float64)  # (n, k), each column has both classes
        # (k, d): count of feature = 1 among trials where the bit is 1. einsum, not BLAS:
        # a small product that a threaded BLAS can stall on a busy machine.
        ones = np.einsum("nk,nd->kd", y, x)
        class_count = np.stack([len(y) - y.sum(axis=0), y.sum(axis=0)], axis=1)  # (k, 2)
        feature_count = np.stack([x.sum(axis=0) - ones, ones], axis=1)  # (k, 2, d)
        self.feature_log_prob = np.log(feature_count + self.alpha) - np.log(class_count + 2 * self.alpha)[:, :, None]
        self.class_log_prior = np.log(class_count) - np.log(len(y))

    def _predict_encoded(self, features: np.ndarray) -> np.ndarray:
        x = _binarize(features)
        log_present = self.feature_log_prob
        log_absent = np.log1p(-np.exp(log_present))
        # joint log-likelihood (m, k, 2) = x . (log p - log(1-p)) + sum log(1-p) + log prior
        joint = np.einsum("md,kcd->mkc", x, log_present - log_absent)
        joint += log_absent.sum(axis=2) + self.class_log_prior
        proba = np.zeros((len(features), N_LABELS))
        proba[:, self.learned] = expit(joint[:, :, 1] - joint[:, :, 0])
        return proba

    def _export_learner(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        arrays = {"nb/feature_log_prob": self.feature_log_prob, "nb/class_log_prior": self.class_log_prior}
        return arrays, {"alpha": self.alpha}

    def _import_learner(self, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> None:
        k = int(self.learned.sum())
        feature_log_prob = array(arrays, "nb/feature_log_prob", (k, 2, N_FEATURES))
        class_log_prior = array(arrays, "nb/class_log_prior", (k, 2))
        if np.any(feature_log_prob >= 0) or np.any(class_log_prior > 0):
            raise ValueError("naive Bayes log-probabilities must be negative")
        self.feature_log_prob = feature_log_prob.astype(np.float64)
        self.class_log_prior = class_log_prior.astype(np.float64)
