"""The world model interface W : (a, r, nabla, X) -> Omega, and how a fitted model becomes an artifact.

Every model predicts, for each candidate trial, the probability of each of the six
Omega bits (Table 2). A fitted model serializes to an *artifact*: its arrays in the
format of :mod:`llcps.models.artifact` (no pickle), plus a JSON-able ``meta`` dict.
"""

from __future__ import annotations

import hashlib
from abc import ABC, abstractmethod
from typing import Any, ClassVar, Collection, Mapping, Sequence

import numpy as np

from llcps.domain import OUTCOME_NAMES, Fluent
from llcps.trial_records import TrialChange, TrialRecord, WorldModelInput
from llcps.errors import LlcpsError

from llcps.models.artifact import pack_arrays, unpack_arrays
from llcps.models.goal import GoalHead, GoalLearner
from llcps.models.relational import GoalQuery
from llcps.models.schedule import bins_trials

#: ``meta["format"]`` of every artifact, and the version this code writes and reads.
ARTIFACT_FORMAT = "llcps-world-model"
ARTIFACT_VERSION = 4


class WorldModel(ABC):
    """A multi-label predictor of Omega from a trial's inputs, with a goal-aware head.

    Two outcomes are learned from the same trials: the paper's Omega (Table 2), and the
    goal-aware one (:mod:`llcps.models.goal`): the probability that a candidate makes
    a failure's missing atoms hold, learned from each trial's symbolic change.

    Attributes:
        name: the registry name (descriptions live in the registry).
        seed: all randomness of fitting and predicting derives from it.
        n_trials: size of the training set of the last fit.
        bins: how many of its first trials fitted the model's bins, calibration and
            learner (a scheduled model; :mod:`llcps.models.schedule`), else ``n_trials``.
        goal: the goal-aware head.
    """

    name: ClassVar[str]
    #: Whether it fits its learner on the schedule of :mod:`llcps.models.schedule` and is
    #: brought up to a grown set between its fits by :meth:`extend`.
    scheduled: ClassVar[bool] = False
    #: Whether :meth:`extend` adds the new trials' counts to the learner (else the
    #: learner stays the fit's until the set doubles, and only rates and priors count).
    counting: ClassVar[bool] = False

    def __init__(self, seed: int) -> None:
        self.seed = int(seed)
        self.n_trials = 0
        self.bins = 0
        self.goal = GoalHead(self._goal_learner())
        #: Whether the goal-aware head takes part (fitted with ``goal=True``, the default).
        self.has_goal = True

    @abstractmethod
    def _goal_learner(self) -> GoalLearner:
        """A fresh learner of the model's own kind for the goal-aware head."""

    def fit(
        self, records: Sequence[TrialRecord], changes: Mapping[int, TrialChange] | None = None, *, goal: bool = True
    ) -> WorldModel:
        """Fit on the training set (any size, including 0), replacing earlier fits.

        Args:
            records: the trials.
            changes: their known symbolic changes by trial id (the goal-aware head
                learns from the trials that have one).
            goal: fit the goal-aware head too. A measure that ranks by Omega alone
                never reads it, and its fit costs as much as Omega's; without it
                :meth:`predict_goal` refuses.
        """
        self._fit_outcome(records)
        self.has_goal = goal
        if goal:
            self.goal.fit(records, changes or {})
        else:
            self.goal = type(self.goal)(self._goal_learner())  # unfitted: what it learned before is gone
        return self

    def can_extend(self, trials: int) -> bool:
        """Whether :meth:`extend` can bring the model up to a training set of ``trials``:
        a scheduled model whose fit's bins are those of that set (:mod:`llcps.models.schedule`)."""
        fits = self.scheduled and self.n_trials <= trials and bins_trials(trials) == self.bins
        return fits and (not self.has_goal or (self.goal.trials == self.n_trials and self.goal.bins == self.bins))

    def extend(self, records: Sequence[TrialRecord], changes: Mapping[int, TrialChange] | None = None) -> WorldModel:
        """Learn the trials after the fit's by adding their counts (a counting model's
        learner; every scheduled model's rates and priors): the model a fit on the whole
        set would give (:mod:`llcps.models.schedule`), for a few trials' work.

        Args:
            records: the trials the training set gained since the fit, in id order.
            changes: their known symbolic changes by trial id.

        Raises:
            LlcpsError: the model cannot (:meth:`can_extend`): it is not scheduled, or the
                grown set fits bins of its own.
        """
        if not self.can_extend(self.n_trials + len(records)):
            raise LlcpsError(
                f"world model {self.name!r} fitted on {self.n_trials} trials cannot count {len(records)} more",
                hint="fit it on the whole training set",
            )
        self._extend_outcome(records)
        if self.has_goal:
            self.goal.extend(records, changes or {})
        return self

    def update(
        self,
        records: Sequence[TrialRecord],
        changes: Mapping[int, TrialChange] | None = None,
        *,
        start: int | None = None,
        asked: Collection[tuple[Fluent, bool]] | None = None,
    ) -> WorldModel:
        """Bring the model up to ``records``, a training set that grew since the last fit.

        What the agent calls during exploration, where the set grows by a few trials at a
        time. Omega is refitted (a model whose fit is costly may continue from its current
        state instead: the network does); the goal-aware head takes the new trials in as
        episode evidence (:mod:`llcps.models.goal`).

        Args:
            start: the snapshot id the candidates being ranked start from. Only new
                trials that started there are episode evidence (None: every new trial);
                the others are learned at the next fit.
            asked: the atoms (with their sign) the ranked candidates are asked to
                change: a new trial's change of any other atom is no episode evidence.
        """
        self._update_outcome(records)
        if self.has_goal:
            self.goal.update(records, changes or {}, start=start, asked=asked)
        return self

    @abstractmethod
    def _fit_outcome(self, records: Sequence[TrialRecord]) -> None:
        """Fit the Omega predictor on ``records``."""

    def _update_outcome(self, records: Sequence[TrialRecord]) -> None:
        """Bring the Omega predictor up to a grown set; a full refit unless overridden."""
        self._fit_outcome(records)

    def _extend_outcome(self, records: Sequence[TrialRecord]) -> None:
        """Add the counts of more trials to the Omega predictor's (a scheduled model only)."""
        raise NotImplementedError(f"world model {self.name!r} does not count")

    @abstractmethod
    def predict_proba(self, candidates: Sequence[WorldModelInput | TrialRecord]) -> np.ndarray:
        """Predicted P(bit = 1) per candidate: float64 (n, 6) in [0, 1], OUTCOME_NAMES order."""

    def predict_goal(self, query: GoalQuery) -> np.ndarray:
        """P(each missing atom changes as needed) per candidate: (n_candidates, n_atoms) in [0, 1].

        Raises:
            LlcpsError: the model was fitted without its goal-aware head.
        """
        if not self.has_goal:
            raise LlcpsError(
                f"world model {self.name!r} was fitted without its goal-aware head",
                hint="fit it with goal=True (fit_or_load does for a measure that uses the goal)",
            )
        return self.goal.predict(query)

    @abstractmethod
    def _export(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """The fitted state as arrays and JSON-able meta (without the common keys)."""

    @classmethod
    @abstractmethod
    def _import(cls, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any], seed: int) -> WorldModel:
        """Rebuild a fitted model from :meth:`_export` output; may raise anything on bad input."""

    def to_artifact(self) -> tuple[bytes, dict[str, Any]]:
        """Serialize the fitted model to (bytes, meta) that load without executing code."""
        arrays, meta = self._export()
        if self.has_goal:
            goal_arrays, goal_meta = self.goal.export()
            arrays = {**arrays, **goal_arrays}
            meta = {**meta, **goal_meta}
        meta["goal"] = self.has_goal
        data = pack_arrays(arrays)
        common = {
            "format": ARTIFACT_FORMAT,
            "version": ARTIFACT_VERSION,
            "model": self.name,
            "seed": self.seed,
            "n_trials": self.n_trials,
            "bins_trials": self.bins,
            "outcome_names": list(OUTCOME_NAMES),
            "sha256": hashlib.sha256(data).hexdigest(),
        }
        return data, {**meta, **common}

    @classmethod
    def from_artifact(cls, artifact: bytes, meta: Mapping[str, Any], seed: int) -> WorldModel:
        """Load a model written by :meth:`to_artifact`.

        Raises:
            LlcpsError: the artifact is not an intact artifact of this model (wrong
                format or model, checksum mismatch, not an array archive, object
                arrays, unexpected shapes). Nothing in it is ever executed.
        """
        hint = "delete the stored model and refit it from the trials (it is refitted automatically when missing)"
        if not isinstance(meta, Mapping) or meta.get("format") != ARTIFACT_FORMAT:
            raise LlcpsError(f"not a {cls.name!r} world-model artifact: unknown format", hint=hint)
        if meta.get("version") != ARTIFACT_VERSION:
            raise LlcpsError(
                f"{cls.name!r} world-model artifact has version {meta.get('version')!r}; "
                f"this llcps reads version {ARTIFACT_VERSION}",
                hint=hint,
            )
        if meta.get("model") != cls.name:
            raise LlcpsError(f"artifact holds world model {meta.get('model')!r}, not {cls.name!r}", hint=hint)
        if not isinstance(artifact, (bytes, bytearray, memoryview)):
            raise LlcpsError(f"{cls.name!r} world-model artifact is not bytes", hint=hint)
        artifact = bytes(artifact)
        if hashlib.sha256(artifact).hexdigest() != meta.get("sha256"):
            raise LlcpsError(f"{cls.name!r} world-model artifact is corrupt (checksum mismatch)", hint=hint)
        try:
            arrays = unpack_arrays(artifact)
            model = cls._import({k: v for k, v in arrays.items() if not k.startswith("goal/")}, meta, seed)
            has_goal = meta.get("goal", True)  # artifacts from before the flag all hold the head
            if not isinstance(has_goal, bool):
                raise ValueError("the goal flag must be true or false")
            if has_goal:
                model.goal.load(arrays, meta)
            model.has_goal = has_goal
            model.n_trials = int(meta.get("n_trials", 0))
            model.bins = int(meta.get("bins_trials", model.n_trials))
            if not 0 <= model.bins <= model.n_trials:
                raise ValueError("a model's bins must be fitted on at most the trials it learned from")
        except LlcpsError as exc:
            raise LlcpsError(f"{cls.name!r} world-model artifact rejected: {exc.message}", hint=hint) from None
        except Exception as exc:  # noqa: BLE001 - any failure to parse means a bad artifact
            raise LlcpsError(
                f"{cls.name!r} world-model artifact rejected: {type(exc).__name__}: {exc}", hint=hint
            ) from None
        return model


def label_prior(outcomes: np.ndarray) -> np.ndarray:
    """Laplace-smoothed frequency of each Omega bit: (k + 1) / (n + 2).

    What a model predicts for a bit it cannot learn: with no trials every bit is
    0.5; a bit never (always) seen in n trials is 1/(n+2) ((n+1)/(n+2)).
    """
    return prior_of_counts(outcomes.sum(axis=0, dtype=np.float64), len(outcomes))


def prior_of_counts(sums: np.ndarray, n: int) -> np.ndarray:
    """:func:`label_prior` from its counts: per bit, the trials with it set, of ``n``."""
    return (sums + 1.0) / (n + 2.0)


def learnable_labels(outcomes: np.ndarray) -> np.ndarray:
    """Boolean mask of the bits with both classes in the training set."""
    if len(outcomes) == 0:
        return np.zeros(len(OUTCOME_NAMES), dtype=bool)
    return outcomes.min(axis=0) != outcomes.max(axis=0)
