"""Tests of the CRS-A465 description (repro/assets/crs_a465, repro.sim.crs_a465).

Published figures are written here as literals (not read back from the module), so a
wrong constant in the module or the URDF fails: joint limits +-175/90/110/180/105/180 deg,
speeds 180/180/180/171/173/171 deg/s, link lengths 0.330/0.305/0.330/0.076 m, axes
z, -y, -y, z, -y, z, and chan2011's eT_c = Rz(90 deg) Rx(-12.5 deg) T(0, -0.085, 0.070).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest
from asset_scripts import import_script
from scipy.spatial.transform import Rotation

from repro.errors import ConfigError
from repro.sim.crs_a465 import (
    CRS_JOINTS,
    CRS_LIMITS,
    T_FLANGE_CAMERA,
    crs_urdf_path,
    dh_flange_pose,
    velocity_limits,
)
from repro.sim.robot import Robot
from repro.sim.world import World

Q_LIMIT_DEG = np.array([175.0, 90.0, 110.0, 180.0, 105.0, 180.0])
QD_MAX_DEG_S = np.array([180.0, 180.0, 180.0, 171.0, 173.0, 171.0])
AXES = np.array([[0, 0, 1], [0, -1, 0], [0, -1, 0], [0, 0, 1], [0, -1, 0], [0, 0, 1]], float)
ARM_LINKS = tuple(f"crs_link{i}" for i in range(7))
BODY_LINKS = ARM_LINKS + ("gripper_palm", "gripper_finger_left", "gripper_finger_right",
                          "camera_body")
FRAME_LINKS = ("flange", "gripper_tcp", "camera_optical")
ALL_LINKS = BODY_LINKS + FRAME_LINKS


@pytest.fixture(scope="module")
def robot():  # type: ignore[no-untyped-def]
    with World() as world:
        yield Robot(world, crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)


def _random_q(rng: np.random.Generator, margin: float = 0.05) -> np.ndarray:
    q_lim = np.deg2rad(Q_LIMIT_DEG)
    return rng.uniform(-q_lim + margin, q_lim - margin)


def _rot_err(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle [rad] of R_a^T R_b."""
    return float(np.linalg.norm(pin.log3(R_a.T @ R_b)))


def _pb_pose(robot: Robot, link: str) -> np.ndarray:
    """T_world_link of a URDF link frame from PyBullet.

    For the base, PyBullet reports the pose of the inertial frame (centre of mass), so the
    URDF link frame is recovered with the local inertial frame from getDynamicsInfo.
    """
    if robot.pb_link_index(link) != -1:
        return robot.pb_link_pose(link)
    pos, quat = p.getBasePositionAndOrientation(robot.body, physicsClientId=robot.client)
    dyn = p.getDynamicsInfo(robot.body, -1, physicsClientId=robot.client)
    T_world_com, T_link_com = np.eye(4), np.eye(4)
    T_world_com[:3, :3] = Rotation.from_quat(quat).as_matrix()
    T_world_com[:3, 3] = pos
    T_link_com[:3, :3] = Rotation.from_quat(dyn[4]).as_matrix()
    T_link_com[:3, 3] = dyn[3]
    return T_world_com @ np.linalg.inv(T_link_com)


