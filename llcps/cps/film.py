"""Re-enacting stored trials: from each trial's stored start state, run it again, and
optionally film it to a captioned GIF.

Physics is deterministic from a stored snapshot (``llcps replay`` checks it bit for
bit), so a film made after an episode shows what was recorded, and the episode's
stored times never include rendering. An episode's film is its plan up to the
failure, the trial that resolved the novelty, and the plan that trial made work.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from llcps.trial_records import TrialRecord
from llcps.errors import LlcpsError
from llcps.store import Store

#: Simulation steps between GIF frames: 15 frames per simulated second.
FILM_EVERY = 16
#: GIF frame size (a caption band is added beneath).
FILM_SIZE = (400, 300)
#: How much faster than real time a film plays.
FILM_SPEEDUP = 2.0
#: Phase names of trials by source, for captions.
PHASES = {"plan": "plan", "exploration": "explore", "pretrain": "pretrain", "replay": "replay"}

ProgressCallback = Callable[[str, int, int], None]
"""``progress(phase, done, total)``; done and total count simulation steps, or GIF frames
when filming."""


@dataclass(frozen=True)
class Shot:
    """One trial of a film and the phase of the episode it belongs to."""

    trial: TrialRecord
    phase: str


@dataclass(frozen=True)
class Reenactment:
    """One trial run again from its stored start state."""

    trial: TrialRecord
    result: object  # llcps.sim.trial.TrialResult (the simulator loads only when used)


def caption(shot: Shot) -> tuple[str, str]:
    """The two caption lines of a shot: trial, phase and scenario; action and parameters."""
    t, p = shot.trial, shot.trial.spec.params
    first = f"trial {t.id} · {shot.phase}" + (f" · {t.scenario}" if t.scenario else "")
    second = (
        f"{t.spec.action}({', '.join(t.spec.arguments)}) · rate {p.rate:.3g} m/s · "
        f"{p.movement_magnitude:.3g} m · {p.orientation}"
    )
    return first, second


def episode_shots(store: Store, episode_id: int) -> list[Shot]:
    """The film of an episode: its plan up to the failure, the resolving trial and the
    plan it enabled (or the whole plan when no exploration was needed)."""
    episode = store.get_episode(episode_id)
    trials = store.visible_trials(episode.branch, episode=episode_id)
    first_exploration = next((i for i, t in enumerate(trials) if t.source == "exploration"), len(trials))
    shots = [Shot(t, "plan") for t in trials[:first_exploration] if t.source == "plan"]
    resolving = episode.summary.get("resolving_trial_id")
    at = next((i for i, t in enumerate(trials) if t.id == resolving), None) if isinstance(resolving, int) else None
    if at is not None:
        shots.append(Shot(trials[at], "explore"))
        for later in trials[at + 1 :]:
            if later.source != "plan":
                break
            shots.append(Shot(later, "re-plan"))
    return shots


def reenact(
    store: Store,
    shots: Sequence[Shot],
    *,
    gif: str | Path | None = None,
    gui: bool = False,
    progress: ProgressCallback | None = None,
) -> list[Reenactment]:
    """Run each shot's trial again from its stored start state, in order; film them to ``gif``.

    Every stored scene and state is untrusted: the scene is checked before the engine
    builds it, and the state before the engine restores it (see :mod:`llcps.sim.snapshot`).

    Raises:
        LlcpsError: a trial has no stored start state; its snapshot fails its hash,
            size or structure checks.
    """
    from llcps.sim.render import GifRecorder, frame_camera
    from llcps.sim.trial import run_trial
    from llcps.sim.world import SceneSpec, World

    for shot in shots:
        if shot.trial.snapshot_id is None:
            raise LlcpsError(
                f"trial {shot.trial.id} has no stored start state, so it cannot be replayed", hint="replay a trial with a snapshot_id"
            )
    phase = "render" if gif is not None else "replay"
    # Steps to simulate, or frames to render (one per FILM_EVERY steps, plus first and last).
    sizes = [max(1, s.trial.sim_steps) // (FILM_EVERY if gif is not None else 1) + (2 if gif is not None else 0) for s in shots]
    total = sum(sizes)
    done = 0
    worlds: dict[str, World] = {}
    recorders: list[GifRecorder] = []
    out: list[Reenactment] = []
    camera = None
    try:
        for shot in shots:
            snapshot = store.get_snapshot(shot.trial.snapshot_id)  # type: ignore[arg-type]
            key = json.dumps(snapshot.scene, sort_keys=True)
            world = worlds.get(key)
            if world is None:
                scene = SceneSpec.from_dict(snapshot.scene)  # checked before the engine builds anything
                world = worlds[key] = World.from_scene(scene, gui=gui)
            world.restore_serialized(snapshot.state)
            if progress is not None:
                progress(phase, done, total)
            if gif is None:
                result = run_trial(world, shot.trial.spec)
            else:
                if camera is None:
                    camera = frame_camera(world)  # one framing for the whole film
                recorder = GifRecorder(world, every=FILM_EVERY, width=FILM_SIZE[0], height=FILM_SIZE[1], camera=camera, shadow=False)
                recorder.caption = caption(shot)
                base = done
                if progress is not None:
                    recorder.on_frame = lambda n, base=base: progress(phase, min(total, base + n), total)
                with recorder:
                    result = run_trial(world, shot.trial.spec)
                recorders.append(recorder)
            done += sizes[len(out)]
            out.append(Reenactment(shot.trial, result))
        if gif is not None and recorders:
            if progress is not None:
                progress("write GIF", total, total)
            film = recorders[0]
            for more in recorders[1:]:
                film.frames.extend(more.frames)
                film.captions.extend(more.captions)
            film.save(gif, speedup=FILM_SPEEDUP)
    finally:
        for world in worlds.values():
            world.close()
    return out


def film_episode(
    store: Store, episode_id: int, gif: str | Path, *, progress: ProgressCallback | None = None
) -> Path | None:
    """Film an episode (see :func:`episode_shots`) to ``gif``; returns the path, or None when
    the episode executed no trial (its goal held from the start, or it had no plan)."""
    shots = episode_shots(store, episode_id)
    if not shots:
        return None
    reenact(store, shots, gif=gif, progress=progress)
    return Path(gif)


__all__ = ["FILM_EVERY", "Reenactment", "Shot", "caption", "episode_shots", "film_episode", "reenact"]
