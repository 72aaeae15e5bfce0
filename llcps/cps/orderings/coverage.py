"""``coverage``: random order, spread evenly over what the candidates do.

Random order (the ``random`` world model ranked) tries the candidates in a seeded
permutation. It knows nothing of the scene, and it may spend its first ten trials on
one action on one pair of bodies. A novelty's resolving candidates are seldom spread
evenly over the space: they share an action on particular arguments (the body in the
way moved aside, the object pushed where the arm reaches it) and often settings (a
slow rate, a long motion). An order that spreads its trials meets such a group sooner:
where one action-argument pair of ``A`` resolves with every setting, random order needs
about ``A`` trials and this order about ``(A + 1) / 2``.

**The order.** The permutation of random order, re-sorted greedily: the next candidate
is the one whose action and arguments the candidates before it met least; among those,
the one whose orientation, movement magnitude and rate (each with those arguments) they
met least, summed; among those, the permutation's first. Every action-argument pair is
tried once before any is tried twice, and each pair's settings in turn. Nothing of the
model or the scene enters: it is a function of the candidate list and the seed only
(:func:`spread`).

**Trials that changed nothing.** Walked during an episode (:class:`SpreadWalk`), a
trial that left the symbolic state as every trial finds it counts its pair met once
more (:data:`UNCHANGED_WEIGHT`): the walk comes back to a pair whose stroke moved
nothing that matters only after the pairs whose trials changed something had another
turn. A resolution changes the state, and a pair that changed nothing in one setting
is likelier to change nothing in the next: over the random-order episodes of the
library's eighteen families, 8.3 % of the pairs whose first trial changed an atom held
the resolution, 4.1 % of those whose first trial changed none (docs/results.md).

**What it guarantees.** Each step picks uniformly at random (the permutation restricted
to them) among the candidates least covered so far, so a resolving set placed without
regard to the candidates' structure is met at about random order's expected position;
one that shares an action, arguments or settings is met sooner. There is no bound
against every permutation of random order: a set chosen to sit where this order comes
last would be met later. docs/world_models.md reports it against random order leave
one family out.
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING, ClassVar, Collection, Sequence

import numpy as np

from llcps.cps.ranking import rank_candidates
from llcps.cps.orderings.base import Exploration, Ordering

if TYPE_CHECKING:
    from llcps.domain import State
    from llcps.trial_records import TrialSpec

#: The world model whose ranking is random order.
RANDOM_ORDER = "random"
#: How many more times a trial that changed no atom counts its action-argument pair met.
UNCHANGED_WEIGHT = 1


def random_order(exploration: Exploration) -> list[int]:
    """Every candidate, in the order the random-order baseline ranks them first."""
    from llcps.models.registry import WORLD_MODELS

    x = exploration
    return list(rank_candidates(WORLD_MODELS[RANDOM_ORDER](x.seed), x.point, measure=x.measure, seed=x.seed).order)


def _codes(keys: Sequence[object]) -> np.ndarray:
    """Each key's number among the distinct keys (int64)."""
    numbers: dict[object, int] = {}
    return np.array([numbers.setdefault(key, len(numbers)) for key in keys], dtype=np.int64)


