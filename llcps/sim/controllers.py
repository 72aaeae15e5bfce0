"""The action controllers R: one per action of Table 1, each a trajectory relative
to its arguments, parameterized by rate (m/s), movement magnitude (m) and
orientation (approach side). Conventions and units: docs/controllers.md.

Directions (robot base at the origin facing +x; "left" is +y):

=========== ================================ =================================
orientation push direction                    side used by place / remove
=========== ================================ =================================
left        -y (from the entity's +y side)    +y
right       +y (from the entity's -y side)    -y
front       +x (from the robot side)          +x (the far side)
top         +x, contact near the entity's top  straight over / the robot side (-x)
=========== ================================ =================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Mapping

from llcps.domain import ACTIONS, PUSH_DIRECTION, SIDE
from llcps.trial_records import TrialSpec
from llcps.errors import LlcpsError
from llcps.sim import geometry as g
from llcps.sim.contact import TOUCH_DISTANCE, in_contact
from llcps.sim.motion import TRANSIT_SPEED, VERTICAL_SPEED, CapReached, Motion
from llcps.sim.robot import FINGER_OPEN, RAY_MASK, TOOL_ABOVE_TIPS

if TYPE_CHECKING:
    from llcps.domain import ControllerParams
    from llcps.sim.world import World

#: Default step budget of one trial (25 s of simulated time at 240 Hz).
DEFAULT_MAX_STEPS = 6000
#: Steps allowed after an action's motion for everything to come to rest (longer than a
#: fresh scene's settle, :data:`llcps.sim.world.SETTLE_STEPS`: what was pushed may still roll).
REST_AFTER_MOTION_STEPS = 720


#: Tool travel before the fingers meet the pushed entity (m).
PRE_CONTACT = 0.03
#: Half thickness of the closed finger pair along the push (m).
FINGER_HALF = 0.015
#: Lowest tool height above a support surface, keeping the fingertips 5 mm clear (m).
MIN_TOOL_ABOVE = TOOL_ABOVE_TIPS + 0.005
#: The Panda hand's footprint: length along the finger axis, depth across it, and the
#: height of its underside above the tool point (m); used to pick a grasp side it fits.
HAND_SPAN = 0.21
HAND_DEPTH = 0.07
HAND_ABOVE_TOOL = 0.05
#: Largest tool position error (m) at which a pick-and-place waypoint counts as reachable.
PLAN_TOLERANCE = 0.03
#: Lowest approach and transit height of the tool above the table (m).
SAFE_Z = 0.25
#: Clearance of a carried object above rims and supports (m).
CARRY_CLEARANCE = 0.04
#: Fraction of a container's inner half width by which a side release is offset.
SIDE_RELEASE_OFFSET = 0.6
#: Gap between a container's footprint and an object set down beside it (m).
SET_DOWN_GAP = 0.06
#: push_together ends with a slow press of this length (m) at this speed (m/s).
PRESS = 0.01
PRESS_SPEED = 0.05
#: Lateral offset of an off-centre push_together contact (fraction of the half width).
OFF_CENTRE = 0.4


def _safe_z(world: "World") -> float:
    """Transit height: above every entity and every scenario fixture (a shelf, a lip)."""
    c = world.client
    fixture_tops = (c.getAABB(body)[1][2] for name, body in world.fixtures.items() if name not in ("table", "floor"))
    tallest = max((*(g.top(world, n) for n in world.entities), *fixture_tops), default=0.0)
    return max(SAFE_Z, tallest + 0.08)


def _approach(
    m: Motion,
    point: tuple[float, float, float],
    yaw: float,
    safe_z: float,
    *,
    until: Callable[[], bool] | None = None,
) -> bool:
    """Rise, travel above ``point`` at the safe height, then descend onto it.

    Returns:
        True when ``until`` stopped the descent early (a guarded move).
    """
    x, y, z = m.target
    if z < safe_z - 1e-6:
        m.move_to((x, y, safe_z), VERTICAL_SPEED, converge=False)
    m.move_to((point[0], point[1], max(safe_z, point[2])), TRANSIT_SPEED, yaw=yaw)
    return m.move_to(point, VERTICAL_SPEED, until=until)


def _blocked(world: "World", target: str) -> Callable[[], bool]:
    """A guard for a descent onto ``target``: the hand touches any other body.

    A grasping descent stops there, as a guarded move on a real arm does, instead
    of pressing on whatever is in the way (a rim, a neighbour) until it gives.
    """
    c, robot, body = world.client, world.robot.body_id, world.body(target)

    def touching_other() -> bool:
        return any(cp[2] != body and cp[8] <= TOUCH_DISTANCE for cp in c.getContactPoints(bodyA=robot))

    return touching_other


def _contact_z(world: "World", name: str, orientation: str) -> float:
    """Tool height for a push: low (fingertips 5 mm above the entity's bottom, the
    finger faces covering its lower 5 cm), or for ``top`` near its top (it tips)."""
    lo, hi = world.aabb(name)
    low = lo[2] + MIN_TOOL_ABOVE
    return max(low, hi[2] - 0.005) if orientation == "top" else low


def _stroke(
    world: "World", m: Motion, name: str, d: tuple[float, float], z: float, lateral: float, safe_z: float
) -> tuple[float, float, float]:
    """Approach ``name`` from the side opposite to ``d``; returns the pre-contact tool point."""
    cx, cy, _ = world.center(name)
    back = g.extent_along(world, name, d) + FINGER_HALF + PRE_CONTACT
    n = (-d[1], d[0])
    start = (cx - d[0] * back + n[0] * lateral, cy - d[1] * back + n[1] * lateral, z)
    m.set_fingers(0.0)
    _approach(m, start, g.yaw_of(d), safe_z)
    return start


def push(world: "World", m: Motion, args: tuple[str, ...], params: "ControllerParams") -> None:
    """Stroke through the entity along the orientation's direction by ``movement_magnitude``."""
    (obj,) = args
    d = PUSH_DIRECTION[params.orientation]
    safe_z = _safe_z(world)
    start = _stroke(world, m, obj, d, _contact_z(world, obj, params.orientation), 0.0, safe_z)
    travel = PRE_CONTACT + params.movement_magnitude
    m.move_to((start[0] + d[0] * travel, start[1] + d[1] * travel, start[2]), params.rate)
    m.go_home(safe_z)


