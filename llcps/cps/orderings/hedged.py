"""``hedged``: the model's ranking, hedged against the model being wrong in a novel scene.

A world model trained on other scenes may rank first, in a novel one, candidates that
can never work there (placements into a container out of reach), and its episode
evidence (:mod:`llcps.models.goal`) moves away from them only as fast as its prior lets
it. Random order knows nothing, but it is never misled. This ordering interleaves the
two:

- *the ranking*: the best untried candidate under the model and measure
  (:class:`~llcps.cps.orderings.ranked.Ranked`, updated after every failed trial);
- *random order, spread*: the next untried candidate of the order
  :mod:`~llcps.cps.orderings.coverage` gives them: the permutation of the random-order
  baseline (the ``random`` world model, which scores each candidate by a hash of the
  seed and the candidate, under the same measure and seed), re-sorted so that every
  action on every argument tuple is tried once before any twice, and each one's
  settings in turn, a pair whose trial (by either side) changed no atom put off
  (:class:`~llcps.cps.orderings.coverage.SpreadWalk`). It knows nothing of the scene
  either, but a resolving group of candidates (one action on the body in the way, in
  most of its settings) is met sooner than in the bare permutation
  (docs/world_models.md, "Why random order spread").

**The share.** Random order takes the first trial and the model the second; after each
trial the model is credited its share ``min(w, MAX_MODEL_SHARE)`` and takes the next
trial whenever its credit (one before the first trial) reaches one (random order takes
the others). Random order goes first because a novelty that many candidates resolve as
a side effect costs it one or two trials, and a model that points the wrong way would
double that; where the model points the right way, its first pick comes second. ``w``
is the posterior probability that the model points the right way in this scene,
starting from :data:`MODEL_PRIOR`. Each failed
trial of a candidate the model gave probability ``p`` of resolving the novelty, whichever
side chose it, multiplies the odds of that by ``(1 - p) / (1 - p_mean)``, ``p_mean``
being the model's mean over the untried candidates (both at most
:data:`MAX_EVIDENCE_PROBABILITY`, so one failure at most halves the odds): the chance of that failure if the
model is right, over its chance if the candidate were one of the others at random. A
model that was sure of candidates that then failed loses its share quickly; one that
expected the failures keeps it. Comparing with the model's own mean judges how well it
points in this scene, not how confident it is overall. A measure without probabilities
of resolving (the paper's four) gives no evidence: its share stays at the prior.

**The two sides stay apart.** The ranking takes in only the trials it chose: a failed
random trial does not move it (it would lower the whole family of a resolving
candidate after one unlucky member). So the model's side is ``ranked`` over the
candidates not yet tried, moved by its own failures only, and random order's side
its spread walk of the permutation, fixed when the episode starts but for the pairs
whose trials changed nothing.

**The guarantee.** Whatever the model predicts, it takes none of the first trial and at
most ``1 + MAX_MODEL_SHARE * (T - 1)`` of the first ``T``, so random order takes the
rest, in its order, skipping candidates the model already tried (which only brings a
resolving one nearer). If that order's first resolving candidate stands at position
``P``, the episode ends by the first trial ``T`` with ``T - floor(1 + MAX_MODEL_SHARE
(T - 1)) >= P``: with the default share of one half, at most ``2 P`` trials, where the
spread random order alone needs ``P``. Against the bare permutation of random order the
bound is measured, not proved: spreading the trials
meets a resolving set placed without regard to the candidates' structure at about the
same position, and a structured one sooner (:mod:`~llcps.cps.orderings.coverage`). While the
model keeps its full share (``w`` at least one half) the model's side loses at most the
same factor: the ``k``-th candidate of its side is tried by trial ``max(2, 2 k - 1)``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, ClassVar

from llcps.cps.ranking import resolve_probabilities
from llcps.cps.orderings.base import MODEL_SIDE, RANDOM_SIDE, Exploration
from llcps.cps.orderings.coverage import SpreadWalk, coverage_walk
from llcps.cps.orderings.ranked import Ranked

if TYPE_CHECKING:
    from llcps.domain import State

#: Most of the trials the model's ranking may take (the rest follow random order).
MAX_MODEL_SHARE = 0.5
#: Belief, before any trial, that the resolving candidate lies where the model says.
MODEL_PRIOR = 0.5
#: Largest probability of resolving a failed trial is counted with: no single failure
#: more than halves the odds. In a novel scene the model's probabilities are not
#: calibrated: one sure of a candidate K claims (p near 1) would otherwise lose every
#: trial to random order after one failure, whatever it knows of the rest.
MAX_EVIDENCE_PROBABILITY = 0.5


class Hedged(Ranked):
    """The ranking interleaved with a random order (see the module docstring).

    Attributes:
        picks: per trial so far, ``"model"`` or ``"random"``: which side chose it.
        beliefs: per trial so far, the belief ``w`` when it was chosen.
    """

    name: ClassVar[str] = "hedged"

    def __init__(self, exploration: Exploration) -> None:
        self.exploration = exploration
        #: Random order's side: every candidate, in the order it tries them.
        self.random = self.random_side()
        super().__init__(exploration)
        self.log_odds = math.log(MODEL_PRIOR / (1.0 - MODEL_PRIOR))
        self.credit = 1.0
        self.picks: list[str] = []
        self.beliefs: list[float] = []

    def random_side(self) -> SpreadWalk:
        """Random order's side: the walk of every candidate it tries, in turn
        (:func:`~llcps.cps.orderings.coverage.coverage_walk`)."""
        return coverage_walk(self.exploration)

    @property
    def belief(self) -> float:
        """The posterior probability that the model points the right way in this scene."""
        return 1.0 / (1.0 + math.exp(-self.log_odds))

    def choose(self) -> int:
        self.beliefs.append(self.belief)
        if self.credit >= 1.0 and self.picks:  # random order takes the first trial
            self.picks.append(MODEL_SIDE)
            return self.order[0]
        self.picks.append(RANDOM_SIDE)
        return self.random.next_untried(set(self.remaining))

    def trace(self) -> dict[str, list[Any]]:
        """``picks`` (which side chose each trial) and ``beliefs`` (the belief ``w`` then,
        to six places): the last pick of a solved episode is the side that found the
        resolution."""
        return {"picks": list(self.picks), "beliefs": [round(b, 6) for b in self.beliefs]}

    def learn(self, index: int, after: State) -> None:
        self.random.learn(index, after)  # whichever side chose it
        self.log_odds += self._evidence(index)
        chosen_by_model = self.picks[-1] == MODEL_SIDE
        if chosen_by_model:
            self.credit -= 1.0
        self.credit += min(self.belief, MAX_MODEL_SHARE)
        self.order.remove(index)
        if chosen_by_model:
            self.evidence(index, after)

    def _evidence(self, index: int) -> float:
        """The log factor a failed trial of ``index`` applies to the odds that the model
        points the right way (0 without probabilities of resolving)."""
        ranking = self.ranking
        probability = resolve_probabilities(ranking, self.exploration.point)
        if probability is None:
            return 0.0
        untried = set(self.remaining) | {index}
        given = {i: float(p) for i, p in zip(ranking.indices, probability) if i in untried}
        if index not in given or len(given) < 2:
            return 0.0
        p = min(given[index], MAX_EVIDENCE_PROBABILITY)
        mean = min(sum(given.values()) / len(given), MAX_EVIDENCE_PROBABILITY)
        return math.log1p(-p) - math.log1p(-mean)
