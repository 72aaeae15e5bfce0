"""The experiment runner: the grid's tasks on a local process pool or on Ray, one writer.

A run is a list of *tasks*: per seed one pretraining task (the seed's pool of random
interactions and every pretraining set drawn from it, each on its own branch) and
one task per sequence of the grid (scenario1 -> scenario2 -> scenario3 under
``update`` or ``reset``). A worker runs a task against a private temporary SQLite
store seeded with exactly what the task reads (a sequence: the trials of its
pretraining branch) and returns a :class:`~llcps.experiments.transfer.Payload`;
the parent, the only writer, imports each payload in one transaction on the
grid's deterministic branch names.

So a kill loses only the tasks in flight, a re-run skips every task whose branches
exist, and nothing a task computes depends on which worker ran it, when, or after
what: its private store, its ids and its seeds are the same in every schedule, so
the results are identical for any number of workers and either engine.

The paper's protocol, per (preset, pretraining size, seed): one pretraining branch
shared by every model and measure of that seed. The seed's pool is
``pretrain(n=preset.pretrain_pool, seed)``; a set as large as the pool is the pool
itself, a smaller one is drawn from it one trial per action in turn
(:func:`pretrain_subset`; the paper's 4 points are one per action). ``update``
solves the three scenarios in order on one branch forked at the pretraining point;
``reset`` solves each on its own branch forked there. Every episode of a sequence
runs with the sequence's seed and the preset's budget.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor
from concurrent.futures import wait as wait_futures
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterable

from llcps.errors import LlcpsError, StoreError, UnknownNameError
from llcps.experiments.grid import (
    SCENARIO_SEQUENCE,
    Preset,
    Sequence,
    _seed_list,
    get_preset,
    pretrain_branch_name,
    validate_preset,
)
from llcps.experiments.results import ResultsTable, table_from_episodes
from llcps.experiments.transfer import Payload, export_branches, import_payload, inverse
from llcps.store import MAIN_BRANCH, PRETRAIN, Store

#: ``--engine`` choices: a local process pool, or Ray (``pip install 'llcps[ray]'``).
ENGINES: tuple[str, ...] = ("local", "ray")
#: Thread pools a worker limits to one thread: results must not depend on core counts,
#: and two workers on two cores should not fight over them.
THREAD_VARIABLES: tuple[str, ...] = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
#: Private branch of a pretraining pool that is not itself one of the preset's sets.
POOL_BRANCH = "pool"
#: The command recorded with every experiment run and episode.
COMMAND = "experiment run"
#: Stream tag of :func:`pretrain_subset` (kept apart from every other use of the seed).
_SUBSET_STREAM = 0x5E7
#: Where ``llcps experiment run`` writes a preset's report unless told otherwise.
RESULTS_DIR = Path("results")
#: Seconds between checks for Ctrl-C and finished tasks.
_POLL_SECONDS = 0.5

class EngineError(LlcpsError):
    """The engine itself failed (a worker process died), not one task."""


ProgressCallback = Callable[[int, int, str], None]
"""Called as ``progress(done, total, label)`` after each task is imported (or fails)."""


# --------------------------------------------------------------------------------------
# Tasks
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PretrainTask:
    """Draw a seed's pool of random interactions and every pretraining set of the preset."""

    preset: str
    seed: int
    pool: int
    sizes: tuple[int, ...]

    @property
    def branches(self) -> tuple[str, ...]:
        return tuple(pretrain_branch_name(self.preset, size, self.seed) for size in self.sizes)

    @property
    def label(self) -> str:
        return f"exp-{self.preset}-pretrain-s{self.seed}"


@dataclass(frozen=True)
class SequenceTask:
    """Solve one sequence; ``base`` (filled when submitted) holds its pretraining trials."""

    sequence: Sequence
    budget: int
    base: Payload | None = None
    #: Exploration trials between world-model refits (the preset's ``refit_every``).
    refit_every: int = 1
    #: Answer repeated trials from the worker's :class:`~llcps.sim.memo.TrialMemo`.
    memo: bool = True

    @property
    def branches(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.sequence.episode_branch(s) for s in SCENARIO_SEQUENCE))

    @property
    def label(self) -> str:
        return self.sequence.branch_name

    @property
    def pretrain_branch(self) -> str:
        return self.sequence.pretrain_branch