def push_together(world: "World", m: Motion, args: tuple[str, ...], params: "ControllerParams") -> None:
    """Push ``a`` along the line a->b until it touches ``b``, then on by at most the magnitude."""
    a, b = args
    ca, cb = world.center(a), world.center(b)
    d = g.unit2(cb[0] - ca[0], cb[1] - ca[1])
    safe_z = _safe_z(world)
    lateral = {"left": OFF_CENTRE, "right": -OFF_CENTRE}.get(params.orientation, 0.0)
    lateral *= g.extent_along(world, a, (-d[1], d[0]))
    start = _stroke(world, m, a, d, _contact_z(world, a, params.orientation), lateral, safe_z)
    # Contact ends the stroke; b's centre bounds it (b's extent along d is not
    # known exactly from its bounding box, so it is not subtracted).
    reach = (cb[0] - ca[0]) * d[0] + (cb[1] - ca[1]) * d[1] - g.extent_along(world, a, d)
    travel = PRE_CONTACT + max(0.0, reach) + params.movement_magnitude
    end = (start[0] + d[0] * travel, start[1] + d[1] * travel, start[2])
    c = world.client
    robot_id, body_a, body_b = world.robot.body_id, world.body(a), world.body(b)

    def pushed_into_contact() -> bool:
        return in_contact(c, robot_id, body_a) and in_contact(c, body_a, body_b)

    if m.move_to(end, params.rate, until=pushed_into_contact):
        x, y, z = m.target
        left = math.dist((x, y), end[:2])
        follow = min(params.movement_magnitude, left)
        m.move_to((x + d[0] * follow, y + d[1] * follow, z), params.rate, converge=False)
        # a last slow press, so that the pair comes to rest together
        x, y, z = m.target
        m.move_to((x + d[0] * PRESS, y + d[1] * PRESS, z), PRESS_SPEED, converge=False)
    m.go_home(safe_z)


