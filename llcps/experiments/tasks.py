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
from llcps.experiments.design import Sequence, explores_in, pretrain_branch_name
from llcps.cps.orderings import PAPER_ORDERING
from llcps.experiments.life import Life, LifeCondition, LifeEpisode, after_branch, episode_branch, life_branch
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
    #: Try last what the arm would refuse (the preset's ``reach_check``; SolveConfig's).
    reach_check: bool = False
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


@dataclass(frozen=True)
class LifeTask:
    """Solve one life under one condition, then (if asked) re-solve every family met on
    forks of its end; ``base`` (filled when submitted) holds its pretraining trials.

    Attributes:
        life: the life's name (its branches' second field).
        condition: how the episodes are solved (:data:`~llcps.experiments.life.LIFE_CONDITIONS`).
        seed: the life's number: the seed of its draws and of every episode's solve.
        episodes: the life's episodes (the same for every condition of the life).
        after: (family, fresh variant) re-solved after the life, in the novelty and the
            original condition, each on its own fork of the life's end.
        sources: family -> what the worker passes to ``get_scenario``.
        pretrain: the pretraining branch (None: the life starts from nothing).
    """

    life: str
    condition: LifeCondition
    seed: int
    episodes: tuple[LifeEpisode, ...]
    sources: tuple[tuple[str, str], ...]
    model: str
    measure: str
    budget: int
    pretrain: str | None
    after: tuple[tuple[str, int], ...] = ()
    refit_every: int = 1
    ordering: str = PAPER_ORDERING
    reach_check: bool = False
    base: Payload | None = None
    cache_url: str | None = None

    def source(self, family: str) -> str:
        return dict(self.sources)[family]

    def episode_branch(self, index: int) -> str:
        return episode_branch(self.life, self.condition, self.seed, index)

    def after_branch(self, family: str, condition: str) -> str:
        return after_branch(self.life, self.condition.name, self.seed, family, condition)

    @property
    def branches(self) -> tuple[str, ...]:
        names = [self.episode_branch(e.index) for e in self.episodes]
        names += [self.after_branch(family, c) for family, _ in self.after for c in ("novelty", "original")]
        return tuple(dict.fromkeys(names))

    @property
    def label(self) -> str:
        return life_branch(self.life, self.condition.name, self.seed)

    @property
    def pretrain_branch(self) -> str | None:
        return self.pretrain


Task = PretrainTask | SequenceTask | LifeTask


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
    return task.sequence.seed if isinstance(task, SequenceTask) else task.seed


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
            SequenceTask(
                s,
                budget,
                refit_every=preset.refit_every,
                ordering=explores_in(s.cell.model, preset.ordering),
                reach_check=preset.reach_check,
                cache_url=cache_url,
                sources=sources,
            )
            for s in sequences
            if s.seed == seed
        )
    return tasks


def plan_life_tasks(life: Life, seeds: Iterable[int], *, cache_url: str | None = None) -> list[Task]:
    """Every task of a life run, life by life: its pretraining (unless no condition
    pretrains or another life shares it), then one task per condition.

    Every condition of life N gets the same draw (:func:`~llcps.experiments.life.draw_life`).
    """
    from llcps.experiments.life import draw_life, life_condition, pretrain_branch, pretrain_preset, pretrain_seed

    conditions = [life_condition(name) for name in life.conditions]
    budget = life.solve_budget()
    tasks: list[Task] = []
    planned: set[str] = set()
    for seed in seed_list(seeds):
        draw = draw_life(life, seed)
        pretrain = pretrain_branch(life, seed)
        if any(c.pretrained for c in conditions) and pretrain not in planned:
            planned.add(pretrain)
            tasks.append(PretrainTask(pretrain_preset(life), pretrain_seed(life, seed), life.pretrain_count, (life.pretrain_count,)))
        for condition in conditions:
            tasks.append(
                LifeTask(
                    life=life.name,
                    condition=condition,
                    seed=seed,
                    episodes=draw.episodes,
                    sources=life.families,
                    model=life.model_for(condition),
                    measure=life.measure_name(),
                    budget=budget,
                    pretrain=pretrain if condition.pretrained else None,
                    after=draw.after if condition.forgets else (),
                    refit_every=life.refit_every,
                    ordering=life.ordering_for(condition),
                    reach_check=life.reach_check,
                    cache_url=cache_url,
                )
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


__all__ = ["LifeTask", "PretrainTask", "plan_life_tasks", "SequenceTask", "Task", "TaskOutput", "plan_tasks", "pretrain_subset", "task_seed"]
