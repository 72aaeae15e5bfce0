"""The tasks of an experiment run: what a worker is asked to do, and what it sends back.

A run is a list of *tasks*: per seed one pretraining task (the seed's pool of
random interactions and every pretraining set drawn from it, each on its own
branch) and one task per sequence of the grid (the preset's scenarios, by default
scenario1 -> scenario2 -> scenario3, under ``update``, ``reset`` or ``others``). Tasks
are plain, picklable data, so the same task runs in a local pool process or as a Ray task.

Pretraining never sees a scenario: the pool is random layouts from the sampler's
catalog (:mod:`llcps.sim.sampler`), the same whichever scenarios the preset solves,
so every scenario (novelty family) is held out of it.

The paper's protocol, per (preset, pretraining size, seed): one pretraining branch
shared by every model and measure of that seed. The seed's pool is
``pretrain(n=preset.pretrain_pool, seed)``; a set as large as the pool is the pool
itself, a smaller one is drawn from it one trial per action in turn
(:func:`pretrain_subset`; the paper's 4 points are one per action).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable

from llcps.domain import ACTIONS
from llcps.experiments.design import Sequence, pretrain_branch_name
from llcps.cps.orderings import PAPER_ORDERING
from llcps.experiments.presets import Preset, resolve_scenarios, seed_list
from llcps.experiments.transfer import Payload

#: Stream tag of :func:`pretrain_subset` (kept apart from every other use of the seed).
_SUBSET_STREAM = 0x5E7


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
    #: The exploration ordering (the preset's ``ordering``).
    ordering: str = PAPER_ORDERING
    #: The store whose physics cache answers trials simulated before (None: no cache).
    #: A URL with its credentials: the worker opens the store itself.
    cache_url: str | None = None
    #: What the worker passes to ``get_scenario`` for each of the sequence's scenarios,
    #: in order (a shipped name, or a .toml file's absolute path); empty: the names.
    sources: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.sources and len(self.sources) != len(self.sequence.scenarios):
            raise ValueError("a sequence task needs one source per scenario")

    @property
    def scenarios(self) -> tuple[tuple[str, str], ...]:
        """``(name, source)`` of each scenario the sequence solves, in order."""
        return tuple(zip(self.sequence.scenarios, self.sources or self.sequence.scenarios))

    @property
    def branches(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.sequence.episode_branch(s) for s in self.sequence.scenarios))

    @property
    def label(self) -> str:
        return self.sequence.branch_name

    @property
    def pretrain_branch(self) -> str:
        return self.sequence.pretrain_branch


Task = PretrainTask | SequenceTask


@dataclass(frozen=True)
class TaskOutput:
    """What a worker sends back: the payload and how the task went.

    Attributes:
        cache: the task's physics-cache counts (hits, misses, stored), empty without a cache.
    """

    label: str
    payload: Payload
    wall_seconds: float
    statuses: tuple[str, ...] = ()
    cache: dict[str, Any] | None = None


def task_seed(task: Task) -> int:
    """The seed a task belongs to."""
    return task.seed if isinstance(task, PretrainTask) else task.sequence.seed


def plan_tasks(
    preset: Preset, seeds: int | Iterable[int] | None = None, *, variants: bool = False, cache_url: str | None = None
) -> list[Task]:
    """Every task of a run, seed by seed: the seed's pretraining, then its sequences.

    ``variants``: seed N solves scene variant N (see :meth:`Preset.sequences`).
    """
    chosen = seed_list(preset.default_seeds if seeds is None else seeds)
    sequences = preset.sequences(chosen, variants=variants)
    sources = tuple(source for _, source in resolve_scenarios(preset.scenarios))
    tasks: list[Task] = []
    budget = preset.exploration_budget()
    for seed in chosen:
        tasks.append(PretrainTask(preset.name, seed, preset.pretrain_pool, tuple(preset.pretrain_sizes)))
        tasks.extend(
            SequenceTask(s, budget, refit_every=preset.refit_every, ordering=preset.ordering, cache_url=cache_url, sources=sources)
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
    import numpy as np  # not at import: the CLI loads this module to start

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


__all__ = ["PretrainTask", "SequenceTask", "Task", "TaskOutput", "plan_tasks", "pretrain_subset", "task_seed"]
