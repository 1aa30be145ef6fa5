"""A robot: the PyBullet body and a pinocchio model built from the same URDF.

PyBullet simulates (contacts, motors); pinocchio gives frame poses and
Jacobians analytically. Both load one URDF file, and the base is fixed at the
world pose ``T_world_base``, so a frame pose from pinocchio and the matching
PyBullet link pose agree (checked in tests/test_robot.py).

Twist convention: a 6-vector ``(v, w)``, linear velocity first [m/s, rad/s].
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as p

from repro.errors import ConfigError, UnknownChoiceError
from repro.sim.world import World, pb_to_pose, pose_to_pb

JACOBIAN_FRAMES = ("local", "world", "local_world_aligned")

#: PyBullet URDF load flags used for every robot (recorded in scene.json).
#: Inertias from the file (not recomputed from collision shapes); exact cylinder collision
#: shapes (not convex hulls), so that PyBullet's distances agree with python-fcl's.
URDF_LOAD_FLAGS = {"URDF_USE_INERTIA_FROM_FILE": p.URDF_USE_INERTIA_FROM_FILE,
                   "URDF_USE_IMPLICIT_CYLINDER": p.URDF_USE_IMPLICIT_CYLINDER}
_PIN_REFERENCE = {
    "local": pin.ReferenceFrame.LOCAL,
    "world": pin.ReferenceFrame.WORLD,
    "local_world_aligned": pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
}


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits of the actuated joints, in the order of ``Robot.joint_names``.

    Attributes:
        q_min, q_max: position limits [rad].
        qd_max: velocity limit magnitude [rad/s].
        tau_max: torque limit magnitude [N m].
    """

    q_min: tuple[float, ...]
    q_max: tuple[float, ...]
    qd_max: tuple[float, ...]
    tau_max: tuple[float, ...]

    def __post_init__(self) -> None:
        n = len(self.q_min)
        for name in ("q_max", "qd_max", "tau_max"):
            if len(getattr(self, name)) != n:
                raise ConfigError(f"JointLimits.{name} has {len(getattr(self, name))} "
                                  f"entries, expected {n}")


#: Joint resets so far, by any :class:`JointSet` (a reset invalidates the joint states a
#: :class:`Robot` caches between physics steps). Code that moves joints behind this module's
#: back (``p.resetJointState``, ``p.stepSimulation`` on a Robot's client) must call
#: :func:`joint_states_changed`.
_RESETS = [0]


def joint_states_stamp(world: World) -> tuple[int, int]:
    """What a cache of joint states read from PyBullet is valid for: ``world``'s physics steps
    and the resets of any robot (:meth:`JointSet.reset`, :func:`joint_states_changed`)."""
    return world.physics_steps, _RESETS[0]


def joint_states_changed() -> None:
    """Tell every :class:`Robot` that its joints moved outside :meth:`JointSet.reset` and
    :meth:`World.step_physics` (its cached joint states are stale)."""
    _RESETS[0] += 1


