"""``llcps pretrain``: random interactions written to the store as ``pretrain`` trials."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Optional

import typer

from llcps.cli._common import CreateFlag, JsonFlag, choice_enum, db_location, message, print_json, print_table, selected_branch
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display
from llcps.domain import MAX_PRETRAIN_TRIALS, MAX_SEED, OUTCOME_NAMES
from llcps.jobs.pretrain import MAX_WORKERS, pretrain
from llcps.models import PAPER_MODELS, WORLD_MODELS

if TYPE_CHECKING:
    from llcps.cps.pretraining import PretrainSummary

ModelName = choice_enum("PretrainModel", tuple(WORLD_MODELS))


def pretrain_cli(
    ctx: typer.Context,
    trials: Annotated[
        int, typer.Option("--trials", metavar="N", min=0, max=MAX_PRETRAIN_TRIALS, help="Number of random interactions (trials) to run.")
    ] = 200,
    seed: Annotated[int, typer.Option("--seed", min=0, max=MAX_SEED, help="Run seed: trial i gets its own seed derived from it.")] = 0,
    model: Annotated[
        Optional[list[ModelName]],  # type: ignore[valid-type]
        typer.Option(
            "--model",
            metavar="NAME",
            help="World model to fit on the branch's trials afterwards (repeatable; default: the paper's nb and nn).",
            show_default=False,
        ),
    ] = None,
    model_seed: Annotated[
        int,
        typer.Option(
            "--model-seed", min=0, max=MAX_SEED, help="Seed of the fitted models (`llcps solve --model-seed` reuses a model fitted with it)."
        ),
    ] = 0,
    again: Annotated[
        bool,
        typer.Option(
            "--again",
            help="Run the interactions even when a finished pretraining with the same --trials and --seed is on the branch "
            "(it adds the same trials once more).",
        ),
    ] = False,
    workers: Annotated[
        int,
        typer.Option(
            "--workers", metavar="N", min=1, max=MAX_WORKERS,
            help="Processes that run the interactions side by side (the stored trials are the same for any number).",
        ),
    ] = 1,
    create: CreateFlag = False,
    as_json: JsonFlag = False,
) -> None:
    """Run N random interactions in settled random scenes, store each as a trial, then
    fit the world models on every trial the branch sees (stored for `llcps solve`).

    The same seed writes the same trials (features, outcome, sim steps) bit for bit, so a
    pretraining with the same --trials and --seed already on the branch is skipped (and
    the models fitted or loaded as before); --again runs it once more.
    """
    names = [str(m.value) for m in model] if model else list(PAPER_MODELS)  # type: ignore[attr-defined]
    with progress_display("pretrain", "loading the simulator") as progress:
        result = pretrain(
            store=db_location(ctx),
            branch=selected_branch(ctx),
            trials=trials,
            seed=seed,
            models=names,
            model_seed=model_seed,
            again=again,
            create=create,
            workers=workers,
            progress=progress,
        )
    summary, fitted = result.summary, result.models
    if result.skipped:
        message(
            f"pretraining with --trials {trials} --seed {seed} is already on branch {summary.branch} "
            f"(run {summary.run_id}): skipped; --again to add more"
        )
    if as_json:
        print_json(result.as_json())
    else:
        show(summary)
        print_table("world models fitted", ("model", "seed", "trials", "fit seconds"), [(f.name, f.seed, f.trials, f"{f.fit_seconds:.2f}") for f in fitted])


EXAMPLES = examples(
    "llcps pretrain                                 # 200 random interactions, nb and nn fitted",
    "llcps pretrain --trials 50 --seed 3 --model nb",
    "llcps pretrain --trials 200 --seed 1 --workers 2      # on two cores: the same trials",
    "llcps pretrain --trials 200 --seed 1 --again          # the same 200 trials once more",
    "llcps --branch exp pretrain --trials 200 --model-seed 1 --json",
)


def show(summary: "PretrainSummary") -> None:
    """The run summary for people: Omega label frequencies and throughput."""
    n = summary.trials
    rows = [
        (name, summary.outcome_counts[name], f"{summary.outcome_counts[name] / n:.1%}" if n else "-")
        for name in OUTCOME_NAMES
    ]
    print_table(
        f"{n} pretraining trials on {summary.branch} (seed {summary.seed}): Omega", ("bit", "trials", "share"), rows
    )
    efficiency = f"{summary.efficiency:.0%}" if summary.efficiency is not None else "-"
    control = f"{summary.control_loop_rate:,.0f}" if summary.control_loop_rate else "-"
    print_table(
        None,
        ("", ""),
        [
            ("actions", ", ".join(f"{k} {v}" for k, v in summary.action_counts.items())),
            ("wall seconds", f"{summary.wall_seconds:.1f}"),
            ("trials / s", f"{summary.trials_per_second:.2f}"),
            ("sim steps / s (wall)", f"{summary.steps_per_second:,.0f}"),
            ("sim steps / CPU s", f"{summary.steps_per_cpu_second:,.0f}"),
            ("control loop / CPU s", control),
            ("efficiency", efficiency),
        ],
        show_header=False,
    )
