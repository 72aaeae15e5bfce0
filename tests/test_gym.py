"""The Gymnasium environment llcps/Explore-v0: Gymnasium's own checks, determinism, and
its trials in the store."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")

import llcps.gym  # noqa: E402  (registers llcps/Explore-v0)
from llcps.cps.observation import CANDIDATE_FEATURE_NAMES, MAX_CANDIDATES  # noqa: E402
from llcps.errors import LlcpsError  # noqa: E402
from llcps.store import Store  # noqa: E402


@pytest.mark.parametrize("scenario", ["scenario2", "scenario3"])
def test_the_environment_passes_gymnasiums_checker(scenario: str, tmp_path: Path) -> None:
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(llcps.gym.ENV_ID, scenario=scenario, db=str(tmp_path / "gym.db"), budget=8)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        obs, info = env.reset(seed=1)
        assert obs["candidates"].shape == (MAX_CANDIDATES, len(CANDIDATE_FEATURE_NAMES))
        mask = env.unwrapped.action_masks()
        assert mask.sum() == info["candidates"] - info["refused"] > 0 and not mask[info["candidates"] :].any()
    finally:
        env.close()


def test_the_reach_check_masks_what_the_arm_would_refuse_as_the_agent_leaves_it_out(tmp_path: Path) -> None:
    """scenario2's bin is beyond the arm's top-down reach: every placement into it and removal
    from it is refused. Masked and shown as unavailable with the reach check (the default, as
    the agent's); offered without it. Choosing one anyway costs a trial and runs nothing."""
    from llcps.cps.observation import CANDIDATE_FEATURE_NAMES

    valid = CANDIDATE_FEATURE_NAMES.index("valid")
    seen = {}
    for check in (True, False):
        env = llcps.gym.ExploreEnv("scenario2", db=str(tmp_path / f"{check}.db"), budget=5, reach_check=check)
        try:
            obs, info = env.reset(seed=0)
            refused = sorted(env._site.point.refused)
            mask = env.action_masks()
            seen[check] = (info["candidates"], refused, int(mask.sum()), float(obs["candidates"][refused, valid].sum()) if refused else 0.0)
            if check:
                _, _, _, _, step = env.step(refused[0])
                assert step["valid"] is False and env.last_trial_id is None
        finally:
            env.close()
    (n, refused, offered, shown), (n_off, refused_off, offered_off, _) = seen[True], seen[False]
    assert n == n_off and len(refused) == 143 and refused_off == []
    assert (offered, shown) == (n - len(refused), 0.0) and offered_off == n
    with Store.open(str(tmp_path / "True.db")) as store:
        assert not [t for t in store.visible_trials(None) if t.source == "gym"]


def _rollout(db: Path, seed: int, steps: int) -> list[tuple[object, ...]]:
    """A random policy over the unmasked candidates, seeded; what each step did."""
    env = gymnasium.make(llcps.gym.ENV_ID, scenario="scenario2", db=str(db), budget=steps)
    rng = np.random.default_rng(seed)
    out = []
    try:
        env.reset(seed=seed)
        for _ in range(steps):
            action = int(rng.choice(np.flatnonzero(env.unwrapped.action_masks())))
            _, reward, terminated, truncated, _ = env.step(action)
            out.append((action, reward, terminated, truncated))
            if terminated or truncated:
                break
    finally:
        env.close()
    with Store.open(str(db)) as store:
        trials = [t for t in store.visible_trials(None) if t.source == "gym"]
    assert len(trials) == len(out)  # every step's trial is stored, with source gym
    outcomes = [(t.spec, t.outcome.bits(), t.sim_steps) for t in trials]
    return [(a, r, t or u, o) for (a, r, t, u), o in zip(out, outcomes)]


def test_a_seeded_random_policy_takes_the_same_trials_twice_and_stores_them(tmp_path: Path) -> None:
    first = _rollout(tmp_path / "a.db", seed=3, steps=6)
    second = _rollout(tmp_path / "b.db", seed=3, steps=6)
    assert first == second
    assert len(first) == 6 or first[-1][2]


def test_a_masked_action_costs_a_trial_and_stores_nothing(tmp_path: Path) -> None:
    env = gymnasium.make(llcps.gym.ENV_ID, scenario="scenario2", db=str(tmp_path / "gym.db"), budget=3, trial_cost=0.25)
    try:
        _, info = env.reset(seed=0)
        _, reward, terminated, _, info = env.step(MAX_CANDIDATES - 1)  # a padding row
        assert (reward, terminated, info["valid"]) == (-0.25, False, False)
        assert env.unwrapped.last_trial_id is None
    finally:
        env.close()
    with Store.open(str(tmp_path / "gym.db")) as store:
        assert not [t for t in store.visible_trials(None) if t.source == "gym"]


def test_bad_settings_are_refused_before_anything_runs(tmp_path: Path) -> None:
    for kwargs in ({"budget": 0}, {"trial_cost": -1.0}, {"scenario": "no-such"}, {"variant": -1}):
        with pytest.raises(LlcpsError):
            llcps.gym.ExploreEnv(**{"scenario": "scenario2", "db": str(tmp_path / "x.db"), **kwargs})


@pytest.mark.slow
def test_a_smoke_training_run_stores_a_policy_that_loads_without_pickle(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import pickle

    import torch

    from llcps.cps import policy as policies
    from llcps.jobs.rl import train

    import tempfile

    db, out, scratch = tmp_path / "rl.db", tmp_path / "policy.npz", tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))  # where a library would leave its files
    result = train(store=str(db), scenarios=["scenario2"], timesteps=192, budget=10, seed=0, out=out, create=True)
    assert not list(scratch.glob("SB3-*")), "training leaves no log folder behind"
    assert result.timesteps >= 192 and result.episodes and all(1 <= e.trials <= 10 for e in result.episodes)
    assert sum(e.trials for e in result.episodes) <= result.timesteps

    def no_unpickling(*args: object, **kwargs: object) -> None:
        raise AssertionError("a policy must load without pickle")

    monkeypatch.setattr(pickle, "loads", no_unpickling)
    monkeypatch.setattr(pickle, "load", no_unpickling)
    with Store.open(str(db)) as store:
        found = policies.load_stored_policy(store, "main")
    assert found is not None
    stored, meta = found
    assert meta["budget"] == 10
    from_file = policies.read_policy_file(out.read_bytes())
    loaded = policies.import_policy(from_file.data, from_file.meta)
    for a, b in zip(stored.state_dict().values(), loaded.state_dict().values()):
        assert torch.equal(a, b)
    assert from_file.meta["timesteps"] == result.timesteps and from_file.meta["episodes"] == len(result.episodes)
    # A damaged file is refused with an error, never executed.
    broken = bytearray(out.read_bytes())
    broken[len(broken) // 2] ^= 0xFF
    with pytest.raises(LlcpsError):
        art = policies.read_policy_file(bytes(broken))
        policies.import_policy(art.data, art.meta)
