"""ORDERINGS: in which order exploration tries a failure point's candidates.

A world model predicts each candidate's outcome and a measure scores it
(:mod:`llcps.models.measures`); an *ordering* turns that into the sequence of trials an
episode runs, learning from each failed trial as it goes:

- ``ranked`` (the paper's): the measure's ranking of the untried candidates, with the
  world model updated and the candidates ranked again after every ``refit_every``
  failed trials.
- ``coverage``: random order spread evenly over the candidates: every action on every
  argument tuple once before any twice, each one's settings in turn, a pair whose trial
  changed no atom put off (no world model).
- ``hedged`` (the default): the same ranking, interleaved with ``coverage``'s order of
  the candidates; the share of trials the ranking gets is the posterior belief that the
  model knows where the resolving candidates are in this scene, never more than
  :data:`~llcps.cps.orderings.hedged.MAX_MODEL_SHARE`. A model that is wrong in a novel
  scene costs at most a bounded multiple of random order (docs/world_models.md).

- ``case-based``, ``trial-and-error``, ``uncertainty`` and ``rl``: the baselines a claim
  about model-guided exploration is measured against (docs/world_models.md): reuse of
  past solutions, Thompson sampling with the model as the prior, an ensemble's
  disagreement, and a policy trained in the Gymnasium environment (:mod:`llcps.gym`).

Entries import their module on first use, so the CLI lists the names without loading
numpy or a world model.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

from llcps.registry import Registry

if TYPE_CHECKING:
    from llcps.cps.orderings.base import Exploration, Ordering


@dataclass(frozen=True)
class OrderingEntry:
    """A registered ordering; calling it with an episode's exploration starts one."""

    name: str
    module: str
    class_name: str
    description: str

    def ordering_class(self) -> type[Ordering]:
        return getattr(importlib.import_module(self.module), self.class_name)

    def __call__(self, exploration: Exploration) -> Ordering:
        return self.ordering_class()(exploration)


def _entries(*entries: OrderingEntry) -> dict[str, OrderingEntry]:
    return {entry.name: entry for entry in entries}


#: name -> ordering, the one list of exploration orderings. Its default is ``hedged``: a
#: novel scene may be one where the model points the wrong way, and the hedge bounds what
#: that costs (at most ``2P`` trials where its random side needs ``P``). Measured leave one
#: family out on the families written after it was designed, it also explored less than
#: the ranking alone (docs/world_models.md, "Which default").
ORDERINGS: Registry[OrderingEntry] = Registry(
    "ordering",
    _entries(
        OrderingEntry(
            "ranked",
            "llcps.cps.orderings.ranked",
            "Ranked",
            "the measure's ranking, ranked again after each failed trial (the paper's)",
        ),
        OrderingEntry(
            "hedged",
            "llcps.cps.orderings.hedged",
            "Hedged",
            "the ranking interleaved with coverage's order, by the belief that the model is right here",
        ),
        OrderingEntry(
            "coverage",
            "llcps.cps.orderings.coverage",
            "Coverage",
            "random order spread evenly: every action on every argument tuple before any twice (no model)",
        ),
        OrderingEntry(
            "case-based",
            "llcps.cps.orderings.case_based",
            "CaseBased",
            "the resolving trials of the most similar past failures first, then the default",
        ),
        OrderingEntry(
            "trial-and-error",
            "llcps.cps.orderings.trial_and_error",
            "TrialAndError",
            "Thompson sampling over candidate families, the world model's prediction as the prior mean",
        ),
        OrderingEntry(
            "uncertainty",
            "llcps.cps.orderings.uncertainty",
            "Uncertainty",
            "the model's probability plus the disagreement of a bootstrap ensemble",
        ),
        OrderingEntry(
            "rl",
            "llcps.cps.orderings.learned",
            "Learned",
            "the policy trained with MaskablePPO (llcps rl train), most probable first",
        ),
    ),
    default="hedged",
)

#: The ordering of the paper's agent: the paper presets run it, so the reproduction stays
#: comparable, and so does the random order (the random model ranked), every ordering's baseline.
PAPER_ORDERING = "ranked"


def get_ordering(name: str) -> OrderingEntry:
    """The ordering called ``name``.

    Raises:
        UnknownNameError: listing the known orderings.
    """
    return ORDERINGS.get_entry(name)
