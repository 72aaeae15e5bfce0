"""The experiment runner: payload transfer, the smoke grid end to end, identical results for
any worker count and engine, resuming after kill -9, and the experiment commands."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from dataclasses import replace
from pathlib import Path
from typing import Any, Iterator

import pytest
from conftest import BACKENDS, POSTGRES_SKIP, fresh_postgres_url, new_store_url
from typer.testing import CliRunner

from llcps.cli.main import app
from llcps.domain import ACTIONS
from llcps.errors import LlcpsError, StoreError
from llcps.experiments.design import PAPER_SCENARIOS, Cell, Sequence, pretrain_branch_name
from llcps.experiments.presets import PRESETS
from llcps.analysis.results import ResultsTable
from llcps.experiments.rows import COLUMNS
from llcps.experiments.runner import (
    PretrainTask,
    SequenceTask,
    make_engine,
    plan_tasks,
    pretrain_subset,
    run_experiment,
)
from llcps.analysis.selection import results_table
from llcps.experiments.transfer import count_rows, export_branches, import_payload, inverse
from llcps.store import Store
from llcps.store import physics_cache

SMOKE = PRESETS["smoke"]


# -- what a store holds, without ids or clocks -----------------------------------------------
def trial_key(t: Any) -> tuple:
    return (t.source, t.scenario, t.spec, t.features, t.outcome.bits(), t.solved, t.sim_steps, t.seed, dict(t.extra))


def store_signature(store: Store, prefix: str = "exp-") -> dict[str, dict[str, Any]]:
    """Per experiment branch: its own trials, episodes, operators and what it sees (ids left out)."""
    out: dict[str, dict[str, Any]] = {}
    for info in store.list_branches():
        if not info.name.startswith(prefix):
            continue
        visible = store.visible_trials(info.name)
        episodes = sorted(store.list_episodes(branch=info.name), key=lambda e: e.id)
        out[info.name] = {
            "parent": info.parent,
            "own": [trial_key(t) for t in visible if t.branch == info.name],
            "seen_at_fork": [trial_key(t) for t in visible if t.branch != info.name],
            "episodes": [
                (e.scenario, e.seed, e.status, *(e.summary.get(k) for k in ("exploration_trials", "plan_trials", "sim_steps")))
                for e in episodes
            ],
            "operators": [(o.name, o.pddl, o.scenario) for o in store.visible_operators(info.name) if o.branch == info.name],
        }
    return out


def table_key(table: ResultsTable) -> list[tuple]:
    return [(r.key, r.branch, r.solved, r.exploration_trials, r.sim_seconds) for r in table]


# -- tasks and pretraining subsets (no simulation) -------------------------------------------
def test_tasks_cover_the_grid_and_never_share_a_branch() -> None:
    preset = PRESETS["paper"]
    tasks = plan_tasks(preset, 3)
    pretraining = [t for t in tasks if isinstance(t, PretrainTask)]
    sequences = [t for t in tasks if isinstance(t, SequenceTask)]
    assert [t.seed for t in pretraining] == [0, 1, 2]
    assert {t.sequence for t in sequences} == set(preset.sequences(3))
    branches = [b for t in tasks for b in t.branches]
    assert len(branches) == len(set(branches))
    # A seed's pretraining comes before its sequences, which read its branches.
    for i, task in enumerate(tasks):
        if isinstance(task, SequenceTask):
            producer = next(j for j, t in enumerate(tasks) if task.pretrain_branch in t.branches)
            assert producer < i and task.budget == preset.exploration_budget()


def test_pretraining_subset_takes_one_trial_per_action_deterministically(store: Store, new_trial) -> None:
    store.create_branch("pool", from_branch="main", at=0)
    store.add_trials([new_trial(i, branch="pool") for i in range(40)])
    pool = store.visible_trials("pool")
    assert {t.spec.action for t in pool} == set(ACTIONS)
    four = pretrain_subset(pool, 4, seed=3)
    assert sorted(t.spec.action for t in four) == sorted(ACTIONS)
    assert [t.id for t in four] == sorted(t.id for t in four)  # the pool's order
    assert [t.id for t in pretrain_subset(pool, 4, seed=3)] == [t.id for t in four]
    assert len({tuple(t.id for t in pretrain_subset(pool, 4, seed=s)) for s in range(6)}) > 1
    assert pretrain_subset(pool, 40, seed=3) == pool
    six = pretrain_subset(pool, 6, seed=0)
    assert len(six) == 6 and all(sum(t.spec.action == a for t in six) in (1, 2) for a in ACTIONS)


# -- transfer: export and import round-trip -----------------------------------------------------
def _source_store(store: Store, new_trial) -> dict[str, Any]:
    """base (pretraining, shared snapshot) <- child (a run, an episode, trials, an operator)."""
    store.create_branch("base", from_branch="main", at=0)
    shared = store.put_snapshot(scene={"name": "shared"}, state=b"\x01" * 64)
    own = store.put_snapshot(scene={"name": "own"}, state=b"\x02" * 64)
    store.add_trials([new_trial(i, branch="base", snapshot_id=shared if i % 2 else own) for i in range(6)])
    store.create_branch("child", from_branch="base")
    run = store.start_run(command="solve", seed=7, config={"budget": 5}, branch="child")
    episode = store.start_episode(run_id=run, branch="child", scenario="scenario1", condition="novelty", model="nb", measure="most-changes", seed=7)
    child_ids = store.add_trials(
        [new_trial(100 + i, branch="child", source="exploration", run_id=run, episode_id=episode, snapshot_id=shared) for i in range(3)]
    )
    store.add_operator(branch="child", name="op", pddl="(:action op)", definition={"k": 1}, scenario="scenario1", episode_id=episode)
    # Plan steps' executions cost K's operators on the branch: they travel with it.
    context = [["near", "?o", "?c"], ["visible", "?o"]]
    store.add_operator_execution(branch="child", operator="push", success=False, context=context, episode_id=episode, trial_id=child_ids[0])
    store.add_operator_execution(branch="child", operator="push", success=True, context=context, episode_id=episode, trial_id=child_ids[1])
    store.finish_episode(episode, status="solved", summary={"episode_id": episode, "run_id": run, "resolving_trial_id": child_ids[-1], "exploration_trials": 3})
    store.finish_run(run, status="solved")
    return {"run": run, "episode": episode, "child_ids": child_ids}


@pytest.fixture(params=BACKENDS)
def dest_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """A new, empty store's URL: a SQLite file, or a fresh PostgreSQL schema."""
    return new_store_url(request.param, tmp_path, "dest.db")


