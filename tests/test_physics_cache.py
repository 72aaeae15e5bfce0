"""The physics cache: its key covers every input of a trial's physics, entries read back
from the store are checked before use, its size is bounded, and an episode records the
same trials with it, without it, and answered entirely from it."""

from __future__ import annotations

import zlib
from dataclasses import fields, replace
from datetime import datetime
from pathlib import Path

import pytest
from sqlalchemy import update

from llcps.cps.episode import SolveConfig, solve
from llcps.domain import ControllerParams, EntityFeatures
from llcps.trial_records import Body, Outcome, TrialSpec
from llcps.cps.pretraining import pretrain
from llcps.sim.cache import decode_result, encode_result, trial_key
from llcps.sim.trial import TrialResult
from llcps.sim.settings import PhysicsSettings
from llcps.store import Store
from llcps.store import physics_cache as pc
from llcps.store.tables import PhysicsCacheEntry

SPEC = TrialSpec("push", ("block",), ControllerParams(0.4, 0.15, "left"))
SETTINGS = PhysicsSettings()
SCENE = {"name": "s", "entities": []}
STATE = zlib.compress(b"BULLET-state" + bytes(200))
RESULT = TrialResult(
    spec=SPEC,
    features=(EntityFeatures("box", 0.001, "red", 0.6, 0.8, 0.6, 0.0),),
    before=frozenset({("visible", "block"), ("reachable", "block")}),
    after=frozenset({("visible", "block")}),
    outcome=Outcome.between({("visible", "block"), ("reachable", "block")}, {("visible", "block")}),
    sim_steps=321,
    wall_seconds=0.25,
)


def _perturbed_settings() -> list[PhysicsSettings]:
    changes = {
        "time_step": 1 / 480,
        "solver_iterations": 49,
        "sub_steps": 1,
        "deterministic_overlapping_pairs": False,
        "gravity": (0.0, 0.0, -9.8),
        "engine": "pybullet 0.0.0 api 0",
        "controllers": SETTINGS.controllers + 1,
    }
    assert set(changes) == {f.name for f in fields(PhysicsSettings)}, "perturb every setting"
    return [replace(SETTINGS, **{name: value}) for name, value in changes.items()]


def test_the_key_changes_with_every_input_of_the_physics() -> None:
    key = trial_key(SETTINGS, SCENE, STATE, SPEC, 6000)
    assert key == trial_key(PhysicsSettings(), dict(SCENE), bytes(STATE), SPEC, 6000)  # a pure function
    others = [trial_key(s, SCENE, STATE, SPEC, 6000) for s in _perturbed_settings()]
    others += [
        trial_key(SETTINGS, {**SCENE, "name": "t"}, STATE, SPEC, 6000),
        trial_key(SETTINGS, SCENE, STATE + b"\x00", SPEC, 6000),
        trial_key(SETTINGS, SCENE, STATE, replace(SPEC, arguments=("other",)), 6000),
        trial_key(SETTINGS, SCENE, STATE, replace(SPEC, params=ControllerParams(0.5, 0.15, "left")), 6000),
        trial_key(SETTINGS, SCENE, STATE, replace(SPEC, params=ControllerParams(0.4, 0.2, "left")), 6000),
        trial_key(SETTINGS, SCENE, STATE, replace(SPEC, params=ControllerParams(0.4, 0.15, "top")), 6000),
        trial_key(SETTINGS, SCENE, STATE, TrialSpec("push_together", ("block", "cup"), SPEC.params), 6000),
        trial_key(SETTINGS, SCENE, STATE, SPEC, 5999),
    ]
    assert len({key, *others}) == 1 + len(others)


