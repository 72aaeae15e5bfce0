"""Pretraining: random interactions (the paper's 200 a-priori data points),
each executed in simulation and written to the experience store as a trial.

Every trial starts from a settled, checked random scene (see
:mod:`llcps.sim.sampler`), carries its own seed (which redraws the same scene
and controller call) and its stored start state (from which ``llcps replay``
re-runs it). A run with the same seed writes the same rows, bit for bit.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Iterator, Mapping

import numpy as np

from llcps.domain import ACTIONS, MAX_PRETRAIN_TRIALS, OUTCOME_NAMES, check_seed
from llcps.trial_records import TrialRecord
from llcps.errors import LlcpsError
from llcps.sim.motion import control_loop_rate
from llcps.sim.sampler import sample_interaction
from llcps.sim.trial import TrialResult, run_trial
from llcps.sim.world import SceneSpec, World

if TYPE_CHECKING:
    from llcps.store import Store

#: ``progress(done, total)`` after every stored trial.
ProgressCallback = Callable[[int, int], None]

#: Measure the raw control-loop rate on every k-th trial's scene (0: never).
CONTROL_LOOP_EVERY = 10
CONTROL_LOOP_STEPS = 480


def trial_seed(seed: int, index: int) -> int:
    """The seed of the ``index``-th pretraining trial of a run seeded with ``seed``."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0])


@dataclass(frozen=True)
class PretrainTrial:
    """One random interaction, executed.

    Attributes:
        seed: redraws this scene and controller call (``sample_interaction``).
        scene: the scene it ran in.
        state: the serialized physics state it started from.
        result: what happened.
    """

    seed: int
    scene: SceneSpec
    state: bytes
    result: TrialResult


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its ended worker processes."""
    times = os.times()
    return time.process_time() + times.children_user + times.children_system


def random_trial(world: World, seed: int) -> PretrainTrial:
    """Draw a random interaction with ``seed``, settle its scene in ``world`` and run it."""
    return _run(world, seed, measure=False)[0]


def _run(world: World, seed: int, *, measure: bool) -> tuple[PretrainTrial, float | None, tuple[float, float]]:
    scene, spec = sample_interaction(np.random.default_rng(seed), world=world)
    state = world.serialize_state()  # the world continues from exactly the stored bytes
    rate, spent = None, (0.0, 0.0)
    if measure:  # on the same scene, from the same state (restored afterwards)
        t, c = time.perf_counter(), time.process_time()
        rate = control_loop_rate(world, steps=CONTROL_LOOP_STEPS, clock=time.process_time)
        spent = (time.perf_counter() - t, time.process_time() - c)
    return PretrainTrial(seed=seed, scene=scene, state=state, result=run_trial(world, spec)), rate, spent


@dataclass
class PretrainSummary:
    """What a pretraining run stored and how fast it ran.

    Rates are given per wall second and per CPU second of this process; the CPU
    figures are the ones to compare on a busy machine. ``control_loop_rate`` is
    the raw rate (IK + motor command + physics step per CPU second) measured on
    some of the same scenes in the same run, and ``efficiency`` the achieved sim
    steps per CPU second over it (1.0: the loop adds nothing to the control loop).
    """

    branch: str
    seed: int
    requested: int
    run_id: int | None = None
    trial_ids: list[int] = field(default_factory=list)
    outcome_counts: dict[str, int] = field(default_factory=lambda: {name: 0 for name in OUTCOME_NAMES})
    action_counts: dict[str, int] = field(default_factory=lambda: {name: 0 for name in ACTIONS})
    sim_steps: int = 0
    wall_seconds: float = 0.0
    cpu_seconds: float = 0.0
    control_loop_rate: float | None = None

    @property
    def trials(self) -> int:
        return len(self.trial_ids)

    @property
    def trials_per_second(self) -> float:
        return self.trials / self.wall_seconds if self.wall_seconds > 0 else 0.0

    @property
    def steps_per_second(self) -> float:
        return self.sim_steps / self.wall_seconds if self.wall_seconds > 0 else 0.0

    @property
    def steps_per_cpu_second(self) -> float:
        return self.sim_steps / self.cpu_seconds if self.cpu_seconds > 0 else 0.0

    @property
    def efficiency(self) -> float | None:
        return self.steps_per_cpu_second / self.control_loop_rate if self.control_loop_rate else None

    def outcome_fractions(self) -> Mapping[str, float]:
        return {k: (v / self.trials if self.trials else 0.0) for k, v in self.outcome_counts.items()}

    def as_json(self) -> dict[str, object]:
        return {
            "branch": self.branch,
            "run_id": self.run_id,
            "seed": self.seed,
            "trials": self.trials,
            "trial_ids": list(self.trial_ids),
            "outcome_counts": dict(self.outcome_counts),
            "outcome_fractions": dict(self.outcome_fractions()),
            "action_counts": dict(self.action_counts),
            "sim_steps": self.sim_steps,
            "wall_seconds": self.wall_seconds,
            "cpu_seconds": self.cpu_seconds,
            "trials_per_second": self.trials_per_second,
            "sim_steps_per_second": self.steps_per_second,
            "sim_steps_per_cpu_second": self.steps_per_cpu_second,
            "control_loop_rate": self.control_loop_rate,
            "efficiency": self.efficiency,
        }


#: Trials a worker process runs per task: small enough to keep both cores busy to the end.
WORKER_CHUNK = 2
#: The simulator of this worker process (:func:`_worker_trial`), made on its first trial.
_worker_world: World | None = None


def _worker_trial(job: tuple[int, bool]) -> tuple[PretrainTrial, float | None, tuple[float, float]]:
    """One trial in a worker process, in that process's own simulator."""
    global _worker_world
    if _worker_world is None:
        _worker_world = World()
    seed, measure = job
    return _run(_worker_world, seed, measure=measure)


