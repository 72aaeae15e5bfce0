"""A seeded toy source of trials whose Omega bits depend learnably on Table 1's inputs.

Not physics: a handful of hand-written noisy rules (fast pushes knock far objects
out of reach, pushing two things together makes them touch, taking an object out of
a container makes it visible and reachable, ...). It exists to test and time the
world models without a simulator; the agent never uses it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from llcps.domain import ACTION_ARITY, ACTIONS, COLORS, GROUND_KIND, SUPPORT_KIND, ORIENTATIONS, OUTCOME_NAMES, SHAPES, ControllerParams, EntityFeatures, fluent
from llcps.trial_records import Body, Outcome, TrialChange, TrialRecord, TrialSpec
from llcps.sim.specs import FLOOR, FLOOR_HALF_WIDTH, TABLE, TableSpec


def _entity(rng: np.random.Generator) -> EntityFeatures:
    direction = rng.normal(size=3)
    direction[2] = abs(direction[2]) * 0.3
    direction /= np.linalg.norm(direction)
    return EntityFeatures(
        shape=SHAPES[rng.integers(len(SHAPES))],
        volume=float(np.exp(rng.uniform(np.log(1e-4), np.log(5e-3)))),
        color=COLORS[rng.integers(len(COLORS))],
        vector_magnitude=float(rng.uniform(0.25, 0.95)),
        unit_x=float(direction[0]),
        unit_y=float(direction[1]),
        unit_z=float(direction[2]),
    )


def _logit_probabilities(spec: TrialSpec, entities: tuple[EntityFeatures, ...]) -> np.ndarray:
    """Per-bit logits of the toy rules, in OUTCOME_NAMES order."""
    action, params, first = spec.action, spec.params, entities[0]
    energy = params.rate * params.movement_magnitude / 0.05  # ~1 for a brisk, long push
    far = first.vector_magnitude - 0.6
    small = np.log(2e-3 / first.volume)
    logits = dict.fromkeys(OUTCOME_NAMES, -3.0)
    if action == "push":
        logits["negative_reachability"] = 3.0 * (energy - 1.0) + 6.0 * far
        logits["negative_visibility"] = 2.5 * (energy - 1.5) + 1.0 * small - 1.0
        logits["positive_reachability"] = 4.0 * (-far) - 1.0 if params.orientation == "front" else -4.0
        logits["negative_touching"] = 1.5 * energy - 2.0
    elif action == "push_together":
        gap = abs(first.vector_magnitude - entities[1].vector_magnitude)
        logits["positive_touching"] = 4.0 * params.movement_magnitude / 0.15 - 8.0 * gap - 1.0
        logits["negative_reachability"] = 2.0 * (energy - 1.5) + 4.0 * far
    elif action == "remove_from_container":
        logits["negative_touching"] = 2.0 if params.orientation == "top" else -1.0
        logits["positive_visibility"] = 3.0 * params.movement_magnitude / 0.15 - 2.0 + (first.shape == "sphere")
        logits["positive_reachability"] = 1.0 - 4.0 * far
    else:  # place_in_container
        logits["positive_touching"] = 2.5 - 5.0 * far - 1.0 * (params.rate > 0.8)
        logits["negative_visibility"] = 1.0 * small - 1.5
        logits["negative_reachability"] = -2.0 + 3.0 * (entities[1].vector_magnitude - 0.6)
    return np.array([logits[name] for name in OUTCOME_NAMES])


def synthetic_trials(n: int, *, seed: int, start_id: int = 1, branch: str = "main") -> list[TrialRecord]:
    """``n`` toy pretraining trials, a deterministic function of ``seed``.

    Args:
        n: number of trials.
        seed: seeds every draw (actions, settings, entities, outcomes).
        start_id: id of the first trial (ids are consecutive).
        branch: branch name written into the records.
    """
    rng = np.random.default_rng(seed)
    records = []
    for index in range(n):
        action = ACTIONS[rng.integers(len(ACTIONS))]
        arity = ACTION_ARITY[action]
        spec = TrialSpec(
            action=action,
            arguments=tuple(f"entity{k}" for k in rng.choice(6, size=arity, replace=False)),
            params=ControllerParams(
                rate=float(rng.uniform(0.05, 1.2)),
                movement_magnitude=float(rng.uniform(0.02, 0.35)),
                orientation=ORIENTATIONS[rng.integers(len(ORIENTATIONS))],
            ),
        )
        entities = tuple(_entity(rng) for _ in range(arity))
        probability = 1.0 / (1.0 + np.exp(-_logit_probabilities(spec, entities)))
        outcome = Outcome.from_bits(rng.random(len(OUTCOME_NAMES)) < probability)
        records.append(
            TrialRecord(
                id=start_id + index,
                branch=branch,
                source="pretrain",
                spec=spec,
                features=entities,
                outcome=outcome,
                solved=False,
                sim_steps=0,
                wall_seconds=0.0,
                seed=seed,
            )
        )
    return records


#: Entities of the toy scenes: four objects and two containers (the toy's place and
#: remove trials take an object and a container; other actions any two).
_TOY_KINDS = ("object", "object", "object", "object", "container", "container")


def _fixture(name: str, kind: str, lo: tuple[float, float, float], hi: tuple[float, float, float]) -> Body:
    return Body(name, kind, None, lo, hi, tuple((a + b) / 2.0 for a, b in zip(lo, hi)))  # type: ignore[arg-type]


def _toy_bodies(rng: np.random.Generator, kinds: dict[str, str], table: TableSpec | None = None) -> tuple[Body, ...]:
    """Random entities on the simulator's table (``table``: its geometry, default the simulator's default)."""
    table = table if table is not None else TableSpec()
    bodies = []
    for name, kind in kinds.items():
        x, y = float(rng.uniform(0.3, 0.9)), float(rng.uniform(-0.4, 0.4))
        half = float(rng.uniform(0.02, 0.08)) if kind == "object" else float(rng.uniform(0.06, 0.12))
        height = 2 * half if kind == "object" else float(rng.uniform(0.05, 0.2))
        shape = SHAPES[int(rng.integers(len(SHAPES)))] if kind == "object" else "box"
        lo, hi = (x - half, y - half, 0.0), (x + half, y + half, height)
        bodies.append(Body(name, kind, shape, lo, hi, (x, y, height / 2)))
    w, floor_z = FLOOR_HALF_WIDTH, table.floor_z
    bodies.append(_fixture(TABLE, SUPPORT_KIND, *table.box))
    bodies.append(_fixture(FLOOR, GROUND_KIND, (-w, -w, floor_z), (w, w, floor_z)))
    return tuple(bodies)


def synthetic_changes(records: list[TrialRecord], *, seed: int) -> dict[int, TrialChange]:
    """A toy symbolic change for each of ``records`` (from :func:`synthetic_trials`), by trial id.

    One learnable relation: ``place_in_container(x, c)`` makes ``(in x c)`` (nine times in
    ten), and nothing else makes anything ``in`` anything; ``remove_from_container(x, c)``
    ends ``(in x c)``. Around it, noise: pushes end reachability and touching, push_together
    makes its arguments touch. Not physics; for tests and timings of the goal-aware head.
    """
    rng = np.random.default_rng([seed, 0x60A1])
    changes: dict[int, TrialChange] = {}
    for record in records:
        spec = record.spec
        kinds = {f"entity{k}": kind for k, kind in enumerate(_TOY_KINDS)}
        if spec.action in ("place_in_container", "remove_from_container"):
            kinds[spec.arguments[0]], kinds[spec.arguments[1]] = "object", "container"
        bodies = _toy_bodies(rng, kinds)
        objects = [n for n, k in kinds.items() if k == "object"]
        containers = [n for n, k in kinds.items() if k == "container"]
        before = {fluent("visible", n) for n in kinds} | {fluent("reachable", n) for n in kinds}
        before |= {fluent("on", n, TABLE) for n in objects} | {fluent("touching", n, TABLE) for n in kinds}
        if spec.action == "remove_from_container" and rng.random() < 0.7:
            before.add(fluent("in", *spec.arguments))
        elif rng.random() < 0.3:
            before.add(fluent("in", objects[int(rng.integers(len(objects)))], containers[0]))
        after = set(before)
        first = spec.arguments[0]
        if spec.action == "place_in_container" and rng.random() < 0.9:
            after |= {fluent("in", *spec.arguments), fluent("touching", *spec.arguments)}
            after -= {fluent("on", first, TABLE)}
        elif spec.action == "remove_from_container":
            after -= {fluent("in", *spec.arguments)}  # a no-op when it was not in
        elif spec.action == "push" and spec.params.movement_magnitude > 0.2 and rng.random() < 0.7:
            after -= {fluent("reachable", first), fluent("touching", first, TABLE)}
        elif spec.action == "push_together" and rng.random() < 0.8:
            after.add(fluent("touching", *spec.arguments))
        changes[record.id] = replace(  # type: ignore[index]
            TrialChange.between(before, after, bodies), trial_id=record.id
        )
    return changes
