"""The goal-aware outcome as numbers: (candidate, atom) pairs in roles and relative geometry.

Omega (Table 2) says what *kind* of fluent a trial changed; a failure asks for
particular ground atoms, "(in x c)". The goal-aware outcome is one binary question per
(candidate c, ground atom m, sign): after c, has m become true (sign +) or stopped being
true (sign -)? One model answers it for every predicate, entity and scene, because m is
encoded without names:

- by its predicate and sign, and the *role* each of its bodies plays for c: argument 1,
  argument 2, or else the kind the domain types the body as (:data:`~llcps.domain.BODY_KINDS`:
  an object, a container, the support fixture the scene stands on, the ground, another
  fixture), read from the stored bodies, never from a body's name (:data:`ROLES`);
- by relational geometry in the robot frame: where m's bodies lie relative to c's first
  argument (offset, horizontal distance, height of their top over its bottom, size) and
  to its second; the direction c moves its first argument in (:func:`motion_direction`)
  against the direction to m's other body (cosine, distance along and across it, and what
  is left of the movement magnitude after covering that distance);
- by c's own action, orientation, rate and magnitude, and its arguments' shape, size and
  position.

A *fixture* (support, ground, wall) is placed at its point nearest to argument 1, an entity
at its centre. Training examples come from stored trials with their
:class:`~llcps.trial_records.TrialChange`: every ground atom over the trial's scene is one
example, labelled by whether the trial changed it the way its truth before allowed
(:func:`trial_examples`). All changed atoms and all atoms touching an argument are kept;
of the rest (bodies the trial did not act on, nearly always unchanged) a bounded,
deterministic sample is kept with weights that stand for the rest, so each trial gives
at most about a hundred examples.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass
from typing import Callable, Collection, Iterable, Mapping, Sequence

import numpy as np

from llcps.domain import ACTIONS, BODY_KINDS, ORIENTATIONS, PREDICATES, PUSH_DIRECTION, SHAPES, SIDE, SYMMETRIC_PREDICATES, Fluent, format_fluent
from llcps.trial_records import Body, TrialChange, TrialRecord, TrialSpec
from llcps.errors import LlcpsError

#: What a body of an atom is for a candidate: one of its arguments, or else its kind.
ROLES: tuple[str, ...] = ("arg1", "arg2", *BODY_KINDS)
#: The second slot of a one-place predicate.
NO_ROLE = "none"
SECOND_ROLES = ROLES + (NO_ROLE,)
_ARG2_SHAPES = SHAPES + (NO_ROLE,)

#: Unchanged atoms that involve no argument kept per trial (the rest stand behind them by weight).
OTHER_NEGATIVES = 8
#: Sizes and offsets are clipped to this (m): the ground is not 6 m "bigger" than the support in any useful sense.
CLIP = 1.0


def onehot(prefix: str, values: Sequence[str]) -> tuple[str, ...]:
    return tuple(f"{prefix}={v}" for v in values)


CATEGORICAL_FEATURES: tuple[str, ...] = (
    *onehot("action", ACTIONS),
    *onehot("orientation", ORIENTATIONS),
    *onehot("predicate", PREDICATES),
    "add",
    *onehot("role1", ROLES),
    *onehot("role2", SECOND_ROLES),
    *onehot("arg1_shape", SHAPES),
    *onehot("arg2_shape", _ARG2_SHAPES),
)

_SLOT = ("dx", "dy", "dz", "distance", "size_x", "size_y", "size_z", "top_over_arg1", "distance_from_arg2")

CONTINUOUS_FEATURES: tuple[str, ...] = (
    "rate",
    "movement_magnitude",
    "arg1_x",
    "arg1_y",
    "arg1_z",
    "arg1_reach",
    "arg1_size_x",
    "arg1_size_y",
    "arg1_size_z",
    "arg2_size_x",
    "arg2_size_y",
    "arg2_size_z",
    "arg2_distance",
    *(f"body1_{name}" for name in _SLOT),
    *(f"body2_{name}" for name in _SLOT),
    "motion_cos",
    "motion_along",
    "motion_across",
    "motion_margin",
)

#: Every column of an encoded (candidate, atom) row, categorical one-hots first.
GOAL_FEATURES: tuple[str, ...] = CATEGORICAL_FEATURES + CONTINUOUS_FEATURES
N_CATEGORICAL = len(CATEGORICAL_FEATURES)
N_GOAL_FEATURES = len(GOAL_FEATURES)
#: True for the continuous columns (the ones a learner scales or bins).
CONTINUOUS_MASK = np.array([False] * N_CATEGORICAL + [True] * len(CONTINUOUS_FEATURES))

FEATURE_INDEX = {name: i for i, name in enumerate(GOAL_FEATURES)}
_ROLE_INDEX = {r: i for i, r in enumerate(SECOND_ROLES)}
_FIRST_CONTINUOUS = N_CATEGORICAL


@dataclass(frozen=True)
class GoalAtom:
    """One atom a failure lacks: ``atom`` must become true (``add``) or stop being true."""

    atom: Fluent
    add: bool

    @property
    def label(self) -> str:
        return ("+" if self.add else "-") + format_fluent(self.atom)


@dataclass(frozen=True)
class GoalQuery:
    """What goal-directed ranking asks a world model.

    Attributes:
        candidates: the candidate trials, in any order.
        atoms: the missing effects of the failure.
        bodies: the scene the candidates would start from (the failure state).
        before: the symbolic state there.
        claimed: per candidate, per atom: whether the robot's knowledge base claims
            the candidate's action has that effect (empty: no claims known).
    """

    candidates: tuple[TrialSpec, ...]
    atoms: tuple[GoalAtom, ...]
    bodies: tuple[Body, ...]
    before: frozenset[Fluent] = frozenset()
    claimed: tuple[tuple[bool, ...], ...] = ()

    def __post_init__(self) -> None:
        if self.claimed and (len(self.claimed) != len(self.candidates) or any(len(c) != len(self.atoms) for c in self.claimed)):
            raise ValueError("claimed must hold one flag per candidate and atom")

    def claimed_rows(self) -> np.ndarray:
        """The claims as one flag per encoded row (candidate-major, as :func:`encode_queries`)."""
        if not self.claimed:
            return np.zeros(len(self.candidates) * len(self.atoms), dtype=bool)
        return np.array(self.claimed, dtype=bool).reshape(-1)

    @classmethod
    def from_missing(
        cls,
        candidates: Iterable[TrialSpec],
        *,
        missing_add: Iterable[Fluent],
        missing_del: Iterable[Fluent],
        bodies: Iterable[Body],
        before: Iterable[Fluent] = (),
        claims: Callable[[TrialSpec, Fluent, bool], bool] | None = None,
    ) -> GoalQuery:
        """A query for a failure's missing add and delete effects (sorted, so the order is fixed).

        Args:
            claims: ``claims(candidate, atom, add)``: whether the robot's knowledge base
                claims the candidate makes ``atom`` true (``add``) or false.
        """
        atoms = tuple(GoalAtom(a, True) for a in sorted(missing_add)) + tuple(
            GoalAtom(a, False) for a in sorted(missing_del)
        )
        specs = tuple(candidates)
        claimed = () if claims is None else tuple(tuple(bool(claims(c, g.atom, g.add)) for g in atoms) for c in specs)
        return cls(specs, atoms, tuple(bodies), frozenset(before), claimed)


class Scene:
    """The bodies of one scene, indexed for encoding many rows against it."""

    def __init__(self, bodies: Iterable[Body]) -> None:
        self.bodies: dict[str, Body] = {b.name: b for b in bodies}

    def role(self, name: str, arguments: tuple[str, ...]) -> str:
        if arguments and name == arguments[0]:
            return "arg1"
        if len(arguments) > 1 and name == arguments[1]:
            return "arg2"
        return self.bodies[name].kind  # a body's kind is its role (Body checks it is one of BODY_KINDS)

    def point(self, name: str, near: tuple[float, float, float]) -> tuple[float, float, float]:
        """Where a body is, seen from ``near``: an entity's centre, a fixture's nearest point."""
        body = self.bodies[name]
        if body.is_entity:
            return body.centre
        lo, hi = body.lo, body.hi
        return (min(max(near[0], lo[0]), hi[0]), min(max(near[1], lo[1]), hi[1]), min(max(near[2], lo[2]), hi[2]))


def motion_direction(spec: TrialSpec, scene: Scene) -> tuple[float, float]:
    """The horizontal direction a controller moves its first argument in.

    A push moves it along its orientation's push direction; push_together and
    place_in_container move it toward the second argument; remove_from_container sets
    it down toward its orientation's side (docs/controllers.md).
    """
    if spec.action == "push":
        return PUSH_DIRECTION[spec.params.orientation]
    if spec.action == "remove_from_container":
        return SIDE[spec.params.orientation]
    a, b = scene.bodies[spec.arguments[0]].centre, scene.bodies[spec.arguments[1]].centre
    dx, dy = b[0] - a[0], b[1] - a[1]
    n = math.hypot(dx, dy)
    return (dx / n, dy / n) if n > 1e-9 else (1.0, 0.0)


def _clip(v: float) -> float:
    return CLIP if v > CLIP else (-CLIP if v < -CLIP else v)


def _size(body: Body) -> tuple[float, float, float]:
    return (_clip(body.hi[0] - body.lo[0]), _clip(body.hi[1] - body.lo[1]), _clip(body.hi[2] - body.lo[2]))


class _Candidate:
    """The parts of a row that depend on the candidate only (computed once per candidate)."""

    __slots__ = ("spec", "head", "continuous", "a1", "a1_bottom", "a2", "direction", "magnitude")

    def __init__(self, spec: TrialSpec, scene: Scene) -> None:
        self.spec = spec
        bodies = scene.bodies
        arg1 = bodies[spec.arguments[0]]
        arg2 = bodies[spec.arguments[1]] if len(spec.arguments) > 1 else None
        head = [
            FEATURE_INDEX[f"action={spec.action}"],
            FEATURE_INDEX[f"orientation={spec.params.orientation}"],
            FEATURE_INDEX[f"arg1_shape={arg1.shape}"],
            FEATURE_INDEX[f"arg2_shape={arg2.shape if arg2 is not None else NO_ROLE}"],
        ]
        self.head = head
        a1 = arg1.centre
        self.a1 = a1
        self.a1_bottom = arg1.lo[2]
        self.a2 = arg2.centre if arg2 is not None else None
        s1 = _size(arg1)
        s2 = _size(arg2) if arg2 is not None else (0.0, 0.0, 0.0)
        self.continuous = [
            spec.params.rate,
            spec.params.movement_magnitude,
            a1[0],
            a1[1],
            a1[2],
            math.hypot(a1[0], a1[1]),
            *s1,
            *s2,
            math.hypot(self.a2[0] - a1[0], self.a2[1] - a1[1]) if self.a2 is not None else 0.0,
        ]
        self.direction = motion_direction(spec, scene)
        self.magnitude = spec.params.movement_magnitude


def _slot_values(cand: _Candidate, scene: Scene, name: str) -> tuple[list[float], tuple[float, float, float]]:
    p = scene.point(name, cand.a1)
    a1 = cand.a1
    dx, dy, dz = p[0] - a1[0], p[1] - a1[1], p[2] - a1[2]
    body = scene.bodies[name]
    from_arg2 = math.hypot(p[0] - cand.a2[0], p[1] - cand.a2[1]) if cand.a2 is not None else 0.0
    values = [
        _clip(dx),
        _clip(dy),
        _clip(dz),
        _clip(math.hypot(dx, dy)),
        *_size(body),
        _clip(body.hi[2] - cand.a1_bottom),
        _clip(from_arg2),
    ]
    return values, p


_ZERO_SLOT = [0.0] * len(_SLOT)


def _ordered(atom: Fluent, cand: _Candidate, scene: Scene) -> tuple[str, ...]:
    """The atom's bodies in slot order; a symmetric predicate's by role, then distance to argument 1."""
    names = atom[1:]
    if atom[0] in SYMMETRIC_PREDICATES and len(names) == 2:
        args = cand.spec.arguments

        def key(name: str) -> tuple[int, float, str]:
            p = scene.point(name, cand.a1)
            return (_ROLE_INDEX[scene.role(name, args)], math.dist(p, cand.a1), name)

        names = tuple(sorted(names, key=key))
    return names


def _row(cand: _Candidate, scene: Scene, atom: Fluent, add: bool, out: np.ndarray) -> None:
    """Write one encoded row into ``out`` (zeroed, length N_GOAL_FEATURES)."""
    names = _ordered(atom, cand, scene)
    args = cand.spec.arguments
    for i in cand.head:
        out[i] = 1.0
    out[FEATURE_INDEX[f"predicate={atom[0]}"]] = 1.0
    out[FEATURE_INDEX["add"]] = 1.0 if add else 0.0
    out[FEATURE_INDEX[f"role1={scene.role(names[0], args)}"]] = 1.0
    out[FEATURE_INDEX[f"role2={scene.role(names[1], args) if len(names) > 1 else NO_ROLE}"]] = 1.0
    slot1, p1 = _slot_values(cand, scene, names[0])
    slot2, p2 = _slot_values(cand, scene, names[1]) if len(names) > 1 else (_ZERO_SLOT, None)
    # The motion is judged against the atom's first body that is not argument 1.
    target = p1 if names[0] != args[0] else p2
    cos = along = across = 0.0
    if target is not None:
        dx, dy = target[0] - cand.a1[0], target[1] - cand.a1[1]
        dist = math.hypot(dx, dy)
        ux, uy = cand.direction
        along = dx * ux + dy * uy
        across = abs(dx * uy - dy * ux)
        cos = along / dist if dist > 1e-3 else 0.0
    tail = [*cand.continuous, *slot1, *slot2, cos, _clip(along), _clip(across), _clip(cand.magnitude - along)]
    out[_FIRST_CONTINUOUS:] = tail


def encode_queries(query: GoalQuery) -> np.ndarray:
    """Rows for every (candidate, atom) of a query: float64 (n_candidates * n_atoms, d), candidate-major.

    Raises:
        LlcpsError: an atom or argument names a body the scene does not have, or an
            atom's predicate is not one perception reports.
    """
    scene = Scene(query.bodies)
    for atom in query.atoms:
        _check_atom(atom.atom, scene)
    out = np.zeros((len(query.candidates) * len(query.atoms), N_GOAL_FEATURES))
    row = 0
    for spec in query.candidates:
        for name in spec.arguments:
            if name not in scene.bodies:
                raise LlcpsError(f"candidate {spec.label} names {name!r}, which the scene does not have")
        cand = _Candidate(spec, scene)
        for goal in query.atoms:
            _row(cand, scene, goal.atom, goal.add, out[row])
            row += 1
    return out


def _check_atom(atom: Fluent, scene: Scene) -> None:
    if atom[0] not in PREDICATES:
        raise LlcpsError(f"the goal-aware world model knows no predicate {atom[0]!r}", hint=f"predicates: {', '.join(PREDICATES)}")
    missing = [n for n in atom[1:] if n not in scene.bodies]
    if missing or not 1 <= len(atom) - 1 <= 2:
        raise LlcpsError(f"atom {format_fluent(atom)} names bodies the scene does not have: {', '.join(missing)}")


def ground_atoms(scene: Scene) -> list[Fluent]:
    """Every atom perception could report over a scene's bodies (:data:`PREDICATES`)."""
    entities = sorted(n for n, b in scene.bodies.items() if b.is_entity)
    everything = sorted(scene.bodies)
    kinds = {n: b.kind for n, b in scene.bodies.items()}
    atoms: list[Fluent] = []
    for e in entities:
        atoms += [("visible", e), ("reachable", e), ("holding", e)]
    for i, a in enumerate(everything):
        for b in everything[i + 1 :]:
            if a in entities or b in entities:
                atoms.append(("touching", a, b))
    for e in entities:
        atoms += [("on", e, s) for s in everything if s != e]
        atoms += [("near", e, other) for other in entities if other != e]
        if kinds[e] == "object":
            atoms += [("in", e, c) for c in entities if kinds[c] == "container"]
    return atoms


