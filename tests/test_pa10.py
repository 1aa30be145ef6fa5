"""Tests of the pomares2011 robot chain (repro/assets/pa10, repro.sim.pa10): PA-10 + the
Barrett BH8-282 (repro/assets/barrett_bh8) + RRR mini-robot with its camera, one URDF, one
Robot of 17 joints.

Published figures are written here as literals (not read back from the module), so a wrong
constant in the module or the URDF fails: ARTE's DH table (d 0.315/0/0/0.50/0/0.08,
a 0/0.45/0/0/0/0, alpha 90/0/90/-90/90/0 deg, offsets +90 deg on joints 2-3), limits
+-177/91/137/255/165/360 deg and speeds 200/200/260/360/360/450 deg/s, the manufacturer's
link masses, and the BH8-282 masses (base 0.60 kg, finger 0.179 kg) and palm height.
"""

from __future__ import annotations

import itertools
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest
from asset_scripts import import_script

from repro.assets.urdf_primitives import mass_properties
from repro.errors import ConfigError
from repro.sim import barrett as B
from repro.sim.drives import TorqueDrive
from repro.sim.pa10 import (
    ALL_JOINTS,
    ALL_LIMITS,
    HAND_JOINTS,
    MINI_GEOMETRY,
    MINI_JOINTS,
    MINI_LIMITS,
    MINI_MASSES,
    PA10_DH,
    PA10_JOINTS,
    PA10_LIMITS,
    PALM_HEIGHT,
    pa10_dh_fk,
    pa10_dh_frames,
    pa10_urdf_path,
)
from repro.sim.robot import Robot
from repro.sim.world import World, WorldConfig

Q_LIMIT_DEG = np.array([177.0, 91.0, 137.0, 255.0, 165.0, 360.0])
QD_MAX_DEG_S = np.array([200.0, 200.0, 260.0, 360.0, 360.0, 450.0])
# 7-DoF manufacturer masses mapped to the 6-DoF links (README): base, 1, 2 = 8.41 + 3.51, ...
PA10_MASSES = {"pa10_link0": 3.04, "pa10_link1": 9.78, "pa10_link2": 11.92,
               "pa10_link3": 4.31, "pa10_link4": 3.45, "pa10_link5": 1.46, "pa10_link6": 0.24}
FINGER_LINKS = tuple(f"bh8_finger{k}_{part}" for k in (1, 2, 3)
                     for part in ("knuckle", "proximal", "distal"))
HAND_LINKS = ("bh8_base", "bh8_palm") + FINGER_LINKS
MINI_BODY_LINKS = ("mini_base", "mini_link1", "mini_link2", "mini_link3", "mini_camera")
BODY_LINKS = tuple(PA10_MASSES) + HAND_LINKS + MINI_BODY_LINKS
FRAME_LINKS = ("pa10_flange", "mini_camera_optical") + B.BH8_PAD_FRAMES + B.BH8_TIP_FRAMES
N_JOINTS = 17


def _hand(proximal_deg: float) -> np.ndarray:
    """(8,) hand joints: spread 0, every finger's motor at 125 x ``proximal_deg`` (engaged)."""
    return B.hand_joints_from_motors((B.J2_RATIO * np.deg2rad(proximal_deg),) * 3)


#: The hand half open (the approach pose of pomares2011 experiments 1-2).
HALF_OPEN = _hand(60.0)


def _q(arm_mini: np.ndarray | list[float], hand: np.ndarray = HALF_OPEN) -> np.ndarray:
    """(17,) ALL_JOINTS order: 9 arm + mini-robot joints, then the hand."""
    return np.r_[np.asarray(arm_mini, dtype=float), hand]
ALL_LINKS = BODY_LINKS + FRAME_LINKS
PHYSICS_1KHZ = WorldConfig(physics_dt=1e-3, control_dt=1e-3)


@pytest.fixture(scope="module")
def robot():  # type: ignore[no-untyped-def]
    with World() as world:
        yield Robot(world, pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS)


def _random_q(rng: np.random.Generator, margin: float = 0.05) -> np.ndarray:
    return rng.uniform(np.asarray(ALL_LIMITS.q_min) + margin,
                       np.asarray(ALL_LIMITS.q_max) - margin)


