"""Tests of repro.sim.robot, repro.sim.panda and repro.sim.world.

The Panda URDF is built with the real thomas2024 attachments (two rings, camera), loaded
in PyBullet and pinocchio; frame poses and Jacobians are checked against PyBullet and
against finite differences, the limits against Franka's datasheet, the time base and the
velocity motors against their specification, and runs for bit-identical repeatability.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from experiments.thomas2024.scene import attachments
from repro.errors import ConfigError, ReproError
from repro.sim.panda import PANDA_JOINTS, PANDA_LIMITS, build_panda_urdf
from repro.sim.robot import JointLimits, Robot, solve_ik
from repro.sim.world import World, WorldConfig

LINKS = tuple(f"panda_link{i}" for i in range(1, 9)) + ("ring1", "ring2", "camera_optical")
Q_MIN = np.array(PANDA_LIMITS.q_min)
Q_MAX = np.array(PANDA_LIMITS.q_max)
# A comfortable configuration, far from every joint limit.
Q_HOME = np.array([0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8])


def _random_q(rng: np.random.Generator, margin: float = 0.05) -> np.ndarray:
    """A configuration uniformly drawn within the joint limits (``margin`` [rad] inside)."""
    return rng.uniform(Q_MIN + margin, Q_MAX - margin)


@pytest.fixture(scope="module")
def urdf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_panda_urdf(tmp_path_factory.mktemp("panda") / "p.urdf", attachments())


@pytest.fixture(scope="module")
def robot(urdf: Path):  # type: ignore[no-untyped-def]
    with World() as world:
        yield Robot(world, urdf, PANDA_JOINTS, PANDA_LIMITS)


def _rot_err(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle [rad] of R_a^T R_b."""
    return float(np.linalg.norm(pin.log3(R_a.T @ R_b)))


# --------------------------------------------------------------------------------------
# pinocchio vs PyBullet
# --------------------------------------------------------------------------------------


def test_urdf_frames_exist(robot: Robot) -> None:
    for link in LINKS:
        robot.frame_id(link)  # raises if pinocchio lacks it
        robot.pb_link_index(link)  # raises if PyBullet lacks it
    assert robot.n == 7 and robot.model.nq == 7
    for dropped in ("panda_hand", "panda_leftfinger", "panda_rightfinger"):
        assert dropped not in robot.link_names()


def test_frame_pose_matches_pybullet(robot: Robot) -> None:
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = _random_q(rng)
        robot.reset(q)
        np.testing.assert_allclose(robot.q(), q, atol=1e-12)
        for link in LINKS:
            T_pin = robot.frame_pose(link, q)
            T_pb = robot.pb_link_pose(link)
            np.testing.assert_allclose(T_pin[:3, 3], T_pb[:3, 3], atol=1e-6, err_msg=link)
            assert _rot_err(T_pin[:3, :3], T_pb[:3, :3]) < 1e-6, link
            np.testing.assert_allclose(T_pin[3], [0, 0, 0, 1])


def test_attachment_poses_in_parent(robot: Robot) -> None:
    """Each attachment sits at its declared pose in its parent link, whatever q."""
    q = _random_q(np.random.default_rng(1))
    for a in attachments():
        T_rel = np.linalg.inv(robot.frame_pose(a.parent, q)) @ robot.frame_pose(a.name, q)
        np.testing.assert_allclose(T_rel, a.T_parent_child, atol=1e-9, err_msg=a.name)


# --------------------------------------------------------------------------------------
# Jacobians
# --------------------------------------------------------------------------------------

JAC_FRAMES = ("panda_link4", "panda_link8", "ring1", "ring2", "camera_optical")


