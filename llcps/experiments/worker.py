"""What runs inside a worker: one task against a private store, and the worker's lifecycle.

A worker runs a task against a private temporary SQLite store seeded with exactly
what the task reads (a sequence: the trials of its pretraining branch) and returns
a :class:`~llcps.experiments.tasks.TaskOutput`. Nothing a task computes depends on
which worker ran it, when, or after what: its private store, its ids and its seeds
are the same in every schedule. The one thing workers share is the physics cache
of the real store (:mod:`llcps.store.physics_cache`), which changes how much
physics is computed, never what a trial records (besides ``cache_hit`` and wall
seconds).

The same :func:`execute_task` runs in a local pool process and as a Ray task; a
local pool worker also starts with :func:`init_local_worker`: it ignores Ctrl-C
(the parent stops it), leaves at once on SIGTERM, exits when its parent is gone,
and tells the parent its process id so the parent can stop it.
"""

from __future__ import annotations

import atexit
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from llcps.errors import LlcpsError
from llcps.cps.episode import SolveConfig
from llcps.experiments.tasks import LifeTask, PretrainTask, SequenceTask, Task, TaskOutput, pretrain_subset
from llcps.experiments.transfer import Payload, export_branches, import_payload, inverse
from llcps.store import MAIN_BRANCH, PRETRAIN, Store

#: Thread pools a worker limits to one thread: results must not depend on core counts,
#: and two workers on two cores should not fight over them.
THREAD_VARIABLES: tuple[str, ...] = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
#: Private branch of a pretraining pool that is not itself one of the preset's sets.
POOL_BRANCH = "pool"
#: The command recorded with every experiment run and episode.
COMMAND = "experiment run"
#: The command recorded with every episode of a life.
LIFE_COMMAND = "life run"

_limited = False
_scratch: str | None = None  # the private store's directory of the task in progress
_caches: dict[str, Any] = {}  # this worker's physics caches by store URL, kept across its tasks
_events: Any = None  # the parent's queue of (kind, value) messages; None outside a local pool

#: Messages a local pool worker puts on its parent's queue: its process id when it starts,
#: and the label of a sequence task whose first scenario is done.
PID, FIRST_SCENARIO = "pid", "first-scenario"


def limit_threads() -> None:
    """One thread for OpenMP/BLAS and torch in this process (idempotent)."""
    global _limited
    if _limited:
        return
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        pass
    if "torch" in sys.modules:  # else it starts with OMP_NUM_THREADS=1
        sys.modules["torch"].set_num_threads(1)
    _limited = True


def _stop_worker(*_: object) -> None:
    """Leave at once (the parent dropped this task), without a task directory behind."""
    if _scratch is not None:
        shutil.rmtree(_scratch, ignore_errors=True)
    os._exit(1)


def _exit_with_parent(parent: int) -> None:
    """End this worker when the run that started it is gone (e.g. killed with -9)."""
    while True:
        time.sleep(1.0)
        if os.getppid() != parent:
            _stop_worker()


def _leave_without_teardown() -> None:
    """The last thing a pool worker does at exit: flush and go, skipping the interpreter's
    teardown. After a long run a worker's heap holds what its tasks left in memory, and
    freeing it object by object made the parent wait for the workers' exit (5.85 s after
    a 10-seed grid, about 40 s after 100 seeds); every result was returned before."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    os._exit(0)


def init_local_worker(events: Any = None) -> None:
    """Initializer of local pool workers; ``events`` is the parent's queue (see :data:`PID`)."""
    global _events
    atexit.register(_leave_without_teardown)  # runs after the handlers registered later (LIFO)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and stops us
    signal.signal(signal.SIGTERM, _stop_worker)
    try:
        sys.stdout.flush()
        os.dup2(2, 1)  # native code prints to fd 1; the parent's stdout is for data
    except (OSError, ValueError):  # pragma: no cover - no real stdout
        pass
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True).start()
    limit_threads()
    _events = events
    report(PID, os.getpid())
    warm_up()


def report(kind: str, value: object) -> None:
    """Tell the parent of a local pool worker (nothing elsewhere)."""
    if _events is not None:
        _events.put((kind, value))


def warm_up() -> None:
    """Import what every task needs while the worker would otherwise wait for its first task."""
    import llcps.cps.executor  # noqa: F401  (the trial executor, the simulator, the models' registry)
    import llcps.cps.plan_execution  # noqa: F401  (the planner)
    import llcps.cps.ranking  # noqa: F401  (the failure point too)
    import llcps.cps.pretraining  # noqa: F401


