"""The learned exploration policy: a candidate scorer trained with sb3-contrib's MaskablePPO,
and how it is kept without pickle.

**The network.** One small MLP scores every candidate row of the observation
(:mod:`llcps.cps.observation`) together with the failure features: the same weights for
every row, so the policy does not depend on where a candidate stands in the table and
carries over to scenes with other candidates. The scores are the action logits
(:class:`CandidatePolicy` has no other action layer); the value head reads them through
one small layer. MaskablePPO masks the candidates tried already and the padding rows.

**Keeping it.** The policy's ``state_dict`` is written as plain arrays in the world
models' artifact format (:mod:`llcps.models.artifact`: a zip of ``.npy`` files, read
with ``allow_pickle=False``), with its settings in a JSON ``meta``; in the store beside
the world models (name :data:`POLICY_NAME`) or in a file. stable-baselines3's own
``save``/``load`` pickle parts of the agent, so they are not used.

Loads torch and stable-baselines3: import it only where a policy is trained or used.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib.common.maskable.policies import MaskableMultiInputActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from llcps.cps.observation import CANDIDATE_FEATURES, FAILURE_FEATURES, MAX_CANDIDATES, action_space, observation_space
from llcps.errors import LlcpsError
from llcps.models.artifact import pack_arrays, unpack_arrays
from llcps.store.model_artifacts import POLICY_NAME

#: ``meta["format"]`` of a stored policy, and the version this code reads.
POLICY_FORMAT = "llcps-policy"
POLICY_VERSION = 1
#: Hidden units of the candidate scorer's layers.
DEFAULT_HIDDEN = (32, 32)


class CandidateScorer(BaseFeaturesExtractor):
    """Scores each candidate row with one MLP over (row, failure features): (batch, MAX_CANDIDATES)."""

    def __init__(self, observation_space: spaces.Dict, hidden: tuple[int, ...] = DEFAULT_HIDDEN) -> None:
        super().__init__(observation_space, features_dim=MAX_CANDIDATES)
        layers: list[nn.Module] = []
        width = CANDIDATE_FEATURES + FAILURE_FEATURES
        for units in hidden:
            layers += [nn.Linear(width, units), nn.Tanh()]
            width = units
        layers.append(nn.Linear(width, 1))
        self.net = nn.Sequential(*layers)

    def forward(self, observations: Mapping[str, torch.Tensor]) -> torch.Tensor:
        candidates = observations["candidates"]
        failure = observations["failure"].unsqueeze(1).expand(-1, candidates.shape[1], -1)
        return self.net(torch.cat([candidates, failure], dim=-1)).squeeze(-1)


class CandidatePolicy(MaskableMultiInputActorCriticPolicy):
    """MaskablePPO's actor-critic with the candidate scores as the action logits."""

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        self.action_net = nn.Identity()
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)


def policy_kwargs(hidden: tuple[int, ...] = DEFAULT_HIDDEN) -> dict[str, Any]:
    """What MaskablePPO builds :class:`CandidatePolicy` with."""
    return {
        "features_extractor_class": CandidateScorer,
        "features_extractor_kwargs": {"hidden": tuple(hidden)},
        "net_arch": {"pi": [], "vf": [16]},
        "share_features_extractor": True,
    }


def new_policy(hidden: tuple[int, ...] = DEFAULT_HIDDEN) -> CandidatePolicy:
    """An untrained policy (for loading weights into)."""
    return CandidatePolicy(observation_space(), action_space(), lambda _: 0.0, **policy_kwargs(hidden))


@dataclass(frozen=True)
class PolicyArtifact:
    """A policy's weights as plain arrays and its JSON-able settings."""

    data: bytes
    meta: dict[str, Any]


def export_policy(policy: CandidatePolicy, *, hidden: tuple[int, ...], info: Mapping[str, Any]) -> PolicyArtifact:
    """The policy's weights in the safe artifact format, with ``info`` (the training run) in its meta."""
    arrays = {f"policy/{key}": value.detach().cpu().numpy() for key, value in policy.state_dict().items()}
    data = pack_arrays(arrays)
    meta = {
        "format": POLICY_FORMAT,
        "version": POLICY_VERSION,
        "hidden": list(hidden),
        "max_candidates": MAX_CANDIDATES,
        "candidate_features": CANDIDATE_FEATURES,
        "failure_features": FAILURE_FEATURES,
        "sha256": hashlib.sha256(data).hexdigest(),
        **dict(info),
    }
    return PolicyArtifact(data, meta)


