"""The three CPS scenarios of the paper (Figure 1), each in an original and a
novelty condition. ``SCENARIOS`` is the one list the CLI, the experiments and the
tests read. See docs/scenarios.md for pictures and the candidate-space figures.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from llcps.domain import fluent
from llcps.scenarios.base import CONDITIONS, Scenario, lookup

if TYPE_CHECKING:
    from llcps.sim.world import SceneSpec

# The scene builders import the simulator when called, so listing scenarios (CLI
# help, registries) stays cheap.

# --------------------------------------------------------------------------- scenario 1
# A light cube near the right (-y) edge of a narrow table, a bucket on the floor
# beneath that edge. Original: push drops the cube in. Novelty: a fence along the edge,
# taller than the cube, stops every push, and the hand lowering the cube into the
# bucket from the top meets the fence; releasing the cube from above the bucket (a place
# from the side, a parameterization K does not use) still drops it in.

#: Height of scenario 1's fence (m): three times the cube, above the nominal carry.
FENCE_HEIGHT = 0.15


def _scenario1(condition: str) -> "SceneSpec":
    from llcps.sim.entities import TableSpec, bucket, edge_lip, solid
    from llcps.sim.world import SceneSpec

    table = TableSpec(y_half=0.45)
    entities = (
        solid("cube", "box", "red", (0.05, 0.05, 0.05), at=(0.4, -0.32)),
        bucket("bucket", "blue", at=(0.4, -0.59), table=table, diameter=0.26, height=0.24),
        solid("ball", "sphere", "green", 0.05, at=(0.4, 0.15)),
    )
    fixtures = (edge_lip(table, "right", height=FENCE_HEIGHT, name="fence"),) if condition == "novelty" else ()
    return SceneSpec(entities=entities, fixtures=fixtures, table=table, name=f"scenario1/{condition}")


# --------------------------------------------------------------------------- scenario 2
# An item and an open bin. Original: the bin stands on the table within reach.
# Novelty: the bin stands on the floor beyond the far end of the table, out of the
# arm's reach; placing falls short, but the item can be driven off the far edge.

def _scenario2(condition: str) -> "SceneSpec":
    from llcps.sim.entities import TableSpec, open_box, solid
    from llcps.sim.world import SceneSpec

    table = TableSpec(x_max=0.92)
    item = solid("can", "cylinder", "blue", (0.05, 0.07), at=(0.62, -0.05))
    if condition == "novelty":
        bin_ = open_box("bin", "green", at=(1.06, -0.05), size=(0.24, 0.3, 0.35), on=table.floor_z, mass=2.0)
    else:
        bin_ = open_box("bin", "green", at=(0.45, 0.3), size=(0.2, 0.2, 0.1))
    other = solid("block", "box", "red", (0.05, 0.05, 0.05), at=(0.35, -0.3))
    return SceneSpec(entities=(item, bin_, other), table=table, name=f"scenario2/{condition}")


# --------------------------------------------------------------------------- scenario 3
# A container holding one ball. Original: a shallow tray; the ball is lifted out
# from the top. Novelty: the ball lies at the bottom of a deep, narrow, heavy cup: the hand
# cannot get down to it (its palm meets the rim), so it cannot be taken out from the
# top; tipping the cup over spills it.


def _scenario3(condition: str) -> "SceneSpec":
    from llcps.sim.entities import inside, open_box, solid
    from llcps.sim.world import SceneSpec

    if condition == "novelty":
        cup = open_box("cup", "green", at=(0.5, 0.0), size=(0.09, 0.09, 0.16), mass=3.0)
        ball = inside(solid("ball", "sphere", "red", 0.045, at=(0, 0)), cup)
    else:
        cup = open_box("cup", "green", at=(0.5, 0.0), size=(0.16, 0.16, 0.05), mass=0.3)
        ball = inside(solid("ball", "sphere", "red", 0.045, at=(0, 0)), cup)
    other = solid("block", "box", "blue", (0.05, 0.05, 0.05), at=(0.35, 0.3))
    return SceneSpec(entities=(cup, ball, other), name=f"scenario3/{condition}")


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario(
            name="scenario1",
            alias="bucket",
            title="push an object off the table into a bucket",
            story=(
                "Push the cube off the table edge into the bucket on the floor. Novelty: a fence "
                "along the edge stops every push and blocks lowering the cube into the bucket; "
                "it must get over the fence another way."
            ),
            build_scene=_scenario1,
            goal_pos=frozenset({fluent("in", "cube", "bucket")}),
        ),
        Scenario(
            name="scenario2",
            alias="container",
            title="place an item into a container",
            story=(
                "Place the can into the bin. Novelty: the bin stands beyond the far end of the "
                "table, out of the arm's reach, so placing falls short."
            ),
            build_scene=_scenario2,
            goal_pos=frozenset({fluent("in", "can", "bin")}),
        ),
        Scenario(
            name="scenario3",
            alias="empty",
            title="empty a container holding one object",
            story=(
                "Take the ball out of its container. Novelty: the ball lies at the bottom of a "
                "deep, narrow cup the hand cannot reach into, so it cannot be lifted out."
            ),
            build_scene=_scenario3,
            goal_neg=frozenset({fluent("in", "ball", "cup")}),
        ),
    )
}


def get_scenario(name: str) -> Scenario:
    """A scenario by name or alias (``scenario2`` or ``container``)."""
    return lookup(SCENARIOS, name)


__all__ = ["CONDITIONS", "SCENARIOS", "Scenario", "get_scenario"]
