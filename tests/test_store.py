"""The store's API: round trips, branches, provenance, snapshots, operators, models."""

from __future__ import annotations

import dataclasses
import sqlite3
from contextlib import closing
from typing import Iterator

import pytest
from conftest import BACKENDS, new_store_url
from hypothesis import given, settings
from hypothesis import strategies as st

from llcps.domain import TRIAL_SOURCES, fluent
from llcps.trial_records import Body, TrialChange, TrialRecord
from llcps.errors import LlcpsError, StoreError, UnknownNameError
from llcps.store import MAIN_BRANCH, Store, validate_branch_name


def _expected_record(trial_id: int, new: TrialRecord, created_at: str) -> TrialRecord:
    return dataclasses.replace(new, id=trial_id, created_at=created_at)


@pytest.fixture(scope="module", params=BACKENDS)
def shared_store(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Store]:
    with Store.open(new_store_url(request.param, tmp_path_factory.mktemp("shared"), "shared.db"), create=True) as opened:
        yield opened


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**62), source=st.sampled_from(TRIAL_SOURCES), extra=st.dictionaries(st.text(max_size=5), st.integers(), max_size=3))
def test_trial_round_trip(shared_store: Store, seed: int, source: str, extra: dict) -> None:
    from store_writer import sample_trial

    new = sample_trial(seed, source=source, extra=extra, scenario="scenario2")
    trial_id = shared_store.add_trial(new)
    got = shared_store.get_trial(trial_id)
    assert got == _expected_record(trial_id, new, got.created_at)
    assert shared_store.visible_trials("main", after_id=trial_id - 1) == [got]
    assert got.as_json()["outcome"] == new.outcome.as_dict()


def test_add_trials_keeps_input_order_and_filters(store: Store, new_trial) -> None:  # noqa: ANN001
    news = [new_trial(i, source=TRIAL_SOURCES[i % len(TRIAL_SOURCES)], solved=i % 3 == 0, scenario=f"s{i % 2}") for i in range(12)]
    ids = store.add_trials(news)
    assert ids == sorted(ids) and len(set(ids)) == 12
    assert [store.get_trial(i).seed for i in ids] == list(range(12))
    plan = TRIAL_SOURCES.index("plan")
    assert [t.id for t in store.visible_trials("main", source="plan")] == [ids[i] for i in range(12) if i % len(TRIAL_SOURCES) == plan]
    assert [t.id for t in store.visible_trials("main", solved=True)] == [ids[i] for i in range(12) if i % 3 == 0]
    assert [t.id for t in store.visible_trials("main", scenario="s1", newest_first=True, limit=2)] == [ids[11], ids[9]]
    assert [t.id for t in store.visible_trials("main", after_id=ids[9])] == ids[10:]
    pretrain = TRIAL_SOURCES.index("pretrain")
    assert store.count_visible_trials("main", source="pretrain") == sum(i % len(TRIAL_SOURCES) == pretrain for i in range(12))
    assert store.max_visible_trial_id("main") == ids[-1]


def test_bad_trials_are_refused_and_nothing_is_written(store: Store, new_trial) -> None:  # noqa: ANN001
    with pytest.raises(LlcpsError, match="unknown trial source"):
        store.add_trials([new_trial(1), new_trial(2, source="dream")])
    with pytest.raises(UnknownNameError, match="unknown branch 'nope'") as info:
        store.add_trial(new_trial(3, branch="nope"))
    assert "main" in (info.value.hint or "")
    one = new_trial(4)
    with pytest.raises(LlcpsError, match="one feature set per argument"):
        store.add_trial(dataclasses.replace(one, features=one.features * 3))
    with pytest.raises(StoreError, match="does not exist"):
        store.add_trial(new_trial(5, episode_id=999))
    assert store.count_visible_trials("main") == 0


def test_unknown_trial_has_a_hint(store: Store) -> None:
    with pytest.raises(LlcpsError) as info:
        store.get_trial(42)
    assert "unknown trial 42" in info.value.message and info.value.hint


@pytest.mark.parametrize("name", ["", "   ", "a b", "a\tb", "x/y", "a..b", "..", "n" * 101, "-x"])
def test_invalid_branch_names(store: Store, name: str) -> None:
    with pytest.raises(LlcpsError, match="invalid branch name"):
        store.create_branch(name)
    assert [b.name for b in store.list_branches()] == [MAIN_BRANCH]


def test_valid_branch_names() -> None:
    for name in ("exp", "seq-1_nb.most-positive", "n" * 100, "ünïcode"):
        assert validate_branch_name(name) == name


