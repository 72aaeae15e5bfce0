"""Frozen dataclasses the store hands out and takes in.

Trials come back as :class:`llcps.trial_records.TrialRecord`; everything else the store
knows (branches, runs, episodes, snapshots, operators, world models) has its own
small record here. None of them holds a database session.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Mapping

from llcps.provenance import Provenance
from llcps.store.writers import Writer


@dataclass(frozen=True)
class BranchInfo:
    """A branch and how much experience it can see.

    Attributes:
        fork_point: the parent's last visible trial id at the fork (0 for a root).
        own_trials: trials written on this branch itself.
        visible_trials: own trials plus the ancestors' trials up to the fork points.
    """

    id: int
    name: str
    parent: str | None
    fork_point: int
    own_trials: int
    visible_trials: int
    created_at: str
    is_current: bool

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class BranchChange:
    """What deleting or resetting a branch removes (or would remove, on a dry run)."""

    branch: str
    action: str
    to: str | None
    dry_run: bool
    trials: int
    operators: int
    world_models: int
    episodes: int
    kept_until: int | None = None
    #: Runs writing to the branch at the time (:mod:`llcps.store.writers`), live or stale.
    writers: tuple[Writer, ...] = ()

    @property
    def summary(self) -> str:
        verb = "would remove" if self.dry_run else "removed"
        text = (
            f"{verb} {self.trials} trial(s), {self.operators} operator(s), "
            f"{self.world_models} world model(s) and {self.episodes} episode(s) "
            f"from branch {self.branch!r}"
        )
        live = [w for w in self.writers if w.live and not w.this_process]
        if live:
            text += "; " + ("live writer(s), refused without --force: " if self.dry_run else "aborted live writer(s): ")
            text += "; ".join(w.describe() for w in live)
        return text

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class RunRecord:
    """One CLI invocation or experiment sequence, and the environment it ran in."""

    id: int
    command: str
    seed: int | None
    config: Mapping[str, Any]
    branch: str
    status: str
    started_at: str
    finished_at: str | None
    provenance: Provenance = field(default_factory=Provenance)

    @property
    def llcps_version(self) -> str | None:
        return self.provenance.llcps_version

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class EpisodeRecord:
    """One scenario solve."""

    id: int
    run_id: int | None
    branch: str
    scenario: str
    condition: str
    model: str | None
    measure: str | None
    seed: int | None
    status: str
    summary: Mapping[str, Any]
    started_at: str
    finished_at: str | None

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class SnapshotRecord:
    """A stored physics state: the scene description and the simulator's bytes."""

    id: int
    scene: Mapping[str, Any]
    state: bytes
    sha256: str


@dataclass(frozen=True)
class OperatorRecord:
    """A learned operator of K', visible on a branch like the trials it came from."""

    id: int
    branch: str
    name: str
    pddl: str
    definition: Mapping[str, Any]
    scenario: str | None
    episode_id: int | None
    watermark: int
    created_at: str

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class ExecutionRecord:
    """One execution of an operator as a plan step on a branch (a row of the experience
    that costs operators), as moved between stores."""

    id: int
    branch: str
    operator: str
    success: bool
    context: tuple[tuple[str, ...], ...]
    episode_id: int | None
    trial_id: int | None
    watermark: int
    created_at: str


@dataclass(frozen=True)
class ExecutionCounts:
    """How often an operator, executed as a plan step in one context, worked or failed.

    Attributes:
        context: lifted atoms (tuples of strings) that held of the step's arguments.
    """

    operator: str
    context: tuple[tuple[str, ...], ...]
    successes: int
    failures: int


@dataclass(frozen=True)
class ModelArtifact:
    """A fitted world model's bytes (npz / state_dict / JSON, never a pickle).

    Attributes:
        watermark: the largest visible trial id when the model was fitted; the model
            is current for a branch when this equals the branch's max visible trial id.
    """

    id: int
    branch: str
    name: str
    seed: int
    watermark: int
    artifact: bytes
    sha256: str
    meta: Mapping[str, Any]
    created_at: str


@dataclass(frozen=True)
class CompactResult:
    """What ``llcps db compact`` did: the store's size on disk before and after (bytes;
    None for an in-memory store)."""

    url: str
    before: int | None
    after: int | None

    @property
    def freed(self) -> int | None:
        return None if self.before is None or self.after is None else self.before - self.after

    def as_json(self) -> dict[str, Any]:
        return {**asdict(self), "freed": self.freed}


@dataclass(frozen=True)
class StoreStatus:
    """What ``llcps db status`` reports."""

    url: str
    revision: str | None
    head: str
    up_to_date: bool
    current_branch: str
    branch: str
    branches: int
    trials_total: int
    visible_trials: int
    visible_by_source: Mapping[str, int]
    #: Trials of the store by how their symbolic change is known (recorded, replayed,
    #: unknown, missing); None for a store whose schema predates trial changes.
    changes: Mapping[str, int] | None = None
    #: Runs marked running, live or stale (:mod:`llcps.store.writers`); empty on an outdated store.
    writers: tuple[Writer, ...] = ()

    def as_json(self) -> dict[str, Any]:
        return asdict(self)
