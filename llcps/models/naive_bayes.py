"""Model 2 of the paper: Bernoulli naive Bayes, one classifier per Omega bit.

Each encoded feature is binarized at 0 (as ``BernoulliNB(binarize=0.0)`` would, but
once for all six classifiers): one-hot columns stay as they are, a standardized
continuous feature becomes "above the training mean". Laplace smoothing (alpha = 1)
keeps unseen feature values from zeroing a class.
"""

from __future__ import annotations

from typing import Any, ClassVar, Mapping

import numpy as np
from sklearn.naive_bayes import BernoulliNB

from llcps.models.learned import SklearnPerLabelModel


class NaiveBayesModel(SklearnPerLabelModel):
    """Paper model 2: multi-label Bernoulli naive Bayes."""

    name: ClassVar[str] = "nb"
    alpha: ClassVar[float] = 1.0

    state_shapes: ClassVar[Mapping[str, tuple[int | str, ...]]] = {
        "classes_": (2,),
        "class_count_": (2,),
        "class_log_prior_": (2,),
        "feature_count_": (2, "d"),
        "feature_log_prob_": (2, "d"),
    }

    def _make_estimator(self) -> Any:
        return BernoulliNB(alpha=self.alpha, binarize=None)

    def _fit_encoded(self, features: np.ndarray, outcomes: np.ndarray) -> None:
        super()._fit_encoded(_binarize(features), outcomes)

    def _predict_encoded(self, features: np.ndarray) -> np.ndarray:
        return super()._predict_encoded(_binarize(features))


def _binarize(features: np.ndarray) -> np.ndarray:
    """1 where a feature is above 0 (present / above the training mean), else 0."""
    return (features > 0).astype(np.float64)  # float64 like the label matrix: one BLAS product
