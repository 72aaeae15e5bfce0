"""The robot: a Franka Emika Panda from ``pybullet_data``, driven by inverse
kinematics and joint position motors, with a two-finger gripper.

The base stands at the world origin facing +x. The *tool point* is the Panda's
``panda_grasptarget`` link, between the finger pads, 11 mm above the fingertips.
Every commanded motion is a tool-point target turned into joint targets by
PyBullet's IK and tracked by the joint motors within the Panda's torque limits,
so a target out of reach is approached as far as the arm allows and no body is
ever teleported.

Grasping is constraint-based (documented in docs/controllers.md): the fingers
close on the object under force control, and only when *both* fingers are in
contact with it is the object fixed to the hand by a constraint with a bounded
force. Opening the hand removes the constraint.
"""

from __future__ import annotations

import atexit
import functools
import hashlib
import math
import os
import shutil
import stat
import tempfile
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from llcps.sim.bullet import pybullet as p
import pybullet_data
from scipy.spatial import ConvexHull

from llcps.sim.contact import TOUCH_DISTANCE

#: Movable arm joints, finger joints, hand link and tool link of panda.urdf.
ARM_JOINTS: tuple[int, ...] = (0, 1, 2, 3, 4, 5, 6)
FINGER_JOINTS: tuple[int, ...] = (9, 10)
HAND_LINK = 8
TOOL_LINK = 11
#: Links that hold a grasped object (no contacts with it while the grasp constraint carries it).
HOLD_LINKS: tuple[int, ...] = (HAND_LINK, 9, 10, TOOL_LINK)

#: Joint torque limits of the Panda (N m) and finger force limit (N).
ARM_FORCES: tuple[float, ...] = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
FINGER_FORCE = 20.0

#: Home posture: the tool 0.36 m above the table at x = 0.42, pointing down, hand open.
HOME: tuple[float, ...] = (0.0, -0.4, 0.0, -2.4, 0.0, 2.0, math.pi / 4)
FINGER_OPEN = 0.04  # per finger (m): an 8 cm opening

#: Tool point height above the fingertips (m).
TOOL_ABOVE_TIPS = 0.011

#: Collision group bit of the robot; perception rays ignore it.
ROBOT_GROUP = 1 << 5
RAY_MASK = ~ROBOT_GROUP & 0xFFFF

#: Grasp constraint strength (N): enough for every catalog object, not for a table.
GRASP_FORCE = 60.0

#: IK solutions a :class:`ReachSolutions` keeps.
REACH_IK_CAPACITY = 8192


#: Version of what :func:`panda_urdf` writes (part of its directory's name).
PANDA_FILES_VERSION = 1


@functools.lru_cache(maxsize=1)
def panda_urdf() -> str:
    """Path of the Panda's URDF with each collision mesh reduced to its convex hull's vertices.

    PyBullet makes a convex hull of every collision mesh anyway; the shipped meshes
    repeat up to nine times more points than their hulls have. Writing the hull
    vertices alone keeps the shapes exactly and halves the time a scene takes to
    build (trials restore by rebuilding). Visual meshes are the shipped ones.

    The files are written once per user and content, into a private directory of the
    temporary directory named by a digest of what they are made from (the shipped
    files, SciPy's version, :data:`PANDA_FILES_VERSION`); every later process reads
    them, and a killed one leaves nothing behind. A directory of that name this user
    does not own privately is not used: the files go to a directory of this process.
    """
    import scipy

    src = Path(pybullet_data.getDataPath()) / "franka_panda"
    sources = [src / "panda.urdf", *sorted((src / "meshes" / "collision").glob("*.obj"))]
    digest = hashlib.sha256(f"{PANDA_FILES_VERSION} {scipy.__version__} {src}".encode())
    for path in sources:
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    shared = Path(tempfile.gettempdir()) / f"llcps-panda-{os.getuid()}-{digest.hexdigest()[:16]}"
    if _private_dir(shared):
        return str(shared / "panda.urdf")
    made = Path(tempfile.mkdtemp(prefix=".llcps-panda-"))  # mode 0700
    _write_panda_files(src, made)
    try:
        made.rename(shared)  # whole or not at all; refused if another process was first
        return str(shared / "panda.urdf")
    except OSError:
        if _private_dir(shared):
            shutil.rmtree(made, ignore_errors=True)
            return str(shared / "panda.urdf")
    atexit.register(shutil.rmtree, made, True)
    return str(made / "panda.urdf")


