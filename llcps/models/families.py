"""How encoded goal rows are grouped (rows from :mod:`llcps.models.relational`).

- *Families* (:func:`family_keys`): (candidate, atom) pairs that share what matters
  physically, the evidence unit of an episode (:mod:`llcps.models.goal`).
- *Strata*: the kind of change a row asks for, (predicate, sign), alone or with the
  controller asked (:func:`stratum_of`, :func:`action_stratum_of`, :func:`action_sign_of`),
  by which the learners split their rows.
"""

from __future__ import annotations

import numpy as np

from llcps.domain import ACTIONS, ORIENTATIONS, PREDICATES
from llcps.models.relational import FEATURE_INDEX, ROLES, SECOND_ROLES, onehot

#: The columns that say which change is asked of which controller: (action, predicate, sign).
_KIND_COLUMNS: tuple[str, ...] = onehot("action", ACTIONS) + onehot("predicate", PREDICATES) + ("add",)
#: Columns of the evidence keys: what makes two (candidate, atom) pairs one *family*,
#: and the one-hot setting that narrows it (the orientation).
FAMILY_COLUMNS: tuple[tuple[str, ...], ...] = (
    _KIND_COLUMNS + onehot("role1", ROLES) + onehot("role2", SECOND_ROLES),
    onehot("orientation", ORIENTATIONS),
)


def family_keys(features: np.ndarray) -> tuple[np.ndarray, ...]:
    """Four family keys per row: (action, predicate, sign, roles); that and the
    orientation; that and the movement magnitude; and the motion itself, (action,
    predicate, sign) with all three settings, whatever the roles.

    No key groups by the rate alone: a leave-one-family-out run with and without it
    (docs/results.md) measured no difference (geometric mean 0.42 with it, 0.43
    without, the largest family moving 0.07), so the simpler grouping stays.

    Within one episode, pairs of a family share what matters physically: a family the
    robot keeps failing with drops, and so, once more for each setting it shares with
    a failure, does each of its parameterizations: exploration moves away from what
    failed in every setting (see :mod:`llcps.models.goal`). The last key carries a
    failed motion over to the action's other bodies: the same stroke with the same
    settings from the same start state tends to do the same thing whichever of the
    scene's bodies it names.
    """
    coarse_cols = [FEATURE_INDEX[c] for c in FAMILY_COLUMNS[0]]
    orientation_cols = [FEATURE_INDEX[c] for c in FAMILY_COLUMNS[1]]
    bits = features[:, coarse_cols] > 0.5
    coarse = (bits @ (1 << np.arange(len(coarse_cols), dtype=np.int64))).astype(np.int64)
    kind = (bits[:, : len(_KIND_COLUMNS)] @ (1 << np.arange(len(_KIND_COLUMNS), dtype=np.int64))).astype(np.int64)
    orientation = (features[:, orientation_cols] > 0.5) @ np.arange(1, len(orientation_cols) + 1, dtype=np.int64)
    magnitude = np.round(features[:, FEATURE_INDEX["movement_magnitude"]] * 1e4).astype(np.int64)  # 0.1 mm steps
    rate = np.round(features[:, FEATURE_INDEX["rate"]] * 1e4).astype(np.int64)  # 0.1 mm/s steps
    motion = ((kind * (len(orientation_cols) + 1) + orientation) * 100_003 + magnitude) * 100_003 + rate
    return (
        coarse,
        coarse * (len(orientation_cols) + 1) + orientation,
        coarse * 100_003 + magnitude,
        motion,
    )


#: (predicate, sign) strata of the rows: what kind of change is asked.
N_STRATA = 2 * len(PREDICATES)
_PREDICATE_COLUMNS = [FEATURE_INDEX[f"predicate={p}"] for p in PREDICATES]


def stratum_of(features: np.ndarray) -> np.ndarray:
    """Each row's (predicate, sign) stratum: ``2 * predicate index + add``."""
    predicate = np.argmax(features[:, _PREDICATE_COLUMNS], axis=1)
    return (2 * predicate + (features[:, FEATURE_INDEX["add"]] > 0.5)).astype(np.int64)


#: (action, predicate, sign) strata of the rows: which change is asked of which controller.
N_ACTION_STRATA = len(ACTIONS) * N_STRATA
_ACTION_COLUMNS = [FEATURE_INDEX[f"action={a}"] for a in ACTIONS]


def action_stratum_of(features: np.ndarray) -> np.ndarray:
    """Each row's (action, predicate, sign) stratum: ``N_STRATA * action index + stratum_of``."""
    action = np.argmax(features[:, _ACTION_COLUMNS], axis=1)
    return (N_STRATA * action + stratum_of(features)).astype(np.int64)


#: (action, sign) strata: which kind of change (adding or deleting any atom) of which controller.
N_ACTION_SIGNS = 2 * len(ACTIONS)


def action_sign_of(features: np.ndarray) -> np.ndarray:
    """Each row's (action, sign) stratum: ``2 * action index + add``."""
    action = np.argmax(features[:, _ACTION_COLUMNS], axis=1)
    return (2 * action + (features[:, FEATURE_INDEX["add"]] > 0.5)).astype(np.int64)


def action_sign_of_stratum(strata: np.ndarray) -> np.ndarray:
    """The (action, sign) stratum of each (action, predicate, sign) stratum: what
    :func:`action_sign_of` gives for a row whose :func:`action_stratum_of` is ``strata``."""
    strata = np.asarray(strata, dtype=np.int64)
    return 2 * (strata // N_STRATA) + strata % 2
