"""Moving experience between stores: branches with their trials, snapshots, runs,
episodes, learned operators and operator executions, as plain data.

An experiment task runs in a worker against a private temporary store and sends
back a :class:`Payload`; the one writer imports it into the real store with
:func:`import_payload`, in one transaction, so a killed run holds whole tasks or
nothing of them. The same two functions seed a worker's store with the
pretraining trials a task needs.

Ids are local to the store they came from. On import every row gets a new id and
references are remapped: trials, runs, episodes, snapshots (deduplicated by their
content hash) and the trial ids that fork points, operator watermarks, episode
summaries and operator executions hold. Trials are imported in id order, so the
mapping is monotone and "visible up to trial id w" keeps its meaning. A payload may refer to trials it
does not carry (the pretraining trials a branch forked from): ``external`` maps
those ids to ids of the destination store.

World models are not carried: they are caches of a fit, refitted (identically,
for a seed) where they are missing. A trained exploration policy is not a cache (the
``rl`` ordering cannot refit it), so a worker's seed carries the policy its branch
sees (``policies``).
"""

from __future__ import annotations

import bisect
import hashlib
from dataclasses import dataclass, field, replace
from datetime import datetime
from typing import Any, Mapping, Sequence

from sqlalchemy import insert, select, update

from llcps.trial_records import TrialChange, TrialRecord
from llcps.errors import StoreError
from llcps.store import EpisodeRecord, ExecutionRecord, OperatorRecord, RunRecord, SnapshotRecord, Store, utc_now
from llcps.store.trial_changes import change_row
from llcps.store.model_artifacts import POLICY_NAME
from llcps.store.records import ModelArtifact
from llcps.store.tables import Branch, Episode, Operator, OperatorExecution, Run, Snapshot, Trial, TrialChangeRow, WorldModel
from llcps.store.runs import run_provenance_values
from llcps.store.training_set import seal_blocks
from llcps.store.trials import trial_row

#: Keys of an episode summary (``SolveResult.as_json()``) that hold store ids.
SUMMARY_ID_KEYS: Mapping[str, str] = {"episode_id": "episodes", "run_id": "runs", "resolving_trial_id": "trials"}

_INSERT_TRIALS = insert(Trial).returning(Trial.id, sort_by_parameter_order=True)


@dataclass(frozen=True)
class BranchLink:
    """A branch to create: its parent (by name) and fork point (a trial id of the payload's store)."""

    name: str
    parent: str | None
    fork_point: int


@dataclass(frozen=True)
class Payload:
    """Branches and everything they own, as picklable plain data.

    Attributes:
        branches: in creation order; a parent is either earlier in the list or
            already in the destination store.
        trials: the branches' own trials, in id order.
        changes: the known symbolic changes of those trials (``trial_id`` of the source).
        external: ids of trials the payload refers to (fork points, watermarks) but
            does not carry, mapped to ids of the destination store.
        executions: the branches' own operator executions as plan steps (what costs
            K's operators on them), in id order.
        policies: trained exploration policies (``rl-policy``), each written to the
            branch it names with its watermark mapped like an operator's.
    """

    branches: tuple[BranchLink, ...]
    runs: tuple[RunRecord, ...] = ()
    episodes: tuple[EpisodeRecord, ...] = ()
    snapshots: tuple[SnapshotRecord, ...] = ()
    trials: tuple[TrialRecord, ...] = ()
    operators: tuple[OperatorRecord, ...] = ()
    external: Mapping[int, int] = field(default_factory=dict)
    changes: tuple[TrialChange, ...] = ()
    executions: tuple[ExecutionRecord, ...] = ()
    policies: tuple[ModelArtifact, ...] = ()

    @property
    def branch_names(self) -> tuple[str, ...]:
        return tuple(b.name for b in self.branches)

    def with_external(self, external: Mapping[int, int]) -> Payload:
        """The same payload with ``external`` ids (a worker knows them after seeding)."""
        return replace(self, external=dict(external))


@dataclass(frozen=True)
class IdMap:
    """Source id -> destination id, per kind of row, after an import."""

    branches: Mapping[str, int]
    trials: Mapping[int, int]
    runs: Mapping[int, int]
    episodes: Mapping[int, int]
    snapshots: Mapping[int, int]
    operators: Mapping[int, int]


