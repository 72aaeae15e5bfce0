"""Each action controller does what its name says, for every orientation."""

from __future__ import annotations

import math

import pytest

from llcps.domain import ACTIONS, ORIENTATIONS, ControllerParams, fluent
from llcps.trial_records import TrialSpec
from llcps.errors import LlcpsError, UnknownNameError
from llcps.sim.controllers import CONTROLLERS, PUSH_DIRECTION, SIDE, execute, path_meets, planned_end
from llcps.sim.builders import inside, open_box, solid
from llcps.sim.specs import FixtureSpec
from llcps.sim.trial import bodies_met
from llcps.sim.perception import perceive
from llcps.sim.world import SceneSpec, World

BIN = open_box("bin", "green", at=(0.45, -0.3), size=(0.2, 0.2, 0.08))
SCENE = SceneSpec(
    entities=(
        solid("a", "box", "red", (0.045, 0.045, 0.045), at=(0.5, 0.05)),
        solid("b", "box", "blue", (0.05, 0.05, 0.05), at=(0.5, 0.25)),
        BIN,
        inside(solid("c", "box", "blue", (0.04, 0.04, 0.04), at=(0, 0)), BIN),
        solid("wide", "box", "green", (0.12, 0.12, 0.04), at=(0.3, 0.3)),
    )
)


def settled(scene: SceneSpec):
    """A world of ``scene`` at rest, its start snapshot in ``start``; closed after the module."""
    w = World.from_scene(scene, visuals=False)
    w.settle(max_steps=240)
    w.start = w.snapshot()
    yield w
    w.close()


@pytest.fixture(scope="module")
def world():
    yield from settled(SCENE)


def run(world: World, action: str, args: tuple[str, ...], rate: float, magnitude: float, orientation: str) -> int:
    world.restore(world.start)
    return execute(world, TrialSpec(action, args, ControllerParams(rate, magnitude, orientation)))


def test_one_controller_per_action() -> None:
    assert tuple(CONTROLLERS) == ACTIONS
    assert set(PUSH_DIRECTION) == set(SIDE) == set(ORIENTATIONS)


@pytest.mark.parametrize("orientation", ORIENTATIONS)
@pytest.mark.parametrize("magnitude", [0.1, 0.2])
def test_push_moves_the_object_by_the_magnitude_along_the_direction(world, orientation, magnitude) -> None:
    world.restore(world.start)
    x0, y0, _ = world.center("a")
    run(world, "push", ("a",), 0.1, magnitude, orientation)
    x1, y1, _ = world.center("a")
    dx, dy = PUSH_DIRECTION[orientation]
    along = (x1 - x0) * dx + (y1 - y0) * dy
    across = abs((x1 - x0) * dy - (y1 - y0) * dx)
    assert along == pytest.approx(magnitude, abs=0.03)
    assert across < 0.02


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_push_together_leaves_the_two_touching(world, orientation) -> None:
    world.restore(world.start)
    assert fluent("touching", "a", "b") not in perceive(world)
    run(world, "push_together", ("a", "b"), 0.1, 0.0, orientation)
    assert fluent("touching", "a", "b") in perceive(world)


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_place_in_container_ends_in_the_container(world, orientation) -> None:
    run(world, "place_in_container", ("a", "bin"), 0.3, 0.1, orientation)
    state = perceive(world)
    assert fluent("in", "a", "bin") in state
    assert not any(f[0] == "holding" for f in state)


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_remove_from_container_ends_outside_beside_it(world, orientation) -> None:
    world.restore(world.start)
    assert fluent("in", "c", "bin") in perceive(world)
    run(world, "remove_from_container", ("c", "bin"), 0.3, 0.1, orientation)
    state = perceive(world)
    assert fluent("in", "c", "bin") not in state
    assert fluent("on", "c", "table") in state
    cx, cy, _ = world.center("c")
    bx, by, _ = world.center("bin")
    sx, sy = SIDE[orientation]
    assert (cx - bx) * sx + (cy - by) * sy > 0.1  # set down on the orientation's side