class JointSet:
    """Joint state and motor commands of a set of joints of one PyBullet body.

    Subclasses set ``body``, ``client``, ``pb_joints`` (PyBullet joint indices), ``n`` and
    ``limits``: :class:`Robot` (every controlled joint of a URDF) and :class:`JointGroup`
    (a subset, e.g. the PA-10 and the mini-robot of one URDF, driven separately).
    """

    body: int
    client: int
    pb_joints: list[int]
    n: int
    limits: JointLimits
    name: str
    column_prefix: str

    def gravity_torques(self, q: np.ndarray) -> np.ndarray:
        """g(q) of these joints [N m] (implemented by the subclasses)."""
        raise NotImplementedError

    def q(self) -> np.ndarray:
        """Joint positions [rad], control order."""
        states = p.getJointStates(self.body, self.pb_joints, physicsClientId=self.client)
        return np.array([s[0] for s in states])

    def qd(self) -> np.ndarray:
        """Joint velocities [rad/s], control order."""
        states = p.getJointStates(self.body, self.pb_joints, physicsClientId=self.client)
        return np.array([s[1] for s in states])

    def reset(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        """Teleport the joints to ``q`` [rad] with velocities ``qd`` [rad/s] (default 0)."""
        _RESETS[0] += 1  # every robot's cached joint states are stale now
        qd = np.zeros(self.n) if qd is None else qd
        for j, qi, qdi in zip(self.pb_joints, q, qd, strict=True):
            p.resetJointState(self.body, j, float(qi), float(qdi), physicsClientId=self.client)

    # --------------------------------------------------------------- commands
    def velocity_mode(self) -> None:
        """Joint motors in velocity control, holding still until commanded."""
        p.setJointMotorControlArray(
            self.body, self.pb_joints, p.VELOCITY_CONTROL,
            targetVelocities=[0.0] * self.n, forces=list(self.limits.tau_max),
            physicsClientId=self.client,
        )

    def set_velocity_command(self, qd: np.ndarray) -> None:
        """Command joint velocities [rad/s], clipped to the limits, motor force <= tau_max."""
        qd_max = np.asarray(self.limits.qd_max)
        qd = np.clip(np.asarray(qd, dtype=float), -qd_max, qd_max)
        p.setJointMotorControlArray(
            self.body, self.pb_joints, p.VELOCITY_CONTROL,
            targetVelocities=qd.tolist(), forces=list(self.limits.tau_max),
            physicsClientId=self.client,
        )

    def set_position_command(self, q_ref: np.ndarray | list[float],
                             qd_ref: np.ndarray | list[float],
                             position_gain: float = 0.2, velocity_gain: float = 1.0) -> None:
        """Track a joint reference with PyBullet's joint PD (position control) [rad, rad/s].

        The gains are PyBullet's dimensionless ones; the motor force is limited to tau_max.
        Called every physics step, this is the inner "PID" loop tracking an interpolated
        reference (chan2011 Sec. V-A5).
        """
        p.setJointMotorControlArray(
            self.body, self.pb_joints, p.POSITION_CONTROL,
            targetPositions=(q_ref if type(q_ref) is list
                             else np.asarray(q_ref, dtype=float).tolist()),
            targetVelocities=(qd_ref if type(qd_ref) is list
                              else np.asarray(qd_ref, dtype=float).tolist()),
            positionGains=[position_gain] * self.n, velocityGains=[velocity_gain] * self.n,
            forces=list(self.limits.tau_max), physicsClientId=self.client,
        )

    def torque_mode(self) -> None:
        """Release the velocity motors so that :meth:`set_torque_command` acts alone."""
        p.setJointMotorControlArray(
            self.body, self.pb_joints, p.VELOCITY_CONTROL,
            targetVelocities=[0.0] * self.n, forces=[0.0] * self.n,
            physicsClientId=self.client,
        )

    def set_torque_command(self, tau: np.ndarray) -> None:
        """Command joint torques [N m], clipped to +-tau_max (call torque_mode() first)."""
        tau_max = np.asarray(self.limits.tau_max)
        tau = np.clip(np.asarray(tau, dtype=float), -tau_max, tau_max)
        p.setJointMotorControlArray(
            self.body, self.pb_joints, p.TORQUE_CONTROL, forces=tau.tolist(),
            physicsClientId=self.client,
        )


class Robot(JointSet):
    """A fixed-base robot in a :class:`World`.

    Args:
        world: the world whose client holds the body.
        urdf_path: URDF loaded by both PyBullet and pinocchio.
        joint_names: the actuated joints, in control order.
        limits: joint limits (used for motor forces and by controllers).
        T_world_base: base pose in the world [m].
    """

    def __init__(
        self,
        world: World,
        urdf_path: Path,
        joint_names: tuple[str, ...],
        limits: JointLimits,
        T_world_base: np.ndarray | None = None,
    ) -> None:
        self.world = world
        self.client = world.client
        self.urdf_path = Path(urdf_path)
        self.joint_names = tuple(joint_names)
        self.limits = limits
        self.T_world_base = np.eye(4) if T_world_base is None else np.asarray(T_world_base)
        self.name = self.urdf_path.stem
        """Name of the robot in its scene."""
        self.column_prefix = ""
        """Prefix of the robot's trace columns (``""`` -> ``q1``; ``"pa10_"`` -> ``pa10_q1``)."""
        pos, quat = pose_to_pb(self.T_world_base)
        self.load_flags = 0
        for flag in URDF_LOAD_FLAGS.values():
            self.load_flags |= flag
        self.body = p.loadURDF(
            str(self.urdf_path), pos, quat, useFixedBase=True, flags=self.load_flags,
            physicsClientId=self.client,
        )
        # PyBullet indices of joints and links (a link has the index of its parent joint).
        self._pb_joint: dict[str, int] = {}
        self._pb_link: dict[str, int] = {}
        for j in range(p.getNumJoints(self.body, physicsClientId=self.client)):
            info = p.getJointInfo(self.body, j, physicsClientId=self.client)
            self._pb_joint[info[1].decode()] = j
            self._pb_link[info[12].decode()] = j
        self._pb_link[p.getBodyInfo(self.body, physicsClientId=self.client)[0].decode()] = -1
        missing = [n for n in self.joint_names if n not in self._pb_joint]
        if missing:
            raise UnknownChoiceError("joint", missing[0], self._pb_joint)
        self.pb_joints = [self._pb_joint[n] for n in self.joint_names]
        self.n = len(self.joint_names)

        #: (physics step, reset count) of the cached joint states, and the states: one
        #: getJointStates per physics step for every reader (the runner, the drives, the
        #: controller and the groups of one chain read the same state several times a step)
        self._states_key: tuple[int, int] | None = None
        self._q_now = np.zeros(0)
        self._qd_now = np.zeros(0)
        self.model = pin.buildModelFromUrdf(str(self.urdf_path))
        self.data = self.model.createData()
        self._g_memo: tuple[bytes, np.ndarray] | None = None  # g(q) of the last q
        #: a second workspace for the dynamics (CRBA, RNEA), so that M(q) and g(q) leave the
        #: kinematics cached in ``data`` valid (same values: each algorithm starts afresh)
        self._data_dyn = self.model.createData()
        # Map control order -> pinocchio q index (all our joints are 1-DoF revolute/prismatic).
        self._pin_q_idx = np.array(
            [self.model.joints[self.model.getJointId(n)].idx_q for n in self.joint_names]
        )
        self._upper = np.triu(np.ones((self.model.nq, self.model.nq), dtype=bool))
        self._ix_ctrl = np.ix_(self._pin_q_idx, self._pin_q_idx)
        if self.model.nq != self.n:
            raise ConfigError(
                f"pinocchio model has nq={self.model.nq} but {self.n} controlled joints; "
                "every non-fixed URDF joint must be controlled"
            )
        # Kinematics cache: the bytes of the q last given to pinocchio (bit-identical q,
        # identical results; a bytes comparison is much cheaper than np.array_equal).
        self._pin_q_key: bytes | None = None
        self._pin_q_identity = bool(np.array_equal(self._pin_q_idx, np.arange(self.model.nq)))
        self._frame_ids: dict[str, int] = {}
        # The drives: the simulation itself clamps every joint speed to its limit, whatever
        # the controller asks (a robot that could exist).
        for j, qd_max in zip(self.pb_joints, self.limits.qd_max, strict=True):
            p.changeDynamics(self.body, j, maxJointVelocity=float(qd_max),
                             physicsClientId=self.client)
        self.velocity_mode()

    # ------------------------------------------------------------------ state
    def link_names(self) -> list[str]:
        """Every link/frame name known to PyBullet."""
        return list(self._pb_link)

    def pb_link_index(self, link: str) -> int:
        """PyBullet link index of ``link`` (-1 for the base)."""
        if link not in self._pb_link:
            raise UnknownChoiceError("link", link, self._pb_link)
        return self._pb_link[link]

    def q(self) -> np.ndarray:
        """Joint positions [rad], control order (read once per physics step)."""
        return self._joint_states()[0].copy()

    def qd(self) -> np.ndarray:
        """Joint velocities [rad/s], control order (read once per physics step)."""
        return self._joint_states()[1].copy()

    def _joint_states(self) -> tuple[np.ndarray, np.ndarray]:
        """(q, qd) as PyBullet has them now, cached until the next physics step or reset."""
        key = joint_states_stamp(self.world)
        if key != self._states_key:
            states = p.getJointStates(self.body, self.pb_joints, physicsClientId=self.client)
            self._q_now = np.array([st[0] for st in states])
            self._qd_now = np.array([st[1] for st in states])
            self._states_key = key
        return self._q_now, self._qd_now

    def gravity_torques(self, q: np.ndarray) -> np.ndarray:
        """g(q): joint torques [N m] that hold the robot still at ``q`` (pinocchio RNEA with
        zero velocity and acceleration, gravity of the world); the last q's is reused."""
        q = np.asarray(q, dtype=float)
        key = q.tobytes()
        if self._g_memo is not None and self._g_memo[0] == key:
            return self._g_memo[1].copy()
        qp = self._pin_q(q)
        self.model.gravity.linear = np.asarray(self.world.config.gravity, dtype=float) @ (
            self.T_world_base[:3, :3])
        g = np.asarray(pin.computeGeneralizedGravity(self.model, self._data_dyn, qp)
                       )[self._pin_q_idx]
        self._g_memo = (key, g)
        return g.copy()

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) [kg m^2] (n, n), control order (pinocchio CRBA, symmetrised)."""
        qp = self._pin_q(np.asarray(q, dtype=float))
        M = np.asarray(pin.crba(self.model, self._data_dyn, qp))  # the upper triangle
        # symmetrised: upper entries kept, lower ones mirrored (+ 0.0: -0.0 -> 0.0, as
        # np.triu(M) + np.triu(M, 1).T gives)
        M = np.where(self._upper, M, M.T) + 0.0
        return M[self._ix_ctrl]

    # ------------------------------------------------------------ kinematics
    def _pin_q(self, q: np.ndarray) -> np.ndarray:
        qp = np.zeros(self.model.nq)
        qp[self._pin_q_idx] = q
        return qp

    def _update(self, q: np.ndarray) -> None:
        q = np.asarray(q, dtype=float)
        key = q.tobytes()
        if key == self._pin_q_key:
            return
        if self._pin_q_identity and q.shape == (self.model.nq,):
            qp = np.ascontiguousarray(q)
        else:
            qp = self._pin_q(q)
        pin.forwardKinematics(self.model, self.data, qp)
        pin.computeJointJacobians(self.model, self.data, qp)
        pin.updateFramePlacements(self.model, self.data)
        self._pin_q_key = key

    def _frame_id(self, frame: str) -> int:
        """:meth:`frame_id`, memoised."""
        fid = self._frame_ids.get(frame)
        if fid is None:
            fid = self._frame_ids[frame] = self.frame_id(frame)
        return fid

    def frame_id(self, frame: str) -> int:
        """pinocchio frame id of a URDF link name."""
        if not self.model.existFrame(frame):
            raise UnknownChoiceError("frame", frame, [f.name for f in self.model.frames])
        return self.model.getFrameId(frame)

    def frame_pose(self, frame: str, q: np.ndarray) -> np.ndarray:
        """T_world_frame (4x4) at joint positions ``q`` [rad] (pinocchio)."""
        self._update(q)
        return self.T_world_base @ self.data.oMf[self._frame_id(frame)].homogeneous

    def frame_jacobian(self, frame: str, q: np.ndarray, reference: str = "local") -> np.ndarray:
        """Geometric Jacobian (6 x n) of ``frame``: twist (v, w) = J qd.

        reference:
            ``"local"``: twist of the frame expressed in the frame itself
            (linear velocity of the frame origin) -- the paper's J_N / eJ_e;
            ``"local_world_aligned"``: velocity of the frame origin, axes of the world;
            ``"world"``: spatial twist in the world frame (velocity of the point at the
            world origin).
        """
        if reference not in JACOBIAN_FRAMES:
            raise UnknownChoiceError("Jacobian reference", reference, JACOBIAN_FRAMES)
        self._update(q)
        J = pin.getFrameJacobian(self.model, self.data, self._frame_id(frame),
                                 _PIN_REFERENCE[reference])  # a new (6, nq) array
        if not self._pin_q_identity:
            J = J[:, self._pin_q_idx]
        if reference != "local":
            R = self.T_world_base[:3, :3]
            if reference == "world" and not np.allclose(self.T_world_base[:3, 3], 0.0):
                raise ConfigError("world-frame Jacobians assume the base at the world origin")
            J = np.vstack([R @ J[:3], R @ J[3:]])
        return J

    def pb_link_pose(self, link: str) -> np.ndarray:
        """T_world_link (4x4) of the URDF link frame as PyBullet has it now."""
        idx = self.pb_link_index(link)
        if idx == -1:
            # PyBullet reports the base's inertial (centre-of-mass) frame; undo the URDF's
            # inertial offset to get the link frame.
            pos, quat = p.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
            info = p.getDynamicsInfo(self.body, -1, physicsClientId=self.client)
            return pb_to_pose(pos, quat) @ np.linalg.inv(pb_to_pose(info[3], info[4]))
        st = p.getLinkState(self.body, idx, computeForwardKinematics=True,
                            physicsClientId=self.client)
        return pb_to_pose(st[4], st[5])

    def min_distance(self, other_body: int, max_distance: float = 1.0) -> float:
        """Ground-truth minimum distance [m] between this robot and a body.

        PyBullet closest points on the collision geometry; negative means
        penetration; ``max_distance`` when nothing is closer than that.
        """
        pts = p.getClosestPoints(self.body, other_body, max_distance,
                                 physicsClientId=self.client)
        if not pts:
            return max_distance
        return float(min(pt[8] for pt in pts))


class JointGroup(JointSet):
    """A subset of a robot's joints, driven and logged on its own.

    One URDF may carry two robots (pomares2011: the PA-10 and the mini-robot on its flange):
    a :class:`Robot` gives the kinematics and dynamics of the whole chain, and one group per
    robot gives each its own drive (velocity for one, torque for the other) and trace
    columns. ``links`` are the PyBullet links the group moves: those whose nearest non-fixed
    ancestor joint (or their own joint) belongs to the group, plus the base link for the
    group that owns the base.

    Args:
        robot: the whole chain.
        name: the group's name (drives, observations and columns use it).
        joints: its joints, a subset of ``robot.joint_names`` in control order.
        column_prefix: prefix of its trace columns (e.g. ``"mini_"``).
        owns_base: the base link belongs to this group.
    """

    def __init__(self, robot: Robot, name: str, joints: tuple[str, ...], column_prefix: str,
                 owns_base: bool = False) -> None:
        unknown = [j for j in joints if j not in robot.joint_names]
        if unknown or not joints:
            raise UnknownChoiceError("joint", unknown[0] if unknown else "", robot.joint_names)
        self.robot, self.name, self.column_prefix = robot, name, column_prefix
        self.world, self.body, self.client = robot.world, robot.body, robot.client
        self.joint_names = tuple(joints)
        self.idx = np.array([robot.joint_names.index(j) for j in joints])
        self.pb_joints = [robot.pb_joints[i] for i in self.idx]
        self.n = len(joints)
        self.limits = JointLimits(*(tuple(float(v) for v in np.asarray(getattr(
            robot.limits, f))[self.idx]) for f in ("q_min", "q_max", "qd_max", "tau_max")))
        mine = set(self.pb_joints)
        controlled = set(robot.pb_joints)
        self.links: list[int] = [-1] if owns_base else []
        for link in range(p.getNumJoints(robot.body, physicsClientId=robot.client)):
            j = link
            while j >= 0 and j not in controlled:  # walk up to the nearest controlled joint
                j = p.getJointInfo(robot.body, j, physicsClientId=robot.client)[16]
            if (j >= 0 and j in mine) or (j < 0 and owns_base):
                self.links.append(link)

    def q(self) -> np.ndarray:
        """The group's joint positions [rad] (the chain's states of this physics step)."""
        return self.robot._joint_states()[0][self.idx]

    def qd(self) -> np.ndarray:
        """The group's joint velocities [rad/s] (the chain's states of this physics step)."""
        return self.robot._joint_states()[1][self.idx]

    def gravity_torques(self, q: np.ndarray | None = None) -> np.ndarray:
        """The group's part of g(q) [N m], at the whole chain's current configuration
        (``q`` of the group, if given, replaces the group's joints)."""
        q_all = self.robot.q()
        if q is not None:
            q_all[self.idx] = q
        return self.robot.gravity_torques(q_all)[self.idx]


def solve_ik(robot: Robot, frame: str, T_world_target: np.ndarray, q_init: np.ndarray,
             iterations: int = 200, damping: float = 1e-6, tol: float = 1e-9) -> np.ndarray:
    """Joint positions [rad] that put ``frame`` at ``T_world_target`` (damped least squares
    on the SE(3) log error, within the joint limits), starting from ``q_init``.

    Raises ReproError when the residual stays above ``tol`` [m, rad].
    """
    from repro.errors import ReproError

    q = np.asarray(q_init, dtype=float).copy()
    q_min, q_max = np.asarray(robot.limits.q_min), np.asarray(robot.limits.q_max)
    target = pin.SE3(T_world_target)
    err = np.full(6, np.inf)
    for _ in range(iterations):
        current = pin.SE3(robot.frame_pose(frame, q))
        err = pin.log6(current.actInv(target)).vector  # twist in the frame, (v, w)
        if np.linalg.norm(err) < tol:
            return q
        J = robot.frame_jacobian(frame, q, "local")
        J = pin.Jlog6(current.actInv(target)) @ J
        q = np.clip(q + J.T @ np.linalg.solve(J @ J.T + damping * np.eye(6), err),
                    q_min, q_max)
    raise ReproError(f"IK for {frame} did not converge: residual {np.linalg.norm(err):.3g}")
