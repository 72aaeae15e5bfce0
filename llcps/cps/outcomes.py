"""What a plan failure asks of exploration, in Omega's terms.

The ``goal-directed`` measure prefers candidates predicted to produce the kinds of
fluent change the failed action a_f was expected to produce but did not. This module
turns the monitor's missing effects into that wish: a weight per Omega bit.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from llcps.domain import OUTCOME_NAMES, Fluent

#: The Omega stem a missing effect of each predicate asks for. ``in``/``on``/``holding``
#: are contact relations: gaining one means a new contact, losing one a lost contact.
_STEM = {
    "visible": "visibility",
    "reachable": "reachability",
    "touching": "touching",
    "in": "touching",
    "on": "touching",
    "holding": "touching",
    "near": "touching",
}


def desired_outcome(*, missing_add: Iterable[Fluent], missing_del: Iterable[Fluent]) -> np.ndarray:
    """A length-6 weight vector over OUTCOME_NAMES for the changes a failure lacked.

    Args:
        missing_add: effects a_f should have made true but did not.
        missing_del: effects a_f should have made false but did not.

    Returns:
        Non-negative weights summing to 1 (uniform over the six if nothing maps).
    """
    weights = np.zeros(len(OUTCOME_NAMES))
    for sign, atoms in (("positive", missing_add), ("negative", missing_del)):
        for atom in atoms:
            stem = _STEM.get(atom[0])
            if stem is not None:
                weights[OUTCOME_NAMES.index(f"{sign}_{stem}")] += 1.0
    total = weights.sum()
    if total == 0:
        return np.full(len(OUTCOME_NAMES), 1.0 / len(OUTCOME_NAMES))
    return weights / total
