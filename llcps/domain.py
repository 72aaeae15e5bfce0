"""The paper's vocabulary as plain, frozen data: the actions of K and the settings of
their controllers R, entity features X (Table 1), fluents and symbolic states s, the
names of the meta-outcome Omega (Table 2), the body kinds, and the two conditions of a
scenario. What one trial is (its call, Omega, its stored record and the symbolic change
it made) is written in this vocabulary in :mod:`llcps.trial_records`.

Every layer speaks these types: the simulator produces them, the store persists
them, the world models learn from them and the agent reasons with them. Nothing
here imports PyBullet, SQLAlchemy, torch or the CLI.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

from llcps.errors import LlcpsError

#: The four actions of Table 1, in the order of their encoding (1..4).
ACTIONS: tuple[str, ...] = ("push", "push_together", "remove_from_container", "place_in_container")

#: The two conditions of every CPS scenario (Figure 1): in the *original* one the nominal
#: plan succeeds; in the *novelty* one the world has changed so that it fails.
CONDITIONS: tuple[str, ...] = ("original", "novelty")

#: Number of entity arguments each action controller takes.
ACTION_ARITY: Mapping[str, int] = {
    "push": 1,
    "push_together": 2,
    "remove_from_container": 2,
    "place_in_container": 2,
}

#: Approach sides of a controller. Table 1 encodes the first two; the other two
#: let a push move an entity along every horizontal axis (see docs/controllers.md).
ORIENTATIONS: tuple[str, ...] = ("left", "top", "right", "front")

#: Horizontal direction in which a push with each orientation moves its argument (robot
#: frame: +x away from the robot, +y to its left). "top" pushes near the top, along +x.
PUSH_DIRECTION: Mapping[str, tuple[float, float]] = {
    "left": (0.0, -1.0),
    "right": (0.0, 1.0),
    "front": (1.0, 0.0),
    "top": (1.0, 0.0),
}
#: Side of an entity each orientation names: where a place releases over a container,
#: and where a remove sets its object down.
SIDE: Mapping[str, tuple[float, float]] = {
    "left": (0.0, 1.0),
    "right": (0.0, -1.0),
    "front": (1.0, 0.0),
    "top": (-1.0, 0.0),
}

#: Entity shapes and colors of Table 1, in the order of their encoding.
SHAPES: tuple[str, ...] = ("sphere", "box", "cylinder")
COLORS: tuple[str, ...] = ("red", "blue", "green")

#: Largest seed accepted anywhere: every consumer (numpy, torch, scikit-learn) takes 32 bits.
MAX_SEED = 2**32 - 1
#: Largest id (trial, snapshot, run, ...) a store can hold: a signed 64-bit integer.
MAX_ID = 2**63 - 1
#: Most random interactions one pretraining run may ask for.
MAX_PRETRAIN_TRIALS = 10_000_000


def check_seed(seed: int, what: str = "seed") -> int:
    """Refuse a seed outside 0..MAX_SEED before any work starts (and anything is stored)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise LlcpsError(f"{what} must be an integer from 0 to {MAX_SEED}, got {seed!r}", hint=f"pass a {what} in 0..{MAX_SEED}")
    return seed


def check_id(value: int, what: str = "id") -> int:
    """Refuse an id no store can hold (a database would fail on it with an overflow)."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_ID:
        raise LlcpsError(f"{what} must be an integer from 0 to {MAX_ID}, got {value!r}", hint="see `llcps inspect trials` for ids")
    return value


#: Where a trial came from (``gym``: an action taken through the Gymnasium environment, :mod:`llcps.gym`).
TRIAL_SOURCES: tuple[str, ...] = ("pretrain", "plan", "exploration", "replay", "gym")

#: The six bits of Omega (Table 2), in order.
OUTCOME_NAMES: tuple[str, ...] = (
    "positive_visibility",
    "negative_visibility",
    "positive_reachability",
    "negative_reachability",
    "positive_touching",
    "negative_touching",
)

#: Fluent predicates whose changes Omega summarises, mapped to their Table-2 stem.
OUTCOME_FLUENTS: Mapping[str, str] = {
    "visible": "visibility",
    "reachable": "reachability",
    "touching": "touching",
}

Fluent = tuple[str, ...]
"""A ground atom, e.g. ``("visible", "red_box")`` or ``("touching", "a", "b")``.

Symmetric predicates (``touching``) keep their arguments sorted so that a fact has
exactly one spelling."""

State = frozenset[Fluent]
"""A symbolic state: the set of fluents that hold (negations are implicit)."""

SYMMETRIC_PREDICATES: frozenset[str] = frozenset({"touching"})

#: Every fluent predicate perception reports (see :mod:`llcps.sim.perception`).
PREDICATES: tuple[str, ...] = ("visible", "reachable", "touching", "on", "in", "holding", "near")

#: Kinds of body perception types (:func:`llcps.sim.perception.scene_bodies`): the
#: fixture the scene stands on, the ground beneath it, and any other static scenery.
SUPPORT_KIND, GROUND_KIND, FIXTURE_KIND = "table", "floor", "fixture"
#: What a body a fluent mentions is: an entity (object or container) or a fixture
#: (the support, the ground, or another piece of static scenery such as a wall).
BODY_KINDS: tuple[str, ...] = ("object", "container", SUPPORT_KIND, GROUND_KIND, FIXTURE_KIND)

#: How a trial's symbolic change came to be known (``unknown``: it could not be).
CHANGE_SOURCES: tuple[str, ...] = ("recorded", "replayed", "unknown")


def fluent(predicate: str, *arguments: str) -> Fluent:
    """Build a fluent in its canonical spelling (symmetric predicates sorted)."""
    if predicate in SYMMETRIC_PREDICATES:
        arguments = tuple(sorted(arguments))
    return (predicate, *arguments)


def format_fluent(atom: Fluent) -> str:
    """Render a fluent the PDDL way: ``(touching a b)``."""
    return "(" + " ".join(atom) + ")"


@dataclass(frozen=True)
class ControllerParams:
    """Sub-symbolic settings r_i of an action controller.

    Attributes:
        rate: end-effector speed during the action's main motion, in m/s.
        movement_magnitude: length of that motion, in metres.
        orientation: the side the end effector approaches the argument from.
    """

    rate: float
    movement_magnitude: float
    orientation: str

    def __post_init__(self) -> None:
        if self.orientation not in ORIENTATIONS:
            raise ValueError(f"unknown orientation {self.orientation!r}; expected one of {ORIENTATIONS}")
        if not self.rate > 0:
            raise ValueError(f"rate must be positive, got {self.rate}")
        if not self.movement_magnitude >= 0:
            raise ValueError(f"movement_magnitude must be >= 0, got {self.movement_magnitude}")


@dataclass(frozen=True)
class EntityFeatures:
    """The feature mapping x_i of one entity (Table 1).

    The vector is the entity's position relative to the robot base, split into its
    magnitude and unit direction.
    """

    shape: str
    volume: float
    color: str
    vector_magnitude: float
    unit_x: float
    unit_y: float
    unit_z: float

    def as_dict(self) -> dict[str, float | str]:
        return dict(self.__dict__)  # the fields, in order (asdict would deep-copy each one)


#: EntityFeatures' numbers, in the order :class:`StoredFeatures` holds them.
ENTITY_NUMBERS: tuple[str, ...] = ("volume", "vector_magnitude", "unit_x", "unit_y", "unit_z")