Task = PretrainTask | SequenceTask


@dataclass(frozen=True)
class TaskOutput:
    """What a worker sends back: the payload and how the task went."""

    label: str
    payload: Payload
    wall_seconds: float
    statuses: tuple[str, ...] = ()


def plan_tasks(preset: Preset, seeds: int | Iterable[int] | None = None, *, memo: bool = True) -> list[Task]:
    """Every task of a run, seed by seed: the seed's pretraining, then its sequences."""
    chosen = _seed_list(preset.default_seeds if seeds is None else seeds)
    sequences = preset.sequences(chosen)
    tasks: list[Task] = []
    for seed in chosen:
        tasks.append(PretrainTask(preset.name, seed, preset.pretrain_pool, tuple(preset.pretrain_sizes)))
        tasks.extend(
            SequenceTask(s, preset.budget, refit_every=preset.refit_every, memo=memo)
            for s in sequences
            if s.seed == seed
        )
    return tasks


def pretrain_subset(pool: Iterable[Any], size: int, *, seed: int) -> list[Any]:
    """``size`` trials of a pool, one per action in turn, chosen at random from the seed.

    Rounds go through the actions in :data:`~llcps.domain.ACTIONS` order, each taking
    one of its remaining trials, so 4 points are one per action when the pool has
    every action. The result keeps the pool's order.
    """
    import numpy as np

    from llcps.domain import ACTIONS

    trials = list(pool)
    if size >= len(trials):
        return trials
    rng = np.random.default_rng([seed, size, _SUBSET_STREAM])
    by_action = {action: [t for t in trials if t.spec.action == action] for action in ACTIONS}
    chosen: list[Any] = []
    while len(chosen) < size:
        for action in ACTIONS:
            options = by_action[action]
            if options and len(chosen) < size:
                chosen.append(options.pop(int(rng.integers(len(options)))))
    order = {id(t): i for i, t in enumerate(trials)}
    return sorted(chosen, key=lambda t: order[id(t)])


# --------------------------------------------------------------------------------------
# The task function (runs in a worker: a pool process or a Ray worker)
# --------------------------------------------------------------------------------------
_limited = False


def _limit_threads() -> None:
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


_scratch: str | None = None  # the private store's directory of the task in progress
_memo = None  # this worker's TrialMemo, made by the first sequence task that asks for one


def _worker_memo():
    """The worker process's trial memo, kept across its tasks."""
    global _memo
    if _memo is None:
        from llcps.sim.memo import TrialMemo

        _memo = TrialMemo()
    return _memo


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


