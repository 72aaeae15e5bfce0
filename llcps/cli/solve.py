"""``llcps solve``: one scenario, one episode, on one branch of the store."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from llcps.cli._common import CreateFlag, JsonFlag, choice_enum, cli_context, err_console, message, notice, print_json, print_table, selected_branch
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display
from llcps.cps.episode import DEFAULT_BUDGET, MAX_BUDGET
from llcps.cps.orderings import ORDERINGS
from llcps.domain import MAX_SEED
from llcps.jobs.solve import solve
from llcps.models import MEASURES, WORLD_MODELS
from llcps.outputs import GIF_SUFFIXES, check_output_file
from llcps.scenarios import CONDITIONS, shipped_names
from llcps.scenarios.variants import MAX_VARIANT

if TYPE_CHECKING:
    from llcps.cps.episode import SolveResult

ModelName = choice_enum("ModelName", tuple(WORLD_MODELS))
MeasureName = choice_enum("MeasureName", tuple(MEASURES))
OrderingName = choice_enum("OrderingName", tuple(ORDERINGS))
Condition = choice_enum("Condition", CONDITIONS)

#: Exit codes of ``llcps solve``.
EXIT_SOLVED, EXIT_UNSOLVED, EXIT_INTERRUPTED = 0, 1, 130

_SCENARIO_HELP = (
    "Scenario to solve: "
    + ", ".join(f"{name} ({alias})" for name, alias in shipped_names().items())
    + "; or the path of a scenario file (.toml, see `llcps scenario`)."
)


def solve_cli(
    ctx: typer.Context,
    scenario: Annotated[str, typer.Argument(metavar="SCENARIO", help=_SCENARIO_HELP, show_default=False)],
    condition: Annotated[Condition, typer.Option("--condition", help="Original (the plan works) or novelty (it fails).")] = "novelty",  # type: ignore[valid-type, assignment]
    model: Annotated[ModelName, typer.Option("--model", help="World model that ranks exploration.")] = WORLD_MODELS.default,  # type: ignore[valid-type, assignment]
    measure: Annotated[MeasureName, typer.Option("--measure", help="Measure that orders candidates by the model's prediction.")] = MEASURES.default,  # type: ignore[valid-type, assignment]
    ordering: Annotated[
        OrderingName,  # type: ignore[valid-type]
        typer.Option(
            "--ordering",
            help="Order of the exploration trials: the ranking alone (ranked, the paper's), or the ranking "
            "hedged with a random order spread over the candidates (hedged, the default: at most 2P trials where that order needs P); "
            "baselines: that spread random order alone (coverage), past solutions first (case-based), "
            "Thompson sampling with the model as prior (trial-and-error), an ensemble's disagreement (uncertainty), "
            "the policy of `llcps rl train` (rl); see docs/world_models.md.",
        ),
    ] = ORDERINGS.default,  # type: ignore[assignment]
    reach_check: Annotated[
        bool,
        typer.Option(
            "--reach-check/--no-reach-check",
            help="Try last the candidates the arm would refuse at the failure point (a pick-and-place waypoint "
            "out of reach: they move nothing); --no-reach-check tries every candidate in the ordering's order, as the paper's agent.",
        ),
    ] = True,
    variant: Annotated[
        int,
        typer.Option(
            "--variant",
            metavar="N",
            min=0,
            max=MAX_VARIANT,
            help="Scene variant: N draws the scene from the ranges the scenario file declares (0: the canonical scene).",
        ),
    ] = 0,
    seed: Annotated[int, typer.Option("--seed", min=0, max=MAX_SEED, help="Run seed: breaks ties in the ranking; recorded with every trial.")] = 0,
    model_seed: Annotated[
        Optional[int],
        typer.Option(
            "--model-seed",
            min=0,
            max=MAX_SEED,
            help="Seed of the world model's fit (default: --seed; `llcps pretrain --model-seed` stores one).",
            show_default=False,
        ),
    ] = None,
    budget: Annotated[int, typer.Option("--budget", metavar="N", min=0, max=MAX_BUDGET, help="Most exploration trials before giving up (exit 1).")] = DEFAULT_BUDGET,
    refit_every: Annotated[
        int, typer.Option("--refit-every", metavar="N", min=1, max=MAX_BUDGET, help="Refit the world model after every N exploration trials.")
    ] = 1,
    gui: Annotated[bool, typer.Option("--gui", help="Watch in a PyBullet window (needs a display).")] = False,
    gif: Annotated[
        Optional[Path],
        typer.Option(
            "--gif",
            metavar="FILE",
            help="Afterwards, film the plan, the resolving trial and the plan it enabled to a captioned GIF "
            "(not counted in the stored times; FILE ends in .gif and its directory must exist).",
            show_default=False,
            dir_okay=False,
        ),
    ] = None,
    create: CreateFlag = False,
    as_json: JsonFlag = False,
) -> None:
    """Plan, execute, explore on failure, learn an operator; every trial goes to the store.

    Progress shows the phase (fit, plan, explore, re-plan, render) and, while exploring,
    trials against the budget with an ETA (the time to spend the whole budget at the
    current rate: an upper bound, as a resolving trial ends it early). Exit code 0 when the task is solved, 1 when the budget ran out (every trial is
    kept), 2 for bad input, 130 when interrupted (Ctrl-C; completed trials are kept).
    """
    if gif is not None:
        check_output_file(gif, what="--gif", suffixes=GIF_SUFFIXES)
    before = _mtime(gif)
    with progress_display("solve", "loading the simulator") as progress:
        result = solve(
            store=cli_context(ctx).db,
            create=create,
            branch=selected_branch(ctx),
            scenario=scenario,
            condition=str(condition.value),  # type: ignore[attr-defined]
            model=str(model.value),  # type: ignore[attr-defined]
            measure=str(measure.value),  # type: ignore[attr-defined]
            ordering=str(ordering.value),  # type: ignore[attr-defined]
            reach_check=reach_check,
            seed=seed,
            model_seed=model_seed,
            budget=budget,
            refit_every=refit_every,
            variant=variant,
            gui=gui,
            gif=gif,
            progress=progress,
        )
    if as_json:
        print_json(result.as_json())
    else:
        show(result)
    if gif is not None and result.status != "interrupted":
        message(f"film written to {gif}" if _mtime(gif) != before else "no film: the episode executed no trial")
    raise typer.Exit(_exit_code(result))


EXAMPLES = examples(
    "llcps solve scenario2                                  # the novelty, default model and measure",
    "llcps solve scenario3 --condition original             # the nominal plan works there",
    "llcps solve bucket --model nn --measure most-changes --budget 50 --json",
    "llcps solve scenario1 --gif scenario1.gif              # then film it",
    "llcps solve scenario2 --variant 3                      # another layout, drawn from the file's ranges",
    "llcps solve scenario2 --ordering hedged                # at most twice its spread random order",
    "llcps solve scenario2 --ordering case-based            # what resolved similar failures first",
    "llcps solve my_scenario.toml                           # a scenario straight from a file",
)


def _mtime(path: Path | None) -> int | None:
    return path.stat().st_mtime_ns if path is not None and path.exists() else None


def _exit_code(result: "SolveResult") -> int:
    if result.status == "solved":
        return EXIT_SOLVED
    if result.status == "interrupted":
        return EXIT_INTERRUPTED
    return EXIT_UNSOLVED


def show(result: "SolveResult") -> None:
    """The episode summary for people."""
    from rich.syntax import Syntax

    variant = f", variant {result.variant}" if result.variant else ""
    print_table(
        f"{result.scenario} ({result.condition}{variant}) on {result.branch}: {result.status}",
        ("", ""),
        [
            ("plan", " ".join(result.plan) or "-"),
            ("failed action", result.failed_action or "-"),
            ("failure", result.missing_effects or "-"),
            ("world model / measure / ordering", f"{result.model} / {result.measure} / {result.ordering} (seed {result.seed})"),
            ("exploration trials", f"{result.exploration_trials} of {result.candidates} candidates"),
            ("plan trials", result.plan_trials),
            ("sim seconds", f"{result.sim_seconds:.1f}"),
            ("wall seconds", f"{result.wall_seconds:.1f}"),
            ("episode", result.episode_id),
        ],
        show_header=False,
    )
    for pddl in result.learned_operators:
        notice("learned operator:")
        err_console.print(Syntax(pddl, "lisp", theme="ansi_dark", background_color="default"))
