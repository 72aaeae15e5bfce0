"""A failure point as fixed-shape arrays: what a learned exploration policy sees.

The Gymnasium environment (:mod:`llcps.gym`) and the ``rl`` ordering build the same
observation here, so a policy trained in one ranks candidates in the other. Shapes are
fixed whatever the scene: the candidates fill the first rows of a table of
:data:`MAX_CANDIDATES` rows, in the failure point's default order, and the rows past
them are zeros with ``valid = 0``.

``failure`` (:data:`FAILURE_FEATURES` floats):
  the failed action a_f as a one-hot over Table 1's actions; how many atoms a_f left
  missing (to add, to delete) and how many subgoals K offers, each over 8 (capped at 1);
  the number of candidates over :data:`MAX_CANDIDATES`; the share of them that are
  focused (a_f's action and arguments); the trials taken so far over the budget.

``candidates`` (:data:`MAX_CANDIDATES` x :data:`CANDIDATE_FEATURES` floats), one row each:
  the Table-1 encoding of the candidate (one-hot action, orientation, shapes and colors,
  then rate, movement magnitude, volumes, vector magnitudes and unit vectors in their
  units, a missing second argument as zeros: the world models' encoding without the
  standardization, :mod:`llcps.models.features`); the share of the missing atoms
  K claims the candidate's action makes; whether it is focused; the world model's
  probability that it resolves the failure (0.5 when the measure has none); its place in
  the measure's order, 1 first down to near 0 last; whether it was tried; whether the
  row is a candidate still to try (the action mask).

No gymnasium here: numpy only (plus the world model's ranking).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Collection

import numpy as np

from llcps.domain import ACTIONS
from llcps.errors import LlcpsError
from llcps.models.features import CONTINUOUS_COLUMNS, ENCODED_FEATURE_NAMES, FeatureEncoder, encode_inputs

from llcps.cps.ranking import candidate_probability

if TYPE_CHECKING:
    from llcps.cps.failure_point import FailurePoint
    from llcps.cps.ranking import Ranking

#: Rows of the candidate table: the largest candidate space an observation holds
#: (the shipped scenes offer 467).
MAX_CANDIDATES = 512
#: Every feature lies in [-FEATURE_BOUND, FEATURE_BOUND] (a scene's lengths, in metres, are clipped there).
FEATURE_BOUND = 100.0
#: Counts in the failure features are divided by this and capped at 1.
_COUNT_SCALE = 8.0

#: Names of the failure features, in order.
FAILURE_FEATURE_NAMES: tuple[str, ...] = (
    *(f"failed_{action}" for action in ACTIONS),
    "missing_add",
    "missing_del",
    "subgoals",
    "candidates",
    "focused_share",
    "trials_used",
)
#: Names of a candidate row's columns, in order.
CANDIDATE_FEATURE_NAMES: tuple[str, ...] = (
    *ENCODED_FEATURE_NAMES,
    "claimed_share",
    "focused",
    "model_probability",
    "model_rank",
    "tried",
    "valid",
)
FAILURE_FEATURES = len(FAILURE_FEATURE_NAMES)
CANDIDATE_FEATURES = len(CANDIDATE_FEATURE_NAMES)
_TRIED = CANDIDATE_FEATURE_NAMES.index("tried")
_VALID = CANDIDATE_FEATURE_NAMES.index("valid")


def _unscaled_encoder() -> FeatureEncoder:
    """The Table-1 encoding with the continuous columns as they are (mean 0, scale 1)."""
    width = len(CONTINUOUS_COLUMNS)
    return FeatureEncoder.from_params({"mean": np.zeros(width), "scale": np.ones(width)})


def observation_space() -> Any:
    """The observation's ``gymnasium.spaces.Dict`` (loads gymnasium)."""
    from gymnasium import spaces

    return spaces.Dict(
        {
            "failure": spaces.Box(0.0, 1.0, shape=(FAILURE_FEATURES,), dtype=np.float32),
            "candidates": spaces.Box(-FEATURE_BOUND, FEATURE_BOUND, shape=(MAX_CANDIDATES, CANDIDATE_FEATURES), dtype=np.float32),
        }
    )