def _private_dir(path: Path) -> bool:
    """Whether ``path`` is a directory of this user that nobody else may write, with the URDF in it."""
    try:
        info = path.lstat()
    except OSError:
        return False
    return stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid() and not info.st_mode & 0o022 and (path / "panda.urdf").is_file()


def _write_panda_files(src: Path, dst: Path) -> None:
    (dst / "meshes" / "collision").mkdir(parents=True)
    (dst / "meshes" / "visual").symlink_to(src / "meshes" / "visual", target_is_directory=True)
    for obj in sorted((src / "meshes" / "collision").glob("*.obj")):
        points = np.array(
            [[float(v) for v in line.split()[1:4]] for line in obj.read_text().splitlines() if line.startswith("v ")]
        )
        hull = ConvexHull(points)
        keep = np.sort(hull.vertices)
        index = {int(old): new + 1 for new, old in enumerate(keep)}
        lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in points[keep].tolist()]
        lines += ["f " + " ".join(str(index[int(v)]) for v in face) for face in hull.simplices]
        (dst / "meshes" / "collision" / obj.name).write_text("\n".join(lines) + "\n")
    shutil.copy(src / "panda.urdf", dst / "panda.urdf")  # last: a directory with the URDF is complete


class ReachSolutions:
    """The IK solutions of :meth:`Robot.reach_error` by target (position, yaw), least
    recently used dropped first, for the robots built in one engine (each rebuild of a
    scene builds a new robot): a solve from HOME depends on the target alone.
    """

    def __init__(self, capacity: int = REACH_IK_CAPACITY) -> None:
        # key -> a slot holding its solution once solved (an lru_cache bounds and orders the slots)
        self._slot: Callable[[tuple[float, float, float, float]], list[tuple[float, ...]]] = functools.lru_cache(maxsize=capacity)(
            lambda key: []
        )

    def get(self, robot: "Robot", key: tuple[float, float, float, float]) -> tuple[float, ...]:
        """The arm joints of ``key``'s solve from HOME, solved by ``robot`` unless remembered."""
        slot = self._slot(key)
        if not slot:
            slot.append(robot._home_ik(key))  # noqa: SLF001
        return slot[0]

    def cache_clear(self) -> None:
        self._slot.cache_clear()  # type: ignore[attr-defined]


def top_down(yaw: float) -> tuple[float, float, float, float]:
    """Quaternion of a tool pointing straight down, fingers closing across ``yaw``.

    At yaw 0 the hand's x axis is world +x and the fingers close along world y.
    """
    return (math.cos(yaw / 2.0), math.sin(yaw / 2.0), 0.0, 0.0)


