"""A scenario's task T as the robot perceives it when an episode starts.

The initial state of a scenario's task is not written anywhere: it is what perception
reports of the settled scene. This builds the scene the way an episode does
(:func:`~llcps.cps.episode.solve`), perceives it and returns the task, without a store,
so that the task can be planned or exported on its own (``llcps inspect knowledge
--pddl problem``).
"""

from __future__ import annotations

from llcps.errors import LlcpsError
from llcps.scenarios.base import CONDITIONS, Scenario
from llcps.scenarios.variants import check_variant
from llcps.sim.perception import perceive
from llcps.sim.world import SETTLE_STEPS, World
from llcps.symbolic.task import Task


def perceived_task(scenario: Scenario, *, condition: str = "novelty", variant: int = 0) -> Task:
    """The task of ``scenario`` in ``condition`` (and scene ``variant``) from the perceived
    initial state, named ``<scenario>-<condition>``.

    Raises:
        LlcpsError: an unknown condition or a bad variant.
    """
    if condition not in CONDITIONS:
        raise LlcpsError(f"unknown condition {condition!r}", hint=f"choose one of: {', '.join(CONDITIONS)}")
    check_variant(variant)
    with World.from_scene(scenario.scene(condition, variant)) as world:
        world.settle(max_steps=SETTLE_STEPS)
        task = Task.from_scene(
            entities={name: entity.spec.kind for name, entity in world.entities.items()},
            fixtures=world.fixtures,
            init=perceive(world),
            goal_pos=scenario.goal_pos,
            goal_neg=scenario.goal_neg,
        )
    suffix = "" if variant == 0 else f"-v{variant}"
    return Task(task.objects, task.init, task.goal_pos, task.goal_neg, name=f"{scenario.name}-{condition}{suffix}")
