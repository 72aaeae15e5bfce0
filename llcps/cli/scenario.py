"""``llcps scenario``: list, show, render and check the scenario files."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from llcps.cli._common import JsonFlag, choice_enum, message, new_app, print_json, print_table
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display
from llcps.outputs import check_output_dir
from llcps.scenarios import CONDITIONS, get_scenario
from llcps.scenarios.variants import MAX_VARIANT, parse_range, range_text

app = new_app(
    "Scenario files: list them, show one, render its scenes, check the properties every scenario must have.",
    epilog=examples(
        "llcps scenario list",
        "llcps scenario show scenario2 > my.toml              # a file to start your own from",
        "llcps scenario check my.toml --variants 0:5 --quick",
    ),
)

Format = choice_enum("Format", ("toml", "json"))
Condition = choice_enum("ScenarioCondition", CONDITIONS)

_NAME_HELP = "A scenario name or alias (see `llcps scenario list`), or the path of a .toml scenario file."
ScenarioArg = Annotated[str, typer.Argument(metavar="NAME|PATH", help=_NAME_HELP, show_default=False)]
VariantOption = Annotated[
    Optional[int],
    typer.Option("--variant", metavar="N", min=0, max=MAX_VARIANT, help="A scene variant: every range of the file drawn with seed N (0: the canonical scene).", show_default=False),
]


def _ref(name: str) -> str:
    """How the library finds the scenario again: its registered name, or the file given."""
    from llcps.scenarios import SCENARIOS

    scenario = get_scenario(name)
    return scenario.name if SCENARIOS.get(scenario.name) is scenario else name


@app.command("list", epilog=examples("llcps scenario list", "llcps scenario list --json"))
def list_cli(as_json: JsonFlag = False) -> None:
    """List the shipped scenarios: name, alias, goal, whether variants differ, and the file."""
    from llcps.scenarios import SCENARIOS
    from llcps.scenarios.goal import goal_text

    rows = [
        {
            "name": s.name,
            "alias": s.alias,
            "title": s.title,
            "goal": goal_text(s.goal_pos, s.goal_neg),
            "varies": s.varies,
            "file": str(s.source.path) if s.source is not None else None,
        }
        for s in SCENARIOS.values()
    ]
    if as_json:
        print_json(rows)
        return
    print_table(
        "scenarios",
        ("name", "alias", "task", "goal", "variants differ"),
        [(r["name"], r["alias"], r["title"], " ".join(r["goal"]), "yes" if r["varies"] else "no") for r in rows],
    )


@app.command(
    "show",
    epilog=examples(
        "llcps scenario show scenario2                        # the shipped file, as TOML",
        "llcps scenario show bucket --format json",
        "llcps scenario show scenario1 --variant 3            # variant 3 as a file of its own",
    ),
)
def show_cli(
    name: ScenarioArg,
    fmt: Annotated[Format, typer.Option("--format", help="TOML (the file itself) or JSON.")] = "toml",  # type: ignore[valid-type, assignment]
    variant: VariantOption = None,
) -> None:
    """Print a scenario file on stdout; with --variant, the file with every range drawn.

    A shown file loads back to the same scenario (and a shown variant to that variant's scene).
    """
    from llcps.scenarios.loader import dump

    scenario = get_scenario(name)
    assert scenario.source is not None
    text = dump(scenario.source, fmt=str(fmt.value), variant=variant)  # type: ignore[attr-defined]
    typer.echo(text, nl=False)


@app.command(
    "render",
    epilog=examples(
        "llcps scenario render scenario1                      # scenario1_original.png, scenario1_novelty.png",
        "llcps scenario render container --variant 4 --out-dir pictures/",
        "llcps scenario render my.toml --condition novelty",
    ),
)
def render_cli(
    name: ScenarioArg,
    variant: VariantOption = None,
    out_dir: Annotated[Path, typer.Option("--out-dir", metavar="DIR", help="Directory to write the PNGs into.", file_okay=False)] = Path("."),
    condition: Annotated[
        Optional[Condition],  # type: ignore[valid-type]
        typer.Option("--condition", help="Render only this condition (default: both).", show_default=False),
    ] = None,
    as_json: JsonFlag = False,
) -> None:
    """Render the scenes of a variant (after they settle) to PNG, one per condition."""
    scenario = get_scenario(name)
    check_output_dir(out_dir, what="--out-dir")
    chosen = CONDITIONS if condition is None else (str(condition.value),)  # type: ignore[attr-defined]
    with progress_display("render", "loading the simulator") as progress:
        from llcps.scenarios.pictures import render_scenes

        written = render_scenes(scenario, out_dir, variant=variant or 0, conditions=chosen, progress=progress)
    if as_json:
        print_json({"scenario": scenario.name, "variant": variant or 0, "files": [str(p) for p in written]})
        return
    for path in written:
        message(f"wrote {path}")


@app.command(
    "check",
    epilog=examples(
        "llcps scenario check scenario2                        # variant 0, full sweep (minutes)",
        "llcps scenario check my.toml --variants 0:10 --quick  # stop each sweep at the first resolving candidate",
        "llcps scenario check bucket --variants 0:20 --json",
    ),
)
def check_cli(
    name: ScenarioArg,
    variants: Annotated[
        str, typer.Option("--variants", metavar="A:B", help="Variants A..B-1 to check (or one variant N).")
    ] = "0:1",
    quick: Annotated[
        bool,
        typer.Option("--quick", help="Stop each sweep at the first resolving candidate: every property is decided, resolving candidates are counted as '>= 1'."),
    ] = False,
    as_json: JsonFlag = False,
) -> None:
    """Check, in physics, the properties every scenario must have, for each variant:

    in the original condition K's plan succeeds with 0 exploration; in the novelty K's
    plan and every plan repair fail; the sweep of the candidate space finds a resolving
    candidate; the first resolving candidate is not first in the default order.
    Prints candidates, resolving candidates and the first position per variant and,
    over a range, the share of variants where each property holds. Nothing is stored.
    Exit code 0 when every property holds on every variant, 1 when one does not.
    """
    chosen = parse_range(variants)
    ref = _ref(name)
    scenario = get_scenario(ref)
    with progress_display(f"check {scenario.name}", "loading the simulator") as progress:
        from llcps.cps.check import check_scenario

        report = check_scenario(scenario, ref, variants=chosen, quick=quick, progress=progress)
    if as_json:
        print_json({**report.as_json(), "variant_range": range_text(chosen)})
    else:
        show_check(report, range_text(chosen))
    raise typer.Exit(0 if report.passed else 1)


def show_check(report: object, span: str) -> None:
    """The check's table (stdout) and each failed property with its reason (stderr)."""
    from llcps.cps.check import PROPERTIES, CheckReport

    assert isinstance(report, CheckReport)
    mark = {True: "yes", False: "NO"}
    print_table(
        f"{report.scenario}: variants {span}" + (" (quick: sweeps stop at the first resolving candidate)" if report.quick else ""),
        ("variant", *PROPERTIES, "candidates", "resolving", "first position"),
        [
            (v.variant, *(mark[v.properties[p]] for p in PROPERTIES), v.sweep.candidates, v.resolving_label, v.sweep.first_position or "-")
            for v in report.variants
        ],
    )
    if len(report.variants) > 1:
        shares = report.shares()
        print_table(
            f"share of variants {span} where each property holds",
            ("property", "share", "what it says"),
            [(p, f"{shares[p]:.0%} ({round(shares[p] * len(report.variants))}/{len(report.variants)})", text) for p, text in PROPERTIES.items()],
        )
    for v in report.variants:
        for prop, reason in v.reasons.items():
            message(f"variant {v.variant}: {prop} does not hold: {reason}")
    message("every property holds" if report.passed else "some property does not hold (exit 1)")
