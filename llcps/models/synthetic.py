"""A seeded toy source of trials whose Omega bits depend learnably on Table 1's inputs.

Not physics: a handful of hand-written noisy rules (fast pushes knock far objects
out of reach, pushing two things together makes them touch, taking an object out of
a container makes it visible and reachable, ...). It exists to test and time the
world models without a simulator; the agent never uses it.
"""

from __future__ import annotations

import numpy as np

from llcps.domain import (
    ACTION_ARITY,
    ACTIONS,
    COLORS,
    ORIENTATIONS,
    OUTCOME_NAMES,
    SHAPES,
    ControllerParams,
    EntityFeatures,
    Outcome,
    TrialRecord,
    TrialSpec,
)


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