def worker_cache(url: str) -> Any:
    """This worker's handle on the physics cache of the store at ``url``, kept across tasks."""
    cache = _caches.get(url)
    if cache is None:
        from llcps.store.physics_cache import StorePhysicsCache  # loads llcps.sim: not where the CLI starts

        store = Store.open(url)
        cache = StorePhysicsCache(store.engine)
        _caches[url] = cache
    return cache


def execute_task(task: Task) -> TaskOutput:
    """Run one task against a private temporary store and return its payload.

    The same function runs in a local pool process and as a Ray task.
    """
    global _scratch
    limit_threads()
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="llcps-task-") as tmp:
        _scratch = tmp
        try:
            with Store.open(str(Path(tmp) / "task.db"), create=True) as store:
                if isinstance(task, PretrainTask):
                    payload, statuses, cache = _run_pretrain(store, task), (), None
                elif isinstance(task, LifeTask):
                    payload, statuses, cache = _run_life(store, task)
                else:
                    payload, statuses, cache = _run_sequence(store, task)
        finally:
            _scratch = None
    return TaskOutput(task.label, payload, time.perf_counter() - started, statuses, cache)


def _run_pretrain(store: Store, task: PretrainTask) -> Payload:
    from llcps.cps.pretraining import pretrain  # the simulator: not loaded where the CLI starts

    own = {size: name for size, name in zip(task.sizes, task.branches)}
    pool_branch = own.get(task.pool, POOL_BRANCH)
    store.create_branch(pool_branch, from_branch=MAIN_BRANCH, at=0)
    pretrain(store, branch=pool_branch, n=task.pool, seed=task.seed, control_loop_every=0)
    pool = store.visible_trials(pool_branch)
    pool_changes = store.visible_changes(pool_branch)
    for size, name in own.items():
        if name == pool_branch:
            continue
        store.create_branch(name, from_branch=MAIN_BRANCH, at=0)
        chosen = pretrain_subset(pool, size, seed=task.seed)
        config = {"pool": task.pool, "size": size, "pool_indices": [t.extra.get("index") for t in chosen]}
        run_id = store.start_run(command=f"{COMMAND} (pretraining subset)", seed=task.seed, config=config, branch=name)
        store.add_trials(
            [
                replace(t, id=None, created_at=None, branch=name, run_id=run_id, episode_id=None, extra={**t.extra, "pool": task.pool})
                for t in chosen
            ],
            changes=[pool_changes.get(t.id) for t in chosen],  # type: ignore[arg-type]
        )
        store.finish_run(run_id, status="ok")
    return export_branches(store, task.branches)


def _solve(store: Store, task: SequenceTask, branch: str, source: str) -> str:
    """Solve one scenario of a sequence task on ``branch``; returns the episode's status."""
    from llcps.cps.episode import solve  # the simulator: not loaded where the CLI starts

    seq = task.sequence
    config = SolveConfig(
        scenario=source,
        condition="novelty",
        model=seq.cell.model,
        measure=seq.cell.measure,
        seed=seq.seed,
        variant=seq.variant,
        model_seed=seq.model_seed,
        budget=task.budget,
        refit_every=task.refit_every,
        ordering=task.ordering,
        reach_check=task.reach_check,
    )
    result = solve(store, branch=branch, config=config, command=f"{COMMAND} --preset {seq.preset}", cache=_cache(task))
    if result.status == "interrupted":
        raise RuntimeError(f"{task.label}: {source} was interrupted")
    return result.status


def _solve_life_episode(
    store: Store, task: LifeTask, branch: str, family: str, variant: int, condition: str, life: dict[str, Any]
) -> str:
    """Solve one episode of a life on ``branch`` and record where in the life it is.

    The episode's place in the life (life, condition, index, first encounter) goes into
    its stored summary under ``life``, so results are rebuilt from the store alone.
    """
    from llcps.cps.episode import solve  # the simulator: not loaded where the CLI starts

    config = SolveConfig(
        scenario=task.source(family),
        condition=condition,
        model=task.model,
        measure=task.measure,
        ordering=task.ordering,
        reach_check=task.reach_check,
        seed=task.seed,
        variant=variant,
        budget=task.budget,
        refit_every=task.refit_every,
    )
    result = solve(store, branch=branch, config=config, command=f"{LIFE_COMMAND} {task.life}", cache=_cache(task))
    if result.status == "interrupted" or result.episode_id is None:
        raise RuntimeError(f"{task.label}: {family} (variant {variant}) was interrupted")
    summary = {**store.get_episode(result.episode_id).summary, "life": {"name": task.life, "condition": task.condition.name,
                                                                       "life": task.seed, **life}}  # fmt: skip
    store.finish_episode(result.episode_id, status=result.status, summary=summary)
    return result.status


