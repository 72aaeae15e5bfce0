"""Result rows: what a run's sequences add up to, one row per (sequence, scenario).

A row says how much exploration one scenario of one sequence took and whether it was
solved; its cell, seed and variant come from the sequence's branch
(:mod:`llcps.experiments.design`), its exploration ordering from the episode (branch
names do not record it, so each ordering runs into its own store and reports of
several are merged from their rows). This module fixes the row's columns and how rows
are written to ``results.csv`` and ``results.json``; reading them back, with one clear
error per bad field, is :mod:`llcps.analysis.results`.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Iterable

from llcps.cps.orderings import ORDERINGS, PAPER_ORDERING
from llcps.cps.orderings.base import MAX_PICK_NAME
from llcps.domain import MAX_ID, MAX_PRETRAIN_TRIALS, MAX_SEED
from llcps.errors import LlcpsError
from llcps.outputs import replaced_atomically, write_text
from llcps.experiments.design import MAX_DRAWS, Cell, Sequence, rank_by
from llcps.tabular import csv_value

#: Columns that can be analysed as "exploration" (the paper's Figure 2 uses time).
METRICS: tuple[str, ...] = ("exploration_trials", "sim_seconds", "wall_seconds")
#: The scenario condition experiment episodes run in.
NOVELTY = "novelty"


#: Columns that hold a name.
_TEXT_COLUMNS: tuple[str, ...] = ("preset", "model", "measure", "condition", "scenario", "branch", "ordering")
#: Longest name a text column may hold.
MAX_TEXT_VALUE = 200


class ColumnError(ValueError):
    """A value a result row cannot hold, naming its column."""

    def __init__(self, column: str, message: str) -> None:
        super().__init__(f"{column}: {message}")
        self.column = column
        self.message = message


def check_metric(metric: str) -> None:
    """Fail unless ``metric`` is one of :data:`METRICS`."""
    if metric not in METRICS:
        raise LlcpsError(f"unknown metric {metric!r}", hint=f"choose one of: {', '.join(METRICS)}")


@dataclass(frozen=True)
class ResultRow:
    """One scenario of one sequence: how much exploration it took and whether it solved."""

    preset: str
    model: str
    measure: str
    pretrain_size: int
    condition: str
    seed: int
    scenario: str
    solved: bool
    exploration_trials: int
    sim_seconds: float
    wall_seconds: float
    episode_id: int | None
    branch: str
    #: The scene variant (0: the canonical scene).
    variant: int = 0
    #: The exploration ordering the episode ran (:mod:`llcps.cps.orderings`); results
    #: written before the column existed ran the paper's.
    ordering: str = PAPER_ORDERING
    #: Which permutation of the random order (:attr:`~llcps.experiments.design.Sequence.draw`;
    #: 0 for every other model, and in results written before the column existed).
    draw: int = 0
    #: The side of the ordering that chose the resolving trial (the hedge's ``model`` or
    #: ``random``: :func:`~llcps.cps.orderings.base.resolving_pick`); empty when the
    #: episode did not solve, its ordering has no sides, or the results predate the column.
    resolving_pick: str = ""

    def __post_init__(self) -> None:
        """Each field of the type and range a run writes: a results file is user input,
        and a NaN or a negative count would make every statistic built on it nonsense."""
        for name in _TEXT_COLUMNS:
            value = getattr(self, name)
            if not isinstance(value, str) or not value or len(value) > MAX_TEXT_VALUE or not value.isprintable():
                raise ColumnError(name, f"must be a printable name of at most {MAX_TEXT_VALUE} characters, got {value!r}")
        for name, high in (("pretrain_size", MAX_PRETRAIN_TRIALS), ("seed", MAX_SEED), ("variant", MAX_SEED), ("draw", MAX_DRAWS - 1), ("exploration_trials", MAX_ID)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= high:
                raise ColumnError(name, f"must be a whole number from 0 to {high}, got {value!r}")
        for name in ("sim_seconds", "wall_seconds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ColumnError(name, f"must be a finite number of seconds, zero or more, got {value!r}")
        pick = self.resolving_pick
        if not isinstance(pick, str) or len(pick) > MAX_PICK_NAME or not pick.isprintable():
            raise ColumnError("resolving_pick", f"must be empty or a printable name of at most {MAX_PICK_NAME} characters, got {pick!r}")
        if not isinstance(self.solved, bool):
            raise ColumnError("solved", f"must be true or false, got {self.solved!r}")
        episode = self.episode_id
        if episode is not None and (isinstance(episode, bool) or not isinstance(episode, int) or not 1 <= episode <= MAX_ID):
            raise ColumnError("episode_id", f"must be empty or an episode id from 1 to {MAX_ID}, got {episode!r}")

    @property
    def cell(self) -> Cell:
        return Cell(self.model, self.measure, self.pretrain_size, self.condition)

    @property
    def sequence(self) -> Sequence:
        return Sequence(self.preset, self.cell, self.seed, self.variant, draw=self.draw)

    @property
    def key(self) -> tuple[Sequence, str, str]:
        """What identifies a row: at most one row per (sequence, scenario, ordering).

        The branch names the sequence but not the ordering, so two orderings' rows of one
        sequence and scenario (run into two stores) sit side by side in one table.
        """
        return (self.sequence, self.scenario, self.ordering)

    @property
    def label(self) -> str:
        """The key for people: ``exp-...-s3 scenario2 (hedged)``."""
        return f"{self.branch} {self.scenario} ({self.ordering})"

    def on_scenes(self, paired: bool) -> bool:
        """Whether the row ran on the canonical scenes (variant 0) or, ``paired``, on its
        seed's own variant (``experiment run --variants``); seed 0 is both."""
        return self.variant == (self.seed if paired else 0)

    def metric(self, name: str) -> float:
        """The value of one of :data:`METRICS`."""
        check_metric(name)
        return float(getattr(self, name))


COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(ResultRow))


def ordering_rank(ordering: str) -> tuple[int, str]:
    """Sort key: the registered orderings in the registry's order (the paper's first), others after by name."""
    return rank_by(tuple(ORDERINGS), ordering)


def row_records(rows: Iterable[ResultRow]) -> list[dict[str, Any]]:
    """The rows as plain dicts, one key per column."""
    return [asdict(r) for r in rows]


def write_rows_csv(rows: Iterable[ResultRow], path: str | Path) -> Path:
    """Write ``results.csv``: floats as ``repr`` (exact), booleans as every export writes them."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with replaced_atomically(path, what="results") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for record in row_records(rows):
            record["episode_id"] = "" if record["episode_id"] is None else record["episode_id"]
            record["sim_seconds"] = repr(record["sim_seconds"])
            record["wall_seconds"] = repr(record["wall_seconds"])
            writer.writerow({k: csv_value(v) for k, v in record.items()})
    return path


def write_rows_json(rows: Iterable[ResultRow], path: str | Path) -> Path:
    """Write ``{"columns": [...], "rows": [...]}``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_text(path, json.dumps({"columns": list(COLUMNS), "rows": row_records(rows)}, indent=1) + "\n", what="results")


__all__ = [
    "COLUMNS",
    "ColumnError",
    "METRICS",
    "NOVELTY",
    "ResultRow",
    "check_metric",
    "ordering_rank",
    "row_records",
    "write_rows_csv",
    "write_rows_json",
]
