"""Tests of the Barrett BH8-282 hand (repro/assets/barrett_bh8, repro.sim.barrett).

Published figures are written here as literals (not read back from the module), so a wrong
constant in the module or the URDF fails: Barrett's DH (Aw 25, A1 50, A2 70, A3 50, D3 9.5 mm,
Phi3 42 deg; Craig's modified convention, r = -1/1/0, j = 1/1/-1), the ranges (spread 0-180,
proximal 0-140, distal 0-48 deg), the drive ratios (125 : 1, 375 : 1, 17.5 : 1), the masses
(base 0.60 kg, finger 0.179 kg), the 2 kg finger load, the palm plate and the pad sizes
(palm 60 x 40, proximal 40 x 15, distal 48 x 18 mm). Dw = 76 mm and the 4096 counts per motor
turn are ours (README), also written as literals.

Every simulation runs in its own PyBullet DIRECT client at 1 kHz.
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
from repro.sim.robot import Robot
from repro.sim.world import World, WorldConfig

PHYSICS_1KHZ = WorldConfig(physics_dt=1e-3, control_dt=1e-3)
H = 1e-3  # physics step [s]
DEG = np.pi / 180.0

JOINTS = ("bh8_finger1_spread", "bh8_finger1_proximal_joint", "bh8_finger1_distal_joint",
          "bh8_finger2_spread", "bh8_finger2_proximal_joint", "bh8_finger2_distal_joint",
          "bh8_finger3_proximal_joint", "bh8_finger3_distal_joint")
Q_MAX_DEG = (180.0, 140.0, 48.0, 180.0, 140.0, 48.0, 140.0, 48.0)
BODY_LINKS = ("bh8_base", "bh8_palm") + tuple(
    f"bh8_finger{k}_{part}" for k in (1, 2, 3) for part in ("knuckle", "proximal", "distal"))
FRAME_LINKS = ("bh8_palm_pad",) + tuple(
    f"bh8_finger{k}_{part}" for k in (1, 2, 3) for part in ("proximal_pad", "distal_pad", "tip"))

# Barrett's finger DH (Hand/280 wiki, facts sheet) and our Dw.
AW, A1, A2, A3, D3, PHI3 = 0.025, 0.050, 0.070, 0.050, 0.0095, 42.0 * DEG
DW = 0.076  # ours


def _craig(a: float, alpha: float, d: float, theta: float) -> np.ndarray:
    """Rx(alpha) Tx(a) Rz(theta) Tz(d), composed from elementary transforms."""
    def rx(t: float) -> np.ndarray:
        c, s = np.cos(t), np.sin(t)
        return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])

    def rz(t: float) -> np.ndarray:
        c, s = np.cos(t), np.sin(t)
        return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])

    def tr(x: float, y: float, z: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, 3] = (x, y, z)
        return T

    return rx(alpha) @ tr(a, 0, 0) @ rz(theta) @ tr(0, 0, d)


def _barrett_frames(k: int, spread: float, q2: float, q3: float) -> list[np.ndarray]:
    """T_W_k1, T_W_k2, T_W_k3, T_W_kT of finger k (Barrett's table)."""
    r, j = (-1, 1, 0)[k - 1], (1, 1, -1)[k - 1]
    rows = ((r * AW, 0.0, DW, r * spread - j * np.pi / 2), (A1, np.pi / 2, 0.0, q2),
            (A2, 0.0, 0.0, q3 + PHI3), (A3, -np.pi / 2, D3, 0.0))
    out, T = [], np.eye(4)
    for row in rows:
        T = T @ _craig(*row)
        out.append(T)
    return out


def _finger_q(q: np.ndarray, k: int) -> tuple[float, float, float]:
    """(spread, proximal, distal) of finger k from the 8 joint positions."""
    if k == 3:
        return 0.0, float(q[6]), float(q[7])
    i = 3 * (k - 1)
    return float(q[i]), float(q[i + 1]), float(q[i + 2])


def _make_urdf_module():  # type: ignore[no-untyped-def]
    """repro/assets/barrett_bh8/make_urdf.py, imported from its file."""
    return import_script(B.bh8_urdf_path().with_name("make_urdf.py"), "bh8_make_urdf")


def _hand(world: World) -> tuple[Robot, B.HandCouplings, list[B.FingerDrive]]:
    robot = Robot(world, B.bh8_urdf_path(), B.BH8_JOINTS, B.BH8_LIMITS)
    couplings = B.add_coupling_constraints(robot.body, robot.client)
    drives = [B.FingerDrive(robot.body, robot.client, k, couplings) for k in (1, 2, 3)]
    return robot, couplings, drives


def _contacts(robot: Robot, other: int, link: str) -> int:
    return len(p.getContactPoints(robot.body, other, robot.pb_link_index(link), -1,
                                  physicsClientId=robot.client))


# --------------------------------------------------------------------------------------
# URDF
# --------------------------------------------------------------------------------------


def test_urdf_loads_with_the_named_joints_and_links() -> None:
    """PyBullet and pinocchio read the same 8 revolute joints (in this order), the root
    bh8_base, every body and frame link; limits 0-180 / 0-140 / 0-48 deg; no mimic tags, only
    boxes and cylinders; the palm plate 76 x 46 x 12 mm on bh8_palm."""
    assert B.BH8_JOINTS == JOINTS
    model = pin.buildModelFromUrdf(str(B.bh8_urdf_path()))
    assert tuple(model.names[1:]) == JOINTS and model.nq == 8
    for link in BODY_LINKS + FRAME_LINKS:
        assert model.existFrame(link), link
    np.testing.assert_allclose(model.lowerPositionLimit, 0.0, atol=1e-12)
    np.testing.assert_allclose(model.upperPositionLimit, np.deg2rad(Q_MAX_DEG), atol=1e-9)
    with World(PHYSICS_1KHZ) as world:
        robot = Robot(world, B.bh8_urdf_path(), B.BH8_JOINTS, B.BH8_LIMITS)
        assert p.getBodyInfo(robot.body, physicsClientId=robot.client)[0] == b"bh8_base"
        assert set(robot.link_names()) == set(BODY_LINKS + FRAME_LINKS)
        revolute = {}
        for j in range(p.getNumJoints(robot.body, physicsClientId=robot.client)):
            info = p.getJointInfo(robot.body, j, physicsClientId=robot.client)
            if info[2] == p.JOINT_REVOLUTE:
                revolute[info[1].decode()] = (info[8], info[9], info[10])
            else:
                assert info[2] == p.JOINT_FIXED
        assert set(revolute) == set(JOINTS)
        for name, q_max in zip(JOINTS, Q_MAX_DEG, strict=True):
            lower, upper, effort = revolute[name]
            assert (lower, upper) == pytest.approx((0.0, np.deg2rad(q_max)), abs=1e-9), name
            assert effort == pytest.approx(B.BH8_LIMITS.tau_max[JOINTS.index(name)]), name
        for link in BODY_LINKS:
            assert p.getCollisionShapeData(robot.body, robot.pb_link_index(link),
                                           physicsClientId=robot.client), link
        for link in FRAME_LINKS:
            assert p.getCollisionShapeData(robot.body, robot.pb_link_index(link),
                                           physicsClientId=robot.client) == (), link
        palm = p.getCollisionShapeData(robot.body, robot.pb_link_index("bh8_palm"),
                                       physicsClientId=robot.client)
        assert len(palm) == 1 and palm[0][2] == p.GEOM_BOX
        np.testing.assert_allclose(palm[0][3], (0.076, 0.046, 0.012), atol=1e-9)
    root = ET.parse(B.bh8_urdf_path()).getroot()
    assert root.find("link").get("name") == "bh8_base"  # type: ignore[union-attr]
    assert not list(root.iter("mimic"))
    assert {g.tag for g in root.iter() if g.tag in ("box", "cylinder", "sphere", "mesh",
                                                     "capsule")} == {"box", "cylinder"}


def test_committed_urdf_is_make_urdf_output() -> None:
    module = _make_urdf_module()
    text = module.build_urdf()
    assert text == module.build_urdf()  # deterministic
    assert B.bh8_urdf_path().read_bytes() == text.encode("utf-8"), (
        "barrett_bh8.urdf is stale: run .venv/bin/python repro/assets/barrett_bh8/make_urdf.py")


# --------------------------------------------------------------------------------------
# Kinematics
# --------------------------------------------------------------------------------------


def test_fingertip_fk_matches_barrett_dh() -> None:
    """The URDF's knuckle / proximal / distal / tip frames are Barrett's DH frames k1, k2, k3,
    kT, in pinocchio (to 1e-10) and in PyBullet (to 1e-6: single precision), at random
    configurations; and two positions worked by hand (finger 3 and finger 1, all joints 0)."""
    # Hand-worked: finger 3 along +y, the distal bent Phi3 = 42 deg, the tip D3 inside.
    c, s = np.cos(PHI3), np.sin(PHI3)
    tip3 = np.array([0.0, A1 + A2 + A3 * c - D3 * s, DW + A3 * s + D3 * c])
    np.testing.assert_allclose(tip3, [0.0, 0.150800501, 0.116516406], atol=1e-9)
    np.testing.assert_allclose(_barrett_frames(3, 0.0, 0.0, 0.0)[3][:3, 3], tip3, atol=1e-12)
    np.testing.assert_allclose(_barrett_frames(1, 0.0, 0.0, 0.0)[3][:3, 3],
                               [-AW, -tip3[1], tip3[2]], atol=1e-12)
    rng = np.random.default_rng(3)
    with World(PHYSICS_1KHZ) as world:
        robot = Robot(world, B.bh8_urdf_path(), B.BH8_JOINTS, B.BH8_LIMITS)
        for trial in range(12):
            q = np.zeros(8) if trial == 0 else rng.uniform(B.BH8_LIMITS.q_min,
                                                             B.BH8_LIMITS.q_max)
            robot.reset(q)
            for k in (1, 2, 3):
                spread, q2, q3 = _finger_q(q, k)
                expected = _barrett_frames(k, spread, q2, q3)
                np.testing.assert_allclose(B.bh8_dh_frames(k, spread, q2, q3), expected,
                                           atol=1e-12)
                for T, part in zip(expected, ("knuckle", "proximal", "distal", "tip"),
                                   strict=True):
                    name = f"bh8_finger{k}_{part}"
                    np.testing.assert_allclose(robot.frame_pose(name, q), T, atol=1e-10,
                                               err_msg=name)
                    np.testing.assert_allclose(robot.pb_link_pose(name), T, atol=1e-6,
                                               err_msg=name)
        # Spread symmetry: fingers 1 and 2 mirror each other about the y-z plane.
        q = np.deg2rad([60.0, 30.0, 10.0, 60.0, 30.0, 10.0, 0.0, 0.0])
        t1 = robot.frame_pose("bh8_finger1_tip", q)[:3, 3]
        t2 = robot.frame_pose("bh8_finger2_tip", q)[:3, 3]
        np.testing.assert_allclose(t1 * [-1, 1, 1], t2, atol=1e-10)
    with pytest.raises(ConfigError):
        B.bh8_dh_frames(4, 0.0, 0.0, 0.0)


def test_pad_faces_fit_the_tactile_pads() -> None:
    """Each pad frame sits on its link's contact face, +z the outward normal: rays cast along
    -z from 5 mm outside the face, at the centre and the four corners of the pad (palm
    60 x 40, proximal 8 x 3 cells of 5 mm = 40 x 15, distal 48 x 18 mm; x along the
    phalanx), hit that link at 5 mm (to 0.1 mm), open (q = 0), half closed and at full
    spread: nothing else (knuckles, other fingers) covers a pad. The rounded fingertip: a
    ray along -x of the distal hits it at A3 + 6.5 mm."""
    pads = {"bh8_palm_pad": ("bh8_palm", 0.060, 0.040)}
    for k in (1, 2, 3):
        pads[f"bh8_finger{k}_proximal_pad"] = (f"bh8_finger{k}_proximal", 0.040, 0.015)
        pads[f"bh8_finger{k}_distal_pad"] = (f"bh8_finger{k}_distal", 0.048, 0.018)
    with World(PHYSICS_1KHZ) as world:
        robot = Robot(world, B.bh8_urdf_path(), B.BH8_JOINTS, B.BH8_LIMITS)
        for q in (np.zeros(8), np.deg2rad([30.0, 45.0, 15.0, 30.0, 45.0, 15.0, 45.0, 15.0]),
                  np.deg2rad([180.0, 20.0, 10.0, 180.0, 20.0, 10.0, 90.0, 30.0])):
            robot.reset(q)
            for pad, (link, length, width) in pads.items():
                T = robot.pb_link_pose(pad)
                for u, v in ((0, 0), *itertools.product((-0.5, 0.5), repeat=2)):
                    point = T @ np.array([0.999 * u * length, 0.999 * v * width, 0.0, 1.0])
                    start = point[:3] + 0.005 * T[:3, 2]
                    end = point[:3] - 0.005 * T[:3, 2]
                    hit = p.rayTest(start.tolist(), end.tolist(),
                                    physicsClientId=robot.client)[0]
                    assert hit[0] == robot.body and hit[1] == robot.pb_link_index(link), (
                        pad, u, v, hit[:2])
                    # On the face to 0.1 mm (Bullet's collision margin rounds box edges:
                    # the distal pad's long edges are 0.5 mm from the face's).
                    assert hit[2] == pytest.approx(0.5, abs=1e-2), (pad, u, v)
                    if u == v == 0:  # the face's normal (the edges are rounded)
                        np.testing.assert_allclose(hit[4], T[:3, 2], atol=1e-6, err_msg=pad)
            for k in (1, 2, 3):
                T = robot.pb_link_pose(f"bh8_finger{k}_distal")
                apex = T @ np.array([A3 + 0.0065, D3, 0.0, 1.0])
                start, end = apex[:3] + 0.01 * T[:3, 0], apex[:3] - 0.01 * T[:3, 0]
                hit = p.rayTest(start.tolist(), end.tolist(), physicsClientId=robot.client)[0]
                assert hit[1] == robot.pb_link_index(f"bh8_finger{k}_distal")
                assert hit[2] == pytest.approx(0.5, abs=1e-3)


# --------------------------------------------------------------------------------------
# Masses, limits
# --------------------------------------------------------------------------------------


def test_masses_add_up_and_inertias_come_from_the_shapes() -> None:
    """Base + palm 0.60 kg, each finger (knuckle, proximal, distal) 0.179 kg, the hand 1.137 kg
    in pinocchio; PyBullet reads the same masses and principal moments; every tensor is the
    one of its link's primitives and physically valid."""
    root = ET.parse(B.bh8_urdf_path()).getroot()
    masses, moments = {}, {}
    for link in root.findall("link"):
        name = link.get("name", "")
        mass, inertia = link.find("inertial/mass"), link.find("inertial/inertia")
        assert mass is not None and inertia is not None
        masses[name] = float(mass.get("value", "nan"))
        moments[name] = np.array([float(inertia.get(f"i{a}{a}", "nan")) for a in "xyz"])
    assert masses["bh8_base"] + masses["bh8_palm"] == pytest.approx(0.60, abs=1e-12)
    for k in (1, 2, 3):
        finger = sum(masses[f"bh8_finger{k}_{part}"] for part in ("knuckle", "proximal",
                                                                  "distal"))
        assert finger == pytest.approx(0.179, abs=1e-12), k
        assert masses[f"bh8_finger{k}_knuckle"] > masses[f"bh8_finger{k}_proximal"] > \
            masses[f"bh8_finger{k}_distal"] > 0.0
    for name in FRAME_LINKS:
        assert masses[name] == 0.0 and not moments[name].any(), name
    model = pin.buildModelFromUrdf(str(B.bh8_urdf_path()))
    assert sum(i.mass for i in model.inertias) == pytest.approx(0.60 + 3 * 0.179, abs=1e-12)
    bodies = {b.name: b for b in _make_urdf_module().BODIES}
    with World(PHYSICS_1KHZ) as world:
        robot = Robot(world, B.bh8_urdf_path(), B.BH8_JOINTS, B.BH8_LIMITS)
        for name in BODY_LINKS:
            _, tensor = mass_properties(bodies[name])
            ev = np.linalg.eigvalsh(tensor)
            # 12 decimals in the file
            np.testing.assert_allclose(np.sort(moments[name]), ev, atol=1e-12, err_msg=name)
            assert ev.min() > 0 and ev[0] + ev[1] >= ev[2], name  # triangle inequality
            if name == "bh8_base":
                continue
            dyn = p.getDynamicsInfo(robot.body, robot.pb_link_index(name),
                                    physicsClientId=robot.client)
            assert dyn[0] == pytest.approx(masses[name], abs=1e-12), name
            np.testing.assert_allclose(dyn[2], moments[name], rtol=1e-9, err_msg=name)
        # A proximal (one box 70 x 6 x 19 mm, x from the axis): its lever in pinocchio.
        Y = model.inertias[model.getJointId("bh8_finger3_proximal_joint")]
        np.testing.assert_allclose(Y.lever, [0.035, 0.0, 0.0], atol=1e-12)


def test_torque_limits_and_breakaway_threshold() -> None:
    """tau_max = 2 kg at the fingertip's largest distance from each axis (literals from the
    DH: 0.1086 / 0.0509 / 0.1508 m); the breakaway threshold lies between 10x the finger's
    own gravity load on the proximal motor (any hand orientation, any pose; the distal's
    load reaches it through the 1/3 gear) and the proximal limit."""
    c, s = np.cos(PHI3), np.sin(PHI3)
    lever = {"proximal": np.hypot(A2 + A3 * c - D3 * s, A3 * s + D3 * c),
             "distal": np.hypot(A3, D3), "spread": A1 + A2 + A3 * c - D3 * s}
    assert lever["proximal"] == pytest.approx(0.1086, abs=1e-4)
    for name, tau in zip(JOINTS, B.BH8_LIMITS.tau_max, strict=True):
        kind = "spread" if name.endswith("spread") else name.split("_")[2]
        assert tau == pytest.approx(2.0 * 9.81 * lever[kind], rel=1e-12), name
    np.testing.assert_allclose(B.BH8_LIMITS.q_max, np.deg2rad(Q_MAX_DEG), rtol=1e-15)
    tau_p = B.BH8_LIMITS.tau_max[1]
    assert tau_p > B.BREAKAWAY_TORQUE
    model = pin.buildModelFromUrdf(str(B.bh8_urdf_path()))
    data = model.createData()
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(300):
        g_dir = rng.normal(size=3)
        model.gravity.linear = 9.81 * g_dir / np.linalg.norm(g_dir)
        q = rng.uniform(B.BH8_LIMITS.q_min, B.BH8_LIMITS.q_max)
        g = pin.computeGeneralizedGravity(model, data, q)
        for i in (1, 4, 6):  # proximal joints; the distal's load reaches the motor / 3
            worst = max(worst, abs(g[i] + g[i + 1] / 3.0))
    assert 0.02 < worst < 0.05 < B.BREAKAWAY_TORQUE / 10.0  # 0.042 N m


# --------------------------------------------------------------------------------------
# Motor, counts
# --------------------------------------------------------------------------------------


def test_motor_counts_round_trip() -> None:
    """Joint angles -> motor counts -> joint angles within one count, before and after
    breakaway; literal values: the proximal at 140 deg engaged is 125 * 140 / 360 * 4096
    counts; the spread at 180 deg is 17.5 / 2 * 4096 = 35840 counts."""
    assert B.finger_counts(140 * DEG, 140 / 3 * DEG) == round(125 * 140 / 360 * 4096)
    assert B.spread_counts(np.pi) == 35840
    assert B.spread_from_counts(35840) == pytest.approx(np.pi, abs=1e-12)
    one_count = 2 * np.pi / 4096  # motor [rad]
    rng = np.random.default_rng(11)
    for q2 in rng.uniform(0.0, 140 * DEG, 50):
        q3 = q2 / 3.0  # engaged
        back = B.finger_joints_from_counts(B.finger_counts(q2, q3))
        np.testing.assert_allclose(back, (q2, q3), atol=one_count / 93.75)
        assert B.finger_motor_angle(q2, q3) == pytest.approx(125.0 * q2, rel=1e-12)
        # Broken away at q_b < q2 / 3 ... the distal closed alone by dq.
        q_b, dq = q2, rng.uniform(0.0, 48 * DEG - q3)
        counts = B.finger_counts(q_b, q3 + dq)
        back = B.finger_joints_from_counts(counts, q_breakaway=q_b)
        np.testing.assert_allclose(back, (q_b, q3 + dq), atol=one_count / 93.75)
        qs = rng.uniform(0.0, np.pi)
        assert abs(B.spread_from_counts(B.spread_counts(qs)) - qs) <= one_count / 17.5
    # Before breakaway the distal turns at 1/3 of the proximal (125 : 375).
    assert B.finger_joints_from_motor(375.0) == pytest.approx((3.0, 1.0), abs=1e-12)
    # After breakaway at 0.5 rad the distal turns at motor / 93.75.
    q_p, q_d = B.finger_joints_from_motor(93.75, q_breakaway=0.5)
    assert (q_p, q_d) == pytest.approx((0.5, 0.5), abs=1e-12)


def test_hand_joints_from_motors_places_each_finger_engaged() -> None:
    """Each finger's motor angle sets only its own proximal (m / 125) and distal (m / 375)
    joints; the spread joints take the spread."""
    m = (100.0, 150.0, 200.0)
    q = dict(zip(JOINTS, B.hand_joints_from_motors(m, spread=0.3), strict=True))
    for k, mk in zip((1, 2, 3), m, strict=True):
        assert q[f"bh8_finger{k}_proximal_joint"] == pytest.approx(mk / 125.0, abs=1e-15)
        assert q[f"bh8_finger{k}_distal_joint"] == pytest.approx(mk / 375.0, abs=1e-15)
    assert q["bh8_finger1_spread"] == q["bh8_finger2_spread"] == 0.3
    assert B.hand_joints_from_motors((0.0, 0.0, 0.0)).tolist() == [0.0] * 8


def test_torque_switch_state_machine() -> None:
    """Engaged: (m/125, m/375); breakaway only while closing past the threshold; then the
    proximal holds and the distal follows m / 93.75 - q_b; reopening re-engages at the
    breakaway point, with continuous targets."""
    sw = B.TorqueSwitch(threshold=1.0)
    t = sw.update(125.0 * 0.4, 0.5, 0.4)
    assert t == pytest.approx((0.4, 0.4 / 3, True))
    # Above the threshold but opening (the motor behind the link): no breakaway.
    assert sw.update(125.0 * 0.3, 1.5, 0.4).engaged
    # Closing against a load at q = 0.41: breaks away there.
    t = sw.update(125.0 * 0.45, 1.5, 0.41)
    assert not t.engaged and sw.q_breakaway == 0.41
    assert t.q_proximal == 0.41
    assert t.q_distal == pytest.approx(125.0 * 0.45 / 93.75 - 0.41, abs=1e-12)
    t = sw.update(125.0 * 0.6, 0.0, 0.41)  # the torque falls: still broken away
    assert not t.engaged and t.q_distal == pytest.approx(125 * 0.6 / 93.75 - 0.41)
    just_above = sw.update(125.0 * 0.41 + 1e-9, 0.0, 0.41)
    assert not just_above.engaged
    back = sw.update(125.0 * 0.41, 0.0, 0.41)
    assert back.engaged
    assert back.q_distal == pytest.approx(just_above.q_distal, abs=1e-9)  # continuous
    assert back.q_proximal == pytest.approx(just_above.q_proximal, abs=1e-9)
    with pytest.raises(ConfigError):
        B.TorqueSwitch(threshold=0.0)


# --------------------------------------------------------------------------------------
# Simulation at 1 kHz
# --------------------------------------------------------------------------------------


def test_gear_constraints_couple_distal_and_spread() -> None:
    """Driving only the proximal joints (PyBullet position control, a 0 -> 100 deg ramp) and
    only finger 1's spread (0 -> 90 deg), then holding 0.6 s: each distal follows at 1/3 and
    finger 2's spread equals finger 1's, within 0.05 deg all along and 0.003 deg at the end;
    the same drive without the constraints leaves the distals and spread 2 behind."""
    results = {}
    for coupled in (True, False):
        with World(PHYSICS_1KHZ) as world:
            robot = Robot(world, B.bh8_urdf_path(), B.BH8_JOINTS, B.BH8_LIMITS)
            if coupled:
                B.add_coupling_constraints(robot.body, robot.client)
            else:  # the followers free, as add_coupling_constraints leaves them
                for name in ("bh8_finger2_spread", *B.BH8_DISTAL_JOINTS):
                    p.setJointMotorControl2(robot.body, robot.pb_joints[JOINTS.index(name)],
                                            p.VELOCITY_CONTROL, force=0.0,
                                            physicsClientId=robot.client)
            prox = [robot.pb_joints[JOINTS.index(n)] for n in B.BH8_PROXIMAL_JOINTS]
            err_d = err_s = 0.0
            for step in range(1500):
                t = step * H
                q_ref = min(100 * DEG, 2.0 * t)  # [rad]
                for j in prox:
                    p.setJointMotorControl2(robot.body, j, p.POSITION_CONTROL,
                                            targetPosition=q_ref, positionGain=0.3,
                                            force=2.13, physicsClientId=robot.client)
                B.set_spread(robot.body, robot.client, min(90 * DEG, 2.0 * t))
                world.step_physics()
                q = robot.q()
                for i in (1, 4, 6):
                    err_d = max(err_d, abs(q[i + 1] - q[i] / 3.0))
                err_s = max(err_s, abs(q[3] - q[0]))
            results[coupled] = (q, err_d, err_s)
    q, err_d, err_s = results[True]
    np.testing.assert_allclose(q[[1, 4, 6]], 100 * DEG, atol=0.1 * DEG)
    assert q[0] == pytest.approx(90 * DEG, abs=0.1 * DEG)
    assert err_d < 0.05 * DEG and err_s < 0.05 * DEG
    # After 0.6 s of holding still: no creep (without the constraints' erp the distals drift
    # ~0.01 deg/s under gravity).
    np.testing.assert_allclose(q[[2, 5, 7]], q[[1, 4, 6]] / 3.0, atol=0.003 * DEG)
    q, err_d, err_s = results[False]
    assert q[1] == pytest.approx(100 * DEG, abs=0.1 * DEG)
    assert err_d > 20 * DEG and err_s > 80 * DEG


def test_free_closing_couples_then_breaks_away_at_the_joint_limit() -> None:
    """FingerDrive closing all three fingers from open, no object: engaged to 100 deg (the
    distal at 1/3, the closing torque of the proximals below 1/10 of the breakaway threshold
    all the way: weight and acceleration of the finger, 0.063 N m at most); then
    closing fully, the proximal reaches its 140 deg stop, breaks away there, and the distal
    alone goes on to its 48 deg stop; reopening re-engages and returns to 0."""
    with World(PHYSICS_1KHZ) as world:
        robot, _, drives = _hand(world)
        tau_free = 0.0
        for _ in range(900):
            for d in drives:
                d.step(125.0 * 100 * DEG, H)
            world.step_physics()
            tau_free = max(tau_free, *(d.proximal_torque() for d in drives))  # closing
        for d in drives:
            q_p, q_d = d.joint_positions()
            assert d.switch.engaged
            assert q_p == pytest.approx(100 * DEG, abs=0.2 * DEG)
            assert q_d == pytest.approx(q_p / 3.0, abs=0.05 * DEG)
            counts = B.finger_counts(100 * DEG, 100 / 3 * DEG)  # 142222
            assert d.counts() == pytest.approx(counts, abs=100)  # 0.07 deg of the proximal
        assert tau_free < 0.1 * B.BREAKAWAY_TORQUE
        for _ in range(700):
            for d in drives:
                d.step(B.MOTOR_ANGLE_MAX, H)
            world.step_physics()
        for d in drives:
            q_p, q_d = d.joint_positions()
            assert d.switch.q_breakaway == pytest.approx(140 * DEG, abs=0.5 * DEG)
            assert q_p == pytest.approx(140 * DEG, abs=0.2 * DEG)
            assert q_d == pytest.approx(48 * DEG, abs=0.2 * DEG)
        for _ in range(1800):
            for d in drives:
                d.step(0.0, H)
            world.step_physics()
        for d in drives:
            q_p, q_d = d.joint_positions()
            assert d.switch.engaged
            assert q_p == pytest.approx(0.0, abs=0.2 * DEG)
            assert q_d == pytest.approx(0.0, abs=0.2 * DEG)
        assert robot.q()[0] == pytest.approx(0.0, abs=0.1 * DEG)


def test_breakaway_on_a_fixed_box() -> None:
    """Finger 3 closes on a fixed box whose lower edge (y 80 mm, z 96 mm in the hand) lies over
    its proximal. The proximal stops where its inner face (3 mm off its axis) meets the edge,
    theta_c = acos(3 / |(30, 20)|) - atan2(30, 20) = 28.9 deg from the geometry, the clutch
    breaks away there, and the distal alone keeps closing, far past the 1/3 coupling, until it
    touches the box's side; reopening re-engages the clutch."""
    d_edge = np.array([0.080 - A1, 0.096 - DW])  # the edge from the proximal axis (y, z)
    theta_c = np.arccos(0.003 / np.linalg.norm(d_edge)) - np.arctan2(*d_edge)
    assert theta_c == pytest.approx(28.92 * DEG, abs=0.01 * DEG)
    with World(PHYSICS_1KHZ) as world:
        robot, couplings, drives = _hand(world)
        T = np.eye(4)
        T[:3, 3] = (0.0, 0.030, 0.148)  # y -20..80 mm, z 96..200 mm
        box = world.add_box((0.05, 0.05, 0.052), T)
        q_d_at_break = None
        for _ in range(800):
            for d in drives:
                d.step(B.MOTOR_ANGLE_MAX if d.finger == 3 else 0.0, H)
            world.step_physics()
            if q_d_at_break is None and not drives[2].switch.engaged:
                q_d_at_break = drives[2].joint_positions()[1]
        f3 = drives[2]
        q_p, q_d = f3.joint_positions()
        assert f3.switch.q_breakaway == pytest.approx(theta_c, abs=0.3 * DEG)
        assert q_p == pytest.approx(theta_c, abs=0.3 * DEG)
        assert q_d_at_break == pytest.approx(theta_c / 3.0, abs=1.5 * DEG)
        assert q_d > theta_c / 3.0 + 20 * DEG  # the distal kept closing alone
        assert q_d < 48 * DEG - 1 * DEG  # ... stopped by the box, not its limit
        assert _contacts(robot, box, "bh8_finger3_proximal") > 0
        assert _contacts(robot, box, "bh8_finger3_distal") > 0
        # The fingers that were not driven stayed open.
        np.testing.assert_allclose(robot.q()[:6], 0.0, atol=0.2 * DEG)
        for _ in range(1000):
            for d in drives:
                d.step(0.0, H)
            world.step_physics()
        q_p, q_d = f3.joint_positions()
        assert f3.switch.engaged
        assert q_p == pytest.approx(0.0, abs=0.2 * DEG)
        assert q_d == pytest.approx(0.0, abs=0.2 * DEG)
        assert _contacts(robot, box, "bh8_finger3_distal") == 0
