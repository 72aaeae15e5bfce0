"""Physics already computed, reused: a trial is a function of its inputs.

A world restored from a serialized state is the same in any process
(:meth:`~llcps.sim.world.World.restore_serialized`), so a trial started from the
same saved state, in the same scene, with the same controller call, step cap and
physics settings gives the same result bit for bit. An experiment grid asks that
question again and again: every sequence of a seed starts a scenario's
exploration from the same failure state, and the measures' orders overlap.

This module is the simulator's side of the physics cache: the key
(:func:`trial_key`, a digest of everything the physics depends on), the value
(:class:`CachedTrial`: the result and the state the trial ended in) and its
encoding as untrusted bytes (:func:`encode_result`, :func:`decode_result`). The
cache itself lives in the experience store (:mod:`llcps.store.physics_cache`),
shared by every worker of a run and by later runs; the agent only sees the
:class:`PhysicsCache` protocol.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any, Callable, Mapping, Protocol

from llcps import bounded_json
from llcps.domain import ACTIONS, ORIENTATIONS, ControllerParams, EntityFeatures
from llcps.trial_records import Body, Outcome, TrialSpec
from llcps.sim.result import TrialResult

if TYPE_CHECKING:
    from llcps.sim.settings import PhysicsSettings

#: Version of the key's layout; part of every key.
KEY_VERSION = 2  # 2: a result holds the scene's bodies (its symbolic change needs them)
#: Largest encoded result accepted (a result is a few kB: two symbolic states).
MAX_RESULT_BYTES = 1 << 20


def _canonical(value: Any) -> bytes:
    return json.dumps(value, sort_keys=True, separators=(",", ":")).encode()


def trial_key(
    settings: PhysicsSettings, scene: Mapping[str, Any], state: bytes, spec: TrialSpec, max_steps: int
) -> str:
    """The hex digest of everything a trial's physics depends on.

    Args:
        settings: the world's physics settings (time step, solver, gravity, engine,
            controllers' revision).
        scene: the scene description the world was built from.
        state: the serialized physics state the trial starts from.
        spec: the controller call.
        max_steps: the step cap the trial runs under.
    """
    h = hashlib.sha256()
    for part in (
        _canonical({"key": KEY_VERSION, "settings": settings.to_dict()}),
        _canonical(scene),
        state,
        _canonical({"spec": asdict(spec), "max_steps": int(max_steps)}),
    ):
        h.update(len(part).to_bytes(8, "big"))  # length-prefixed: no two inputs spell the same bytes
        h.update(part)
    return h.hexdigest()


@dataclass(frozen=True)
class CachedTrial:
    """A trial answered from the cache.

    Attributes:
        result: what the trial did; its ``wall_seconds`` are those of the simulation
            that computed it, not of this lookup.
        end_state: the serialized physics state the trial ended in.
    """

    result: TrialResult
    end_state: bytes


StateCheck = Callable[[bytes], object]
"""Raises :class:`~llcps.errors.LlcpsError` when an end state may not be restored."""

StateTrust = Callable[[bytes], object]
"""Marks an end state safe to restore without checks (it carries a valid seal)."""


class PhysicsCache(Protocol):
    """What the agent needs of a physics cache (see :mod:`llcps.store.physics_cache`)."""

    def get(self, key: str, *, check: StateCheck | None = None, trust: StateTrust | None = None) -> CachedTrial | None:
        """The trial stored under ``key``, or None (absent, or failed validation).

        ``check`` (the restoring world's :meth:`~llcps.sim.world.World.check_serialized`)
        is called on the end state too; an entry it refuses counts as absent and is
        replaced by the next simulation of its key. An entry the cache can vouch for
        (a seal, see :mod:`llcps.store.physics_cache`) gets ``trust`` (the world's
        :meth:`~llcps.sim.world.World.trust_serialized`) instead.
        """

    def put(self, key: str, result: TrialResult, end_state: bytes) -> None:
        """Keep a simulated trial; a key already present is left as it is."""

    def flush(self) -> None:
        """Write back any bookkeeping held in memory (an episode ends)."""


# ----------------------------------------------------------------------------- encoding
def encode_result(result: TrialResult) -> bytes:
    """A trial's result as canonical JSON bytes."""
    return _canonical(
        {
            "spec": asdict(result.spec),
            "features": [f.as_dict() for f in result.features],
            "before": sorted(list(f) for f in result.before),
            "after": sorted(list(f) for f in result.after),
            "outcome": list(result.outcome.bits()),
            "sim_steps": result.sim_steps,
            "wall_seconds": result.wall_seconds,
            "bodies": [b.as_dict() for b in result.bodies],
        }
    )


def _expect(condition: bool, what: str) -> None:
    if not condition:
        raise ValueError(what)


def _number(value: Any, what: str) -> float:
    _expect(isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value), what)
    return float(value)