def random_trials(
    *, seed: int, n: int, world: World | None = None, control_loop_every: int = 0, workers: int = 1
) -> Iterator[tuple[PretrainTrial, float | None, tuple[float, float]]]:
    """The ``n`` random interactions of a run seeded with ``seed``, in order.

    Each trial is a function of its own seed alone (its scene is drawn and settled
    afresh), so ``workers`` processes run them side by side, each in its own simulator,
    and they are yielded in index order: the same trials as one process, bit for bit.

    Yields:
        Each executed trial; the control-loop rate measured on its scene when it is
        a measured one (every ``control_loop_every``-th), else None; and the wall
        and CPU seconds the measurement took.
    """
    jobs = [(trial_seed(seed, index), bool(control_loop_every) and index % control_loop_every == 0) for index in range(n)]
    if workers > 1 and n > 1:
        context = multiprocessing.get_context("spawn")  # a fresh interpreter: no forked simulator state
        with context.Pool(min(workers, n)) as pool:
            yield from pool.imap(_worker_trial, jobs, chunksize=WORKER_CHUNK)
        return
    own = world is None
    w = world if world is not None else World()
    try:
        for trial_seed_, measure in jobs:
            yield _run(w, trial_seed_, measure=measure)
    finally:
        if own:
            w.close()


def finished_pretraining(store: "Store", *, branch: str | None, n: int, seed: int) -> PretrainSummary | None:
    """A pretraining run with ``n`` trials and ``seed`` that finished (status ``ok``) and
    whose ``n`` trials ``branch`` still sees, summed up from its stored trials; None when
    there is none (or ``n`` is 0). Such a run would be written again bit for bit, so
    ``llcps pretrain`` skips it.
    """
    if n <= 0:
        return None
    name = store.resolve_branch(branch).name
    by_run: dict[int, list[TrialRecord]] = {}
    for record in store.visible_trials(name, source="pretrain"):
        if record.run_id is not None:
            by_run.setdefault(record.run_id, []).append(record)
    if not by_run:
        return None
    for run in sorted(store.list_runs(ids=list(by_run)), key=lambda r: r.id):
        records = by_run[run.id]
        if run.command != "pretrain" or run.status != "ok" or run.seed != seed or run.config.get("n") != n or len(records) != n:
            continue
        summary = PretrainSummary(branch=name, seed=seed, requested=n, run_id=run.id)
        for record in records:
            summary.trial_ids.append(int(record.id))  # type: ignore[arg-type]
            for key, bit in record.outcome.as_dict().items():
                summary.outcome_counts[key] += bit
            summary.action_counts[record.spec.action] += 1
            summary.sim_steps += record.sim_steps
            summary.wall_seconds += record.wall_seconds
        return summary
    return None


