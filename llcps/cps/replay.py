"""Replay a stored trial: rebuild its scene, restore its start state, execute it
again with its stored settings, and check that the physics gives what was recorded.

Physics is deterministic from a stored snapshot, so a replay must match bit for bit:
the same Omega, the same ``solved`` (the scenario's goal held after the trial) and
the same number of simulation steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from llcps.cps.film import PHASES, ProgressCallback, Shot, reenact
from llcps.domain import Fluent
from llcps.trial_records import Outcome, TrialRecord
from llcps.errors import LlcpsError
from llcps.outputs import GIF_SUFFIXES, check_output_file
from llcps.scenarios import get_scenario, is_path
from llcps.scenarios.goal import parse_goal
from llcps.store import Store


@dataclass(frozen=True)
class ReplayReport:
    """What a replay found, next to what the store recorded."""

    trial: TrialRecord
    outcome: Outcome
    solved: bool
    sim_steps: int
    wall_seconds: float

    @property
    def matches(self) -> bool:
        return (
            self.outcome == self.trial.outcome
            and self.solved == self.trial.solved
            and self.sim_steps == self.trial.sim_steps
        )

    def as_json(self) -> dict[str, object]:
        return {
            "trial_id": self.trial.id,
            "source": self.trial.source,
            "action": self.trial.spec.label,
            "matches": self.matches,
            "recorded": {
                "outcome": self.trial.outcome.as_dict(),
                "solved": self.trial.solved,
                "sim_steps": self.trial.sim_steps,
            },
            "replayed": {
                "outcome": self.outcome.as_dict(),
                "solved": self.solved,
                "sim_steps": self.sim_steps,
            },
            "wall_seconds": round(self.wall_seconds, 4),
        }


def trial_goal(store: Store, trial: TrialRecord) -> tuple[frozenset[Fluent], frozenset[Fluent]] | None:
    """The goal a trial was judged by: the one its snapshot stored with the scene, or, for
    snapshots stored before goals were, its scenario's (None: a trial of no scenario).

    Raises:
        LlcpsError: the stored goal is malformed (the store is untrusted input).
    """
    if trial.snapshot_id is not None:
        scene = store.get_snapshot(trial.snapshot_id).scene
        atoms = scene.get("goal") if isinstance(scene, dict) else None
        if atoms is not None:
            names = [str(e.get("name")) for e in scene.get("entities", ()) if isinstance(e, dict)]
            names += [str(f.get("name")) for f in scene.get("fixtures", ()) if isinstance(f, dict)] + ["table"]
            try:
                if not isinstance(atoms, list):
                    raise ValueError("not a list of atoms")
                return parse_goal(atoms, names)
            except ValueError as exc:
                raise LlcpsError(
                    f"snapshot {trial.snapshot_id} of trial {trial.id} holds a malformed goal: {exc}",
                    hint="the store was written by something else; replay another trial",
                ) from None
    if not trial.scenario or is_path(trial.scenario):
        return None
    scenario = get_scenario(trial.scenario)
    return scenario.goal_pos, scenario.goal_neg


def replay(
    store: Store,
    trial_id: int,
    *,
    gif: str | Path | None = None,
    gui: bool = False,
    progress: ProgressCallback | None = None,
) -> ReplayReport:
    """Re-execute stored trial ``trial_id`` from its start snapshot.

    Args:
        store: the experience store holding the trial and its snapshot.
        trial_id: the trial to replay.
        gif: also render the replay to this captioned GIF.
        gui: watch it in a PyBullet window (needs a display).
        progress: ``progress(phase, done, total)`` in simulation steps.

    Raises:
        LlcpsError: the trial does not exist or has no stored start state; its snapshot
            fails its hash, size or structure checks (see :mod:`llcps.sim.snapshot`).
    """
    if gif is not None:
        check_output_file(gif, what="gif", suffixes=GIF_SUFFIXES)
    trial = store.get_trial(trial_id)
    goal = trial_goal(store, trial)  # a stored goal (or scenario name) is checked before any physics
    (done,) = reenact(store, [Shot(trial, PHASES.get(trial.source, trial.source))], gif=gif, gui=gui, progress=progress)
    result = done.result
    solved = goal is not None and goal[0] <= result.after and not (goal[1] & result.after)
    return ReplayReport(
        trial=trial,
        outcome=result.outcome,
        solved=solved,
        sim_steps=result.sim_steps,
        wall_seconds=result.wall_seconds,
    )
