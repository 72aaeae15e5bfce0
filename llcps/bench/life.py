"""The cost of a life: per-episode work outside physics as the experience store grows.

A synthetic life (:mod:`llcps.models.synthetic`: toy trials and changes, no physics)
of :data:`TRIALS_PER_EPISODE` trials per episode. At episode ``k`` the store holds the
trials of the episodes before it, and the episode before it has fitted its world model
(so what a life keeps between episodes, the stored model and encoded examples, is
there). The episode's overhead is measured as a real episode spends it: taking its
training set and fitting the goal-directed world model at the episode's start (``fit``),
then per trial as exploration does, encoding and ranking every candidate of a toy
failure (``rank``), writing the trial (``store``) and bringing the model up to it
(``update``). An episode reads the store's trials only when its fit needs them
(:class:`~llcps.training.TrainingSet`).
Past :data:`~llcps.models.schedule.FULL_FIT_TRIALS` trials an episode's fit counts its
new trials into the stored model, and a full fit comes once each time the training set
doubles (:mod:`llcps.models.schedule`); its cost, measured as the fit of the episode
before, is spread over the episodes of its doubling (``refit``), so ``overhead`` is
what an episode costs on average at that point of the life. A life grows linearly;
the target is an overhead at episode 1,000 within 1.2 times that at episode 10 (a cost
that stays flat as experience grows).

The store is filled with batched inserts, not episode by episode, so a point far into
the life costs one fit before it, not a thousand. The group also measures the store of
a long life: 1,000,000 trials on a branch, the load of its visible set as columns
(:meth:`~llcps.store.Store.visible_columns`, target ≤ 2 s) and, without a target, as
records (what a model's fit reads), and durable single-trial commits on it (target
≥ 1,000/s).
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from functools import partial
from pathlib import Path

from threadpoolctl import threadpool_limits

from llcps.bench.core import Clock, Figure, Progress, figure, say
from llcps.bench.store import TrialPool
from llcps.cps.candidates import enumerate_candidates
from llcps.models import fit_or_load
from llcps.models.measures import rank
from llcps.models.persistence import clear_fits
from llcps.models.relational import GoalQuery
from llcps.models.schedule import FULL_FIT_TRIALS, bins_trials
from llcps.models.synthetic import synthetic_changes, synthetic_trials
from llcps.errors import LlcpsError
from llcps.store import Store
from llcps.trial_records import TrialChange, TrialRecord, WorldModelInput

GROUP = "life"
_figure = partial(figure, GROUP)

#: The episodes whose overhead is measured, and with ``--quick``.
EPISODES = (10, 100, 1000)
EPISODES_QUICK = (10, 100)
#: Trials each episode of the synthetic life adds to the store.
TRIALS_PER_EPISODE = 10
#: The world model and measure of the life (the paper's goal-directed agent's).
MODEL = "nb"
MEASURE = "goal-directed"
#: Trials of the store measured at scale, and with ``--quick``.
STORE_TRIALS = 1_000_000
STORE_TRIALS_QUICK = 100_000
#: Most trials per transaction when the store is filled.
BATCH = 5000
#: The toy failure every episode ranks candidates for: an object that must go in a container.
MISSING = ("in", "entity0", "entity4")


@dataclass(frozen=True)
class EpisodeCost:
    """CPU seconds of one episode's work outside physics, at a point of the life."""

    episode: int
    trials: int
    fit: float
    rank: float
    store: float
    #: The world model's updates, one per trial.
    update: float = 0.0
    #: The episode's share of the full fit that comes once per doubling of the training set.
    refit: float = 0.0

    @property
    def overhead(self) -> float:
        return self.fit + self.rank + self.store + self.update + self.refit

    def as_json(self) -> dict[str, float]:
        return {**asdict(self), "overhead": self.overhead}


def _episode_trials(episode: int) -> tuple[list[TrialRecord], list[TrialChange]]:
    """The toy trials of one episode of the life (seeded by the episode) and their changes."""
    made = synthetic_trials(TRIALS_PER_EPISODE, seed=episode)
    changes = synthetic_changes(made, seed=episode)
    records = [
        TrialRecord(
            branch="main", source="exploration", spec=r.spec, features=r.features, outcome=r.outcome,
            solved=False, sim_steps=0, wall_seconds=0.0, seed=episode,
        )
        for r in made
    ]
    return records, [changes[r.id] for r in made]  # type: ignore[index]