def _grasp_yaw(world: "World", name: str, point: tuple[float, float, float], safe_z: float) -> float:
    """Close the fingers across the entity's narrower horizontal side, or across the
    other side when only there the hand's descent column is free of other bodies
    (a shelf edge, a container wall) and the entity still fits between the fingers."""
    spec = world.entity(name).spec
    _, orn = world.pose(name)
    yaw = world.client.getEulerFromQuaternion(orn)[2]
    across_x = spec.shape == "box" and spec.size[0] < spec.size[1]
    if across_x:
        yaw += math.pi / 2  # close along the entity's own x
    options = [yaw]
    other_width = spec.size[0] if not across_x else spec.size[1]
    if spec.shape != "box" or other_width <= 2 * FINGER_OPEN - 0.01:
        options.append(yaw + math.pi / 2)
    best = min(options, key=lambda y: _hand_obstacles(world, name, point, y, safe_z))
    return g.yaw_of((math.cos(best), math.sin(best)))


def _hand_obstacles(world: "World", name: str, point: tuple[float, float, float], yaw: float, safe_z: float) -> int:
    """How many vertical rays down the open hand's descent column hit something else
    before the hand gets there: rays across the palm stop at its underside (a shelf),
    rays down each finger's path at the grasp height (a container wall)."""
    fx, fy = -math.sin(yaw), math.cos(yaw)  # the finger axis: the hand is long along it
    hx, hy = math.cos(yaw), math.sin(yaw)
    top = max(safe_z, point[2]) + HAND_ABOVE_TOOL + 0.1
    starts, ends = [], []

    def column(a: float, b: float, bottom: float) -> None:
        x, y = point[0] + fx * a + hx * b, point[1] + fy * a + hy * b
        starts.append((x, y, top))
        ends.append((x, y, bottom))

    for a in (-HAND_SPAN / 2, -HAND_SPAN / 4, 0.0, HAND_SPAN / 4, HAND_SPAN / 2):
        for b in (-HAND_DEPTH / 2, 0.0, HAND_DEPTH / 2):
            column(a, b, point[2] + HAND_ABOVE_TOOL)
    for side in (-1.0, 1.0):
        for a in (FINGER_OPEN - 0.004, FINGER_OPEN + 0.006, FINGER_OPEN + 0.016):
            for b in (-0.01, 0.0, 0.01):
                column(side * a, b, point[2] - 0.01)
    ignore = {world.robot.body_id, world.body(name)}
    rays = world.client.rayTestBatch(starts, ends, collisionFilterMask=RAY_MASK)
    return sum(1 for hit in rays if hit[0] >= 0 and hit[0] not in ignore)


def _grasp_point(world: "World", obj: str) -> tuple[tuple[float, float, float], float]:
    """Where the tool grasps ``obj`` from the top, and its height above ``obj``'s bottom then."""
    lo, hi = world.aabb(obj)
    cx, cy, _ = world.center(obj)
    z = max(lo[2] + MIN_TOOL_ABOVE, hi[2] - 0.03)
    return (cx, cy, z), z - lo[2]


def _reachable(world: "World", *points: tuple[float, float, float]) -> bool:
    """Whether the arm can put its tool at every waypoint, top-down (IK then FK).

    Pick-and-place controllers check their waypoints before moving, as a motion
    planner would: an action whose grasp or release point is out of reach is
    refused and nothing moves, rather than dropping the object wherever the
    stretched arm happens to be.
    """
    return all(world.robot.reach_error(point, 0.0)[0] <= PLAN_TOLERANCE for point in points)


def _pick(world: "World", m: Motion, obj: str, safe_z: float) -> bool:
    """Open, approach ``obj`` from the top with a guarded descent and grasp it.

    Returns:
        Whether ``obj`` is held. A controller whose grasp failed stops there and
        returns the arm home, as a robot that checks its grasp does.
    """
    point, _ = _grasp_point(world, obj)
    m.set_fingers(FINGER_OPEN)
    _approach(m, point, _grasp_yaw(world, obj, point, safe_z), safe_z, until=_blocked(world, obj))
    return m.grasp(world.body(obj))


def _lift(m: Motion, params: "ControllerParams", min_z: float) -> None:
    x, y, z = m.target
    m.move_to((x, y, max(z + params.movement_magnitude, min_z)), VERTICAL_SPEED, converge=False)