def import_policy(data: bytes, meta: Mapping[str, Any]) -> CandidatePolicy:
    """Rebuild a policy from :func:`export_policy` output; nothing in it is executed.

    Raises:
        LlcpsError: not an intact policy of this observation's shapes.
    """
    hint = "train the policy again (`llcps rl train`)"
    if not isinstance(meta, Mapping) or meta.get("format") != POLICY_FORMAT or meta.get("version") != POLICY_VERSION:
        raise LlcpsError("not an llcps policy artifact (format or version)", hint=hint)
    shapes = (meta.get("max_candidates"), meta.get("candidate_features"), meta.get("failure_features"))
    if shapes != (MAX_CANDIDATES, CANDIDATE_FEATURES, FAILURE_FEATURES):
        raise LlcpsError(f"the policy was trained on observations of shape {shapes}, not of this llcps's", hint=hint)
    if hashlib.sha256(bytes(data)).hexdigest() != meta.get("sha256"):
        raise LlcpsError("the policy artifact is corrupt (checksum mismatch)", hint=hint)
    hidden = meta.get("hidden")
    if not isinstance(hidden, list) or not 1 <= len(hidden) <= 8 or not all(isinstance(h, int) and 1 <= h <= 4096 for h in hidden):
        raise LlcpsError("the policy artifact's hidden layers are malformed", hint=hint)
    policy = new_policy(tuple(hidden))
    arrays = unpack_arrays(bytes(data))
    state = policy.state_dict()
    if set(arrays) != {f"policy/{key}" for key in state}:
        raise LlcpsError("the policy artifact's arrays do not match the network", hint=hint)
    loaded = {}
    for key, value in state.items():
        array = arrays[f"policy/{key}"]
        if array.shape != tuple(value.shape) or array.dtype.kind not in "fiu" or not np.all(np.isfinite(array)):
            raise LlcpsError(f"the policy artifact's array {key!r} is malformed", hint=hint)
        loaded[key] = torch.as_tensor(array, dtype=value.dtype)
    policy.load_state_dict(loaded)
    policy.set_training_mode(False)
    return policy


def write_policy_file(artifact: PolicyArtifact) -> bytes:
    """One file's bytes: the arrays and the meta (as a JSON byte array) in one archive."""
    arrays = unpack_arrays(artifact.data)
    arrays["meta"] = np.frombuffer(json.dumps(artifact.meta, sort_keys=True).encode(), dtype=np.uint8)
    return pack_arrays(arrays)


def read_policy_file(data: bytes) -> PolicyArtifact:
    """The artifact of a file written by :func:`write_policy_file`.

    Raises:
        LlcpsError: not such a file.
    """
    arrays = unpack_arrays(data)
    raw = arrays.pop("meta", None)
    if raw is None or raw.dtype != np.uint8 or raw.ndim != 1 or raw.size > 1 << 20:
        raise LlcpsError("not an llcps policy file (no meta)", hint="write one with `llcps rl train --out FILE`")
    try:
        meta = json.loads(raw.tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise LlcpsError("not an llcps policy file (its meta is not JSON)") from None
    if not isinstance(meta, dict):
        raise LlcpsError("not an llcps policy file (its meta is not an object)")
    return PolicyArtifact(pack_arrays(arrays), meta)


def action_probabilities(policy: CandidatePolicy, observation: Mapping[str, np.ndarray], mask: np.ndarray) -> np.ndarray:
    """The policy's probability of each candidate row (0 where ``mask`` is False)."""
    obs = {key: torch.as_tensor(np.asarray(value, dtype=np.float32))[None] for key, value in observation.items()}
    with torch.no_grad():
        distribution = policy.get_distribution(obs, action_masks=np.asarray(mask, dtype=bool)[None])
        probs = distribution.distribution.probs[0].cpu().numpy().astype(np.float64)
    return np.where(mask, probs, 0.0)


def load_stored_policy(store: Any, branch: str) -> tuple[CandidatePolicy, dict[str, Any]] | None:
    """The newest policy stored on ``branch`` (or a branch it descends from) and its
    meta; None if there is none.

    Raises:
        LlcpsError: the stored policy is not intact.
    """
    stored = store.latest_world_model(branch, POLICY_NAME, 0)
    return None if stored is None else (import_policy(stored.artifact, stored.meta), dict(stored.meta))