def test_payload_round_trip_remaps_ids_and_dedups_snapshots(store: Store, dest_url: str, new_trial) -> None:
    _source_store(store, new_trial)
    payload = export_branches(store, ["base", "child"])
    assert count_rows(payload) == {
        "branches": 2, "runs": 1, "episodes": 1, "snapshots": 2, "trials": 9, "operators": 1, "changes": 0, "executions": 2, "policies": 0
    }  # fmt: skip
    with Store.open(dest_url, create=True) as dest:
        # Ids in the destination start elsewhere, and one snapshot is there already.
        dest.create_branch("other", from_branch="main", at=0)
        dest.add_trials([new_trial(1000 + i, branch="other") for i in range(5)])
        dest.put_snapshot(scene={"name": "shared"}, state=b"\x01" * 64)
        ids = import_payload(dest, payload)
        assert store_signature(dest, "")["child"] == store_signature(store, "")["child"]
        assert store_signature(dest, "")["base"] == store_signature(store, "")["base"]
        moved = dest.visible_trials("child")
        assert [t.id for t in moved] == sorted(t.id for t in moved) and min(t.id for t in moved) > 5
        assert len({t.snapshot_id for t in moved}) == 2  # the shared snapshot was reused, not copied
        assert dest.get_snapshot(moved[0].snapshot_id).state in (b"\x01" * 64, b"\x02" * 64)
        op = dest.visible_operators("child")[0]
        assert op.watermark == max(t.id for t in moved) and op.episode_id == ids.episodes[payload.episodes[0].id]
        episode = dest.list_episodes(branch="child")[0]
        assert episode.summary["episode_id"] == episode.id and episode.run_id == episode.summary["run_id"]
        assert episode.summary["resolving_trial_id"] == max(t.id for t in moved)
        assert {t.run_id for t in moved if t.branch == "child"} == {episode.run_id}
        assert dest.operator_experience("child") == store.operator_experience("child") != []
        assert dest.operator_experience("base") == []
        executions = dest.own_operator_executions("child")
        assert [e.trial_id for e in executions] == [t.id for t in moved if t.branch == "child"][:2]
        assert {e.episode_id for e in executions} == {episode.id}
        assert all(e.watermark == max(t.id for t in moved) for e in executions)
        # A second import writes nothing at all: the transaction is all or nothing.
        before = dest.status().trials_total
        with pytest.raises(StoreError, match="already exists"):
            import_payload(dest, payload)
        assert dest.status().trials_total == before and len(dest.list_episodes()) == 1


def test_payload_seeds_a_private_store_and_comes_back_onto_the_original_ids(store: Store, tmp_path: Path, new_trial) -> None:
    _source_store(store, new_trial)
    base = export_branches(store, ["base"], snapshots=False, provenance=False)
    assert base.snapshots == () and all(t.snapshot_id is None and t.run_id is None for t in base.trials)
    with Store.open(str(tmp_path / "private.db"), create=True) as private:
        private.create_branch("filler", from_branch="main", at=0)
        private.add_trials([new_trial(500 + i, branch="filler") for i in range(10)])  # private ids differ
        seeded = import_payload(private, base)
        private.create_branch("work", from_branch="base")
        private.add_trials([new_trial(900 + i, branch="work", source="exploration") for i in range(2)])
        private.add_operator(branch="work", name="w", pddl="(w)", definition={}, scenario=None, episode_id=None)
        private.add_operator_execution(branch="work", operator="w", success=True, context=[["visible", "?o"]])
        back = export_branches(private, ["work"], external=inverse(seeded.trials))
    import_payload(store, back)
    work = store.visible_trials("work")
    assert [trial_key(t) for t in work] == [trial_key(t) for t in store.visible_trials("base")] + [
        trial_key(t) for t in back.trials
    ]
    assert store.resolve_branch("work").fork_point == max(t.id for t in store.visible_trials("base"))
    assert store.visible_operators("work")[0].watermark == max(t.id for t in work)
    assert [(c.operator, c.successes, c.failures) for c in store.operator_experience("work")] == [("w", 1, 0)]


def _policy_file(path: Path) -> Path:
    """An untrained policy in the file format `llcps rl train --out` writes."""
    from llcps.cps.policy import DEFAULT_HIDDEN, export_policy, new_policy, write_policy_file

    torch = pytest.importorskip("torch")
    torch.manual_seed(0)
    artifact = export_policy(new_policy(DEFAULT_HIDDEN), hidden=DEFAULT_HIDDEN, info={"budget": 5, "timesteps": 0})
    path.write_bytes(write_policy_file(artifact))
    return path