def _state(value: Any) -> frozenset[tuple[str, ...]]:
    _expect(isinstance(value, list) and len(value) <= 10_000, "a state is a list of fluents")
    fluents = []
    for f in value:
        _expect(isinstance(f, list) and 1 <= len(f) <= 8 and all(isinstance(a, str) for a in f), "a fluent is a list of names")
        fluents.append(tuple(f))
    return frozenset(fluents)


def decode_result(data: bytes) -> TrialResult:
    """Read back :func:`encode_result`'s bytes, checking every field (they come from a database).

    Raises:
        ValueError: the bytes are not a well-formed result.
    """
    _expect(isinstance(data, (bytes, bytearray)) and len(data) <= MAX_RESULT_BYTES, "a result is at most 1 MiB")
    try:
        raw = bounded_json.loads(bytes(data))
    except ValueError as exc:
        raise ValueError(f"not JSON: {exc}") from None
    _expect(isinstance(raw, dict), "a result is an object")
    spec_raw, params = raw.get("spec"), (raw.get("spec") or {}).get("params") if isinstance(raw.get("spec"), dict) else None
    _expect(isinstance(spec_raw, dict) and isinstance(params, dict), "a result has a spec with params")
    action, arguments = spec_raw.get("action"), spec_raw.get("arguments")
    _expect(action in ACTIONS, "unknown action")
    _expect(isinstance(arguments, list) and all(isinstance(a, str) for a in arguments), "arguments are names")
    _expect(params.get("orientation") in ORIENTATIONS, "unknown orientation")
    spec = TrialSpec(
        action,
        tuple(arguments),
        ControllerParams(
            _number(params.get("rate"), "rate"),
            _number(params.get("movement_magnitude"), "movement_magnitude"),
            params["orientation"],
        ),
    )
    features_raw = raw.get("features")
    _expect(isinstance(features_raw, list) and len(features_raw) == len(arguments), "one feature set per argument")
    features = []
    for f in features_raw:
        _expect(isinstance(f, dict) and set(f) == set(EntityFeatures.__dataclass_fields__), "entity features")
        _expect(isinstance(f["shape"], str) and isinstance(f["color"], str), "shape and color are names")
        numbers = {k: _number(v, k) for k, v in f.items() if k not in ("shape", "color")}
        features.append(EntityFeatures(shape=f["shape"], color=f["color"], **numbers))
    outcome = raw.get("outcome")
    _expect(isinstance(outcome, list) and all(b in (0, 1) for b in outcome), "outcome bits")
    sim_steps = raw.get("sim_steps")
    _expect(isinstance(sim_steps, int) and not isinstance(sim_steps, bool) and sim_steps >= 0, "sim_steps")
    before, after = _state(raw.get("before")), _state(raw.get("after"))
    decoded = Outcome.from_bits(outcome)
    _expect(decoded == Outcome.between(before, after), "the outcome does not follow from the states")
    return TrialResult(
        spec=spec,
        features=tuple(features),
        before=before,
        after=after,
        outcome=decoded,
        sim_steps=sim_steps,
        wall_seconds=_number(raw.get("wall_seconds"), "wall_seconds"),
        bodies=_bodies(raw.get("bodies")),
    )


def _bodies(value: Any) -> tuple[Body, ...]:
    _expect(isinstance(value, list) and len(value) <= 1000, "bodies are a list")
    return tuple(Body.from_dict(item) for item in value)


__all__ = ["CachedTrial", "KEY_VERSION", "PhysicsCache", "StateCheck", "decode_result", "encode_result", "trial_key"]