def _grow(store: Store, first: int, last: int) -> None:
    """Write the trials of episodes ``first`` .. ``last - 1`` in batches."""
    records: list[TrialRecord] = []
    changes: list[TrialChange] = []
    for episode in range(first, last):
        more, more_changes = _episode_trials(episode)
        records += more
        changes += more_changes
        if len(records) >= BATCH or episode == last - 1:
            store.add_trials(records, changes=changes)
            records, changes = [], []


def _query() -> tuple[GoalQuery, list[WorldModelInput]]:
    """Every candidate for the toy failure of :data:`MISSING` in a toy scene, as a goal
    query and as world-model inputs."""
    probe = synthetic_trials(1, seed=0, start_id=1)
    bodies = next(iter(synthetic_changes(probe, seed=0).values())).bodies
    kinds = {b.name: b.kind for b in bodies if b.is_entity}
    query = GoalQuery.from_missing(enumerate_candidates(failed=None, entities=kinds), missing_add=[MISSING], missing_del=[], bodies=bodies)
    entity = probe[0].features[0]
    inputs = [WorldModelInput(spec, (entity,) * len(spec.arguments)) for spec in query.candidates]
    return query, inputs


def episode_cost(
    store: Store, episode: int, query: GoalQuery, inputs: Sequence[WorldModelInput], full_fit: float = 0.0
) -> EpisodeCost:
    """The overhead of episode ``episode``, whose predecessors' trials are all in ``store``.

    Args:
        full_fit: CPU seconds of a full fit at this point of the life; an episode whose
            own fit only counts (past ``FULL_FIT_TRIALS`` trials) takes its share.
    """
    clear_fits()  # no fit of this process is reused: a life's processes do not share memory
    with Clock() as fit:
        records, changes = store.training_set("main")
        model = fit_or_load(store, "main", MODEL, 0, records=records, changes=changes)
    ranking = storing = updating = 0.0
    for record, change in zip(*_episode_trials(episode)):  # as exploration does: rank, try, learn
        with Clock() as clock:
            rank(model.predict_proba(inputs), MEASURE, seed=episode, goal=model.predict_goal(query))
        ranking += clock.cpu
        with Clock() as clock:
            trial_id = store.add_trial(record, change=change)
            records.append(replace(record, id=trial_id))
            changes[trial_id] = replace(change, trial_id=trial_id)
        storing += clock.cpu
        with Clock() as clock:
            model.update(records, changes)
        updating += clock.cpu
    trials = len(records)
    before = trials - TRIALS_PER_EPISODE
    refit = 0.0 if before <= FULL_FIT_TRIALS else full_fit * TRIALS_PER_EPISODE / bins_trials(before)
    return EpisodeCost(episode, trials, fit.cpu, ranking, storing, updating, refit)


def live(episodes: Sequence[int], progress: Progress | None = None, *, path: Path | None = None) -> list[EpisodeCost]:
    """Run a synthetic life to each of ``episodes`` (ascending) and measure each of them."""
    query, inputs = _query()
    costs = []
    import sklearn.linear_model  # noqa: F401 - loads the BLAS libraries the limit below must reach

    # One BLAS thread, as in an experiment's workers: on a busy machine a threaded BLAS
    # spins in the goal head's small logistic fits (ten times the CPU at 100 trials).
    with threadpool_limits(1), tempfile.TemporaryDirectory(prefix="llcps-life-") as tmp:
        with Store.open(f"sqlite:///{path or Path(tmp) / 'life.db'}", create=True) as store:
            done = 1
            for episode in episodes:
                say(progress, f"life: episode {episode} ({(episode - 1) * TRIALS_PER_EPISODE:,} trials before it)")
                _grow(store, done, episode - 1)
                clear_fits()
                with Clock() as full_fit:  # the episode before fits on what it saw (past the fit before: a full fit)
                    fit_or_load(store, "main", MODEL, 0)
                _grow(store, episode - 1, episode)
                costs.append(episode_cost(store, episode, query, inputs, full_fit.cpu))
                done = episode + 1
    return costs


