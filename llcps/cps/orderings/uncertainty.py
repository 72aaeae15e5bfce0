"""``uncertainty``: the model's probability plus a bonus where a bootstrap ensemble disagrees.

As in active sampler learning (Kumar et al., "Practice Makes Perfect: Planning to Learn
Skill Parameter Policies", RSS 2024; the *predicators* active sampler explorer) and
bootstrapped exploration in general (Osband et al., "Deep Exploration
via Bootstrapped DQN", NeurIPS 2016): a candidate the model is unsure about is worth a
trial because it teaches the model most. :data:`MEMBERS` copies of the episode's world
model (same kind, their own seeds) are fitted on bootstrap resamples of the trials the
branch sees, once per episode; each predicts every candidate's probability of
resolving the failure (:func:`~llcps.cps.ranking.candidate_probability`). A
candidate scores

    p(candidate) + BONUS * std over the members of their probabilities,

where ``p`` is the episode's own world model, taken up to the episode's trials after
every failed trial as the ranked ordering does. Exact ties go by the seeded tie key.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

import numpy as np

from llcps.cps.ranking import candidate_probability, rank_candidates
from llcps.cps.orderings.base import Exploration, Ordering
from llcps.models.measures import get_measure, tie_break_key

if TYPE_CHECKING:
    from llcps.domain import State

#: Bootstrap members of the ensemble.
MEMBERS = 5
#: Weight of the members' disagreement (their standard deviation) in the score.
BONUS = 1.0
#: Stream of the bootstrap resamples, apart from the other seeded draws of an episode.
_STREAM = 0xB0075


class Uncertainty(Ordering):
    """Probability plus disagreement (see the module docstring).

    Attributes:
        disagreement: per candidate, the standard deviation of the members' probabilities.
        probability: per candidate, the episode model's probability, as of the last update.
    """

    name: ClassVar[str] = "uncertainty"

    def __init__(self, exploration: Exploration) -> None:
        super().__init__(exploration)
        self.disagreement = np.std(self.members(), axis=0)
        self.tie = tie_break_key(len(exploration.point.candidates), exploration.seed)
        self.taken: list[int] = []
        self._rank()

    def members(self) -> np.ndarray:
        """(MEMBERS, n): each bootstrap member's probability that each candidate resolves the failure."""
        from llcps.models import WORLD_MODELS

        x = self.exploration
        records = list(x.store.visible_trials(x.branch)) if x.store is not None and x.branch is not None else []
        changes = x.store.visible_changes(x.branch) if x.store is not None and x.branch is not None else {}
        goal = get_measure(x.measure).uses_goal
        rng = np.random.default_rng([int(x.seed), _STREAM])
        out = []
        for _ in range(MEMBERS):
            sample = [records[i] for i in rng.integers(len(records), size=len(records))] if records else []
            member = WORLD_MODELS[x.model.name](int(rng.integers(2**31))).fit(sample, changes, goal=goal)
            out.append(candidate_probability(x.point, rank_candidates(member, x.point, measure=x.measure, seed=x.seed)))
        return np.stack(out)

    def _rank(self) -> None:
        point = self.exploration.point
        ranking = rank_candidates(self.exploration.model, point, measure=self.exploration.measure, seed=self.exploration.seed)
        self.probability = candidate_probability(point, ranking)
        self.score = self.probability + BONUS * self.disagreement

    def choose(self) -> int:
        return min(self.remaining, key=lambda i: (-self.score[i], self.tie[i]))

    def learn(self, index: int, after: State) -> None:
        self.taken.append(index)
        if self.remaining and len(self.taken) % self.exploration.refit_every == 0:
            self.exploration.update(self.taken)
            self._rank()
