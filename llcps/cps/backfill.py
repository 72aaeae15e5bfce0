"""Backfill: give the trials of an older store their symbolic change.

Stores written before trial changes were recorded (schema 0004) hold trials without
one. Physics is deterministic from a stored start state, so such a trial's change is
recovered by *replay*: rebuild its scene, restore the state, run the same controller
call, and take the change between the states before and after. The replay must agree
with the stored trial (the same Omega and the same number of simulation steps); then
the change is recorded with source ``replayed``. A trial without a stored start state,
whose stored state cannot be replayed, or whose replay disagrees, is recorded as
``unknown`` and the goal-aware world model leaves it out. Nothing else about a trial
is changed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

from llcps.trial_records import TrialChange
from llcps.errors import LlcpsError
from llcps.store import Store

ProgressCallback = Callable[[int, int], None]
"""Called as ``progress(done, total)`` after each trial."""

#: Trials written per transaction (a killed backfill keeps every batch before it).
BATCH = 50


@dataclass
class BackfillReport:
    """What a backfill did: trials recovered by replay, and trials left unknown (and why)."""

    total: int = 0
    replayed: int = 0
    no_snapshot: int = 0
    mismatched: int = 0
    failed: int = 0
    wall_seconds: float = 0.0
    mismatched_ids: list[int] = field(default_factory=list)

    @property
    def unknown(self) -> int:
        return self.no_snapshot + self.mismatched + self.failed

    def as_json(self) -> dict[str, object]:
        return {
            "trials": self.total,
            "replayed": self.replayed,
            "unknown": self.unknown,
            "unknown_no_snapshot": self.no_snapshot,
            "unknown_replay_mismatch": self.mismatched,
            "unknown_replay_failed": self.failed,
            "mismatched_ids": self.mismatched_ids[:100],
            "wall_seconds": round(self.wall_seconds, 3),
        }


def backfill_changes(store: Store, *, replay: bool = True, progress: ProgressCallback | None = None) -> BackfillReport:
    """Record a change for every trial of ``store`` that has none (see the module docstring).

    Args:
        store: the experience store (at the newest schema).
        replay: recover changes by replay; False marks every such trial unknown at once.
        progress: called after each trial.

    Returns:
        Counts of replayed and unknown trials.
    """
    started = time.perf_counter()
    todo = store.trials_without_change()
    report = BackfillReport(total=len(todo))
    pending: list[tuple[int, TrialChange | None]] = []
    world = None
    scene_key: str | None = None
    try:
        for done, (trial_id, snapshot_id) in enumerate(todo, start=1):
            change: TrialChange | None = None
            if not replay or snapshot_id is None:
                report.no_snapshot += 1
            else:
                try:
                    change, world, scene_key = _replay(store, trial_id, snapshot_id, world, scene_key)
                except LlcpsError:  # a stored scene or state that does not rebuild
                    report.failed += 1
                    if world is not None:
                        world.close()
                    world, scene_key = None, None
                else:
                    if change is None:
                        report.mismatched += 1
                        report.mismatched_ids.append(trial_id)
                    else:
                        report.replayed += 1
            pending.append((trial_id, change))
            if len(pending) >= BATCH:
                store.put_changes(pending)
                pending = []
            if progress is not None:
                progress(done, report.total)
        store.put_changes(pending)
    finally:
        if world is not None:
            world.close()
        report.wall_seconds = time.perf_counter() - started
    return report


def _replay(store: Store, trial_id: int, snapshot_id: int, world, scene_key: str | None):  # noqa: ANN001, ANN202
    """Replay one trial; returns (its change or None on a mismatch, the world, its scene's key)."""
    import json

    from llcps.sim.trial import run_trial
    from llcps.sim.world import World

    trial = store.get_trial(trial_id)
    snapshot = store.get_snapshot(snapshot_id)
    key = json.dumps(snapshot.scene, sort_keys=True)
    if world is None or key != scene_key:
        if world is not None:
            world.close()
        world = World.from_scene(snapshot.scene)
    world.restore_serialized(snapshot.state)
    result = run_trial(world, trial.spec)
    if result.outcome != trial.outcome or result.sim_steps != trial.sim_steps:
        return None, world, key
    return TrialChange.between(result.before, result.after, result.bodies, source="replayed"), world, key