def test_fork_points(store: Store, new_trial) -> None:  # noqa: ANN001
    pre = store.add_trials([new_trial(i) for i in range(3)])
    later = store.add_trials([new_trial(10 + i, source="exploration") for i in range(2)])
    assert store.create_branch("at-pretrain", at="pretrain").fork_point == pre[-1]
    assert store.create_branch("at-latest").fork_point == later[-1]
    assert store.create_branch("at-id", at=pre[0]).visible_trials == 1
    assert store.create_branch("at-zero", at=0).visible_trials == 0
    with pytest.raises(LlcpsError, match="not visible"):
        store.create_branch("bad", at=later[-1] + 100)
    with pytest.raises(StoreError, match="already exists"):
        store.create_branch("at-id")
    with pytest.raises(UnknownNameError):
        store.create_branch("orphan", from_branch="nope")
    own = store.add_trial(new_trial(20, branch="at-zero", source="exploration"))
    with pytest.raises(LlcpsError, match="not visible"):  # a trial of a sibling branch
        store.create_branch("bad2", from_branch="at-id", at=own)
    empty_root_child = store.create_branch("grandchild", from_branch="at-zero", at="pretrain")
    assert empty_root_child.fork_point == 0 and empty_root_child.visible_trials == 0
    assert store.branch_names() == [b.name for b in store.list_branches()]
    assert store.branch_names()[0] == MAIN_BRANCH and "grandchild" in store.branch_names()


def test_pretrain_fork_point_is_the_end_of_the_first_pretraining(store: Store, new_trial) -> None:  # noqa: ANN001
    """`make run` twice: pretraining, a solve that learns an operator, pretraining again and
    another solve. `--at pretrain` forks after the first pretraining: the branch sees none
    of the exploration, nor the operator learned from it; `reset --to pretrain` keeps as much."""
    first = store.add_trials([new_trial(i) for i in range(3)])
    explored = store.add_trials([new_trial(10 + i, source="exploration") for i in range(2)])
    store.add_operator(branch="main", name="learned", pddl="", definition={}, scenario=None, episode_id=None)
    store.add_trials([new_trial(20 + i) for i in range(3)])
    store.add_trials([new_trial(30, source="plan")])
    fresh = store.create_branch("fresh", at="pretrain")
    assert fresh.fork_point == first[-1] and fresh.visible_trials == len(first)
    seen = store.visible_trials("fresh")
    assert [t.id for t in seen] == first and {t.source for t in seen} == {"pretrain"}
    assert not store.visible_operators("fresh") and store.visible_operators("main")
    assert explored[0] > fresh.fork_point
    change = store.reset_branch("main", to="pretrain", dry_run=True)
    assert change.trials == 2 + 3 + 1 and change.operators == 1


def test_interleaved_branch_ranges_still_come_back_in_id_order(tmp_path, new_trial) -> None:  # noqa: ANN001
    """A branch's visible trials are read link by link; if a changed fork point makes the
    links' id ranges interleave, the store falls back to one sorted query."""
    path = tmp_path / "interleaved.db"
    with Store.open(str(path), create=True) as store:
        body = Body("cube", "object", "box", (0.0, 0.0, 0.0), (0.1, 0.1, 0.1), (0.05, 0.05, 0.05))
        change = TrialChange.between({fluent("visible", "cube")}, set(), (body,))
        store.add_trials([new_trial(i) for i in range(2)], changes=[change, change])  # main: 1, 2
        store.create_branch("b")  # forked at 2
        store.add_trial(new_trial(3, branch="b", source="exploration"), change=change)  # b: 3
        store.add_trial(new_trial(4, source="exploration"), change=change)  # main: 4, not seen by b
        assert [t.id for t in store.visible_trials("b")] == [1, 2, 3]
        assert list(store.visible_changes("b")) == [1, 2, 3]
    with closing(sqlite3.connect(path)) as conn, conn:
        conn.execute("UPDATE branches SET fork_point = 4 WHERE name = 'b'")  # b now sees 4, older than its own 3
    with Store.open(str(path)) as store:
        assert [t.id for t in store.visible_trials("b")] == [1, 2, 3, 4]
        assert [t.id for t in store.visible_trials("b", newest_first=True)] == [4, 3, 2, 1]
        assert [t.id for t in store.visible_trials("b", source="exploration")] == [3, 4]
        assert [t.branch for t in store.visible_trials("b")] == ["main", "main", "b", "main"]
        assert list(store.visible_changes("b")) == [1, 2, 3, 4]


def test_compact_gives_the_space_of_removed_rows_back_and_changes_nothing(store: Store, new_trial) -> None:  # noqa: ANN001
    store.create_branch("big")
    store.add_trials([new_trial(i, branch="big", extra={"pad": "x" * 4000}) for i in range(200)])
    store.add_trials([new_trial(1000 + i) for i in range(3)])
    store.delete_branch("big", dry_run=False)
    kept = store.visible_trials("main")
    result = store.compact()
    assert store.visible_trials("main") == kept and store.branch_names() == ["main"]
    assert result.before is not None and result.after is not None
    if store.engine.dialect.name == "sqlite":  # PostgreSQL keeps the space for the tables to reuse
        assert result.freed is not None and result.freed > 200 * 4000
        assert store.compact().freed == 0  # nothing left to give back