def _init_local_worker() -> None:
    """Initializer of local pool workers."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and stops us
    signal.signal(signal.SIGTERM, _stop_worker)
    try:
        sys.stdout.flush()
        os.dup2(2, 1)  # native code prints to fd 1; the parent's stdout is for data
    except (OSError, ValueError):  # pragma: no cover - no real stdout
        pass
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True).start()
    _limit_threads()


def execute_task(task: Task) -> TaskOutput:
    """Run one task against a private temporary store and return its payload.

    The same function runs in a local pool process and as a Ray task.
    """
    global _scratch
    _limit_threads()
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="llcps-task-") as tmp:
        _scratch = tmp
        try:
            with Store.open(str(Path(tmp) / "task.db"), create=True) as store:
                if isinstance(task, PretrainTask):
                    payload, statuses = _run_pretrain(store, task), ()
                else:
                    payload, statuses = _run_sequence(store, task)
        finally:
            _scratch = None
    return TaskOutput(task.label, payload, time.perf_counter() - started, statuses)


def _run_pretrain(store: Store, task: PretrainTask) -> Payload:
    from llcps.pretrain import pretrain
    from llcps.domain import TrialRecord

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
                TrialRecord(
                    branch=name,
                    source=t.source,
                    spec=t.spec,
                    features=t.features,
                    outcome=t.outcome,
                    solved=t.solved,
                    sim_steps=t.sim_steps,
                    wall_seconds=t.wall_seconds,
                    seed=t.seed,
                    run_id=run_id,
                    snapshot_id=t.snapshot_id,
                    scenario=t.scenario,
                    extra={**t.extra, "pool": task.pool},
                )
                for t in chosen
            ],
            changes=[pool_changes.get(t.id) for t in chosen],  # type: ignore[arg-type]
        )
        store.finish_run(run_id, status="ok")
    return export_branches(store, task.branches)


def _run_sequence(store: Store, task: SequenceTask) -> tuple[Payload, tuple[str, ...]]:
    from llcps.cps.agent import solve
    from llcps.cps.episode import SolveConfig

    if task.base is None:
        raise LlcpsError(f"task {task.label} was sent without its pretraining trials")
    seeded = import_payload(store, task.base)
    seq = task.sequence
    memo = _worker_memo() if task.memo else None
    statuses: list[str] = []
    for scenario in SCENARIO_SEQUENCE:
        branch = seq.episode_branch(scenario)
        if scenario == SCENARIO_SEQUENCE[0] or seq.cell.condition == "reset":
            store.create_branch(branch, from_branch=seq.pretrain_branch, at=PRETRAIN)
        config = SolveConfig(
            scenario=scenario,
            condition="novelty",
            model=seq.cell.model,
            measure=seq.cell.measure,
            seed=seq.seed,
            budget=task.budget,
            refit_every=task.refit_every,
        )
        result = solve(store, branch=branch, config=config, command=f"{COMMAND} --preset {seq.preset}", memo=memo)
        if result.status == "interrupted":
            raise RuntimeError(f"{task.label}: {scenario} was interrupted")
        statuses.append(result.status)
    return export_branches(store, task.branches, external=inverse(seeded.trials)), tuple(statuses)


# --------------------------------------------------------------------------------------
# Engines: submit a task, wait for some, collect, stop
# --------------------------------------------------------------------------------------
class LocalEngine:
    """A spawn-context process pool; each worker owns its own PyBullet client."""

    name = "local"

    def __init__(self, workers: int) -> None:
        import multiprocessing

        self.workers = workers
        self._pool = ProcessPoolExecutor(
            max_workers=workers, mp_context=multiprocessing.get_context("spawn"), initializer=_init_local_worker
        )

    def submit(self, task: Task) -> Future:
        return self._pool.submit(execute_task, task)

    def wait(self, handles: Iterable[Future], timeout: float) -> list[Future]:
        done, _ = wait_futures(list(handles), timeout=timeout, return_when=FIRST_COMPLETED)
        return list(done)

    def result(self, handle: Future) -> TaskOutput:
        try:
            return handle.result()
        except BrokenProcessPool:
            raise EngineError(
                "a worker process died (out of memory, or killed)",
                hint="every task imported so far is kept; run the same command again to resume",
            ) from None

    def close(self, *, abort: bool, pending: Iterable[Future] = ()) -> None:
        if abort:  # drop the tasks in flight: their workers are stopped, nothing was written
            for process in list(getattr(self._pool, "_processes", {}).values()):
                process.terminate()
        self._pool.shutdown(wait=True, cancel_futures=True)


class RayEngine:
    """The same task function as a Ray task, on a local Ray instance or a cluster."""

    name = "ray"

    def __init__(self, workers: int, address: str | None) -> None:
        try:
            import ray
        except ImportError:
            raise LlcpsError(
                "the ray engine needs Ray, which is not installed", hint="pip install 'llcps[ray]'"
            ) from None
        self._ray = ray
        self.workers = workers
        self._started = not ray.is_initialized()
        if self._started:
            env = {name: "1" for name in THREAD_VARIABLES}
            options: dict[str, Any] = {
                "include_dashboard": False,
                "runtime_env": {"env_vars": env},
                "logging_level": "WARNING",
            }
            if address is None:
                options["num_cpus"] = workers
            try:
                ray.init(address=address, **options)
            except (ConnectionError, RuntimeError, ValueError) as exc:
                raise LlcpsError(
                    f"cannot start or reach Ray{f' at {address}' if address else ''}: {str(exc).splitlines()[0]}",
                    hint="check --ray-address (e.g. ray://host:10001 or auto), or drop it for a local instance",
                ) from None
        self._remote = ray.remote(num_cpus=1, max_retries=0)(execute_task)

    def submit(self, task: Task) -> Any:
        return self._remote.remote(task)

    def wait(self, handles: Iterable[Any], timeout: float) -> list[Any]:
        ready, _ = self._ray.wait(list(handles), num_returns=1, timeout=timeout)
        return list(ready)

    def result(self, handle: Any) -> TaskOutput:
        try:
            return self._ray.get(handle)
        except self._ray.exceptions.RayTaskError as exc:
            cause = exc.as_instanceof_cause()
            raise cause from None

    def close(self, *, abort: bool, pending: Iterable[Any] = ()) -> None:
        if abort:
            for handle in pending:
                try:
                    self._ray.cancel(handle, force=True)
                except Exception:  # noqa: BLE001 - already finished or gone
                    pass
        if self._started:
            self._ray.shutdown()


def make_engine(engine: str, workers: int, *, ray_address: str | None = None) -> LocalEngine | RayEngine:
    """An engine by name (see :data:`ENGINES`)."""
    if engine == "local":
        if ray_address is not None:
            raise LlcpsError("--ray-address needs --engine ray")
        return LocalEngine(workers)
    if engine == "ray":
        return RayEngine(workers, ray_address)
    raise UnknownNameError("engine", engine, ENGINES)


# --------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------
@dataclass
class RunSummary:
    """What a run did; ``status`` is ``ok``, ``failed`` (some task raised) or ``interrupted``."""

    preset: str
    seeds: tuple[int, ...]
    engine: str
    workers: int
    tasks: int = 0
    done: int = 0
    skipped: int = 0
    failed: list[tuple[str, str]] = field(default_factory=list)
    blocked: int = 0
    status: str = "running"
    wall_seconds: float = 0.0
    task_seconds: dict[str, float] = field(default_factory=dict)
    run_id: int | None = None

    def as_json(self) -> dict[str, Any]:
        return {
            "preset": self.preset,
            "seeds": list(self.seeds),
            "engine": self.engine,
            "workers": self.workers,
            "status": self.status,
            "tasks": self.tasks,
            "tasks_done": self.done,
            "tasks_skipped": self.skipped,
            "tasks_failed": [{"task": label, "error": error} for label, error in self.failed],
            "tasks_blocked": self.blocked,
            "wall_seconds": round(self.wall_seconds, 3),
            "task_seconds": {k: round(v, 3) for k, v in self.task_seconds.items()},
            "run_id": self.run_id,
        }


def results_table(store: Store, preset: str, seeds: Iterable[int] | None = None) -> ResultsTable:
    """The results of one preset (optionally some seeds) from the store's episodes."""
    wanted = None if seeds is None else set(seeds)
    table = table_from_episodes(store.list_episodes()).table
    return ResultsTable(r for r in table if r.preset == preset and (wanted is None or r.seed in wanted))


