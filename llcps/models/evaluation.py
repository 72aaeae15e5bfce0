"""Held-out evaluation of a world model, next to the majority-class baseline.

The paper splits its data into a training and a testing set; this does the same
with a seeded shuffle and reports, per Omega bit, accuracy and F1 at threshold 0.5
and the Brier score, beside a baseline that ignores the inputs: the training
set's majority class for accuracy and F1, its label frequency for the Brier score.

With the trials' symbolic changes it also scores the goal-aware head on the held-out
trials' (candidate, atom) examples: weighted Brier score and ROC AUC, beside the
training set's change rate (whose AUC is 0.5).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from sklearn.metrics import accuracy_score, f1_score, roc_auc_score

from llcps.domain import OUTCOME_NAMES
from llcps.trial_records import TrialChange, TrialRecord
from llcps.errors import LlcpsError
from llcps.models.features import outcome_matrix
from llcps.models.goal import examples_of
from llcps.models.registry import make_world_model


@dataclass(frozen=True)
class LabelMetrics:
    """Held-out metrics of one Omega bit."""

    label: str
    #: Fraction of 1s in the training and the test split.
    train_frequency: float
    test_frequency: float
    #: Both classes occur in the test split (F1 is informative only then).
    both_classes: bool
    accuracy: float
    f1: float
    brier: float
    baseline_accuracy: float
    baseline_f1: float
    baseline_brier: float


@dataclass(frozen=True)
class GoalMetrics:
    """Held-out metrics of the goal-aware head over (candidate, atom) examples.

    Attributes:
        examples: held-out examples (each stands for ``weight`` atoms).
        positives: of them, atoms the trial changed as asked.
        brier: weighted Brier score; ``baseline_brier`` of the training change rate.
        auc: weighted ROC AUC (NaN with a single class held out); the baseline's is 0.5.
    """

    examples: int
    positives: int
    brier: float
    baseline_brier: float
    auc: float


@dataclass(frozen=True)
class EvaluationReport:
    """A model's held-out metrics per Omega bit, and of its goal-aware head."""

    model: str
    seed: int
    n_train: int
    n_test: int
    labels: tuple[LabelMetrics, ...]
    goal: GoalMetrics | None = None

    def mean(self, metric: str) -> float:
        """Mean of one LabelMetrics field over the six bits."""
        return float(np.mean([getattr(label, metric) for label in self.labels]))

    def beats_baseline_f1(self) -> list[str]:
        """Bits with both classes in the test split where the model's F1 beats the baseline's."""
        return [m.label for m in self.labels if m.both_classes and m.f1 > m.baseline_f1]

    def as_json(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "seed": self.seed,
            "n_train": self.n_train,
            "n_test": self.n_test,
            "labels": [asdict(label) for label in self.labels],
            "goal": None if self.goal is None else asdict(self.goal),
        }


def split(n: int, *, seed: int, test_fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Seeded (train, test) index arrays; the test split has round(n * fraction) items, at least 1.

    Raises:
        LlcpsError: fewer than 2 trials, or a fraction outside (0, 1).
    """
    if not 0.0 < test_fraction < 1.0:
        raise LlcpsError(f"test fraction must lie in (0, 1), got {test_fraction}")
    if n < 2:
        raise LlcpsError(
            f"a held-out evaluation needs at least 2 trials, the branch has {n}",
            hint="collect trials first: llcps pretrain --n 200",
        )
    n_test = min(n - 1, max(1, round(n * test_fraction)))
    order = np.random.default_rng(seed).permutation(n)
    return np.sort(order[n_test:]), np.sort(order[:n_test])


def label_metrics(label: str, truth: np.ndarray, proba: np.ndarray, train_truth: np.ndarray) -> LabelMetrics:
    """Metrics of one bit: predictions vs truth, and the baseline fitted on train_truth."""
    frequency = float(train_truth.mean()) if len(train_truth) else 0.5
    majority = int(frequency > 0.5)
    predicted = (proba >= 0.5).astype(int)
    constant = np.full(len(truth), majority)
    return LabelMetrics(
        label=label,
        train_frequency=frequency,
        test_frequency=float(truth.mean()),
        both_classes=bool(truth.min() != truth.max()),
        accuracy=float(accuracy_score(truth, predicted)),
        f1=float(f1_score(truth, predicted, zero_division=0.0)),
        brier=float(np.mean((proba - truth) ** 2)),
        baseline_accuracy=float(accuracy_score(truth, constant)),
        baseline_f1=float(f1_score(truth, constant, zero_division=0.0)),
        baseline_brier=float(np.mean((frequency - truth) ** 2)),
    )


def evaluate(
    name: str,
    records: Sequence[TrialRecord],
    *,
    seed: int,
    test_fraction: float = 0.25,
    model_seed: int | None = None,
    changes: Mapping[int, TrialChange] | None = None,
) -> EvaluationReport:
    """Fit ``name`` on a seeded training split of ``records`` and score it on the rest.

    Args:
        name: a WORLD_MODELS name.
        records: the trials to split (e.g. a branch's visible trials).
        seed: seeds the split (and the model, without ``model_seed``).
        test_fraction: share of trials held out.
        model_seed: seed of the model (None: ``seed``).
        changes: the trials' symbolic changes by id: also score the goal-aware head.
    """
    train_index, test_index = split(len(records), seed=seed, test_fraction=test_fraction)
    train = [records[i] for i in train_index]
    test = [records[i] for i in test_index]
    model = make_world_model(name, seed if model_seed is None else model_seed).fit(train, changes)
    proba = model.predict_proba(test)
    truth, train_truth = outcome_matrix(test), outcome_matrix(train)
    labels = tuple(
        label_metrics(label, truth[:, j], proba[:, j], train_truth[:, j]) for j, label in enumerate(OUTCOME_NAMES)
    )
    goal = _goal_metrics(model, test, changes) if changes else None
    return EvaluationReport(model=name, seed=seed, n_train=len(train), n_test=len(test), labels=labels, goal=goal)


def _goal_metrics(model: Any, test: Sequence[TrialRecord], changes: Mapping[int, TrialChange]) -> GoalMetrics | None:
    examples = examples_of(test, changes)
    if not len(examples):
        return None
    p = model.goal.predict_rows(examples.features)
    y, w = examples.labels.astype(np.float64), examples.weights
    prior = model.goal.prior
    both = 0 < y.sum() < len(y)
    return GoalMetrics(
        examples=len(examples),
        positives=int(y.sum()),
        brier=float(np.average((p - y) ** 2, weights=w)),
        baseline_brier=float(np.average((prior - y) ** 2, weights=w)),
        auc=float(roc_auc_score(y, p, sample_weight=w)) if both else float("nan"),
    )