def test_a_workers_seed_carries_the_policy_its_branch_sees(store: Store, store_url: str, tmp_path: Path, new_trial) -> None:
    pytest.importorskip("sb3_contrib")
    from llcps.cps.policy import POLICY_NAME

    _source_store(store, new_trial)
    result = CliRunner().invoke(app, ["--db", store_url, "--branch", "main", "rl", "import", str(_policy_file(tmp_path / "p.npz"))])
    assert result.exit_code == 0, result.output
    stored = store.latest_world_model("base", POLICY_NAME, 0)  # on main, seen from base
    assert stored is not None and stored.branch == "main"
    assert export_branches(store, ["base"]).policies == ()  # only a worker's seed asks for it
    base = export_branches(store, ["base"], snapshots=False, provenance=False, policies=True)
    assert count_rows(base)["policies"] == 1
    with Store.open(str(tmp_path / "private.db"), create=True) as private:
        private.create_branch("filler", from_branch="main", at=0)
        private.add_trials([new_trial(500 + i, branch="filler") for i in range(3)])  # private ids differ
        import_payload(private, base)
        private.create_branch("work", from_branch="base")
        carried = private.latest_world_model("work", POLICY_NAME, 0)
        assert carried is not None and carried.branch == "base" and carried.artifact == stored.artifact
        assert carried.meta == stored.meta and carried.watermark <= private.resolve_branch("work").fork_point
    # A damaged payload is refused whole.
    broken = replace(base, policies=(replace(base.policies[0], artifact=base.policies[0].artifact[:-1]),))
    with Store.open(str(tmp_path / "other.db"), create=True) as other, pytest.raises(StoreError, match="checksum"):
        import_payload(other, broken)
    with Store.open(str(tmp_path / "other.db")) as other:
        assert "base" not in other.branch_names()


@pytest.mark.parametrize(
    ("content", "error"),
    [(b"not a zip", "not an array archive"), (None, "no policy file")],
)
def test_rl_import_refuses_what_is_not_a_policy_and_stores_nothing(
    store: Store, store_url: str, tmp_path: Path, content: bytes | None, error: str
) -> None:
    pytest.importorskip("sb3_contrib")
    from llcps.cps.policy import POLICY_NAME

    path = tmp_path / "p.npz"
    if content is not None:
        path.write_bytes(content)
    result = CliRunner().invoke(app, ["--db", store_url, "rl", "import", str(path)])
    assert result.exit_code == 2 and error in result.output and "Traceback" not in result.output
    assert store.latest_world_model("main", POLICY_NAME, 0) is None


# -- the smoke grid, run for real -------------------------------------------------------------
@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Store, Any]]:
    """The smoke grid on one local worker: the run every other run must reproduce."""
    path = tmp_path_factory.mktemp("reference") / "ref.db"
    with Store.open(str(path), create=True) as store:
        summary = run_experiment(store, preset="smoke", workers=1)
        yield store, summary


def test_smoke_grid_runs_end_to_end_into_a_well_formed_table(reference: tuple[Store, Any], tmp_path: Path) -> None:
    store, summary = reference
    assert summary.status == "ok" and summary.done == summary.tasks == SMOKE.default_seeds * (1 + len(SMOKE.cells()))
    table = results_table(store, "smoke")
    sequences = set(SMOKE.sequences())
    assert len(table) == len(sequences) * len(PAPER_SCENARIOS)
    assert table.complete_sequences() == sequences and table.missing(SMOKE.sequences()) == ()
    assert ResultsTable.read_csv(table.write_csv(tmp_path / "t.csv")) == table
    for row in table:
        assert set(row.__dict__) == set(COLUMNS)
        assert 0 <= row.exploration_trials <= SMOKE.budget and row.sim_seconds > 0
        assert row.branch == row.sequence.episode_branch(row.scenario)
    for seed in range(SMOKE.default_seeds):
        pretraining = store.visible_trials(pretrain_branch_name("smoke", 4, seed))
        assert len(pretraining) == 4 and {t.source for t in pretraining} == {"pretrain"}
        assert all(t.snapshot_id is not None for t in pretraining)  # replayable
    for seq in SMOKE.sequences():
        fork = max(t.id for t in store.visible_trials(seq.pretrain_branch))
        for scenario in PAPER_SCENARIOS:
            info = store.resolve_branch(seq.episode_branch(scenario))
            assert info.parent == seq.pretrain_branch and info.fork_point == fork
            (episode,) = [e for e in store.list_episodes(branch=info.name) if e.scenario == scenario]
            assert episode.seed == seq.seed and episode.status in ("solved", "budget_exhausted")
    # update: one branch holds all three scenarios; reset: each scenario saw only the pretraining set
    update = Sequence("smoke", Cell("nb", "most-changes", 4, "update"), 0)
    assert len(store.list_episodes(branch=update.branch_name)) == 3


@pytest.mark.slow
def test_results_are_identical_with_two_workers(reference: tuple[Store, Any], tmp_path: Path) -> None:
    ref_store, _ = reference
    with Store.open(str(tmp_path / "two.db"), create=True) as store:
        summary = run_experiment(store, preset="smoke", workers=2)
        assert summary.status == "ok" and summary.workers == 2
        assert table_key(results_table(store, "smoke")) == table_key(results_table(ref_store, "smoke"))
        assert store_signature(store) == store_signature(ref_store)


