"""The cost of fitting W: fit, update with one more trial and predict of every registered world model.

Times are the minimum over repeats (the least disturbed run) on seeded synthetic
trials (:mod:`llcps.models.synthetic`):

- *fit*: a fresh model fitted on n trials (every trial encoded).
- *update*: ``WorldModel.update`` with those n trials plus one new one, as the agent does
  during exploration. What that costs depends on the model: naive Bayes and the
  scikit-learn baselines refit on the n + 1 trials (known trials' rows reused); the
  network fine-tunes its current weights for a fixed number of steps
  (``NeuralNetworkModel.update_steps``), which is not a fit on n + 1 trials.
- *predict*: predicted Omega for 1,000 candidates.

``llcps bench --group models`` reports them as figures; ``python -m llcps.bench.models``
prints the table docs/world_models.md reports.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from functools import partial

from llcps.bench.core import Figure, Progress, best_of, figure, say
from llcps.bench.ranking import time_ranking
from llcps.models.measures import MEASURES
from llcps.models.registry import PAPER_MODELS, WORLD_MODELS, make_world_model
from llcps.models.synthetic import synthetic_trials

GROUP = "models"
_figure = partial(figure, GROUP)

#: Training-set sizes of the world-model timings.
MODEL_SIZES = (200, 2_000, 10_000)
MODEL_SIZES_QUICK = (200, 2_000)
#: Targets of ``update`` with one more trial at 10,000 trials (seconds) by model name.
UPDATE_TARGETS = {"nb": 0.020, "nn": 2.0}
#: Models timed once per size in the full run: a fit takes about a second or more, so the
#: minimum of three adds little but time.
SLOW_MODELS = ("nn", "logreg", "forest")


@dataclass(frozen=True)
class Timing:
    """Seconds for one model at one training-set size."""

    model: str
    n_trials: int
    fit: float
    update: float
    predict: float


def time_world_models(
    names: Sequence[str] = PAPER_MODELS,
    sizes: Sequence[int] = MODEL_SIZES,
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
            fit = best_of(lambda: make_world_model(name, seed).fit(pool[:n]), repeats, clock)
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
            predict = best_of(lambda: model.predict_proba(queries), repeats, clock)
            rows.append(Timing(name, n, fit, min(update_times), predict))
    return rows


def run(quick: bool = False, progress: Progress | None = None) -> list[Figure]:
    """Fit, update (+1 trial) and predict (1,000 candidates) of every registered model at each size.

    Quick mode times the paper's models only, at 10,000 trials only where a target
    is set, with one repeat.
    """
    figures = []
    names = PAPER_MODELS if quick else tuple(WORLD_MODELS)
    for name in names:
        sizes = MODEL_SIZES_QUICK + ((10_000,) if name in UPDATE_TARGETS else ()) if quick else MODEL_SIZES
        say(progress, f"models: {name} at {', '.join(map(str, sizes))} trials")
        WORLD_MODELS[name].model_class()  # import scikit-learn / torch before the clock starts
        repeats = 1 if quick or name in SLOW_MODELS else 3
        what = _update_note(name)
        for row in time_world_models([name], sizes, repeats=repeats):
            subject = f"{name}.{row.n_trials}"
            target = UPDATE_TARGETS.get(name) if row.n_trials == 10_000 else None
            figures += [
                _figure("fit", row.fit * 1e3, "ms", subject=subject),
                _figure("update", row.update * 1e3, "ms", subject=subject, at_most=None if target is None else target * 1e3, note=what),
                _figure("predict", row.predict * 1e3, "ms", subject=subject, note="1,000 candidates"),
            ]
    # CPU time where it means the model's own work: naive Bayes runs on one thread (torch
    # uses several, so its CPU time would count each of them).
    say(progress, "models: nb update at 10,000 trials in CPU time")
    (row,) = time_world_models(["nb"], (10_000,), repeats=5, clock=time.process_time)
    figures.append(_figure("update_cpu", row.update * 1e3, "ms cpu", subject="nb.10000", note="the same update in CPU time, steady on a busy machine"))
    return figures


def _update_note(name: str) -> str:
    """What ``update()`` with one more trial does for a model, truthfully."""
    steps = getattr(WORLD_MODELS[name].model_class(), "update_steps", None)
    if steps is not None:
        return f"update() with one more trial: {steps} fine-tuning steps of the current weights, not a fit on n + 1"
    return "update() with one more trial: a refit on n + 1 trials"


def markdown(rows: Sequence[Timing], ranking: float) -> str:
    """The timing table as Markdown (milliseconds), with the ranking time below it."""
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
    """``python -m llcps.bench.models``: the table of docs/world_models.md (or ``--json``)."""
    parser = argparse.ArgumentParser(description="Fit, update, predict and ranking times of the world models on toy trials.")
    parser.add_argument("--models", nargs="+", default=list(PAPER_MODELS))
    parser.add_argument("--sizes", nargs="+", type=int, default=list(MODEL_SIZES))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    rows = time_world_models(args.models, args.sizes, repeats=args.repeats)
    ranking = time_ranking()
    if args.json:
        print(json.dumps({"timings": [asdict(r) for r in rows], "ranking_seconds": ranking}, indent=2))
    else:
        print(markdown(rows, ranking))


__all__ = ["GROUP", "MODEL_SIZES", "MODEL_SIZES_QUICK", "SLOW_MODELS", "UPDATE_TARGETS", "Timing", "markdown", "run", "time_world_models"]


if __name__ == "__main__":
    main()
