"""The cost of ranking with W's predictions: 1,000 candidates ordered under every measure."""

from __future__ import annotations

import numpy as np

from llcps.bench.core import Figure, Progress, best_of, figure, say
from llcps.models.measures import MEASURES, rank

GROUP = "ranking"


def time_ranking(n: int = 1000, *, seed: int = 0, repeats: int = 5) -> float:
    """Seconds to rank ``n`` candidates under every measure (given predictions), the best of ``repeats``."""
    proba = np.random.default_rng(seed).random((n, 6))
    desired = np.eye(6)[2]
    return best_of(lambda: [rank(proba, name, seed=seed, desired=desired) for name in MEASURES], repeats)


def run(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Ranking 1,000 candidates (given predictions) under every measure."""
    say(progress, "ranking: 1,000 candidates")
    seconds = time_ranking(1000, repeats=3 if quick else 10)
    return [figure(GROUP, "all_measures_1000", seconds * 1e3, "ms", at_most=50, note=f"all {len(MEASURES)} measures")]


__all__ = ["GROUP", "run", "time_ranking"]
