"""``llcps inspect runs``, ``inspect episodes`` and ``inspect knowledge``: what was run,
where, what it did, and what was learned (also as plain PDDL for other planners)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from llcps.cli._common import JsonFlag, choice_enum, db_location, message, print_json, print_table, selected_branch
from llcps.cli._conventions import examples
from llcps.cli.inspect import app
from llcps.domain import CONDITIONS, MAX_ID
from llcps.errors import LlcpsError
from llcps.jobs import inspect as jobs
from llcps.jobs.inspect import PDDL_COSTS, PDDL_PARTS, RunRow
from llcps.scenarios.variants import MAX_VARIANT

LimitOption = Annotated[int, typer.Option("--limit", min=0, max=MAX_ID, metavar="N", help="Show the newest N; 0 shows all.")]
AllBranches = Annotated[bool, typer.Option("--all", help="Every branch, not just --branch.")]


@app.command(
    "runs",
    epilog=examples(
        "llcps inspect runs                      # runs on the current branch, with where they ran",
        "llcps inspect runs --all --limit 0 --json",
        "llcps inspect runs --compare 3 7        # two runs side by side, differences marked",
    ),
)
def runs_cli(
    ctx: typer.Context,
    limit: LimitOption = 20,
    all_branches: AllBranches = False,
    compare: Annotated[
        Optional[tuple[int, int]],
        typer.Option(
            "--compare", metavar="A B", min=1, max=MAX_ID, help="Show runs A and B side by side instead of the list.", show_default=False
        ),
    ] = None,
    as_json: JsonFlag = False,
) -> None:
    """Runs (one per command or experiment task), oldest first: what ran, where, and what it wrote."""
    if compare is not None:
        _compare(ctx, compare[0], compare[1], as_json)
        return
    result = jobs.list_runs(store=db_location(ctx), branch=selected_branch(ctx), all_branches=all_branches, limit=limit or None)
    branch, runs = result.branch, result.runs
    if as_json:
        print_json([row.as_json() for row in runs])
        return
    print_table(
        f"runs on {branch or 'every branch'} ({len(runs)} shown)",
        ("run", "command", "branch", "seed", "status", "started (UTC)", "s", "episodes", "trials", "llcps", "commit", "host"),
        [_run_cells(row) for row in runs],
    )


def _run_cells(row: RunRow) -> tuple[Any, ...]:
    r = row.run
    return (
        r.id,
        r.command,
        r.branch,
        "-" if r.seed is None else r.seed,
        r.status,
        r.started_at[:19],
        _seconds(row.seconds),
        row.activity["episodes"],
        row.activity["trials"],
        r.provenance.llcps_version or "-",
        r.provenance.commit_text,
        r.provenance.host or "-",
    )


def _compare(ctx: typer.Context, a: int, b: int, as_json: bool) -> None:
    comparison = jobs.compare_runs(store=db_location(ctx), a=a, b=b)
    if as_json:
        print_json(comparison.as_json())
        return
    print_table(
        f"run {a} and run {b} ({len(comparison.differences)} field(s) differ, marked *)",
        ("", "field", f"run {a}", f"run {b}"),
        [("" if f.same else "*", f.name, _value(f.a), _value(f.b)) for f in comparison.fields],
    )


@app.command(
    "episodes",
    epilog=examples(
        "llcps inspect episodes                      # status and exploration per scenario",
        "llcps inspect episodes --scenario scenario2 --all",
        "llcps inspect episodes --run 3 --json",
    ),
)
def episodes_cli(
    ctx: typer.Context,
    limit: LimitOption = 20,
    all_branches: AllBranches = False,
    scenario: Annotated[
        Optional[str], typer.Option("--scenario", metavar="NAME", help="Only episodes of this scenario (a name or its alias).", show_default=False)
    ] = None,
    run: Annotated[Optional[int], typer.Option("--run", metavar="ID", min=1, max=MAX_ID, help="Only episodes of this run.", show_default=False)] = None,
    as_json: JsonFlag = False,
) -> None:
    """Episodes (scenario solves), oldest first: status and exploration per scenario."""
    result = jobs.list_episodes(
        store=db_location(ctx), branch=selected_branch(ctx), all_branches=all_branches, scenario=scenario, run=run, limit=limit or None
    )
    branch, episodes = result.branch, result.episodes
    if as_json:
        print_json([e.as_json() for e in episodes])
        return
    print_table(
        f"episodes on {branch or 'every branch'} ({len(episodes)} shown)",
        ("episode", "run", "branch", "scenario", "condition", "model", "measure", "seed", "status", "exploration trials", "sim s", "wall s"),
        [
            (
                e.id,
                e.run_id,
                e.branch,
                e.scenario,
                e.condition,
                e.model,
                e.measure,
                e.seed,
                e.status,
                e.summary.get("exploration_trials", "-"),
                _seconds(e.summary.get("sim_seconds")),
                _seconds(e.summary.get("wall_seconds")),
            )
            for e in episodes
        ],
    )


PddlPart = choice_enum("PddlPart", PDDL_PARTS)
PddlCosts = choice_enum("PddlCosts", PDDL_COSTS)
Condition = choice_enum("KnowledgeCondition", CONDITIONS)


@app.command(
    "knowledge",
    epilog=examples(
        "llcps inspect knowledge                 # K' in PDDL",
        "llcps --branch exp inspect knowledge --json",
        "llcps inspect knowledge --pddl domain --out domain.pddl                        # for other planners",
        "llcps inspect knowledge --pddl problem --scenario scenario2 --out problem.pddl",
        "llcps inspect knowledge --pddl problem --scenario scenario2 --condition original --costs none",
    ),
)
def knowledge_cli(
    ctx: typer.Context,
    pddl: Annotated[
        Optional[PddlPart],  # type: ignore[valid-type]
        typer.Option(
            "--pddl",
            help="Write plain PDDL for other planners instead: K' as a domain, or --scenario's task as a problem for it.",
            show_default=False,
        ),
    ] = None,
    scenario: Annotated[
        Optional[str],
        typer.Option("--scenario", metavar="NAME", help="The scenario whose task --pddl problem writes (a name, alias or file).", show_default=False),
    ] = None,
    condition: Annotated[Condition, typer.Option("--condition", help="The condition of --scenario's task.")] = "novelty",  # type: ignore[valid-type, assignment]
    variant: Annotated[
        int, typer.Option("--variant", metavar="N", min=0, max=MAX_VARIANT, help="Scene variant of --scenario (0: the canonical scene).")
    ] = 0,
    costs: Annotated[
        PddlCosts,  # type: ignore[valid-type]
        typer.Option("--costs", help="integer: experience costs x 1000, rounded; none: a cost-free compilation for planners without action costs."),
    ] = "integer",  # type: ignore[assignment]
    out: Annotated[
        Optional[Path],
        typer.Option("--out", metavar="FILE", help="Write the --pddl file here instead of to stdout.", show_default=False, dir_okay=False),
    ] = None,
    as_json: JsonFlag = False,
) -> None:
    """The branch's knowledge base K' in PDDL, and what experience says of each operator.

    Each operator's plan cost is its nominal cost divided by the Laplace-smoothed rate at
    which its executions as plan steps on the branch achieved their effects, relative to
    the rate 1/2 of an operator never executed (docs/knowledge.md). The PDDL shows these costs.

    With --pddl, plain PDDL that other planners (Fast Downward, through unified-planning)
    accept: integer costs, the learned operators' inequalities, and the contexts where an
    operator only failed as preconditions; what PDDL cannot say is a comment in the file.
    """
    if pddl is None:
        given = [name for name, value in (("--scenario", scenario), ("--out", out)) if value is not None]
        if given:
            raise LlcpsError(f"{given[0]} is an option of --pddl", hint="add --pddl domain or --pddl problem")
        _print_knowledge(ctx, as_json)
        return
    result = jobs.export_pddl(
        store=db_location(ctx),
        branch=selected_branch(ctx),
        part=str(pddl.value),
        scenario=scenario,
        condition=str(condition.value),  # type: ignore[attr-defined]
        variant=variant,
        costs=str(costs.value),  # type: ignore[attr-defined]
        out=out,
    )
    if as_json:
        print_json(result.as_json())
    elif result.path is not None:
        what = f"{result.scenario}'s {result.condition} task" if result.part == "problem" else f"the knowledge base of {result.branch}"
        message(f"wrote {what} as a PDDL {result.part} (costs: {result.costs}) to {result.path}")
    else:
        typer.echo(result.text, nl=False)


def _print_knowledge(ctx: typer.Context, as_json: bool) -> None:
    result = jobs.knowledge(store=db_location(ctx), branch=selected_branch(ctx))
    if as_json:
        print_json(result.as_json())
        return
    typer.echo(result.domain)
    print_table(
        f"operators of {result.branch}: executions as plan steps and plan cost",
        ("operator", "learned", "successes", "failures", "nominal cost", "cost"),
        [
            (r.operator, "yes" if r.learned else "no", r.successes, r.failures, f"{r.nominal_cost:g}", f"{r.cost:.3g}")
            for r in result.operators
        ],
    )


def _seconds(value: object) -> str:
    return f"{value:.1f}" if isinstance(value, (int, float)) and not isinstance(value, bool) else "-"


def _value(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)