def _fd_jacobians(robot: Robot, frame: str, q: np.ndarray, h: float = 1e-6
                  ) -> dict[str, np.ndarray]:
    """Central finite differences of frame_pose: local, world (spatial) and LWA twists."""
    T0 = pin.SE3(robot.frame_pose(frame, q))
    out = {k: np.zeros((6, q.size)) for k in ("local", "world", "local_world_aligned")}
    for i in range(q.size):
        dq = np.zeros(q.size)
        dq[i] = h
        Tp = pin.SE3(robot.frame_pose(frame, q + dq))
        Tm = pin.SE3(robot.frame_pose(frame, q - dq))
        # Body twist: T(q)^-1 T(q + h e_i) = exp(h xi_local).
        out["local"][:, i] = (pin.log6(T0.actInv(Tp)).vector
                              - pin.log6(T0.actInv(Tm)).vector) / (2 * h)
        # Spatial twist: T(q + h e_i) T(q)^-1 = exp(h xi_world).
        out["world"][:, i] = (pin.log6(Tp * T0.inverse()).vector
                              - pin.log6(Tm * T0.inverse()).vector) / (2 * h)
        # Local-world-aligned: velocity of the frame origin and angular velocity, world axes.
        out["local_world_aligned"][:3, i] = (Tp.translation - Tm.translation) / (2 * h)
        out["local_world_aligned"][3:, i] = out["world"][3:, i]
    return out


def test_jacobians_match_finite_differences(robot: Robot) -> None:
    rng = np.random.default_rng(2)
    for _ in range(3):
        q = _random_q(rng)
        for frame in JAC_FRAMES:
            fd = _fd_jacobians(robot, frame, q)
            for ref, J_fd in fd.items():
                J = robot.frame_jacobian(frame, q, ref)
                assert J.shape == (6, 7)
                np.testing.assert_allclose(J, J_fd, atol=1e-6, err_msg=f"{frame} {ref}")


def test_jacobian_frames_are_related_by_their_definitions(robot: Robot) -> None:
    q = _random_q(np.random.default_rng(3))
    for frame in JAC_FRAMES:
        T = robot.frame_pose(frame, q)
        R, t = T[:3, :3], T[:3, 3]
        J_l = robot.frame_jacobian(frame, q, "local")
        J_lwa = robot.frame_jacobian(frame, q, "local_world_aligned")
        J_w = robot.frame_jacobian(frame, q, "world")
        # LWA = local rotated into world axes.
        np.testing.assert_allclose(J_lwa[:3], R @ J_l[:3], atol=1e-12)
        np.testing.assert_allclose(J_lwa[3:], R @ J_l[3:], atol=1e-12)
        # World (spatial): same w; v of the point at the world origin = v_o - w x t.
        np.testing.assert_allclose(J_w[3:], J_lwa[3:], atol=1e-12)
        np.testing.assert_allclose(J_w[:3], J_lwa[:3] - np.cross(J_lwa[3:].T, t).T,
                                   atol=1e-12)
        # World = Ad(T) local.
        np.testing.assert_allclose(J_w, pin.SE3(T).action @ J_l, atol=1e-12)


def test_jacobian_matches_pybullet(robot: Robot) -> None:
    """PyBullet's calculateJacobian (linear/angular of a link point, world axes, all 7
    movable joints) equals the local-world-aligned Jacobian at the link origin."""
    rng = np.random.default_rng(4)
    zeros = [0.0] * 7
    for _ in range(5):
        q = _random_q(rng)
        robot.reset(q)
        for link in LINKS:
            idx = robot.pb_link_index(link)
            lin, ang = p.calculateJacobian(robot.body, idx, [0.0, 0.0, 0.0], q.tolist(), zeros,
                                           zeros, physicsClientId=robot.client)
            J_pb = np.vstack([np.asarray(lin), np.asarray(ang)])
            J = robot.frame_jacobian(link, q, "local_world_aligned")
            np.testing.assert_allclose(J, J_pb, atol=1e-6, err_msg=link)
        # A point off the origin of link 5 (which has an inertial offset), in link axes:
        # v_p = v_o + w x (R p).
        p_local = np.array([0.03, -0.05, 0.1])
        lin, ang = p.calculateJacobian(robot.body, robot.pb_link_index("panda_link5"),
                                       p_local.tolist(), q.tolist(), zeros, zeros,
                                       physicsClientId=robot.client)
        J = robot.frame_jacobian("panda_link5", q, "local_world_aligned")
        Rp = robot.frame_pose("panda_link5", q)[:3, :3] @ p_local
        np.testing.assert_allclose(np.asarray(lin), J[:3] + np.cross(J[3:].T, Rp).T,
                                   atol=1e-6)
        np.testing.assert_allclose(np.asarray(ang), J[3:], atol=1e-6)


