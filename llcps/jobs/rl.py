"""``llcps rl train``: train the exploration policy with MaskablePPO in ``llcps/Explore-v0``.

The agent explores the failure points of the given scenarios and variants, one RL
episode per novelty (:mod:`llcps.gym`), on CPU. Every trial it takes is stored
(source ``gym``); the trained policy is stored on the branch beside the world models
(the ``rl`` ordering uses the newest) and, with ``out``, written to a file, both as
plain arrays without pickle (:mod:`llcps.cps.policy`).

Needs the ``rl`` extra; nothing of it loads until the job runs.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

from llcps.errors import LlcpsError
from llcps.jobs._common import Progress, StoreRef, no_progress, opened
from llcps.outputs import check_output_file, written_atomically

#: Extensions of the policy files ``--out`` writes (a zip of .npy arrays).
POLICY_SUFFIXES: tuple[str, ...] = (".npz",)
#: Most environment steps one training run may take.
MAX_TIMESTEPS = 1_000_000
#: PPO's rollout length and minibatch (small: an episode is a few dozen steps).
N_STEPS = 64
BATCH_SIZE = 32


@dataclass(frozen=True)
class TrainedEpisode:
    """One training episode: where, how many trials, and whether the novelty was resolved."""

    scenario: str
    variant: int
    trials: int
    resolved: bool


@dataclass(frozen=True)
class TrainResult:
    """What a training run did and where the policy went.

    Attributes:
        episodes: every finished training episode, in order (the learning curve).
        timesteps: environment steps taken (trials, including masked actions).
        wall_seconds: wall time of the training, set-up included.
        policy_id: the stored policy's row (``world_models``, name ``rl-policy``).
        out: the file written, if any.
    """

    scenarios: list[str]
    variants: list[int]
    seed: int
    budget: int
    trial_cost: float
    reach_check: bool
    timesteps: int
    hidden: list[int]
    branch: str
    wall_seconds: float
    policy_id: int
    out: str | None
    episodes: list[TrainedEpisode] = field(default_factory=list)

    def curve(self, bins: int = 5) -> list[dict[str, float]]:
        """Mean trials per episode and share resolved, over ``bins`` consecutive blocks of episodes."""
        n = len(self.episodes)
        out = []
        for b in range(min(bins, n)):
            block = self.episodes[b * n // bins : (b + 1) * n // bins] if n >= bins else self.episodes[b : b + 1]
            if block:
                out.append(
                    {
                        "first_episode": b * n // bins + 1 if n >= bins else b + 1,
                        "episodes": len(block),
                        "mean_trials": sum(e.trials for e in block) / len(block),
                        "resolved": sum(e.resolved for e in block) / len(block),
                    }
                )
        return out

    def as_json(self) -> dict[str, Any]:
        data = asdict(self)
        data["curve"] = self.curve()
        data["wall_seconds"] = round(self.wall_seconds, 3)
        return data


def train(
    *,
    store: StoreRef,
    scenarios: Sequence[str],
    variants: Sequence[int] = (0,),
    timesteps: int = 512,
    seed: int = 0,
    budget: int = 50,
    trial_cost: float = 0.01,
    hidden: Sequence[int] | None = None,
    model: str | None = None,
    measure: str | None = None,
    reach_check: bool = True,
    branch: str | None = None,
    out: str | os.PathLike[str] | None = None,
    create: bool = False,
    progress: Progress = no_progress,
) -> TrainResult:
    """Train a MaskablePPO policy over the scenarios' failure points; see the module docstring.

    Raises:
        LlcpsError: bad settings (checked before the store is opened), or the rl extra missing.
    """
    from llcps.domain import check_seed
    from llcps.scenarios import get_scenario
    from llcps.scenarios.variants import check_variant

    if not scenarios:
        raise LlcpsError("name at least one scenario to train on", hint="e.g. --scenario scenario2")
    for name in scenarios:
        get_scenario(name)
    for v in variants:
        check_variant(v)
    if not 1 <= timesteps <= MAX_TIMESTEPS:
        raise LlcpsError(f"timesteps must be from 1 to {MAX_TIMESTEPS}, got {timesteps}")
    check_seed(seed)
    if out is not None:
        check_output_file(out, what="--out", suffixes=POLICY_SUFFIXES)
    try:
        import torch
        from sb3_contrib import MaskablePPO
        from stable_baselines3.common.callbacks import BaseCallback
        from stable_baselines3.common.logger import Logger

        from llcps.cps.policy import DEFAULT_HIDDEN, POLICY_NAME, CandidatePolicy, export_policy, policy_kwargs, write_policy_file
        from llcps.gym.env import ExploreEnv
    except ImportError as exc:
        raise LlcpsError(f"training a policy needs the rl extra ({exc.name} is missing)", hint="pip install 'llcps[rl]'") from None
    layers = tuple(DEFAULT_HIDDEN if hidden is None else hidden)
    if not 1 <= len(layers) <= 8 or not all(1 <= h <= 4096 for h in layers):
        raise LlcpsError(f"hidden layers must be 1 to 8 sizes from 1 to 4096, got {list(layers)}")
    settings = {k: v for k, v in {"model": model, "measure": measure}.items() if v is not None}
    started = time.perf_counter()
    with opened(store, create=create) as s:
        env = ExploreEnv(list(scenarios), variant=list(variants), db=s, branch=branch, budget=budget, trial_cost=trial_cost, seed=seed,
                         reach_check=reach_check, **settings)  # fmt: skip
        try:
            torch.set_num_threads(1)
            agent = MaskablePPO(
                CandidatePolicy,
                env,
                n_steps=N_STEPS,
                batch_size=BATCH_SIZE,
                n_epochs=4,
                learning_rate=3e-4,
                ent_coef=0.01,
                seed=seed,
                device="cpu",
                policy_kwargs=policy_kwargs(layers),
                verbose=0,
            )
            # Without a logger of its own, every learn() leaves an empty SB3-<time> folder in the temporary directory.
            agent.set_logger(Logger(folder=None, output_formats=[]))

            class _Report(BaseCallback):
                def _on_step(self) -> bool:
                    progress("train", self.num_timesteps, timesteps)
                    return True

            progress("set up the failure points", 0, timesteps)
            agent.learn(total_timesteps=timesteps, callback=_Report())
            history = list(env.history)
            branch_name = env.branch
        finally:
            env.close()
        wall = time.perf_counter() - started
        info = {
            "scenarios": [str(x) for x in scenarios],
            "variants": [int(v) for v in variants],
            "seed": seed,
            "budget": budget,
            "trial_cost": trial_cost,
            "reach_check": reach_check,
            "timesteps": int(agent.num_timesteps),
            "episodes": len(history),
            "wall_seconds": round(wall, 3),
        }
        artifact = export_policy(agent.policy, hidden=layers, info=info)
        policy_id = s.save_world_model(
            branch=branch_name, name=POLICY_NAME, seed=0, watermark=s.max_visible_trial_id(branch_name), artifact=artifact.data, meta=artifact.meta
        )
    if out is not None:
        with written_atomically(Path(out).expanduser(), what="--out") as target:
            target.write_bytes(write_policy_file(artifact))
    return TrainResult(
        scenarios=info["scenarios"],
        variants=info["variants"],
        seed=seed,
        budget=budget,
        trial_cost=trial_cost,
        reach_check=reach_check,
        timesteps=int(agent.num_timesteps),
        hidden=list(layers),
        branch=branch_name,
        wall_seconds=wall,
        policy_id=int(policy_id),
        out=None if out is None else os.fspath(out),
        episodes=[TrainedEpisode(e["scenario"], int(e["variant"]), int(e["trials"]), bool(e["resolved"])) for e in history],
    )


@dataclass(frozen=True)
class ImportResult:
    """A policy file stored on a branch: where, and what the file says it was trained on."""

    branch: str
    policy_id: int
    path: str
    watermark: int
    trained: dict[str, Any]

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


#: What a training run records in a policy's meta (shown by ``rl import``).
TRAINING_KEYS: tuple[str, ...] = ("scenarios", "variants", "seed", "budget", "trial_cost", "reach_check", "timesteps", "episodes", "wall_seconds")


def import_policy_file(*, store: StoreRef, path: str | os.PathLike[str], branch: str | None = None, create: bool = False) -> ImportResult:
    """Store a policy written by ``rl train --out`` on ``branch``, where the ``rl`` ordering
    (and an experiment's sequences forked from it) will use it.

    The file is checked as a policy of this llcps's observation shapes before anything is
    stored; its weights are loaded as plain arrays, never unpickled.

    Raises:
        LlcpsError: not a readable, intact policy file (nothing is stored), or the rl extra missing.
    """
    from llcps.inputs import read_user_file
    from llcps.store.model_artifacts import MAX_MODEL_BYTES

    hint = "give a file `llcps rl train --out FILE` wrote"
    data = read_user_file(path, what="policy file", max_bytes=MAX_MODEL_BYTES, hint=hint)
    try:
        from llcps.cps.policy import POLICY_NAME, import_policy, read_policy_file
    except ImportError as exc:
        raise LlcpsError(f"a policy needs the rl extra ({exc.name} is missing)", hint="pip install 'llcps[rl]'") from None
    try:
        artifact = read_policy_file(data)
        import_policy(artifact.data, artifact.meta)  # refuses a damaged or foreign policy
    except LlcpsError as exc:
        raise LlcpsError(f"{os.fspath(path)}: {exc.message}", hint=exc.hint or hint) from None
    with opened(store, create=create) as s:
        name = s.resolve_branch(branch).name
        watermark = s.max_visible_trial_id(name)
        policy_id = s.save_world_model(branch=name, name=POLICY_NAME, seed=0, watermark=watermark, artifact=artifact.data, meta=artifact.meta)
    trained = {k: artifact.meta[k] for k in TRAINING_KEYS if k in artifact.meta}
    return ImportResult(branch=name, policy_id=int(policy_id), path=os.fspath(path), watermark=int(watermark), trained=trained)
