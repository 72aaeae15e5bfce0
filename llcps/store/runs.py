"""Runs side by side: what two runs were asked to do, where they ran, and what they did.

A difference in results between two runs is explained by a difference here (code,
libraries, host, configuration) or it is noise; :func:`compare_runs` lines the two
up field by field for ``llcps inspect runs --compare A B`` and the Python API.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

from llcps.provenance import FIELDS as PROVENANCE_FIELDS
from llcps.store.records import EpisodeRecord, RunRecord
from llcps.store.store import Store


def run_seconds(run: RunRecord) -> float | None:
    """Wall seconds from a run's start to its end (None while it runs)."""
    if not run.finished_at or not run.started_at:
        return None
    try:
        return round((datetime.fromisoformat(run.finished_at) - datetime.fromisoformat(run.started_at)).total_seconds(), 3)
    except ValueError:  # an unparseable timestamp read from the database
        return None


@dataclass(frozen=True)
class ComparedField:
    """One line of a comparison: a field and its value in each run."""

    name: str
    a: Any
    b: Any

    @property
    def same(self) -> bool:
        return self.a == self.b

    def as_json(self) -> dict[str, Any]:
        return {"field": self.name, "a": self.a, "b": self.b, "same": self.same}


@dataclass(frozen=True)
class RunComparison:
    """Two runs, field by field (run, configuration, provenance, activity, episodes)."""

    a: RunRecord
    b: RunRecord
    fields: tuple[ComparedField, ...]

    @property
    def differences(self) -> tuple[ComparedField, ...]:
        return tuple(f for f in self.fields if not f.same)

    def as_json(self) -> dict[str, Any]:
        return {
            "a": self.a.id,
            "b": self.b.id,
            "fields": [f.as_json() for f in self.fields],
            "differences": [f.name for f in self.differences],
        }


def _episode_fields(episodes: list[EpisodeRecord]) -> dict[str, Any]:
    """Per scenario: the episodes' statuses and their exploration trials and wall seconds, summed."""
    out: dict[str, Any] = {}
    for scenario in sorted({e.scenario for e in episodes}):
        mine = [e for e in episodes if e.scenario == scenario]
        out[f"{scenario} status"] = ", ".join(e.status for e in mine)
        for key in ("exploration_trials", "wall_seconds"):
            values = [e.summary.get(key) for e in mine]
            numbers = [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]
            out[f"{scenario} {key.replace('_', ' ')}"] = round(sum(numbers), 3) if numbers else None
    return out


def _run_fields(store: Store, run: RunRecord) -> dict[str, Any]:
    fields: dict[str, Any] = {
        "command": run.command,
        "branch": run.branch,
        "seed": run.seed,
        "status": run.status,
        "started_at": run.started_at,
        "wall seconds": run_seconds(run),
    }
    fields.update({f"config.{k}": v for k, v in sorted(run.config.items())})
    fields.update({name: getattr(run.provenance, name) for name in PROVENANCE_FIELDS})
    activity = store.run_activity([run.id])[run.id]
    fields.update({k if k in ("episodes", "trials") else f"{k} trials": v for k, v in activity.items()})
    fields.update(_episode_fields(store.list_episodes(run_id=run.id)))
    return fields


def compare_runs(store: Store, a: int, b: int) -> RunComparison:
    """Runs ``a`` and ``b`` side by side; a field one run lacks shows as None there.

    Raises:
        LlcpsError: either run does not exist.
    """
    run_a, run_b = store.get_run(a), store.get_run(b)
    fields_a, fields_b = _run_fields(store, run_a), _run_fields(store, run_b)
    names = list(dict.fromkeys([*fields_a, *fields_b]))
    return RunComparison(
        a=run_a, b=run_b, fields=tuple(ComparedField(n, fields_a.get(n), fields_b.get(n)) for n in names)
    )


__all__ = ["ComparedField", "RunComparison", "compare_runs", "run_seconds"]