@dataclass(frozen=True)
class StoreAtScale:
    """The store of a long life: how long filling it took, reading what a branch sees, and
    durable commits on it."""

    trials: int
    fill_seconds: float
    visible_load: Clock
    records_load: Clock
    commits_per_s: float


def store_at_scale(n: int, progress: Progress | None = None, *, commits: int = 300) -> StoreAtScale:
    """A store of ``n`` trials on one branch, each with features of its own (as pretraining
    writes them), filled with batched inserts; then its visible set loaded once as
    columns and once as records, and ``commits`` single-trial durable commits."""
    pool = TrialPool()
    with tempfile.TemporaryDirectory(prefix="llcps-life-") as tmp:
        with Store.open(str(Path(tmp) / "scale.db"), create=True) as store:
            say(progress, f"life: filling a store with {n:,} trials")
            with Clock() as fill:
                for start in range(0, n, BATCH):
                    store.add_trials(list(pool.trials(min(BATCH, n - start), "main", start=start)))
            say(progress, f"life: loading the {n:,} visible trials as columns")
            with Clock() as load:
                seen = len(store.visible_columns("main"))
            say(progress, f"life: loading the {n:,} visible trials as records")
            with Clock() as records:
                if len(store.visible_trials("main")) != seen:
                    raise LlcpsError(f"the visible set read as records and as columns differ in size ({seen:,} as columns)")
            say(progress, f"life: {commits} durable commits on {seen:,} trials")
            one_by_one = list(pool.trials(commits, "main", start=n))
            with Clock() as single:
                for trial in one_by_one:
                    store.add_trial(trial)
    return StoreAtScale(seen, fill.wall, load, records, commits / single.wall)


def run(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """The overhead outside physics of episodes 10, 100 and 1,000 of a synthetic life, and
    the store at 1,000,000 trials (100,000 with ``quick``)."""
    costs = live(EPISODES_QUICK if quick else EPISODES, progress)
    scale = store_at_scale(STORE_TRIALS_QUICK if quick else STORE_TRIALS, progress)
    figures = []
    for cost in costs:
        subject = f"episode{cost.episode}"
        note = (
            f"{cost.trials:,} trials; {MODEL} fit {cost.fit:.3f} s, {TRIALS_PER_EPISODE} trials' rank {cost.rank:.3f} s, "
            f"store {cost.store:.3f} s, update {cost.update:.3f} s, share of the full fit per doubling {cost.refit:.4f} s"
        )
        figures += [
            _figure("overhead", cost.overhead, "s CPU", subject=subject, note=note),
            _figure("fit", cost.fit, "s CPU", subject=subject),
            _figure("rank", cost.rank, "s CPU", subject=subject),
            _figure("store", cost.store, "s CPU", subject=subject),
            _figure("update", cost.update, "s CPU", subject=subject),
            _figure("refit", cost.refit, "s CPU", subject=subject),
        ]
    first, last = costs[0], costs[-1]
    figures.append(
        _figure(
            "growth", last.overhead / max(first.overhead, 1e-9), "x", at_most=1.2,
            note=f"overhead at episode {last.episode} over that at episode {first.episode}",
        )
    )
    subject = f"store{scale.trials}"
    figures += [
        _figure("fill", scale.fill_seconds, "s wall", subject=subject, note=f"{BATCH:,} trials per transaction"),
        _figure(
            "visible_load", scale.visible_load.wall, "s wall", subject=subject,
            at_most=2.0 if scale.trials >= STORE_TRIALS else None,
            note="as columns (Store.visible_columns: packed blocks and the rows after them); every trial's features distinct",
        ),
        _figure("visible_load_cpu", scale.visible_load.cpu, "s cpu", subject=subject),
        _figure(
            "visible_records_load", scale.records_load.wall, "s wall", subject=subject,
            note="as one TrialRecord per trial (Store.visible_trials), what a model's full fit reads",
        ),
        _figure("commits_per_s", scale.commits_per_s, "trials/s wall", subject=subject, at_least=1000, note="add_trial one at a time, each durable on return"),
    ]
    return figures


__all__ = ["EPISODES", "GROUP", "STORE_TRIALS", "EpisodeCost", "StoreAtScale", "episode_cost", "live", "run", "store_at_scale"]
