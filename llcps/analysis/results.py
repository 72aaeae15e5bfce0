"""The results table: every result row of an experiment, read back and checked.

Everything downstream (statistics, plots, report) reads this table and nothing else,
so a report can be rebuilt from a CSV, a JSON file or the experience store without
re-running a single trial. The table is a tuple of frozen rows
(:class:`~llcps.experiments.rows.ResultRow`); numpy arrays are made on demand (no
pandas: the table is small and its columns are fixed). Reading validates every
field, with one clear error per bad value; writing is the rows' own format.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, TypeVar

import numpy as np

from llcps.errors import LlcpsError
from llcps.inputs import read_user_text
from llcps.limits import MAX_RESULTS_FILE_BYTES
from llcps.experiments.design import Sequence, parse_branch, scenario_rank
from llcps.experiments.presets import PRESETS
from llcps.cps.orderings import PAPER_ORDERING
from llcps.cps.orderings.base import resolving_pick
from llcps.experiments.rows import (
    COLUMNS,
    METRICS,
    ColumnError,
    NOVELTY,
    ResultRow,
    ordering_rank,
    row_records,
    write_rows_csv,
    write_rows_json,
)

K = TypeVar("K")


def _integer(raw: Any) -> int:
    """An integer column: an int or its text (a float, even 3.0, is not a count)."""
    if isinstance(raw, bool) or isinstance(raw, float):
        raise ValueError(f"not a whole number: {raw!r}")
    return int(raw)


def _real(raw: Any) -> float:
    if isinstance(raw, bool):
        raise ValueError(f"not a number: {raw!r}")
    return float(raw)


_PARSERS: dict[str, Callable[[Any], Any]] = {
    "pretrain_size": _integer,
    "seed": _integer,
    "variant": _integer,
    "draw": _integer,
    "exploration_trials": _integer,
    "sim_seconds": _real,
    "wall_seconds": _real,
}


#: The hint of an error reading a results file.
_READ_HINT = "pass a results directory, or the results.csv or results.json a run wrote"


def _parse_bool(text: str) -> bool:
    low = text.strip().lower()
    if low in ("true", "1", "yes"):
        return True
    if low in ("false", "0", "no"):
        return False
    raise ValueError(f"not a boolean: {text!r}")


def _text(raw: Any) -> str:
    """A text column's value: a string as read (a CSV cell, or a JSON string); a JSON
    number, list or object there is an error, not its ``str()``."""
    if not isinstance(raw, str):
        raise TypeError(f"not text: {type(raw).__name__}")
    return raw


def _row_from_mapping(data: Mapping[str, Any], where: str) -> ResultRow:
    """Build a row from strings (CSV) or JSON values, with one clear error per bad field.

    Results written before scene variants existed have no ``variant`` column: variant 0;
    before orderings were recorded, no ``ordering`` column: the paper's ordering, the
    only one runs had; before draws of the random order, no ``draw`` column: draw 0;
    before the resolving pick was recorded, no ``resolving_pick`` column: empty.
    """
    data = {"variant": 0, "ordering": PAPER_ORDERING, "draw": 0, "resolving_pick": "", **data}
    missing = [c for c in COLUMNS if c not in data]
    if missing:
        raise LlcpsError(
            f"{where}: missing column(s) {', '.join(missing)}", hint=f"expected columns: {', '.join(COLUMNS)}"
        )
    values: dict[str, Any] = {}
    for name in COLUMNS:
        raw = data[name]
        try:
            if name == "solved":
                values[name] = raw if isinstance(raw, bool) else _parse_bool(str(raw))
            elif name == "episode_id":
                values[name] = None if raw in (None, "") else _integer(raw)
            elif name == "resolving_pick":
                values[name] = "" if raw is None else _text(raw)
            elif name in _PARSERS:
                values[name] = _PARSERS[name](raw)
            else:
                values[name] = _text(raw)
        except (TypeError, ValueError, OverflowError):
            raise LlcpsError(f"{where}: column {name!r}: bad value {_shown(raw)}", hint=_ROW_HINT) from None
    try:
        return ResultRow(**values)
    except ColumnError as exc:
        raise LlcpsError(f"{where}: column {exc.column!r}: {exc.message}", hint=_ROW_HINT) from None


#: The hint of an error about a row of a results file.
_ROW_HINT = "a results file is written by `llcps experiment run`; fix or remove the row named"


def _shown(raw: Any) -> str:
    text = repr(raw)
    return text if len(text) <= 60 else text[:57] + "..."



class ResultsTable:
    """An immutable, ordered collection of :class:`ResultRow` with one row per key
    (sequence, scenario, ordering).

    Rows are kept sorted by (sequence, ordering, scenario order), so two tables with the
    same rows compare, serialise and analyse identically whatever order they were built in.
    """

    def __init__(self, rows: Iterable[ResultRow] = ()) -> None:
        by_key: dict[tuple[Sequence, str, str], ResultRow] = {}
        for row in rows:
            if row.key in by_key:
                raise LlcpsError(f"two results for {row.label}")
            by_key[row.key] = row
        self._rows: tuple[ResultRow, ...] = tuple(
            sorted(by_key.values(), key=lambda r: (r.sequence, ordering_rank(r.ordering), scenario_rank(r.scenario)))
        )

    # -- collection protocol -------------------------------------------------
    def __iter__(self) -> Iterator[ResultRow]:
        return iter(self._rows)

    def __len__(self) -> int:
        return len(self._rows)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ResultsTable) and self._rows == other._rows

    def __repr__(self) -> str:
        return f"ResultsTable({len(self._rows)} rows)"

    @property
    def rows(self) -> tuple[ResultRow, ...]:
        return self._rows

    def filter(self, **equal: Any) -> ResultsTable:
        """The rows whose fields equal every given value, e.g. ``filter(scenario="scenario2")``."""
        unknown = set(equal) - set(COLUMNS)
        if unknown:
            raise LlcpsError(f"unknown column(s) {', '.join(sorted(unknown))}", hint=f"columns: {', '.join(COLUMNS)}")
        return ResultsTable(r for r in self._rows if all(getattr(r, k) == v for k, v in equal.items()))

    def column(self, name: str) -> np.ndarray:
        """One column as a numpy array (object dtype for text columns)."""
        if name not in COLUMNS:
            raise LlcpsError(f"unknown column {name!r}", hint=f"columns: {', '.join(COLUMNS)}")
        values = [getattr(r, name) for r in self._rows]
        if name in METRICS or name in ("pretrain_size", "seed", "variant", "draw"):
            return np.asarray(values, dtype=float if name in METRICS else int)
        if name == "solved":
            return np.asarray(values, dtype=bool)
        return np.asarray(values, dtype=object)

    def unique(self, name: str) -> tuple[Any, ...]:
        """Distinct values of a column in first-seen (i.e. sorted-table) order."""
        return tuple(dict.fromkeys(getattr(r, name) for r in self._rows))

    # -- completeness, for resumable runs ------------------------------------
    def complete_runs(self) -> frozenset[tuple[Sequence, str]]:
        """(sequence, ordering) pairs with a row for every scenario their preset's rows hold.

        The store does not record which scenarios a run asked for, so a preset's list
        is every scenario any of its sequences solved in this table.
        """
        seen: dict[tuple[Sequence, str], set[str]] = {}
        per_preset: dict[str, set[str]] = {}
        for row in self._rows:
            seen.setdefault((row.sequence, row.ordering), set()).add(row.scenario)
            per_preset.setdefault(row.preset, set()).add(row.scenario)
        return frozenset(run for run, done in seen.items() if done >= per_preset[run[0].preset])

    def complete_sequences(self) -> frozenset[Sequence]:
        """Sequences complete (:meth:`complete_runs`) in every ordering the table holds them in."""
        complete = self.complete_runs()
        runs = {(r.sequence, r.ordering) for r in self._rows}
        return frozenset(s for s, _ in runs) - frozenset(s for s, o in runs if (s, o) not in complete)

    def missing(self, sequences: Iterable[Sequence]) -> tuple[Sequence, ...]:
        """The given sequences that are not complete yet, in the given order."""
        done = self.complete_sequences()
        return tuple(s for s in sequences if s not in done)

    # -- serialisation ---------------------------------------------------------
    def to_records(self) -> list[dict[str, Any]]:
        return row_records(self._rows)

    def write_csv(self, path: str | Path) -> Path:
        return write_rows_csv(self._rows, path)

    @classmethod
    def read_csv(cls, path: str | Path) -> ResultsTable:
        path = Path(path)
        text = read_user_text(path, what="results file", max_bytes=MAX_RESULTS_FILE_BYTES, hint=_READ_HINT)
        try:
            reader = csv.DictReader(io.StringIO(text, newline=""))
            return cls(_row_from_mapping(rec, f"{path}: row {i + 1} (line {reader.line_num})") for i, rec in enumerate(reader))
        except csv.Error as exc:
            raise LlcpsError(f"{path}: not a CSV file: {exc}", hint=_READ_HINT) from None

    def write_json(self, path: str | Path) -> Path:
        return write_rows_json(self._rows, path)

    @classmethod
    def read_json(cls, path: str | Path) -> ResultsTable:
        path = Path(path)
        text = read_user_text(path, what="results file", max_bytes=MAX_RESULTS_FILE_BYTES, hint=_READ_HINT)
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise LlcpsError(f"{path} is not valid JSON: {exc}", hint=_READ_HINT) from None
        except RecursionError:
            raise LlcpsError(f"{path}: JSON nested too deeply to be a results file", hint=_READ_HINT) from None
        rows = data.get("rows") if isinstance(data, dict) else data
        if not isinstance(rows, list):
            raise LlcpsError(f"{path}: expected a list of rows or an object with 'rows'", hint=_READ_HINT)
        for i, rec in enumerate(rows):
            if not isinstance(rec, dict):
                raise LlcpsError(f"{path}: row {i + 1}: not an object of columns", hint=_READ_HINT)
        return cls(_row_from_mapping(rec, f"{path}: row {i + 1}") for i, rec in enumerate(rows))

    @classmethod
    def read(cls, path: str | Path) -> ResultsTable:
        """Read a table from a ``.csv`` or ``.json`` file, or from a directory's ``results.csv``."""
        path = Path(path)
        if path.is_dir():
            path = path / "results.csv"
        if path.suffix == ".json":
            return cls.read_json(path)
        return cls.read_csv(path)


