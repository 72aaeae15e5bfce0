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
model or the scene enters: it is a function of the candidate list and the seed only.

**What it guarantees.** Each step picks uniformly at random (the permutation restricted
to them) among the candidates least covered so far, so a resolving set placed without
regard to the candidates' structure is met at about random order's expected position;
one that shares an action, arguments or settings is met sooner. There is no bound
against every permutation of random order: a set chosen to sit where this order comes
last would be met later. docs/world_models.md reports it against random order leave
one family out.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Collection, Sequence

import numpy as np

from llcps.cps.ranking import rank_candidates
from llcps.cps.orderings.base import Exploration, Ordering

if TYPE_CHECKING:
    from llcps.trial_records import TrialSpec

#: The world model whose ranking is random order.
RANDOM_ORDER = "random"


def random_order(exploration: Exploration) -> list[int]:
    """Every candidate, in the order the random-order baseline ranks them first."""
    from llcps.models.registry import WORLD_MODELS

    x = exploration
    return list(rank_candidates(WORLD_MODELS[RANDOM_ORDER](x.seed), x.point, measure=x.measure, seed=x.seed).order)


def _codes(keys: Sequence[object]) -> np.ndarray:
    """Each key's number among the distinct keys (int64)."""
    numbers: dict[object, int] = {}
    return np.array([numbers.setdefault(key, len(numbers)) for key in keys], dtype=np.int64)


def spread(candidates: Sequence[TrialSpec], permutation: Sequence[int]) -> list[int]:
    """``permutation`` (candidate indices) re-sorted to cover the candidates evenly (see
    the module docstring)."""
    pairs = _codes([(c.action, c.arguments) for c in candidates])
    settings = [
        _codes([(c.action, c.arguments, value(c)) for c in candidates])
        for value in (lambda c: c.params.orientation, lambda c: c.params.movement_magnitude, lambda c: c.params.rate)
    ]
    pair_met = np.zeros(int(pairs.max(initial=-1)) + 1, dtype=np.int64)
    setting_met = [np.zeros(int(codes.max(initial=-1)) + 1, dtype=np.int64) for codes in settings]
    left = np.asarray(permutation, dtype=np.int64)  # untried, in the permutation's order
    order: list[int] = []
    while len(left):
        met = pair_met[pairs[left]]
        least = left[met == met.min()]
        within = sum(counts[codes[least]] for codes, counts in zip(settings, setting_met))
        chosen = int(least[int(np.argmin(within))])  # argmin: the permutation's first
        order.append(chosen)
        pair_met[pairs[chosen]] += 1
        for codes, counts in zip(settings, setting_met):
            counts[codes[chosen]] += 1
        left = left[left != chosen]
    return order


def coverage_order(exploration: Exploration) -> list[int]:
    """Every candidate, random order spread evenly (:func:`spread` of :func:`random_order`)."""
    return spread(exploration.point.candidates, random_order(exploration))


class FixedOrder:
    """Every candidate in an order fixed when the episode starts, walked once: what
    :class:`Coverage` tries, and the hedge's random side
    (:class:`~llcps.cps.orderings.hedged.Hedged`)."""

    def __init__(self, order: list[int]) -> None:
        #: Candidate indices, in the order they are tried.
        self.order = order
        self._cursor = 0

    def next_untried(self, untried: Collection[int]) -> int:
        """The first candidate of the order in ``untried`` (never empty). A candidate once
        tried stays tried, so the walk never goes back."""
        while self.order[self._cursor] not in untried:
            self._cursor += 1
        return self.order[self._cursor]


class Coverage(Ordering):
    """Try the candidates in :func:`coverage_order`; a failed trial changes nothing."""

    name: ClassVar[str] = "coverage"

    def __init__(self, exploration: Exploration) -> None:
        super().__init__(exploration)
        self.walk = FixedOrder(coverage_order(exploration))

    def choose(self) -> int:
        return self.walk.next_untried(set(self.remaining))
