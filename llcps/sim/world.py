"""The simulated world: one PyBullet client holding the floor, the table, the
robot, scenario fixtures and the entities, with deterministic engine settings and
in-memory / serialized snapshots.

A :class:`SceneSpec` is a JSON-able description from which :meth:`World.from_scene`
rebuilds the same bodies in the same order, so a physics state saved in one
process can be restored in another (``serialize_state`` / ``restore_serialized``)
and stepping from it gives bit-identical results.
"""

from __future__ import annotations

import functools
import math
import os
import sys
import zlib
from typing import Any, Callable, Mapping, Sequence

from llcps.errors import LlcpsError, UnknownNameError
from llcps.sim import snapshot as snapshots
from llcps.sim.bodies import Entity, build_entity, build_fixture
from llcps.sim.bullet import pybullet as p
from llcps.sim.connection import POOL, ConnectionPool
from llcps.sim.robot import Robot
from llcps.sim.settings import PhysicsSettings
from llcps.sim.specs import FIXTURE_RGBA, FLOOR, TABLE, FixtureSpec, SceneSpec
from llcps.sim.state_check import check_state

#: zlib level of serialized states (a scene's state shrinks from ~90 kB to ~40 kB in ~1 ms).
STATE_COMPRESSION = 3

#: Simulation steps a probe takes after restoring, to see that stepping survives too.
PROBE_STEPS = 4

#: Rest thresholds used by :meth:`World.settle` and the controllers.
REST_LINEAR = 0.005  # m/s
REST_ANGULAR = 0.05  # rad/s
REST_CHECK_EVERY = 8  # steps between rest checks
REST_CHECKS = 3  # consecutive quiet checks that count as rest
#: Cap on the steps a scene gets to settle (:meth:`World.settle`) before anything runs in it
#: (2 s at 240 Hz): a solve, a scene picture and a pretraining layout settle alike.
SETTLE_STEPS = 480


class SavedState:
    """A physics state this process saved (:meth:`World.save`): its raw ``.bullet``
    bytes, and :attr:`serialized`, what :meth:`World.serialize_state` would give,
    compressed only when first asked for (most saved states are only restored)."""

    __slots__ = ("raw", "_serialized")

    def __init__(self, raw: bytes) -> None:
        self.raw = raw
        self._serialized: bytes | None = None

    @property
    def serialized(self) -> bytes:
        if self._serialized is None:
            self._serialized = zlib.compress(self.raw, STATE_COMPRESSION)
        return self._serialized