class Robot:
    """The Panda arm in one BulletClient.

    Attributes:
        body_id: PyBullet body id.
        grasped: body id of the object held by the grasp constraint, if any.
    """

    def __init__(
        self,
        client: Any,
        *,
        visuals: bool = True,
        reach: ReachSolutions | None = None,
        grip_force: float | None = None,
        top_down_reach: float | None = None,
    ) -> None:
        self.client = client
        #: Strength (N) of the grasp constraint that carries a lifted object.
        self.grip_force = GRASP_FORCE if grip_force is None else grip_force
        #: Farthest horizontal distance (m) from the base of a top-down pose (None: the arm's own).
        self.top_down_reach = top_down_reach
        #: The IK solutions of :meth:`reach_error`, shared by the robots of one engine.
        self.reach = reach if reach is not None else ReachSolutions()
        cid = client._client
        # hot-path calls bound to the client once (BulletClient re-binds on every call)
        self._ik = functools.partial(p.calculateInverseKinematics, physicsClientId=cid)
        self._motors = functools.partial(p.setJointMotorControlArray, physicsClientId=cid)
        self._link_state = functools.partial(p.getLinkState, physicsClientId=cid)
        self._joint_states = functools.partial(p.getJointStates, physicsClientId=cid)
        self._reset_joint = functools.partial(p.resetJointState, physicsClientId=cid)
        flags = 0 if visuals else p.URDF_IGNORE_VISUAL_SHAPES
        try:
            self.body_id: int = client.loadURDF(panda_urdf(), (0.0, 0.0, 0.0), useFixedBase=True, flags=flags)
        except p.error:  # the private copy was removed from under us: make it again
            panda_urdf.cache_clear()
            self.body_id = client.loadURDF(panda_urdf(), (0.0, 0.0, 0.0), useFixedBase=True, flags=flags)
        info = [client.getJointInfo(self.body_id, j) for j in ARM_JOINTS + FINGER_JOINTS]
        self.lower = [i[8] for i in info]
        self.upper = [i[9] for i in info]
        self.ranges = [hi - lo for lo, hi in zip(self.lower, self.upper)]
        self.rest = list(HOME) + [FINGER_OPEN, FINGER_OPEN]
        for link in range(-1, client.getNumJoints(self.body_id)):
            client.setCollisionFilterGroupMask(self.body_id, link, ROBOT_GROUP, 0xFFFF)
        for link in FINGER_JOINTS:
            client.changeDynamics(self.body_id, link, lateralFriction=1.0)
        self.grasped: int | None = None
        self._constraint: int | None = None
        self.reset_home()
        state = client.getLinkState(self.body_id, TOOL_LINK, computeForwardKinematics=1)
        self.home_tool: tuple[float, float, float] = tuple(state[4])  # type: ignore[assignment]

    # ------------------------------------------------------------------ state

    def reset_home(self) -> None:
        """Put the arm at HOME with the hand open, at rest (no physics involved)."""
        self.release()
        for j, q in zip(ARM_JOINTS, HOME):
            self.client.resetJointState(self.body_id, j, q, 0.0)
        for j in FINGER_JOINTS:
            self.client.resetJointState(self.body_id, j, FINGER_OPEN, 0.0)
        self.hold()

    def joint_positions(self) -> list[float]:
        """Positions of the 7 arm joints and 2 finger joints."""
        states = self.client.getJointStates(self.body_id, ARM_JOINTS + FINGER_JOINTS)
        return [s[0] for s in states]

    def hold(self) -> None:
        """Command every motor to keep its current position."""
        q = self.joint_positions()
        self.command_arm(q[:7])
        self.command_fingers(q[7], force=FINGER_FORCE)

    def tool_position(self, *, fresh: bool = False) -> tuple[float, float, float]:
        """Tool point in the world: as of the last step, or (``fresh``) computed from the joints now."""
        if fresh:
            return self._link_state(self.body_id, TOOL_LINK, computeForwardKinematics=1)[4]
        return self._link_state(self.body_id, TOOL_LINK)[4]

    def finger_width(self) -> float:
        """Current opening between the fingers (m)."""
        states = self.client.getJointStates(self.body_id, FINGER_JOINTS)
        return states[0][0] + states[1][0]

    # ------------------------------------------------------------------ control

    def ik(self, position: Sequence[float], orientation: Sequence[float], *, iterations: int = 5) -> tuple:
        """Joint targets that bring the tool point to a pose, seeded by the current joints.

        A few iterations suffice per control step (the target moves a millimetre or
        so); :meth:`reach_error` uses a longer, HOME-seeded solve.
        """
        return self._ik(
            self.body_id,
            TOOL_LINK,
            position,
            orientation,
            maxNumIterations=iterations,
            residualThreshold=1e-3 if iterations < 20 else 1e-5,
        )

    def command_arm(self, targets: Sequence[float]) -> None:
        self._motors(self.body_id, ARM_JOINTS, p.POSITION_CONTROL, targetPositions=targets[:7], forces=ARM_FORCES)

    def command_fingers(self, each: float, *, force: float = FINGER_FORCE) -> None:
        """Drive both fingers to ``each`` metres from the centre."""
        self._motors(
            self.body_id, FINGER_JOINTS, p.POSITION_CONTROL, targetPositions=(each, each), forces=(force, force)
        )

    def fingers_touch(self, body: int) -> bool:
        """Whether both fingers press on ``body`` from the sides (from the last step).

        A contact counts only when its normal runs along the closing axis, so fingers
        resting on top of something too wide to grip do not make a grasp.
        """
        c = self.client
        x, y, z, w = self._link_state(self.body_id, HAND_LINK)[5]
        axis = (2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x))  # hand y in world
        for finger in FINGER_JOINTS:
            if not any(
                cp[8] <= TOUCH_DISTANCE and abs(cp[7][0] * axis[0] + cp[7][1] * axis[1] + cp[7][2] * axis[2]) > 0.7
                for cp in c.getContactPoints(self.body_id, body, finger)
            ):
                return False
        return True

    def attach(self, body: int) -> None:
        """Fix ``body`` to the tool link where it is now (the fingers hold it)."""
        if self._constraint is not None:
            self.release()
        c = self.client
        tool = c.getLinkState(self.body_id, TOOL_LINK)
        obj_pos, obj_orn = c.getBasePositionAndOrientation(body)
        inv_pos, inv_orn = c.invertTransform(tool[0], tool[1])
        rel_pos, rel_orn = c.multiplyTransforms(inv_pos, inv_orn, obj_pos, obj_orn)
        self._constraint = c.createConstraint(
            self.body_id,
            TOOL_LINK,
            body,
            -1,
            p.JOINT_FIXED,
            (0, 0, 0),
            parentFramePosition=rel_pos,
            childFramePosition=(0, 0, 0),
            parentFrameOrientation=rel_orn,
            childFrameOrientation=(0, 0, 0, 1),
        )
        c.changeConstraint(self._constraint, maxForce=self.grip_force)
        # The constraint now carries the object: the fingers stop pressing on it
        # (their contacts would only fight the constraint) until it is released.
        for link in HOLD_LINKS:
            c.setCollisionFilterPair(self.body_id, body, link, -1, 0)
        each = self.finger_width() / 2.0
        self.command_fingers(each)
        self.grasped = body

    def release(self) -> None:
        """Drop whatever the grasp constraint holds (the fingers are not moved)."""
        if self._constraint is not None:
            self.client.removeConstraint(self._constraint)
            for link in HOLD_LINKS:
                self.client.setCollisionFilterPair(self.body_id, self.grasped, link, -1, 1)
        self._constraint = None
        self.grasped = None

    # ------------------------------------------------------------------ kinematic probe

    def reach_error(self, position: Sequence[float], yaw: float) -> tuple[float, float]:
        """How closely the arm can put its tool at a top-down pose, by IK then FK.

        The IK starts from HOME whatever the arm is doing, so the answer depends on
        the target alone, and each target's solve is remembered (:attr:`reach`). The
        joints still go to HOME, to the solution and back on every call (what the
        world saves next depends on those moves); no time passes and no body moves.

        Returns:
            (position error in m, angle between the tool axis and straight down in rad).
        """
        body, reset = self.body_id, self._reset_joint
        joints = ARM_JOINTS + FINGER_JOINTS
        saved = self._joint_states(body, joints)
        for j, q in zip(joints, self.rest):
            reset(body, j, q, 0.0)
        key = (float(position[0]), float(position[1]), float(position[2]), float(yaw))
        q = self.reach.get(self, key)
        for j, qj in zip(ARM_JOINTS, q):
            reset(body, j, min(max(qj, self.lower[j]), self.upper[j]), 0.0)
        state = self._link_state(body, TOOL_LINK, computeForwardKinematics=1)
        for j, s in zip(joints, saved):
            reset(body, j, s[0], s[1])
        pos, orn = state[4], state[5]
        err = math.dist(pos, position)
        if self.top_down_reach is not None:  # a shorter reach: the pose is as far off as it lies beyond it
            err = max(err, math.hypot(position[0], position[1]) - self.top_down_reach)
        # tool z axis in world: third column of the rotation matrix
        x, y, z, w = orn
        axis_z = (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))
        angle = math.acos(max(-1.0, min(1.0, -axis_z[2])))
        return err, angle

    def _home_ik(self, key: tuple[float, float, float, float]) -> tuple[float, ...]:
        """The arm joints of a top-down tool pose solved from HOME (the joints are at HOME)."""
        return self.client.calculateInverseKinematics(
            self.body_id,
            TOOL_LINK,
            key[:3],
            top_down(key[3]),
            lowerLimits=self.lower,
            upperLimits=self.upper,
            jointRanges=self.ranges,
            restPoses=self.rest,
            maxNumIterations=100,
            residualThreshold=1e-5,
        )[:7]