def test_checkout_and_current_branch(store: Store) -> None:
    store.create_branch("exp")
    assert store.current_branch() == MAIN_BRANCH
    assert store.checkout("exp").is_current
    assert store.current_branch() == "exp"
    assert store.resolve_branch(None).name == "exp"
    assert [b.name for b in store.list_branches() if b.is_current] == ["exp"]
    with pytest.raises(UnknownNameError, match="unknown branch"):
        store.checkout("nope")
    assert store.current_branch() == "exp"


def test_reset_to_pretrain_is_the_papers_second_experiment(store: Store, new_trial) -> None:  # noqa: ANN001
    pre = store.add_trials([new_trial(i) for i in range(4)])
    run = store.start_run(command="test", seed=1, config={}, branch="main")
    episode = store.start_episode(run_id=run, branch="main", scenario="s1", condition="novelty", model="nb", measure="m", seed=1)
    explored = store.add_trials([new_trial(10 + i, source="exploration", episode_id=episode) for i in range(3)])
    store.add_operator(branch="main", name="op", pddl="(:action op)", definition={}, scenario="s1", episode_id=episode)
    store.save_world_model(branch="main", name="nb", seed=1, watermark=explored[-1], artifact=b"x", meta={})
    store.save_world_model(branch="main", name="nb", seed=1, watermark=pre[-1], artifact=b"old", meta={})

    plan = store.reset_branch("main", to="pretrain", dry_run=True)
    assert (plan.trials, plan.operators, plan.world_models, plan.episodes, plan.dry_run) == (3, 1, 1, 1, True)
    assert store.count_visible_trials("main") == 7  # a dry run changes nothing

    done = store.reset_branch(None, to="pretrain", dry_run=False)
    assert done == dataclasses.replace(plan, dry_run=False)
    assert [t.id for t in store.visible_trials("main")] == pre
    assert store.visible_operators("main") == [] and store.list_episodes() == []
    model = store.latest_world_model("main", "nb", 1)
    assert model is not None and model.artifact == b"old"

    assert store.reset_branch("main", to="empty", dry_run=False).trials == 4
    assert store.count_visible_trials("main") == 0


def test_reset_and_delete_refuse_what_children_still_see(store: Store, new_trial) -> None:  # noqa: ANN001
    store.add_trials([new_trial(i) for i in range(2)])
    explored = store.add_trial(new_trial(5, source="exploration"))
    store.create_branch("child", at=explored)
    with pytest.raises(StoreError, match="child"):
        store.reset_branch("main", to="pretrain", dry_run=True)
    store.create_branch("grandchild", from_branch="child")
    with pytest.raises(StoreError, match="child branches: grandchild"):
        store.delete_branch("child", dry_run=False)
    store.checkout("grandchild")
    with pytest.raises(StoreError, match="checked out"):
        store.delete_branch("grandchild", dry_run=False)
    store.checkout("main")
    assert store.delete_branch("grandchild", dry_run=False).action == "delete"
    assert store.delete_branch("child", dry_run=False).trials == 0
    assert store.reset_branch("main", to="pretrain", dry_run=False).trials == 1
    with pytest.raises(StoreError, match="main branch cannot be deleted"):
        store.delete_branch("main", dry_run=False)


def test_deleted_branch_ids_and_trial_ids_are_never_reused(store: Store, new_trial) -> None:  # noqa: ANN001
    store.create_branch("tmp")
    last = store.add_trial(new_trial(1, branch="tmp"))
    store.delete_branch("tmp", dry_run=False)
    store.create_branch("tmp")
    assert store.add_trial(new_trial(2, branch="tmp")) > last
    assert store.resolve_branch("tmp").visible_trials == 1


def test_runs_and_episodes(store: Store) -> None:
    run = store.start_run(command="llcps solve", seed=7, config={"model": "nb"}, branch="main")
    episode = store.start_episode(run_id=run, branch="main", scenario="s2", condition="novelty", model="nb", measure="m", seed=7)
    store.finish_episode(episode, status="solved", summary={"trials": 3})
    store.finish_run(run, status="ok")
    (got_run,) = store.list_runs()
    assert (got_run.id, got_run.status, got_run.config, got_run.seed) == (run, "ok", {"model": "nb"}, 7)
    assert got_run.finished_at is not None
    (got_episode,) = store.list_episodes(run_id=run)
    assert (got_episode.status, got_episode.summary, got_episode.branch) == ("solved", {"trials": 3}, "main")
    assert store.list_episodes(scenario="other") == []
    with pytest.raises(LlcpsError, match="unknown run"):
        store.finish_run(run + 1, status="ok")
    with pytest.raises(LlcpsError, match="unknown episode"):
        store.finish_episode(episode + 1, status="ok", summary={})


