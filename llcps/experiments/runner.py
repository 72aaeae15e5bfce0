"""The experiment runner: a preset's grid, run as tasks on an engine, into one store.

A run plans its tasks (:mod:`llcps.experiments.tasks`), leaves out those the store
already holds, and schedules the rest on an engine (:mod:`llcps.experiments.executors`:
a local process pool or Ray) that runs :func:`llcps.experiments.worker.execute_task`;
the scheduler (:mod:`llcps.experiments.scheduler`) imports each result as it
arrives. Results are identical for any number of workers, either engine, with or
without the physics cache, and after a resume. See docs/experiments.md.
"""

from __future__ import annotations

import time
from typing import Any, Iterable

from llcps.errors import LlcpsError, UnknownNameError
from llcps.cps.orderings import PAPER_ORDERING
from llcps.experiments.design import RANDOM_ORDER_MODEL
from llcps.experiments.executors import ENGINES, EngineError, LocalEngine, RayEngine, make_engine
from llcps.experiments.presets import Preset, get_preset, validate_preset
from llcps.experiments.scheduler import ProgressCallback, RunSummary, check_partial, check_scenarios, existing_branches, schedule
from llcps.experiments.life import Life
from llcps.experiments.tasks import (
    LifeTask,
    PretrainTask,
    SequenceTask,
    Task,
    TaskOutput,
    plan_life_tasks,
    plan_tasks,
    pretrain_subset,
    task_seed,
)
from llcps.experiments.worker import COMMAND, LIFE_COMMAND, execute_task
from llcps.store import MAIN_BRANCH, Store
from llcps.store.model_artifacts import POLICY_NAME
from llcps.store import physics_cache


def cache_url(store: Store, *, remote_workers: bool = False) -> str | None:
    """The URL workers open to share ``store``'s physics cache (with its credentials).

    None when the workers cannot reach it: a SQLite file is on this machine only, so
    workers on a Ray cluster run without the cache (a PostgreSQL store serves them all).
    """
    url = store.engine.url
    if remote_workers and url.get_backend_name() == "sqlite":
        return None
    return url.render_as_string(hide_password=False)


def run_experiment(
    store: Store,
    *,
    preset: Preset | str = "smoke",
    seeds: int | Iterable[int] | None = None,
    variants: bool = False,
    scenarios: Iterable[str] | None = None,
    with_others: bool = False,
    ordering: str | None = None,
    workers: int = 1,
    engine: str = "local",
    ray_address: str | None = None,
    progress: ProgressCallback | None = None,
    cache: bool = True,
) -> RunSummary:
    """Run every task of a preset's grid that the store does not hold yet.

    Args:
        store: the experience store; the only writer of this run.
        preset: a :class:`Preset` or a name in :data:`~llcps.experiments.presets.PRESETS`.
        seeds: a count (seeds ``0..n-1``), explicit seeds, or None for the preset's default.
        variants: seed N solves its scenarios in scene variant N (paired with the seeds,
            not crossed); otherwise every seed solves the canonical scenes (variant 0).
        scenarios: the scenarios each sequence solves, in order (names, aliases or .toml
            paths); None: the preset's own list (the paper's three for the paper's presets).
        with_others: solve each scenario after the list's other scenarios on its branch
            (the preset's ``reset`` becomes ``others``; see :meth:`Preset.with_others`).
        ordering: the exploration ordering of every episode (None: the preset's). The
            branch names do not say it: run another ordering into another store.
        workers: processes (local) or concurrent Ray tasks.
        engine: one of :data:`ENGINES`.
        ray_address: a Ray cluster (None: start a local instance with ``workers`` CPUs).
        progress: see :data:`ProgressCallback`.
        cache: let workers answer trials simulated before (by this run or an earlier
            one on the store) from the store's physics cache
            (:mod:`llcps.store.physics_cache`); the results are the same either way.
            The cache is pruned back to its bound when the run ends. Workers on a Ray
            cluster share it only through a PostgreSQL store.

    Returns:
        What ran; on Ctrl-C the tasks imported so far stay and ``status`` is ``interrupted``.
    """
    grid = get_preset(preset) if isinstance(preset, str) else preset
    grid = grid.with_scenarios(scenarios).with_ordering(ordering)
    if with_others:
        grid = grid.with_others()
    validate_preset(grid)
    check_run_options(engine, workers, ray_address)
    shared = cache_url(store, remote_workers=ray_address is not None) if cache else None
    tasks = plan_tasks(grid, seeds, variants=variants, cache_url=shared)
    check_orderings(store, tasks)
    check_policies(store, tasks)
    seed_list = tuple(dict.fromkeys(task_seed(t) for t in tasks))
    summary = RunSummary(
        preset=grid.name, seeds=seed_list, variants=variants, engine=engine, workers=workers, tasks=len(tasks)
    )
    config = {
        "preset": grid.name,
        "seeds": list(seed_list),
        "variants": variants,
        "scenarios": [name for name in grid.scenario_names()],
        "conditions": list(grid.conditions),
        "ordering": grid.ordering,
        "workers": workers,
        "engine": engine,
        "cache": cache,
    }
    command = (
        f"{COMMAND} --preset {grid.name}" + (" --variants" if variants else "") + (" --with-others" if with_others else "")
        + (f" --ordering {grid.ordering}" if ordering else "")
    )  # fmt: skip
    return run_tasks(
        store, tasks, summary, command=command, config=config, engine=engine, ray_address=ray_address, progress=progress, cache=cache
    )