@pytest.mark.postgresql
@pytest.mark.skipif(POSTGRES_SKIP is not None, reason=POSTGRES_SKIP or "")
def test_a_grid_run_into_postgresql_stores_what_sqlite_does(reference: tuple[Store, Any]) -> None:
    """One seed of the smoke grid, two workers, imported into PostgreSQL: the SQLite run's rows."""
    ref_store, _ = reference
    with Store.open(fresh_postgres_url(), create=True) as store:
        summary = run_experiment(store, preset="smoke", seeds=[0], workers=2)
        assert summary.status == "ok"
        expected = {k: v for k, v in store_signature(ref_store).items() if k.endswith("-s0") or "-s0-" in k}
        assert store_signature(store) == expected
        assert table_key(results_table(store, "smoke")) == table_key(results_table(ref_store, "smoke", [0]))


@pytest.mark.slow
def test_results_are_identical_without_the_cache_and_from_a_warm_one(reference: tuple[Store, Any], tmp_path: Path) -> None:
    """The reference ran with a cold cache; --no-cache and a later run on a warm cache give the same store."""
    ref_store, ref_summary = reference
    assert ref_summary.cache is not None and ref_summary.cache["stored"] > 0
    with Store.open(str(tmp_path / "plain.db"), create=True) as store:
        summary = run_experiment(store, preset="smoke", workers=1, cache=False)
        assert summary.status == "ok" and summary.cache is None and physics_cache.status(store).entries == 0
        assert table_key(results_table(store, "smoke")) == table_key(results_table(ref_store, "smoke"))
        assert store_signature(store) == store_signature(ref_store)
    warm_db = tmp_path / "warm.db"
    with Store.open(str(warm_db), create=True):
        pass
    with closing(sqlite3.connect(warm_db)) as conn, conn:  # the reference's cache, as a later run finds it
        conn.execute("ATTACH DATABASE ? AS ref", (ref_store.url.split("///", 1)[1],))
        conn.execute("INSERT INTO physics_cache SELECT * FROM ref.physics_cache")
    with Store.open(str(warm_db)) as store:
        summary = run_experiment(store, preset="smoke", workers=2)
        assert summary.status == "ok" and summary.cache == {**summary.cache, "misses": 0, "stored": 0}
        assert table_key(results_table(store, "smoke")) == table_key(results_table(ref_store, "smoke"))
        assert store_signature(store) == store_signature(ref_store)
        sequence_trials = [t for t in store.visible_trials(None) if t.source != "pretrain"]
        episode_trials = [
            t for info in store.list_branches() if "-pretrain-" not in info.name and info.name.startswith("exp-")
            for t in store.visible_trials(info.name) if t.branch == info.name
        ]
        assert not sequence_trials and episode_trials and all(t.cache_hit for t in episode_trials)
        assert summary.cache["hits"] == len(episode_trials)


@pytest.mark.slow
def test_ray_engine_gives_the_local_engine_results(reference: tuple[Store, Any], tmp_path: Path) -> None:
    pytest.importorskip("ray", reason="Ray is not installed (pip install 'llcps[ray]')")
    ref_store, _ = reference
    ray_db = tmp_path / "ray.db"
    with Store.open(str(ray_db), create=True):
        pass
    # The reference's physics cache, so the Ray workers replay its trials instead of
    # simulating them (the results are the same either way): the test is Ray's, not physics'.
    with closing(sqlite3.connect(ray_db)) as conn, conn:
        conn.execute("ATTACH DATABASE ? AS ref", (ref_store.url.split("///", 1)[1],))
        conn.execute("INSERT INTO physics_cache SELECT * FROM ref.physics_cache")
    with Store.open(str(ray_db)) as store:
        summary = run_experiment(store, preset="smoke", workers=2, engine="ray")
        assert summary.status == "ok" and summary.engine == "ray"
        assert table_key(results_table(store, "smoke")) == table_key(results_table(ref_store, "smoke"))
        assert store_signature(store) == store_signature(ref_store)


def _ray_cluster_run(store: Store, *, kill: bool, seeds: list[int] | None = None) -> tuple[Any, list[str]]:
    """The smoke grid on a local two-node Ray cluster (a head and a worker node, one CPU
    each); with ``kill``, the worker node is killed as soon as a task runs on it, and the
    head runs the rest. Returns the summary and what happened to the nodes."""
    import threading

    import ray
    from ray._private import ray_constants
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    worker = cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="WARNING")
    events: list[str] = []
    done = threading.Event()

    def running_a_task() -> bool:
        """Whether a worker process of the worker node runs a task (Ray titles it ``ray::<function>``)."""
        raylet = worker.all_processes[ray_constants.PROCESS_TYPE_RAYLET][0].process.pid
        for pid in _children(raylet):
            try:
                title = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0]
            except OSError:
                continue
            if title.startswith(b"ray::execute_task"):
                return True
        return False

    def killer() -> None:
        while not done.is_set():
            if running_a_task():
                time.sleep(1.0)  # well into the task
                if running_a_task():
                    cluster.remove_node(worker, allow_graceful=False)
                    events.append("killed the worker node with a task in flight")
                    return
            time.sleep(0.05)

    thread = threading.Thread(target=killer, daemon=True)
    try:
        if kill:
            thread.start()
        summary = run_experiment(store, preset="smoke", seeds=seeds, workers=2, engine="ray")
        if kill:
            events.append("the run finished")
        return summary, events
    finally:
        done.set()
        if kill:
            thread.join(timeout=60)
        ray.shutdown()
        cluster.shutdown()


