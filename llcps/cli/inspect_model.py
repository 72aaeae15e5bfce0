"""``llcps inspect model``: held-out metrics of the world models, label frequencies,
and a scenario's top candidates under each measure."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Optional

import typer

from llcps.cli._common import JsonFlag, choice_enum, db_location, notice, print_json, print_table, selected_branch
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display
from llcps.cli.inspect import app
from llcps.domain import MAX_SEED, OUTCOME_NAMES
from llcps.jobs.inspect import inspect_model
from llcps.models import WORLD_MODELS
from llcps.scenarios.variants import MAX_VARIANT

if TYPE_CHECKING:
    from llcps.cps.inspection import ModelInspection

ModelName = choice_enum("ModelName", tuple(WORLD_MODELS))

#: Most candidates listed per measure.
MAX_TOP = 1000

_SHORT = {name: ("+" if name.startswith("positive") else "-") + name.split("_", 1)[1][:5] for name in OUTCOME_NAMES}


@app.command(
    "model",
    epilog=examples(
        "llcps inspect model                                   # nb and nn: held-out metrics",
        "llcps inspect model --scenario scenario2 --limit 3    # and each measure's top 3 candidates",
        "llcps inspect model --scenario scenario3 --variant 7  # ranked in another layout of the scene",
        "llcps db branch before --at pretrain && llcps --branch before inspect model --scenario scenario2   # after a solve",
        "llcps inspect model --model forest --model logreg --seed 1 --json",
    ),
)
def model_cli(
    ctx: typer.Context,
    model: Annotated[
        Optional[list[ModelName]],  # type: ignore[valid-type]
        typer.Option("--model", metavar="NAME", help="World model to inspect (repeatable; default: the paper's nb and nn).", show_default=False),
    ] = None,
    scenario: Annotated[
        Optional[str],
        typer.Option("--scenario", metavar="NAME", help="Also rank this scenario's failure-state candidates under every measure.", show_default=False),
    ] = None,
    variant: Annotated[
        int,
        typer.Option(
            "--variant",
            metavar="N",
            min=0,
            max=MAX_VARIANT,
            help="Scene variant of --scenario, as `llcps solve --variant` draws it (0: the canonical scene).",
        ),
    ] = 0,
    limit: Annotated[int, typer.Option("--limit", min=1, max=MAX_TOP, metavar="N", help="Candidates shown per measure.")] = 5,
    seed: Annotated[int, typer.Option("--seed", min=0, max=MAX_SEED, help="Run seed: the held-out split and tie-breaks.")] = 0,
    model_seed: Annotated[
        Optional[int],
        typer.Option("--model-seed", min=0, max=MAX_SEED, help="Seed of the world models (default: --seed).", show_default=False),
    ] = None,
    test_fraction: Annotated[float, typer.Option("--test-fraction", min=0.01, max=0.99, help="Share of trials held out.")] = 0.25,
    reach_check: Annotated[
        bool,
        typer.Option(
            "--reach-check/--no-reach-check",
            help="List last, as `llcps solve` tries them, the candidates the arm would refuse at the failure point "
            "(marked refused); --no-reach-check: the measure's order alone.",
        ),
    ] = True,
    as_json: JsonFlag = False,
) -> None:
    """Evaluate world models on the branch's trials (held-out split) next to the majority baseline.

    With --scenario, its novelty plan runs first, before any model is fitted: when the plan
    (or a repair) succeeds on the branch, as after a solve that learned an operator, the
    metrics are printed with a note and no ranking; fork a branch at the pretraining point
    (`llcps db branch before --at pretrain`) and inspect it (`--branch before`) to rank.
    """
    with progress_display("inspect model", "loading the world models") as progress:
        report = inspect_model(
            store=db_location(ctx),
            branch=selected_branch(ctx),
            models=[str(m.value) for m in model] if model else None,  # type: ignore[attr-defined]
            scenario=scenario,
            variant=variant,
            limit=limit,
            seed=seed,
            model_seed=model_seed,
            test_fraction=test_fraction,
            reach_check=reach_check,
            progress=progress,
        )
    if as_json:
        print_json(report.as_json())
    else:
        show(report)


def show(report: "ModelInspection") -> None:
    """The inspection as tables."""
    print_table(
        f"label frequencies in the {report.n_trials} trials {report.branch} sees",
        OUTCOME_NAMES,
        [[f"{report.label_frequencies[name]:.3f}" for name in OUTCOME_NAMES]],
    )
    if report.evaluation_note:
        notice(f"no held-out metrics: {report.evaluation_note}")
    for evaluation in report.evaluations:
        print_table(
            f"{evaluation.model}: {evaluation.n_train} training / {evaluation.n_test} held-out trials "
            "(model | majority baseline)",
            ("label", "train freq", "accuracy", "F1", "Brier"),
            [
                (
                    m.label,
                    f"{m.train_frequency:.3f}",
                    f"{m.accuracy:.3f} | {m.baseline_accuracy:.3f}",
                    f"{m.f1:.3f} | {m.baseline_f1:.3f}" + ("" if m.both_classes else " (one class)"),
                    f"{m.brier:.3f} | {m.baseline_brier:.3f}",
                )
                for m in evaluation.labels
            ],
        )
    goal_rows = [
        (e.model, e.goal.examples, e.goal.positives, f"{e.goal.brier:.4f} | {e.goal.baseline_brier:.4f}", f"{e.goal.auc:.3f} | 0.500")
        for e in report.evaluations
        if e.goal is not None
    ]
    if goal_rows:
        print_table(
            f"goal-aware outcome: held-out (candidate, atom) examples of the {report.n_changes} trials with a known change "
            "(model | change-rate baseline)",
            ("model", "examples", "changed", "Brier", "ROC AUC"),
            goal_rows,
        )
    if report.ranking_note is not None:
        notice(f"no candidates ranked: {report.ranking_note}")
        if report.ranking_hint:
            notice(report.ranking_hint)
    if report.failure is None:
        return
    failure = report.failure
    where = f" (variant {report.variant})" if report.variant else ""
    refused = f", {len(failure.refused)} the arm would refuse here (tried last)" if failure.refused else ""
    notice(f"{failure.scenario}{where}: {failure.missing_effects}; {len(failure.candidates)} candidates{refused}")
    for k, subgoal in enumerate(failure.subgoals, start=1):
        notice(f"subgoal S{k}: {subgoal.label} (a trial that meets it lets K's step finish the job)")
    if failure.met:
        notice(
            f"met on a_f's path: {', '.join(failure.met)} ({len(failure.in_the_way)} candidates of a_f's action "
            "whose path meets it too are lowered under goal-directed; "
            f"{len(failure.relocations)} that would take an argument of a_f off its path are raised)"
        )
    for model, by_measure in report.rankings.items():
        for measure, ranked in by_measure.items():
            atoms = list(ranked[0].goal) if ranked else []
            subgoals = list(ranked[0].subgoals) if ranked else []
            resolve = bool(ranked) and ranked[0].resolve is not None and failure.ranks_by_resolve
            via = [f"P(S{k})" for k in range(1, len(subgoals) + 1)] + (["P(resolve)"] if resolve else [])
            print_table(
                f"{model} / {measure}",
                ("#", "trial", "K claims", "score", *(f"P{a}" for a in atoms), "P(all)", *via, *(_SHORT[name] for name in OUTCOME_NAMES)),
                [
                    (
                        c.position,
                        c.trial + (" (refused)" if c.refused else ""),
                        " ".join(c.claimed) or "-",
                        f"{c.score:.3f}",
                        *(f"{c.goal[a]:.3f}" for a in atoms),
                        f"{c.joint:.3f}",
                        *(f"{c.subgoals[s]:.3f}" for s in subgoals),
                        *((f"{c.resolve:.3f}",) if resolve else ()),
                        *(f"{c.outcome[n]:.2f}" for n in OUTCOME_NAMES),
                    )
                    for c in ranked
                ],
            )
