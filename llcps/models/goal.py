"""The goal-aware head every world model carries beside Omega.

A :class:`GoalHead` learns P(a candidate changes an atom as needed) from the
(candidate, atom) examples of :mod:`llcps.models.relational`, with a learner of the
model's own kind (:class:`GoalLearner`: naive Bayes, a network, logistic regression, a
forest, or no learning at all for ``random``), and answers a :class:`GoalQuery` with
one probability per candidate and missing atom.

**Fit and update.** :meth:`GoalHead.fit` trains the learner on every stored trial with
a known change. During exploration the agent calls :meth:`GoalHead.update` after every
trial; it does not retrain the learner (a refit on tens of thousands of examples would
take many failures to move, and costs a second for some learners) but keeps
*episode evidence*: every example of the trials the learner has not seen, grouped into
families by :func:`~llcps.models.families.family_keys` (action, predicate, sign and
roles; and that with the same orientation, with the same movement magnitude; and the
motion, the action with all three settings, whatever bodies it names). Physics is deterministic and every exploration trial
starts from the same state, so the outcomes of one family's parameterizations are not
independent draws: either the family can work in this scene or it cannot. That holds
from one start state only, so the agent names it (``start``: the failure snapshot) and
only trials that started there are evidence; the plan steps K runs from the state a
trial left behind wait for the next fit. Each family
is therefore a two-way mixture: it works here with belief ``b``, and then some share
``s`` of its members changes the atom; or it does not, and none does. The share is not
known: it is Beta-distributed with mean :data:`FAMILY_SUCCESS` and strength
:data:`FAMILY_SHARE_STRENGTH` (uniform with the defaults), since in one scene every
stroke of a family may work and in another only one setting in thirty-six. The
learner's mean probability ``p`` over the family's tried members sets the prior belief
``b = min(p / FAMILY_SUCCESS, MAX_BELIEF)`` (never more than :data:`MAX_BELIEF`: the
scene is novel, and the learner may not see why a family that works elsewhere fails
here). After ``n`` failures and no success the belief is
``b m / (b m + 1 - b)`` with ``m = E[(1 - s)^n]``, and the share's mean falls to
``(a + k) / (a + c + n)`` after ``k`` successes (``a``: the prior's first parameter,
``c`` the second); a success makes the belief 1. Every member's probability is scaled
by the posterior chance that a further member works over the prior one
(:func:`family_scale`). With the defaults, for a family the learner gave 0.25, the first failure lowers its
probability to 0.44 of that, the fifth to 0.08 and the fortieth to 0.002 (a fixed share
of one half: 0.67, 0.06 and 2e-12), and each setting
(orientation, magnitude) a member shares with a failure lowers it again:
exploration moves away from what failed in every setting, then in kind; and a motion
that failed drops on the action's other bodies too, so one stroke is not tried on every
pair of bodies in turn before any other. The evidence lives for one fit: the next fit
learns from those trials anyway.

**Nothing is ruled out, and K is heard.** A learner trained on random interactions
gives a change it never saw (a push that lands an object in a container) a vanishing
probability, and such a change is what a novelty may need. The head's probability is
therefore the learner's mixed with a prior: ``(1 - e) p + e q`` with ``e`` =
:data:`NOVELTY_MIX`. ``q`` is 1 where the robot's knowledge base K claims the
candidate's action has the effect (an operator of K whose controller is the candidate's
action lists the atom among its effects, whatever the settings and preconditions:
``GoalQuery.claimed``, filled by the agent from
:meth:`~llcps.symbolic.knowledge_base.KnowledgeBase.claims`), and otherwise the base rate
``r`` of its kind of change (predicate and sign) over the training set. So an action K
believes can make the missing atom is tried early even where experience never saw it
do so, and the learner orders everything else. A family that keeps failing falls below
all untried candidates.

**Several atoms.** A candidate's score is the product of its atoms' probabilities:
the atoms are treated as independent given the candidate (:func:`joint_probability`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any, Callable, ClassVar, Mapping, Sequence

import numpy as np

from llcps.trial_records import TrialChange, TrialRecord
from llcps.models.artifact import array
from llcps.models.measures import GOAL_FLOOR
from llcps.models.families import (
    N_ACTION_SIGNS,
    N_ACTION_STRATA,
    N_STRATA,
    action_sign_of,
    action_sign_of_stratum,
    action_stratum_of,
    family_keys,
    stratum_of,
)
from llcps.models.relational import (
    CONTINUOUS_MASK,
    N_GOAL_FEATURES,
    ExampleTable,
    Examples,
    GoalQuery,
    encode_queries,
)

#: Expected share of a family's members that change the atom when the family works in a scene.
FAMILY_SUCCESS = 0.5
#: Strength (alpha + beta) of the Beta prior over that share: 2 with a mean of 0.5 is uniform.
FAMILY_SHARE_STRENGTH = 2.0
#: Most belief, before any evidence, that a family works in a novel scene.
MAX_BELIEF = 0.5
#: Share of the base rate of its kind of change mixed into every learned probability:
#: in a novel scene no change is ruled out (see the module docstring).
NOVELTY_MIX = 0.1


class GoalLearner(ABC):
    """A weighted binary classifier over encoded (candidate, atom) rows."""

    #: Name in the artifact (the model's own name).
    name: ClassVar[str]

    def __init__(self, seed: int) -> None:
        self.seed = int(seed)

    @abstractmethod
    def fit(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        """Fit on raw rows (n, d), 0/1 labels with both classes present, positive weights."""

    @abstractmethod
    def predict(self, features: np.ndarray) -> np.ndarray:
        """P(label = 1) per raw row, float64 (m,)."""

    @abstractmethod
    def export(self) -> dict[str, np.ndarray]:
        """The fitted state as plain arrays."""

    @abstractmethod
    def load(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Restore :meth:`export` output (shapes checked; may raise on bad input)."""


