"""What a trial's physics depends on besides the scene, the state and the call:
the engine, its version and settings, and the revision of llcps's controllers."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as package_version
from typing import Any

from llcps.sim.bullet import pybullet as p


def _engine_version() -> str:
    """PyBullet's package version and API date: a new engine may compute other physics."""
    try:
        release = package_version("pybullet")
    except PackageNotFoundError:  # pragma: no cover - a source build
        release = "unknown"
    return f"pybullet {release} api {p.getAPIVersion()}"


#: Revision of llcps's own controllers, motion primitives, robot model and perception.
#: Raise it with any change that alters what a trial computes from the same scene,
#: state and call: the physics cache keys every trial by it (together with the
#: engine's settings), so trials simulated by older code are never reused.
CONTROLLERS_REVISION = 1


@dataclass(frozen=True)
class PhysicsSettings:
    """Everything besides the scene, the state and the call that a trial's physics depends on.

    A :class:`World` owns one; the physics cache keys every trial by it, so a change
    of any field (a new engine, other solver settings, a revised controller) can
    never be answered from trials simulated under the old one.

    Attributes:
        time_step: seconds per simulation step.
        solver_iterations: the constraint solver's iterations per step.
        sub_steps: engine sub-steps per step (0: none).
        deterministic_overlapping_pairs: sort broad-phase pairs (needed for bit-exact replay).
        gravity: m/s^2 along x, y, z.
        engine: the physics engine's version.
        controllers: :data:`CONTROLLERS_REVISION`, the revision of
            llcps's own controllers, motion primitives and perception.
    """

    time_step: float = 1.0 / 240.0
    solver_iterations: int = 50
    sub_steps: int = 0
    deterministic_overlapping_pairs: bool = True
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    engine: str = field(default_factory=_engine_version)
    controllers: int = CONTROLLERS_REVISION

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able form (the cache key hashes it)."""
        data = asdict(self)
        data["gravity"] = list(self.gravity)
        return data