def one_preset(table: ResultsTable, preset: str | None = None) -> tuple[str, ResultsTable]:
    """The rows of ``preset``, or of the table's only preset when none is named.

    Presets share model and measure names, so a report over two of them would mix
    their cells; a table holding several needs a choice.
    """
    presets = table.unique("preset")
    if preset is None:
        if len(presets) > 1:
            raise LlcpsError(
                f"the results hold {len(presets)} presets: {', '.join(presets)}", hint="choose one with --preset"
            )
        if not presets:
            raise LlcpsError("there are no experiment results", hint="run `llcps experiment run` first")
        preset = str(presets[0])
    if preset not in presets:
        raise LlcpsError(
            f"no results of preset {preset!r}",
            hint=f"the results hold: {', '.join(presets)}" if presets else "run `llcps experiment run` first",
        )
    return preset, table.filter(preset=preset)


def with_baseline(table: ResultsTable, source: ResultsTable, baseline_preset: str) -> ResultsTable:
    """``table`` plus the random-order rows of ``baseline_preset`` from ``source``.

    A grid without the random model (``paper``) gets its baseline from a preset run
    beside it in the same store (``random``); the random order uses no training data,
    so its rows stand for any pretraining size.
    """
    from llcps.experiments.stats import BASELINE_MODEL

    extra = source.filter(preset=baseline_preset, model=BASELINE_MODEL)
    if len(extra) == 0:
        raise LlcpsError(
            f"no {BASELINE_MODEL}-model results of preset {baseline_preset!r}",
            hint=f"run `llcps experiment run --preset {baseline_preset}` on the same store first",
        )
    return ResultsTable([*table, *extra])


