"""Tests of repro.sim.human: the capsule skeleton (Winter fractions), the scripted visit
(reach on time, speeds under 2 m/s, far away before and after), the tracking noise, and
the capsules' poses in a PyBullet Scene."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from repro.errors import ConfigError, UnknownChoiceError
from repro.geometry import Rz, trans
from repro.planning.capsules import Capsule, capsule_distance, min_distance
from repro.sim.human import (
    CONSERVATIVE_RADII,
    PHASES,
    SEGMENT_FRACTIONS,
    TIGHT_RADII,
    V_MAX,
    HumanBody,
    HumanInScene,
    HumanMotion,
    HumanPath,
    add_tracking_noise,
)

# A visit in a base frame placed off the world origin, turned 30 deg, on a floor 0.1 m up.
T_WORLD_BASE = trans(0.4, -0.2, 0.1) @ Rz(math.radians(30.0))
PATH = HumanPath(start=(3.0, 0.5), approach=(0.6, 0.2, 1.1), t_enter=1.0, t_reach=5.0,
                 t_hold=7.0, t_leave=12.0)
FAR = 1.5  # [m] surface-to-approach-point distance before t_enter and after t_leave
SEGMENT_OF = {"torso": "trunk", "head": "head_neck", "upper_arm": "upper_arm",
              "forearm": "forearm", "hand": "hand", "thigh": "thigh", "shank": "shank"}


@pytest.fixture(scope="module")
def motion() -> HumanMotion:
    return HumanMotion(PATH, HumanBody(stature=1.75), T_WORLD_BASE)


def _approach_world() -> np.ndarray:
    return T_WORLD_BASE[:3, :3] @ np.asarray(PATH.approach) + T_WORLD_BASE[:3, 3]


def test_bone_lengths_match_winter_fractions(motion: HumanMotion) -> None:
    H = motion.body.stature
    for t in (0.0, 3.0, 4.5, 6.0, 8.0, 9.5, 11.0, 13.0):  # every phase
        caps = dict(motion.capsules(t))
        assert len(caps) == 12
        for name, c in caps.items():
            frac = SEGMENT_FRACTIONS[SEGMENT_OF[name.removesuffix("_l").removesuffix("_r")]]
            assert c.length == pytest.approx(frac * H, rel=1e-12), (t, name)
        assert caps["upper_arm_r"].length / caps["forearm_r"].length == pytest.approx(
            0.186 / 0.146)
    J = motion.joints(0.0)
    floor = T_WORLD_BASE[2, 3]
    # ankle + shank + thigh + trunk + head+neck, standing: 0.948 H
    assert J["head_top"][2] - floor == pytest.approx(
        (0.039 + 0.246 + 0.245 + 0.288 + 0.130) * H, abs=1e-12)
    assert J["neck"][2] - floor == pytest.approx(motion.body.shoulder_height)
    assert motion.body.arm_length == pytest.approx((0.186 + 0.146 + 0.108) * H)
    # arms hanging: fingertip at shoulder height - arm length
    assert J["fingertip_l"][2] == pytest.approx(J["shoulder_l"][2] - motion.body.arm_length)


def test_hand_reaches_the_approach_point_on_time(motion: HumanMotion) -> None:
    target = _approach_world()
    for t in (PATH.t_reach, 0.5 * (PATH.t_reach + PATH.t_hold), PATH.t_hold):
        np.testing.assert_allclose(motion.fingertip(t), target, atol=1e-9)
    # smooth arrival: within 1 mm 50 ms before, still 5 cm away 0.5 s before
    assert np.linalg.norm(motion.fingertip(PATH.t_reach - 0.05) - target) < 1e-3
    assert np.linalg.norm(motion.fingertip(PATH.t_reach - 0.5) - target) > 0.05
    # the reach distance from the shoulder is reach_extension * arm length
    J = motion.joints(PATH.t_reach)
    assert np.linalg.norm(target - J["shoulder_r"]) == pytest.approx(
        PATH.reach_extension * motion.body.arm_length)
    assert motion.phase(PATH.t_reach) == "hold"


def test_joint_speeds_below_2_m_per_s(motion: HumanMotion) -> None:
    dt = 1e-3
    ts = np.arange(PATH.t_enter - 0.5, PATH.t_leave + 0.5, dt)
    P = np.array([list(motion.joints(float(t)).values()) for t in ts])  # (T, joints, 3)
    speed = np.linalg.norm(np.diff(P, axis=0), axis=2) / dt
    assert speed.max() <= V_MAX
    assert speed.max() <= motion.speed_bound() + 1e-3  # the closed-form bound holds
    assert speed.max() > 0.5  # the person does move
    # minimum-jerk profiles: standing still at the ends of the visit
    assert speed[0].max() == 0.0 and speed[-1].max() == 0.0


def test_a_too_fast_visit_is_rejected() -> None:
    fast = HumanPath(start=(3.0, 0.5), approach=(0.6, 0.2, 1.1), t_enter=1.0, t_reach=3.0,
                     t_hold=3.0, t_leave=8.0)  # 1.9 m in 0.5 s
    with pytest.raises(ConfigError, match="m/s"):
        HumanMotion(fast)
    with pytest.raises(ConfigError, match="m/s"):
        HumanMotion(HumanPath(start=(3.0, 0.5), approach=(0.6, 0.2, 1.1), t_enter=1.0,
                              t_reach=5.0, t_hold=7.0, t_leave=12.0, reach_duration=0.5))


def test_far_from_the_approach_point_before_enter_and_after_leave(
        motion: HumanMotion) -> None:
    point = _approach_world()
    probe = Capsule(point, point, 0.0)
    for t in np.concatenate([np.linspace(-5.0, PATH.t_enter, 20),
                             np.linspace(PATH.t_leave, PATH.t_leave + 10.0, 20)]):
        caps = [c for _, c in motion.capsules(float(t))]
        assert min_distance(caps, [probe])[0] > FAR, t
    assert motion.phase(PATH.t_enter - 1e-6) == "before"
    assert motion.phase(PATH.t_leave) == "after"
    # ... and close during the visit (the hand's surface encloses the point)
    at_reach = dict(motion.capsules(PATH.t_reach))
    assert capsule_distance(at_reach["hand_r"], probe) < 0.0


def test_phases_come_in_order(motion: HumanMotion) -> None:
    seen = [motion.phase(float(t)) for t in np.arange(-1.0, 14.0, 0.05)]
    order = [ph for i, ph in enumerate(seen) if i == 0 or ph != seen[i - 1]]
    assert order == list(PHASES)


def test_bad_paths_are_rejected() -> None:
    with pytest.raises(ConfigError, match="out of reach"):
        HumanMotion(HumanPath(start=(3.0, 0.0), approach=(0.6, 0.0, 2.6), t_enter=1.0,
                              t_reach=5.0, t_hold=7.0, t_leave=12.0))
    with pytest.raises(ConfigError, match="farther than the stance"):
        HumanMotion(HumanPath(start=(0.8, 0.0), approach=(0.6, 0.0, 1.1), t_enter=1.0,
                              t_reach=5.0, t_hold=7.0, t_leave=12.0))
    with pytest.raises(ConfigError, match="no time to walk"):
        HumanPath(start=(3.0, 0.0), approach=(0.6, 0.0, 1.1), t_enter=4.0, t_reach=5.0,
                  t_hold=7.0, t_leave=12.0)
    with pytest.raises(UnknownChoiceError, match="left, right"):
        HumanPath(start=(3.0, 0.0), approach=(0.6, 0.0, 1.1), t_enter=1.0, t_reach=5.0,
                  t_hold=7.0, t_leave=12.0, arm="third")


def test_left_arm_and_exit_point() -> None:
    path = HumanPath(start=(0.0, 3.0), approach=(0.3, 0.5, 0.9), t_enter=0.0, t_reach=4.0,
                     t_hold=4.0, t_leave=10.0, arm="left", exit=(-2.5, 1.0))
    m = HumanMotion(path)
    np.testing.assert_allclose(m.fingertip(4.0), path.approach, atol=1e-9)
    J = m.joints(11.0)
    np.testing.assert_allclose(0.5 * (J["ankle_l"] + J["ankle_r"])[:2], path.exit_point,
                               atol=1e-12)
    assert m.peak_speed(dt=2e-3) <= m.speed_bound() + 1e-3 <= V_MAX + 1e-3


def test_radii_presets(motion: HumanMotion) -> None:
    tight = motion.capsules(6.0)
    wide = motion.capsules(6.0, radii=CONSERVATIVE_RADII)
    assert [n for n, _ in tight] == [n for n, _ in wide]
    for (_, a), (_, b) in zip(tight, wide, strict=True):
        np.testing.assert_array_equal(a.p0, b.p0)
        assert b.radius >= a.radius
    assert dict(wide)["torso"].radius == 0.217 and dict(wide)["hand_r"].radius == 0.103
    assert dict(tight)["torso"].radius == TIGHT_RADII.torso


def test_tracking_noise_is_zero_mean_with_the_stated_std(motion: HumanMotion) -> None:
    std = 0.02  # [m]
    truth = motion.capsules(6.0)
    errors = []
    rng = np.random.default_rng(11)
    for _ in range(400):
        meas = add_tracking_noise(truth, std, rng)
        per_joint: dict[bytes, np.ndarray] = {}  # one error per distinct joint
        for (_, c), (_, m) in zip(truth, meas, strict=True):
            per_joint[c.p0.tobytes()] = m.p0 - c.p0
            per_joint[c.p1.tobytes()] = m.p1 - c.p1
            assert m.radius == c.radius
        assert len(per_joint) == 17
        errors += list(per_joint.values())
        # joints shared by two segments stay shared: the measured skeleton is connected
        md = dict(meas)
        np.testing.assert_array_equal(md["upper_arm_r"].p1, md["forearm_r"].p0)
    E = np.array(errors)
    assert np.all(np.abs(E.mean(axis=0)) < 4.0 * std / math.sqrt(len(E)))
    np.testing.assert_allclose(E.std(axis=0), std, rtol=0.05)
    # reproducible with a seed; the ground truth is untouched
    m5 = add_tracking_noise(truth, std, np.random.default_rng(5))
    m5_again = add_tracking_noise(truth, std, np.random.default_rng(5))
    m6 = add_tracking_noise(truth, std, np.random.default_rng(6))
    assert all(np.array_equal(x.p0, y.p0) and np.array_equal(x.p1, y.p1)
               for (_, x), (_, y) in zip(m5, m5_again, strict=True))
    assert not np.array_equal(m5[0][1].p0, m6[0][1].p0)
    np.testing.assert_array_equal(truth[0][1].p0, motion.capsules(6.0)[0][1].p0)
    exact = add_tracking_noise(truth, 0.0, np.random.default_rng(5))
    np.testing.assert_array_equal(exact[3][1].p1, truth[3][1].p1)
    with pytest.raises(ConfigError):
        add_tracking_noise(truth, -0.01, np.random.default_rng(5))


def test_scene_capsules_match_the_analytic_geometry(motion: HumanMotion) -> None:
    from repro.sim.scene import Scene
    from repro.sim.world import WorldConfig

    with Scene(WorldConfig()) as scene:
        human = HumanInScene(motion)
        human.add(scene, t=0.0)
        probe_at = _approach_world() + np.array([0.0, 0.0, 0.15])
        scene.add_capsule("probe", 0.02, 0.01, trans(*probe_at), (1, 0, 0, 1), moving=True)
        probe = Capsule(probe_at - [0, 0, 0.005], probe_at + [0, 0, 0.005], 0.02)
        for t in (0.0, 4.4, 6.0, 8.5):
            human.move(scene, t)
            for name, c in motion.capsules(t):
                pts = p.getClosestPoints(scene["human_" + name].ids[0], scene["probe"].ids[0],
                                         10.0, physicsClientId=scene.physics.client)
                assert min(pt[8] for pt in pts) == pytest.approx(
                    capsule_distance(c, probe), abs=1e-4), (t, name)