def export_branches(
    store: Store,
    branches: Sequence[str],
    *,
    snapshots: bool = True,
    provenance: bool = True,
    external: Mapping[int, int] | None = None,
    policies: bool = False,
) -> Payload:
    """Everything ``branches`` own in ``store``, ready for :func:`import_payload`.

    Args:
        branches: names, parents before children.
        snapshots: carry the physics states the trials start from (off: trials
            lose their ``snapshot_id``, e.g. when only a model will read them).
        provenance: carry runs and episodes (off: trials lose ``run_id`` and
            ``episode_id``, and operators their ``episode_id``).
        external: see :class:`Payload`.
        policies: carry the newest exploration policy each branch sees, wherever it is
            stored (its own or an ancestor's), as that branch's (a worker's seed: the
            ``rl`` ordering reads it there).
    """
    names = list(dict.fromkeys(branches))
    links: list[BranchLink] = []
    trials: list[TrialRecord] = []
    episodes: list[EpisodeRecord] = []
    runs: dict[int, RunRecord] = {}
    operators: list[OperatorRecord] = []
    executions: list[ExecutionRecord] = []
    for name in names:
        info = store.resolve_branch(name)
        links.append(BranchLink(name=name, parent=info.parent, fork_point=info.fork_point))
        trials.extend(t for t in store.visible_trials(name) if t.branch == name)
        operators.extend(o for o in store.visible_operators(name) if o.branch == name)
        executions.extend(store.own_operator_executions(name))
        if provenance:
            episodes.extend(reversed(store.list_episodes(branch=name)))
            runs.update((r.id, r) for r in store.list_runs(branch=name))
    trials.sort(key=lambda t: t.id)
    own = {t.id for t in trials}
    # A child branch sees its parent's trials too: each change once, by its trial.
    by_trial = {i: c for name in names for i, c in store.visible_changes(name).items() if i in own}
    changes = [by_trial[i] for i in sorted(by_trial)]
    episodes.sort(key=lambda e: e.id)
    if provenance:
        wanted = {t.run_id for t in trials} | {e.run_id for e in episodes}
        wanted.discard(None)
        if not wanted <= runs.keys():  # runs recorded on another branch: look them up
            runs.update((r.id, r) for r in store.list_runs() if r.id in wanted)
        runs = {k: v for k, v in runs.items() if k in wanted or v.branch in names}
    else:
        trials = [replace(t, run_id=None, episode_id=None) for t in trials]
        operators = [replace(o, episode_id=None) for o in operators]
        executions = [replace(e, episode_id=None) for e in executions]
        runs = {}
    if snapshots:
        snapshot_ids = sorted({t.snapshot_id for t in trials if t.snapshot_id is not None})
        states = tuple(store.get_snapshot(i) for i in snapshot_ids)
    else:
        trials = [replace(t, snapshot_id=None) for t in trials]
        states = ()
    return Payload(
        branches=tuple(links),
        runs=tuple(sorted(runs.values(), key=lambda r: r.id)),
        episodes=tuple(episodes),
        snapshots=states,
        trials=tuple(trials),
        operators=tuple(operators),
        external=dict(external or {}),
        changes=tuple(changes),
        executions=tuple(sorted(executions, key=lambda e: e.id)),
        policies=tuple(_policies(store, names)) if policies else (),
    )


def _policies(store: Store, names: Sequence[str]) -> list[ModelArtifact]:
    """The newest policy each branch sees, as that branch's own."""
    found = []
    for name in names:
        policy = store.latest_world_model(name, POLICY_NAME, 0)
        if policy is not None:
            found.append(replace(policy, branch=name))
    return found


def _time(text: str | None) -> datetime | None:
    return None if not text else datetime.fromisoformat(text)


class _TrialIds:
    """Maps trial ids, and ids that merely bound a prefix (fork points, watermarks).

    A bound ``w`` means "trials with id <= w"; it maps to the destination id of the
    largest known trial id <= w, which keeps the same prefix because the map is monotone.
    """

    def __init__(self, known: Mapping[int, int]) -> None:
        self.known = dict(known)
        self._keys: list[int] | None = None

    def add(self, source: int, destination: int) -> None:
        self.known[source] = destination
        self._keys = None

    def bound(self, value: int) -> int:
        if value <= 0:
            return 0
        if value in self.known:
            return self.known[value]
        if self._keys is None:
            self._keys = sorted(self.known)
        i = bisect.bisect_right(self._keys, value)
        if i == 0:
            return 0
        return self.known[self._keys[i - 1]]


