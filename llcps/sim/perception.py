"""Symbolic perception: the fluents of a state, and the Table-1 features of an
entity, measured from physics.

Fluents (names shared with the symbolic layer and the PDDL domain):

- ``visible(e)``: some sample point of ``e`` is in the robot's fixed camera's
  field of view and the ray from the camera through it meets ``e`` before any
  other body (the robot itself is ignored). Occlusion counts.
- ``reachable(e)``: the arm can put its tool top-down just above ``e`` (IK from
  HOME, then forward kinematics within REACH_TOLERANCE) *and* the vertical
  approach is clear (a ray from APPROACH_HEIGHT above ``e`` down meets ``e``
  first; for a container, nothing lies over its opening).
- ``touching(a, b)``: contact points (within TOUCH_DISTANCE) between two
  entities or an entity and a fixture; the robot is not an entity.
- ``on(e, s)``: ``e`` touches ``s`` and rests on its top (``s`` a fixture such as
  the table, or another entity).
- ``in(o, c)``: the centre of ``o`` lies inside the interior volume of container ``c``.
- ``holding(o)``: the gripper holds ``o``.
- ``near(a, b)``: the horizontal gap between the footprints of two entities is
  below NEAR_DISTANCE (both orders are listed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from llcps.domain import EntityFeatures, State, fluent
from llcps.trial_records import Body
from llcps.sim import geometry as g
from llcps.sim.contact import TOUCH_DISTANCE
from llcps.sim.robot import RAY_MASK
from llcps.sim.specs import FLOOR, FLOOR_HALF_WIDTH, TABLE

if TYPE_CHECKING:
    from llcps.sim.world import World

#: Footprint gap below which two entities are near (m).
NEAR_DISTANCE = 0.15
#: Largest forward-kinematics error of a reachable pose (m) and tilt from straight down (rad).
REACH_TOLERANCE = 0.02
REACH_TILT = 0.3
#: The tool pose tested for reachability is this far above the entity's top (m).
REACH_ABOVE = 0.02
#: Start height of the vertical approach ray above the entity's top (m).
APPROACH_HEIGHT = 0.5
#: Fraction of an entity's extent by which visibility sample points spread from its centre.
SAMPLE_SPREAD = 0.35


@dataclass(frozen=True)
class PerceptionCamera:
    """The robot's fixed camera: behind and above the base, looking over the table."""

    eye: tuple[float, float, float] = (-0.3, 0.0, 0.75)
    target: tuple[float, float, float] = (0.6, 0.0, 0.0)
    fov: float = 80.0  # full cone angle, degrees


CAMERA = PerceptionCamera()


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _norm(v):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (v[0] / n, v[1] / n, v[2] / n)


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def visible_entities(world: "World", camera: PerceptionCamera = CAMERA) -> set[str]:
    """Entities with a line of sight from the camera (one batch of ray tests)."""
    eye = camera.eye
    forward = _norm(_sub(camera.target, eye))
    right = _norm(_cross(forward, (0.0, 0.0, 1.0)))
    up = _cross(right, forward)
    cos_half = math.cos(math.radians(camera.fov / 2.0))
    starts, ends, owners = [], [], []
    for name in world.entities:
        centre = world.center(name)
        lo, hi = world.aabb(name)
        span = SAMPLE_SPREAD * min(hi[0] - lo[0], hi[1] - lo[1])
        rise = SAMPLE_SPREAD * (hi[2] - lo[2])
        for a, b in ((0.0, 0.0), (span, 0.0), (-span, 0.0), (0.0, rise), (0.0, -rise)):
            pt = (
                centre[0] + a * right[0] + b * up[0],
                centre[1] + a * right[1] + b * up[1],
                centre[2] + a * right[2] + b * up[2],
            )
            ray = _sub(pt, eye)
            dist = math.sqrt(ray[0] ** 2 + ray[1] ** 2 + ray[2] ** 2)
            if (ray[0] * forward[0] + ray[1] * forward[1] + ray[2] * forward[2]) / dist < cos_half:
                continue
            starts.append(eye)
            ends.append((eye[0] + 2 * ray[0], eye[1] + 2 * ray[1], eye[2] + 2 * ray[2]))
            owners.append(name)
    if not starts:
        return set()
    hits = world.client.rayTestBatch(starts, ends, collisionFilterMask=RAY_MASK)
    names = world.names
    return {owner for owner, hit in zip(owners, hits) if names.get(hit[0]) == owner}


def approach_clear(world: "World", name: str) -> bool:
    """Whether the vertical approach to ``name`` from above is free of other bodies."""
    lo, hi = world.aabb(name)
    cx, cy, _ = world.center(name)
    body = world.body(name)
    start = (cx, cy, hi[2] + APPROACH_HEIGHT)
    if world.entity(name).is_container:
        # nothing over the opening: the first hit is the container itself or lies below the rim
        hit = world.client.rayTestBatch([start], [(cx, cy, lo[2] - 0.01)], collisionFilterMask=RAY_MASK)[0]
        return hit[0] < 0 or hit[0] == body or hit[3][2] < hi[2] - 0.005
    hit = world.client.rayTestBatch([start], [(cx, cy, lo[2] - 0.01)], collisionFilterMask=RAY_MASK)[0]
    return hit[0] == body