@dataclass(frozen=True)
class Examples:
    """Encoded training examples of the goal-aware outcome.

    Attributes:
        features: float64 (n, N_GOAL_FEATURES).
        labels: uint8 (n,): the trial changed the atom the way its truth allowed.
        weights: float64 (n,): how many atoms an example stands for.
        trial_ids: int64 (n,): the trial each example came from.
    """

    features: np.ndarray
    labels: np.ndarray
    weights: np.ndarray
    trial_ids: np.ndarray

    @classmethod
    def empty(cls) -> Examples:
        return cls(
            np.zeros((0, N_GOAL_FEATURES)), np.zeros(0, np.uint8), np.zeros(0), np.zeros(0, np.int64)
        )

    def __len__(self) -> int:
        return len(self.labels)

    @classmethod
    def concatenate(cls, parts: Sequence[Examples]) -> Examples:
        if not parts:
            return cls.empty()
        return cls(
            np.concatenate([p.features for p in parts]),
            np.concatenate([p.labels for p in parts]),
            np.concatenate([p.weights for p in parts]),
            np.concatenate([p.trial_ids for p in parts]),
        )


def _sample_key(trial: TrialRecord, atom: Fluent) -> int:
    return zlib.crc32(("|".join(atom) + f"#{trial.seed}#{trial.spec.label}").encode())


