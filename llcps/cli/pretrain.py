"""``llcps pretrain``: random interactions written to the store as ``pretrain`` trials."""

from __future__ import annotations

from typing import Annotated

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from llcps.cli._common import JsonFlag, err_console, open_store, print_json, print_table, selected_branch
from llcps.domain import OUTCOME_NAMES
from llcps.pretrain import PretrainSummary, pretrain


def pretrain_cli(
    ctx: typer.Context,
    n: Annotated[
        int, typer.Option("--n", metavar="N", min=0, help="Number of random interactions (trials) to run.")
    ] = 200,
    seed: Annotated[int, typer.Option("--seed", help="Run seed; trial i gets its own seed derived from it.")] = 0,
    as_json: JsonFlag = False,
) -> None:
    """Run N random interactions in settled random scenes and store each as a trial.

    The same seed writes the same trials (features, outcome, sim steps) bit for bit.
    """
    with open_store(ctx, create=True) as store:
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
    if as_json:
        print_json(summary.as_json())
    else:
        show(summary)


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
