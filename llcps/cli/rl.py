"""``llcps rl``: the learned exploration policy (Gymnasium environment ``llcps/Explore-v0``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, List, Optional

import typer

from llcps.cli._common import CreateFlag, JsonFlag, db_location, message, new_app, print_json, print_table, selected_branch
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display
from llcps.domain import MAX_SEED
from llcps.jobs import rl as jobs

app = new_app(
    "The learned exploration policy: MaskablePPO trained in the Gymnasium environment llcps/Explore-v0 "
    "(needs the rl extra: pip install 'llcps[rl]'); `llcps solve --ordering rl` uses it.",
    epilog=examples("llcps rl train --scenario scenario2 --scenario scenario3 --timesteps 2000"),
)

TRAIN_EXAMPLES = examples(
    "llcps rl train --scenario scenario2 --timesteps 512",
    "llcps rl train --scenario scenario2 --scenario scenario3 --variant 0 --variant 1 --timesteps 3000 --out policy.npz",
    "llcps rl train --scenario scenario2 --timesteps 256 --json",
)


@app.command("train", epilog=TRAIN_EXAMPLES)
def train_cli(
    ctx: typer.Context,
    scenario: Annotated[
        List[str], typer.Option("--scenario", metavar="NAME|FILE", help="A scenario to train on (repeatable; each episode picks one).")
    ],
    variant: Annotated[
        Optional[List[int]], typer.Option("--variant", metavar="N", min=0, help="Scene variants to train on (repeatable; default 0).", show_default=False)
    ] = None,
    timesteps: Annotated[int, typer.Option("--timesteps", metavar="N", min=1, max=jobs.MAX_TIMESTEPS, help="Environment steps (trials) to train for.")] = 512,
    budget: Annotated[int, typer.Option("--budget", metavar="N", min=1, max=512, help="Trials per training episode before it is cut off.")] = 50,
    trial_cost: Annotated[float, typer.Option("--trial-cost", metavar="X", min=0.0, max=1.0, help="Reward subtracted per trial (a resolve earns 1).")] = 0.01,
    seed: Annotated[int, typer.Option("--seed", min=0, max=MAX_SEED, help="Run seed: seeds the training (PPO's network and draws, and which scenario and variant each episode takes).")] = 0,
    reach_check: Annotated[
        bool,
        typer.Option(
            "--reach-check/--no-reach-check",
            help="Mask the candidates the arm would refuse at the failure point, as the agent leaves them out of its "
            "ordering (the default); --no-reach-check offers every candidate.",
        ),
    ] = True,
    out: Annotated[
        Optional[Path],
        typer.Option("--out", metavar="FILE", help="Also write the policy to FILE (.npz: plain arrays, no pickle).", dir_okay=False, show_default=False),
    ] = None,
    create: CreateFlag = False,
    as_json: JsonFlag = False,
) -> None:
    """Train the exploration policy on the scenarios' failure points; store it on the branch.

    Every trial the agent takes is stored (source gym). Prints the learning curve:
    mean trials per episode over consecutive blocks of training episodes.
    """
    with progress_display("rl train", "loading the simulator") as progress:
        result = jobs.train(
            store=db_location(ctx),
            scenarios=scenario,
            variants=variant or [0],
            timesteps=timesteps,
            budget=budget,
            trial_cost=trial_cost,
            seed=seed,
            reach_check=reach_check,
            branch=selected_branch(ctx),
            out=out,
            create=create,
            progress=progress,
        )
    if as_json:
        print_json(result.as_json())
        return
    print_table(
        f"learning curve ({len(result.episodes)} episodes, {result.timesteps} steps, {result.wall_seconds:.0f} s)",
        ("episodes", "mean trials", "resolved"),
        [
            (f"{c['first_episode']}-{c['first_episode'] + c['episodes'] - 1}", f"{c['mean_trials']:.1f}", f"{c['resolved']:.0%}")
            for c in result.curve()
        ],
    )
    message(f"stored policy {result.policy_id} on branch {result.branch}" + (f"; wrote {result.out}" if result.out else ""))


IMPORT_EXAMPLES = examples(
    "llcps rl train --scenario scenario2 --timesteps 2000 --out policy.npz",
    "llcps --db runs.db --branch exp-generalization-pretrain-p200-s0 rl import policy.npz",
    "llcps --db runs.db experiment run --preset generalization --ordering rl   # every pretraining branch holds one",
)


@app.command("import", epilog=IMPORT_EXAMPLES)
def import_cli(
    ctx: typer.Context,
    path: Annotated[Path, typer.Argument(metavar="FILE", help="A policy file written by `llcps rl train --out`.", dir_okay=False, show_default=False)],
    create: CreateFlag = False,
    as_json: JsonFlag = False,
) -> None:
    """Store a trained policy file on the branch (--branch, default: the current one).

    The rl ordering uses the newest policy its branch sees, so a policy stored on an
    experiment's pretraining branch is what `experiment run --ordering rl` explores with
    on every sequence forked from it. The file is checked (shapes, checksum, plain
    arrays; never unpickled) before anything is stored.
    """
    result = jobs.import_policy_file(store=db_location(ctx), path=path, branch=selected_branch(ctx), create=create)
    if as_json:
        print_json(result.as_json())
        return
    trained = result.trained
    what = ", ".join(f"{k} {v}" for k, v in trained.items() if k in ("scenarios", "variants", "timesteps", "seed"))
    message(f"stored policy {result.policy_id} on branch {result.branch} (visible from trial {result.watermark})" + (f"; trained on {what}" if what else ""))
