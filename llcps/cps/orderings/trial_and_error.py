"""``trial-and-error``: Thompson sampling over candidate families, the world model as the prior.

After Cully, Clune, Tarapore and Mouret, "Robots that can adapt like animals" (Nature
521, 2015; *Intelligent Trial and Error*): a prior over what will work, from a model
learned beforehand, is updated by every trial the robot takes, and the next trial is
the one the posterior favours. Here the prior comes from the world model, and the
posterior is a Beta-Bernoulli model per *candidate family* (one action on one tuple of
arguments, all its controller settings):

- prior: ``Beta(k m, k (1 - m))`` with ``m`` the world model's largest probability
  that a candidate of the family resolves the failure
  (:func:`~llcps.cps.ranking.candidate_probability`, clipped to
  [:data:`PRIOR_FLOOR`, 1 - :data:`PRIOR_FLOOR`]) and ``k`` :data:`PRIOR_STRENGTH`
  pseudo-trials;
- choice: one draw ``theta_f ~ Beta`` per family with untried candidates (Thompson
  sampling); the family with the largest draw gives its best-ranked untried candidate;
- update: a failed trial adds one failure to its family (``beta += 1``).

The draws come from one generator seeded by the episode's seed, so the same seed and
the same trials give the same order.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Collection

import numpy as np

from llcps.cps.ranking import candidate_probability, rank_candidates
from llcps.cps.orderings.base import Exploration, Ordering

if TYPE_CHECKING:
    from llcps.domain import State

#: Pseudo-trials the world model's prediction is worth.
PRIOR_STRENGTH = 2.0
#: The prior mean stays this far from 0 and 1.
PRIOR_FLOOR = 0.02
#: Stream of the Thompson draws, apart from the other seeded draws of an episode.
_STREAM = 0x7A5C


class TrialAndError(Ordering):
    """Thompson sampling over candidate families (see the module docstring).

    Attributes:
        families: family (action, arguments) -> its candidates, best-ranked first.
        alpha, beta: the Beta posterior of each family.
    """

    name: ClassVar[str] = "trial-and-error"

    def __init__(self, exploration: Exploration) -> None:
        super().__init__(exploration)
        point = exploration.point
        ranking = rank_candidates(exploration.model, point, measure=exploration.measure, seed=exploration.seed)
        probability = candidate_probability(point, ranking)
        self.families: dict[tuple[str, tuple[str, ...]], list[int]] = {}
        for index in ranking.order:
            spec = point.candidates[index]
            self.families.setdefault((spec.action, spec.arguments), []).append(index)
        self._family_of = {i: key for key, members in self.families.items() for i in members}
        self.alpha: dict[tuple[str, tuple[str, ...]], float] = {}
        self.beta: dict[tuple[str, tuple[str, ...]], float] = {}
        for key, members in self.families.items():
            mean = float(np.clip(probability[members].max(), PRIOR_FLOOR, 1.0 - PRIOR_FLOOR))
            self.alpha[key] = PRIOR_STRENGTH * mean
            self.beta[key] = PRIOR_STRENGTH * (1.0 - mean)
        self.rng = np.random.default_rng([int(exploration.seed), _STREAM])
        self._untried = set(self.remaining)

    def choose(self) -> int:
        open_families = [key for key, members in self.families.items() if any(i in self._untried for i in members)]
        draws = self.rng.beta([self.alpha[k] for k in open_families], [self.beta[k] for k in open_families])
        family = open_families[int(np.argmax(draws))]
        return next(i for i in self.families[family] if i in self._untried)

    def exclude(self, indices: Collection[int]) -> None:
        super().exclude(indices)
        self._untried.difference_update(indices)

    def learn(self, index: int, after: State) -> None:
        self._untried.discard(index)
        self.beta[self._family_of[index]] += 1.0
