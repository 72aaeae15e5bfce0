"""Scheduling an experiment run: keep every worker busy, import results as they arrive.

The parent process is the only writer of a run's results: it imports each task's
payload in one transaction on the grid's deterministic branch names, so a kill
loses only the tasks in flight, a re-run skips every task whose branches exist,
and two runners sharing a store (PostgreSQL) never import a task twice.
A sequence task waits for its seed's pretraining to be imported, then carries
that pretraining branch's trials to its worker.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, Iterable

from llcps.errors import LlcpsError, StoreError, UnknownNameError
from llcps.experiments.executors import Engine, EngineError
from llcps.experiments.tasks import LifeTask, PretrainTask, SequenceTask, Task
from llcps.experiments.transfer import Payload, export_branches, import_payload
from llcps.store import Store

#: Seconds between checks for Ctrl-C and finished tasks.
POLL_SECONDS = 0.5

ProgressCallback = Callable[[int, int, str], None]
"""Called as ``progress(done, total, label)`` after each task is imported (or fails)."""


@dataclass
class RunSummary:
    """What a run did; ``status`` is ``ok``, ``failed`` (some task raised) or ``interrupted``."""

    preset: str
    seeds: tuple[int, ...]
    engine: str
    workers: int
    tasks: int = 0
    #: Whether seed N solved scene variant N (otherwise every seed the canonical scenes).
    variants: bool = False
    done: int = 0
    skipped: int = 0
    failed: list[tuple[str, str]] = field(default_factory=list)
    blocked: int = 0
    status: str = "running"
    wall_seconds: float = 0.0
    task_seconds: dict[str, float] = field(default_factory=dict)
    run_id: int | None = None
    #: Physics-cache counts summed over the tasks (None: the run used no cache).
    cache: dict[str, int] | None = None

    def count_cache(self, counts: dict[str, int] | None) -> None:
        """Add one task's physics-cache counts."""
        if counts is None:
            return
        if self.cache is None:
            self.cache = {}
        for key, value in counts.items():
            self.cache[key] = self.cache.get(key, 0) + int(value)

    @property
    def cache_hit_rate(self) -> float | None:
        """Trials answered from the cache over trials asked of it."""
        if not self.cache:
            return None
        asked = self.cache.get("hits", 0) + self.cache.get("misses", 0)
        return None if asked == 0 else self.cache.get("hits", 0) / asked

    def as_json(self) -> dict[str, Any]:
        return {
            "preset": self.preset,
            "seeds": list(self.seeds),
            "variants": list(self.seeds) if self.variants else [0],
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
            "cache": None if self.cache is None else {**self.cache, "hit_rate": self.cache_hit_rate},
        }



def existing_branches(store: Store) -> set[str]:
    return set(store.branch_names())  # names only: counting every branch's trials takes minutes in a store of thousands


def check_partial(tasks: Iterable[Task], existing: set[str]) -> None:
    partial = [t for t in tasks if 0 < sum(b in existing for b in t.branches) < len(t.branches)]
    if partial:
        names = ", ".join(b for t in partial[:3] for b in t.branches if b in existing)
        raise LlcpsError(
            f"{len(partial)} task(s) have only some of their branches ({names}{', ...' if len(partial) > 3 else ''})",
            hint="a run imports a task's branches together; delete these with `llcps db delete NAME --yes` and run again",
        )


def expected_scenarios(task: SequenceTask) -> dict[str, list[str]]:
    """Branch -> the scenarios its episodes solve, in order, when ``task`` runs."""
    names = list(task.sequence.scenarios)
    condition = task.sequence.cell.condition
    if condition == "update":
        return {task.sequence.branch_name: names}
    if condition == "others":
        return {task.sequence.episode_branch(s): [o for o in names if o != s] + [s] for s in names}
    return {task.sequence.episode_branch(s): [s] for s in names}