def default_out_dir(preset: str) -> Path:
    """``results/<preset>``."""
    return RESULTS_DIR / preset


def write_report(table: ResultsTable, out_dir: str | Path) -> tuple[Path, dict[str, Any]]:
    """Build every report file into ``out_dir``; returns it and the analysis as JSON data."""
    import json

    from llcps.experiments.report import build_report

    paths = build_report(table, out_dir)
    return paths.out_dir, json.loads(paths.figure2_json.read_text(encoding="utf-8"))


def _existing_branches(store: Store) -> set[str]:
    return {b.name for b in store.list_branches()}


def _check_partial(tasks: Iterable[Task], existing: set[str]) -> None:
    partial = [t for t in tasks if 0 < sum(b in existing for b in t.branches) < len(t.branches)]
    if partial:
        names = ", ".join(b for t in partial[:3] for b in t.branches if b in existing)
        raise LlcpsError(
            f"{len(partial)} task(s) have only some of their branches ({names}{', ...' if len(partial) > 3 else ''})",
            hint="a run imports a task's branches together; delete these with `llcps db delete NAME --yes` and run again",
        )


def run_experiment(
    store: Store,
    *,
    preset: Preset | str = "smoke",
    seeds: int | Iterable[int] | None = None,
    workers: int = 1,
    engine: str = "local",
    ray_address: str | None = None,
    progress: ProgressCallback | None = None,
    memo: bool = True,
) -> RunSummary:
    """Run every task of a preset's grid that the store does not hold yet.

    Args:
        store: the experience store; the only writer of this run.
        preset: a :class:`Preset` or a name in :data:`~llcps.experiments.grid.PRESETS`.
        seeds: a count (seeds ``0..n-1``), explicit seeds, or None for the preset's default.
        workers: processes (local) or concurrent Ray tasks.
        engine: one of :data:`ENGINES`.
        ray_address: a Ray cluster (None: start a local instance with ``workers`` CPUs).
        progress: see :data:`ProgressCallback`.
        memo: let each worker answer repeated trials from the physics it already ran
            (:mod:`llcps.sim.memo`); the results are the same either way.

    Returns:
        What ran; on Ctrl-C the tasks imported so far stay and ``status`` is ``interrupted``.
    """
    grid = get_preset(preset) if isinstance(preset, str) else preset
    validate_preset(grid)
    if engine not in ENGINES:
        raise UnknownNameError("engine", engine, ENGINES)
    if ray_address is not None and engine != "ray":
        raise LlcpsError("--ray-address needs --engine ray")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise LlcpsError(f"workers must be at least 1, not {workers!r}", hint="pass --workers 1 or more")
    tasks = plan_tasks(grid, seeds, memo=memo)
    seed_list = tuple(dict.fromkeys(t.seed if isinstance(t, PretrainTask) else t.sequence.seed for t in tasks))
    summary = RunSummary(preset=grid.name, seeds=seed_list, engine=engine, workers=workers, tasks=len(tasks))
    existing = _existing_branches(store)
    _check_partial(tasks, existing)
    todo = [t for t in tasks if not all(b in existing for b in t.branches)]
    summary.skipped = len(tasks) - len(todo)
    started = time.perf_counter()
    summary.run_id = store.start_run(
        command=f"{COMMAND} --preset {grid.name}",
        seed=None,
        config={"preset": grid.name, "seeds": list(seed_list), "workers": workers, "engine": engine, "memo": memo},
        branch=MAIN_BRANCH,
    )
    runner = None
    in_flight: dict[Any, Task] = {}
    try:
        if progress is not None:
            progress(0, len(todo), "")
        if todo:
            runner = make_engine(engine, workers, ray_address=ray_address)
            _loop(store, runner, todo, existing, summary, in_flight, progress)
        summary.status = "failed" if summary.failed or summary.blocked else "ok"
    except KeyboardInterrupt:
        summary.status = "interrupted"
    finally:
        if runner is not None:
            runner.close(abort=summary.status != "ok" or bool(in_flight), pending=list(in_flight))
        summary.wall_seconds = time.perf_counter() - started
        if summary.status == "running":
            summary.status = "failed"
        store.finish_run(summary.run_id, status=summary.status)
    return summary


