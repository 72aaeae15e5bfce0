"""Which results one report covers: a preset's rows from the store, one set of scenes,
one preset, the random-order baseline run beside it, and the ordering of its per-cell
sections."""

from __future__ import annotations

from typing import Iterable

from llcps.analysis.results import ResultsTable, table_from_episodes
from llcps.analysis.versus_random import BASELINE_MODEL
from llcps.cps.orderings import PAPER_ORDERING
from llcps.experiments.rows import ordering_rank
from llcps.errors import LlcpsError
from llcps.store import Store


def results_table(
    store: Store,
    preset: str,
    seeds: Iterable[int] | None = None,
    *,
    variants: bool = False,
    scenarios: Iterable[str] | None = None,
) -> ResultsTable:
    """The results of one preset (optionally some seeds and scenarios) from the store's episodes.

    ``variants``: the sequences where seed N solved scene variant N; otherwise those on
    the canonical scenes (variant 0). Seed 0 of either is the same sequence.
    """
    wanted = None if seeds is None else set(seeds)
    names = None if scenarios is None else set(scenarios)
    table = table_from_episodes(store.list_episodes()).table
    return ResultsTable(
        r
        for r in table
        if r.preset == preset
        and (wanted is None or r.seed in wanted)
        and (names is None or r.scenario in names)
        and r.on_scenes(paired=variants)
    )


def select_scenes(table: ResultsTable, variants: range | None = None) -> tuple[ResultsTable, int]:
    """The rows of one set of scenes, and how many rows of other scenes were left out.

    Statistics pair sequences by seed, so a report covers one set of scenes: with
    ``variants`` (A..B-1), the sequences where seed N solved variant N for N in the range;
    without, the whole table when it is all canonical (variant 0) or all paired, else its
    canonical rows.
    """
    if variants is not None:
        chosen = ResultsTable(r for r in table if r.on_scenes(paired=True) and r.seed in variants)
        if len(chosen) == 0:
            held = sorted({r.variant for r in table if r.variant})
            raise LlcpsError(
                f"no results on scene variants {variants.start}:{variants.stop}",
                hint=(
                    f"the results hold variants {_span(held)}" if held else "they hold the canonical scenes only: omit --variants"
                )
                + f"; run `llcps experiment run --variants {variants.start}:{variants.stop}` first",
            )
        return chosen, len(table) - len(chosen)
    if all(r.on_scenes(paired=False) for r in table) or all(r.on_scenes(paired=True) for r in table):
        return table, 0
    chosen = ResultsTable(r for r in table if r.on_scenes(paired=False))
    return chosen, len(table) - len(chosen)


def _span(values: list[int]) -> str:
    return f"{values[0]}-{values[-1]}" if values else "none"


def one_preset(table: ResultsTable, preset: str | None = None) -> tuple[str, ResultsTable]:
    """The rows of ``preset``, or of the table's only preset when none is named.

    Presets share model and measure names, so a report over two of them would mix
    their cells; a table holding several needs a choice.
    """
    presets = table.unique("preset")
    if preset is None:
        if len(presets) > 1:
            raise LlcpsError(
                f"the results hold {len(presets)} presets: {', '.join(presets)}", hint="choose one with --preset"
            )
        if not presets:
            raise LlcpsError("there are no experiment results", hint="run `llcps experiment run` first")
        preset = str(presets[0])
    if preset not in presets:
        raise LlcpsError(
            f"no results of preset {preset!r}",
            hint=f"the results hold: {', '.join(presets)}" if presets else "run `llcps experiment run` first",
        )
    return preset, table.filter(preset=preset)


def with_baseline(table: ResultsTable, source: ResultsTable, baseline_preset: str) -> ResultsTable:
    """``table`` plus the random-order rows of ``baseline_preset`` from ``source``.

    A grid without the random model (``paper``) gets its baseline from a preset run
    beside it in the same store (``random``); the random order uses no training data,
    so its rows stand for any pretraining size.
    """
    extra = source.filter(preset=baseline_preset, model=BASELINE_MODEL)
    if len(extra) == 0:
        raise LlcpsError(
            f"no {BASELINE_MODEL}-model results of preset {baseline_preset!r}",
            hint=f"run `llcps experiment run --preset {baseline_preset}` on the same store first",
        )
    return ResultsTable([*table, *extra])


def orderings(table: ResultsTable) -> tuple[str, ...]:
    """The orderings the table's rows ran, the paper's first."""
    return tuple(sorted(table.unique("ordering"), key=ordering_rank))


def one_ordering(table: ResultsTable) -> tuple[str, ResultsTable]:
    """The ordering a report's per-cell sections cover, and its rows with their baseline.

    Cells are named by model, measure, pretraining size and condition, so two
    orderings' rows of one cell (results of several stores, merged) would be pooled;
    the leave-one-family-out comparison groups by ordering and takes the whole table,
    every other section one ordering: the paper's when a model other than the random
    order ran it, else the first such. Its random-order rows are those of the paper's
    ordering when the table holds them (the baseline of every ordering), else its own.
    A table of one ordering is returned whole.
    """
    if len(table.unique("ordering")) <= 1:
        return (str(table.rows[0].ordering) if len(table) else PAPER_ORDERING), table
    guided = ResultsTable(r for r in table if r.model != BASELINE_MODEL)
    chosen = orderings(guided)[0] if len(guided) else orderings(table)[0]
    random = orderings(ResultsTable(r for r in table if r.model == BASELINE_MODEL))
    base = PAPER_ORDERING if PAPER_ORDERING in random else chosen
    return chosen, ResultsTable(r for r in table if r.ordering == (base if r.model == BASELINE_MODEL else chosen))


__all__ = ["one_ordering", "one_preset", "orderings", "results_table", "select_scenes", "with_baseline"]