def test_snapshots_are_deduplicated_by_content(store: Store, new_trial) -> None:  # noqa: ANN001
    scene = {"entities": [{"name": "red_box", "pose": [0.1, 0.2, 0.3]}], "scenario": "s1"}
    first = store.put_snapshot(scene=scene, state=b"\x00\x01state")
    assert store.put_snapshot(scene=dict(reversed(list(scene.items()))), state=b"\x00\x01state") == first
    assert store.put_snapshot(scene=scene, state=b"\x00\x01other") != first
    got = store.get_snapshot(first)
    assert (got.scene, got.state, got.sha256) == (scene, b"\x00\x01state", Store.snapshot_hash(scene, b"\x00\x01state"))
    trial_id = store.add_trial(new_trial(1, snapshot_id=first))
    assert store.get_trial(trial_id).snapshot_id == first
    with pytest.raises(LlcpsError, match="unknown snapshot"):
        store.get_snapshot(first + 100)


def test_operators_and_models_follow_branch_visibility(store: Store, new_trial) -> None:  # noqa: ANN001
    store.add_trials([new_trial(i) for i in range(2)])
    early = store.add_operator(branch="main", name="early", pddl="(:action early)", definition={"k": 1}, scenario=None, episode_id=None)
    store.save_world_model(branch="main", name="nn", seed=0, watermark=store.max_visible_trial_id("main"), artifact=b"v1", meta={"a": 1})
    store.create_branch("child")
    store.add_trial(new_trial(3))
    late = store.add_operator(branch="main", name="late", pddl="(:action late)", definition={}, scenario="s1", episode_id=None)
    store.save_world_model(branch="main", name="nn", seed=0, watermark=store.max_visible_trial_id("main"), artifact=b"v2", meta={})
    assert [o.id for o in store.visible_operators("main")] == [early, late]
    (inherited,) = store.visible_operators("child")
    assert (inherited.id, inherited.branch, inherited.definition) == (early, "main", {"k": 1})
    child_model = store.latest_world_model("child", "nn", 0)
    assert child_model is not None and child_model.artifact == b"v1" and child_model.meta == {"a": 1}
    main_model = store.latest_world_model("main", "nn", 0)
    assert main_model is not None and main_model.artifact == b"v2"
    assert store.latest_world_model("main", "nn", 1) is None
    with pytest.raises(LlcpsError, match="must be bytes"):
        store.save_world_model(branch="main", name="nn", seed=0, watermark=0, artifact="text", meta={})  # type: ignore[arg-type]


def test_status_counts(store: Store, new_trial) -> None:  # noqa: ANN001
    store.add_trials([new_trial(i) for i in range(3)] + [new_trial(9, source="plan")])
    store.create_branch("exp", at="pretrain")
    store.add_trial(new_trial(10, branch="exp", source="exploration"))
    status = store.status("exp")
    assert (status.revision, status.up_to_date, status.current_branch, status.branch) == (store.head, True, "main", "exp")
    assert (status.trials_total, status.visible_trials, dict(status.visible_by_source)) == (5, 4, {"pretrain": 3, "exploration": 1})


def test_what_a_paused_collection_made_is_old_afterwards_and_others_freezes_stay() -> None:
    """gc_paused leaves no young backlog for the next collection to traverse (the objects
    made in the pause go to the oldest generation), and never thaws what another part of
    the process froze."""
    import gc

    from llcps.store.trials import gc_paused

    class Made:  # a tracked container, to be found in the collector's lists
        pass

    collections: list[int] = []

    def seen(phase: str, info: dict) -> None:
        if phase == "start":
            collections.append(info["generation"])

    assert gc.get_freeze_count() == 0
    gc.callbacks.append(seen)
    try:
        with gc_paused():
            made = [Made() for _ in range(10_000)]
            assert not gc.isenabled()
        enabled, backlog = gc.isenabled(), gc.get_count()[0]
        in_oldest = any(o is made[-1] for o in gc.get_objects(generation=2))
    finally:
        gc.callbacks.remove(seen)
    assert enabled and backlog < 700 and in_oldest
    assert collections == []  # nothing traversed the 10,000 objects on the way there
    gc.freeze()
    try:
        frozen = gc.get_freeze_count()
        with gc_paused():
            more = [Made() for _ in range(1_000)]
        assert gc.get_freeze_count() == frozen and len(more) == 1_000
    finally:
        gc.unfreeze()