def test_a_result_round_trips_and_malformed_ones_are_refused() -> None:
    assert decode_result(encode_result(RESULT)) == RESULT
    good = encode_result(RESULT)
    cup = Body("cup", "container", "box", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (0.5, 0.5, 0.5))
    with_body = encode_result(replace(RESULT, bodies=(cup,)))
    assert decode_result(with_body).bodies == (cup,) and b'"lo":[0.0,0.0,0.0]' in with_body
    for bad in (
        with_body.replace(b'"lo":[0.0,0.0,0.0]', b'"lo":[1' + b"0" * 400 + b',0.0,0.0]'),  # too large for a float
        with_body.replace(b'"shape":"box"', b'"shape":"cube"'),
        b"not json",
        b"[]",
        good.replace(b'"push"', b'"fly"'),
        good.replace(b'"sim_steps":321', b'"sim_steps":-1'),
        good.replace(b'"outcome":[0,0,0,1,0,0]', b'"outcome":[1,0,0,1,0,0]'),  # not what the states say
        good.replace(b'"wall_seconds":0.25', b'"wall_seconds":NaN'),
        b" " * (2 << 20),
    ):
        with pytest.raises(ValueError):
            decode_result(bad)


def test_a_stored_entry_is_shared_between_handles_and_checked_on_every_read(store: Store) -> None:
    writer, reader = pc.StorePhysicsCache(store.engine), pc.StorePhysicsCache(store.engine)
    key = trial_key(SETTINGS, SCENE, STATE, SPEC, 6000)
    assert reader.get(key) is None
    writer.put(key, RESULT, STATE)
    writer.put(key, replace(RESULT, sim_steps=1), STATE)  # a key keeps its first entry
    got = reader.get(key)
    assert got is not None and got.result == RESULT and got.end_state == STATE
    assert (reader.counts.hits, reader.counts.misses, writer.counts.stored) == (1, 1, 1)

    def damage(**values: object) -> None:
        with store.engine.begin() as conn:
            conn.execute(update(PhysicsCacheEntry).where(PhysicsCacheEntry.key == key).values(**values))

    damage(end_state=STATE + b"x")  # the content hash no longer matches
    assert reader.get(key) is None and reader.counts.rejected == 1
    bomb = zlib.compress(b"BULLET" + bytes(pc.MAX_RAW_STATE_BYTES + 1), 9)
    damage(end_state=bomb, sha256=pc.content_hash(encode_result(RESULT), bomb))  # well hashed, inflates past the cap
    assert reader.get(key) is None and reader.counts.rejected == 2
    reader.put(key, RESULT, STATE)  # the next simulation replaces a rejected entry
    assert reader.get(key) is not None


class _Calls:
    """The check and trust a world would pass, counting what the cache calls."""

    def __init__(self, refuse: bool = False) -> None:
        self.checked = self.trusted = 0
        self.refuse = refuse

    def check(self, state: bytes) -> None:
        self.checked += 1
        if self.refuse:
            raise pc.LlcpsError("refused")

    def trust(self, state: bytes) -> None:
        self.trusted += 1


