"""Perception reads the symbolic state from physics: visibility with occlusion,
reachability of the workspace and the top approach, contacts, containment."""

from __future__ import annotations

import math

import pytest

from llcps.domain import SHAPES, fluent
from llcps.sim.builders import inside, open_box, solid, stacked
from llcps.sim.perception import CAMERA, entity_features, perceive
from llcps.sim.world import SceneSpec, World


def _behind(occluder_xy, distance):
    """A point ``distance`` beyond ``occluder_xy`` as seen from the camera."""
    ux, uy = occluder_xy[0] - CAMERA.eye[0], occluder_xy[1] - CAMERA.eye[1]
    n = math.hypot(ux, uy)
    return (occluder_xy[0] + ux / n * distance, occluder_xy[1] + uy / n * distance)


WALL = solid("wall", "box", "green", (0.06, 0.14, 0.2), at=(0.4, -0.25))
BASE = solid("base", "box", "blue", (0.06, 0.06, 0.05), at=(0.35, 0.35))
BIN = open_box("bin", "red", at=(0.55, 0.3), size=(0.2, 0.2, 0.12))
SCENE = SceneSpec(
    entities=(
        WALL,
        solid("hidden", "box", "red", (0.04, 0.04, 0.04), at=_behind((0.4, -0.25), 0.1)),
        solid("open", "sphere", "red", 0.05, at=(0.45, 0.05)),
        solid("far", "cylinder", "blue", (0.05, 0.08), at=(1.0, 0.0)),
        BASE,
        stacked(solid("top", "box", "green", (0.04, 0.04, 0.04), at=(0, 0)), BASE),
        BIN,
        inside(solid("inner", "box", "green", (0.04, 0.04, 0.04), at=(0, 0)), BIN, offset=(-0.05, 0.0)),
        solid("left", "box", "red", (0.05, 0.05, 0.05), at=(0.6, -0.05)),
        solid("right", "box", "blue", (0.05, 0.05, 0.05), at=(0.6, -0.1)),
    )
)


@pytest.fixture(scope="module")
def world():
    w = World.from_scene(SCENE, visuals=False)
    w.settle(max_steps=240)
    yield w
    w.close()


@pytest.fixture(scope="module")
def state(world):
    return perceive(world)


def test_an_object_behind_a_taller_one_is_not_visible(state) -> None:
    assert fluent("visible", "wall") in state
    assert fluent("visible", "open") in state
    assert fluent("visible", "hidden") not in state


def test_an_object_inside_a_deep_bin_is_hidden_by_its_wall(state) -> None:
    assert fluent("in", "inner", "bin") in state
    assert fluent("visible", "bin") in state
    assert fluent("visible", "inner") not in state


def test_beyond_the_workspace_is_not_reachable(state) -> None:
    assert fluent("reachable", "open") in state
    assert fluent("visible", "far") in state
    assert fluent("reachable", "far") not in state


def test_an_object_under_another_cannot_be_approached_from_the_top(state) -> None:
    assert fluent("on", "top", "base") in state
    assert fluent("reachable", "top") in state
    assert fluent("reachable", "base") not in state


def test_contacts_give_touching_and_on(world, state) -> None:
    assert fluent("touching", "left", "right") in state
    assert fluent("touching", "right", "left") == fluent("touching", "left", "right")
    assert fluent("touching", "open", "table") in state
    assert fluent("on", "open", "table") in state
    assert fluent("touching", "open", "left") not in state
    assert fluent("near", "left", "right") in state and fluent("near", "right", "left") in state
    assert fluent("near", "open", "far") not in state
    assert not any(f[0] == "holding" for f in state)
    names = {arg for f in state for arg in f[1:]}
    assert names <= set(world.entities) | set(world.fixtures)  # the arm is not an entity


def test_perception_does_not_disturb_the_world(world) -> None:
    positions = {n: world.center(n) for n in world.entities}
    joints = world.robot.joint_positions()
    first = perceive(world)
    assert perceive(world) == first
    assert {n: world.center(n) for n in world.entities} == positions
    assert world.robot.joint_positions() == joints


def test_features_are_the_entity_seen_from_the_robot_base(world) -> None:
    feats = entity_features(world, "far")
    x, y, z = world.center("far")
    assert feats.shape == "cylinder" and feats.shape in SHAPES and feats.color == "blue"
    assert feats.volume == pytest.approx(math.pi * 0.025**2 * 0.08)
    assert feats.vector_magnitude == pytest.approx(math.sqrt(x * x + y * y + z * z))
    m = feats.vector_magnitude
    assert (feats.unit_x, feats.unit_y, feats.unit_z) == pytest.approx((x / m, y / m, z / m))
