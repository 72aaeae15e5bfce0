"""The cost of fitting W: fit, update with one more trial and predict of every registered world model.

``update`` is what the agent calls during exploration, and it is not the same work
for every model: a refit on n + 1 trials for naive Bayes and the baselines, a fixed
number of fine-tuning steps of the current weights for the network.
"""

from __future__ import annotations

import time
from functools import partial

from llcps.bench.core import Figure, Progress, figure, say
from llcps.models.benchmark import time_world_models
from llcps.models.registry import PAPER_MODELS, WORLD_MODELS

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


__all__ = ["GROUP", "MODEL_SIZES", "MODEL_SIZES_QUICK", "SLOW_MODELS", "UPDATE_TARGETS", "run"]