def merge_tables(sources: Iterable[tuple[str, ResultsTable]]) -> ResultsTable:
    """One table of the rows of several, each given with where it came from (a path).

    A row that several hold alike (same key, same values: e.g. the random-order rows
    every copy of one store keeps) is kept once. Two rows with the same key and
    different values cannot both be a result: an error naming the key and both sources.
    """
    merged: dict[tuple[Sequence, str, str], tuple[ResultRow, str]] = {}
    for source, table in sources:
        for row in table:
            held = merged.setdefault(row.key, (row, source))
            if held[0] != row:
                raise LlcpsError(
                    f"{held[1]} and {source} hold different results for {row.label}",
                    hint="one sequence, scenario and ordering has one result; results written before the ordering "
                    f"was recorded read as {PAPER_ORDERING!r}: set the ordering column of the rows another ordering ran",
                )
    return ResultsTable(row for row, _ in merged.values())


def _episode_summary(episode: Any) -> Mapping[str, Any] | None:
    if isinstance(episode, Mapping):
        return episode
    summary = getattr(episode, "summary", None)
    if not isinstance(summary, Mapping):
        return None
    merged = dict(summary)
    # The record's columns are authoritative; the summary may predate the episode's end.
    # (The record has no ordering column: the summary's, absent before it was recorded.)
    columns = ("branch", "status", "scenario", "condition", "model", "measure")
    for key, attribute in (*((c, c) for c in columns), ("episode_id", "id")):
        value = getattr(episode, attribute, None)
        if value is not None:
            merged[key] = value
    return merged