@pytest.mark.slow
@pytest.mark.parametrize("kill", [False, True], ids=["steady", "killed-node"])
def test_a_multi_node_ray_cluster_gives_the_local_engine_results(
    reference: tuple[Store, Any], tmp_path: Path, kill: bool
) -> None:
    """A head and a second node with its own CPU, on SQLite; a node killed mid-run loses
    only its task in flight, which Ray runs again elsewhere."""
    pytest.importorskip("ray", reason="Ray is not installed (pip install 'llcps[ray]')")
    ref_store, _ = reference
    ray_db = tmp_path / "cluster.db"
    with Store.open(str(ray_db), create=True):
        pass
    with closing(sqlite3.connect(ray_db)) as conn, conn:  # replay the reference's physics (see above)
        conn.execute("ATTACH DATABASE ? AS ref", (ref_store.url.split("///", 1)[1],))
        conn.execute("INSERT INTO physics_cache SELECT * FROM ref.physics_cache")
    with Store.open(str(ray_db)) as store:
        summary, events = _ray_cluster_run(store, kill=kill)
        assert summary.status == "ok" and summary.engine == "ray" and summary.done == summary.tasks
        if kill:  # the task in flight on the dead node ran again on the head
            assert events == ["killed the worker node with a task in flight", "the run finished"]
        assert table_key(results_table(store, "smoke")) == table_key(results_table(ref_store, "smoke"))
        assert store_signature(store) == store_signature(ref_store)


@pytest.mark.slow
@pytest.mark.skipif(POSTGRES_SKIP is not None, reason=POSTGRES_SKIP or "")
def test_a_multi_node_ray_cluster_with_a_killed_node_fills_a_postgresql_store(reference: tuple[Store, Any]) -> None:
    """One seed of the smoke grid on the two-node cluster into PostgreSQL, a node killed mid-run."""
    pytest.importorskip("ray", reason="Ray is not installed (pip install 'llcps[ray]')")
    ref_store, _ = reference
    with Store.open(fresh_postgres_url(), create=True) as store:
        summary, events = _ray_cluster_run(store, kill=True, seeds=[0])
        assert summary.status == "ok" and events == ["killed the worker node with a task in flight", "the run finished"]
        expected = {k: v for k, v in store_signature(ref_store).items() if k.endswith("-s0") or "-s0-" in k}
        assert store_signature(store) == expected
        assert table_key(results_table(store, "smoke")) == table_key(results_table(ref_store, "smoke", [0]))


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _has_branch(db: Path, name: str) -> bool:
    try:  # the file may still be being created by the run
        with Store.open(str(db)) as store:
            return name in {b.name for b in store.list_branches()}
    except StoreError:
        return False


def _llcps(*args: str) -> list[str]:
    return [sys.executable, "-m", "llcps.cli.main", *args]