def _support_z(world: "World", x: float, y: float, below: float, ignore: int) -> float:
    """Height of the first surface under (x, y) beneath ``below`` (robot and ``ignore`` excluded)."""
    c = world.client
    start, end = (x, y, below), (x, y, world.scene.table.floor_z - 0.1)
    for _ in range(4):
        hit = c.rayTestBatch([start], [end], collisionFilterMask=RAY_MASK)[0]
        if hit[0] != ignore:
            return hit[3][2] if hit[0] >= 0 else world.scene.table.floor_z
        start = (x, y, hit[3][2] - 1e-4)
    return world.scene.table.floor_z


@dataclass(frozen=True)
class _Carry:
    """Where a pick-and-place call takes its object: the grasp point, the height it is
    carried at, the point above which it is carried, and how far below the tool it hangs."""

    obj: str
    grasp: tuple[float, float, float]
    held: float
    carry_z: float
    target: tuple[float, float]

    def waypoints(self, params: "ControllerParams") -> tuple[tuple[float, float, float], ...]:
        """The tool poses the arm must reach: the grasp, and the carry above the target."""
        tx, ty = self.target
        return self.grasp, (tx, ty, max(self.carry_z, self.grasp[2] + params.movement_magnitude))


def _place_carry(world: "World", args: tuple[str, ...], params: "ControllerParams") -> _Carry:
    """``place_in_container(o, c)``: over ``c``'s centre (top) or offset toward a side."""
    obj, container = args
    grasp, held = _grasp_point(world, obj)
    carry_z = g.top(world, container) + CARRY_CLEARANCE + held
    cx, cy, _ = world.center(container)
    if params.orientation == "top":
        tx, ty = cx, cy
    else:
        side = SIDE[params.orientation]
        off = SIDE_RELEASE_OFFSET * g.inner_half(world, container, side)
        tx, ty = cx + side[0] * off, cy + side[1] * off
    return _Carry(obj, grasp, held, carry_z, (tx, ty))


def _remove_carry(world: "World", args: tuple[str, ...], params: "ControllerParams") -> _Carry:
    """``remove_from_container(o, c)``: beyond ``c``'s footprint toward the orientation's side."""
    obj, container = args
    grasp, held = _grasp_point(world, obj)
    carry_z = g.top(world, container) + CARRY_CLEARANCE + held
    side = SIDE[params.orientation]
    cx, cy, _ = world.center(container)
    reach = g.extent_along(world, container, side) + g.extent_along(world, obj, side) + SET_DOWN_GAP
    return _Carry(obj, grasp, held, carry_z, (cx + side[0] * reach, cy + side[1] * reach))


def _carry(world: "World", m: Motion, carry: _Carry, params: "ControllerParams", safe_z: float) -> bool:
    """Check the waypoints, pick the object, lift it and carry it above the target at ``rate``.

    Returns:
        False when the action was refused (a waypoint out of reach) or the grasp
        failed; the arm is then back home with nothing held.
    """
    if not _reachable(world, *carry.waypoints(params)):
        return False
    if not _pick(world, m, carry.obj, safe_z):
        m.open_hand()
        m.go_home(safe_z)
        return False
    _lift(m, params, carry.carry_z)
    m.move_to((*carry.target, m.target[2]), params.rate)
    return True


def place_in_container(world: "World", m: Motion, args: tuple[str, ...], params: "ControllerParams") -> None:
    """Grasp ``o`` from the top, lift, carry over ``c`` at ``rate``, lower in (top) or
    release offset toward a side from carry height."""
    _, container = args
    safe_z = _safe_z(world)
    carry = _place_carry(world, args, params)
    if not _carry(world, m, carry, params, safe_z):
        return
    if params.orientation == "top":
        m.move_to((*carry.target, g.inner_floor_z(world, container) + 0.015 + carry.held), VERTICAL_SPEED)
    m.open_hand()
    m.go_home(safe_z)


