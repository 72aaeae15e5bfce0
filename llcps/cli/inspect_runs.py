"""``llcps inspect runs`` and ``llcps inspect knowledge``: what was run, and what was learned."""

from __future__ import annotations

from typing import Annotated

import typer

from llcps.cli._common import JsonFlag, open_store, print_json, print_table, selected_branch
from llcps.cli.inspect import app
from llcps.domain import MAX_ID


@app.command("runs")
def runs_cli(
    ctx: typer.Context,
    limit: Annotated[int, typer.Option("--limit", min=0, max=MAX_ID, metavar="N", help="Show the newest N episodes; 0 shows all.")] = 20,
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
    """The branch's knowledge base K' in PDDL: the domain's actions and every learned operator."""
    from llcps.cps.knowledge import load_knowledge

    with open_store(ctx) as store:
        branch = store.resolve_branch(selected_branch(ctx)).name
        kb = load_knowledge(store, branch)
        operators = store.visible_operators(branch)
    if as_json:
        print_json(
            {
                "branch": branch,
                "domain": kb.to_pddl(),
                "learned_operators": [op.as_json() for op in operators],
            }
        )
        return
    typer.echo(kb.to_pddl())


def _seconds(value: object) -> str:
    return f"{value:.1f}" if isinstance(value, (int, float)) else "-"