def trial_examples(
    trial: TrialRecord,
    change: TrialChange,
    *,
    other_negatives: int = OTHER_NEGATIVES,
    asked: Collection[tuple[Fluent, bool]] | None = None,
) -> Examples:
    """The examples one stored trial gives (see the module docstring).

    A trial whose arguments are not in its change's scene gives none (a damaged row).

    Args:
        asked: if given, the atoms (with their sign) a question asks for: an atom the
            trial changed that is not among them gives no example (episode evidence,
            :meth:`~llcps.models.goal.GoalHead.update`).
    """
    scene = Scene(change.bodies)
    if any(name not in scene.bodies for name in trial.spec.arguments):
        return Examples.empty()
    args = set(trial.spec.arguments)
    kept: list[tuple[Fluent, bool, int, float]] = []
    others: list[tuple[Fluent, bool]] = []
    for atom in ground_atoms(scene):
        add = atom not in change.before
        changed = atom in (change.added if add else change.deleted)
        if changed and asked is not None and (atom, add) not in asked:
            continue
        if changed or args.intersection(atom[1:]):
            kept.append((atom, add, int(changed), 1.0))
        else:
            others.append((atom, add))
    if others:
        chosen = sorted(others, key=lambda item: _sample_key(trial, item[0]))[:other_negatives]
        weight = len(others) / len(chosen)
        kept += [(atom, add, 0, weight) for atom, add in chosen]
    features = np.zeros((len(kept), N_GOAL_FEATURES))
    cand = _Candidate(trial.spec, scene)
    for i, (atom, add, _, _) in enumerate(kept):
        _row(cand, scene, atom, add, features[i])
    return Examples(
        features,
        np.array([k[2] for k in kept], dtype=np.uint8),
        np.array([k[3] for k in kept]),
        np.full(len(kept), -1 if trial.id is None else trial.id, dtype=np.int64),
    )


