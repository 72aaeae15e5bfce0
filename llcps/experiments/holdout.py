"""Checking that pretraining held the scenarios out.

An experiment's pretraining set is random interactions in random layouts drawn from
the sampler's catalog (:mod:`llcps.sim.sampler`; the simulator layer cannot import
:mod:`llcps.scenarios`, an import contract in pyproject.toml), never a scenario's
scene. :func:`pretraining_leaks` checks a stored pretraining branch against the
scenes of the scenarios it is meant to hold out: every trial on it must be a
``pretrain`` trial of no scenario, and none may start from one of their scenes.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Iterable

from llcps.scenarios import CONDITIONS, get_scenario
from llcps.store import Store


@dataclass(frozen=True)
class Leak:
    """A pretraining trial that saw a scenario: why, and which scene."""

    trial_id: int | None
    reason: str


def _plain(scene: Any) -> Any:
    return json.loads(json.dumps(scene, sort_keys=True))


def pretraining_leaks(store: Store, branch: str, scenarios: Iterable[str], variants: Iterable[int] = (0,)) -> tuple[Leak, ...]:
    """The trials of pretraining branch ``branch`` that did not hold ``scenarios`` out (empty: none).

    Args:
        store: the experience store.
        branch: a pretraining branch (e.g. ``exp-generalization-pretrain-p200-s3``).
        scenarios: names, aliases or .toml paths of the held-out scenarios.
        variants: the scene variants to compare with, in every condition of each scenario.
    """
    scenes = {}
    for name in scenarios:
        scenario = get_scenario(name)
        for variant in variants:
            for condition in CONDITIONS:
                scenes[json.dumps(_plain(scenario.scene(condition, variant).to_dict()), sort_keys=True)] = (
                    f"{scenario.name} ({condition}, variant {variant})"
                )
    leaks: list[Leak] = []
    for trial in store.visible_trials(branch):
        if trial.source != "pretrain" or trial.scenario is not None or trial.episode_id is not None:
            leaks.append(Leak(trial.id, f"a {trial.source} trial of scenario {trial.scenario}, not a random interaction"))
            continue
        if trial.snapshot_id is None:
            continue
        scene = json.dumps(_plain(store.get_snapshot(trial.snapshot_id).scene), sort_keys=True)
        if scene in scenes:
            leaks.append(Leak(trial.id, f"starts from the scene of {scenes[scene]}"))
    return tuple(leaks)


__all__ = ["Leak", "pretraining_leaks"]