def action_space() -> Any:
    """One action per candidate row: ``gymnasium.spaces.Discrete(MAX_CANDIDATES)`` (loads gymnasium)."""
    from gymnasium import spaces

    return spaces.Discrete(MAX_CANDIDATES)


@dataclass
class FailureObservation:
    """The observation of one failure point; :meth:`observe` adds the trials taken so far.

    Attributes:
        base_failure: the failure features, with ``trials_used`` 0.
        base_candidates: the candidate table with nothing tried.
        n: the number of candidates.
    """

    base_failure: np.ndarray
    base_candidates: np.ndarray
    n: int

    @classmethod
    def of(cls, point: FailurePoint, ranking: Ranking) -> FailureObservation:
        """The observation of ``point`` with the world model's ``ranking`` of all its candidates.

        Raises:
            LlcpsError: more candidates than :data:`MAX_CANDIDATES`.
        """
        n = len(point.candidates)
        if n > MAX_CANDIDATES:
            raise LlcpsError(
                f"the failure point offers {n} candidates; an observation holds at most {MAX_CANDIDATES}",
                hint="use a coarser candidate grid (the scenario file's [grid])",
            )
        step = point.failure.step
        call = step.controller
        action = call.action if call is not None else step.name
        arguments = tuple(call.arguments) if call is not None else step.args
        focused = np.array([c.action == action and c.arguments == arguments for c in point.candidates], dtype=np.float32)
        missing = len(point.failure.missing_add) + len(point.failure.missing_del)
        claimed = np.array([len(c) / missing if missing else 0.0 for c in (point.claimed or [frozenset()] * n)], dtype=np.float32)
        probability = candidate_probability(point, ranking)
        place = np.empty(n)
        place[np.asarray(ranking.order, dtype=np.int64)] = 1.0 - np.arange(n) / max(n, 1)
        table = np.zeros((MAX_CANDIDATES, CANDIDATE_FEATURES), dtype=np.float32)
        if n:
            encoded = _unscaled_encoder().transform(encode_inputs(point.inputs))
            table[:n, : len(ENCODED_FEATURE_NAMES)] = np.clip(encoded, -FEATURE_BOUND, FEATURE_BOUND)
            extra = np.stack([claimed, focused, probability, place, np.zeros(n), np.ones(n)], axis=1)
            table[:n, len(ENCODED_FEATURE_NAMES) :] = extra
        failure = np.zeros(FAILURE_FEATURES, dtype=np.float32)
        if action in ACTIONS:
            failure[ACTIONS.index(action)] = 1.0
        k = len(ACTIONS)
        failure[k] = min(len(point.failure.missing_add) / _COUNT_SCALE, 1.0)
        failure[k + 1] = min(len(point.failure.missing_del) / _COUNT_SCALE, 1.0)
        failure[k + 2] = min(len(point.subgoals) / _COUNT_SCALE, 1.0)
        failure[k + 3] = n / MAX_CANDIDATES
        failure[k + 4] = float(focused.mean()) if n else 0.0
        return cls(base_failure=failure, base_candidates=table, n=n)

    def observe(self, tried: Collection[int], trials: int, budget: int) -> dict[str, np.ndarray]:
        """The observation after ``trials`` trials of a budget of ``budget``, ``tried`` the candidates tried."""
        failure = self.base_failure.copy()
        failure[-1] = min(trials / budget, 1.0) if budget else 1.0
        candidates = self.base_candidates.copy()
        rows = np.fromiter(tried, dtype=np.int64) if tried else np.empty(0, dtype=np.int64)
        candidates[rows, _TRIED] = 1.0
        candidates[rows, _VALID] = 0.0
        return {"failure": failure, "candidates": candidates}

    def mask(self, tried: Collection[int]) -> np.ndarray:
        """The action mask: True for a candidate not tried yet."""
        mask = np.zeros(MAX_CANDIDATES, dtype=bool)
        mask[: self.n] = True
        if tried:
            mask[np.fromiter(tried, dtype=np.int64)] = False
        return mask
