"""``llcps pretrain``: random interactions written to the store as ``pretrain`` trials."""

from __future__ import annotations

import time
from typing import Annotated, Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from llcps.cli._common import CreateFlag, JsonFlag, choice_enum, err_console, open_store, print_json, print_table, selected_branch
from llcps.domain import MAX_SEED, OUTCOME_NAMES
from llcps.models import PAPER_MODELS, WORLD_MODELS
from llcps.pretrain import MAX_PRETRAIN_TRIALS, PretrainSummary, pretrain

ModelName = choice_enum("PretrainModel", tuple(WORLD_MODELS))


def pretrain_cli(
    ctx: typer.Context,
    n: Annotated[
        int, typer.Option("--n", metavar="N", min=0, max=MAX_PRETRAIN_TRIALS, help="Number of random interactions (trials) to run.")
    ] = 200,
    seed: Annotated[int, typer.Option("--seed", min=0, max=MAX_SEED, help="Run seed; trial i gets its own seed derived from it.")] = 0,
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
        int, typer.Option("--model-seed", min=0, max=MAX_SEED, help="Seed of the fitted models (`llcps solve --seed` reuses a model fitted with its seed).")
    ] = 0,
    create: CreateFlag = False,
    as_json: JsonFlag = False,
) -> None:
    """Run N random interactions in settled random scenes, store each as a trial, then
    fit the world models on every trial the branch sees (stored for `llcps solve`).

    The same seed writes the same trials (features, outcome, sim steps) bit for bit.
    """
    names = [str(m.value) for m in model] if model else list(PAPER_MODELS)  # type: ignore[attr-defined]
    with open_store(ctx, create=create) as store:
        with Progress(
            TextColumn("pretraining"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=err_console,
            transient=True,
        ) as progress:
            task = progress.add_task("pretraining", total=n)
            summary = pretrain(
                store,
                branch=selected_branch(ctx),
                n=n,
                seed=seed,
                progress=lambda done, total: progress.update(task, completed=done),
            )
        fitted = _fit_models(store, summary.branch, names, model_seed)
    if as_json:
        print_json({**summary.as_json(), "models": fitted})
    else:
        show(summary)
        print_table("world models fitted", ("model", "seed", "trials", "fit seconds"), [(f["name"], f["seed"], f["trials"], f"{f['fit_seconds']:.2f}") for f in fitted])


def _fit_models(store, branch: str, names: list[str], seed: int) -> list[dict[str, object]]:
    """Fit (and store) each world model on the branch's visible trials."""
    from llcps.models.persistence import fit_or_load  # torch / sklearn load only here

    records = store.visible_trials(branch)
    fitted = []
    for name in names:
        started = time.perf_counter()
        fit_or_load(store, branch, name, seed, records=records)
        fitted.append({"name": name, "seed": seed, "trials": len(records), "fit_seconds": time.perf_counter() - started})
    return fitted


def show(summary: PretrainSummary) -> None:
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