def check_orderings(store: Store, tasks: Iterable[Task]) -> None:
    """A sequence the store holds already was explored in the ordering asked for now.

    Branch names do not say the ordering, so a run in another ordering would find every
    sequence stored and report the stored ordering's episodes as if they were its own.
    The random order's sequences are every ordering's baseline and are not checked.
    """
    existing = existing_branches(store)
    for t in tasks:
        if not isinstance(t, SequenceTask) or t.sequence.cell.model == RANDOM_ORDER_MODEL:
            continue
        if not all(b in existing for b in t.branches):
            continue
        for branch in t.branches:
            episodes = store.list_episodes(branch=branch, limit=1)
            stored = str(episodes[0].summary.get("ordering") or PAPER_ORDERING) if episodes and isinstance(episodes[0].summary, dict) else None
            if stored is not None and stored != t.ordering:
                raise LlcpsError(
                    f"this store holds the sequences of this grid explored in the {stored!r} ordering ({branch}, ...), "
                    f"not {t.ordering!r}: experiment branch names do not say the ordering, so nothing would run",
                    hint="run each ordering into a store of its own (another --db; a copy of this SQLite file keeps its "
                    "pretraining and random order, once `llcps db delete` took the stored ordering's sequences out of it), "
                    "then merge the reports: `llcps experiment report DIR1 DIR2 --out-dir DIR`",
                )
            break


def check_policies(store: Store, tasks: Iterable[Task]) -> None:
    """Every sequence or life still to run in the ``rl`` ordering finds a trained policy
    on the branch it starts from (a worker carries the one that branch sees); checked
    before anything runs."""
    existing = existing_branches(store)
    to_run = [
        t for t in tasks
        if isinstance(t, (SequenceTask, LifeTask)) and t.ordering == "rl" and not all(b in existing for b in t.branches)
    ]  # fmt: skip
    starts = sorted({t.pretrain_branch or MAIN_BRANCH for t in to_run})
    missing = [b for b in starts if b not in existing]
    if missing:
        raise LlcpsError(
            f"the rl ordering needs the pretraining branches first; {len(missing)} are missing ({', '.join(missing[:3])}"
            f"{', ...' if len(missing) > 3 else ''})",
            hint="run once with another ordering or condition (it pretrains), then store a policy on each pretraining "
            "branch: `llcps --branch NAME rl import policy.npz`",
        )
    without = [b for b in starts if store.latest_world_model(b, POLICY_NAME, 0) is None]
    if without:
        raise LlcpsError(
            f"the rl ordering needs a trained policy on every pretraining branch; {len(without)} have none "
            f"({', '.join(without[:3])}{', ...' if len(without) > 3 else ''})",
            hint="store one on each: `llcps --branch NAME rl import policy.npz` (a policy `llcps rl train --out` wrote)",
        )


def run_tasks(
    store: Store,
    tasks: list[Task],
    summary: RunSummary,
    *,
    command: str,
    config: dict[str, Any],
    engine: str,
    ray_address: str | None,
    progress: ProgressCallback | None,
    cache: bool,
) -> RunSummary:
    """Run the tasks the store does not hold yet on ``summary.workers`` workers, as one
    recorded run; the part every kind of run (a preset's grid, lives) shares.

    A task whose branches all exist is skipped (a resume); one with only some of them
    is an error (a run imports a task's branches together).
    """
    existing = existing_branches(store)
    check_partial(tasks, existing)
    check_scenarios(store, tasks, existing)
    todo = [t for t in tasks if not all(b in existing for b in t.branches)]
    summary.skipped = len(tasks) - len(todo)
    started = time.perf_counter()
    summary.run_id = store.start_run(command=command, seed=None, config=config, branch=MAIN_BRANCH)
    runner = None
    in_flight: dict[Any, Task] = {}
    try:
        if progress is not None:
            progress(0, len(todo), "")
        if todo:
            runner = make_engine(engine, summary.workers, ray_address=ray_address)
            schedule(store, runner, todo, existing, summary, in_flight, progress)
        summary.status = "failed" if summary.failed or summary.blocked else "ok"
    except KeyboardInterrupt:
        summary.status = "interrupted"
    finally:
        if runner is not None:
            runner.close(abort=summary.status != "ok" or bool(in_flight), pending=list(in_flight))
        summary.wall_seconds = time.perf_counter() - started
        if summary.status == "running":
            summary.status = "failed"
        if cache and summary.status != "interrupted":
            physics_cache.prune(store)
        store.finish_run(summary.run_id, status=summary.status)
    return summary