def test_an_object_wider_than_the_hand_is_never_held(world) -> None:
    world.restore(world.start)
    before = world.center("wide")
    run(world, "place_in_container", ("wide", "bin"), 0.3, 0.1, "top")
    assert fluent("in", "wide", "bin") not in perceive(world)
    assert abs(world.center("wide")[2] - before[2]) < 0.02  # it never left the table


def test_the_step_cap_ends_a_trial_and_releases_the_grasp(world) -> None:
    steps = 0
    world.restore(world.start)
    spec = TrialSpec("place_in_container", ("a", "bin"), ControllerParams(0.05, 0.3, "top"))
    for cap in (40, 700):  # before and after the grasp closes
        world.restore(world.start)
        steps = execute(world, spec, max_steps=cap)
        assert steps == cap
        assert world.robot.grasped is None


def test_bad_arguments_are_refused(world) -> None:
    world.restore(world.start)
    with pytest.raises(UnknownNameError):
        execute(world, TrialSpec("push", ("nothing",), ControllerParams(0.1, 0.1, "left")))
    with pytest.raises(LlcpsError):
        execute(world, TrialSpec("push_together", ("a", "a"), ControllerParams(0.1, 0.1, "left")))


FAR = SceneSpec(
    entities=(
        solid("near", "box", "red", (0.045, 0.045, 0.045), at=(0.5, 0.05)),
        solid("far", "box", "blue", (0.045, 0.045, 0.045), at=(1.3, 0.0)),
        open_box("tray", "green", at=(0.45, -0.3), size=(0.2, 0.2, 0.08)),
    )
)


@pytest.fixture(scope="module")
def far_world():
    yield from settled(FAR)


def _poses(world: World) -> dict[str, tuple[float, float, float]]:
    return {name: world.center(name) for name in ("near", "far", "tray")}


@pytest.mark.parametrize("orientation", ORIENTATIONS)
def test_a_pick_out_of_reach_is_refused_and_moves_nothing(far_world, orientation) -> None:
    from llcps.sim.controllers import refuses

    world = far_world
    for magnitude in (0.05, 0.3):
        spec = TrialSpec("place_in_container", ("far", "tray"), ControllerParams(0.4, magnitude, orientation))
        world.restore(world.start)
        before = _poses(world)
        assert refuses(world, spec)
        assert _poses(world) == before  # asking moves nothing
        execute(world, spec)
        after = _poses(world)
        assert all(math.dist(before[n], after[n]) < 1e-4 for n in before)  # the trial moved nothing either


def test_what_the_arm_reaches_is_not_refused_and_pushes_never_are(far_world) -> None:
    from llcps.sim.controllers import refuses

    world = far_world
    world.restore(world.start)
    place = TrialSpec("place_in_container", ("near", "tray"), ControllerParams(0.4, 0.15, "top"))
    assert not refuses(world, place)
    assert not refuses(world, TrialSpec("push", ("far",), ControllerParams(0.4, 0.15, "front")))
    assert not refuses(world, TrialSpec("push_together", ("far", "near"), ControllerParams(0.4, 0.15, "front")))
    before = world.center("near")
    execute(world, place)
    assert fluent("in", "near", "tray") in perceive(world)
    assert math.dist(before, world.center("near")) > 0.1


#: A low wall 12 cm beyond the cube along +x (a push from the front), and a box beside the
#: bin that a carry at the usual height passes through and a higher lift passes over.
WALLED = SceneSpec(
    entities=(
        solid("cube", "box", "red", (0.045, 0.045, 0.045), at=(0.4, 0.1)),
        open_box("tray", "green", at=(0.4, -0.25), size=(0.16, 0.16, 0.06)),
    ),
    fixtures=(
        FixtureSpec("wall", (0.02, 0.2, 0.06), (0.52, 0.1, 0.03)),
        FixtureSpec("screen", (0.2, 0.02, 0.16), (0.4, -0.1, 0.08)),
    ),
)


