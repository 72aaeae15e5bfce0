"""``ranked``: the measure's ranking of the untried candidates (the paper's agent)."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Collection

from llcps.cps.ranking import Ranking, rank_candidates
from llcps.cps.orderings.base import Exploration, Ordering

if TYPE_CHECKING:
    from llcps.domain import State


class Ranked(Ordering):
    """Try the best-ranked untried candidate; after every ``refit_every`` failed trials,
    take them into the world model (episode evidence) and rank the rest again.

    A failed trial that met one of K's subgoals (:class:`~llcps.cps.failure_point.Subgoal`)
    halves the trust in that subgoal's step for the next ranking. The belief that a
    contact blocked a_f is the first ranking's, before any trial
    (:func:`~llcps.cps.ranking.blocked_belief`): later rankings see a_f's own action
    lowered by the episode's failures, which are no evidence against the contact.
    """

    name: ClassVar[str] = "ranked"

    def __init__(self, exploration: Exploration) -> None:
        super().__init__(exploration)
        self.tried = 0
        #: Per subgoal of the failure point: failed trials that met it.
        self.subgoal_failures = [0] * len(exploration.point.subgoals)
        #: Failed trials that would have taken a_f's arguments off a body it met.
        self.relocation_failures = 0
        #: The failed trials (candidate indices) the ranking took in, in order.
        self.taken: list[int] = []
        #: The belief that a clearance's contact blocked a_f, fixed by the first ranking.
        self.blocked: float | None = None
        self.ranking = self.rank()
        self.blocked = self.ranking.blocked
        self.order = self.ordered(self.ranking)

    def ordered(self, ranking: Ranking) -> list[int]:
        """The order the untried candidates are tried in, from a ranking of them: the ranking's."""
        return list(ranking.order)

    def rank(self) -> Ranking:
        """The untried candidates ranked by the model and measure as they are now."""
        x = self.exploration
        return rank_candidates(
            x.model, x.point, measure=x.measure, seed=x.seed, indices=self.remaining, subgoal_failures=self.subgoal_failures,
            blocked=self.blocked, relocation_failures=self.relocation_failures,
        )

    def choose(self) -> int:
        return self.order[0]

    def exclude(self, indices: Collection[int]) -> None:
        super().exclude(indices)
        gone = set(indices)
        self.order = [i for i in self.order if i not in gone]

    def learn(self, index: int, after: State) -> None:
        self.order.remove(index)
        self.evidence(index, after)

    def evidence(self, index: int, after: State) -> None:
        """Take the failed trial of ``index`` into the ranking: count the subgoals it met
        and, every ``refit_every`` such trials, update the model and rank again."""
        self.tried += 1
        self.taken.append(index)
        for k, subgoal in enumerate(self.exploration.point.subgoals):
            self.subgoal_failures[k] += subgoal.met(after)
        self.relocation_failures += index in self.exploration.point.relocations
        if self.tried % self.exploration.refit_every == 0 and self.remaining:
            self.exploration.update(self.taken)
            self.ranking = self.rank()
            self.order = self.ordered(self.ranking)