def run_lives(
    store: Store,
    life: Life,
    *,
    lives: int | Iterable[int] = 1,
    workers: int = 1,
    engine: str = "local",
    ray_address: str | None = None,
    progress: ProgressCallback | None = None,
    cache: bool = True,
) -> RunSummary:
    """Run every (life, condition) of ``life`` the store does not hold yet.

    Args:
        life: a checked life file (:func:`~llcps.experiments.life.load_life`), possibly
            cut short (:meth:`~llcps.experiments.life.Life.with_episodes`) or under other
            conditions (:meth:`~llcps.experiments.life.Life.with_conditions`).
        lives: a count (lives ``0..n-1``) or the lives' numbers (their seeds).
        workers, engine, ray_address, progress, cache: as for :func:`run_experiment`.
            One task is one life under one condition: a kill loses the lives in
            flight, and the same command resumes with the rest.
    """
    check_run_options(engine, workers, ray_address)
    shared = cache_url(store, remote_workers=ray_address is not None) if cache else None
    tasks = plan_life_tasks(life, lives, cache_url=shared)
    chosen = tuple(dict.fromkeys(task_seed(t) for t in tasks if isinstance(t, LifeTask)))
    summary = RunSummary(preset=life.name, seeds=chosen, engine=engine, workers=workers, tasks=len(tasks))
    check_lives(store, [t for t in tasks if isinstance(t, LifeTask)])
    check_policies(store, tasks)
    config = {
        "life": life.name,
        "source": life.source,
        "lives": list(chosen),
        "episodes": life.episodes,
        "conditions": list(life.conditions),
        "workers": workers,
        "engine": engine,
        "cache": cache,
    }
    return run_tasks(
        store, tasks, summary, command=f"{LIFE_COMMAND} {life.name}", config=config, engine=engine, ray_address=ray_address,
        progress=progress, cache=cache,
    )  # fmt: skip


def check_lives(store: Store, tasks: Iterable[LifeTask]) -> None:
    """Fail when a stored life solved other episodes than this run would draw.

    Branch names do not encode a life's episodes: a life file edited between two runs
    (or cut to another ``--episodes``) would pass for the same life.
    """
    wanted = {t.label: [(e.family, e.variant, e.condition) for e in t.episodes] for t in tasks}
    held: dict[str, list[tuple[Any, ...]]] = {}
    for episode in sorted(store.list_episodes(), key=lambda e: e.id):
        place = episode.summary.get("life") if isinstance(episode.summary, dict) else None
        if not isinstance(place, dict) or place.get("phase") != "life":
            continue
        label = f"life-{place.get('name')}-{place.get('condition')}-l{place.get('life')}"
        if label in wanted:
            held.setdefault(label, []).append((place.get("family"), place.get("variant"), episode.condition))
    for label, have in held.items():
        if have != wanted[label]:
            raise LlcpsError(
                f"{label} holds {len(have)} other episodes than this run draws ({len(wanted[label])})",
                hint="a life's name stands for one list of episodes per store: use another --db, or delete its branches "
                "(`llcps db delete NAME --yes`)",
            )


def check_run_options(engine: str, workers: int, ray_address: str | None) -> None:
    """The engine, its address and the worker count, checked before anything runs."""
    if engine not in ENGINES:
        raise UnknownNameError("engine", engine, ENGINES)
    if ray_address is not None and engine != "ray":
        raise LlcpsError("--ray-address needs --engine ray")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise LlcpsError(f"workers must be at least 1, not {workers!r}", hint="pass --workers 1 or more")


__all__ = [
    "ENGINES",
    "EngineError",
    "LocalEngine",
    "PretrainTask",
    "RayEngine",
    "RunSummary",
    "SequenceTask",
    "Task",
    "TaskOutput",
    "cache_url",
    "execute_task",
    "make_engine",
    "plan_tasks",
    "pretrain_subset",
    "run_experiment",
    "run_lives",
    "run_tasks",
]
