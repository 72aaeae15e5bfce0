"""``llcps bench``: how close each layer comes to the physics bound (see docs/performance.md)."""

from __future__ import annotations

from typing import Annotated

import typer

from llcps.bench import GROUPS, SLOW_GROUPS, Figure, run_bench, unsteady
from llcps.cli._common import (
    JsonFlag,
    choice_enum,
    notice,
    print_json,
    print_table,
)
from llcps.cli._conventions import examples
from llcps.cli._progress import progress_display

EXAMPLES = examples(
    "llcps bench --quick                      # under a minute",
    "llcps bench --group physics --group store",
    "llcps bench --json > bench.json",
)

GroupName = choice_enum("BenchGroup", tuple(GROUPS))


def bench_cli(
    quick: Annotated[
        bool,
        typer.Option("--quick", help=f"Smaller runs, under a minute; leaves out {', '.join(SLOW_GROUPS)}."),
    ] = False,
    group: Annotated[
        list[GroupName] | None,  # type: ignore[valid-type]
        typer.Option("--group", metavar="NAME", help=f"Measure only this group (repeatable): {', '.join(GROUPS)}.", show_default=False),
    ] = None,
    as_json: JsonFlag = False,
) -> None:
    """Measure physics, exploration, world models, ranking, the store and worker scaling
    in this process, each against its target.

    Rates are per second of this process's CPU time (stable on a busy machine) and of
    wall time. Temporary stores only: --db is not touched. Exit code 0 even when a
    target is missed (the `met` column says which). A warning says when the machine's
    speed changed while the figures were taken; that group's targets are then not judged.
    """
    groups = [str(g.value) for g in group] if group else None  # type: ignore[attr-defined]
    with progress_display("bench", "loading") as progress:
        figures = run_bench(quick=quick, groups=groups, progress=progress.note)
    if as_json:
        print_json([f.as_json() for f in figures])
    else:
        print_table("llcps bench" + (" --quick" if quick else ""), ("figure", "value", "unit", "target", "met"), [_row(f) for f in figures])
        missed = [f.name for f in figures if f.met is False]
        if missed:
            notice(f"targets missed: {', '.join(missed)} (see docs/performance.md)")
    for caution in unsteady(figures):  # on stderr, beside the JSON too
        notice(f"warning: {caution}")


def _row(f: Figure) -> tuple[str, str, str, str, str]:
    met = ("not judged" if f.target else "") if f.met is None else ("yes" if f.met else "NO")
    return f.name, _num(f.value), f.unit, f.target or "", met


def _num(value: float) -> str:
    """Three significant digits, thousands separated."""
    if value == 0 or abs(value) >= 100:
        return f"{value:,.0f}"
    return f"{value:.3g}"
