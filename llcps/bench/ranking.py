"""The cost of ranking with W's predictions: 1,000 candidates ordered under every measure."""

from __future__ import annotations

from llcps.bench.core import Figure, Progress, figure, say
from llcps.models.benchmark import time_ranking
from llcps.models.measures import MEASURES

GROUP = "ranking"


def run(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Ranking 1,000 candidates (given predictions) under every measure."""
    say(progress, "ranking: 1,000 candidates")
    seconds = time_ranking(1000, repeats=3 if quick else 10)
    return [figure(GROUP, "all_measures_1000", seconds * 1e3, "ms", at_most=50, note=f"all {len(MEASURES)} measures")]


__all__ = ["GROUP", "run"]