class Counts:
    """How often the candidates walked so far met each action-argument pair and each
    pair's settings: what :func:`spread` sorts by."""

    def __init__(self, candidates: Sequence[TrialSpec]) -> None:
        self.pairs = _codes([(c.action, c.arguments) for c in candidates])
        self.settings = [
            _codes([(c.action, c.arguments, value(c)) for c in candidates])
            for value in (lambda c: c.params.orientation, lambda c: c.params.movement_magnitude, lambda c: c.params.rate)
        ]
        self.pair_met = np.zeros(int(self.pairs.max(initial=-1)) + 1, dtype=np.int64)
        self.setting_met = [np.zeros(int(codes.max(initial=-1)) + 1, dtype=np.int64) for codes in self.settings]

    def copy(self) -> Counts:
        twin = copy.copy(self)
        twin.pair_met = self.pair_met.copy()
        twin.setting_met = [counts.copy() for counts in self.setting_met]
        return twin

    def pick(self, left: np.ndarray) -> int:
        """The candidate of ``left`` (in the permutation's order) to walk next, counted as met."""
        met = self.pair_met[self.pairs[left]]
        least = left[met == met.min()]
        within = sum(counts[codes[least]] for codes, counts in zip(self.settings, self.setting_met))
        chosen = int(least[int(np.argmin(within))])  # argmin: the permutation's first
        self.pair_met[self.pairs[chosen]] += 1
        for codes, counts in zip(self.settings, self.setting_met):
            counts[codes[chosen]] += 1
        return chosen

    def sort(self, left: np.ndarray) -> list[int]:
        """``left`` (in the permutation's order) re-sorted greedily from these counts on."""
        order: list[int] = []
        while len(left):
            order.append(self.pick(left))
            left = left[left != order[-1]]
        return order


def spread(candidates: Sequence[TrialSpec], permutation: Sequence[int]) -> list[int]:
    """``permutation`` (candidate indices) re-sorted to cover the candidates evenly (see
    the module docstring)."""
    return Counts(candidates).sort(np.asarray(permutation, dtype=np.int64))


def coverage_walk(exploration: Exploration) -> SpreadWalk:
    """Random order spread evenly, walked from the failure point's state
    (:class:`SpreadWalk` of :func:`random_order`)."""
    x = exploration
    return SpreadWalk(x.point.candidates, random_order(x), x.point.state)


class SpreadWalk:
    """:func:`spread`'s order, walked one candidate at a time, that puts off a pair whose
    trial changed no atom: what :class:`Coverage` tries, and the hedge's random side
    (:class:`~llcps.cps.orderings.hedged.Hedged`).

    A trial that changed nothing (the symbolic state after it is ``start``, the one every
    trial starts from) counts its action-argument pair met :data:`UNCHANGED_WEIGHT` more
    times, so the walk comes back to that pair only after the pairs whose trials changed
    something have had another turn. Without such trials it walks :func:`spread`'s order.
    """

    def __init__(self, candidates: Sequence[TrialSpec], permutation: Sequence[int], start: State) -> None:
        self.counts = Counts(candidates)
        self.start = start
        self.left = np.asarray(permutation, dtype=np.int64)  # not walked yet, in the permutation's order
        #: The candidates walked so far, in turn (the ones tried before skipped, not tried).
        self.walked: list[int] = []

    def next_untried(self, untried: Collection[int]) -> int:
        """The next candidate of the walk in ``untried`` (never empty); the ones walked
        past were tried already. The walk never goes back."""
        while True:
            index = self.counts.pick(self.left)
            self.left = self.left[self.left != index]
            self.walked.append(index)
            if index in untried:
                return index

    def learn(self, index: int, after: State) -> None:
        """Candidate ``index`` was tried (by any side) and left ``after``: if it changed
        no atom, put its pair off."""
        if after == self.start:
            self.counts.pair_met[self.counts.pairs[index]] += UNCHANGED_WEIGHT

    @property
    def order(self) -> list[int]:
        """Every candidate: the ones walked, then the rest as the walk would go on if no
        further trial changed nothing."""
        return self.walked + self.counts.copy().sort(self.left)


class Coverage(Ordering):
    """Try the candidates in :func:`coverage_walk`'s order; a failed trial that changed
    no atom puts its pair off."""

    name: ClassVar[str] = "coverage"

    def __init__(self, exploration: Exploration) -> None:
        super().__init__(exploration)
        self.walk = coverage_walk(exploration)

    def choose(self) -> int:
        return self.walk.next_untried(set(self.remaining))

    def learn(self, index: int, after: State) -> None:
        self.walk.learn(index, after)
