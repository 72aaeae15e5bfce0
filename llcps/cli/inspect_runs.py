"""``llcps inspect runs`` and ``llcps inspect knowledge``: what was run, and what was learned."""

from __future__ import annotations

from typing import Annotated

import typer

from llcps.cli._common import JsonFlag, open_store, print_json, print_table, selected_branch
from llcps.cli.inspect import app


@app.command("runs")
def runs_cli(
    ctx: typer.Context,
    limit: Annotated[int, typer.Option("--limit", min=0, metavar="N", help="Show the newest N episodes; 0 shows all.")] = 20,
    all_branches: Annotated[bool, typer.Option("--all", help="Episodes of every branch, not just --branch.")] = False,
    as_json: JsonFlag = False,
) -> None:
    """Episodes (scenario solves) of the branch, oldest first: status and exploration per scenario."""
    with open_store(ctx) as store:
        branch = None if all_branches else store.resolve_branch(selected_branch(ctx)).name
        episodes = store.list_episodes(branch=branch, limit=limit or None)
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


@app.command("knowledge")
def knowledge_cli(ctx: typer.Context, as_json: JsonFlag = False) -> None:
    """The branch's knowledge base K' in PDDL, and what experience says of each operator.

    Each operator's plan cost is its nominal cost divided by the Laplace-smoothed rate at
    which its executions as plan steps on the branch achieved their effects, relative to
    the rate 1/2 of an operator never executed (docs/knowledge.md). The PDDL shows these costs.
    """
    from llcps.cps.knowledge import load_knowledge

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
    return f"{value:.1f}" if isinstance(value, (int, float)) else "-"