def remove_from_container(world: "World", m: Motion, args: tuple[str, ...], params: "ControllerParams") -> None:
    """Grasp ``o`` from the top, lift clear of ``c``'s rim, carry at ``rate`` beyond
    ``c``'s footprint toward the orientation's side, set it down and release."""
    obj = args[0]
    safe_z = _safe_z(world)
    carry = _remove_carry(world, args, params)
    if not _carry(world, m, carry, params, safe_z):
        return
    tx, ty = carry.target
    support = _support_z(world, tx, ty, m.target[2] - carry.held - 0.005, world.body(obj))
    m.move_to((tx, ty, support + 0.01 + carry.held), VERTICAL_SPEED)
    m.open_hand()
    m.go_home(safe_z)


#: The pick-and-place actions: where each carries its object (the others never refuse).
_CARRIES: Mapping[str, Callable[["World", tuple[str, ...], "ControllerParams"], _Carry]] = {
    "place_in_container": _place_carry,
    "remove_from_container": _remove_carry,
}


def refuses(world: "World", spec: TrialSpec) -> bool:
    """Whether the controller would refuse ``spec`` in the world as it stands: a
    pick-and-place call with a waypoint out of the arm's reach (:func:`_reachable`), which
    moves nothing. What its trial would check first, asked without running it: IK only,
    no time passes and no body moves (:meth:`~llcps.sim.robot.Robot.reach_error`)."""
    where = _CARRIES.get(spec.action)
    return where is not None and not _reachable(world, *where(world, spec.arguments, spec.params).waypoints(spec.params))


#: Spacing of the points at which :func:`path_meets` places the moved boxes along a path (m).
PATH_STEP = 0.01
#: Height of the hand above the tool point that :func:`path_meets` sweeps with a carry (m).
HAND_HEIGHT = 0.1

_Box = tuple[tuple[float, float, float], tuple[float, float, float]]


def _sweeps(path: list[tuple[float, float, float]], box: _Box, body: _Box) -> bool:
    """Whether ``box`` (offsets from a path point) meets ``body`` at a point of ``path``,
    a polyline sampled every :data:`PATH_STEP`."""
    (bx0, by0, bz0), (bx1, by1, bz1) = body
    (ox0, oy0, oz0), (ox1, oy1, oz1) = box
    for a, b in zip(path, path[1:]):
        n = max(1, math.ceil(math.dist(a, b) / PATH_STEP))
        for i in range(n + 1):
            x, y, z = (a[k] + (b[k] - a[k]) * i / n for k in range(3))
            if x + ox0 < bx1 and x + ox1 > bx0 and y + oy0 < by1 and y + oy1 > by0 and z + oz0 < bz1 and z + oz1 > bz0:
                return True
    return False


def _to_contact(
    world: "World", obj: str, at: tuple[float, float], other: str, other_at: tuple[float, float]
) -> tuple[tuple[float, float], float]:
    """``push_together``'s planned slide of ``obj`` from ``at`` toward ``other`` standing at
    ``other_at``: the direction, and how far it goes until their bounding boxes meet."""
    d = g.unit2(other_at[0] - at[0], other_at[1] - at[1])
    return d, max(0.0, math.dist(at, other_at) - g.extent_along(world, obj, d) - g.extent_along(world, other, d))


