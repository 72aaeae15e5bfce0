"""Random interactions for pretraining the world model: a random scene, settled
and checked, and a random controller call on random arguments.

The paper blames part of its weak first result on objects falling off the table
before exploration began. Here every sampled scene is built and settled first,
and a layout in which anything fell, slid or toppled is rejected and redrawn, so
that each trial starts from a calm, meaningful state.

Layouts are varied on purpose, so that every kind of fluent change of Table 2
happens in pretraining: objects beyond the arm's reach, objects stacked on others
(blocking the top approach), objects behind tall ones (hidden from the camera),
objects under a shelf, objects near a table edge (which a push sends to the
floor), open boxes on the table (some holding an object) and buckets on the
floor beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import numpy as np

from llcps.domain import ACTIONS, COLORS, ORIENTATIONS, ControllerParams
from llcps.trial_records import TrialSpec
from llcps.sim.builders import bucket, inside, open_box, shelf, solid, stacked
from llcps.sim.specs import EntitySpec, FixtureSpec, TableSpec
from llcps.sim.geometry import in_interior
from llcps.sim.perception import CAMERA
from llcps.sim.world import SETTLE_STEPS, SceneSpec, World


@dataclass(frozen=True)
class CatalogItem:
    """A kind of object the robot meets: shape and a size range (m), mass from density."""

    shape: str
    min_size: tuple[float, ...]
    max_size: tuple[float, ...]


#: Objects of the catalog. Sizes are ranges of the ``size`` argument of :func:`solid`.
#: Everything up to 7 cm wide fits the gripper (8 cm opening).
CATALOG: Mapping[str, CatalogItem] = {
    "ball": CatalogItem("sphere", (0.035,), (0.065,)),
    "cube": CatalogItem("box", (0.035, 0.035, 0.035), (0.06, 0.06, 0.06)),
    "brick": CatalogItem("box", (0.04, 0.06, 0.03), (0.06, 0.12, 0.05)),
    "can": CatalogItem("cylinder", (0.035, 0.05), (0.065, 0.1)),
    "tall_block": CatalogItem("box", (0.05, 0.07, 0.14), (0.06, 0.12, 0.2)),
    "tall_can": CatalogItem("cylinder", (0.05, 0.14), (0.065, 0.2)),
}


#: Controller settings drawn for pretraining: rate log-uniform (m/s), magnitude uniform (m).
RATE_RANGE: tuple[float, float] = (0.05, 1.0)
MAGNITUDE_RANGE: tuple[float, float] = (0.02, 0.4)
#: Steps a layout always takes to settle, and how far anything may move meanwhile (m).
SETTLE_MIN_STEPS = 48
MOVE_TOLERANCE = 0.01
#: Layouts drawn before giving up (a bug, not bad luck, if ever reached).
MAX_ATTEMPTS = 200

#: Table region where objects are placed (m).
X_RANGE: tuple[float, float] = (0.25, 1.0)
Y_HALF = 0.5
#: Distances from the robot base of "far" placements (the top-down reach is about 0.8 m).
FAR_RING: tuple[float, float] = (0.8, 0.95)
#: How an object is placed, with weights; modes whose prerequisite is missing fall back to "free".
PLACEMENTS: dict[str, float] = {
    "free": 0.26,
    "edge": 0.16,
    "far": 0.12,
    "behind": 0.14,
    "stack": 0.16,
    "inside": 0.10,
    "under_shelf": 0.08,
}
#: Catalog items with weights.
ITEMS: dict[str, float] = {"ball": 0.15, "cube": 0.25, "brick": 0.15, "can": 0.2, "tall_block": 0.12, "tall_can": 0.13}
SMALL_ITEMS: dict[str, float] = {"ball": 0.3, "cube": 0.4, "brick": 0.3}
CONTAINER_ACTIONS = ("remove_from_container", "place_in_container")


class _Layout:
    """Footprints already used on the table while a scene is drawn."""

    def __init__(self, rng: np.random.Generator, table: TableSpec) -> None:
        self.rng = rng
        self.table = table
        self.discs: list[tuple[float, float, float]] = []
        self.entities: list[EntitySpec] = []
        self.fixtures: list[FixtureSpec] = []
        self.names: set[str] = set()

    def name(self, stem: str) -> str:
        k = 1
        name = stem
        while name in self.names:
            k += 1
            name = f"{stem}_{k}"
        self.names.add(name)
        return name

    def free(self, x: float, y: float, r: float) -> bool:
        t = self.table
        if not (t.x_min + 0.3 + r <= x <= t.x_max - r and abs(y) <= t.y_half - r):
            return False
        return all(math.hypot(x - ox, y - oy) >= r + orad + 0.01 for ox, oy, orad in self.discs)

    def add(self, spec: EntitySpec, *, footprint: bool = True) -> None:
        self.entities.append(spec)
        if footprint:
            self.discs.append((spec.position[0], spec.position[1], _radius(spec)))


def _radius(spec: EntitySpec) -> float:
    return 0.5 * math.hypot(spec.size[0], spec.size[1])


def _choice(rng: np.random.Generator, weights: dict[str, float]) -> str:
    keys = list(weights)
    w = np.array([weights[k] for k in keys], dtype=float)
    return keys[int(rng.choice(len(keys), p=w / w.sum()))]


def _object(rng: np.random.Generator, item: str, name: str, at: Sequence[float], on: float = 0.0) -> EntitySpec:
    entry = CATALOG[item]
    size = tuple(float(rng.uniform(lo, hi)) for lo, hi in zip(entry.min_size, entry.max_size))
    color = COLORS[int(rng.integers(len(COLORS)))]
    yaw = float(rng.uniform(-math.pi / 4, math.pi / 4)) if entry.shape == "box" else 0.0
    return solid(name, entry.shape, color, size if len(size) > 1 else size[0], at=at, on=on, yaw=yaw)


def _place(lay: _Layout, spec: EntitySpec, mode: str) -> EntitySpec | None:
    """Position ``spec`` on the table according to ``mode``; None when no spot is found."""
    rng, t = lay.rng, lay.table
    r = _radius(spec)
    for _ in range(40):
        if mode == "edge":
            side = int(rng.integers(3))
            gap = float(rng.uniform(0.0, 0.03)) + r
            if side == 0:
                x, y = t.x_max - gap, float(rng.uniform(-Y_HALF, Y_HALF))
            else:
                x, y = float(rng.uniform(0.35, 0.85)), (1 if side == 1 else -1) * (t.y_half - gap)
        elif mode == "far":  # a ring just beyond the arm's top-down reach
            radius, bearing = float(rng.uniform(*FAR_RING)), float(rng.uniform(-0.6, 0.6))
            x, y = radius * math.cos(bearing), radius * math.sin(bearing)
        elif mode == "behind":
            tall = [e for e in lay.entities if e.kind == "object" and e.size[2] >= 0.12 and e.position[2] < 0.2]
            if not tall:
                return None
            occ = tall[int(rng.integers(len(tall)))]
            ux, uy = occ.position[0] - CAMERA.eye[0], occ.position[1] - CAMERA.eye[1]
            n = math.hypot(ux, uy)
            ux, uy = ux / n, uy / n
            dist = _radius(occ) + r + float(rng.uniform(0.012, 0.05))
            lateral = float(rng.uniform(-0.01, 0.01))
            x, y = occ.position[0] + ux * dist - uy * lateral, occ.position[1] + uy * dist + ux * lateral
        elif mode == "under_shelf":
            boards = [f for f in lay.fixtures if not f.name.endswith("_post")]
            if not boards:
                return None
            b = boards[0]
            clearance = b.position[2] - b.size[2] / 2
            if spec.size[2] > clearance - 0.03:
                return None
            x = b.position[0] + float(rng.uniform(-0.35, 0.2)) * b.size[0]
            y = b.position[1] + float(rng.uniform(-0.4, 0.4)) * b.size[1]
        else:
            x, y = float(rng.uniform(*X_RANGE)), float(rng.uniform(-Y_HALF, Y_HALF))
        if lay.free(x, y, r):
            return spec.moved((x, y, spec.position[2]))
    return None


def _stack(lay: _Layout, spec: EntitySpec) -> EntitySpec | None:
    if spec.shape == "sphere":
        return None
    bases = [
        e
        for e in lay.entities
        if e.kind == "object"
        and e.shape != "sphere"
        and abs(e.position[2] - e.size[2] / 2) < 1e-6
        and min(e.size[:2]) >= max(spec.size[:2]) - 0.005
        and e.size[2] <= 0.1
        and not any(o.position[:2] == e.position[:2] and o is not e for o in lay.entities)
    ]
    if not bases:
        return None
    base = bases[int(lay.rng.integers(len(bases)))]
    return replace(stacked(spec, base), yaw=base.yaw)


def _inside(lay: _Layout, spec: EntitySpec) -> EntitySpec | None:
    boxes = [e for e in lay.entities if e.kind == "container" and e.shape == "box" and e.position[2] > 0]
    if not boxes:
        return None
    box = boxes[int(lay.rng.integers(len(boxes)))]
    room_x = box.size[0] / 2 - box.wall - _radius(spec) - 0.005
    room_y = box.size[1] / 2 - box.wall - _radius(spec) - 0.005
    if room_x < 0 or room_y < 0 or spec.size[2] > 2 * box.size[2]:
        return None
    if any(
        e.kind == "object"
        and abs(e.position[0] - box.position[0]) < box.size[0] / 2
        and abs(e.position[1] - box.position[1]) < box.size[1] / 2
        for e in lay.entities
    ):
        return None
    # bias toward the wall nearer the camera, where the contents are hidden
    offset = (float(lay.rng.uniform(-1.0, 0.2)) * room_x, float(lay.rng.uniform(-1.0, 1.0)) * room_y)
    return replace(inside(spec, box, offset=offset), yaw=box.yaw)


def sample_scene(rng: np.random.Generator, *, need_container: bool = False, want_inside: bool = False) -> SceneSpec:
    """Draw a layout (not yet settled or checked)."""
    table = TableSpec()
    lay = _Layout(rng, table)
    if rng.random() < (0.75 if need_container else 0.4):
        size = (float(rng.uniform(0.16, 0.24)), float(rng.uniform(0.16, 0.24)), float(rng.uniform(0.06, 0.13)))
        color = COLORS[int(rng.integers(len(COLORS)))]
        spec = _place(
            lay,
            open_box(lay.name(f"{color}_bin"), color, at=(0, 0), size=size, yaw=float(rng.uniform(-0.4, 0.4))),
            "free",
        )
        if spec is not None:
            lay.add(spec)
    has_box = bool(lay.entities)
    if rng.random() < (1.0 if need_container and not has_box else 0.35):
        diameter, height = float(rng.uniform(0.22, 0.3)), float(rng.uniform(0.16, 0.26))
        side = int(rng.integers(3))
        gap = diameter / 2 + float(rng.uniform(0.0, 0.04))
        if side == 0:
            at = (table.x_max + gap, float(rng.uniform(-0.35, 0.35)))
        else:
            at = (float(rng.uniform(0.3, 0.85)), (1 if side == 1 else -1) * (table.y_half + gap))
        color = COLORS[int(rng.integers(len(COLORS)))]
        lay.add(
            bucket(lay.name(f"{color}_bucket"), color, at=at, diameter=diameter, height=height, table=table),
            footprint=False,
        )
    if rng.random() < 0.25:
        at = (float(rng.uniform(0.4, 0.7)), float(rng.uniform(-0.35, 0.35)))
        if lay.free(at[0], at[1], 0.05):
            board = shelf("shelf", at=at, clearance=float(rng.uniform(0.12, 0.2)), size=(0.24, 0.3, 0.02))
            lay.fixtures.extend(board)
            post = board[1]
            lay.discs.append((post.position[0], post.position[1], 0.03))

    n_objects = int(rng.integers(2, 6))
    placed_inside = False
    for k in range(n_objects):
        mode = "inside" if (want_inside and not placed_inside and has_box) else _choice(rng, PLACEMENTS)
        # what goes into a bin is mostly small enough to vanish below its rim
        item = _choice(rng, SMALL_ITEMS if mode == "inside" and rng.random() < 0.7 else ITEMS)
        spec = _object(rng, item, lay.name(f"obj{k + 1}"), (0.0, 0.0))
        if mode == "stack":
            out = _stack(lay, spec)
        elif mode == "inside":
            out = _inside(lay, spec)
            placed_inside = placed_inside or out is not None
        else:
            out = _place(lay, spec, mode)
        if out is None and mode != "free":
            out = _place(lay, spec, "free")
        if out is not None:
            lay.add(out, footprint=mode not in ("stack", "inside"))
    # objects get readable, unique names: colour and item
    renamed = []
    taken: set[str] = set()
    for e in lay.entities:
        if e.kind == "object":
            stem = f"{e.color}_{e.shape}"
            name, k = stem, 1
            while name in taken:
                k += 1
                name = f"{stem}_{k}"
            e = replace(e, name=name)
        taken.add(e.name)
        renamed.append(e)
    return SceneSpec(tuple(renamed), tuple(lay.fixtures), table, name="pretrain")


def sample_spec(
    rng: np.random.Generator, scene: SceneSpec, action: str | None = None, world: World | None = None
) -> TrialSpec:
    """Draw a controller call on the scene's entities."""
    action = action or ACTIONS[int(rng.integers(len(ACTIONS)))]
    objects = [e.name for e in scene.entities if e.kind == "object"]
    containers = [e.name for e in scene.entities if e.kind == "container"]
    everything = [e.name for e in scene.entities]

    def pick(pool: Sequence[str]) -> str:
        return pool[int(rng.integers(len(pool)))]

    if action == "push":
        args: tuple[str, ...] = (pick(objects) if not containers or rng.random() < 0.8 else pick(containers),)
    elif action == "push_together":
        a = pick(objects) if not containers or rng.random() < 0.85 else pick(containers)
        args = (a, pick([n for n in everything if n != a]))
    else:
        contents = {c: [o for o in objects if world is not None and _is_in(world, o, c)] for c in containers}
        full = [c for c in containers if contents[c]]
        if action == "remove_from_container" and full and rng.random() < 0.9:
            c = pick(full)
            o = pick(contents[c])
        else:
            c = pick(containers)
            o = pick([o for o in objects if o not in contents[c]] or objects)
        args = (o, c)
    rate = float(math.exp(rng.uniform(math.log(RATE_RANGE[0]), math.log(RATE_RANGE[1]))))
    magnitude = float(rng.uniform(*MAGNITUDE_RANGE))
    orientation = ORIENTATIONS[int(rng.integers(len(ORIENTATIONS)))]
    return TrialSpec(action, args, ControllerParams(rate=rate, movement_magnitude=magnitude, orientation=orientation))


