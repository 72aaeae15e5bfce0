"""MEASURES: how a world model's predictions become an exploration order.

Each measure scores a candidate from its predicted Omega probabilities (paper,
"Measures"); :func:`rank` orders candidates best-first and breaks exact ties with a
seeded random key, so the order is a deterministic function of (predictions, seed).

- ``least-destructive``: smallest P(negative reachability).
- ``most-changes``: largest sum of all six probabilities.
- ``most-positive-changes``: largest P(+visibility) + P(+reachability) + P(+touching).
- ``least-negative-changes``: smallest P(-visibility) + P(-reachability) + P(-touching).
- ``goal-directed`` (ours): largest predicted probability that the failure's missing
  atoms all change as needed: the product over atoms of the goal-aware head's
  probabilities (``goal``, one column per missing atom; :mod:`llcps.models.goal`),
  ranked by its logarithm. (A caller may pass one column instead: the probability that
  a candidate resolves the failure by any way it knows of; the agent passes the missing
  atoms and K's subgoals combined, docs/world_models.md.) A caller without atom
  predictions may pass ``desired``
  instead, weights over Omega's bits for the kinds of change the failed action lacked
  (``llcps.cps.outcomes.desired_outcome``), ranked by ``sum_k desired[k] * P(bit k)``;
  with neither it falls back to ``most-positive-changes``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from llcps.domain import OUTCOME_NAMES
from llcps.errors import LlcpsError
from llcps.registry import Registry

if TYPE_CHECKING:
    import numpy as np

# numpy is imported inside the functions that compute: MEASURES, the one list of measure
# names, stays light for the CLI's option choices.

_POSITIVE = tuple(name for name in OUTCOME_NAMES if name.startswith("positive_"))
_NEGATIVE = tuple(name for name in OUTCOME_NAMES if name.startswith("negative_"))


@dataclass(frozen=True)
class Measure:
    """A ranking measure: a sum over some Omega bits, to maximize or minimize.

    Attributes:
        name: registry name.
        description: one line for help texts.
        bits: the Omega bits whose predicted probabilities are summed.
        maximize: True when a larger sum ranks first.
        uses_desired: True when the agent's ``desired`` weights replace ``bits``.
        uses_goal: True when the goal-aware atom probabilities, if given, are the score.
    """

    name: str
    description: str
    bits: tuple[str, ...]
    maximize: bool
    uses_desired: bool = False
    uses_goal: bool = False

    def score(self, proba: np.ndarray, desired: np.ndarray | None = None, goal: np.ndarray | None = None) -> np.ndarray:
        """Higher is better: the (signed) sum this measure ranks by.

        Args:
            proba: (n, 6) predicted probabilities in OUTCOME_NAMES order.
            desired: length-6 non-negative weights (goal-directed only).
            goal: (n, k) probabilities of the k missing atoms (goal-directed only); the
                score is the log of their product.
        """
        proba = check_proba(proba)
        if self.uses_goal and goal is not None:
            return goal_score(goal, len(proba))
        weights = _desired_weights(desired) if self.uses_desired else None
        if weights is not None:
            total = (proba * weights).sum(axis=1)
        else:
            total = proba[:, [OUTCOME_NAMES.index(bit) for bit in self.bits]].sum(axis=1)
        return total if self.maximize else -total


def _entries(*measures: Measure) -> dict[str, Measure]:
    return {measure.name: measure for measure in measures}


#: name -> measure, the one list of ranking measures; its default is ``goal-directed``.
MEASURES: Registry[Measure] = Registry(
    "measure",
    _entries(
        Measure("least-destructive", "smallest P(negative reachability) first", ("negative_reachability",), False),
        Measure("most-changes", "largest sum of all six predicted changes first", OUTCOME_NAMES, True),
        Measure("most-positive-changes", "largest sum of the three positive changes first", _POSITIVE, True),
        Measure("least-negative-changes", "smallest sum of the three negative changes first", _NEGATIVE, False),
        Measure(
            "goal-directed",
            "largest predicted probability that the failure's missing atoms all change as needed",
            _POSITIVE,
            True,
            uses_desired=True,
            uses_goal=True,
        ),
    ),
    default="goal-directed",
)

#: The paper's four measures, in the order of its Figure 2 (``goal-directed`` is this project's addition).
PAPER_MEASURES: tuple[str, ...] = (
    "least-destructive",
    "most-positive-changes",
    "least-negative-changes",
    "most-changes",
)


def get_measure(name: str) -> Measure:
    """The measure called ``name``.

    Raises:
        UnknownNameError: listing the known measures.
    """
    return MEASURES.get_entry(name)


def check_proba(proba: np.ndarray) -> np.ndarray:
    """Validate predicted probabilities: float (n, 6), finite, within [0, 1]."""
    import numpy as np

    proba = np.asarray(proba, dtype=np.float64)
    if proba.ndim != 2 or proba.shape[1] != len(OUTCOME_NAMES):
        raise LlcpsError(f"predictions must have shape (n, {len(OUTCOME_NAMES)}), got {proba.shape}")
    if not np.all(np.isfinite(proba)) or np.any((proba < 0) | (proba > 1)):
        raise LlcpsError("predictions must be finite probabilities in [0, 1]")
    return proba


def _desired_weights(desired: np.ndarray | None) -> np.ndarray | None:
    """Validated goal-directed weights, or None to fall back to the default bits."""
    import numpy as np

    if desired is None:
        return None
    weights = np.asarray(desired, dtype=np.float64)
    if weights.shape != (len(OUTCOME_NAMES),) or not np.all(np.isfinite(weights)) or np.any(weights < 0):
        raise LlcpsError(
            f"goal-directed weights must be {len(OUTCOME_NAMES)} finite non-negative numbers, got {desired!r}",
            hint=f"one weight per Omega bit: {', '.join(OUTCOME_NAMES)}",
        )
    return weights if weights.any() else None


#: Atom probabilities are floored here before their logarithm (a zero would tie every such
#: candidate); the goal-aware head keeps its predictions inside [GOAL_FLOOR, 1 - GOAL_FLOOR].
GOAL_FLOOR = 1e-12


def goal_score(goal: np.ndarray, n: int) -> np.ndarray:
    """log of the product of each candidate's missing-atom probabilities.

    Raises:
        LlcpsError: not an (n, k) array of finite probabilities.
    """
    import numpy as np

    goal = np.asarray(goal, dtype=np.float64)
    if goal.ndim != 2 or goal.shape[0] != n:
        raise LlcpsError(f"goal predictions must have shape ({n}, k), got {goal.shape}")
    if not np.all(np.isfinite(goal)) or np.any((goal < 0) | (goal > 1)):
        raise LlcpsError("goal predictions must be finite probabilities in [0, 1]")
    return np.log(np.maximum(goal, GOAL_FLOOR)).sum(axis=1)


def tie_break_key(n: int, seed: int) -> np.ndarray:
    """A seeded random permutation of ``range(n)``: the order among exact ties."""
    import numpy as np

    return np.random.default_rng(seed).permutation(n)


def rank(
    proba: np.ndarray,
    measure: str,
    *,
    seed: int,
    desired: np.ndarray | None = None,
    goal: np.ndarray | None = None,
) -> np.ndarray:
    """Candidate indices, best first, under ``measure``.

    Args:
        proba: (n, 6) predicted probabilities, one row per candidate.
        measure: a name in MEASURES.
        seed: orders exact ties (same seed, same order; another seed may differ).
        desired: goal-directed weights over OUTCOME_NAMES (ignored by other measures).
        goal: (n, k) predicted probabilities of the failure's k missing atoms
            (goal-directed ranks by their product; ignored by other measures).

    Returns:
        An int64 permutation of ``range(n)``.
    """
    import numpy as np

    score = get_measure(measure).score(proba, desired, goal)
    return np.lexsort((tie_break_key(len(score), seed), -score))
