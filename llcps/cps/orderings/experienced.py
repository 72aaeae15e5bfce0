"""``experienced``: the hedge, its model side trial and error on a failure met before.

What the branch has lived through decides how the model's side of the hedge
(:class:`~llcps.cps.orderings.hedged.Hedged`) chooses:

- a failure the branch never resolved (no past case with the same failed operator, the
  same missing atoms in roles and a_f's arguments of about the same size and place,
  :func:`~llcps.cps.orderings.case_based.met_before`) is explored by the hedge as it is:
  the ranking, moved by its own failures, against random order;
- a failure the branch resolved before in a scene like this one is one the model has
  trials of its resolution for: the model's side chooses by Thompson sampling with the
  model's prediction as the prior
  (:class:`~llcps.cps.orderings.trial_and_error.TrialAndError`), which keeps to a family
  the model believes in through a failed member; random order keeps its share, so a
  model wrong even there costs at most ``2P + 1`` trials where random order needs ``P``.

A branch with no past episodes (pretraining only: the ``generalization`` preset, a
life's ``reset`` condition) explores exactly as the hedge does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Collection

from llcps.cps.orderings.base import Exploration
from llcps.cps.orderings.case_based import met_before
from llcps.cps.orderings.hedged import Hedged
from llcps.cps.orderings.trial_and_error import TrialAndError

if TYPE_CHECKING:
    from llcps.domain import State


class Experienced(Hedged):
    """:class:`Hedged`; on a failure the branch met before, its model side is
    :class:`TrialAndError` (see the module docstring).

    Attributes:
        met_before: whether the branch resolved this failure before in a like scene.
        thompson: the model side on a failure met before (None otherwise).
    """

    name: ClassVar[str] = "experienced"

    def __init__(self, exploration: Exploration) -> None:
        super().__init__(exploration)
        self.met_before = met_before(exploration)
        self.thompson = TrialAndError(exploration) if self.met_before else None

    @property
    def explored_in(self) -> str:
        return "hedged trial-and-error" if self.thompson is not None else "hedged"

    def model_choice(self) -> int:
        return self.thompson.choose() if self.thompson is not None else super().model_choice()

    def model_learn(self, index: int, after: State, own: bool) -> None:
        if self.thompson is None:
            super().model_learn(index, after, own)
        elif own:
            self.thompson.observe(index, after)
        else:
            self.thompson.exclude([index])

    def exclude(self, indices: Collection[int]) -> None:
        super().exclude(indices)
        if self.thompson is not None:
            self.thompson.exclude(indices)
