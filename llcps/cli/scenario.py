"""``llcps scenario``: list, show, render and check the scenario files."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional, Sequence

import typer

from llcps.cli._common import JsonFlag, choice_enum, message, new_app, notice, print_json, print_table
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display
from llcps.jobs import scenario as jobs
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


@app.command("list", epilog=examples("llcps scenario list", "llcps scenario list --json"))
def list_cli(as_json: JsonFlag = False) -> None:
    """List the shipped scenarios: name, alias, goal, whether variants differ, and the file."""
    scenarios = jobs.list_scenarios()
    if as_json:
        print_json([s.as_json() for s in scenarios])
        return
    print_table(
        "scenarios",
        ("name", "alias", "task", "goal", "variants differ"),
        [(s.name, s.alias, s.title, " ".join(s.goal), "yes" if s.varies else "no") for s in scenarios],
    )


@app.command(
    "show",
    epilog=examples(
        "llcps scenario show scenario2                        # the shipped file, as TOML",
        "llcps scenario show scenario2 > my.toml && llcps solve my.toml   # a copy of your own, named my",
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

    Saved as TOML, a shown file loads back to the same scenes (a shown variant to that
    variant's scene) as a scenario of its own: a shipped scenario's name and alias are
    commented out, so `llcps solve my.toml` names it after the file ("my") unless you set
    a name in it; no two scenarios share a name.
    """
    text = jobs.show_scenario(name=name, fmt=str(fmt.value), variant=variant)  # type: ignore[attr-defined]
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
    chosen = CONDITIONS if condition is None else (str(condition.value),)  # type: ignore[attr-defined]
    with progress_display("scenario render", "loading the simulator") as progress:
        result = jobs.render_scenario(name=name, out_dir=out_dir, variant=variant, conditions=chosen, progress=progress)
    if as_json:
        print_json(result.as_json())
        return
    for path in result.files:
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
    A full sweep tries every candidate in physics, minutes per variant: once a sweep's
    first 3 trials are timed, a line on stderr says how long it may take (candidates x
    the larger of their time and a typical 0.5 s a trial).
    Exit code 0 when every property holds on every variant, 1 when one does not.
    """
    chosen = parse_range(variants)
    label = get_scenario(name).name
    from llcps.cps.check import TIMED_TRIALS  # the simulator loads here, not at start

    sweeps = "stopping at the first resolving candidate" if quick else "every candidate, often minutes"
    message(
        f"checking {label}, {len(chosen)} variant(s): for each a solve of the original condition and a sweep of the "
        f"novelty's candidates ({sweeps}); how long a sweep may take follows once its first {TIMED_TRIALS} trials are timed"
    )
    with progress_display(f"scenario check {label}", "loading the simulator") as progress:
        report = jobs.check_scenario(
            name=name, variants=chosen, quick=quick, progress=progress, estimate=lambda e: message(sweep_estimate_text(e, chosen))
        )
    if as_json:
        print_json({**report.as_json(), "variant_range": range_text(chosen)})
    else:
        show_check(report, range_text(chosen))
    raise typer.Exit(0 if report.passed else 1)


def sweep_estimate_text(estimate: object, variants: Sequence[int]) -> str:
    """How long a variant's sweep may take, for people (and the whole check, at the first variant)."""
    from llcps.cps.check import TYPICAL_SECONDS_PER_TRIAL, SweepEstimate

    assert isinstance(estimate, SweepEstimate)
    text = (
        f"variant {estimate.variant}: {estimate.candidates} candidates x ~{estimate.seconds_per_trial:.1f} s a trial "
        f"(the first {estimate.timed} took {estimate.measured:.2f} s each, a typical trial {TYPICAL_SECONDS_PER_TRIAL} s): "
        f"the sweep may take {about(estimate.seconds)}"
    )
    if estimate.quick:
        text += " at most (--quick stops at the first resolving candidate)"
    if len(variants) > 1 and estimate.variant == variants[0]:
        text += f"; {len(variants)} variants, if alike: {about(estimate.seconds * len(variants))}"
    return text


def about(seconds: float) -> str:
    """A rough duration for people: ``under a minute``, ``~7 min``, ``~2 h 5 min``."""
    if seconds < 60:
        return "under a minute"
    minutes = round(seconds / 60)
    return f"~{minutes} min" if minutes < 60 else f"~{minutes // 60} h {minutes % 60} min"


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
            notice(f"variant {v.variant}: {prop} does not hold: {reason}")
    notice("every property holds" if report.passed else "some property does not hold (exit 1)")