def _loop(
    store: Store,
    runner: LocalEngine | RayEngine,
    todo: list[Task],
    existing: set[str],
    summary: RunSummary,
    in_flight: dict[Any, Task],
    progress: ProgressCallback | None,
) -> None:
    """Keep every worker busy with the first ready task; import results as they arrive."""
    pending = list(todo)
    bases: dict[str, Payload] = {}
    failed_pretraining: set[str] = set()
    finished = 0

    def ready(task: Task) -> bool:
        return isinstance(task, PretrainTask) or task.pretrain_branch in existing

    def blocked(task: Task) -> bool:
        return isinstance(task, SequenceTask) and task.pretrain_branch in failed_pretraining

    def refill() -> None:
        for task in [t for t in pending if blocked(t)]:
            summary.blocked += 1
            pending.remove(task)
        while len(in_flight) < runner.workers:
            task = next((t for t in pending if ready(t)), None)
            if task is None:
                return
            pending.remove(task)
            if isinstance(task, SequenceTask):
                base = bases.get(task.pretrain_branch)
                if base is None:
                    base = export_branches(store, [task.pretrain_branch], snapshots=False, provenance=False)
                    bases[task.pretrain_branch] = base
                task = replace(task, base=base)
            in_flight[runner.submit(task)] = task

    refill()
    while in_flight:
        for handle in runner.wait(in_flight, timeout=_POLL_SECONDS):
            task = in_flight.pop(handle)
            try:
                output = runner.result(handle)
            except EngineError:
                raise
            except Exception as exc:  # noqa: BLE001 - one failed task must not end the run
                summary.failed.append((task.label, f"{type(exc).__name__}: {exc}"))
                if isinstance(task, PretrainTask):
                    failed_pretraining.update(task.branches)
            else:
                refill()  # keep the workers busy while the parent writes
                if _import(store, output.payload, task):
                    summary.done += 1
                    summary.task_seconds[task.label] = output.wall_seconds
                else:
                    summary.skipped += 1  # imported meanwhile by another run on the same store
                existing.update(task.branches)
            finished += 1
            if progress is not None:
                progress(finished, len(todo), task.label)
            refill()
    summary.blocked += len(pending)


def _import(store: Store, payload: Payload, task: Task) -> bool:
    """Import a task's payload; False when another runner on the same store got there first."""
    if _exists(store, task.branches):
        return False
    try:
        import_payload(store, payload)
    except StoreError:
        if _exists(store, task.branches):  # lost the race; the transaction wrote nothing
            return False
        raise
    return True


def _exists(store: Store, branches: Iterable[str]) -> bool:
    try:
        for name in branches:
            store.resolve_branch(name)
    except UnknownNameError:
        return False
    return True


__all__ = [
    "ENGINES",
    "EngineError",
    "default_out_dir",
    "LocalEngine",
    "PretrainTask",
    "RayEngine",
    "RunSummary",
    "SequenceTask",
    "TaskOutput",
    "execute_task",
    "make_engine",
    "one_preset",
    "with_baseline",
    "plan_tasks",
    "pretrain_subset",
    "results_table",
    "run_experiment",
    "write_report",
]
