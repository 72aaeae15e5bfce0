"""Runs and episodes: what each invocation and each scenario solve was asked to do,
where it ran (its provenance), how it ended, and two runs side by side.

A run is one CLI invocation or experiment sequence; an episode is one scenario solve
within it, on one branch. A difference in results between two runs is explained by a
difference in what :func:`compare_runs` lines up (code, libraries, host,
configuration) or it is noise; it serves ``llcps inspect runs --compare A B`` and the
Python API.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from datetime import datetime
from typing import Any, Mapping, Sequence

from sqlalchemy import func, insert, select, update

from llcps.errors import LlcpsError, StoreError
from llcps.provenance import FIELDS as PROVENANCE_FIELDS
from llcps.provenance import Provenance
from llcps.provenance import current as provenance_of_process
from llcps.store.branches import BranchQueries
from llcps.store.records import EpisodeRecord, RunRecord
from llcps.store.tables import Branch, Episode, Run, Trial
from llcps.store.transactions import CHANGED_HINT, utc_now
from llcps.store.writers import Heartbeats
from llcps.store.trials import iso_timestamp


def run_provenance_values(provenance: Provenance) -> dict[str, Any]:
    """The ``runs`` columns that hold a run's provenance."""
    values = provenance.as_json()
    values["llcps_version"] = values["llcps_version"] or "unknown"  # the column predates provenance and is NOT NULL
    return values


def run_record(row: Any) -> RunRecord:
    """A ``runs`` row as a :class:`RunRecord` (the one place runs are read)."""
    return RunRecord(
        id=row.id,
        command=row.command,
        seed=row.seed,
        config=_mapping(row.config, f"run {row.id}", "config"),
        branch=row.branch,
        status=row.status,
        started_at=iso_timestamp(row.started_at) or "",
        finished_at=iso_timestamp(row.finished_at),
        provenance=Provenance(
            llcps_version=row.llcps_version,
            git_commit=row.git_commit,
            git_dirty=None if row.git_dirty is None else bool(row.git_dirty),
            python_version=row.python_version,
            pybullet_version=row.pybullet_version,
            torch_version=row.torch_version,
            sklearn_version=row.sklearn_version,
            numpy_version=row.numpy_version,
            host=row.host,
            cpu_count=row.cpu_count,
        ),
    )


def _episode_record(row: Any) -> EpisodeRecord:
    """An ``episodes`` row joined with its branch name, as an :class:`EpisodeRecord`."""
    return EpisodeRecord(
        id=row.id,
        run_id=row.run_id,
        branch=row.branch_name,
        scenario=row.scenario,
        condition=row.condition,
        model=row.model,
        measure=row.measure,
        seed=row.seed,
        status=row.status,
        summary=_mapping(row.summary, f"episode {row.id}", "summary"),
        started_at=iso_timestamp(row.started_at) or "",
        finished_at=iso_timestamp(row.finished_at),
    )


def _mapping(value: Any, row: str, column: str) -> Mapping[str, Any]:
    """A JSON column that must hold an object."""
    if not isinstance(value, dict):
        raise StoreError(f"{row} is malformed: its {column} is not a JSON object", hint=CHANGED_HINT)
    return value