def pretrain(
    store: "Store",
    *,
    branch: str | None,
    n: int,
    seed: int,
    progress: ProgressCallback | None = None,
    control_loop_every: int = CONTROL_LOOP_EVERY,
    workers: int = 1,
) -> PretrainSummary:
    """Run ``n`` random interactions and store each as a ``pretrain`` trial.

    Trials are written one by one as they finish, so an interrupted run keeps
    every completed trial; the run record says how it ended.

    Args:
        store: the experience store.
        branch: branch to write to; None for the store's current branch.
        n: number of trials.
        seed: run seed; trial i uses ``trial_seed(seed, i)``.
        progress: called after every stored trial.
        control_loop_every: measure the raw control-loop rate on every k-th scene (0: never).
        workers: processes that run the trials side by side (the stored trials are the
            same for any number; the CPU seconds are then this process's and not the workers').
    """
    if workers < 1:
        raise LlcpsError(f"the number of workers must be at least 1, got {workers}", hint="pass --workers 2, say")
    if not 0 <= n <= MAX_PRETRAIN_TRIALS:
        raise LlcpsError(f"the number of trials must be from 0 to {MAX_PRETRAIN_TRIALS}, got {n}", hint="pass --trials 200, say")
    check_seed(seed)
    name = store.resolve_branch(branch).name
    summary = PretrainSummary(branch=name, seed=seed, requested=n)
    summary.run_id = store.start_run(command="pretrain", seed=seed, config={"n": n}, branch=name)
    status = "failed"
    rate_steps = 0
    rate_seconds = 0.0
    measuring_wall = measuring_cpu = 0.0
    t0, c0 = time.perf_counter(), _cpu_seconds()
    try:
        trials = random_trials(seed=seed, n=n, control_loop_every=control_loop_every, workers=workers)
        for index, (trial, rate, spent) in enumerate(trials):
            r = trial.result
            snapshot_id = store.put_snapshot(scene=trial.scene.to_dict(), state=trial.state)
            record = TrialRecord.from_result(
                r,
                branch=name,
                source="pretrain",
                seed=trial.seed,
                run_id=summary.run_id,
                snapshot_id=snapshot_id,
                extra={"pretrain_seed": seed, "index": index},
            )
            trial_id = store.add_trial(record, change=r.change)
            summary.trial_ids.append(trial_id)
            for key, bit in r.outcome.as_dict().items():
                summary.outcome_counts[key] += bit
            summary.action_counts[r.spec.action] += 1
            summary.sim_steps += r.sim_steps
            if rate is not None:
                rate_steps += CONTROL_LOOP_STEPS
                rate_seconds += CONTROL_LOOP_STEPS / rate
                measuring_wall += spent[0]
                measuring_cpu += spent[1]
            # the measurement's own time is not pretraining time
            summary.wall_seconds = time.perf_counter() - t0 - measuring_wall
            summary.cpu_seconds = _cpu_seconds() - c0 - measuring_cpu
            if progress is not None:
                progress(index + 1, n)
        summary.cpu_seconds = _cpu_seconds() - c0 - measuring_cpu  # with the workers', now they have ended
        status = "ok"
    except KeyboardInterrupt:
        status = "interrupted"
        raise
    finally:
        summary.control_loop_rate = rate_steps / rate_seconds if rate_seconds > 0 else None
        store.finish_run(summary.run_id, status=status)
    return summary