def _need(mapping: Mapping[int, int], value: int | None, what: str) -> int | None:
    if value is None:
        return None
    try:
        return mapping[value]
    except KeyError:
        raise StoreError(
            f"the payload refers to {what} {value}, which it does not carry",
            hint="export with provenance and snapshots, or map the id in `external`",
        ) from None


def _remap_summary(summary: Mapping[str, Any], maps: Mapping[str, Mapping[int, int]]) -> dict[str, Any]:
    out = dict(summary)
    for key, kind in SUMMARY_ID_KEYS.items():
        value = out.get(key)
        if isinstance(value, int) and not isinstance(value, bool):
            out[key] = maps[kind].get(value)
    return out


def import_payload(store: Store, payload: Payload) -> IdMap:
    """Write a payload into ``store`` in one transaction: all of it, or nothing.

    Raises:
        StoreError: a branch already exists, a parent is missing, or the payload
            refers to a row it does not carry (nothing is written then).
    """
    trial_ids = _TrialIds(payload.external)
    with store._write() as conn:  # one transaction for the whole payload
        existing = {name: bid for bid, name in conn.execute(select(Branch.id, Branch.name))}
        branch_ids: dict[str, int] = {}
        for link in payload.branches:
            if link.name in existing or link.name in branch_ids:
                raise StoreError(f"branch {link.name!r} already exists", hint="it was imported before; nothing was written")
            parent = branch_ids.get(link.parent or "", existing.get(link.parent or ""))
            if link.parent is not None and parent is None:
                raise StoreError(f"branch {link.name!r} needs parent branch {link.parent!r}, which is missing")
            branch_ids[link.name] = conn.execute(
                insert(Branch).values(name=link.name, parent_id=parent, fork_point=0, created_at=utc_now())
            ).inserted_primary_key[0]

        def branch_id(name: str) -> int:
            if name not in branch_ids:
                raise StoreError(f"the payload writes to branch {name!r}, which it does not create")
            return branch_ids[name]

        run_ids: dict[int, int] = {}
        for run in payload.runs:
            run_ids[run.id] = conn.execute(
                insert(Run).values(
                    command=run.command,
                    seed=run.seed,
                    config=dict(run.config),
                    branch=run.branch,
                    status=run.status,
                    started_at=_time(run.started_at),
                    finished_at=_time(run.finished_at),
                    **run_provenance_values(run.provenance),  # where the worker ran it
                )
            ).inserted_primary_key[0]
        episode_ids: dict[int, int] = {}
        for episode in payload.episodes:
            episode_ids[episode.id] = conn.execute(
                insert(Episode).values(
                    run_id=_need(run_ids, episode.run_id, "run"),
                    branch_id=branch_id(episode.branch),
                    scenario=episode.scenario,
                    condition=episode.condition,
                    model=episode.model,
                    measure=episode.measure,
                    seed=episode.seed,
                    status=episode.status,
                    summary={},
                    started_at=_time(episode.started_at),
                    finished_at=_time(episode.finished_at),
                )
            ).inserted_primary_key[0]
        snapshot_ids: dict[int, int] = {}
        if payload.snapshots:
            shas = [s.sha256 for s in payload.snapshots]
            found = dict(conn.execute(select(Snapshot.sha256, Snapshot.id).where(Snapshot.sha256.in_(shas))).all())
            for snap in payload.snapshots:
                if Store.snapshot_hash(snap.scene, snap.state) != snap.sha256:
                    raise StoreError(f"snapshot {snap.id} does not match its content hash", hint="the payload is corrupt")
                if snap.sha256 not in found:
                    found[snap.sha256] = conn.execute(
                        insert(Snapshot).values(
                            sha256=snap.sha256, scene=dict(snap.scene), state=bytes(snap.state), created_at=utc_now()
                        )
                    ).inserted_primary_key[0]
                snapshot_ids[snap.id] = found[snap.sha256]
        trials = sorted(payload.trials, key=lambda t: t.id)
        if trials:
            rows = [
                trial_row(
                    replace(
                        t,
                        run_id=_need(run_ids, t.run_id, "run"),
                        episode_id=_need(episode_ids, t.episode_id, "episode"),
                        snapshot_id=_need(snapshot_ids, t.snapshot_id, "snapshot"),
                    ),
                    branch_id=branch_id(t.branch),
                    created_at=_time(t.created_at) or utc_now(),
                )
                for t in trials
            ]
            new_ids = list(conn.execute(_INSERT_TRIALS, rows).scalars())
            seal_blocks(conn, [row["branch_id"] for row in rows], new_ids)
            for t, new in zip(trials, new_ids, strict=True):
                trial_ids.add(t.id, new)
        if payload.changes:
            carried = {t.id for t in trials}
            rows = []
            for change in payload.changes:
                if change.trial_id not in carried:
                    raise StoreError(f"the payload holds a change of trial {change.trial_id}, which it does not carry")
                rows.append(change_row(trial_ids.known[change.trial_id], change))
            conn.execute(insert(TrialChangeRow), rows)
        operator_ids: dict[int, int] = {}
        for op in payload.operators:
            operator_ids[op.id] = conn.execute(
                insert(Operator).values(
                    branch_id=branch_id(op.branch),
                    name=op.name,
                    pddl=op.pddl,
                    definition=dict(op.definition),
                    scenario=op.scenario,
                    episode_id=_need(episode_ids, op.episode_id, "episode"),
                    watermark=trial_ids.bound(op.watermark),
                    created_at=_time(op.created_at),
                )
            ).inserted_primary_key[0]
        if payload.executions:
            conn.execute(
                insert(OperatorExecution),
                [
                    {
                        "branch_id": branch_id(e.branch),
                        "operator": e.operator,
                        "success": bool(e.success),
                        "context": [list(atom) for atom in e.context],
                        "episode_id": _need(episode_ids, e.episode_id, "episode"),
                        "trial_id": _need(trial_ids.known, e.trial_id, "trial"),
                        "watermark": trial_ids.bound(e.watermark),
                        "created_at": _time(e.created_at) or utc_now(),
                    }
                    for e in payload.executions
                ],
            )
        for policy in payload.policies:
            if hashlib.sha256(policy.artifact).hexdigest() != policy.sha256:
                raise StoreError(f"the payload's policy {policy.id} does not match its checksum", hint="the payload is corrupt")
            conn.execute(
                insert(WorldModel).values(
                    branch_id=branch_id(policy.branch),
                    name=policy.name,
                    seed=policy.seed,
                    watermark=trial_ids.bound(policy.watermark),
                    artifact=bytes(policy.artifact),
                    sha256=policy.sha256,
                    meta=dict(policy.meta),
                    created_at=_time(policy.created_at) or utc_now(),
                )
            )
        for link in payload.branches:
            conn.execute(
                update(Branch).where(Branch.id == branch_ids[link.name]).values(fork_point=trial_ids.bound(link.fork_point))
            )
        own_trials = {t.id: trial_ids.known[t.id] for t in trials}
        maps = {"episodes": episode_ids, "runs": run_ids, "trials": own_trials}
        for episode in payload.episodes:
            conn.execute(
                update(Episode)
                .where(Episode.id == episode_ids[episode.id])
                .values(summary=_remap_summary(episode.summary, maps))
            )
    return IdMap(
        branches=branch_ids,
        trials=own_trials,
        runs=run_ids,
        episodes=episode_ids,
        snapshots=snapshot_ids,
        operators=operator_ids,
    )


def count_rows(payload: Payload) -> dict[str, int]:
    """How many rows of each kind a payload carries (for logs and tests)."""
    return {
        "branches": len(payload.branches),
        "runs": len(payload.runs),
        "episodes": len(payload.episodes),
        "snapshots": len(payload.snapshots),
        "trials": len(payload.trials),
        "changes": len(payload.changes),
        "operators": len(payload.operators),
        "executions": len(payload.executions),
        "policies": len(payload.policies),
    }


def inverse(mapping: Mapping[int, int]) -> dict[int, int]:
    """Destination id -> source id (the ids a worker sends back refer to the parent's store)."""
    return {v: k for k, v in mapping.items()}


__all__ = [
    "BranchLink",
    "IdMap",
    "Payload",
    "count_rows",
    "export_branches",
    "import_payload",
    "inverse",
]