@pytest.fixture(scope="module")
def walled():
    yield from settled(WALLED)


def test_a_stroke_meets_the_bodies_in_its_way_and_only_them(walled) -> None:
    """A push from the front drives the cube into the wall: met. A push to the left,
    away from it, meets nothing; the cube's argument, the table and what touched it
    before the stroke are never named."""
    walled.restore(walled.start)
    assert bodies_met(walled, TrialSpec("push", ("cube",), ControllerParams(0.2, 0.3, "front"))) == {"wall"}
    walled.restore(walled.start)
    assert bodies_met(walled, TrialSpec("push", ("cube",), ControllerParams(0.2, 0.1, "left"))) == frozenset()


def test_a_planned_path_meets_what_lies_across_it_by_geometry_alone(walled) -> None:
    walled.restore(walled.start)

    def spec(action: str, args: tuple[str, ...], magnitude: float, orientation: str) -> TrialSpec:
        return TrialSpec(action, args, ControllerParams(0.2, magnitude, orientation))

    # pushes slide along the table: toward the wall far enough, or not
    assert path_meets(walled, spec("push", ("cube",), 0.3, "front"), "wall")
    assert not path_meets(walled, spec("push", ("cube",), 0.05, "front"), "wall")
    assert not path_meets(walled, spec("push", ("cube",), 0.3, "left"), "wall")
    # a carry at the usual height goes through the 16 cm screen; lifted 30 cm, over it
    assert path_meets(walled, spec("place_in_container", ("cube", "tray"), 0.05, "top"), "screen")
    assert not path_meets(walled, spec("place_in_container", ("cube", "tray"), 0.3, "top"), "screen")
    assert not path_meets(walled, spec("place_in_container", ("cube", "tray"), 0.05, "top"), "wall")
    # the real stroke agrees with the geometry
    assert bodies_met(walled, spec("place_in_container", ("cube", "tray"), 0.05, "top")) >= {"screen"}
    walled.restore(walled.start)
    assert "screen" not in bodies_met(walled, spec("place_in_container", ("cube", "tray"), 0.3, "top"))


def test_where_a_planned_motion_leaves_its_object_and_the_path_from_there(walled) -> None:
    """A push moves the cube by its magnitude; a push from the front meets the wall from
    where the cube stands and misses it from where a push to the right would leave it; a
    remove sets it down beside the container; a placement leaves it in one (None)."""
    walled.restore(walled.start)
    x, y, _ = walled.center("cube")

    def spec(action: str, args: tuple[str, ...], magnitude: float, orientation: str) -> TrialSpec:
        return TrialSpec(action, args, ControllerParams(0.2, magnitude, orientation))

    name, end = planned_end(walled, spec("push", ("cube",), 0.2, "right"))
    assert name == "cube" and end == pytest.approx((x, y + 0.2))
    front = spec("push", ("cube",), 0.3, "front")
    assert path_meets(walled, front, "wall") and path_meets(walled, front, "wall", at={"cube": (x, y)})
    assert not path_meets(walled, front, "wall", at={"cube": end})
    assert path_meets(walled, front, "wall", at={"tray": end})  # not an argument: from where the cube stands
    name, end = planned_end(walled, spec("push_together", ("cube", "tray"), 0.1, "front"))
    tray = walled.center("tray")
    assert name == "cube" and end[0] == pytest.approx(x, abs=0.01) and tray[1] < end[1] < y
    name, end = planned_end(walled, spec("remove_from_container", ("cube", "tray"), 0.1, "left"))
    assert name == "cube" and end[0] == pytest.approx(tray[0]) and end[1] > tray[1] + 0.08  # beside it, on the left side (+y)
    assert planned_end(walled, spec("place_in_container", ("cube", "tray"), 0.1, "top")) is None