class StratifiedLearner(GoalLearner):
    """One sub-learner per (action, predicate, sign) stratum of the rows.

    For learners without interactions (naive Bayes, a linear model), what predicts a
    change depends on which change is asked and of which controller: a push_together
    makes things touch and never puts them in containers, and a setting that helps one
    controller make a change can hinder another (a slow, careful grasp lifts an object
    out of a container; a slow push does not tip one over). Pooled over controllers,
    such a learner would carry the settings of the controller that makes a change most
    often over to every other. Each stratum gets its own fit.

    A stratum with one class in training (a change its controller was never seen to
    make) backs off to its (action, sign) stratum: a sub-learner fitted on every change
    of that sign the controller made, whatever the predicate, says which candidates
    change the relations of the atom's bodies at all (roles, geometry, settings). The
    prediction is that probability times the stratum's change rate over its parent's;
    a stratum's rate is its weighted change rate smoothed toward its parent's rate (two
    pseudo-rows), so one never seen is its parent's. Without a back-off either, the rate alone.
    The network and the forest learn such interactions themselves and are fitted on
    all rows.
    """

    def __init__(self, seed: int, make: Callable[[int], GoalLearner]) -> None:
        super().__init__(seed)
        self.name = make(seed).name  # type: ignore[misc]
        self._make = make
        self.priors = np.full(N_ACTION_STRATA, 0.5)
        self.subs: dict[int, GoalLearner] = {}
        #: Sub-learners of the (action, sign) strata (the back-off).
        self.backoffs: dict[int, GoalLearner] = {}
        #: Per (action, predicate, sign) stratum, the change rate of its (action, sign) stratum.
        self.parents = np.full(N_ACTION_STRATA, 0.5)

    def fit(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        strata = action_stratum_of(features)
        signs = action_sign_of(features)
        self.subs = {}
        self.backoffs = {}
        rates = np.full(N_ACTION_SIGNS, 0.5)
        for c in range(N_ACTION_SIGNS):
            rows = signs == c
            y, w = labels[rows], weights[rows]
            rates[c] = (float(w @ y) + 1.0) / (float(w.sum()) + 2.0)
            if 0 < y.sum() < len(y):
                sub = self._make(self.seed)
                sub.fit(features[rows], y, w)
                self.backoffs[c] = sub
        # A stratum's rate is smoothed toward its (action, sign) stratum's rate (two
        # pseudo-rows of it), so a stratum seen on a few rows, or none, gets its parent's.
        self.parents = rates[action_sign_of_stratum(np.arange(N_ACTION_STRATA))]
        for k in range(N_ACTION_STRATA):
            rows = strata == k
            y, w = labels[rows], weights[rows]
            self.priors[k] = (float(w @ y) + 2.0 * self.parents[k]) / (float(w.sum()) + 2.0)
            if 0 < y.sum() < len(y):
                sub = self._make(self.seed)
                sub.fit(features[rows], y, w)
                self.subs[k] = sub

    def predict(self, features: np.ndarray) -> np.ndarray:
        strata = action_stratum_of(features)
        out = self.priors[strata]
        backed = np.ones(len(features), dtype=bool)
        for k, sub in self.subs.items():
            rows = strata == k
            if rows.any():
                out[rows] = sub.predict(features[rows])
                backed[rows] = False
        if self.backoffs and backed.any():
            signs = action_sign_of(features)
            for c, sub in self.backoffs.items():
                rows = backed & (signs == c)
                if rows.any():
                    ratio = np.clip(sub.predict(features[rows]), 0.0, 1.0) / self.parents[strata[rows]]
                    out[rows] = np.clip(out[rows] * ratio, 0.0, 1.0)
        return out

    def export(self) -> dict[str, np.ndarray]:
        arrays = {
            "priors": self.priors,
            "learned": np.array([k in self.subs for k in range(N_ACTION_STRATA)]),
            "backoff": np.array([c in self.backoffs for c in range(N_ACTION_SIGNS)]),
            "parents": self.parents,
        }
        for k, sub in self.subs.items():
            arrays.update({f"s{k}/{name}": value for name, value in sub.export().items()})
        for c, sub in self.backoffs.items():
            arrays.update({f"b{c}/{name}": value for name, value in sub.export().items()})
        return arrays

    def load(self, arrays: Mapping[str, np.ndarray]) -> None:
        priors = array(arrays, "priors", (N_ACTION_STRATA,))
        if np.any((priors <= 0) | (priors >= 1)):
            raise ValueError("stratum priors must lie strictly inside (0, 1)")
        parents = array(arrays, "parents", (N_ACTION_STRATA,))
        if np.any((parents <= 0) | (parents >= 1)):
            raise ValueError("parent rates must lie strictly inside (0, 1)")
        self.priors = priors.astype(np.float64)
        self.parents = parents.astype(np.float64)
        self.subs = self._load_subs(arrays, "learned", N_ACTION_STRATA, "s")
        self.backoffs = self._load_subs(arrays, "backoff", N_ACTION_SIGNS, "b")

    def _load_subs(self, arrays: Mapping[str, np.ndarray], flags: str, n: int, letter: str) -> dict[int, GoalLearner]:
        subs = {}
        for k in np.flatnonzero(array(arrays, flags, (n,), kind="b")):
            sub = self._make(self.seed)
            prefix = f"{letter}{k}/"
            sub.load({name[len(prefix) :]: v for name, v in arrays.items() if name.startswith(prefix)})
            subs[int(k)] = sub
        return subs


class Standardizer:
    """Zero mean, unit variance on the continuous columns (weighted), one-hots untouched."""

    def __init__(self) -> None:
        self.mean = np.zeros(N_GOAL_FEATURES)
        self.scale = np.ones(N_GOAL_FEATURES)

    def fit(self, features: np.ndarray, weights: np.ndarray) -> Standardizer:
        w = weights / weights.sum()
        mean = w @ features
        var = w @ (features - mean) ** 2
        self.mean = np.where(CONTINUOUS_MASK, mean, 0.0)
        scale = np.sqrt(var)
        self.scale = np.where(CONTINUOUS_MASK & (scale > 1e-9), scale, 1.0)
        return self

    def transform(self, features: np.ndarray) -> np.ndarray:
        return ((features - self.mean) / self.scale).astype(np.float32)

    def export(self, prefix: str) -> dict[str, np.ndarray]:
        return {f"{prefix}/mean": self.mean, f"{prefix}/scale": self.scale}

    def load(self, arrays: Mapping[str, np.ndarray], prefix: str) -> Standardizer:
        self.mean = array(arrays, f"{prefix}/mean", (N_GOAL_FEATURES,)).astype(np.float64)
        scale = array(arrays, f"{prefix}/scale", (N_GOAL_FEATURES,)).astype(np.float64)
        if np.any(scale <= 0):
            raise ValueError("scales must be positive")
        self.scale = scale
        return self


def family_scale(tried: int, changed: float, mean_probability: float) -> float:
    """How much a family's probabilities change after ``tried`` members of it, ``changed``
    of which changed the atom as asked (see the module docstring): the posterior
    probability that a further member changes it, over the prior one.

    A family works here with belief ``b``; if it does, the share of its members that
    change the atom is unknown, Beta-distributed with mean :data:`FAMILY_SUCCESS` and
    strength :data:`FAMILY_SHARE_STRENGTH`. A member's probability is ``b`` times the
    expected share; failures lower both.
    """
    prior = min(mean_probability / FAMILY_SUCCESS, MAX_BELIEF)
    works = FAMILY_SUCCESS * FAMILY_SHARE_STRENGTH  # Beta(works, fails) over the share
    fails = FAMILY_SHARE_STRENGTH - works
    share = (works + changed) / (FAMILY_SHARE_STRENGTH + tried)
    if changed > 0:
        belief = 1.0
    else:  # E[(1 - share)^tried] under the prior: the chance a working family failed every time
        stays = prior * math.exp(
            math.lgamma(fails + tried) - math.lgamma(fails) + math.lgamma(FAMILY_SHARE_STRENGTH) - math.lgamma(FAMILY_SHARE_STRENGTH + tried)
        )
        belief = stays / (stays + 1.0 - prior)
    return (belief * share) / (prior * FAMILY_SUCCESS)


def joint_probability(proba: np.ndarray) -> np.ndarray:
    """P(every atom changes as needed) per candidate: the product over atoms (independence)."""
    return np.prod(np.clip(proba, 0.0, 1.0), axis=1)


class GoalHead:
    """The goal-aware outcome of one world model (see the module docstring)."""

    def __init__(self, learner: GoalLearner) -> None:
        self.learner = learner
        self.prior = 0.5
        #: Weighted, Laplace-smoothed change rate per (predicate, sign) stratum.
        self.rates = np.full(N_STRATA, 0.5)
        self.learned = False
        self.n_examples = 0
        #: Largest trial id the learner was fitted on: later trials are episode evidence.
        self.watermark = 0
        self.table = ExampleTable()
        self._evidence: tuple[np.ndarray, ...] | None = None
        self._evidence_ids: set[int] = set()

    # ------------------------------------------------------------------ fitting
    def fit(self, records: Sequence[TrialRecord], changes: Mapping[int, TrialChange]) -> GoalHead:
        """Fit the learner on every record with a known change; forget episode evidence."""
        examples = self.table.encode(records, changes)
        self.n_examples = len(examples)
        self.watermark = max((r.id for r in records if r.id is not None), default=0)
        positive = float(examples.weights @ examples.labels)
        total = float(examples.weights.sum())
        self.prior = (positive + 1.0) / (total + 2.0)
        strata = stratum_of(examples.features)
        for k in range(N_STRATA):
            rows = strata == k
            w = examples.weights[rows]
            self.rates[k] = (float(w @ examples.labels[rows]) + 1.0) / (float(w.sum()) + 2.0)
        self.learned = bool(0 < examples.labels.sum() < len(examples))
        if self.learned:
            self.learner.fit(examples.features, examples.labels, examples.weights)
        self._evidence = None
        self._evidence_ids = set()
        return self

    def update(
        self, records: Sequence[TrialRecord], changes: Mapping[int, TrialChange], *, start: int | None = None
    ) -> GoalHead:
        """Take in the trials after the fit as episode evidence (the learner is not refitted).

        Args:
            start: the snapshot id the ranked candidates start from: only trials that
                started there are evidence (None: every trial after the fit). A family's
                outcomes are one mixture only from one start state; a plan step run from
                the state a trial left behind says nothing certain about that family there.
        """
        fresh = [
            r
            for r in records
            if r.id is not None
            and r.id > self.watermark
            and r.id not in self._evidence_ids
            and r.id in changes
            and (start is None or r.snapshot_id == start)
        ]
        if not fresh:
            return self
        examples = self.table.encode(fresh, changes)
        self._evidence_ids.update(r.id for r in fresh)  # type: ignore[misc]
        if not len(examples):
            return self
        keys = family_keys(examples.features)
        expected = self._base(examples.features)
        observed = examples.labels.astype(np.float64)
        parts = (*keys, observed, expected)
        if self._evidence is not None:
            parts = tuple(np.concatenate([old, new]) for old, new in zip(self._evidence, parts))
        self._evidence = parts
        return self

    # --------------------------------------------------------------- predicting
    def _base(self, features: np.ndarray, claimed: np.ndarray | None = None) -> np.ndarray:
        """The learner's probability mixed with what K claims, else its stratum's change
        rate (nothing is ruled out; see the module docstring)."""
        if not len(features):
            return np.zeros(0)
        rate = self.rates[stratum_of(features)]
        learned = np.clip(self.learner.predict(features), 0.0, 1.0) if self.learned else rate
        prior = rate if claimed is None else np.where(claimed, 1.0, rate)
        return (1.0 - NOVELTY_MIX) * learned + NOVELTY_MIX * prior

    def _corrected(self, features: np.ndarray, claimed: np.ndarray | None = None) -> np.ndarray:
        p = self._base(features, claimed)
        if self._evidence is None or not len(features):
            return p
        *ev_levels, observed, expected = self._evidence
        scale = np.ones(len(features))
        for keys, ev_keys in zip(family_keys(features), ev_levels):
            for key in np.unique(keys):
                tried = ev_keys == key
                if tried.any():
                    scale[keys == key] *= family_scale(
                        int(tried.sum()), float(observed[tried].sum()), float(expected[tried].mean())
                    )
        return np.clip(p * scale, GOAL_FLOOR, 1.0 - GOAL_FLOOR)

    def predict(self, query: GoalQuery) -> np.ndarray:
        """P(each atom changes as needed) per candidate: float64 (n_candidates, n_atoms) in [0, 1]."""
        n, k = len(query.candidates), len(query.atoms)
        if n == 0 or k == 0:
            return np.zeros((n, k))
        return self._corrected(encode_queries(query), query.claimed_rows()).reshape(n, k)

    def predict_rows(self, features: np.ndarray) -> np.ndarray:
        """P(label = 1) for encoded rows (held-out evaluation), evidence included."""
        return self._corrected(features)

    # -------------------------------------------------------------- persistence
    def export(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        arrays = {"goal/prior": np.array([self.prior]), "goal/rates": self.rates}
        if self.learned:
            arrays.update({f"goal/{k}": v for k, v in self.learner.export().items()})
        meta = {"goal_learned": self.learned, "goal_examples": self.n_examples, "goal_watermark": self.watermark}
        return arrays, meta

    def load(self, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> GoalHead:
        prior = float(array(arrays, "goal/prior", (1,))[0])
        if not 0.0 < prior < 1.0:
            raise ValueError("the goal prior must lie strictly inside (0, 1)")
        self.prior = prior
        rates = array(arrays, "goal/rates", (N_STRATA,))
        if np.any((rates <= 0) | (rates >= 1)):
            raise ValueError("the goal change rates must lie strictly inside (0, 1)")
        self.rates = rates.astype(np.float64)
        self.learned = bool(meta.get("goal_learned", False))
        self.n_examples = int(meta.get("goal_examples", 0))
        self.watermark = int(meta.get("goal_watermark", 0))
        if self.learned:
            prefix = "goal/"
            self.learner.load(
                {k[len(prefix) :]: v for k, v in arrays.items() if k.startswith(prefix) and k not in ("goal/prior", "goal/rates")}
            )
        return self


def examples_of(records: Sequence[TrialRecord], changes: Mapping[int, TrialChange]) -> Examples:
    """Every goal-aware example of ``records`` (for evaluation and tests)."""
    return ExampleTable().encode(records, changes)