#: Most examples one stored trial may hold (a guard against crafted stored bytes).
MAX_TRIAL_EXAMPLES = 1 << 16
_EXAMPLES_MAGIC = b"LGX1"
_EXAMPLES_HEADER = struct.Struct("<4sIH")


def pack_examples(examples: Examples) -> bytes:
    """One trial's examples as bytes of a fixed layout (no pickle): a header (magic,
    rows, width), then the one-hot columns as bits (:func:`numpy.packbits`, row by
    row), the continuous columns as float64, the uint8 labels and the float64 weights.
    Round trips exactly."""
    n = len(examples)
    if n > MAX_TRIAL_EXAMPLES:
        raise ValueError(f"{n} examples is more than one trial may hold ({MAX_TRIAL_EXAMPLES})")
    features = np.asarray(examples.features, dtype=np.float64)
    categorical = features[:, :N_CATEGORICAL]
    if np.any((categorical != 0.0) & (categorical != 1.0)):
        raise ValueError("one-hot columns must hold 0 or 1")
    return b"".join(
        (
            _EXAMPLES_HEADER.pack(_EXAMPLES_MAGIC, n, N_GOAL_FEATURES),
            np.packbits(features[:, :N_CATEGORICAL] > 0.5, axis=1).tobytes(),
            np.ascontiguousarray(features[:, N_CATEGORICAL:], dtype="<f8").tobytes(),
            np.ascontiguousarray(examples.labels, dtype=np.uint8).tobytes(),
            np.ascontiguousarray(examples.weights, dtype="<f8").tobytes(),
        )
    )