@pytest.mark.slow
def test_kill_9_then_run_again_completes_without_duplicates(reference: tuple[Store, Any], tmp_path: Path) -> None:
    ref_store, _ = reference
    db, out = tmp_path / "killed.db", tmp_path / "report"
    args = ("--db", str(db), "experiment", "run", "--preset", "smoke", "--seeds", "1", "--workers", "1", "--out", str(out), "--create")
    first = pretrain_branch_name("smoke", 4, 0)
    child = subprocess.Popen(_llcps(*args), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 240
        while True:  # wait until the first task (the seed's pretraining) is imported
            assert child.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline, "the first task was never imported"
            if _has_branch(db, first):
                break
            time.sleep(0.2)
        workers = _children(child.pid)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.kill()
        child.wait()
    deadline = time.monotonic() + 30
    while any(_alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(_alive(p) for p in workers), "workers outlived the killed run"

    done = subprocess.run(_llcps(*args, "--json"), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    data = json.loads(done.stdout)
    assert data["run"]["tasks_skipped"] >= 1 and data["run"]["tasks_skipped"] + data["run"]["tasks_done"] == 3
    assert data["figure2"] and (out / "report.md").exists()
    with Store.open(str(db)) as store:
        ours = store_signature(store)
        expected = {k: v for k, v in store_signature(ref_store).items() if k.endswith("-s0") or "-s0-" in k}
        assert ours == expected  # each branch once, with exactly the uninterrupted run's trials
        assert len(store.list_episodes()) == 2 * len(PAPER_SCENARIOS)


def test_rerun_skips_every_stored_task(reference: tuple[Store, Any]) -> None:
    store, _ = reference
    before = store_signature(store)
    summary = run_experiment(store, preset="smoke", workers=2)
    assert (summary.done, summary.skipped, summary.status) == (0, summary.tasks, "ok")
    assert store_signature(store) == before


def test_a_run_in_another_ordering_is_refused_where_the_grid_is_stored(reference: tuple[Store, Any]) -> None:
    """Branch names do not say the ordering: a run in another ordering would skip every
    stored sequence and report the stored ordering's episodes as its own."""
    store, _ = reference
    before = store_signature(store)
    with pytest.raises(LlcpsError, match="explored in the 'ranked' ordering") as refused:
        run_experiment(store, preset="smoke", ordering="hedged")
    assert "store of its own" in (refused.value.hint or "")
    assert store_signature(store) == before
    db = store.url.split("///", 1)[1]
    result = CliRunner().invoke(app, ["--db", db, "experiment", "run", "--preset", "smoke", "--ordering", "hedged"])
    assert result.exit_code == 2 and "Traceback" not in result.output and "'ranked' ordering" in result.output
    assert store_signature(store) == before


def test_the_rl_ordering_runs_a_grid_with_the_policy_of_each_pretraining_branch(reference: tuple[Store, Any], tmp_path: Path) -> None:
    """Seed 0's sequences again, exploring in the rl ordering with a policy stored on its
    pretraining branch; first refused while that branch holds none."""
    pytest.importorskip("sb3_contrib")
    ref_store, _ = reference
    path = tmp_path / "rl.db"
    with closing(sqlite3.connect(ref_store.engine.url.database)) as src, closing(sqlite3.connect(path)) as dst:
        src.backup(dst)
    sequences = [t for t in plan_tasks(SMOKE, [0]) if isinstance(t, SequenceTask)]
    with Store.open(str(path)) as store:
        for task in sequences:
            for branch in reversed(task.branches):
                store.delete_branch(branch, dry_run=False)
        pretraining = {t.pretrain_branch for t in sequences}
        with pytest.raises(LlcpsError, match="needs a trained policy on every pretraining branch") as refused:
            run_experiment(store, preset="smoke", seeds=[0], ordering="rl")
        assert "rl import" in (refused.value.hint or "")
        assert not any(b in store.branch_names() for t in sequences for b in t.branches)  # nothing ran
        for branch in sorted(pretraining):
            result = CliRunner().invoke(app, ["--db", str(path), "--branch", branch, "rl", "import", str(_policy_file(tmp_path / "p.npz"))])
            assert result.exit_code == 0, result.output
        summary = run_experiment(store, preset="smoke", seeds=[0], ordering="rl")
        assert (summary.status, summary.done) == ("ok", len(sequences))
        episodes = [e for t in sequences for b in t.branches for e in store.list_episodes(branch=b)]
        assert episodes and {e.summary["ordering"] for e in episodes} == {"rl"}


def test_a_task_with_only_some_branches_is_refused(store: Store) -> None:
    seq = SMOKE.sequences(1)[1]
    assert seq.cell.condition == "reset"
    store.create_branch(seq.episode_branch("scenario2"), from_branch="main", at=0)
    with pytest.raises(LlcpsError, match="only some of their branches"):
        run_experiment(store, preset="smoke", seeds=1)


# -- the commands -------------------------------------------------------------------------------
def test_report_rebuilds_from_a_directory_and_from_the_store(reference: tuple[Store, Any], tmp_path: Path) -> None:
    store, _ = reference
    db = store.url.split("///", 1)[1]
    runner = CliRunner()
    from_db = runner.invoke(app, ["--db", db, "experiment", "report", "--from-db", "--out", str(tmp_path / "a"), "--json"])
    assert from_db.exit_code == 0, from_db.output
    data = json.loads(from_db.stdout)
    assert data["overview"]["rows"] == len(SMOKE.sequences()) * 3
    assert {(r["scenario"], r["n_seeds"]) for r in data["figure2"]} == {(s, SMOKE.default_seeds) for s in PAPER_SCENARIOS}
    again = runner.invoke(app, ["experiment", "report", str(tmp_path / "a"), "--out", str(tmp_path / "b"), "--json"])
    assert again.exit_code == 0, again.output
    assert json.loads(again.stdout)["figure2"] == data["figure2"]
    assert (tmp_path / "b" / "results.csv").read_text() == (tmp_path / "a" / "results.csv").read_text()
    # where the runs ran travels with the results into the new directory
    assert json.loads((tmp_path / "b" / "provenance.json").read_text()) == json.loads((tmp_path / "a" / "provenance.json").read_text())
    assert json.loads((tmp_path / "a" / "provenance.json").read_text())  # the store recorded its runs
    text = runner.invoke(app, ["experiment", "report", str(tmp_path / "a")])
    assert text.exit_code == 0 and "scenario3" in text.stdout


def test_report_takes_the_random_baseline_from_another_preset(reference: tuple[Store, Any], tmp_path: Path) -> None:
    from dataclasses import replace

    db = reference[0].url.split("///", 1)[1]
    runner = CliRunner()
    assert runner.invoke(app, ["--db", db, "experiment", "report", "--from-db", "--out", str(tmp_path / "a")]).exit_code == 0
    smoke = ResultsTable.read(tmp_path / "a" / "results.csv")
    baseline = [
        replace(
            row,
            preset="random",
            model="random",
            condition="reset",
            exploration_trials=row.exploration_trials + 100,
            branch=Sequence("random", Cell("random", row.measure, row.pretrain_size, "reset"), row.seed).episode_branch(row.scenario),
        )
        for row in smoke.filter(condition="reset")
    ]
    ResultsTable([*smoke, *baseline]).write_csv(tmp_path / "both.csv")
    result = runner.invoke(
        app, ["experiment", "report", str(tmp_path / "both.csv"), "--preset", "smoke", "--baseline-preset", "random",
              "--out", str(tmp_path / "c"), "--json"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert {r["model"] for r in data["random_comparison"]} == {"nb"}
    best = data["best_versus_random"]
    assert sorted(r["scenario"] for r in best) == sorted(PAPER_SCENARIOS)
    assert all(r["condition"] == "reset" and r["median_model"] < r["median_random"] for r in best)
    assert "The best model x measure per scenario" in (tmp_path / "c" / "report.md").read_text()
    missing = runner.invoke(app, ["experiment", "report", str(tmp_path / "a"), "--baseline-preset", "random"])
    assert missing.exit_code == 2 and "no random-model results of preset 'random'" in missing.stderr


@pytest.mark.parametrize(
    "argv, error",
    [
        (["experiment", "report"], "no results directory given"),  # and results/paper holds none
        (["experiment", "report", "--from-db", "--preset", "paper"], "no results of preset 'paper'"),
        (["experiment", "run", "--preset", "smoke", "--engine", "local", "--ray-address", "auto"], "--ray-address needs --engine ray"),
    ],
)
def test_bad_experiment_input_is_one_error_line(reference: tuple[Store, Any], argv: list[str], error: str) -> None:
    db = reference[0].url.split("///", 1)[1]
    result = CliRunner().invoke(app, ["--db", db, *argv])
    assert result.exit_code == 2 and error in result.stderr and "Traceback" not in result.output


def test_ray_engine_without_ray_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(LlcpsError) as info:
        make_engine("ray", 2)
    assert info.value.hint == "pip install 'llcps[ray]'" and "not installed" in info.value.message


class _RecordingEngine:
    """Finishes every task at once with an error; remembers the order tasks were submitted in."""

    name, workers = "recording", 2

    def __init__(self, past_first_scenario: set[str] = frozenset()) -> None:  # type: ignore[assignment]
        self.submitted: list[str] = []
        self.past = set(past_first_scenario)

    def submit(self, task: Any) -> str:
        self.submitted.append(task.label)
        return task.label

    def past_first_scenario(self) -> set[str]:
        return set(self.past)

    def wait(self, handles: Any, timeout: float) -> list[str]:
        return list(handles)[:1]

    def result(self, handle: str) -> Any:
        raise RuntimeError("not run")

    def close(self, *, abort: bool, pending: Any = ()) -> None:
        pass


def test_the_scheduler_keeps_twins_apart(store: Store) -> None:
    from llcps.experiments.scheduler import RunSummary, schedule

    tasks = [t for t in plan_tasks(SMOKE, 2) if isinstance(t, SequenceTask)]  # s0 update, s0 reset, s1 update, s1 reset
    for name in {t.pretrain_branch for t in tasks}:
        store.create_branch(name, from_branch="main", at=0)
    engine = _RecordingEngine()
    summary = RunSummary(preset="smoke", seeds=(0, 1), engine="recording", workers=2)
    schedule(store, engine, tasks, {b.name for b in store.list_branches()}, summary, {}, None)
    # the two sequences of seed 0 would simulate scenario 1 side by side: seed 1's goes second
    assert engine.submitted[:2] == [tasks[0].label, tasks[2].label]
    assert sorted(engine.submitted) == sorted(t.label for t in tasks) and len(summary.failed) == 4


def test_a_twin_past_its_first_scenario_no_longer_holds_back_the_other(store: Store) -> None:
    """Seed 0's update has finished scenario 1 (its trials are in the physics cache): its
    reset may start beside it, ahead of seed 1's update."""
    from llcps.experiments.scheduler import RunSummary, schedule

    tasks = [t for t in plan_tasks(SMOKE, 2) if isinstance(t, SequenceTask)]  # s0 update, s0 reset, s1 update, s1 reset
    for name in {t.pretrain_branch for t in tasks}:
        store.create_branch(name, from_branch="main", at=0)
    engine = _RecordingEngine(past_first_scenario={tasks[0].label})
    summary = RunSummary(preset="smoke", seeds=(0, 1), engine="recording", workers=2)
    schedule(store, engine, tasks, {b.name for b in store.list_branches()}, summary, {}, None)
    assert engine.submitted[:2] == [tasks[0].label, tasks[1].label]


@pytest.mark.slow
def test_a_local_worker_reports_the_end_of_a_sequences_first_scenario(reference: tuple[Store, Any]) -> None:
    """What the scheduler reads to let a twin start: reported by a real pool worker."""
    from dataclasses import replace

    from llcps.experiments.executors import LocalEngine

    ref_store, _ = reference
    task = next(t for t in plan_tasks(SMOKE, 1) if isinstance(t, SequenceTask))
    task = replace(task, base=export_branches(ref_store, [task.pretrain_branch], snapshots=False, provenance=False))
    engine = LocalEngine(1)
    try:
        assert engine.past_first_scenario() == set()
        handle = engine.submit(task)
        assert engine.wait([handle], timeout=300) == [handle]
        assert engine.result(handle).label == task.label
        assert engine.past_first_scenario() == {task.label}
        assert len(engine.worker_pids()) == 1
    finally:
        engine.close(abort=False)


class _ImportingEngine(_RecordingEngine):
    """Finishes the newest task first, each successfully (the scheduler's import is faked)."""

    def wait(self, handles: Any, timeout: float) -> list[str]:
        return list(handles)[-1:]

    def result(self, handle: str) -> Any:
        from llcps.experiments.tasks import TaskOutput

        return TaskOutput(handle, payload=None, wall_seconds=0.0)  # type: ignore[arg-type]


def test_a_pretraining_being_imported_is_waited_for_rather_than_running_a_twin(
    store: Store, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Seed 1's pretraining finishes while seed 0's update runs: before its import only seed 0's
    reset (a twin) is ready; the scheduler waits for the import and starts seed 1's update."""
    from llcps.experiments import scheduler

    planned = plan_tasks(SMOKE, 2)
    for name in [t for t in planned if isinstance(t, PretrainTask) and t.seed == 0][0].branches:
        store.create_branch(name, from_branch="main", at=0)
    tasks = [t for t in planned if not (isinstance(t, PretrainTask) and t.seed == 0)]  # U0, R0, P1, U1, R1

    def fake_import(store_: Store, payload: Any, task: Any) -> bool:
        for name in task.branches:
            store_.create_branch(name, from_branch="main", at=0)
        return True

    monkeypatch.setattr(scheduler, "_import", fake_import)
    monkeypatch.setattr(scheduler, "export_branches", lambda *a, **k: None)
    engine = _ImportingEngine()
    summary = scheduler.RunSummary(preset="smoke", seeds=(0, 1), engine="importing", workers=2)
    scheduler.schedule(store, engine, tasks, {b.name for b in store.list_branches()}, summary, {}, None)
    u0, r0, p1, u1, r1 = tasks
    assert engine.submitted[:3] == [u0.label, p1.label, u1.label]  # not r0, which would repeat u0's physics
    assert sorted(engine.submitted) == sorted(t.label for t in tasks) and summary.done == 5 and not summary.failed


# -- scene variants, paired with seeds ----------------------------------------------------------
def test_variant_sequences_name_their_variant_and_parse_back() -> None:
    from llcps.experiments.design import parse_branch

    sequences = SMOKE.sequences([0, 3], variants=True)
    assert {(s.seed, s.variant) for s in sequences} == {(0, 0), (3, 3)}
    for seq in sequences:
        assert seq.branch_name.endswith("-s3-v3" if seq.seed == 3 else "-s0")
        for scenario in PAPER_SCENARIOS:
            assert parse_branch(seq.episode_branch(scenario)).sequence == seq
    # Variant 0 is the canonical scene: seed 0 of a variants run is seed 0 of a canonical run.
    assert SMOKE.sequences([0], variants=True) == SMOKE.sequences([0])
    assert parse_branch("exp-smoke-nb-most-changes-p4-update-s3-v03") is None  # not a name this module writes
    tasks = plan_tasks(SMOKE, [5], variants=True)
    assert {t.sequence.variant for t in tasks if isinstance(t, SequenceTask)} == {5}
    assert [t.seed for t in tasks if isinstance(t, PretrainTask)] == [5]


@pytest.mark.slow
def test_a_variants_run_solves_each_seed_in_its_variant_and_reports_it(reference: tuple[Store, Any], tmp_path: Path) -> None:
    """`--variants 1:2` next to the canonical seeds 0-1: seed 1 solves variant 1; reports keep the scenes apart."""
    db = tmp_path / "v.db"
    with closing(sqlite3.connect(reference[0].url.split("///", 1)[1])) as src, closing(sqlite3.connect(db)) as dst:
        src.backup(dst)
    runner = CliRunner()
    ran = runner.invoke(
        app, ["--db", str(db), "experiment", "run", "--preset", "smoke", "--variants", "1:2", "--workers", "1",
              "--out-dir", str(tmp_path / "v"), "--json"],
    )  # fmt: skip
    assert ran.exit_code == 0, ran.output
    data = json.loads(ran.stdout)
    assert data["run"]["seeds"] == [1] and data["run"]["variants"] == [1]
    assert data["run"]["tasks_skipped"] == 1  # seed 1's pretraining is the canonical run's
    assert data["overview"]["variants"] == [1] and data["overview"]["rows"] == len(SMOKE.cells()) * 3
    with Store.open(str(db)) as store:
        for seq in SMOKE.sequences([1], variants=True):
            for scenario in PAPER_SCENARIOS:
                (episode,) = [e for e in store.list_episodes(branch=seq.episode_branch(scenario)) if e.scenario == scenario]
                assert episode.summary["variant"] == 1 and episode.seed == 1
        both = results_table(store, "smoke")
        assert {r.variant for r in both} == {0}  # the canonical rows only
        assert {r.variant for r in results_table(store, "smoke", variants=True)} == {0, 1}  # seed 0 is variant 0
    canonical = runner.invoke(app, ["--db", str(db), "experiment", "report", "--from-db", "--out", str(tmp_path / "c"), "--json"])
    assert canonical.exit_code == 0, canonical.output
    assert json.loads(canonical.stdout)["overview"]["variants"] == [0]
    assert "left out" in canonical.stderr and "--variants" in canonical.stderr
    paired = runner.invoke(
        app, ["--db", str(db), "experiment", "report", "--from-db", "--variants", "0:2", "--out", str(tmp_path / "p"), "--json"]
    )
    assert paired.exit_code == 0, paired.output
    report = json.loads(paired.stdout)
    assert report["overview"]["variants"] == [0, 1]
    assert {(v["scenario"], v["variant"]) for v in report["per_variant"]} == {(s, v) for s in PAPER_SCENARIOS for v in (0, 1)}
    text = (tmp_path / "p" / "report.md").read_text()
    assert "## Per scene variant" in text and "Scenes: variants 0-1" in text
    assert {r.variant for r in ResultsTable.read(tmp_path / "p" / "results.csv")} == {0, 1}


@pytest.mark.parametrize(
    "argv, error",
    [
        (["experiment", "run", "--preset", "smoke", "--variants", "0:2", "--seeds", "2"], "drop --seeds and --first-seed"),
        (["experiment", "run", "--preset", "smoke", "--variants", "2:1"], "not a range of variants"),
        (["experiment", "report", "--from-db", "--variants", "50:60"], "no results on scene variants 50:60"),
    ],
)
def test_bad_variants_are_one_error_line(reference: tuple[Store, Any], argv: list[str], error: str) -> None:
    db = reference[0].url.split("///", 1)[1]
    result = CliRunner().invoke(app, ["--db", db, *argv])
    assert result.exit_code == 2 and error in result.stderr and "Traceback" not in result.output


def test_results_written_before_variants_read_as_the_canonical_scene(reference: tuple[Store, Any], tmp_path: Path) -> None:
    table = results_table(reference[0], "smoke")
    path = table.write_csv(tmp_path / "t.csv")
    lines = path.read_text().splitlines()
    column = lines[0].split(",").index("variant")
    old = "\n".join(",".join(v for i, v in enumerate(line.split(",")) if i != column) for line in lines) + "\n"
    (tmp_path / "old.csv").write_text(old)
    assert ResultsTable.read_csv(tmp_path / "old.csv") == table
