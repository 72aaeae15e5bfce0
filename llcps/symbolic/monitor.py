"""The execution monitor: did a plan step do what K said it would?

After each step the perceived state is compared with the step's expected effects. A
step fails when an add effect is not perceived (missing) or a delete effect is still
perceived (unexpected remaining); the failure names the action a_f and its arguments,
which is where creative problem solving starts.
"""

from __future__ import annotations

from dataclasses import dataclass

from llcps.domain import Fluent, State, format_fluent
from llcps.symbolic.lifted import GroundAction, sort_fluents


@dataclass(frozen=True)
class StepFailure:
    """A plan step whose expected effects were not perceived.

    Attributes:
        step: the failed step a_f (operator, arguments, expected effects, controller).
        missing_add: add effects that do not hold after the step.
        missing_del: delete effects that still hold after the step.
    """

    step: GroundAction
    missing_add: frozenset[Fluent]
    missing_del: frozenset[Fluent]

    @property
    def action(self) -> str:
        """The failed action a_f (the operator's name)."""
        return self.step.name

    @property
    def arguments(self) -> tuple[str, ...]:
        return self.step.args

    def describe(self) -> str:
        """One line for people: ``(push cube bucket) failed: missing (in cube bucket)``."""
        parts = []
        if self.missing_add:
            parts.append("missing " + " ".join(format_fluent(a) for a in sort_fluents(self.missing_add)))
        if self.missing_del:
            parts.append("still " + " ".join(format_fluent(a) for a in sort_fluents(self.missing_del)))
        return f"{self.step} failed: " + "; ".join(parts)


def check_step(step: GroundAction, perceived_after: State) -> StepFailure | None:
    """Compare a step's expected effects with the state perceived after executing it.

    Returns:
        None when every expected effect is perceived, else the failure.
    """
    missing_add = step.add - perceived_after
    # An atom both deleted and added ends up true (STRIPS), so only pure deletes must be gone.
    missing_del = (step.delete - step.add) & perceived_after
    if not missing_add and not missing_del:
        return None
    return StepFailure(step=step, missing_add=frozenset(missing_add), missing_del=frozenset(missing_del))