class RunQueries(BranchQueries):
    """Recording runs and episodes as they start and end, and reading them back."""

    def start_run(
        self,
        *,
        command: str,
        seed: int | None,
        config: Mapping[str, Any],
        branch: str,
        provenance: Provenance | None = None,
        started_at: datetime | None = None,
    ) -> int:
        """Record the start of a CLI invocation or experiment sequence.

        Args:
            provenance: where the run runs (default: this process, :func:`llcps.provenance.current`).
            started_at: when the command started, in UTC without a time zone (default:
                now); a command that reads and fits before it records its run passes
                its own start, so the run's time is the command's.
        """
        env = provenance_of_process() if provenance is None else provenance
        with self._write() as conn:
            self._chain(conn, branch)
            run_id = conn.execute(
                insert(Run).values(
                    command=command,
                    seed=seed,
                    config=dict(config),
                    branch=branch,
                    status="running",
                    started_at=utc_now() if started_at is None else started_at,
                    # The live-writer marker (llcps.store.writers): this process, alive now.
                    pid=os.getpid() if provenance is None else None,
                    heartbeat_at=utc_now(),
                    **run_provenance_values(env),
                )
            ).inserted_primary_key[0]
        if provenance is None:
            self._heartbeats().start(run_id)
        return run_id

    def finish_run(self, run_id: int, *, status: str) -> None:
        """Record how a run ended (e.g. ``ok``, ``failed``, ``interrupted``)."""
        self._heartbeats().finish(run_id)
        with self._write() as conn:
            if conn.execute(update(Run).where(Run.id == run_id).values(status=status, finished_at=utc_now())).rowcount == 0:
                raise LlcpsError(f"unknown run {run_id}", hint="see `llcps inspect runs`")

    def _heartbeats(self) -> Heartbeats:
        """This store's heartbeat thread for the runs this process writes (made on first use)."""
        beats = self.__dict__.get("_run_heartbeats")
        if beats is None:
            beats = self.__dict__.setdefault("_run_heartbeats", Heartbeats(self._beat))
        return beats

    def _beat(self, run_ids: list[int]) -> None:
        with self._write() as conn:
            conn.execute(update(Run).where(Run.id.in_(run_ids), Run.status == "running").values(heartbeat_at=utc_now()))

    def start_episode(
        self,
        *,
        run_id: int | None,
        branch: str,
        scenario: str,
        condition: str,
        model: str | None,
        measure: str | None,
        seed: int | None,
    ) -> int:
        """Record the start of one scenario solve."""
        with self._write() as conn:
            chain = self._chain(conn, branch)
            return conn.execute(
                insert(Episode).values(
                    run_id=run_id,
                    branch_id=chain[0].branch_id,
                    scenario=scenario,
                    condition=condition,
                    model=model,
                    measure=measure,
                    seed=seed,
                    status="running",
                    summary={},
                    started_at=utc_now(),
                )
            ).inserted_primary_key[0]

    def finish_episode(self, episode_id: int, *, status: str, summary: Mapping[str, Any]) -> None:
        """Record an episode's outcome and summary (trial counts, times, learned operator)."""
        with self._write() as conn:
            stmt = update(Episode).where(Episode.id == episode_id).values(status=status, summary=dict(summary), finished_at=utc_now())
            if conn.execute(stmt).rowcount == 0:
                raise LlcpsError(f"unknown episode {episode_id}", hint="see `llcps inspect runs`")

    def list_runs(
        self, *, branch: str | None = None, limit: int | None = None, ids: Sequence[int] | None = None
    ) -> list[RunRecord]:
        """Runs, newest first (``ids``: only these runs)."""
        stmt = select(Run).order_by(Run.id.desc()).limit(limit)
        if branch is not None:
            stmt = stmt.where(Run.branch == branch)
        if ids is not None:
            stmt = stmt.where(Run.id.in_(list(ids)))
        with self._read() as conn:
            return [run_record(r) for r in conn.execute(stmt)]

    def run_activity(self, run_ids: Sequence[int]) -> dict[int, dict[str, int]]:
        """Per run: its episodes and its trials by source (``{"episodes": 3, "pretrain": 0, ...}``)."""
        ids = list(run_ids)
        out: dict[int, dict[str, int]] = {i: {"episodes": 0, "trials": 0} for i in ids}
        if not ids:
            return out
        with self._read() as conn:
            episodes = conn.execute(
                select(Episode.run_id, func.count()).where(Episode.run_id.in_(ids)).group_by(Episode.run_id)
            ).all()
            trials = conn.execute(
                select(Trial.run_id, Trial.source, func.count()).where(Trial.run_id.in_(ids)).group_by(Trial.run_id, Trial.source)
            ).all()
        for run_id, count in episodes:
            out[run_id]["episodes"] = int(count)
        for run_id, source, count in trials:
            out[run_id][str(source)] = int(count)
            out[run_id]["trials"] += int(count)
        return out

    def get_run(self, run_id: int) -> RunRecord:
        """One run by id."""
        found = self.list_runs(ids=[run_id])
        if not found:
            raise LlcpsError(f"unknown run {run_id}", hint="see `llcps inspect runs` for run ids")
        return found[0]

    def list_episodes(
        self,
        *,
        run_id: int | None = None,
        branch: str | None = None,
        scenario: str | None = None,
        limit: int | None = None,
    ) -> list[EpisodeRecord]:
        """Episodes, newest first; ``branch`` means episodes run on that branch itself."""
        stmt = (
            select(Episode, Branch.name.label("branch_name"))
            .join(Branch, Branch.id == Episode.branch_id)
            .order_by(Episode.id.desc())
            .limit(limit)
        )
        if run_id is not None:
            stmt = stmt.where(Episode.run_id == run_id)
        if branch is not None:
            stmt = stmt.where(Branch.name == branch)
        if scenario is not None:
            stmt = stmt.where(Episode.scenario == scenario)
        with self._read() as conn:
            return [_episode_record(r) for r in conn.execute(stmt)]

    def get_episode(self, episode_id: int) -> EpisodeRecord:
        """One episode by id, on whatever branch it ran."""
        stmt = (
            select(Episode, Branch.name.label("branch_name"))
            .join(Branch, Branch.id == Episode.branch_id)
            .where(Episode.id == episode_id)
        )
        with self._read() as conn:
            row = conn.execute(stmt).first()
        if row is None:
            raise LlcpsError(f"unknown episode {episode_id}", hint="see `llcps inspect episodes` for episode ids")
        return _episode_record(row)


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


def _run_fields(store: RunQueries, run: RunRecord) -> dict[str, Any]:
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


def compare_runs(store: RunQueries, a: int, b: int) -> RunComparison:
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


__all__ = ["ComparedField", "RunComparison", "RunQueries", "compare_runs", "run_provenance_values", "run_record", "run_seconds"]