def path_meets(world: "World", spec: TrialSpec, body: str, *, at: Mapping[str, tuple[float, float]] | None = None) -> bool:
    """Whether ``spec``'s planned motion, by geometry alone, takes what it moves through
    ``body``'s bounding box (grown by :data:`~llcps.sim.contact.TOUCH_DISTANCE`).

    A push slides its object along the table: from where it stands, along the push
    (``push_together``: toward the other argument, up to it), by the stroke's travel. A
    pick-and-place call lifts its object from the grasp to the carry height its
    magnitude sets, carries it to the target, and, placing from the top, lowers it into
    the container; the hand above it sweeps a column of the object's footprint. No time passes and nothing moves: what the
    arm would sweep on the way to the object, and where a body bounces, is not known.

    Args:
        at: for a push, a horizontal position of the centre of some of its arguments
            other than where they stand (where another motion would leave them,
            :func:`planned_end`); ignored by a pick-and-place call.
    """
    lo, hi = world.aabb(body)
    grown = (tuple(v - TOUCH_DISTANCE for v in lo), tuple(v + TOUCH_DISTANCE for v in hi))
    obj = spec.arguments[0]
    olo, ohi = world.aabb(obj)
    cx, cy, cz = world.center(obj)
    rx, ry = (ohi[0] - olo[0]) / 2.0, (ohi[1] - olo[1]) / 2.0
    where = _CARRIES.get(spec.action)
    if where is None:
        moved = at or {}
        cx, cy = moved.get(obj, (cx, cy))
        if spec.action == "push_together":
            d, travel = _to_contact(world, obj, (cx, cy), spec.arguments[1], moved.get(spec.arguments[1], world.center(spec.arguments[1])[:2]))
        else:
            d = PUSH_DIRECTION[spec.params.orientation]
            travel = PRE_CONTACT + spec.params.movement_magnitude
        path = [(cx, cy, cz), (cx + d[0] * travel, cy + d[1] * travel, cz)]
        return _sweeps(path, ((-rx, -ry, olo[2] - cz), (rx, ry, ohi[2] - cz)), grown)
    carry = where(world, spec.arguments, spec.params)
    grasp, above = carry.waypoints(spec.params)
    path = [grasp, (grasp[0], grasp[1], above[2]), above]
    if spec.action == "place_in_container" and spec.params.orientation == "top":
        path.append((above[0], above[1], g.inner_floor_z(world, spec.arguments[1]) + 0.015 + carry.held))
    # the object hangs ``held`` below the tool point, the hand stands above it: a column
    # of the object's footprint
    h = max(rx, ry)
    moved_box = ((-h, -h, -carry.held), (h, h, max(ohi[2] - olo[2] - carry.held, HAND_HEIGHT)))
    return _sweeps(path, moved_box, grown)


def planned_end(world: "World", spec: TrialSpec) -> tuple[str, tuple[float, float]] | None:
    """Where ``spec``'s planned motion leaves what it moves, by geometry alone: its name
    and the horizontal position of its centre; None for a placement, which leaves it in
    a container.

    A push moves its object by the magnitude along the push; ``push_together`` moves it
    along the line to the other argument until their bounding boxes meet;
    ``remove_from_container`` sets it down beside the container, toward the
    orientation's side. As :func:`path_meets`, no time passes: where a body slides on,
    tips or is stopped is not known.
    """
    obj = spec.arguments[0]
    cx, cy, _ = world.center(obj)
    if spec.action == "push":
        d = PUSH_DIRECTION[spec.params.orientation]
        return obj, (cx + d[0] * spec.params.movement_magnitude, cy + d[1] * spec.params.movement_magnitude)
    if spec.action == "push_together":
        d, travel = _to_contact(world, obj, (cx, cy), spec.arguments[1], world.center(spec.arguments[1])[:2])
        return obj, (cx + d[0] * travel, cy + d[1] * travel)
    if spec.action == "remove_from_container":
        return obj, _remove_carry(world, spec.arguments, spec.params).target
    return None


Controller = Callable[["World", Motion, tuple[str, ...], "ControllerParams"], None]

#: The action controllers, one per action (keys == llcps.domain.ACTIONS).
CONTROLLERS: Mapping[str, Controller] = {
    "push": push,
    "push_together": push_together,
    "remove_from_container": remove_from_container,
    "place_in_container": place_in_container,
}
assert tuple(CONTROLLERS) == ACTIONS


def execute(world: "World", spec: TrialSpec, *, max_steps: int = DEFAULT_MAX_STEPS) -> int:
    """Run one controller call to completion in ``world``.

    The trial ends when the motion is done and every entity is at rest, or at
    ``max_steps``; any grasp is released at the end either way.

    Returns:
        Simulation steps used.
    """
    for name in spec.arguments:
        world.entity(name)
    if len(set(spec.arguments)) != len(spec.arguments):
        raise LlcpsError(f"{spec.action} needs distinct arguments, got {spec.arguments}")
    m = Motion(world, max_steps=max_steps)
    try:
        CONTROLLERS[spec.action](world, m, spec.arguments, spec.params)
        m.wait_rest(max_steps=min(REST_AFTER_MOTION_STEPS, max_steps - m.steps))
    except CapReached:
        pass
    finally:
        world.robot.release()
    return m.steps
