"""``llcps pretrain``: random interactions stored as trials, then the world models fitted on them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Sequence

from llcps.jobs._common import Progress, StoreRef, no_progress, opened

if TYPE_CHECKING:
    from llcps.models.persistence import FittedModel
    from llcps.cps.pretraining import PretrainSummary

#: Most worker processes of one pretraining.
MAX_WORKERS = 64
#: The phase in which the random interactions run (counted trial by trial).
INTERACTIONS = "random interactions"


@dataclass(frozen=True)
class PretrainResult:
    """What a pretraining run stored, and the world models fitted afterwards."""

    summary: PretrainSummary
    models: tuple[FittedModel, ...]
    #: The same pretraining (trials, seed) was already on the branch: nothing was run,
    #: ``summary`` sums up that earlier run (its ``run_id``).
    skipped: bool = False

    def as_json(self) -> dict[str, Any]:
        return {**self.summary.as_json(), "skipped": self.skipped, "models": [f.as_json() for f in self.models]}


def pretrain(
    *,
    store: StoreRef,
    branch: str | None = None,
    trials: int = 200,
    seed: int = 0,
    models: Sequence[str] | None = None,
    model_seed: int = 0,
    again: bool = False,
    create: bool = False,
    workers: int = 1,
    progress: Progress | None = None,
) -> PretrainResult:
    """Run ``trials`` random interactions on ``branch`` (None: the current branch), store each
    as a ``pretrain`` trial (with the run), then fit ``models`` (default: the paper's nb and nn)
    on every trial the branch sees, with ``model_seed``.

    When a finished pretraining run with the same ``trials`` and ``seed`` is already on the
    branch (its trials all visible), it would write the same trials again: nothing is run
    (``skipped``) unless ``again``; the models are fitted (or loaded) all the same.
    ``create`` makes the store when ``store`` names none yet. ``workers`` processes run the
    interactions side by side; the stored trials are the same for any number of them.
    """
    from llcps.models import PAPER_MODELS
    from llcps.cps.pretraining import finished_pretraining
    from llcps.cps.pretraining import pretrain as run_pretrain  # the simulator loads only when a job needs it

    report = progress or no_progress
    names = list(models) if models else list(PAPER_MODELS)
    with opened(store, create=create) as s:
        earlier = None if again else finished_pretraining(s, branch=branch, n=trials, seed=seed)
        if earlier is not None:
            summary = earlier
        else:
            summary = run_pretrain(
                s,
                branch=branch,
                n=trials,
                seed=seed,
                workers=workers,
                progress=lambda done, total: report(INTERACTIONS, done, total),
            )
        from llcps.models.persistence import fit_models  # torch / sklearn load only here

        fitted = fit_models(
            s,
            summary.branch,
            names,
            model_seed,
            progress=lambda name, done, total: report(
                "fitting world models" if done == total else f"fitting world model {name}", done, total
            ),
        )
    return PretrainResult(summary=summary, models=tuple(fitted), skipped=earlier is not None)
