"""What every exploration ordering is: the episode it serves and the two calls it answers."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Collection, Mapping

if TYPE_CHECKING:
    from llcps.cps.failure_point import FailurePoint
    from llcps.domain import State
    from llcps.models.base import WorldModel
    from llcps.store import Store


@dataclass(frozen=True)
class Exploration:
    """One episode's exploration, as an ordering sees it.

    Attributes:
        model: the branch's world model, fitted at the start of the episode.
        point: the failure point: its candidates, their inputs and the goal-aware query.
        measure: the measure that scores the model's predictions.
        seed: the episode's seed (exact ties, and any random draw of the ordering).
        refit_every: take the trials in and rank again after this many failed trials.
        update: takes the trials of some tried candidates (indices; None: every trial
            so far) into ``model`` as episode evidence.
        store: the experience store, for orderings that read the branch's past
            (None: they see no past).
        branch: the episode's branch in ``store``.
        episode_id: the episode's id in ``store`` (its own trials are no past).
    """

    model: WorldModel
    point: FailurePoint
    measure: str
    seed: int
    refit_every: int = 1
    update: Callable[[Collection[int] | None], None] = lambda only: None
    store: Store | None = None
    branch: str | None = None
    episode_id: int | None = None


class Ordering(ABC):
    """The order of an episode's trials, one at a time.

    The episode asks :meth:`next` for a candidate, executes it, and, when it did not
    resolve the novelty, tells :meth:`observe` what it left behind. An ordering is a
    deterministic function of the exploration and the trials observed: the same seed
    gives the same order.
    """

    name: ClassVar[str]

    def __init__(self, exploration: Exploration) -> None:
        self.exploration = exploration
        #: Candidate indices (into ``exploration.point.candidates``) not tried yet, in the default order.
        self.remaining: list[int] = list(range(len(exploration.point.candidates)))

    def next(self) -> int | None:
        """The candidate to try next (an untried index), or None when every one was tried."""
        return self.choose() if self.remaining else None

    def observe(self, index: int, after: State) -> None:
        """Candidate ``index`` was tried, did not resolve the novelty, and left ``after``."""
        self.remaining.remove(index)
        self.learn(index, after)

    @abstractmethod
    def choose(self) -> int:
        """An index from :attr:`remaining` (never empty when called)."""

    def learn(self, index: int, after: State) -> None:
        """Take a failed trial in (after it left :attr:`remaining`); nothing by default."""

    def trace(self) -> dict[str, list[Any]] | None:
        """What the ordering decided for each trial it chose, in order, kept in the
        episode's summary (``ordering_trace``); None: nothing beyond the order itself."""
        return None

    def exclude(self, indices: Collection[int]) -> None:
        """Candidates tried before this ordering took over (another ordering chose them):
        they leave :attr:`remaining` without being learned from."""
        gone = set(indices)
        self.remaining = [i for i in self.remaining if i not in gone]


#: The sides of a two-sided ordering (``hedged``): the world model's ranking, and random order.
MODEL_SIDE = "model"
RANDOM_SIDE = "random"
#: Longest name of a side of an ordering read back from a trace (``model``, ``random``).
MAX_PICK_NAME = 16


def resolving_pick(summary: Mapping[str, Any]) -> str | None:
    """Which side of the ordering chose a solved episode's last trial, read from its
    stored summary's ``ordering_trace`` (:meth:`Ordering.trace`; untrusted input): None
    without one, or when the last trial was not the ordering's pick (a candidate the arm
    would refuse, tried after every other)."""
    trace, trials = summary.get("ordering_trace"), summary.get("exploration_trials")
    picks = trace.get("picks") if isinstance(trace, Mapping) else None
    if not isinstance(picks, list) or not picks or type(trials) is not int or len(picks) != trials:
        return None
    last = picks[-1]
    return last if isinstance(last, str) and 0 < len(last) <= MAX_PICK_NAME and last.isprintable() else None