def _joint_origins(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World positions of the six joint frames: (pinocchio, PyBullet) (6 x 3 each)."""
    robot.reset(q)
    robot.frame_pose("flange", q)  # runs forward kinematics
    o_pin = np.array([robot.data.oMi[robot.model.getJointId(n)].translation
                      for n in CRS_JOINTS])
    # A PyBullet link frame is the frame of its parent joint.
    o_pb = np.array([robot.pb_link_pose(f"crs_link{i}")[:3, 3] for i in range(1, 7)])
    return o_pin, o_pb


# --------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------


def test_loads_in_pybullet_and_pinocchio(robot: Robot) -> None:
    assert robot.n == 6
    assert robot.model.nq == robot.model.nv == 6
    movable = [j for j in range(p.getNumJoints(robot.body, physicsClientId=robot.client))
               if p.getJointInfo(robot.body, j, physicsClientId=robot.client)[2]
               != p.JOINT_FIXED]
    assert len(movable) == 6
    for j in movable:
        assert p.getJointInfo(robot.body, j, physicsClientId=robot.client)[2] == p.JOINT_REVOLUTE
    assert p.getBodyInfo(robot.body, physicsClientId=robot.client)[0].decode() == "crs_link0"
    for link in ALL_LINKS:
        robot.frame_id(link)  # raises if pinocchio lacks it
        robot.pb_link_index(link)  # raises if PyBullet lacks it
    # A second, independent pinocchio parse (not through Robot).
    model = pin.buildModelFromUrdf(str(crs_urdf_path()))
    assert [model.names[i] for i in range(1, model.njoints)] == list(CRS_JOINTS)


# --------------------------------------------------------------------------------------
# Kinematics
# --------------------------------------------------------------------------------------


def test_flange_upright_at_zero(robot: Robot) -> None:
    """q = 0 is the upright 'ready' pose: flange 0.330 + 0.305 + 0.330 + 0.076 m up,
    pointing up, its frame parallel to the base."""
    q0 = np.zeros(6)
    robot.reset(q0)
    expected = np.eye(4)
    expected[2, 3] = 0.330 + 0.305 + 0.330 + 0.076
    assert expected[2, 3] == pytest.approx(1.041)
    np.testing.assert_allclose(robot.frame_pose("flange", q0), expected, atol=1e-9)
    np.testing.assert_allclose(robot.pb_link_pose("flange"), expected, atol=1e-6)
    np.testing.assert_allclose(robot.frame_pose("crs_link6", q0), expected, atol=1e-9)


def test_link_lengths(robot: Robot) -> None:
    """Consecutive joint origins: base-shoulder 0.330, shoulder-elbow 0.305, joints 3 and 4
    both at the elbow, elbow-wrist 0.330, wrist-flange 0.076 (joint 6 at the flange)."""
    expected = [0.330, 0.305, 0.0, 0.330, 0.076]
    rng = np.random.default_rng(10)
    for q in (np.zeros(6), _random_q(rng), _random_q(rng)):
        for o in _joint_origins(robot, q):
            # PyBullet keeps URDF origins in single precision: 1e-6 m.
            np.testing.assert_allclose(np.linalg.norm(np.diff(o, axis=0), axis=1), expected,
                                       atol=1e-6)
            np.testing.assert_allclose(o[0], 0.0, atol=1e-9)  # joint 1 on the mounting surface
    o_pin, _ = _joint_origins(robot, np.zeros(6))
    np.testing.assert_allclose(o_pin[:, 2], [0.0, 0.330, 0.635, 0.635, 0.965, 1.041], atol=1e-9)
    np.testing.assert_allclose(o_pin[:, :2], 0.0, atol=1e-12)


def test_joint_axes_at_zero(robot: Robot) -> None:
    q0 = np.zeros(6)
    robot.reset(q0)
    # pinocchio: the angular rows of the world Jacobian are the joint axes in the world.
    J = robot.frame_jacobian("flange", q0, "world")
    np.testing.assert_allclose(J[3:].T, AXES, atol=1e-12)
    # PyBullet: the joint axis (in the child link frame) rotated into the world.
    for k, name in enumerate(CRS_JOINTS):
        info = p.getJointInfo(robot.body, robot.pb_joints[k], physicsClientId=robot.client)
        assert info[1].decode() == name
        R = robot.pb_link_pose(f"crs_link{k + 1}")[:3, :3]
        np.testing.assert_allclose(R @ np.asarray(info[13]), AXES[k], atol=1e-9)


def test_positive_pitch_tilts_towards_minus_x(robot: Robot) -> None:
    """Axis -y: a small positive q2 moves the flange towards -x (the documented sign)."""
    T = robot.frame_pose("flange", np.array([0.0, 0.1, 0.0, 0.0, 0.0, 0.0]))
    assert T[0, 3] == pytest.approx(-(0.305 + 0.330 + 0.076) * np.sin(0.1))
    assert T[2, 3] == pytest.approx(0.330 + (0.305 + 0.330 + 0.076) * np.cos(0.1))


def test_pinocchio_matches_pybullet(robot: Robot) -> None:
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = _random_q(rng)
        robot.reset(q)
        np.testing.assert_allclose(robot.q(), q, atol=1e-12)
        for link in ALL_LINKS:
            T_pin = robot.frame_pose(link, q)
            T_pb = _pb_pose(robot, link)
            np.testing.assert_allclose(T_pin[:3, 3], T_pb[:3, 3], atol=1e-6, err_msg=link)
            assert _rot_err(T_pin[:3, :3], T_pb[:3, :3]) < 1e-6, link


def test_dh_table_matches_urdf(robot: Robot) -> None:
    """The README's / module's standard DH table gives the URDF's flange pose."""
    rng = np.random.default_rng(1)
    for q in [np.zeros(6)] + [_random_q(rng) for _ in range(10)]:
        np.testing.assert_allclose(dh_flange_pose(q), robot.frame_pose("flange", q),
                                   atol=1e-12)
    with pytest.raises(ConfigError):
        dh_flange_pose(np.zeros(5))


# --------------------------------------------------------------------------------------
# Camera and gripper
# --------------------------------------------------------------------------------------


def test_camera_optical_is_papers_eTc(robot: Robot) -> None:
    """chan2011 Sec. V-A: eT_c = Rz(90 deg) Rx(-12.5 deg) T(0, -0.085, 0.070) [m], the
    camera (= optical) frame in the flange frame, product read left to right."""
    T_ref = np.eye(4)
    T_ref[:3, :3] = Rotation.from_euler("ZX", [90.0, -12.5], degrees=True).as_matrix()
    T_ref[:3, 3] = T_ref[:3, :3] @ np.array([0.0, -0.085, 0.070])
    np.testing.assert_allclose(T_FLANGE_CAMERA, T_ref, atol=1e-15)
    # By hand: the optical centre 68 mm to the flange's +x side and 87 mm above it; the
    # optical axis along the flange z, tilted 12.5 deg towards the gripper axis (-x); the
    # image x axis along flange +y.
    s, c = np.sin(np.deg2rad(12.5)), np.cos(np.deg2rad(12.5))
    np.testing.assert_allclose(T_ref[:3, 3], [0.085 * c - 0.070 * s, 0.0,
                                              0.085 * s + 0.070 * c], atol=1e-15)
    np.testing.assert_allclose(T_ref[:3, 3], [0.06783, 0.0, 0.08674], atol=1e-5)
    np.testing.assert_allclose(T_ref[:3, 2], [-s, 0.0, c], atol=1e-15)
    np.testing.assert_allclose(T_ref[:3, 0], [0.0, 1.0, 0.0], atol=1e-15)
    rng = np.random.default_rng(2)
    for q in (np.zeros(6), _random_q(rng), _random_q(rng)):
        robot.reset(q)
        # pinocchio to 1e-9; PyBullet keeps URDF origins in single precision (1e-6).
        for pose, tol in ((robot.frame_pose, 1e-9),
                          (lambda link, _q: robot.pb_link_pose(link), 1e-6)):
            T_fc = np.linalg.inv(pose("flange", q)) @ pose("camera_optical", q)
            np.testing.assert_allclose(T_fc, T_ref, atol=tol)
            T_fb = np.linalg.inv(pose("flange", q)) @ pose("camera_body", q)
            np.testing.assert_allclose(T_fb, T_ref, atol=tol)


def test_gripper_tcp_between_fingertips(robot: Robot) -> None:
    """At q = 0 (flange axes = world axes) the fingers point up from the palm, and the TCP
    is on the flange axis between them, in their distal half."""
    q0 = np.zeros(6)
    robot.reset(q0)
    tcp = robot.frame_pose("gripper_tcp", q0)[:3, 3]
    flange = robot.frame_pose("flange", q0)[:3, 3]
    np.testing.assert_allclose(tcp[:2], 0.0, atol=1e-9)
    lo_l, hi_l = (np.array(v) for v in p.getAABB(
        robot.body, robot.pb_link_index("gripper_finger_left"), physicsClientId=robot.client))
    lo_r, hi_r = (np.array(v) for v in p.getAABB(
        robot.body, robot.pb_link_index("gripper_finger_right"), physicsClientId=robot.client))
    lo_p, hi_p = (np.array(v) for v in p.getAABB(
        robot.body, robot.pb_link_index("gripper_palm"), physicsClientId=robot.client))
    assert lo_p[2] == pytest.approx(flange[2], abs=2e-3)  # the palm sits on the flange
    for lo, hi in ((lo_l, hi_l), (lo_r, hi_r)):
        assert lo[2] == pytest.approx(hi_p[2], abs=2e-3)  # finger roots on the palm
        assert hi[2] - lo[2] > 0.04  # long along the flange z
        assert (lo[2] + hi[2]) / 2 < tcp[2] < hi[2]
    assert lo_r[1] < hi_r[1] < tcp[1] < lo_l[1] < hi_l[1]  # between the fingers in y
    assert tcp[1] - hi_r[1] == pytest.approx(lo_l[1] - tcp[1], abs=1e-6)


def test_collision_geometry(robot: Robot) -> None:
    """Every body link (arm, gripper, camera) has collision shapes; frames have none."""
    for link in BODY_LINKS:
        shapes = p.getCollisionShapeData(robot.body, robot.pb_link_index(link),
                                         physicsClientId=robot.client)
        assert len(shapes) >= 1, link
        # Robot loads without URDF_USE_IMPLICIT_CYLINDER: cylinders become convex hulls.
        for s in shapes:
            assert s[2] in (p.GEOM_BOX, p.GEOM_CYLINDER, p.GEOM_MESH), link
    for link in FRAME_LINKS:
        assert p.getCollisionShapeData(robot.body, robot.pb_link_index(link),
                                       physicsClientId=robot.client) == (), link
    # The camera body: 0.05 x 0.05 x 0.07 m, along the optical axis, behind the lens front.
    cam = p.getCollisionShapeData(robot.body, robot.pb_link_index("camera_body"),
                                  physicsClientId=robot.client)
    assert len(cam) == 1 and cam[0][2] == p.GEOM_BOX
    np.testing.assert_allclose(cam[0][3], [0.05, 0.05, 0.07], atol=1e-9)
    # Only primitives in the URDF (no meshes, no capsules); base column ~0.2 m diameter.
    root = ET.parse(crs_urdf_path()).getroot()
    kinds = {g.tag for g in root.iter() if g.tag in ("box", "cylinder", "sphere", "mesh",
                                                      "capsule")}
    assert kinds == {"box", "cylinder"}
    base = root.find("link[@name='crs_link0']")
    assert base is not None
    radii = [float(c.get("radius", "nan")) for c in base.iter("cylinder")]
    assert radii and 0.09 <= max(radii) <= 0.11


def test_camera_and_gripper_clear_of_each_other(robot: Robot) -> None:
    """The mounted camera does not intersect the gripper or the flange (whatever q)."""
    q = _random_q(np.random.default_rng(4))
    robot.reset(q)
    cam = robot.pb_link_index("camera_body")
    for link in ("gripper_palm", "gripper_finger_left", "gripper_finger_right", "crs_link6"):
        pts = p.getClosestPoints(robot.body, robot.body, 0.05, cam, robot.pb_link_index(link),
                                 physicsClientId=robot.client)
        assert all(pt[8] > 0.005 for pt in pts), link


# --------------------------------------------------------------------------------------
# Limits, masses
# --------------------------------------------------------------------------------------


def test_limits_are_published(robot: Robot) -> None:
    np.testing.assert_allclose(CRS_LIMITS.q_max, np.deg2rad(Q_LIMIT_DEG), rtol=1e-15)
    np.testing.assert_allclose(CRS_LIMITS.q_min, -np.deg2rad(Q_LIMIT_DEG), rtol=1e-15)
    np.testing.assert_allclose(CRS_LIMITS.qd_max, np.deg2rad(QD_MAX_DEG_S), rtol=1e-15)
    tau = np.asarray(CRS_LIMITS.tau_max)
    assert np.all(tau[:3] >= 20.0) and np.all(tau[3:] <= 10.0) and np.all(tau > 0)
    # The URDF, as PyBullet and pinocchio read it, has the same limits.
    for k in range(6):
        info = p.getJointInfo(robot.body, robot.pb_joints[k], physicsClientId=robot.client)
        lower, upper, force, velocity = info[8], info[9], info[10], info[11]
        assert (lower, upper) == pytest.approx((CRS_LIMITS.q_min[k], CRS_LIMITS.q_max[k]),
                                               abs=1e-9)
        assert velocity == pytest.approx(CRS_LIMITS.qd_max[k], abs=1e-9)
        assert force == pytest.approx(CRS_LIMITS.tau_max[k], abs=1e-9)
    np.testing.assert_allclose(robot.model.lowerPositionLimit, CRS_LIMITS.q_min, atol=1e-9)
    np.testing.assert_allclose(robot.model.upperPositionLimit, CRS_LIMITS.q_max, atol=1e-9)
    np.testing.assert_allclose(robot.model.velocityLimit, CRS_LIMITS.qd_max, atol=1e-9)
    np.testing.assert_allclose(robot.model.effortLimit, CRS_LIMITS.tau_max, atol=1e-9)


def test_velocity_limits_fraction() -> None:
    """chan2011 Sec. V-A: 5 % of the maximum joint speeds."""
    np.testing.assert_allclose(velocity_limits(0.05), 0.05 * np.deg2rad(QD_MAX_DEG_S),
                               rtol=1e-15)
    np.testing.assert_allclose(np.rad2deg(velocity_limits(0.05)),
                               [9.0, 9.0, 9.0, 8.55, 8.65, 8.55], rtol=1e-12)
    np.testing.assert_allclose(velocity_limits(1.0), CRS_LIMITS.qd_max, rtol=1e-15)
    for bad in (0.0, -0.05, 1.5):
        with pytest.raises(ConfigError):
            velocity_limits(bad)


def test_mass_properties(robot: Robot) -> None:
    """31 kg arm; every body's inertia is physically valid; PyBullet and pinocchio read the
    same masses."""
    root = ET.parse(crs_urdf_path()).getroot()
    masses = {}
    for link in root.findall("link"):
        name = link.get("name", "")
        mass = link.find("inertial/mass")
        assert mass is not None
        m = float(mass.get("value", "nan"))
        masses[name] = m
        inertia = link.find("inertial/inertia")
        assert inertia is not None
        I = np.array([[float(inertia.get("i" + a + b, inertia.get("i" + b + a, "nan")))
                       for b in "xyz"] for a in "xyz"])
        if name in FRAME_LINKS:
            assert m == 0.0 and not I.any(), name
            continue
        assert m > 0, name
        ev = np.linalg.eigvalsh(I)
        assert ev.min() > 0, name
        assert ev[0] + ev[1] >= ev[2] - 1e-12, name  # triangle inequality
        if name != "crs_link0":
            idx = robot.pb_link_index(name)
            dyn = p.getDynamicsInfo(robot.body, idx, physicsClientId=robot.client)
            assert dyn[0] == pytest.approx(m), name
            np.testing.assert_allclose(dyn[2], np.diag(I), rtol=1e-9, err_msg=name)
    assert sum(masses[n] for n in ARM_LINKS) == pytest.approx(31.0)
    # pinocchio: base merged into the universe, everything else into the six bodies.
    assert sum(i.mass for i in robot.model.inertias) == pytest.approx(sum(masses.values()))


def test_holds_outstretched_arm_against_gravity(robot: Robot) -> None:
    """The torque limits (ours) hold the near-horizontal arm still in velocity mode (q2 and
    q5 at 80 deg, inside their limits: a joint at its limit would be held by the limit)."""
    q = np.array([0.3, 1.4, 0.0, 0.0, 1.4, 0.0])
    g = pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q)
    assert np.all(np.abs(g) < 0.8 * np.asarray(CRS_LIMITS.tau_max))
    assert abs(g[1]) > 20.0  # the shoulder does carry the arm
    robot.reset(q)
    robot.velocity_mode()
    for _ in range(240):
        robot.world.step_physics()
    np.testing.assert_allclose(robot.q(), q, atol=2e-3)


# --------------------------------------------------------------------------------------
# Generator
# --------------------------------------------------------------------------------------


def test_committed_urdf_is_make_urdf_output() -> None:
    module = import_script(crs_urdf_path().with_name("make_urdf.py"), "crs_make_urdf")
    text = module.build_urdf()
    assert text == module.build_urdf()  # deterministic
    assert crs_urdf_path().read_text() == text, (
        "crs_a465.urdf is stale: run .venv/bin/python repro/assets/crs_a465/make_urdf.py")