def _is_in(world: World, obj: str, container: str) -> bool:
    return in_interior(world, world.center(obj), container)


def settled_ok(world: World) -> bool:
    """Whether every entity is still where its spec put it (nothing fell, slid or toppled)."""
    for name, ent in world.entities.items():
        if math.dist(world.center(name), ent.spec.position) > MOVE_TOLERANCE:
            return False
    return True


def sample_interaction(
    rng: np.random.Generator, *, world: World | None = None, max_attempts: int = MAX_ATTEMPTS
) -> tuple[SceneSpec, TrialSpec]:
    """Draw a settled, checked scene and a random controller call on it.

    Args:
        rng: the only source of randomness.
        world: a world to build the scene in (left settled, ready to snapshot);
            a temporary one is used when omitted.
        max_attempts: layouts to draw before giving up.

    Returns:
        The scene (as built, before settling) and the trial to run in it.
    """
    own = world is None
    w = world if world is not None else World(visuals=False)
    try:
        action = ACTIONS[int(rng.integers(len(ACTIONS)))]
        need = action in CONTAINER_ACTIONS
        for _ in range(max_attempts):
            want_inside = action == "remove_from_container" and rng.random() < 0.8
            scene = sample_scene(rng, need_container=need, want_inside=want_inside)
            if need and not any(e.kind == "container" for e in scene.entities):
                continue
            if sum(e.kind == "object" for e in scene.entities) < 1:
                continue
            w.load(scene)
            w.settle(max_steps=SETTLE_STEPS, min_steps=SETTLE_MIN_STEPS)
            if settled_ok(w):
                return scene, sample_spec(rng, scene, action, w)
        raise RuntimeError(f"no stable layout in {max_attempts} attempts")
    finally:
        if own:
            w.close()
