"""The world: scenes round-trip, bodies are named, snapshots restore exactly,
states replay across processes, frames render headless."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from typing import Any

import numpy as np
import pytest
from PIL import Image

from llcps.domain import ControllerParams
from llcps.trial_records import TrialSpec
from llcps.errors import LlcpsError, UnknownNameError
from llcps.sim.builders import bucket, edge_lip, inside, open_box, shelf, solid, stacked
from llcps.sim.specs import EntitySpec
from llcps.sim.render import GifRecorder, render_png
from llcps.sim.trial import run_trial
from llcps.sim.world import FLOOR, TABLE, SceneSpec, World

BIN = open_box("bin", "green", at=(0.45, -0.3), size=(0.2, 0.2, 0.08))
BASE = solid("base", "box", "red", (0.06, 0.06, 0.05), at=(0.6, 0.25))
SCENE = SceneSpec(
    entities=(
        BASE,
        stacked(solid("cap", "cylinder", "blue", (0.04, 0.04), at=(0, 0)), BASE),
        solid("ball", "sphere", "red", 0.05, at=(0.5, 0.0)),
        BIN,
        inside(solid("cube", "box", "blue", (0.04, 0.04, 0.04), at=(0, 0)), BIN),
        bucket("bucket", "red", at=(1.2, 0.0)),
    ),
    fixtures=(edge_lip(SceneSpec().table, "left"), *shelf("shelf", at=(0.3, 0.35), clearance=0.15)),
    name="test",
)
SPECS = [
    TrialSpec("push_together", ("ball", "base"), ControllerParams(0.3, 0.05, "front")),
    TrialSpec("remove_from_container", ("cube", "bin"), ControllerParams(0.5, 0.1, "front")),
    TrialSpec("place_in_container", ("cap", "bin"), ControllerParams(0.4, 0.1, "left")),
]


@pytest.fixture(scope="module")
def world():
    w = World.from_scene(SCENE)
    w.settle(max_steps=240)
    yield w
    w.close()


def test_scene_round_trips_through_json() -> None:
    data = json.loads(json.dumps(SCENE.to_dict()))
    assert SceneSpec.from_dict(data) == SCENE
    assert EntitySpec.from_dict(SCENE.entities[0].to_dict()) == SCENE.entities[0]


def test_bad_scenes_are_refused() -> None:
    with pytest.raises(ValueError):
        SceneSpec(entities=(solid("table", "box", "red", (0.05, 0.05, 0.05), at=(0.5, 0)),))
    with pytest.raises(ValueError):
        solid("x", "cone", "red", (0.05, 0.05, 0.05), at=(0.5, 0))
    with pytest.raises(ValueError):
        solid("x", "box", "purple", (0.05, 0.05, 0.05), at=(0.5, 0))
    with pytest.raises(LlcpsError):
        SceneSpec.from_dict({"entities": [{"name": "x"}]})


def test_bodies_are_named(world) -> None:
    assert set(world.entities) == {e.name for e in SCENE.entities}
    assert {TABLE, FLOOR, "lip", "shelf", "shelf_post"} == set(world.fixtures)
    assert world.entities["bin"].spec.kind == "container"
    assert world.center("bin") == pytest.approx(BIN.position, abs=2e-3)  # the box centre, not its centre of mass
    with pytest.raises(UnknownNameError):
        world.entity("nothing")


def test_settled_scene_stays_put(world) -> None:
    for spec in SCENE.entities:
        assert world.center(spec.name) == pytest.approx(spec.position, abs=0.005), spec.name


def test_restoring_a_snapshot_repeats_a_trial_exactly(world) -> None:
    snap = world.snapshot()
    first = [run_trial(world, spec) for spec in SPECS[:1]]
    positions = {n: world.center(n) for n in world.entities}
    world.restore(snap)
    again = [run_trial(world, spec) for spec in SPECS[:1]]
    assert [(r.outcome, r.sim_steps, r.after) for r in again] == [(r.outcome, r.sim_steps, r.after) for r in first]
    assert {n: world.center(n) for n in world.entities} == positions
    world.restore(snap)


REPLAY = textwrap.dedent(
    """
    import base64, json, sys
    from llcps.domain import ControllerParams
    from llcps.trial_records import TrialSpec
    from llcps.sim.trial import run_trial
    from llcps.sim.world import World
    job = json.load(sys.stdin)
    out = []
    for case in job:
        world = World.from_scene(case["scene"])
        world.restore_serialized(base64.b64decode(case["state"]))
        a, args, rate, mag, orient = case["spec"]
        r = run_trial(world, TrialSpec(a, tuple(args), ControllerParams(rate, mag, orient)))
        out.append({"bits": list(r.outcome.bits()), "steps": r.sim_steps,
                    "positions": {n: list(world.center(n)) for n in world.entities}})
        world.close()
    print(json.dumps(out))
    """
)


def test_a_trial_replays_bit_for_bit_in_a_new_process(world) -> None:
    """Each trial runs after the previous one (a grasp included), as an agent would."""
    import base64

    cases, expected = [], []
    for spec in SPECS:
        state = world.serialize_state()
        r = run_trial(world, spec)
        cases.append(
            {
                "scene": world.scene.to_dict(),
                "state": base64.b64encode(state).decode(),
                "spec": [
                    spec.action,
                    list(spec.arguments),
                    spec.params.rate,
                    spec.params.movement_magnitude,
                    spec.params.orientation,
                ],
            }
        )
        expected.append(
            {
                "bits": list(r.outcome.bits()),
                "steps": r.sim_steps,
                "positions": {n: list(world.center(n)) for n in world.entities},
            }
        )
    done = subprocess.run(
        [sys.executable, "-c", REPLAY],
        input=json.dumps(cases),
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONHASHSEED": "0"},
    )
    assert json.loads(done.stdout) == expected


def test_a_state_from_another_scene_is_refused(world) -> None:
    with World.from_scene(SceneSpec(entities=(solid("solo", "box", "red", (0.05, 0.05, 0.05), at=(0.5, 0)),))) as other:
        state = other.serialize_state()
    with pytest.raises(LlcpsError):
        world.restore_serialized(state)
    with pytest.raises(LlcpsError):
        world.restore(12345)
    with pytest.raises(LlcpsError):
        world.restore_serialized(b"not a state")


def test_gui_without_a_display_is_a_clear_error(monkeypatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    if not sys.platform.startswith("linux"):
        pytest.skip("the display check is for Linux")
    with pytest.raises(LlcpsError, match="display"):
        World(gui=True)


def test_frames_render_headless(world, tmp_path) -> None:
    path = render_png(world, tmp_path / "scene.png", width=160, height=120)
    image = Image.open(path)
    assert image.size == (160, 120)
    assert len(np.unique(np.asarray(image).reshape(-1, 3), axis=0)) > 20  # a scene, not a blank frame
    with GifRecorder(world, every=60, width=80, height=60) as rec:
        world.step(180)
    assert len(rec.frames) == 2 + 3
    gif = Image.open(rec.save(tmp_path / "clip.gif"))
    assert gif.size == (80, 60)  # identical frames of a scene at rest may be merged


def _settled(scene: SceneSpec = SCENE, **kwargs: Any) -> World:
    w = World.from_scene(scene, **kwargs)
    w.settle(max_steps=120)
    return w


def test_a_reach_probe_solves_its_ik_once_per_target_and_leaves_the_same_state(monkeypatch, fresh_caches) -> None:
    """`reach_error` remembers its IK solve by target; the probe still moves the joints
    (which changes what the world saves next), so a remembered probe saves the same bytes."""
    with _settled() as w:
        start = w.serialize_state()
        solve = w.client.calculateInverseKinematics
        solves: list[object] = []
        spy = lambda *a, **k: solves.append(a) or solve(*a, **k)  # noqa: E731
        monkeypatch.setattr(w.client, "calculateInverseKinematics", spy, raising=False)
        target, yaw = (0.5, 0.1, 0.12), 0.3
        first = w.robot.reach_error(target, yaw)
        after_first = w.save_state()
        assert len(solves) == 1
        w.restore_serialized(start)
        again = w.robot.reach_error(target, yaw)
        assert len(solves) == 1  # answered from the memo
        assert again == first
        assert w.save_state() == after_first
        w.robot.reach_error((0.5, 0.1, 0.13), yaw)
        assert len(solves) == 2  # another target is solved


def test_a_saved_state_restores_as_its_serialized_bytes() -> None:
    with _settled() as w:
        run_trial(w, SPECS[0])
        saved = w.save()
        serialized = saved.serialized
        assert serialized == w.save_state()  # the same bytes, compressed on demand
        w.restore_saved(saved)
        from_saved = w.save_state()
        w.restore_serialized(serialized)
        assert w.save_state() == from_saved


def test_a_state_checked_once_is_not_inflated_again(monkeypatch) -> None:
    from llcps.sim import world as world_module

    with _settled() as w:
        state = w.serialize_state()
        inflate = world_module.snapshots.decompress_state
        inflated: list[int] = []
        monkeypatch.setattr(world_module.snapshots, "decompress_state", lambda s: inflated.append(len(s)) or inflate(s))
        w.restore_serialized(state)
        w.restore_serialized(state)
        assert len(inflated) == 1  # the same bytes object as the last check
        w.restore_serialized(bytes(bytearray(state)))  # equal bytes, another object: checked again
        assert len(inflated) == 2


def test_a_closed_world_leaves_its_engine_to_the_next_world_which_behaves_as_fresh() -> None:
    from llcps.sim.connection import ConnectionPool

    used = _settled()
    client = used.client
    for spec in SPECS:  # history in the engine: contacts, a grasp constraint that came and went
        run_trial(used, spec)
    used.close()
    with _settled() as reused:
        assert reused.client is client
        trial = run_trial(reused, SPECS[1])
        reused_state = reused.save_state()
    with _settled(pool=ConnectionPool(capacity=0)) as fresh:
        assert fresh.client is not client
        again = run_trial(fresh, SPECS[1])
        assert (again.outcome, again.sim_steps, again.after) == (trial.outcome, trial.sim_steps, trial.after)
        assert fresh.save_state() == reused_state


def _state_after(world: World, raw: bytes) -> tuple[bytes, tuple[float, float, float]]:
    """Restore ``raw``, step a little, and return what the world then holds."""
    world._restore_raw(raw)  # noqa: SLF001 - the engine's restore path is what is tested
    world.step(30)
    return world._save_raw(), world.center("ball")  # noqa: SLF001


def test_many_distinct_states_restore_as_themselves_in_any_order() -> None:
    """More distinct states than the engine's file cache holds, restored twice in
    different orders: each gives what it gave the first time (no state is restored
    from a file name that held another)."""
    from llcps.sim import state_files

    with _settled() as w:
        states = []
        for _ in range(state_files.CAPACITY + 8):
            w.step(3)
            states.append(w._save_raw())  # noqa: SLF001
        assert len(set(states)) == len(states)
        first = [_state_after(w, raw) for raw in states]
        again = [_state_after(w, raw) for raw in reversed(states)][::-1]
        assert again == first
        assert len({after for after, _ in first}) == len(states)
        assert _state_after(w, states[0]) == first[0]  # held by the engine, restored without a write


def _rss_kb() -> int:
    with open("/proc/self/status") as fh:
        return int(fh.read().split("VmRSS:")[1].split()[0])


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="reads /proc/self/status")
def test_restoring_many_distinct_states_keeps_the_engine_small() -> None:
    """The engine's file layer keeps every file it reads; 200 restores of distinct
    ~90 kB states used to grow the process by 18 MB."""
    with _settled() as w:
        states = []
        for _ in range(200):
            w.step(2)
            states.append(w._save_raw())  # noqa: SLF001
        size = len(states[0])
        for raw in states[:40]:  # the first clears of the engine's cache, and the allocator's pools
            w._restore_raw(raw)  # noqa: SLF001
        before = _rss_kb()
        for raw in states:
            w._restore_raw(raw)  # noqa: SLF001
        grown = _rss_kb() - before
        assert grown * 1024 < 40 * size, f"grew by {grown} kB over 200 restores of {size} byte states"


def test_saving_and_restoring_create_no_named_files_a_kill_could_leave(tmp_path, monkeypatch) -> None:
    import tempfile

    seen: set[str] = set()
    original = os.open

    def watched(path, *args, **kwargs):  # every file opened while saving and restoring
        seen.add(str(path))
        return original(path, *args, **kwargs)

    with _settled() as w:
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        monkeypatch.setattr(os, "open", watched)
        raw = w._save_raw()  # noqa: SLF001
        w._restore_raw(raw)  # noqa: SLF001
        w.serialize_state()
    assert not any(p.startswith(str(tmp_path)) for p in seen)
    assert list(tmp_path.iterdir()) == []


@pytest.fixture()
def panda_files_in(tmp_path, monkeypatch):
    """panda_urdf() writing into ``tmp_path`` as the temporary directory, for this test only."""
    import tempfile

    from llcps.sim.robot import panda_urdf

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    panda_urdf.cache_clear()
    yield tmp_path
    monkeypatch.undo()
    panda_urdf.cache_clear()


def test_the_pandas_files_are_written_once_and_shared_by_processes(panda_files_in) -> None:
    from llcps.sim.robot import panda_urdf

    first = panda_urdf()
    script = f"import tempfile; tempfile.tempdir = {str(panda_files_in)!r}\nfrom llcps.sim.robot import panda_urdf; print(panda_urdf())"
    other = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.strip()
    assert other == first
    assert [p.name for p in panda_files_in.iterdir()] == [os.path.basename(os.path.dirname(first))]  # nothing else left
    with World.from_scene(SceneSpec()) as w:  # the shared files build the robot
        assert w.client.getNumJoints(w.robot.body_id) > 9


def test_a_panda_directory_others_may_write_is_not_used(panda_files_in) -> None:
    from llcps.sim.robot import panda_urdf

    shared = os.path.dirname(panda_urdf())
    os.chmod(shared, 0o777)
    panda_urdf.cache_clear()
    private = os.path.dirname(panda_urdf())
    assert private != shared and os.stat(private).st_mode & 0o077 == 0
    for name in os.listdir(os.path.join(shared, "meshes", "collision")):
        with open(os.path.join(shared, "meshes", "collision", name), "rb") as a, open(os.path.join(private, "meshes", "collision", name), "rb") as b:
            assert a.read() == b.read()


def test_without_memory_files_states_go_through_a_private_directory_and_restore_the_same(monkeypatch) -> None:
    """Where the system has no anonymous in-memory files, a private temporary directory serves."""
    from llcps.sim.connection import ConnectionPool

    with _settled() as w:
        states = []
        for _ in range(3):
            w.step(3)
            states.append(w._save_raw())  # noqa: SLF001
        expected = [_state_after(w, raw) for raw in states]
        monkeypatch.delattr(os, "memfd_create")
    with _settled(pool=ConnectionPool(capacity=0)) as w:  # an engine of its own: its files are made now
        assert [_state_after(w, raw) for raw in states] == expected
        files = w._connection.files  # noqa: SLF001
        directory = files._directory  # noqa: SLF001
        assert directory is not None and os.stat(directory).st_mode & 0o077 == 0
        assert sorted(os.listdir(directory)) == ["save.bullet", "state-0.bullet", "state-1.bullet", "state-2.bullet"]