def test_unknown_frame_and_reference_raise(robot: Robot) -> None:
    with pytest.raises(ConfigError):
        robot.frame_pose("no_such_link", Q_HOME)
    with pytest.raises(ConfigError):
        robot.frame_jacobian("ring2", Q_HOME, "body")
    with pytest.raises(ConfigError):
        robot.pb_link_index("no_such_link")


# --------------------------------------------------------------------------------------
# Limits
# --------------------------------------------------------------------------------------


def test_panda_limits_are_frankas() -> None:
    """Franka Emika Panda datasheet (FCI docs, "Robot and interface specifications")."""
    np.testing.assert_array_equal(
        PANDA_LIMITS.q_min, [-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
    np.testing.assert_array_equal(
        PANDA_LIMITS.q_max, [2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
    assert PANDA_LIMITS.q_max[3] == -0.0698
    np.testing.assert_array_equal(PANDA_LIMITS.qd_max, [2.175] * 4 + [2.61] * 3)
    np.testing.assert_array_equal(PANDA_LIMITS.tau_max, [87.0] * 4 + [12.0] * 3)
    assert np.all(Q_MIN < Q_MAX)


def test_joint_limits_length_mismatch_raises() -> None:
    with pytest.raises(ConfigError):
        JointLimits((0.0, 0.0), (1.0, 1.0), (1.0,), (1.0, 1.0))


def test_urdf_has_the_limits(urdf: Path) -> None:
    root = ET.parse(urdf).getroot()
    for i, name in enumerate(PANDA_JOINTS):
        joints = root.findall(f"joint[@name='{name}']")
        assert len(joints) == 1, name
        lim = joints[0].find("limit")
        assert lim is not None
        assert float(lim.get("lower")) == PANDA_LIMITS.q_min[i]
        assert float(lim.get("upper")) == PANDA_LIMITS.q_max[i]
        assert float(lim.get("velocity")) == PANDA_LIMITS.qd_max[i]
        assert float(lim.get("effort")) == PANDA_LIMITS.tau_max[i]
    # Meshes point at existing files (the URDF loads from anywhere).
    meshes = [m.get("filename") for m in root.iter("mesh")]
    assert meshes and all(Path(f).is_file() for f in meshes)


def test_loaded_models_have_the_limits(robot: Robot) -> None:
    np.testing.assert_allclose(robot.model.lowerPositionLimit, Q_MIN)
    np.testing.assert_allclose(robot.model.upperPositionLimit, Q_MAX)
    np.testing.assert_allclose(robot.model.velocityLimit, PANDA_LIMITS.qd_max)
    for i, j in enumerate(robot.pb_joints):
        info = p.getJointInfo(robot.body, j, physicsClientId=robot.client)
        assert (info[8], info[9]) == (PANDA_LIMITS.q_min[i], PANDA_LIMITS.q_max[i])
        assert info[11] == PANDA_LIMITS.qd_max[i]


# --------------------------------------------------------------------------------------
# World time base
# --------------------------------------------------------------------------------------


def test_steps_per_control() -> None:
    assert WorldConfig(physics_dt=1 / 240, control_dt=1 / 30).steps_per_control == 8
    assert WorldConfig().steps_per_control == 8
    assert WorldConfig(physics_dt=0.001, control_dt=0.001).steps_per_control == 1
    for physics_dt, control_dt in ((1 / 240, 0.03), (0.01, 0.025), (0.01, 0.005)):
        with pytest.raises(ConfigError):
            _ = WorldConfig(physics_dt=physics_dt, control_dt=control_dt).steps_per_control
    with pytest.raises(ConfigError):  # World checks at construction
        World(WorldConfig(physics_dt=1 / 240, control_dt=0.03))


def test_world_time_advances() -> None:
    with World() as world:
        world.step_control()
        world.step_physics()
        assert world.physics_steps == 9
        assert world.t == pytest.approx(9 / 240)


# --------------------------------------------------------------------------------------
# Motors and determinism
# --------------------------------------------------------------------------------------


def test_velocity_mode_tracks_command(urdf: Path) -> None:
    with World() as world:
        robot = Robot(world, urdf, PANDA_JOINTS, PANDA_LIMITS)
        robot.reset(Q_HOME)
        cmd = np.array([0.2, 0, 0, 0, 0, 0, 0])
        robot.set_velocity_command(cmd)
        n_steps = round(0.5 / world.config.physics_dt)
        for _ in range(n_steps):
            world.step_physics()
        assert world.t == pytest.approx(0.5)
        np.testing.assert_allclose(robot.qd(), cmd, atol=1e-2)
        dq = robot.q() - Q_HOME
        assert dq[0] == pytest.approx(0.1, abs=5e-3)
        np.testing.assert_allclose(dq[1:], 0.0, atol=1e-2)  # the others hold against gravity


def test_velocity_command_is_clipped(urdf: Path) -> None:
    with World() as world:
        robot = Robot(world, urdf, PANDA_JOINTS, PANDA_LIMITS)
        robot.reset(Q_HOME)
        robot.set_velocity_command(np.array([0, 0, 0, 0, 0, 0, 10.0]))
        for _ in range(24):
            world.step_physics()
        assert robot.qd()[6] == pytest.approx(PANDA_LIMITS.qd_max[6], abs=2e-2)


def _run(urdf: Path, n_control: int = 60) -> np.ndarray:
    with World() as world:
        robot = Robot(world, urdf, PANDA_JOINTS, PANDA_LIMITS)
        robot.reset(Q_HOME)
        traj = [np.concatenate([robot.q(), robot.qd()])]
        for k in range(n_control):
            t = k * world.config.control_dt
            robot.set_velocity_command(0.2 + 0.3 * np.sin(2 * np.pi * 0.7 * t + np.arange(7)))
            world.step_control()
            traj.append(np.concatenate([robot.q(), robot.qd()]))
        return np.array(traj)


def test_runs_are_bit_identical(urdf: Path) -> None:
    a, b = _run(urdf), _run(urdf)
    assert a.shape == (61, 14)
    assert np.array_equal(a, b)
    assert np.max(np.abs(a[-1, :7] - a[0, :7])) > 0.05  # the robot did move


# --------------------------------------------------------------------------------------
# Inverse kinematics
# --------------------------------------------------------------------------------------


def test_solve_ik_reaches_fk_pose(robot: Robot) -> None:
    rng = np.random.default_rng(5)
    for frame in ("ring2", "camera_optical"):
        for _ in range(3):
            q_true = _random_q(rng, margin=0.3)
            target = robot.frame_pose(frame, q_true)
            q0 = np.clip(q_true + rng.normal(0.0, 0.1, 7), Q_MIN, Q_MAX)
            q = solve_ik(robot, frame, target, q0)
            assert np.all(q >= Q_MIN) and np.all(q <= Q_MAX)
            err = pin.log6(pin.SE3(robot.frame_pose(frame, q)).actInv(pin.SE3(target))).vector
            assert np.linalg.norm(err) < 1e-8, (frame, err)


def test_solve_ik_unreachable_raises(robot: Robot) -> None:
    target = robot.frame_pose("ring2", Q_HOME)
    target[:3, 3] += np.array([3.0, 0.0, 0.0])  # 3 m further: out of reach
    with pytest.raises(ReproError):
        solve_ik(robot, "ring2", target, Q_HOME, iterations=50)


@pytest.mark.parametrize("seed", range(3))
def test_pose_to_pb_is_scipys_quaternion(seed: int) -> None:
    """pose_to_pb's own quaternion equals scipy's from_matrix(...).as_quat() (every branch:
    random rotations and the half turns about each axis, where the trace is -1) and
    PyBullet turns it back into the same matrix."""
    from scipy.spatial.transform import Rotation

    from repro.sim.world import pose_to_pb

    rots = list(Rotation.random(200, random_state=seed).as_matrix())
    rots += [np.diag(d) for d in ((1.0, -1.0, -1.0), (-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0))]
    for R in rots:
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, (0.1, -0.2, 0.3)
        pos, quat = pose_to_pb(T)
        np.testing.assert_allclose(quat, Rotation.from_matrix(R).as_quat(), atol=1e-15)
        np.testing.assert_allclose(np.reshape(p.getMatrixFromQuaternion(quat), (3, 3)), R,
                                   atol=1e-12)
        assert pos == [0.1, -0.2, 0.3]
