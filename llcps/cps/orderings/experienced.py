"""``experienced``: the hedge for a failure never met, trial and error for one met before.

What the branch has lived through decides how far the world model is trusted:

- a failure the branch never resolved (no past case with the same failed operator and
  the same missing atoms in roles, :func:`~llcps.cps.orderings.case_based.met_before`)
  is a novelty the model may point the wrong way in: it is explored in
  :class:`~llcps.cps.orderings.hedged.Hedged`, which costs at most ``2P + 1`` trials
  where random order needs ``P``;
- a failure the branch resolved before (in another scene, on other entities) is one the
  model has trials of its resolution for: it is explored in
  :class:`~llcps.cps.orderings.trial_and_error.TrialAndError`, Thompson sampling with the
  model's prediction as the prior, which keeps to a family the model believes in
  through a failed member instead of handing half the trials to random order.

Measured on the ``default`` life (docs/results.md, "Every ordering as a life condition"):
on recurrences trial and error explored less than the hedge; on first encounters the
two were level. A branch with no past episodes (pretraining only: the ``generalization``
preset, a life's ``reset`` condition) explores exactly as the hedge does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Collection

from llcps.cps.orderings.base import Exploration, Ordering
from llcps.cps.orderings.case_based import met_before
from llcps.cps.orderings.hedged import Hedged
from llcps.cps.orderings.trial_and_error import TrialAndError

if TYPE_CHECKING:
    from llcps.domain import State


class Experienced(Ordering):
    """:class:`Hedged` or, for a failure the branch met before, :class:`TrialAndError`.

    Attributes:
        met_before: whether the branch resolved this failure before.
        inner: the ordering the episode is explored in.
    """

    name: ClassVar[str] = "experienced"

    def __init__(self, exploration: Exploration) -> None:
        super().__init__(exploration)
        self.met_before = met_before(exploration)
        self.inner: Ordering = (TrialAndError if self.met_before else Hedged)(exploration)

    @property
    def explored_in(self) -> str:
        return self.inner.name

    def next(self) -> int | None:
        return self.inner.next()

    def choose(self) -> int:
        return self.inner.choose()

    def observe(self, index: int, after: State) -> None:
        self.inner.observe(index, after)
        self.remaining = self.inner.remaining

    def exclude(self, indices: Collection[int]) -> None:
        self.inner.exclude(indices)
        self.remaining = self.inner.remaining