def test_a_sealed_entry_skips_the_checks_and_any_other_is_checked_then_sealed(store: Store, tmp_path: Path) -> None:
    mine, theirs = tmp_path / "mine.key", tmp_path / "theirs.key"
    key = trial_key(SETTINGS, SCENE, STATE, SPEC, 6000)
    pc.StorePhysicsCache(store.engine, key_file=mine).put(key, RESULT, STATE)

    def read(key_file: Path, refuse: bool = False) -> tuple[bool, int, int]:
        cache, calls = pc.StorePhysicsCache(store.engine, key_file=key_file), _Calls(refuse)
        got = cache.get(key, check=calls.check, trust=calls.trust)
        cache.flush()
        return got is not None, calls.checked, calls.trusted

    def damage(**values: object) -> None:
        with store.engine.begin() as conn:
            conn.execute(update(PhysicsCacheEntry).where(PhysicsCacheEntry.key == key).values(**values))

    assert read(mine) == (True, 0, 1)  # sealed by this machine: trusted, not checked
    assert read(theirs, refuse=True) == (False, 1, 0)  # another secret: checked, refused, not sealed
    assert read(mine) == (True, 0, 1)
    assert read(theirs) == (True, 1, 0)  # checked, passes, sealed under their secret ...
    assert read(theirs) == (True, 0, 1)
    assert read(mine) == (True, 1, 0)  # ... which this machine cannot verify: checked again
    other = zlib.compress(b"BULLET-other" + bytes(200))
    damage(end_state=other, sha256=pc.content_hash(encode_result(RESULT), other))  # rehashed, seal left as it was
    assert read(mine) == (True, 1, 0)
    forged: list[object] = ["0" * 64, "é" * 64]
    if store.engine.dialect.name == "sqlite":  # a typed column holds nothing but text
        forged += [b"\xff" * 64, 12345]
    for seal in forged:  # forged or of the wrong type: checked, no crash
        damage(seal=seal)
        assert read(mine) == (True, 1, 0)
    unusable = tmp_path / "a-file"
    unusable.write_bytes(b"")
    assert pc.load_secret(unusable / "key") is None  # its directory cannot exist
    assert read(unusable / "key") == (True, 1, 0)  # no secret: every entry is checked, as before seals


def test_the_seal_secret_is_made_once_private_and_read_back(tmp_path: Path) -> None:
    path = tmp_path / "dir" / "physics-cache.key"
    secret = pc.load_secret(path)
    assert secret is not None and len(secret) == pc.SECRET_BYTES and path.read_bytes() == secret
    assert path.stat().st_mode & 0o777 == 0o600
    pc.load_secret.cache_clear()
    assert pc.load_secret(path) == secret  # another process reads the same file
    short = tmp_path / "short.key"
    short.write_bytes(b"too short")
    assert pc.load_secret(short) is None
    assert list(path.parent.iterdir()) == [path]  # no temporary file left


@pytest.mark.parametrize(
    "state", [b"", b"\x78\x9c garbage", zlib.compress(b"not a bullet file"), zlib.compress(b"BULLET" + bytes(100))[:-4]]
)
def test_end_states_that_are_not_physics_states_are_refused(state: bytes) -> None:
    with pytest.raises(ValueError):
        pc.validate_state(state)


def test_pruning_keeps_the_most_recently_used_entries_within_the_bound(store: Store) -> None:
    cache = pc.StorePhysicsCache(store.engine)
    keys = [trial_key(SETTINGS, SCENE, STATE, SPEC, steps) for steps in range(5)]
    for key in keys:
        cache.put(key, RESULT, STATE)
    size = pc.status(store).bytes // 5
    assert pc.status(store).entries == 5 and pc.status(store).max_bytes == pc.DEFAULT_MAX_BYTES
    with store.engine.begin() as conn:  # make the use order explicit: keys[0] oldest ... keys[4] newest
        for age, key in enumerate(keys):
            conn.execute(update(PhysicsCacheEntry).where(PhysicsCacheEntry.key == key).values(last_used=datetime(2026, 1, 1 + age)))
    dry = pc.prune(store, limit=2 * size, dry_run=True)
    assert (dry.removed, dry.kept, pc.status(store).entries) == (3, 2, 5)
    pc.set_max_bytes(store, 2 * size)
    done = pc.prune(store)
    assert (done.removed, done.kept, done.kept_bytes) == (3, 2, 2 * size)
    assert [cache.get(k) is not None for k in keys] == [False, False, False, True, True]
    assert pc.prune(store, limit=0).kept == 0 and pc.status(store).entries == 0


def _row(t):
    """What an episode decided and observed, without ids, times and provenance."""
    return (t.source, t.spec, t.features, t.outcome, t.solved, t.sim_steps, t.seed)