def check_scenarios(store: Store, tasks: Iterable[Task], existing: set[str]) -> None:
    """Fail when a stored sequence solved another scenario list than this run would.

    Branch names do not encode a sequence's scenarios, so an ``update`` or ``others``
    branch run with one list would pass for a run with another. Reset branches hold one
    scenario each and cannot disagree.
    """
    stored = [
        t
        for t in tasks
        if isinstance(t, SequenceTask) and t.sequence.cell.condition != "reset" and all(b in existing for b in t.branches)
    ]
    if not stored:
        return
    held: dict[str, list[str]] = {}
    for episode in sorted(store.list_episodes(), key=lambda e: e.id):
        if episode.condition == "novelty" and episode.status != "running":
            held.setdefault(episode.branch, []).append(episode.scenario)
    for task in stored:
        for branch, wanted in expected_scenarios(task).items():
            have = held.get(branch, [])
            if have and have != wanted:
                raise LlcpsError(
                    f"branch {branch} holds episodes of {', '.join(have)}, not of {', '.join(wanted)} as this run asks",
                    hint=(
                        "a preset's update and others sequences solve one scenario list per store: use another "
                        "--db, or delete the branch with `llcps db delete NAME --yes`"
                    ),
                )


def twin_key(task: Task) -> tuple[object, ...] | None:
    """What a sequence shares with its other-condition twin: both start scenario 1 alike.

    A life's ``update`` and ``reset`` (same model, from the same pretraining) share its first episode.
    """
    if isinstance(task, LifeTask):
        if not task.condition.pretrained:
            return None
        return ("life", task.life, task.seed, task.model, task.measure)
    if not isinstance(task, SequenceTask):
        return None
    cell = task.sequence.cell
    return (task.sequence.preset, task.sequence.seed, cell.model, cell.measure, cell.pretrain_size, task.sequence.draw)


def schedule(
    store: Store,
    runner: Engine,
    todo: list[Task],
    existing: set[str],
    summary: RunSummary,
    in_flight: dict[Any, Task],
    progress: ProgressCallback | None,
) -> None:
    """Keep every worker busy with the first ready task; import results as they arrive.

    Of the ready tasks, one whose twin is not in flight goes first (see :func:`twin_key`);
    a twin that has finished its first scenario counts as not in flight, since what
    the two share is then in the physics cache.
    """
    pending = list(todo)
    bases: dict[str, Payload] = {}
    failed_pretraining: set[str] = set()
    finished = 0

    def ready(task: Task) -> bool:
        return isinstance(task, PretrainTask) or task.pretrain_branch is None or task.pretrain_branch in existing

    def blocked(task: Task) -> bool:
        return not isinstance(task, PretrainTask) and task.pretrain_branch in failed_pretraining

    def refill(*, twins: bool = True) -> None:
        """Start ready tasks on idle workers; a twin of a running task only if ``twins``."""
        for task in [t for t in pending if blocked(t)]:
            summary.blocked += 1
            pending.remove(task)
        while len(in_flight) < runner.workers:
            candidates = [t for t in pending if ready(t)]
            past = runner.past_first_scenario()
            busy = {twin_key(t) for t in in_flight.values() if t.label not in past} - {None}
            # A sequence whose twin (same seed and cell, other condition) is in its first
            # scenario would simulate that scenario at the same time; run something else
            # first, and the twin's trials come from the physics cache when it starts.
            task = next((t for t in candidates if twin_key(t) not in busy), None)
            if task is None and twins:
                task = next(iter(candidates), None)
            if task is None:
                return
            pending.remove(task)
            if not isinstance(task, PretrainTask) and task.pretrain_branch is not None:
                base = bases.get(task.pretrain_branch)
                if base is None:
                    base = export_branches(store, [task.pretrain_branch], snapshots=False, provenance=False, policies=True)
                    bases[task.pretrain_branch] = base
                task = replace(task, base=base)
            in_flight[runner.submit(task)] = task

    refill()
    while in_flight:
        for handle in runner.wait(in_flight, timeout=POLL_SECONDS):
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
                # Keep the workers busy while the parent writes, but not with a twin of a
                # running task: the import may make better tasks ready (a pretraining's
                # sequences), and a twin run alongside repeats its physics.
                refill(twins=False)
                if _import(store, output.payload, task):
                    summary.done += 1
                    summary.task_seconds[task.label] = output.wall_seconds
                    summary.count_cache(output.cache)
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
    "POLL_SECONDS",
    "ProgressCallback",
    "RunSummary",
    "check_partial",
    "check_scenarios",
    "existing_branches",
    "expected_scenarios",
    "schedule",
]
