"""The experience store's throughput: durable commits, batched inserts, and the visible set
of a branch three levels deep (what a fit reads at the start of every episode).
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import replace
from functools import cached_property, partial
from pathlib import Path

from llcps.bench.core import Clock, Figure, Progress, figure, say
from llcps.domain import EntityFeatures
from llcps.trial_records import Body, TrialChange, TrialRecord
from llcps.models.synthetic import synthetic_changes, synthetic_trials
from llcps.store import Store

GROUP = "store"
_figure = partial(figure, GROUP)

#: Trials the deepest branch of the store bench sees.
VISIBLE_TRIALS = 100_000
VISIBLE_TRIALS_QUICK = 10_000
#: Trials per transaction of the batched inserts.
BATCH = 5000


def _pretrain_trial(pooled: TrialRecord, *, branch: str, features: tuple[EntityFeatures, ...], seed: int) -> TrialRecord:
    """A new pretraining trial on ``branch`` with ``pooled``'s action and outcome and these features."""
    return TrialRecord(
        branch=branch,
        source="pretrain",
        spec=pooled.spec,
        features=features,
        outcome=pooled.outcome,
        solved=pooled.solved,
        sim_steps=pooled.sim_steps,
        wall_seconds=pooled.wall_seconds,
        seed=seed,
    )


class TrialPool:
    """A seeded pool of synthetic trials and their symbolic changes, cycled into as many
    new trials as a measurement stores; the pool and its changes are made on first use.
    """

    def __init__(self, size: int = 997, *, seed: int = 7) -> None:
        self.size, self.seed = size, seed

    @cached_property
    def records(self) -> list[TrialRecord]:
        return synthetic_trials(self.size, seed=self.seed)

    @cached_property
    def _changes_by_id(self) -> dict[int, TrialChange]:
        return synthetic_changes(self.records, seed=self.seed)

    def trials(self, n: int, branch: str, start: int = 0, *, unique: bool = True) -> Iterator[TrialRecord]:
        """Trials ``start`` to ``start + n`` on ``branch``, the pool cycled; with ``unique``
        every trial's features are made distinct (the store's decoder shares repeated ones).
        """
        pool = self.records
        for i in range(start, start + n):
            r = pool[i % len(pool)]
            first = r.features[0]
            features = (replace(first, volume=first.volume * (1.0 + i * 1e-9)),) + r.features[1:] if unique else r.features
            yield _pretrain_trial(r, branch=branch, features=features, seed=i)

    def changes(self, n: int, start: int = 0) -> list[TrialChange]:
        """The symbolic changes of :meth:`trials`'s trials, each in a scene of its own (as in
        pretraining: the first body moved by a trial-specific amount), so none is shared."""
        pool = self.records
        out = []
        for i in range(start, start + n):
            change = self._changes_by_id[pool[i % len(pool)].id]
            first = change.bodies[0]
            moved = Body(first.name, first.kind, first.shape, (first.lo[0] + i * 1e-9, *first.lo[1:]), first.hi, first.centre)
            out.append(replace(change, bodies=(moved, *change.bodies[1:]), trial_id=None))
        return out


def _deep_branch(pool: TrialPool, path: Path, visible: int, *, unique: bool, repeats: int) -> tuple[int, float, list[Clock], list[Clock]]:
    """Fill main <- level1 <- level2 <- level3 (a quarter each) in batches, then load level3's visible set.

    With ``unique`` every trial also gets a symbolic change of its own, and the changes
    level3 sees are loaded too (what a fit reads beside the trials).

    Returns (trials seen, batched inserts/s of the trials alone, one clock per load of
    the trials, one per load of the changes).
    """
    chain: Sequence[str] = ("main", "level1", "level2", "level3")
    inserted, wall = 0, 0.0
    with Store.open(str(path), create=True) as store:
        for level, name in enumerate(chain):
            if level:
                store.create_branch(name, from_branch=chain[level - 1])
            share = visible // len(chain) if level < len(chain) - 1 else visible - inserted
            while share > 0:
                rows = list(pool.trials(min(BATCH, share), name, start=inserted, unique=unique))
                if unique:
                    store.add_trials(rows, changes=pool.changes(len(rows), start=inserted))
                else:
                    with Clock() as clock:
                        store.add_trials(rows)
                    wall += clock.wall
                inserted += len(rows)
                share -= len(rows)
        loads = []
        for _ in range(repeats):
            with Clock() as load:
                records = store.visible_trials(chain[-1])
            seen = len(records)
            del records  # freeing 100,000 records (~0.1 s) is not part of loading them
            loads.append(load)
        change_loads = []
        for _ in range(repeats if unique else 0):
            with Clock() as load:
                changes = store.visible_changes(chain[-1])
            del changes
            change_loads.append(load)
    return seen, inserted / wall if wall else float("nan"), loads, change_loads


def run(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Durable single-trial commits, batched inserts, and the visible set of a branch three levels deep.

    The visible set is loaded twice: with every trial's features distinct (pretraining
    trials, each from its own random scene: the decoder's worst case) and with
    features repeated as in exploration (one scene per episode). The first also holds
    each trial's symbolic change, in a scene of its own, and loads those as well.
    """
    pool = TrialPool()
    commits = 300 if quick else 1000
    visible = VISIBLE_TRIALS_QUICK if quick else VISIBLE_TRIALS
    repeats = 2
    target = 1.0 if visible == VISIBLE_TRIALS else None
    with tempfile.TemporaryDirectory(prefix="llcps-bench-") as tmp:
        with Store.open(str(Path(tmp) / "commits.db"), create=True) as store:
            say(progress, f"store: {commits} single-trial commits")
            one_by_one = list(pool.trials(commits, "main"))
            with Clock() as single:
                for trial in one_by_one:
                    store.add_trial(trial)
        say(progress, f"store: a branch 3 levels deep seeing {visible:,} trials with distinct features")
        seen, _, unique, changes = _deep_branch(pool, Path(tmp) / "unique.db", visible, unique=True, repeats=repeats)
        say(progress, f"store: a branch 3 levels deep seeing {visible:,} trials with repeated features")
        _, batched, shared, _ = _deep_branch(pool, Path(tmp) / "shared.db", visible, unique=False, repeats=repeats)
    return [
        _figure("commits_per_s", commits / single.wall, "trials/s wall", at_least=1000, note="add_trial one at a time, each durable on return"),
        _figure("batched_inserts_per_s", batched, "trials/s wall", note="add_trials, 5,000 per transaction (trials without changes)"),
        _figure("visible_trials", seen, "trials", note="seen by a branch 3 levels deep"),
        _figure("visible_load", min(c.wall for c in unique), "s wall", at_most=target, note="every trial's features distinct (pretraining)"),
        _figure("visible_load_cpu", min(c.cpu for c in unique), "s cpu"),
        _figure("visible_load_shared", min(c.wall for c in shared), "s wall", note="features repeated (exploration in one scene)"),
        _figure("visible_load_shared_cpu", min(c.cpu for c in shared), "s cpu"),
        _figure("visible_changes_load", min(c.wall for c in changes), "s wall", note="the same trials' symbolic changes, each in a scene of its own: what a fit reads beside them"),
        _figure("visible_changes_load_cpu", min(c.cpu for c in changes), "s cpu"),
    ]


__all__ = ["BATCH", "GROUP", "VISIBLE_TRIALS", "VISIBLE_TRIALS_QUICK", "TrialPool", "run"]
