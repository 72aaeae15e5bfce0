"""``rl``: the candidates in the order of a policy trained with MaskablePPO.

The policy (:mod:`llcps.cps.policy`) is the newest one trained on the branch
(``llcps rl train``, in the Gymnasium environment ``llcps/Explore-v0``). At every
trial it sees the failure point as the environment shows it (:mod:`llcps.cps.observation`,
the world model's predictions included, the trials used counted against the budget it
was trained with) and the candidates tried so far, those taken out of its order (the
reach check's refused calls) shown as unavailable, as the environment shows them; the
untried candidate it gives the largest probability is tried next (greedy: the same trials give the same order; exact
ties go to the lower index). Needs the ``rl`` extra.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Collection

import numpy as np

from llcps.cps.ranking import rank_candidates
from llcps.cps.observation import FailureObservation
from llcps.cps.orderings.base import Exploration, Ordering
from llcps.errors import LlcpsError

if TYPE_CHECKING:
    from llcps.domain import State


class Learned(Ordering):
    """The trained policy's most probable untried candidate first."""

    name: ClassVar[str] = "rl"

    def __init__(self, exploration: Exploration) -> None:
        super().__init__(exploration)
        try:
            from llcps.cps.policy import load_stored_policy
        except ImportError as exc:
            raise LlcpsError(f"the rl ordering needs the rl extra ({exc.name} is missing)", hint="pip install 'llcps[rl]'") from None
        store, branch = exploration.store, exploration.branch
        found = load_stored_policy(store, branch) if store is not None and branch is not None else None
        if found is None:
            raise LlcpsError("no trained policy on this branch for the rl ordering", hint="train one first: llcps rl train --scenario NAME")
        self.policy, meta = found
        budget = meta.get("budget")
        self.budget = budget if isinstance(budget, int) and budget > 0 else 50
        point = exploration.point
        ranking = rank_candidates(exploration.model, point, measure=exploration.measure, seed=exploration.seed)
        self.observation = FailureObservation.of(point, ranking)
        self.tried: list[int] = []
        self.excluded: list[int] = []

    def probabilities(self) -> np.ndarray:
        """The policy's probability of each candidate row now (0 for the tried and the padding)."""
        from llcps.cps.policy import action_probabilities

        unavailable = self.tried + self.excluded
        obs = self.observation.observe(unavailable, len(self.tried), self.budget)
        return action_probabilities(self.policy, obs, self.observation.mask(unavailable))

    def choose(self) -> int:
        probs = self.probabilities()
        return int(max(self.remaining, key=lambda i: (probs[i], -i)))

    def learn(self, index: int, after: State) -> None:
        self.tried.append(index)

    def exclude(self, indices: Collection[int]) -> None:
        super().exclude(indices)
        self.excluded = sorted(set(self.excluded) | {int(i) for i in indices})
