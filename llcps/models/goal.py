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
pair of bodies in turn before any other. A success counts only on an atom the candidates
are asked to change (``asked``): that a family made two other bodies touch does not say
it can make the pair the novelty stopped touch. The evidence lives for one fit: the next
fit learns from those trials anyway.

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
from typing import Any, Callable, ClassVar, Collection, Mapping, Sequence

import numpy as np

from llcps.domain import Fluent, fluent
from llcps.trial_records import TrialChange, TrialRecord
from llcps.training import TrainingSet
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
from llcps.models.schedule import bins_trials
from llcps.models.relational import (
    CONTINUOUS_MASK,
    N_GOAL_FEATURES,
    ExampleTable,
    Examples,
    GoalQuery,
    encode_queries,
    trial_examples,
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
    #: Whether it is fitted on the schedule of :mod:`llcps.models.schedule`, and whether
    #: it then learns more rows by adding their counts (:meth:`extend`).
    scheduled: ClassVar[bool] = False
    counting: ClassVar[bool] = False

    def __init__(self, seed: int) -> None:
        self.seed = int(seed)

    @abstractmethod
    def fit(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        """Fit on raw rows (n, d), 0/1 labels with both classes present, positive weights."""

    def extend(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        """Learn more rows by adding their counts to the fit's (a :attr:`counting` learner);
        a scheduled learner that does not count stays the fit's until the set doubles."""
        if not self.scheduled:
            raise NotImplementedError(f"the {self.name} goal learner is not scheduled")

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
        made = make(seed)
        self.name = made.name  # type: ignore[misc]
        self.scheduled = made.scheduled  # type: ignore[misc]
        self.counting = made.counting  # type: ignore[misc]
        self._make = make
        self.priors = np.full(N_ACTION_STRATA, 0.5)
        self.subs: dict[int, GoalLearner] = {}
        #: Sub-learners of the (action, sign) strata (the back-off).
        self.backoffs: dict[int, GoalLearner] = {}
        #: Per (action, predicate, sign) stratum, the change rate of its (action, sign) stratum.
        self.parents = np.full(N_ACTION_STRATA, 0.5)
        #: Weighted changes and weighted rows, per (action, sign) and per (action, predicate, sign) stratum.
        self.sign_sums = np.zeros((N_ACTION_SIGNS, 2))
        self.stratum_sums = np.zeros((N_ACTION_STRATA, 2))

    def fit(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        strata = action_stratum_of(features)
        signs = action_sign_of(features)
        self.subs = {}
        self.backoffs = {}
        self.sign_sums = np.zeros((N_ACTION_SIGNS, 2))
        for c in range(N_ACTION_SIGNS):
            rows = signs == c
            y, w = labels[rows], weights[rows]
            self.sign_sums[c] = (float(w @ y), float(w.sum()))
            if 0 < y.sum() < len(y):
                sub = self._make(self.seed)
                sub.fit(features[rows], y, w)
                self.backoffs[c] = sub
        self.stratum_sums = np.zeros((N_ACTION_STRATA, 2))
        for k in range(N_ACTION_STRATA):
            rows = strata == k
            y, w = labels[rows], weights[rows]
            self.stratum_sums[k] = (float(w @ y), float(w.sum()))
            if 0 < y.sum() < len(y):
                sub = self._make(self.seed)
                sub.fit(features[rows], y, w)
                self.subs[k] = sub
        self._rates()

    def extend(self, features: np.ndarray, labels: np.ndarray, weights: np.ndarray) -> None:
        """Add more rows: to the strata's sums, and (counting learners) to the
        sub-learners of their strata (a stratum without one stays without: which strata
        learn is the fit's)."""
        if not len(labels):
            return
        strata = action_stratum_of(features)
        signs = action_sign_of(features)
        changed = weights * labels
        self.sign_sums = self.sign_sums + np.stack(
            [np.bincount(signs, changed, N_ACTION_SIGNS), np.bincount(signs, weights, N_ACTION_SIGNS)], axis=1
        )
        self.stratum_sums = self.stratum_sums + np.stack(
            [np.bincount(strata, changed, N_ACTION_STRATA), np.bincount(strata, weights, N_ACTION_STRATA)], axis=1
        )
        for groups, subs in ((strata, self.subs), (signs, self.backoffs)) if self.counting else ():
            for k, sub in subs.items():
                rows = groups == k
                if rows.any():
                    sub.extend(features[rows], labels[rows], weights[rows])
        self._rates()

    def _rates(self) -> None:
        """The change rates of the strata's sums. A stratum's rate is smoothed toward its
        (action, sign) stratum's rate (two pseudo-rows of it), so a stratum seen on a few
        rows, or none, gets its parent's."""
        rates = (self.sign_sums[:, 0] + 1.0) / (self.sign_sums[:, 1] + 2.0)
        self.parents = rates[action_sign_of_stratum(np.arange(N_ACTION_STRATA))]
        self.priors = (self.stratum_sums[:, 0] + 2.0 * self.parents) / (self.stratum_sums[:, 1] + 2.0)

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
            "sign_sums": self.sign_sums,
            "stratum_sums": self.stratum_sums,
            "learned": np.array([k in self.subs for k in range(N_ACTION_STRATA)]),
            "backoff": np.array([c in self.backoffs for c in range(N_ACTION_SIGNS)]),
        }
        for k, sub in self.subs.items():
            arrays.update({f"s{k}/{name}": value for name, value in sub.export().items()})
        for c, sub in self.backoffs.items():
            arrays.update({f"b{c}/{name}": value for name, value in sub.export().items()})
        return arrays

    def load(self, arrays: Mapping[str, np.ndarray]) -> None:
        self.sign_sums = _sums(arrays, "sign_sums", N_ACTION_SIGNS)
        self.stratum_sums = _sums(arrays, "stratum_sums", N_ACTION_STRATA)
        self._rates()
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


def _sums(arrays: Mapping[str, np.ndarray], key: str, n: int) -> np.ndarray:
    """Stored (weighted changes, weighted rows) of ``n`` strata, checked: neither negative,
    and no more changes than rows."""
    sums = array(arrays, key, (n, 2)).astype(np.float64)
    if np.any(sums < 0) or np.any(sums[:, 0] > sums[:, 1] * (1 + 1e-9)):
        raise ValueError(f"{key}: weighted changes and rows must be non-negative, with no more changes than rows")
    return sums


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
        #: Weighted changes and weighted examples, in all and per (predicate, sign) stratum.
        self.totals = np.zeros(2)
        self.rate_sums = np.zeros((N_STRATA, 2))
        self.learned = False
        self.n_examples = 0
        #: Trials learned from, and how many of the first of them fitted the learner's bins
        #: (:mod:`llcps.models.schedule`; the rest were counted).
        self.trials = 0
        self.bins = 0
        #: Largest trial id the learner was fitted on: later trials are episode evidence.
        self.watermark = 0
        self.table = ExampleTable()
        self._evidence: tuple[np.ndarray, ...] | None = None
        self._evidence_ids: set[int] = set()

    # ------------------------------------------------------------------ fitting
    def fit(self, records: Sequence[TrialRecord], changes: Mapping[int, TrialChange]) -> GoalHead:
        """Fit the learner on every record with a known change; forget episode evidence.

        A scheduled learner fits on the first :func:`~llcps.models.schedule.bins_trials`
        records and the rest are counted (:meth:`extend`); any other learner fits on all of them.
        """
        bins = bins_trials(len(records)) if self.learner.scheduled else len(records)
        examples = self.table.encode(records[:bins], changes)
        self.n_examples = len(examples)
        self.trials = self.bins = bins
        self.watermark = max((r.id for r in records[:bins] if r.id is not None), default=0)
        self.totals = np.array([float(examples.weights @ examples.labels), float(examples.weights.sum())])
        strata = stratum_of(examples.features)
        self.rate_sums = np.zeros((N_STRATA, 2))
        for k in range(N_STRATA):
            rows = strata == k
            w = examples.weights[rows]
            self.rate_sums[k] = (float(w @ examples.labels[rows]), float(w.sum()))
        self._rates()
        self.learned = bool(0 < examples.labels.sum() < len(examples))
        if self.learned:
            self.learner.fit(examples.features, examples.labels, examples.weights)
        self._evidence = None
        self._evidence_ids = set()
        if bins < len(records):
            self.extend(records[bins:], changes)
        return self

    def extend(self, records: Sequence[TrialRecord], changes: Mapping[int, TrialChange]) -> GoalHead:
        """Learn trials after the fit's by adding their counts (the rates, and a counting
        learner's counts; the bins and calibration stay the fit's: :mod:`llcps.models.schedule`);
        forget episode evidence.

        Raises:
            NotImplementedError: the learner is not scheduled.
        """
        examples = self.table.encode(records, changes)
        self.trials += len(records)
        self.watermark = max((r.id for r in records if r.id is not None), default=self.watermark)
        if len(examples):
            w, y = examples.weights, examples.labels
            self.n_examples += len(examples)
            self.totals = self.totals + np.array([float(w @ y), float(w.sum())])
            strata = stratum_of(examples.features)
            self.rate_sums = self.rate_sums + np.stack(
                [np.bincount(strata, w * y, N_STRATA), np.bincount(strata, w, N_STRATA)], axis=1
            )
            self._rates()
            if self.learned:
                self.learner.extend(examples.features, y, w)
        self._evidence = None
        self._evidence_ids = set()
        return self

    def _rates(self) -> None:
        """The Laplace-smoothed change rates of the sums: in all, and per stratum."""
        self.prior = (self.totals[0] + 1.0) / (self.totals[1] + 2.0)
        self.rates = (self.rate_sums[:, 0] + 1.0) / (self.rate_sums[:, 1] + 2.0)

    def update(
        self,
        records: Sequence[TrialRecord],
        changes: Mapping[int, TrialChange],
        *,
        start: int | None = None,
        asked: Collection[tuple[Fluent, bool]] | None = None,
    ) -> GoalHead:
        """Take in the trials after the fit as episode evidence (the learner is not refitted).

        Args:
            start: the snapshot id the ranked candidates start from: only trials that
                started there are evidence (None: every trial after the fit). A family's
                outcomes are one mixture only from one start state; a plan step run from
                the state a trial left behind says nothing certain about that family there.
            asked: the atoms (with their sign) the ranked candidates are asked to change
                (None: any). A trial's change of another atom is no evidence: that a
                family made two other bodies touch does not say it can make the bodies
                the novelty stopped touch. Its failures still are (a motion that failed
                drops on the action's other bodies).
        """
        # the trials after the fit: a training set's base (up to its watermark) is older
        after_fit = records.tail if isinstance(records, TrainingSet) and records.watermark <= self.watermark else records
        fresh = [
            r
            for r in after_fit
            if r.id is not None
            and r.id > self.watermark
            and r.id not in self._evidence_ids
            and r.id in changes
            and (start is None or r.snapshot_id == start)
        ]
        if not fresh:
            return self
        if asked is None:
            examples = self.table.encode(fresh, changes)
        else:
            spelled = {(fluent(*atom), add) for atom, add in asked}
            examples = Examples.concatenate([trial_examples(r, changes[r.id], asked=spelled) for r in fresh])  # type: ignore[index]
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
        arrays = {"goal/totals": self.totals.reshape(1, 2), "goal/rate_sums": self.rate_sums}
        if self.learned:
            arrays.update({f"goal/{k}": v for k, v in self.learner.export().items()})
        meta = {
            "goal_learned": self.learned,
            "goal_examples": self.n_examples,
            "goal_watermark": self.watermark,
            "goal_trials": self.trials,
            "goal_bins": self.bins,
        }
        return arrays, meta

    def load(self, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> GoalHead:
        self.totals = _sums(arrays, "goal/totals", 1).reshape(2)
        self.rate_sums = _sums(arrays, "goal/rate_sums", N_STRATA)
        self._rates()
        self.learned = bool(meta.get("goal_learned", False))
        self.n_examples = int(meta.get("goal_examples", 0))
        self.watermark = int(meta.get("goal_watermark", 0))
        self.trials = int(meta.get("goal_trials", 0))
        self.bins = int(meta.get("goal_bins", 0))
        if not 0 <= self.bins <= self.trials:
            raise ValueError("the goal head's bins must be fitted on at most the trials it learned from")
        if self.learned:
            prefix = "goal/"
            own = ("goal/totals", "goal/rate_sums")
            self.learner.load({k[len(prefix) :]: v for k, v in arrays.items() if k.startswith(prefix) and k not in own})
        return self


def examples_of(records: Sequence[TrialRecord], changes: Mapping[int, TrialChange]) -> Examples:
    """Every goal-aware example of ``records`` (for evaluation and tests)."""
    return ExampleTable().encode(records, changes)
