"""Result rows: what a run's sequences add up to, one row per (sequence, scenario).

A row says how much exploration one scenario of one sequence took and whether it was
solved; its cell, seed and variant come from the sequence's branch
(:mod:`llcps.experiments.design`). This module fixes the row's columns and how rows
are written to ``results.csv`` and ``results.json``; reading them back, with one clear
error per bad field, is :mod:`llcps.analysis.results`.
"""

from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Iterable

from llcps.errors import LlcpsError
from llcps.experiments.design import Cell, Sequence
from llcps.tabular import csv_value

#: Columns that can be analysed as "exploration" (the paper's Figure 2 uses time).
METRICS: tuple[str, ...] = ("exploration_trials", "sim_seconds", "wall_seconds")
#: The scenario condition experiment episodes run in.
NOVELTY = "novelty"


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

    @property
    def cell(self) -> Cell:
        return Cell(self.model, self.measure, self.pretrain_size, self.condition)

    @property
    def sequence(self) -> Sequence:
        return Sequence(self.preset, self.cell, self.seed, self.variant)

    @property
    def key(self) -> tuple[Sequence, str]:
        """What identifies a row: at most one row per (sequence, scenario)."""
        return (self.sequence, self.scenario)

    def on_scenes(self, paired: bool) -> bool:
        """Whether the row ran on the canonical scenes (variant 0) or, ``paired``, on its
        seed's own variant (``experiment run --variants``); seed 0 is both."""
        return self.variant == (self.seed if paired else 0)

    def metric(self, name: str) -> float:
        """The value of one of :data:`METRICS`."""
        check_metric(name)
        return float(getattr(self, name))


COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(ResultRow))


def row_records(rows: Iterable[ResultRow]) -> list[dict[str, Any]]:
    """The rows as plain dicts, one key per column."""
    return [asdict(r) for r in rows]


def write_rows_csv(rows: Iterable[ResultRow], path: str | Path) -> Path:
    """Write ``results.csv``: floats as ``repr`` (exact), booleans as every export writes them."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as fh:
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
    path.write_text(json.dumps({"columns": list(COLUMNS), "rows": row_records(rows)}, indent=1) + "\n", encoding="utf-8")
    return path


__all__ = ["COLUMNS", "METRICS", "NOVELTY", "ResultRow", "check_metric", "row_records", "write_rows_csv", "write_rows_json"]
