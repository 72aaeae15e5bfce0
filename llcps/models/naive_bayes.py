"""Model 2 of the paper: Bernoulli naive Bayes, one classifier per Omega bit.

Each classifier is exactly scikit-learn's ``BernoulliNB(alpha=1.0, binarize=0.0)``
(tests/test_models.py checks agreement to 1e-12 on fit and predict), computed for
all six bits at once: one matrix product gives every bit's feature counts, where
six separate ``BernoulliNB.fit`` calls spend most of their time validating input.
That keeps a refit on 10,000 trials within the agent's refit budget. Both learners
keep their counts: past 4,096 trials they bin at the means (quartiles) of the first
4,096 x 2^k trials and count the rest, so an episode learns its new trials by adding
theirs (:mod:`llcps.models.schedule`).

Each encoded feature is binarized at 0: one-hot columns stay as they are, a
standardized continuous feature becomes "above the training mean". Laplace
smoothing (alpha = 1) keeps unseen feature values from zeroing a class.
"""

from __future__ import annotations

from typing import Any, ClassVar, Mapping

import numpy as np
from scipy.special import expit
from sklearn.linear_model import LogisticRegression

from llcps.models.artifact import array
from llcps.models.goal import GoalLearner, StratifiedLearner
from llcps.models.learned import N_FEATURES, N_LABELS, EncodedWorldModel
from llcps.models.relational import CONTINUOUS_MASK


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
    scheduled: ClassVar[bool] = True
    counting: ClassVar[bool] = True
    alpha: ClassVar[float] = 1.0

    def _reset(self) -> None:
        k = int(self.learned.sum())
        #: Counts of the learnable bits: trials, trials with each bit set, trials with each
        #: feature set, and with both.
        self.rows = np.zeros(1)
        self.label_count = np.zeros(k)
        self.feature_sum = np.zeros(N_FEATURES)
        self.ones = np.zeros((k, N_FEATURES))
        self.feature_log_prob = np.zeros((k, 2, N_FEATURES))
        self.class_log_prior = np.zeros((k, 2))

    def _fit_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        self._reset()
        self._extend_encoded(features, outcomes)

    def _extend_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        x = _binarize(features)
        y = outcomes[:, self.learned].astype(np.float64)  # (n, k)
        # (k, d): count of feature = 1 among trials where the bit is 1. einsum, not BLAS:
        # a small product that a threaded BLAS can stall on a busy machine.
        self.ones = self.ones + np.einsum("nk,nd->kd", y, x)
        self.feature_sum = self.feature_sum + x.sum(axis=0)
        self.label_count = self.label_count + y.sum(axis=0)
        self.rows = self.rows + len(y)
        self._probabilities()

    def _probabilities(self) -> None:
        """The Laplace-smoothed log-probabilities of the counts."""
        class_count = np.stack([self.rows - self.label_count, self.label_count], axis=1)  # (k, 2)
        feature_count = np.stack([self.feature_sum - self.ones, self.ones], axis=1)  # (k, 2, d)
        self.feature_log_prob = np.log(feature_count + self.alpha) - np.log(class_count + 2 * self.alpha)[:, :, None]
        self.class_log_prior = np.log(class_count) - np.log(self.rows)

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

    def _goal_learner(self) -> GoalLearner:
        return StratifiedLearner(self.seed, NaiveBayesGoal)

    def _export_learner(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        arrays = {"nb/rows": self.rows, "nb/label_count": self.label_count, "nb/feature_sum": self.feature_sum, "nb/ones": self.ones}
        return arrays, {"alpha": self.alpha}

    def _import_learner(self, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> None:
        k = int(self.learned.sum())
        rows = array(arrays, "nb/rows", (1,)).astype(np.float64)
        label_count = array(arrays, "nb/label_count", (k,)).astype(np.float64)
        feature_sum = array(arrays, "nb/feature_sum", (N_FEATURES,)).astype(np.float64)
        ones = array(arrays, "nb/ones", (k, N_FEATURES)).astype(np.float64)
        if not (
            np.all((label_count > 0) & (label_count < rows))
            and np.all((feature_sum >= 0) & (feature_sum <= rows))
            and np.all((ones >= 0) & (ones <= feature_sum) & (ones <= label_count[:, None]))
        ):
            raise ValueError("naive Bayes counts must be consistent: both classes of every learned bit, no count above its total")
        self.rows, self.label_count, self.feature_sum, self.ones = rows, label_count, feature_sum, ones
        self._probabilities()


class NaiveBayesGoal(GoalLearner):
    """Weighted Bernoulli naive Bayes on (candidate, atom) rows.

    One-hot columns are features as they are; each continuous column becomes three
    bits, "above its training quartile q" for q = 1, 2, 3, so that naive Bayes sees
    where in its range a distance or a size lies, not only which side of the mean.
    Laplace smoothing (alpha = 1) on weighted counts. Naive Bayes counts correlated
    bits as independent evidence and so saturates at 0 and 1, which would tie the very
    candidates to be ranked; its log-odds are rescaled by a logistic fit on the
    training rows (Platt scaling, slope kept positive), which keeps its order and
    makes its probabilities mean what they say.

    It keeps its weighted counts, so more rows are learned by adding theirs (:meth:`extend`,
    in the quartiles and the scaling of the fit; :mod:`llcps.models.schedule`).
    """

    name: ClassVar[str] = "nb"
    scheduled: ClassVar[bool] = True
    counting: ClassVar[bool] = True
    alpha: ClassVar[float] = 1.0
    quantiles: ClassVar[tuple[float, ...]] = (0.25, 0.5, 0.75)

    def __init__(self, seed: int) -> None:
        super().__init__(seed)
        width = int(CONTINUOUS_MASK.sum())
        self.thresholds = np.zeros((width, len(self.quantiles)))
        #: Weighted counts of rows per class, and of rows with each bit set per class.
        self.class_weight = np.ones(2)
        self.ones = np.zeros((2, self._width()))
        self.feature_log_prob = np.zeros((2, self._width()))
        self.class_log_prior = np.log(np.full(2, 0.5))
        #: Slope and intercept of the Platt scaling of the log-odds.
        self.platt = np.array([1.0, 0.0])

    def _width(self) -> int:
        return int((~CONTINUOUS_MASK).sum()) + self.thresholds.size

    def _bits(self, features: np.ndarray) -> np.ndarray:
        categorical = features[:, ~CONTINUOUS_MASK] > 0.5
        continuous = features[:, CONTINUOUS_MASK]
        above = continuous[:, :, None] > self.thresholds[None, :, :]
        return np.concatenate([categorical, above.reshape(len(features), -1)], axis=1).astype(np.float64)

    def fit(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        self.thresholds = np.quantile(features[:, CONTINUOUS_MASK], self.quantiles, axis=0).T.copy()
        x = self._bits(features)
        y = labels.astype(np.float64)
        self.class_weight = np.array([weights @ (1.0 - y), weights @ y])
        self.ones = np.stack([np.einsum("n,n,nd->d", weights, 1.0 - y, x), np.einsum("n,n,nd->d", weights, y, x)])
        self._probabilities()
        self.platt = np.array([1.0, 0.0])
        scale = LogisticRegression(C=1e4, max_iter=1000).fit(self._log_odds_of_bits(x)[:, None], labels, sample_weight=weights)
        slope = float(scale.coef_[0, 0])
        if slope > 0:
            self.platt = np.array([slope, float(scale.intercept_[0])])

    def extend(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        """Add the weighted counts of more rows, in the bins of the fit; the Platt scaling stays."""
        if not len(labels):
            return
        x = self._bits(features)
        y = labels.astype(np.float64)
        self.class_weight = self.class_weight + np.array([weights @ (1.0 - y), weights @ y])
        self.ones = self.ones + np.stack([np.einsum("n,n,nd->d", weights, 1.0 - y, x), np.einsum("n,n,nd->d", weights, y, x)])
        self._probabilities()

    def _probabilities(self) -> None:
        """The Laplace-smoothed log-probabilities of the weighted counts."""
        self.feature_log_prob = np.log(self.ones + self.alpha) - np.log(self.class_weight + 2 * self.alpha)[:, None]
        self.class_log_prior = np.log(self.class_weight) - np.log(self.class_weight.sum())

    def _log_odds(self, features: np.ndarray) -> np.ndarray:
        return self._log_odds_of_bits(self._bits(features))

    def _log_odds_of_bits(self, x: np.ndarray) -> np.ndarray:
        log_present = self.feature_log_prob
        log_absent = np.log1p(-np.exp(log_present))
        joint = x @ (log_present - log_absent).T + log_absent.sum(axis=1) + self.class_log_prior
        return joint[:, 1] - joint[:, 0]

    def predict(self, features: np.ndarray) -> np.ndarray:
        return expit(self.platt[0] * self._log_odds(features) + self.platt[1])

    def export(self) -> dict[str, np.ndarray]:
        return {
            "nb/thresholds": self.thresholds,
            "nb/ones": self.ones,
            "nb/class_weight": self.class_weight,
            "nb/platt": self.platt,
        }

    def load(self, arrays: Mapping[str, np.ndarray]) -> None:
        self.thresholds = array(arrays, "nb/thresholds", self.thresholds.shape).astype(np.float64)
        ones = array(arrays, "nb/ones", (2, self._width())).astype(np.float64)
        class_weight = array(arrays, "nb/class_weight", (2,)).astype(np.float64)
        if np.any(class_weight <= 0) or np.any(ones < 0) or np.any(ones > class_weight[:, None] * (1 + 1e-9)):
            raise ValueError("naive Bayes counts must be positive per class, and no bit counted more often than its class")
        self.ones, self.class_weight = ones, class_weight
        self._probabilities()
        platt = array(arrays, "nb/platt", (2,))
        if platt[0] <= 0:
            raise ValueError("the Platt slope must be positive")
        self.platt = platt.astype(np.float64)