def unpack_examples(data: bytes, trial_id: int) -> Examples:
    """Read :func:`pack_examples` bytes (untrusted: sizes, values and layout are checked).

    Raises:
        LlcpsError: not examples of this encoding (wrong magic or width, wrong length,
            too many rows, non-finite or out-of-range values).
    """
    data = bytes(data)
    if len(data) < _EXAMPLES_HEADER.size:
        raise LlcpsError("stored goal examples are truncated")
    magic, n, width = _EXAMPLES_HEADER.unpack_from(data)
    if magic != _EXAMPLES_MAGIC or width != N_GOAL_FEATURES:
        raise LlcpsError("stored goal examples are not of this encoding")
    bits = (N_CATEGORICAL + 7) // 8
    continuous = N_GOAL_FEATURES - N_CATEGORICAL
    if n > MAX_TRIAL_EXAMPLES or len(data) != _EXAMPLES_HEADER.size + n * (bits + 8 * continuous + 9):
        raise LlcpsError("stored goal examples have the wrong length")
    at = _EXAMPLES_HEADER.size
    packed = np.frombuffer(data, np.uint8, n * bits, at).reshape(n, bits)
    at += n * bits
    features = np.empty((n, N_GOAL_FEATURES))
    features[:, :N_CATEGORICAL] = np.unpackbits(packed, axis=1, count=N_CATEGORICAL)
    features[:, N_CATEGORICAL:] = np.frombuffer(data, "<f8", n * continuous, at).reshape(n, continuous)
    at += 8 * n * continuous
    labels = np.frombuffer(data, np.uint8, n, at).copy()
    weights = np.frombuffer(data, "<f8", n, at + n).astype(np.float64)
    if not np.all(np.isfinite(features)) or np.any(labels > 1) or not np.all(np.isfinite(weights) & (weights > 0.0)):
        raise LlcpsError("stored goal examples hold values out of range")
    return Examples(features, labels, weights, np.full(n, trial_id, dtype=np.int64))