def _rot_err(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle [rad] of R_a^T R_b."""
    return float(np.linalg.norm(pin.log3(R_a.T @ R_b)))


def _rel(robot: Robot, a: str, b: str, q: np.ndarray) -> np.ndarray:
    """T_a_b (pinocchio)."""
    return np.linalg.inv(robot.frame_pose(a, q)) @ robot.frame_pose(b, q)


# --------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------


def test_loads_in_pybullet_and_pinocchio(robot: Robot) -> None:
    assert ALL_JOINTS == PA10_JOINTS + MINI_JOINTS + B.BH8_JOINTS
    assert HAND_JOINTS == B.BH8_JOINTS
    assert PA10_JOINTS == tuple(f"pa10_joint{i}" for i in range(1, 7))
    assert MINI_JOINTS == ("mini_joint1", "mini_joint2", "mini_joint3")
    assert robot.n == N_JOINTS and robot.model.nq == robot.model.nv == N_JOINTS
    movable = [j for j in range(p.getNumJoints(robot.body, physicsClientId=robot.client))
               if p.getJointInfo(robot.body, j, physicsClientId=robot.client)[2]
               != p.JOINT_FIXED]
    assert len(movable) == N_JOINTS
    for j in movable:
        assert p.getJointInfo(robot.body, j, physicsClientId=robot.client)[2] == p.JOINT_REVOLUTE
    assert p.getBodyInfo(robot.body, physicsClientId=robot.client)[0].decode() == "pa10_link0"
    for link in ALL_LINKS:
        assert " " not in link
        robot.frame_id(link)  # raises if pinocchio lacks it
        robot.pb_link_index(link)  # raises if PyBullet lacks it
    # A second, independent pinocchio parse (not through Robot): the same joints (pinocchio
    # orders the flange's two subtrees by its own rule; Robot maps them by name).
    model = pin.buildModelFromUrdf(str(pa10_urdf_path()))
    assert sorted(model.names[i] for i in range(1, model.njoints)) == sorted(ALL_JOINTS)


def test_no_joint_damping_or_friction(robot: Robot) -> None:
    """Torque control at 1 kHz relies on undamped joints (facts sheet: URDF damping makes
    gravity compensation drift)."""
    root = ET.parse(pa10_urdf_path()).getroot()
    assert root.find(".//dynamics") is None
    for j in robot.pb_joints:
        info = p.getJointInfo(robot.body, j, physicsClientId=robot.client)
        assert info[6] == 0.0 and info[7] == 0.0, info[1]


# --------------------------------------------------------------------------------------
# PA-10 kinematics
# --------------------------------------------------------------------------------------


def test_dh_table_is_artes() -> None:
    """ARTE parameters.m: theta = [q1, q2 + pi/2, q3 + pi/2, q4, q5, q6],
    d = [0.315 0 0 0.5 0 0.08], a = [0 0.45 0 0 0 0], alpha = [pi/2 0 pi/2 -pi/2 pi/2 0]."""
    h = np.pi / 2
    expected = [(0, 0.315, 0, h), (h, 0, 0.45, 0), (h, 0, 0, h), (0, 0.5, 0, -h),
                (0, 0, 0, h), (0, 0.08, 0, 0)]
    np.testing.assert_array_equal(np.array(PA10_DH), np.array(expected, dtype=float))
    with pytest.raises(ConfigError):
        pa10_dh_fk(np.zeros(7))


def test_upright_at_zero_and_tilt_sign(robot: Robot) -> None:
    """q = 0: the arm straight up, the flange 0.315 + 0.45 + 0.50 + 0.08 = 1.345 m above the
    base, DH frame 6 turned 180 deg about z (the +90 deg offsets of joints 2-3 cancel the
    alphas); a positive q2 tilts the arm towards -x."""
    expected = np.diag([-1.0, -1.0, 1.0, 1.0])
    expected[2, 3] = 1.345
    np.testing.assert_allclose(pa10_dh_fk(np.zeros(6)), expected, atol=1e-15)
    np.testing.assert_allclose(robot.frame_pose("pa10_flange", np.zeros(N_JOINTS)), expected,
                               atol=1e-9)
    q = np.zeros(N_JOINTS)
    q[1] = 0.1
    T = robot.frame_pose("pa10_flange", q)
    assert T[0, 3] == pytest.approx(-(0.45 + 0.50 + 0.08) * np.sin(0.1), abs=1e-12)
    assert T[2, 3] == pytest.approx(0.315 + (0.45 + 0.50 + 0.08) * np.cos(0.1), abs=1e-12)
    # q3 = -90 deg: the forearm horizontal, the flange 0.45 up and 0.58 out along +x.
    q = np.zeros(N_JOINTS)
    q[2] = -np.pi / 2
    np.testing.assert_allclose(robot.frame_pose("pa10_flange", q)[:3, 3],
                               [0.58, 0.0, 0.765], atol=1e-12)


def test_urdf_fk_equals_dh_table(robot: Robot) -> None:
    """pinocchio's pa10_flange equals the DH flange pose to 1e-9 at random q (whatever the
    mini-robot does), and every PA-10 joint turns about the DH axis z_{i-1}."""
    rng = np.random.default_rng(1)
    for q in [np.zeros(N_JOINTS)] + [_random_q(rng) for _ in range(20)]:
        np.testing.assert_allclose(robot.frame_pose("pa10_flange", q), pa10_dh_fk(q[:6]),
                                   atol=1e-9)
        frames = pa10_dh_frames(q[:6])
        J = robot.frame_jacobian("pa10_flange", q, "world")
        for i in range(6):
            z, o = frames[i][:3, 2], frames[i][:3, 3]
            np.testing.assert_allclose(J[3:, i], z, atol=1e-9)
            # The joint origin lies on the DH axis line.
            o_pin = robot.data.oMi[robot.model.getJointId(PA10_JOINTS[i])].translation
            np.testing.assert_allclose(np.cross(o_pin - o, z), 0.0, atol=1e-9)


def test_pinocchio_matches_pybullet(robot: Robot) -> None:
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = _random_q(rng)
        robot.reset(q)
        np.testing.assert_allclose(robot.q(), q, atol=1e-12)
        for link in ALL_LINKS:
            T_pin = robot.frame_pose(link, q)
            T_pb = robot.pb_link_pose(link)
            # PyBullet keeps URDF origins in single precision: 1e-6.
            np.testing.assert_allclose(T_pin[:3, 3], T_pb[:3, 3], atol=1e-6, err_msg=link)
            assert _rot_err(T_pin[:3, :3], T_pb[:3, :3]) < 1e-6, link


# --------------------------------------------------------------------------------------
# Hand, mini-robot, camera
# --------------------------------------------------------------------------------------


def test_hand_on_flange(robot: Robot) -> None:
    """The BH8-282 on the flange: bh8_base = pa10_flange, bh8_palm 79 mm out on its axis,
    and every hand frame relative to bh8_base is Barrett's DH frame of the standalone hand
    (repro.sim.barrett.bh8_dh_frames) at random hand joints, whatever the arm does."""
    rng = np.random.default_rng(5)
    for _ in range(5):
        q = _random_q(rng)
        np.testing.assert_allclose(_rel(robot, "pa10_flange", "bh8_base", q), np.eye(4),
                                   atol=1e-12)
        T_fp = _rel(robot, "pa10_flange", "bh8_palm", q)
        np.testing.assert_allclose(T_fp[:3, :3], np.eye(3), atol=1e-12)
        np.testing.assert_allclose(T_fp[:3, 3], [0.0, 0.0, 0.079], atol=1e-12)
        qh = dict(zip(ALL_JOINTS, q, strict=True))
        for k in (1, 2, 3):
            spread = qh["bh8_finger1_spread"] if k == 1 else qh["bh8_finger2_spread"]
            frames = B.bh8_dh_frames(k, spread if k != 3 else 0.0,
                                     qh[f"bh8_finger{k}_proximal_joint"],
                                     qh[f"bh8_finger{k}_distal_joint"])
            for name, T_dh in zip(("knuckle", "proximal", "distal", "tip"), frames,
                                  strict=True):
                link = f"bh8_finger{k}_{name}"
                np.testing.assert_allclose(_rel(robot, "bh8_base", link, q), T_dh, atol=1e-9,
                                           err_msg=link)
    assert PALM_HEIGHT == pytest.approx(0.079)


def test_half_open_hand_clears_the_camera_view(robot: Robot) -> None:
    """The approach pose (every finger half open) keeps all nine phalanges and knuckles
    below the optical centre at q = 0, the tips of finger 3 and of fingers 1-2 on either
    side of the hand axis."""
    q = _q(np.zeros(9))
    T_fc = _rel(robot, "pa10_flange", "mini_camera_optical", q)
    for k in (1, 2, 3):
        tip = _rel(robot, "bh8_palm", f"bh8_finger{k}_tip", q)[:3, 3]
        assert (tip[1] > 0.03) if k == 3 else (tip[1] < -0.03), (k, tip)
        assert 0.0 < _rel(robot, "pa10_flange", f"bh8_finger{k}_tip", q)[2, 3] < T_fc[2, 3] - 0.05


def test_camera_looks_forward_at_zero(robot: Robot) -> None:
    """Stated property: at q = 0 the optical axis (z) is the flange +z, the optical centre
    0.13 m off the hand axis (flange +x) and 0.25 m out, ahead of the fingertips; image y
    points away from the hand axis; nothing of the robot is in front of the lens."""
    q0 = _q(np.zeros(9))
    T = _rel(robot, "pa10_flange", "mini_camera_optical", q0)
    # 1e-10: the URDF writes angles to 12 significant digits.
    np.testing.assert_allclose(T[:3, :3], [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-10)
    np.testing.assert_allclose(T[:3, 3], [0.13, 0.0, 0.25], atol=1e-12)
    np.testing.assert_allclose(_rel(robot, "pa10_flange", "mini_base", q0), np.eye(4),
                               atol=1e-12)
    robot.reset(q0)
    T_wf = robot.pb_link_pose("pa10_flange")
    for link in FINGER_LINKS:
        lo, hi = p.getAABB(robot.body, robot.pb_link_index(link), physicsClientId=robot.client)
        corners = np.array(list(itertools.product(*zip(lo, hi, strict=True))))
        z_flange = (np.linalg.inv(T_wf) @ np.c_[corners, np.ones(8)].T)[2]
        assert z_flange.max() < T[2, 3] - 0.03, link
    T_wc = robot.frame_pose("mini_camera_optical", q0)
    start = T_wc @ np.array([0.0, 0.0, 1e-3, 1.0])
    end = T_wc @ np.array([0.0, 0.0, 1.0, 1.0])
    hit = p.rayTest(start[:3].tolist(), end[:3].tolist(), physicsClientId=robot.client)[0]
    assert hit[0] == -1


@pytest.mark.parametrize("ahead", [0.2, 0.3, 0.4])
def test_camera_can_look_at_object_ahead_of_hand(robot: Robot, ahead: float) -> None:
    """A point on the hand axis ``ahead`` [m] in front of the palm (the PA-10 reaching
    forward) can be put at the image centre, unoccluded, wherever q1 puts the mini-robot,
    with q2, q3 inside their limits; leaning back (q2 = -0.6 rad) the camera sees it from
    >= 0.14 m. The optical axis is the line joint 3 -> camera, so
    q2 + q3 = atan2(r3, z_obj - z3) with joint 3 at (r3, z3) (radius, height in mini_base)."""
    rng = np.random.default_rng(int(ahead * 100))
    g = MINI_GEOMETRY
    for q1, q2 in itertools.product((-2.5, -1.0, 0.0, 1.6, 3.0), (-0.6, -0.3, 0.0)):
        # The PA-10 reaching forward, its forearm horizontal, random rolls and base turn.
        q = _q(np.zeros(9))
        q[[0, 3, 5]] = rng.uniform(-3.0, 3.0, 3)
        q[2] = -np.pi / 2
        q[6], q[7] = q1, q2
        r3 = g.radius - g.link2 * np.sin(q2)
        z3 = g.joint2_height + g.link2 * np.cos(q2)
        z_obj = PALM_HEIGHT + ahead
        q[8] = np.arctan2(r3, z_obj - z3) - q2
        assert MINI_LIMITS.q_min[2] < q[8] < MINI_LIMITS.q_max[2]
        P_world = robot.frame_pose("bh8_palm", q) @ np.array([0.0, 0.0, ahead, 1.0])
        P_cam = np.linalg.inv(robot.frame_pose("mini_camera_optical", q)) @ P_world
        np.testing.assert_allclose(P_cam[:2] / P_cam[2], 0.0, atol=1e-9)
        assert P_cam[2] > (0.14 if q2 == -0.6 else 0.08)  # depth [m]
        robot.reset(q)
        start = robot.frame_pose("mini_camera_optical", q) @ np.array([0.0, 0.0, 1e-3, 1.0])
        hit = p.rayTest(start[:3].tolist(), P_world[:3].tolist(),
                        physicsClientId=robot.client)[0]
        assert hit[0] == -1, (q1, q2, hit)


@pytest.mark.parametrize("proximal_deg", [60.0, 100.0, 140.0])
def test_mini_robot_clears_hand(robot: Robot, proximal_deg: float) -> None:
    """Turning around the task (q1, q2 = q3 = 0) the mini-robot stays >= 1 cm from the hand,
    its fingers from the approach pose (60 deg) to fully closed."""
    for q1 in np.linspace(-np.pi, np.pi, 25):
        q = _q(np.zeros(9), _hand(proximal_deg))
        q[6] = q1
        robot.reset(q)
        for a, b in itertools.product(MINI_BODY_LINKS[1:], HAND_LINKS):
            pts = p.getClosestPoints(robot.body, robot.body, 0.05, robot.pb_link_index(a),
                                     robot.pb_link_index(b), physicsClientId=robot.client)
            assert all(pt[8] > 0.01 for pt in pts), (q1, a, b)


def test_collision_geometry(robot: Robot) -> None:
    """Every body link has collision shapes; frames have none; only boxes and cylinders."""
    for link in BODY_LINKS:
        shapes = p.getCollisionShapeData(robot.body, robot.pb_link_index(link),
                                         physicsClientId=robot.client)
        assert len(shapes) >= 1, link
        for s in shapes:
            assert s[2] in (p.GEOM_BOX, p.GEOM_CYLINDER), link
    for link in FRAME_LINKS:
        assert p.getCollisionShapeData(robot.body, robot.pb_link_index(link),
                                       physicsClientId=robot.client) == (), link
    root = ET.parse(pa10_urdf_path()).getroot()
    kinds = {g.tag for g in root.iter() if g.tag in ("box", "cylinder", "sphere", "mesh",
                                                      "capsule")}
    assert kinds == {"box", "cylinder"}
    # Roughly the real arm: base column ~0.23 m across, the upper arm 0.12 m.
    for link, radius in (("pa10_link0", 0.115), ("pa10_link2", 0.06)):
        el = root.find(f"link[@name='{link}']")
        assert el is not None
        assert max(float(c.get("radius", "nan")) for c in el.iter("cylinder")) == radius


# --------------------------------------------------------------------------------------
# Limits, masses
# --------------------------------------------------------------------------------------


def test_limits(robot: Robot) -> None:
    np.testing.assert_allclose(PA10_LIMITS.q_max, np.deg2rad(Q_LIMIT_DEG), rtol=1e-15)
    np.testing.assert_allclose(PA10_LIMITS.q_min, -np.deg2rad(Q_LIMIT_DEG), rtol=1e-15)
    np.testing.assert_allclose(PA10_LIMITS.qd_max, np.deg2rad(QD_MAX_DEG_S), rtol=1e-15)
    for field in ("q_min", "q_max", "qd_max", "tau_max"):
        assert getattr(ALL_LIMITS, field) == (getattr(PA10_LIMITS, field)
                                              + getattr(MINI_LIMITS, field)
                                              + getattr(B.BH8_LIMITS, field))
    assert np.all(np.asarray(ALL_LIMITS.tau_max) > 0)
    # The URDF, as PyBullet and pinocchio read it, has the same limits.
    for k in range(N_JOINTS):
        info = p.getJointInfo(robot.body, robot.pb_joints[k], physicsClientId=robot.client)
        lower, upper, force, velocity = info[8], info[9], info[10], info[11]
        assert (lower, upper) == pytest.approx((ALL_LIMITS.q_min[k], ALL_LIMITS.q_max[k]),
                                               abs=1e-9)
        assert velocity == pytest.approx(ALL_LIMITS.qd_max[k], abs=1e-9)
        assert force == pytest.approx(ALL_LIMITS.tau_max[k], abs=1e-9)
    m = robot.model
    idx = [m.joints[m.getJointId(n)].idx_q for n in ALL_JOINTS]  # pinocchio's own order
    np.testing.assert_allclose(m.lowerPositionLimit[idx], ALL_LIMITS.q_min, atol=1e-9)
    np.testing.assert_allclose(m.upperPositionLimit[idx], ALL_LIMITS.q_max, atol=1e-9)
    np.testing.assert_allclose(m.velocityLimit[idx], ALL_LIMITS.qd_max, atol=1e-9)
    np.testing.assert_allclose(m.effortLimit[idx], ALL_LIMITS.tau_max, atol=1e-9)


def test_mass_properties(robot: Robot) -> None:
    """Masses as published / stated; every inertia physically valid; PyBullet reads the
    same masses, principal moments and principal axes."""
    root = ET.parse(pa10_urdf_path()).getroot()
    masses: dict[str, float] = {}
    for link in root.findall("link"):
        name = link.get("name", "")
        mass = link.find("inertial/mass")
        inertia = link.find("inertial/inertia")
        origin = link.find("inertial/origin")
        assert mass is not None and inertia is not None and origin is not None
        m = masses[name] = float(mass.get("value", "nan"))
        I = np.array([[float(inertia.get("i" + a + b, inertia.get("i" + b + a, "nan")))
                       for b in "xyz"] for a in "xyz"])
        if name in FRAME_LINKS:
            assert m == 0.0 and not I.any(), name
            continue
        assert m > 0, name
        assert not (I - np.diag(np.diag(I))).any(), name  # principal axes written
        ev = np.linalg.eigvalsh(I)
        assert ev.min() > 0 and ev[0] + ev[1] >= ev[2] - 1e-12, name  # triangle inequality
        if name == "pa10_link0":
            continue
        dyn = p.getDynamicsInfo(robot.body, robot.pb_link_index(name),
                                physicsClientId=robot.client)
        assert dyn[0] == pytest.approx(m), name
        np.testing.assert_allclose(dyn[2], np.diag(I), rtol=1e-9, err_msg=name)
        rpy = [float(v) for v in origin.get("rpy", "").split()]
        R_file = pin.rpy.rpyToMatrix(*rpy)
        R_pb = np.array(p.getMatrixFromQuaternion(dyn[4])).reshape(3, 3)
        assert _rot_err(R_file, R_pb) < 1e-6, name
    for name, m in PA10_MASSES.items():
        assert masses[name] == pytest.approx(m, abs=1e-12), name
    assert masses["bh8_base"] + masses["bh8_palm"] == pytest.approx(0.60, abs=1e-12)
    for k in (1, 2, 3):
        finger = sum(masses[f"bh8_finger{k}_{part}"] for part in ("knuckle", "proximal",
                                                                  "distal"))
        assert finger == pytest.approx(0.179, abs=1e-12)
    for name, m in MINI_MASSES.items():
        assert masses[name] == m
    assert sum(masses[n] for n in MINI_BODY_LINKS) < 1.0  # a light mini-robot [kg]
    # pinocchio: the base in the universe body, everything else in the nine joint bodies.
    total = sum(masses.values())
    assert sum(i.mass for i in robot.model.inertias) == pytest.approx(total)
    # pinocchio's inertia of the bodies that hold one link only equals the tensor of the
    # link's shapes (so the principal axes and their rpy were written correctly).
    make_urdf = _make_urdf_module()
    bodies = {b.name: b for b in make_urdf.BODIES}
    for body_link, joint in (("pa10_link1", "pa10_joint1"), ("pa10_link2", "pa10_joint2"),
                             ("pa10_link4", "pa10_joint4"), ("mini_link1", "mini_joint1"),
                             ("mini_link2", "mini_joint2")):
        com, tensor = mass_properties(bodies[body_link])
        Y = robot.model.inertias[robot.model.getJointId(joint)]
        assert Y.mass == pytest.approx(masses[body_link], abs=1e-12), body_link
        np.testing.assert_allclose(Y.lever, com, atol=1e-11, err_msg=body_link)
        np.testing.assert_allclose(Y.inertia, tensor, atol=1e-10, err_msg=body_link)
    assert abs(mass_properties(bodies["mini_link1"])[1][0, 2]) > 1e-5  # rotated


def test_gravity_compensation_holds_and_zero_torque_falls() -> None:
    """At 1 kHz with TorqueDrive (torques clipped to tau_max), g(q) from pinocchio holds the
    nine-joint chain still for 1 s in a generic and in the stretched-out pose; zero torque
    lets the same chain fall."""
    poses = (_q([0.3, 0.6, 0.4, 0.2, 0.7, 0.1, 0.5, 0.4, -0.3]),
             _q([0.0, 0.99 * np.pi / 2, 0.0, 0.0, 0.0, 0.0, np.pi / 2, 0.0, 0.0]))
    for q0, compensate in itertools.product(poses, (True, False)):
        with World(PHYSICS_1KHZ) as world:
            robot = Robot(world, pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS)
            robot.reset(q0)
            drive = TorqueDrive(robot)
            z0 = robot.frame_pose("bh8_palm", q0)[2, 3]
            T_fc0 = _rel(robot, "pa10_flange", "mini_camera_optical", q0)
            h = world.config.physics_dt
            for _ in range(1000):
                tau = robot.gravity_torques(robot.q()) if compensate else np.zeros(N_JOINTS)
                drive.command(tau, h)
                drive.substep(1, h)
                world.step_physics()
            q = robot.q()
            if compensate:
                np.testing.assert_allclose(q, q0, atol=1e-4)
                np.testing.assert_allclose(robot.qd(), 0.0, atol=1e-3)
            else:
                assert robot.frame_pose("bh8_palm", q)[2, 3] < z0 - 0.05  # the arm falls
                T_fc = _rel(robot, "pa10_flange", "mini_camera_optical", q)
                assert np.linalg.norm(T_fc[:3, 3] - T_fc0[:3, 3]) > 0.02  # and the mini


def test_torque_limits_hold_worst_gravity_pose(robot: Robot) -> None:
    """The arm stretched horizontally (q2 = +-90 deg), over wrist and mini-robot poses: the
    static load stays under tau_max, with room for the PA-10's 10 kg rated payload at the
    palm on the arm joints (>= 10 % left) and >= 2x margin on the mini-robot."""
    tau_max = np.asarray(ALL_LIMITS.tau_max)
    worst_self = np.zeros(N_JOINTS)
    worst_total = np.zeros(N_JOINTS)
    grid = itertools.product((np.pi / 2, -np.pi / 2), np.linspace(-np.pi, np.pi, 7),
                             np.linspace(-np.pi / 2, np.pi / 2, 5),
                             np.linspace(-np.pi, np.pi, 9), np.linspace(-1.5, 1.5, 5),
                             np.linspace(-1.5, 1.5, 5))
    for q2, q4, q5, m1, m2, m3 in grid:
        q = _q([0.0, q2, 0.0, q4, q5, 0.0, m1, m2, m3])
        g = np.abs(robot.gravity_torques(q))
        J = robot.frame_jacobian("bh8_palm", q, "local_world_aligned")[:3]
        payload = np.abs(J.T @ np.array([0.0, 0.0, 10.0 * 9.81]))  # 10 kg at the palm
        worst_self = np.maximum(worst_self, g)
        worst_total = np.maximum(worst_total, g + payload)
    assert worst_self[1] > 100.0 and worst_self[2] > 30.0  # the shoulder does carry the arm
    assert np.all(worst_total[:6] < 0.9 * tau_max[:6])
    assert np.all(worst_self[6:9] < 0.5 * tau_max[6:9])
    assert worst_self[6] > 0.5  # q1 carries the mini-robot when the flange is horizontal


# --------------------------------------------------------------------------------------
# Generator
# --------------------------------------------------------------------------------------


def _make_urdf_module():  # type: ignore[no-untyped-def]
    """repro/assets/pa10/make_urdf.py, imported from its file."""
    return import_script(pa10_urdf_path().with_name("make_urdf.py"), "pa10_make_urdf")


def test_committed_urdf_is_make_urdf_output() -> None:
    module = _make_urdf_module()
    text = module.build_urdf()
    assert text == module.build_urdf()  # deterministic
    assert pa10_urdf_path().read_bytes() == text.encode("utf-8"), (
        "pa10_mini.urdf is stale: run .venv/bin/python repro/assets/pa10/make_urdf.py")