@pytest.mark.slow
def test_episodes_record_the_same_trials_without_the_cache_from_a_cold_one_and_from_a_warm_one(tmp_path: Path) -> None:
    with Store.open(str(tmp_path / "cache.db"), create=True) as store:
        cache = pc.StorePhysicsCache(store.engine)
        pretrain(store, branch="main", n=6, seed=3)
        # An episode that re-plans after exploration (plan trials start from exploration's
        # end states): the first of a few seeds whose episode does, as the goal head decides.
        for seed in range(6):
            config = SolveConfig(scenario="scenario2", budget=8, seed=seed)
            store.create_branch(f"plain{seed}", from_branch="main", at="pretrain")
            plain = solve(store, branch=f"plain{seed}", config=config)
            sources = [t.source for t in store.visible_trials(f"plain{seed}") if t.source != "pretrain"]
            if "plan" in sources[sources.index("exploration") :]:
                break
        else:
            pytest.fail("no seed of 0-5 re-plans after exploration in scenario 2")
        for name in ("cold", "warm"):
            store.create_branch(name, from_branch="main", at="pretrain")
        cold = solve(store, branch="cold", config=config, cache=cache)
        simulated = cache.counts.misses
        warm = solve(store, branch="warm", config=config, cache=pc.StorePhysicsCache(store.engine))  # a later run
        trials = {n: [t for t in store.visible_trials(b) if t.source != "pretrain"] for n, b in (("plain", f"plain{seed}"), ("cold", "cold"), ("warm", "warm"))}
        recorded_hits = pc.status(store).hits  # written back when the episode ended
    assert plain.exploration_trials == cold.exploration_trials == warm.exploration_trials > 0
    assert plain.status == cold.status == warm.status
    assert [_row(t) for t in trials["plain"]] == [_row(t) for t in trials["cold"]] == [_row(t) for t in trials["warm"]]
    assert simulated == len(trials["cold"]) and cache.counts.stored == simulated
    assert (plain.cache_hits, cold.cache_hits, warm.cache_hits) == (0, 0, len(trials["warm"])) == (0, 0, recorded_hits)
    assert not any(t.cache_hit for t in trials["plain"] + trials["cold"]) and all(t.cache_hit for t in trials["warm"])
    for first, again in zip(trials["cold"], trials["warm"], strict=True):
        # honest clocks: the original simulation's time is kept apart from this run's lookup
        assert first.simulation_wall_seconds == first.wall_seconds
        assert again.simulation_wall_seconds == pytest.approx(first.wall_seconds, rel=1e-9)
        assert again.wall_seconds != again.simulation_wall_seconds


def test_a_later_process_restores_sealed_end_states_without_checking_them(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from llcps.sim import snapshot
    from llcps.sim import world as world_module

    config = SolveConfig(scenario="scenario2", budget=6, seed=2)
    with Store.open(str(tmp_path / "sealed.db"), create=True) as store:
        pretrain(store, branch="main", n=4, seed=1)
        for name in ("cold", "warm"):
            store.create_branch(name, from_branch="main", at="pretrain")
        solve(store, branch="cold", config=config, cache=pc.StorePhysicsCache(store.engine))
        snapshot.TRUSTED.clear()  # what a new process knows

        def no_probe(*args: object, **kwargs: object) -> None:
            raise AssertionError("a sealed end state was probed")

        monkeypatch.setattr(world_module, "probe_states", no_probe)
        warm = solve(store, branch="warm", config=config, cache=pc.StorePhysicsCache(store.engine))
        trials = {n: [_row(t) for t in store.visible_trials(n) if t.source != "pretrain"] for n in ("cold", "warm")}
    assert warm.cache_hits == len(trials["warm"]) > 0
    assert trials["warm"] == trials["cold"]


def test_workers_on_a_cluster_share_no_sqlite_file(store: Store) -> None:
    from llcps.experiments.runner import cache_url

    url = store.engine.url.render_as_string(hide_password=False)
    assert cache_url(store) == url
    if store.engine.dialect.name == "sqlite":
        assert cache_url(store, remote_workers=True) is None  # the file is on this machine only
    else:
        assert cache_url(store, remote_workers=True) == url  # a server serves every worker