def _run_life(store: Store, task: LifeTask) -> tuple[Payload, tuple[str, ...], dict[str, Any] | None]:
    """Solve a life's episodes under its condition, then re-solve each family met on forks of its end."""
    seeded = import_payload(store, task.base) if task.base is not None else None
    cache = _cache(task)
    counted = None if cache is None else dict(cache.counts.as_json())
    statuses: list[str] = []
    start = task.pretrain if task.pretrain is not None else MAIN_BRANCH
    at: int | str = PRETRAIN if task.pretrain is not None else 0
    created: set[str] = set()
    for episode in task.episodes:
        branch = task.episode_branch(episode.index)
        if branch not in created:
            store.create_branch(branch, from_branch=start, at=at)
            created.add(branch)
        place = {"episode": episode.index, "family": episode.family, "variant": episode.variant,
                 "first_encounter": episode.first_encounter, "probe": episode.probe, "phase": "life"}  # fmt: skip
        statuses.append(_solve_life_episode(store, task, branch, episode.family, episode.variant, episode.condition, place))
        if episode.index == 0:
            report(FIRST_SCENARIO, task.label)
    end = task.episode_branch(task.episodes[-1].index) if task.episodes else start
    for family, variant in task.after:
        for condition in ("novelty", "original"):
            branch = task.after_branch(family, condition)
            store.create_branch(branch, from_branch=end, at=None)
            place = {"episode": None, "family": family, "variant": variant, "first_encounter": False, "probe": False,
                     "phase": "after"}  # fmt: skip
            _solve_life_episode(store, task, branch, family, variant, condition, place)
    counts = None
    if cache is not None and counted is not None:
        after = cache.counts.as_json()
        counts = {k: after[k] - counted[k] for k in ("hits", "misses", "rejected", "stored")}
    external = inverse(seeded.trials) if seeded is not None else {}
    payload = export_branches(store, task.branches, external=external)
    return payload, tuple(statuses), counts


def _cache(task: SequenceTask | LifeTask) -> Any:
    return worker_cache(task.cache_url) if task.cache_url is not None else None


def _run_sequence(store: Store, task: SequenceTask) -> tuple[Payload, tuple[str, ...], dict[str, Any] | None]:
    if task.base is None:
        raise LlcpsError(f"task {task.label} was sent without its pretraining trials")
    seeded = import_payload(store, task.base)
    seq = task.sequence
    cache = _cache(task)
    counted = None if cache is None else dict(cache.counts.as_json())
    statuses: list[str] = []
    scenarios = task.scenarios
    condition = seq.cell.condition
    for index, (scenario, source) in enumerate(scenarios):
        branch = seq.episode_branch(scenario)
        if index == 0 or condition != "update":
            store.create_branch(branch, from_branch=seq.pretrain_branch, at=PRETRAIN)
        # Under ``others`` the held-out scenario's branch first solves every other one.
        before = [item for item in scenarios if item[0] != scenario] if condition == "others" else []
        for _, other in before:
            _solve(store, task, branch, other)
        status = _solve(store, task, branch, source)
        statuses.append(status)
        if index == 0:
            report(FIRST_SCENARIO, task.label)  # its twin's first scenario is in the physics cache now
    counts = None
    if cache is not None and counted is not None:
        after = cache.counts.as_json()
        counts = {k: after[k] - counted[k] for k in ("hits", "misses", "rejected", "stored")}
    payload = export_branches(store, task.branches, external=inverse(seeded.trials))
    return payload, tuple(statuses), counts


__all__ = [
    "COMMAND",
    "LIFE_COMMAND",
    "FIRST_SCENARIO",
    "PID",
    "POOL_BRANCH",
    "THREAD_VARIABLES",
    "execute_task",
    "init_local_worker",
    "limit_threads",
    "report",
    "worker_cache",
]
