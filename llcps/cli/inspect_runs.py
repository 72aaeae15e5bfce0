"""``llcps inspect runs``, ``inspect episodes`` and ``inspect knowledge``: what was run,
where, what it did, and what was learned."""

from __future__ import annotations

from typing import Annotated, Any, Optional

import typer

from llcps.cli._common import JsonFlag, open_store, print_json, print_table, selected_branch
from llcps.cli._conventions import examples
from llcps.cli.inspect import app
from llcps.domain import MAX_ID
from llcps.scenarios import get_scenario

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
    from llcps.store.runs import run_seconds

    with open_store(ctx) as store:
        branch = None if all_branches else store.resolve_branch(selected_branch(ctx)).name
        runs = store.list_runs(branch=branch, limit=limit or None)
        activity = store.run_activity([r.id for r in runs])
    runs.reverse()
    if as_json:
        print_json([{**r.as_json(), "seconds": run_seconds(r), "activity": activity[r.id]} for r in runs])
        return
    print_table(
        f"runs on {branch or 'every branch'} ({len(runs)} shown)",
        ("run", "command", "branch", "seed", "status", "started (UTC)", "s", "episodes", "trials", "llcps", "commit", "host"),
        [
            (
                r.id,
                r.command,
                r.branch,
                "-" if r.seed is None else r.seed,
                r.status,
                r.started_at[:19],
                _seconds(run_seconds(r)),
                activity[r.id]["episodes"],
                activity[r.id]["trials"],
                r.provenance.llcps_version or "-",
                r.provenance.commit_text,
                r.provenance.host or "-",
            )
            for r in runs
        ],
    )


def _compare(ctx: typer.Context, a: int, b: int, as_json: bool) -> None:
    from llcps.store.runs import compare_runs

    with open_store(ctx) as store:
        comparison = compare_runs(store, a, b)
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
    scenario = None if scenario is None else get_scenario(scenario).name
    with open_store(ctx) as store:
        branch = None if all_branches else store.resolve_branch(selected_branch(ctx)).name
        episodes = store.list_episodes(branch=branch, scenario=scenario, run_id=run, limit=limit or None)
    episodes.reverse()
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


@app.command(
    "knowledge",
    epilog=examples(
        "llcps inspect knowledge                 # K' in PDDL",
        "llcps --branch exp inspect knowledge --json",
    ),
)
def knowledge_cli(ctx: typer.Context, as_json: JsonFlag = False) -> None:
    """The branch's knowledge base K' in PDDL, and what experience says of each operator.

    Each operator's plan cost is its nominal cost divided by the Laplace-smoothed rate at
    which its executions as plan steps on the branch achieved their effects, relative to
    the rate 1/2 of an operator never executed (docs/knowledge.md). The PDDL shows these costs.
    """
    from llcps.cps.branch_knowledge import load_knowledge

    with open_store(ctx) as store:
        branch = store.resolve_branch(selected_branch(ctx)).name
        kb = load_knowledge(store, branch)
        operators = store.visible_operators(branch)
    learned = {op.name for op in kb.learned}
    rows = [
        {
            "operator": op.name,
            "learned": op.name in learned,
            "successes": kb.counts(op.name)[0],
            "failures": kb.counts(op.name)[1],
            "nominal_cost": kb.nominal_cost(op.name),
            "cost": round(kb.cost(op.name), 4),
        }
        for op in kb.operators()
    ]
    if as_json:
        print_json(
            {
                "branch": branch,
                "domain": kb.to_pddl(),
                "operators": rows,
                "learned_operators": [op.as_json() for op in operators],
            }
        )
        return
    typer.echo(kb.to_pddl())
    print_table(
        f"operators of {branch}: executions as plan steps and plan cost",
        ("operator", "learned", "successes", "failures", "nominal cost", "cost"),
        [
            (r["operator"], "yes" if r["learned"] else "no", r["successes"], r["failures"], f"{r['nominal_cost']:g}", f"{r['cost']:.3g}")
            for r in rows
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