class ExampleTable:
    """Examples of a growing training set, encoded once per trial (the set only grows).

    Examples encoded elsewhere (kept in the store) can be handed in (:meth:`prime`);
    :attr:`encoded` holds the ones this table encoded itself, to be kept in turn.
    """

    def __init__(self) -> None:
        self._cache: dict[int, Examples] = {}
        #: Examples this table encoded (not primed), by trial id.
        self.encoded: dict[int, Examples] = {}

    def __deepcopy__(self, memo: dict[int, object]) -> ExampleTable:
        """A copy that shares the examples: they are never changed in place, and copying
        a large training set's arrays was a fifth of a fit's time (a fit is remembered as a copy)."""
        copied = ExampleTable()
        copied._cache = dict(self._cache)
        copied.encoded = dict(self.encoded)
        return copied

    def prime(self, examples: Mapping[int, Examples]) -> None:
        """Take in examples of trials encoded before (the same encoding: :func:`trial_examples`)."""
        self._cache.update(examples)

    def encode(self, records: Sequence[TrialRecord], changes: Mapping[int, TrialChange]) -> Examples:
        """Examples of every record with a known change, in record order."""
        parts = []
        for record in records:
            change = changes.get(record.id) if record.id is not None else None
            if change is None:
                continue
            found = self._cache.get(record.id)  # type: ignore[arg-type]
            if found is None:
                found = trial_examples(record, change)
                self._cache[record.id] = found  # type: ignore[index]
                self.encoded[record.id] = found  # type: ignore[index]
            parts.append(found)
        return Examples.concatenate(parts)
