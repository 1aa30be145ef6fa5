"""pomares2011 experiment 2 pieces: the mini-robot's capsules cover its links, the
controller's human distance against PyBullet and the analytic capsule distance, its
gradient against finite differences of the distance over the joints, and the indirect
baseline's velocity reference and gains."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from experiments.pomares2011 import scene as sc
from experiments.pomares2011.human_tracking import human_distance
from repro.control.hybrid_vs import distance_gradient_from_joints
from repro.control.indirect_vs import ibvs_velocity_reference, pd_gains_from_inertia
from repro.errors import ConfigError
from repro.planning.capsules import Capsule, capsule_distance
from repro.sim.pa10 import ALL_JOINTS, ALL_LIMITS, MINI_CAPSULES, MINI_JOINTS, pa10_urdf_path
from repro.sim.robot import Robot
from repro.sim.world import World, WorldConfig

MINI_IDX = np.array([ALL_JOINTS.index(j) for j in MINI_JOINTS])


@pytest.fixture(scope="module")
def chain() -> Robot:
    world = World(WorldConfig(1e-3, 1e-3))
    robot = Robot(world, pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS)
    yield robot
    world.close()


def _random_q(rng: np.random.Generator) -> np.ndarray:
    q = np.array(sc.Q_GOAL, dtype=float)
    q[MINI_IDX] += rng.uniform(-0.8, 0.8, size=3)
    return q


@pytest.mark.parametrize("seed", range(6))
def test_mini_capsules_cover_the_links(chain: Robot, seed: int) -> None:
    """Capsule distance <= PyBullet's distance to the real link geometry, for probe spheres
    all around the mini-robot (a capsule set that left a part of a link out would report a
    larger distance than the truth somewhere)."""
    rng = np.random.default_rng(seed)
    q = _random_q(rng)
    chain.reset(q)
    links = {chain.pb_link_index(n) for n in ("mini_link1", "mini_link2", "mini_link3",
                                               "mini_camera")}
    caps = [c for _, c in sc.mini_capsules(chain, q)]
    cam = chain.frame_pose("mini_camera_optical", q)[:3, 3]
    r = 0.01
    sphere = p.createCollisionShape(p.GEOM_SPHERE, radius=r, physicsClientId=chain.client)
    probe = p.createMultiBody(0.0, sphere, -1, [0, 0, 5], physicsClientId=chain.client)
    n_close = 0
    for _ in range(60):
        x = cam + rng.normal(size=3) * 0.12
        p.resetBasePositionAndOrientation(probe, x.tolist(), [0, 0, 0, 1],
                                          physicsClientId=chain.client)
        pts = [pt for pt in p.getClosestPoints(chain.body, probe, 0.5,
                                               physicsClientId=chain.client)
               if pt[3] in links]
        if not pts:
            continue
        truth = min(pt[8] for pt in pts)
        mine = min(capsule_distance(c, Capsule(x, x, r)) for c in caps)
        assert mine <= truth + 1e-4, (x, mine, truth)
        n_close += truth < 0.05
    p.removeBody(probe, physicsClientId=chain.client)
    assert n_close > 3  # the probes did come close to the links


def test_capsules_are_tight(chain: Robot) -> None:
    """... and not absurdly large: every capsule radius within 1 cm of the half-thickness
    of what it covers (20-30 mm parts)."""
    for link, p0, p1, radius in MINI_CAPSULES:
        assert 0.015 <= radius <= 0.035, link
        assert np.linalg.norm(np.subtract(p1, p0)) > 0.04


def test_human_distance_matches_analytic_and_its_gradient_is_exact(chain: Robot) -> None:
    """dist (python-fcl) = the analytic capsule minimum; d(dist)/dt = g_r^T J_g qd for
    joint motions (finite differences over the mini-robot's joints)."""
    q = np.array(sc.Q_GOAL, dtype=float)
    cam = chain.frame_pose("mini_camera_optical", q)[:3, 3]
    human = [("hand_r", Capsule(cam + [0.0, -0.15, 0.02], cam + [0.0, -0.30, 0.05], 0.045)),
             ("forearm_r", Capsule(cam + [0.0, -0.30, 0.05], cam + [0.05, -0.5, 0.1], 0.04))]
    hd = human_distance(chain, q, human, human)
    mini = [c for _, c in sc.mini_capsules(chain, q)]
    analytic = min(capsule_distance(a, b) for a in mini for _, b in human)
    assert hd.dist == pytest.approx(analytic, abs=1e-9)
    assert hd.dist == hd.dist_true and 0.0 < hd.dist < 0.3
    J_g = chain.frame_jacobian("mini_camera_optical", q)[:, MINI_IDX]
    g_q = J_g.T @ hd.grad
    h = 1e-6
    fd = np.zeros(3)
    for k in range(3):
        dq = np.zeros(len(q))
        dq[MINI_IDX[k]] = h
        fd[k] = (human_distance(chain, q + dq, human, human).dist
                 - human_distance(chain, q - dq, human, human).dist) / (2 * h)
    assert np.abs(fd).max() > 0.01
    np.testing.assert_allclose(g_q, fd, atol=1e-6)


def test_gradient_from_joints_reproduces_the_joint_gradient() -> None:
    rng = np.random.default_rng(3)
    J_g = rng.normal(size=(6, 3))
    J_p = rng.normal(size=(3, 3))
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    g_r = distance_gradient_from_joints(J_g, J_p, n)
    np.testing.assert_allclose(J_g.T @ g_r, J_p.T @ n, atol=1e-12)
    # the minimum-norm solution: in the range of J_g
    P = J_g @ np.linalg.pinv(J_g)
    np.testing.assert_allclose(P @ g_r, g_r, atol=1e-12)
    with pytest.raises(ValueError, match="unit"):
        distance_gradient_from_joints(J_g, J_p, 2 * n)


def test_indirect_velocity_reference_solves_the_kinematics() -> None:
    rng = np.random.default_rng(1)
    J = rng.normal(size=(8, 3)) * 300.0
    qd_true = np.array([0.1, -0.2, 0.05])
    e = J @ qd_true  # an error exactly explained by a joint motion
    qd = ibvs_velocity_reference(J, e, 2.0)
    np.testing.assert_allclose(qd, -2.0 * qd_true, rtol=1e-6)
    capped = ibvs_velocity_reference(J, e, 2.0, qd_max=np.array([0.1, 0.1, 0.1]))
    assert np.max(np.abs(capped)) == pytest.approx(0.1)
    np.testing.assert_allclose(capped / np.linalg.norm(capped), qd / np.linalg.norm(qd))


def test_pd_gains_set_every_mode() -> None:
    M = np.array([[0.02, 0.003, 0.0], [0.003, 0.01, 0.001], [0.0, 0.001, 0.002]])
    g = pd_gains_from_inertia(M, 60.0, 1.0)
    lam = np.linalg.eigvals(np.linalg.solve(M, g.K_p))
    np.testing.assert_allclose(np.sort(lam.real), [3600.0] * 3, rtol=1e-9)
    np.testing.assert_allclose(np.linalg.solve(M, g.K_d), 120.0 * np.eye(3), atol=1e-9)
    with pytest.raises(ConfigError):
        pd_gains_from_inertia(-M, 60.0)


def _twist_fd(chain: Robot, frame: str, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """(6, 9) local-frame Jacobian of ``frame`` by central differences of its pose:
    column i = log(T(q - h e_i)^-1 T(q + h e_i)) / (2 h)."""
    import pinocchio as pin

    J = np.zeros((6, len(q)))
    for i in range(len(q)):
        dq = np.zeros(len(q))
        dq[i] = h
        Tm, Tp = chain.frame_pose(frame, q - dq), chain.frame_pose(frame, q + dq)
        J[:, i] = pin.log6(pin.SE3(np.linalg.inv(Tm) @ Tp)).vector / (2 * h)
    return J


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("frame", ["pa10_flange", "mini_camera_optical"])
def test_chain_jacobians_match_finite_differences(chain: Robot, seed: int, frame: str) -> None:
    """The PA-10's flange Jacobian (the RVC's eJ_e) and the mini-robot camera's (J_g of eq. 7)
    against finite differences over all nine joints, on random configurations."""
    rng = np.random.default_rng(seed)
    q = np.array(sc.Q_GOAL, dtype=float) + rng.uniform(-0.5, 0.5, size=len(sc.Q_GOAL))
    J = chain.frame_jacobian(frame, q)
    np.testing.assert_allclose(J, _twist_fd(chain, frame, q), atol=1e-6)
    if frame == "pa10_flange":  # the mini-robot's joints do not move the flange
        assert np.abs(J[:, MINI_IDX]).max() == 0.0


@pytest.mark.parametrize("seed", range(3))
def test_mini_robot_task_jacobian_matches_finite_differences(chain: Robot, seed: int) -> None:
    """J = L_s J_g (eq. 6) of the four dots in pixels against finite differences of their
    exact projections over the mini-robot's joints (the PA-10 fixed)."""
    from experiments.pomares2011.controller import pixel_interaction_matrix
    from repro.sensors.camera import project_points

    rng = np.random.default_rng(seed)
    q = np.array(sc.Q_GOAL, dtype=float)
    q[MINI_IDX] += rng.uniform(-0.1, 0.1, size=3)
    P = sc.DOTS.points_world(sc.OBJECT.T_world)

    def s_of(x: np.ndarray) -> np.ndarray:
        uv, _ = project_points(sc.INTRINSICS, chain.frame_pose("mini_camera_optical", x), P)
        return np.asarray(uv).ravel()

    uv, Z = project_points(sc.INTRINSICS, chain.frame_pose("mini_camera_optical", q), P)
    J = pixel_interaction_matrix(np.asarray(uv), np.asarray(Z)) @ chain.frame_jacobian(
        "mini_camera_optical", q)[:, MINI_IDX]
    h = 1e-6
    fd = np.zeros_like(J)
    for k, i in enumerate(MINI_IDX):
        dq = np.zeros(len(q))
        dq[i] = h
        fd[:, k] = (s_of(q + dq) - s_of(q - dq)) / (2 * h)
    assert np.abs(fd).max() > 100.0  # px/rad: the dots do move
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-3)


def test_the_operators_visit_follows_its_swept_fields() -> None:
    """Issue 19: experiment 2's hand gap and entry time are config fields; the defaults are
    the committed visit, the gap moves only the approach point, t_enter shifts every time,
    and experiment 1's config does not carry them (its hash unchanged)."""
    import dataclasses

    from experiments.pomares2011 import config as c
    from repro.sweep_ranges import declared_ranges

    d = c.Exp2Config()
    assert sc.human_path(d.human_gap, d.human_t_enter) == sc.HUMAN_PATH
    near = sc.human_path(0.05, 8.0)
    assert near.approach[1] - sc.HUMAN_PATH.approach[1] == pytest.approx(0.07)
    assert near.approach[0::2] == sc.HUMAN_PATH.approach[0::2]
    late = sc.human_path(0.12, 10.0)
    for name in ("t_enter", "t_reach", "t_hold", "t_leave"):
        assert getattr(late, name) - getattr(sc.HUMAN_PATH, name) == pytest.approx(2.0)
    assert dataclasses.replace(late, t_enter=8.0, t_reach=11.5, t_hold=14.0,
                               t_leave=19.0) == sc.HUMAN_PATH
    assert {"human_gap", "human_t_enter"} <= set(declared_ranges(c.Exp2NoSecondaryConfig))
    assert not {"human_gap", "human_t_enter"} & {f.name for f in
                                                 dataclasses.fields(c.Exp1Config)}