class World:
    """One PyBullet client and everything in it.

    Attributes:
        client: the BulletClient (DIRECT unless ``gui``) of the world's connection, taken
            from ``pool`` (:data:`llcps.sim.connection.POOL` unless given) and given back
            to it by :meth:`close`.
        scene: the description this world was built from.
        settings: the engine settings every rebuild applies.
        robot: the Panda.
        entities: entities by name (objects and containers).
        fixtures: static bodies by name: "table", "floor" and the scene's fixtures.
        visuals: whether the robot's visual meshes are loaded (only rendering needs them).
    """

    def __init__(
        self,
        *,
        gui: bool = False,
        settings: PhysicsSettings | None = None,
        scene: SceneSpec | Mapping[str, Any] | None = None,
        visuals: bool = False,
        pool: ConnectionPool | None = None,
    ) -> None:
        if gui and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
            raise LlcpsError(
                "cannot open a GUI window: no display", hint="unset --gui, or run under a desktop / xvfb-run"
            )
        self._pool = pool if pool is not None else POOL
        self._connection = self._pool.connect(gui=gui)
        self.client = self._connection.client
        cid = self.client._client
        self._step = functools.partial(p.stepSimulation, physicsClientId=cid)
        self._velocity = functools.partial(p.getBaseVelocity, physicsClientId=cid)
        self.gui = gui
        self.visuals = visuals or gui
        self.settings = settings if settings is not None else PhysicsSettings()
        self.entities: dict[str, Entity] = {}
        self.fixtures: dict[str, int] = {}
        self.names: dict[int, str] = {}
        self._observers: list[Callable[["World"], None]] = []
        self._snapshots: dict[int, bytes] = {}
        self._snapshot_count = 0
        # (serialized state, scene key, raw bytes) of the last state check_serialized passed
        self._last_checked: tuple[bytes, str, bytes] | None = None
        # (scene key, raw bytes) of the reference state last taken (reference_state)
        self._reference: tuple[str, bytes] | None = None
        self._closed = False
        self.load(scene if scene is not None else SceneSpec())

    @classmethod
    def from_scene(
        cls,
        scene: SceneSpec | Mapping[str, Any],
        *,
        gui: bool = False,
        visuals: bool = False,
        settings: PhysicsSettings | None = None,
        pool: ConnectionPool | None = None,
    ) -> "World":
        """Build a world from a scene description (deterministic: same scene, same bodies).

        ``visuals`` loads the robot's visual meshes now; rendering loads them on demand
        anyway (:meth:`ensure_visuals`), and skipping them makes rebuilds four times faster.
        """
        return cls(gui=gui, scene=scene, visuals=visuals, settings=settings, pool=pool)

    @property
    def time_step(self) -> float:
        """Seconds per simulation step."""
        return self.settings.time_step

    # ------------------------------------------------------------------ building

    def load(self, scene: SceneSpec | Mapping[str, Any]) -> None:
        """Rebuild the whole simulation from ``scene`` (reset, then bodies in a fixed order)."""
        if not isinstance(scene, SceneSpec):
            scene = SceneSpec.from_dict(scene)
        c = self.client
        c.resetSimulation()
        settings = self.settings
        c.setPhysicsEngineParameter(
            fixedTimeStep=settings.time_step,
            numSubSteps=settings.sub_steps,
            deterministicOverlappingPairs=int(settings.deterministic_overlapping_pairs),
            numSolverIterations=settings.solver_iterations,
        )
        c.setGravity(*settings.gravity)
        if self.gui:
            c.configureDebugVisualizer(p.COV_ENABLE_GUI, 0)
        if scene is not getattr(self, "scene", None):  # a restore rebuilds the same scene: keep its digest
            self._scene_key = snapshots.scene_key(scene.to_dict())
        self.scene = scene
        self.entities = {}
        self.fixtures = {}
        table = scene.table
        floor_col = c.createCollisionShape(p.GEOM_PLANE)
        floor_vis = c.createVisualShape(p.GEOM_BOX, halfExtents=(3, 3, 0.001), rgbaColor=FIXTURE_RGBA["floor"])
        self.fixtures[FLOOR] = c.createMultiBody(0.0, floor_col, floor_vis, basePosition=(0.0, 0.0, table.floor_z))
        self.fixtures[TABLE] = build_fixture(
            c,
            FixtureSpec(
                TABLE,
                (table.x_max - table.x_min, 2 * table.y_half, table.height),
                ((table.x_max + table.x_min) / 2, 0.0, -table.height / 2),
                color="wood",
            ),
        )
        if table.friction is not None:
            c.changeDynamics(self.fixtures[TABLE], -1, lateralFriction=table.friction)
        c.changeDynamics(self.fixtures[FLOOR], -1, lateralFriction=0.6, restitution=0.0)
        for spec in scene.fixtures:
            self.fixtures[spec.name] = build_fixture(c, spec)
        self.robot = Robot(c, visuals=self.visuals, reach=self._connection.reach, grip_force=scene.robot.grip_force, top_down_reach=scene.robot.reach)
        for link in (-1, 0):  # the base and shoulder stand on the table and never leave it
            c.setCollisionFilterPair(self.robot.body_id, self.fixtures[TABLE], link, -1, 0)
        for spec in scene.entities:
            self.entities[spec.name] = build_entity(c, spec)
        self.names = {body: name for name, body in self.fixtures.items()}
        self.names.update({e.body_id: name for name, e in self.entities.items()})
        self.sim_steps = 0

    # ------------------------------------------------------------------ lookup

    def entity(self, name: str) -> Entity:
        try:
            return self.entities[name]
        except KeyError:
            raise UnknownNameError("entity", name, sorted(self.entities)) from None

    def body(self, name: str) -> int:
        """Body id of an entity or fixture by name."""
        if name in self.entities:
            return self.entities[name].body_id
        if name in self.fixtures:
            return self.fixtures[name]
        raise UnknownNameError("entity", name, sorted(self.entities) + sorted(self.fixtures))

    def center(self, name: str) -> tuple[float, float, float]:
        """World position of an entity's bounding-box centre."""
        e = self.entity(name)
        pos, orn = self.client.getBasePositionAndOrientation(e.body_id)
        if e.com_offset == (0.0, 0.0, 0.0):
            return pos
        off = self.client.multiplyTransforms((0, 0, 0), orn, [-v for v in e.com_offset], (0, 0, 0, 1))[0]
        return (pos[0] + off[0], pos[1] + off[1], pos[2] + off[2])

    def pose(self, name: str) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """Bounding-box centre and orientation of an entity."""
        e = self.entity(name)
        return self.center(name), self.client.getBasePositionAndOrientation(e.body_id)[1]

    def aabb(self, name: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """World axis-aligned bounding box of an entity or fixture."""
        return self.client.getAABB(self.body(name))

    # ------------------------------------------------------------------ stepping

    def add_observer(self, fn: Callable[["World"], None]) -> None:
        """Call ``fn(world)`` after every simulation step (frame recorders use this)."""
        self._observers.append(fn)

    def remove_observer(self, fn: Callable[["World"], None]) -> None:
        self._observers.remove(fn)

    def step(self, n: int = 1) -> None:
        """Advance the simulation ``n`` fixed time steps."""
        observers = self._observers
        if n == 1 and not observers:  # the controllers' hot path
            self._step()
            self.sim_steps += 1
            return
        step = self._step
        for _ in range(n):
            step()
            self.sim_steps += 1
            if observers:
                for fn in observers:
                    fn(self)

    def at_rest(self) -> bool:
        """Whether every entity is (nearly) still."""
        get = self._velocity
        for e in self.entities.values():
            lin, ang = get(e.body_id)
            if (
                lin[0] * lin[0] + lin[1] * lin[1] + lin[2] * lin[2] > REST_LINEAR * REST_LINEAR
                or ang[0] * ang[0] + ang[1] * ang[1] + ang[2] * ang[2] > REST_ANGULAR * REST_ANGULAR
            ):
                return False
        return True

    def settle(self, *, max_steps: int, min_steps: int = 0) -> int:
        """Step with the robot holding still until every entity is at rest, or ``max_steps``.

        Args:
            max_steps: the cap.
            min_steps: steps always taken first (slow topples start at rest).

        Returns:
            The number of steps taken.
        """
        taken = min(min_steps, max_steps)
        self.step(taken)
        quiet = 0
        while taken < max_steps:
            n = min(REST_CHECK_EVERY, max_steps - taken)
            self.step(n)
            taken += n
            quiet = quiet + 1 if self.at_rest() else 0
            if quiet >= REST_CHECKS:
                break
        return taken

    # ------------------------------------------------------------------ snapshots
    #
    # Restoring rebuilds the engine from the scene before loading the saved state.
    # The engine keeps history that a saved state does not hold (the order of its
    # contact manifolds, warm-starting data of constraints that came and went), and
    # that history changes what the next steps compute. A world restored this way
    # is the same as a fresh process's World.from_scene(scene) + restore_serialized:
    # trials replay bit for bit anywhere. It costs a rebuild and a read of the state
    # file (about 12 ms without visual meshes) instead of an in-place restoreState.

    def snapshot(self) -> int:
        """Save the physics state in memory; returns a handle for :meth:`restore`.

        Like :meth:`serialize_state`, the world then continues from the saved copy.
        """
        self._snapshot_count += 1
        self._snapshots[self._snapshot_count] = self.serialize_state()
        return self._snapshot_count

    def restore(self, snap: int) -> None:
        """Return to a state saved by :meth:`snapshot` (see restore_serialized)."""
        try:
            state = self._snapshots[snap]
        except KeyError:
            raise LlcpsError(f"unknown snapshot {snap}", hint="use a handle returned by World.snapshot()") from None
        self.restore_serialized(state)

    def discard(self, snap: int) -> None:
        """Forget an in-memory snapshot."""
        self._snapshots.pop(snap, None)

    def serialize_state(self) -> bytes:
        """The current physics state as bytes (a zlib-compressed .bullet file), for the experience store.

        The world then continues from exactly these bytes (it is restored from
        them), so whatever runs next replays bit for bit from the stored state in
        any process. A grasp is not part of the state: take snapshots between trials.
        The state is remembered as trusted, so restoring it skips the checks.
        """
        saved = self.save()
        self.restore_saved(saved)
        return saved.serialized

    @property
    def scene_key(self) -> str:
        """A digest of the scene this world is built from (what its states belong to)."""
        return self._scene_key

    def save_state(self) -> bytes:
        """The current physics state as :meth:`serialize_state` gives it, without continuing from it.

        The world goes on from its live state, which is not the same as the one a
        restore of these bytes gives (the engine keeps history a saved state does
        not hold). For callers that restore next anyway: an agent whose next step
        either restores another state or continues from exactly these bytes. The
        state is remembered as trusted, so restoring it skips the checks.
        """
        return self.save().serialized

    def save(self) -> SavedState:
        """:meth:`save_state` for a caller that may only restore it (:meth:`restore_saved`):
        the bytes are compressed only if asked for."""
        raw = self._save_raw()
        self._trust(raw)
        return SavedState(raw)

    def restore_saved(self, state: SavedState) -> None:
        """:meth:`restore_serialized` of a state :meth:`save` gave (in this process: no checks)."""
        self._restore_raw(state.raw)

    def restore_serialized(self, state: bytes, *, probe: bool = True) -> None:
        """Rebuild the scene and load a state made by :meth:`serialize_state` in a world
        built from the same scene (in this process or any other).

        Afterwards the world is exactly a fresh ``World.from_scene(scene)`` with the
        state restored; the motors hold the restored pose and nothing is grasped.
        A state this process did not make or check before goes through
        :meth:`check_serialized` first.

        Raises:
            StateError: the state is too large, malformed, or not one of this scene.
        """
        self._restore_raw(self.check_serialized(state, probe=probe))

    def check_serialized(self, state: bytes, *, probe: bool = True) -> bytes:
        """Check that an untrusted serialized state may be restored into this world's scene;
        returns its raw ``.bullet`` bytes.

        The state is inflated under a size cap, its structure is checked against the
        scene's (:func:`llcps.sim.snapshot.check_state`) and, with ``probe``, it is
        restored once in a child process first, so that a state that would crash the
        engine becomes a clean error (see :mod:`llcps.sim.snapshot`). A state this
        process made, or checked before, costs only its digest. The first check of a
        scene may rebuild the world from it (to take the reference state): restore a
        state afterwards.

        Raises:
            StateError: the state is too large, malformed, or not one of this scene.
        """
        last = self._last_checked
        if last is not None and last[0] is state and last[1] == self._scene_key:
            return last[2]  # the same bytes object as the last check: an episode restores its snapshot per trial
        raw = snapshots.decompress_state(state)
        key = (self._scene_key, snapshots.state_digest(raw))
        if key not in snapshots.TRUSTED:
            check_state(raw, self.reference_state())
            if probe:
                probe_states(self.scene.to_dict(), [raw])
            snapshots.TRUSTED.add(key)
        self._last_checked = (state, self._scene_key, raw)
        return raw

    def trust_serialized(self, state: bytes) -> None:
        """Remember a serialized state as safe to restore into this world's scene without checks.

        Only for a state vouched for by something the database cannot forge (the
        physics cache's seal); anything else goes through :meth:`check_serialized`.

        Raises:
            StateError: the state does not inflate within the size cap.
        """
        self._trust(snapshots.decompress_state(state))

    def reference_state(self) -> bytes:
        """The raw state of this world's scene freshly built: what a stored state is checked against.

        Taking it the first time (in this world, for this scene) rebuilds the world from
        its scene (the live state is lost).
        """
        if self._reference is None or self._reference[0] != self._scene_key:
            self.load(self.scene)
            self._reference = (self._scene_key, self._save_raw())
        return self._reference[1]

    def _trust(self, raw: bytes) -> None:
        """Remember a state this process saved: restoring it needs no checks."""
        snapshots.TRUSTED.add((self._scene_key, snapshots.state_digest(raw)))

    def _save_raw(self) -> bytes:
        files = self._connection.files
        self.client.saveBullet(files.save_path())
        return files.read_saved()

    def _restore_raw(self, raw: bytes) -> None:
        self.load(self.scene)
        try:
            self.client.restoreState(fileName=self._connection.files.restore_path(raw))
        except p.error as exc:
            raise snapshots.StateError(
                "cannot restore the physics state: it does not match this scene",
                hint="restore a state into World.from_scene(<the scene it was saved with>)",
            ) from exc
        # Motor targets are not part of a saved state: make them a function of it.
        self.robot.hold()

    def ensure_visuals(self) -> None:
        """Load the robot's visual meshes (for rendering) if this world was built without them.

        The physics is unchanged: visual shapes take no part in it.
        """
        if not self.visuals:
            self.visuals = True
            self.serialize_state()

    # ------------------------------------------------------------------ lifetime

    def close(self) -> None:
        """Let go of the engine. A headless engine is kept for the next world of this
        process, which rebuilds it from its own scene (:meth:`load` resets it)."""
        if not self._closed:
            self._closed = True
            self._pool.release(self._connection)

    def __enter__(self) -> "World":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass


def probe_states(
    scene: Mapping[str, Any], states: Sequence[bytes], *, timeout: float = snapshots.PROBE_TIMEOUT, check: bool = True
) -> None:
    """Restore each raw state into ``scene`` in a child process and step it a little
    (the third gate of :mod:`llcps.sim.snapshot`); one child serves every state given.

    Args:
        check: run :func:`~llcps.sim.state_check.check_state` in the child too (False
            only to test the probe itself).

    Raises:
        StateError: the child crashed, hung, ran out of memory or refused a state.
    """
    snapshots.probe(lambda: _restore_each(scene, states, check=check), timeout=timeout)


def _restore_each(scene: Mapping[str, Any], states: Sequence[bytes], *, check: bool) -> str:  # pragma: no cover
    """What the probe's child does: "" when every state restores and steps soundly, else why not."""
    world = World.from_scene(scene)
    for raw in states:
        try:
            if check:
                check_state(raw, world.reference_state())
            world._restore_raw(raw)  # noqa: SLF001 - the unchecked restore is what is probed
            world.step(PROBE_STEPS)
        except LlcpsError as exc:
            return exc.message
        for name in world.entities:
            position, orientation = world.client.getBasePositionAndOrientation(world.body(name))
            if not all(math.isfinite(v) for v in (*position, *orientation)):
                return f"entity {name} has no finite pose after the restore"
    world.close()
    return ""
