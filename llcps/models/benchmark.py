"""Fit, update, predict and ranking times of the world models on toy trials.

``python -m llcps.models.benchmark`` prints the table docs/world_models.md reports.
Times are the minimum over repeats (the least disturbed run) of wall-clock seconds
on this machine; they are figures to report, never assertions in tests.

- *fit*: a fresh model fitted on n trials (every trial encoded).
- *update*: ``WorldModel.update`` with those n trials plus one new one, as the agent does
  during exploration. What that costs depends on the model: naive Bayes and the
  scikit-learn baselines refit on the n + 1 trials (known trials' rows reused); the
  network fine-tunes its current weights for a fixed number of steps
  (``NeuralNetworkModel.update_steps``), which is not a fit on n + 1 trials.
- *predict*: predicted Omega for 1,000 candidates.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict, dataclass
from typing import Callable, Sequence

import numpy as np

from llcps.models.measures import MEASURES, rank
from llcps.models.registry import PAPER_MODELS, make_world_model
from llcps.models.synthetic import synthetic_trials


@dataclass(frozen=True)
class Timing:
    """Seconds for one model at one training-set size."""

    model: str
    n_trials: int
    fit: float
    update: float
    predict: float


def _best(action: Callable[[], object], repeats: int, clock: Callable[[], float] = time.perf_counter) -> float:
    times = []
    for _ in range(repeats):
        start = clock()
        action()
        times.append(clock() - start)
    return min(times)


def time_world_models(
    names: Sequence[str] = PAPER_MODELS,
    sizes: Sequence[int] = (200, 2000, 10000),
    *,
    seed: int = 0,
    candidates: int = 1000,
    repeats: int = 3,
    clock: Callable[[], float] = time.perf_counter,
) -> list[Timing]:
    """Time fit / update / predict of each model at each training-set size.

    ``clock``: wall time by default; ``time.process_time`` (CPU time of the process)
    is steadier on a busy machine for single-threaded models.
    """
    pool = synthetic_trials(max(sizes) + 1, seed=seed)
    queries = [r.model_input for r in synthetic_trials(candidates, seed=seed + 1)]
    rows = []
    for name in names:
        for n in sizes:
            fit = _best(lambda: make_world_model(name, seed).fit(pool[:n]), repeats, clock)
            model = make_world_model(name, seed)
            growing = list(pool[:n])

            def update() -> None:
                model.fit(growing[:n])
                growing.append(pool[n])
                start = clock()
                model.update(growing)
                update_times.append(clock() - start)
                growing.pop()

            update_times: list[float] = []
            for _ in range(repeats):
                update()
            predict = _best(lambda: model.predict_proba(queries), repeats, clock)
            rows.append(Timing(name, n, fit, min(update_times), predict))
    return rows


def time_ranking(n: int = 1000, *, seed: int = 0, repeats: int = 5) -> float:
    """Seconds to rank ``n`` candidates under every measure (given predictions)."""
    proba = np.random.default_rng(seed).random((n, 6))
    desired = np.eye(6)[2]
    return _best(lambda: [rank(proba, name, seed=seed, desired=desired) for name in MEASURES], repeats)


def markdown(rows: Sequence[Timing], ranking: float) -> str:
    """The timing table as Markdown (milliseconds)."""
    lines = [
        "| model | trials | fit (ms) | update +1 trial (ms) | predict 1,000 (ms) |",
        "|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r.model} | {r.n_trials:,} | {r.fit * 1e3:.1f} | {r.update * 1e3:.1f} | {r.predict * 1e3:.1f} |")
    lines.append("")
    lines.append(f"Ranking 1,000 candidates under all {len(MEASURES)} measures: {ranking * 1e3:.2f} ms.")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=list(PAPER_MODELS))
    parser.add_argument("--sizes", nargs="+", type=int, default=[200, 2000, 10000])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    rows = time_world_models(args.models, args.sizes, repeats=args.repeats)
    ranking = time_ranking()
    if args.json:
        import json

        print(json.dumps({"timings": [asdict(r) for r in rows], "ranking_seconds": ranking}, indent=2))
    else:
        print(markdown(rows, ranking))


if __name__ == "__main__":
    main()