def is_reachable(world: "World", name: str) -> bool:
    """Reachability of one entity (see the module docstring)."""
    if not approach_clear(world, name):
        return False
    cx, cy, _ = world.center(name)
    z = g.top(world, name) + REACH_ABOVE
    err, tilt = world.robot.reach_error((cx, cy, z), math.atan2(cy, cx) if math.hypot(cx, cy) > 1e-6 else 0.0)
    return err <= REACH_TOLERANCE and tilt <= REACH_TILT


def contacts(world: "World") -> set[tuple[str, str]]:
    """Touching pairs (sorted names) among entities and fixtures, from current contact points."""
    names = world.names
    robot = world.robot.body_id
    fixtures = world.fixtures
    pairs: set[tuple[str, str]] = set()
    for cp in world.client.getContactPoints():
        a, b = cp[1], cp[2]
        if a == robot or b == robot or cp[8] > TOUCH_DISTANCE:
            continue
        na, nb = names.get(a), names.get(b)
        if na is None or nb is None or na == nb or (na in fixtures and nb in fixtures):
            continue
        pairs.add((na, nb) if na < nb else (nb, na))
    return pairs


def perceive(world: "World") -> State:
    """The symbolic state s of the world as it is now."""
    world.client.performCollisionDetection()
    facts = set()
    touching = contacts(world)
    boxes = {n: world.aabb(n) for n in list(world.entities) + list(world.fixtures)}
    inside = set()
    for o, ent in world.entities.items():
        if ent.kind != "object":
            continue
        centre = world.center(o)
        for c, cont in world.entities.items():
            if cont.is_container and g.in_interior(world, centre, c):
                inside.add((o, c))
                facts.add(fluent("in", o, c))
    tops = {n: box[1][2] for n, box in boxes.items()}
    tops[FLOOR] = world.scene.table.floor_z  # a plane's bounding box is unbounded
    for a, b in touching:
        facts.add(fluent("touching", a, b))
        for upper, base in ((a, b), (b, a)):
            if upper in world.entities and (upper, base) not in inside:
                if boxes[upper][0][2] >= tops[base] - 0.01 and boxes[upper][1][2] > tops[base]:
                    facts.add(fluent("on", upper, base))
    for name in visible_entities(world):
        facts.add(fluent("visible", name))
    for name in world.entities:
        if is_reachable(world, name):
            facts.add(fluent("reachable", name))
    grasped = world.robot.grasped
    if grasped is not None and grasped in world.names:
        facts.add(fluent("holding", world.names[grasped]))
    ents = sorted(world.entities)
    for i, a in enumerate(ents):
        for b in ents[i + 1 :]:
            if g.footprint_gap(boxes[a], boxes[b]) < NEAR_DISTANCE:
                facts.add(fluent("near", a, b))
                facts.add(fluent("near", b, a))
    return frozenset(facts)


def entity_features(world: "World", name: str) -> EntityFeatures:
    """Table-1 features of an entity: shape, volume, colour, and its position
    relative to the robot base as a magnitude and unit vector."""
    spec = world.entity(name).spec
    x, y, z = world.center(name)  # the robot base is the world origin
    mag = math.sqrt(x * x + y * y + z * z)
    ux, uy, uz = (x / mag, y / mag, z / mag) if mag > 0 else (0.0, 0.0, 0.0)
    return EntityFeatures(
        shape=spec.shape,
        volume=spec.volume,
        color=spec.color,
        vector_magnitude=mag,
        unit_x=ux,
        unit_y=uy,
        unit_z=uz,
    )


def scene_bodies(world: "World") -> tuple[Body, ...]:
    """Every entity and fixture as it is now: kind, shape and bounding box.

    What a trial records beside its symbolic change, so that a world model can say
    where an atom's bodies are relative to a candidate's arguments. Entities come in
    scene order, then the table, the floor and the scene's other fixtures.
    """
    bodies = []
    for name, entity in world.entities.items():
        lo, hi = world.aabb(name)
        bodies.append(Body(name, entity.kind, entity.spec.shape, lo, hi, world.center(name)))
    floor_z = world.scene.table.floor_z
    w = FLOOR_HALF_WIDTH
    for name in world.fixtures:
        if name == FLOOR:
            lo, hi = (-w, -w, floor_z), (w, w, floor_z)
            kind = "floor"
        else:
            lo, hi = world.aabb(name)
            kind = "table" if name == TABLE else "fixture"
        centre = tuple((a + b) / 2.0 for a, b in zip(lo, hi))
        bodies.append(Body(name, kind, None, lo, hi, centre))
    return tuple(bodies)