@dataclass(frozen=True)
class EpisodeImport:
    """A table built from stored episodes, and what was left out and why."""

    table: ResultsTable
    skipped: dict[str, int]


def table_from_episodes(episodes: Iterable[Any]) -> EpisodeImport:
    """Build the results table from the experience store's episodes.

    Each episode is a mapping holding ``SolveResult.as_json()`` (scenario, condition,
    model, measure, ordering, seed, branch, solved, status, exploration_trials,
    sim_seconds, wall_seconds, episode_id), or a store ``EpisodeRecord`` whose ``summary`` holds it;
    the record's own ``branch``, ``status`` and ``id`` take precedence. The cell and
    seed come from the branch name; the summary must agree with it. The ordering is the
    summary's (the paper's when a summary predates it).

    Episodes on other branches, in the original condition, or still ``running``
    (a run cut off mid-episode) are skipped and counted. When one (sequence,
    scenario) was solved more than once in one ordering (a re-run), the latest episode wins.
    """
    skipped: dict[str, int] = {}
    chosen: dict[tuple[Sequence, str, str], tuple[tuple[int, int], ResultRow]] = {}

    def skip(reason: str) -> None:
        skipped[reason] = skipped.get(reason, 0) + 1

    for order, episode in enumerate(episodes):
        summary = _episode_summary(episode)
        if summary is None:
            skip("no summary")
            continue
        parsed = parse_branch(str(summary.get("branch", "")))
        if parsed is None:
            skip("not an experiment branch")
            continue
        if summary.get("condition", NOVELTY) != NOVELTY:
            skip("not the novelty condition")
            continue
        if summary.get("status") == "running":
            skip("unfinished episode")
            continue
        seq, scenario = parsed.sequence, str(summary.get("scenario"))
        if parsed.scenario is not None and parsed.scenario != scenario:
            # Under ``others`` the held-out scenario's branch holds the other scenarios'
            # episodes too: experience, not results.
            skip("another scenario's episode before the held-out one" if seq.cell.condition == "others" else "scenario does not match its branch")
            continue
        if summary.get("model") != seq.cell.model or summary.get("measure") != seq.cell.measure:
            skip("model or measure does not match its branch")
            continue
        if summary.get("variant", 0) != seq.variant:
            skip("scene variant does not match its branch")
            continue
        try:
            row = ResultRow(
                preset=seq.preset,
                model=seq.cell.model,
                measure=seq.cell.measure,
                pretrain_size=seq.cell.pretrain_size,
                condition=seq.cell.condition,
                seed=seq.seed,
                scenario=scenario,
                solved=bool(summary["solved"]),
                exploration_trials=int(summary["exploration_trials"]),
                sim_seconds=float(summary["sim_seconds"]),
                wall_seconds=float(summary["wall_seconds"]),
                episode_id=None if summary.get("episode_id") is None else int(summary["episode_id"]),
                branch=str(summary["branch"]),
                variant=seq.variant,
                ordering=str(summary.get("ordering") or PAPER_ORDERING),
                draw=seq.draw,
                resolving_pick=(resolving_pick(summary) or "") if summary["solved"] is True else "",
            )
        except (KeyError, TypeError, ValueError):
            skip("malformed summary")
            continue
        rank = (-1 if row.episode_id is None else row.episode_id, order)
        previous = chosen.get(row.key)
        if previous is not None:
            skip("superseded by a later episode")
            if previous[0] > rank:
                continue
        chosen[row.key] = (rank, row)
    return EpisodeImport(ResultsTable(row for _, row in chosen.values()), skipped)


def group_rows(rows: Iterable[ResultRow], key: Callable[[ResultRow], K]) -> dict[K, list[ResultRow]]:
    """Rows grouped by ``key``, each group in the rows' order."""
    groups: dict[K, list[ResultRow]] = {}
    for row in rows:
        groups.setdefault(key(row), []).append(row)
    return groups


def by_seed(rows: Iterable[ResultRow], metric: str) -> dict[int, float]:
    """seed -> the metric's value: the mean over the seed's rows, which are one row, or
    the draws of the random order (:attr:`~llcps.experiments.rows.ResultRow.draw`)."""
    values: dict[int, list[float]] = {}
    for row in rows:
        values.setdefault(row.seed, []).append(row.metric(metric))
    return {seed: sum(v) / len(v) for seed, v in values.items()}


def table_budget(table: ResultsTable) -> int | None:
    """The exploration budget of the table's episodes, when its presets share one."""
    budgets = {PRESETS[p].exploration_budget() if p in PRESETS else None for p in table.unique("preset")}
    return budgets.pop() if len(budgets) == 1 else None


__all__ = [
    "EpisodeImport",
    "ResultsTable",
    "by_seed",
    "group_rows",
    "merge_tables",
    "table_budget",
    "table_from_episodes",
]
