"""Tests of repro.control.rvc (pomares2011 Sec. 5.1): the pose composition, the RVC
projection, the learned s_u*, exponential convergence of law (18) on a free-flying RVC (with
s_u computed directly and through VVS on a moving mini-robot camera), and the RVC feature
Jacobian by finite differences through a random 6-DoF chain."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from repro.control.rvc import (
    RVCFeatures,
    estimate_object_pose_in_rvc,
    learn_desired_features,
    object_pose_in_rvc,
    rvc_feature_jacobian,
    rvc_features,
    rvc_from_mounts,
    rvc_joint_velocity,
    rvc_velocity,
)
from repro.errors import SensorError
from repro.geometry import Rx, Rz, inv_T, trans, transform_points
from repro.sensors.camera import Intrinsics, project_points
from repro.vision.features import twist_transform
from repro.vision.ibvs import NonFiniteInputError
from repro.vision.vvs import se3_exp

#: pomares2011 Sec. 7 intrinsics, which the paper implies for the RVC too.
INTR = Intrinsics(640, 480, 1082.3, 1073.7, 298.0, 225.0)
SEEDS = range(5)
#: Characteristic points P_u^O of the RVC (ours): 4 non-coplanar points [m].
P_U = np.array([[-0.06, -0.04, 0.0], [0.05, -0.05, 0.02], [0.06, 0.05, 0.0],
                [-0.05, 0.04, -0.02]])
#: Points P_p^O the real camera sees (ours): a 10 cm square [m].
P_P = np.array([[-0.05, -0.05, 0.0], [0.05, -0.05, 0.0], [0.05, 0.05, 0.0],
                [-0.05, 0.05, 0.0]])


def random_pose(rng: np.random.Generator, scale: float = 0.5) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.uniform(-scale, scale, 3)
    return T


def facing_view(rng: np.random.Generator, tilt_deg: float = 20.0) -> np.ndarray:
    """T_cam_obj: the object's +z faces the camera, tilted, 0.4-0.7 m in front."""
    T = np.eye(4)
    tilt = np.deg2rad(tilt_deg) * np.r_[rng.uniform(-1.0, 1.0, 2), 0.0] / np.sqrt(2.0)
    T[:3, :3] = Rotation.from_rotvec(tilt).as_matrix() @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = (*rng.uniform(-0.05, 0.05, 2), rng.uniform(0.4, 0.7))
    return T


def small_motion(rng: np.random.Generator, dist: float, angle: float) -> np.ndarray:
    """A rigid motion of exactly ``dist`` [m] and ``angle`` [rad], random directions."""
    u, k = rng.normal(size=3), rng.normal(size=3)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(angle * k / np.linalg.norm(k)).as_matrix()
    T[:3, 3] = dist * u / np.linalg.norm(u)
    return T


@pytest.mark.parametrize("seed", SEEDS)
def test_object_pose_in_rvc_is_the_composition(seed: int) -> None:
    """M_O^RVC = M_MC^RVC M_O^MC equals inv(T_w_rvc) T_w_obj computed directly, with
    M_MC^RVC from the two mounts on the flange (random poses)."""
    rng = np.random.default_rng(seed)
    T_w_e, T_e_rvc, T_e_mc, T_w_obj = (random_pose(rng) for _ in range(4))
    T_w_rvc, T_w_mc = T_w_e @ T_e_rvc, T_w_e @ T_e_mc
    T_rvc_mc = rvc_from_mounts(T_e_rvc, T_e_mc)
    np.testing.assert_allclose(T_rvc_mc, inv_T(T_w_rvc) @ T_w_mc, atol=1e-12)
    T_mc_obj = inv_T(T_w_mc) @ T_w_obj
    np.testing.assert_allclose(object_pose_in_rvc(T_rvc_mc, T_mc_obj),
                               inv_T(T_w_rvc) @ T_w_obj, atol=1e-12)
    bad = T_mc_obj.copy()
    bad[0, 3] = np.nan
    with pytest.raises(NonFiniteInputError, match="T_mc_obj"):
        object_pose_in_rvc(T_rvc_mc, bad)


@pytest.mark.parametrize("seed", SEEDS)
def test_rvc_features_match_project_points(seed: int) -> None:
    """Eqs. (19)-(21) agree with the camera module's projection (pixels and depths)."""
    rng = np.random.default_rng(seed)
    T_w_rvc, T_rvc_obj = random_pose(rng), facing_view(rng)
    P_w = transform_points(T_w_rvc @ T_rvc_obj, P_U)
    uv, Z = project_points(INTR, T_w_rvc, P_w)
    f = rvc_features(INTR, T_rvc_obj, P_U)
    np.testing.assert_allclose(f.uv, uv, atol=1e-9)
    np.testing.assert_allclose(f.Z, Z, atol=1e-12)
    np.testing.assert_allclose(f.xy, INTR.to_normalized(uv), atol=1e-12)


def test_rvc_features_refuse_points_behind() -> None:
    T = facing_view(np.random.default_rng(0))
    T[2, 3] = 0.01  # the plane through the optical centre cuts the model
    with pytest.raises(SensorError, match="not in front"):
        rvc_features(INTR, T, P_U)


@pytest.mark.parametrize("seed", SEEDS)
def test_learned_features_are_the_projection_at_the_goal(seed: int) -> None:
    """s_u* = projection of P_u at the goal; learned through the whole chain (VVS on a
    mini-robot image at any mini-robot pose, composition, projection) it is the same, and
    law (18) commands zero velocity at the goal."""
    rng = np.random.default_rng(seed)
    T_rvc_obj_goal = facing_view(rng)
    uv_star = learn_desired_features(INTR, T_rvc_obj_goal, P_U)
    uv, _ = project_points(INTR, np.eye(4), transform_points(T_rvc_obj_goal, P_U))
    np.testing.assert_allclose(uv_star, uv, atol=1e-9)
    # the mini-robot camera somewhere else, looking at the object
    T_mc_obj = facing_view(rng)
    T_rvc_mc = T_rvc_obj_goal @ inv_T(T_mc_obj)
    uv_mc, _ = project_points(INTR, inv_T(T_mc_obj), P_P)
    T_rvc_obj, res = estimate_object_pose_in_rvc(
        P_P, uv_mc, INTR, T_mc_obj @ small_motion(rng, 0.03, np.deg2rad(5.0)), T_rvc_mc,
        eps=1e-20)
    assert res.converged
    np.testing.assert_allclose(learn_desired_features(INTR, T_rvc_obj, P_U), uv_star,
                               atol=1e-6)
    v = rvc_velocity(rvc_features(INTR, T_rvc_obj_goal, P_U), uv_star, INTR, 1.0)
    np.testing.assert_allclose(v, 0.0, atol=1e-12)


def assert_sampled_exponential(norms: np.ndarray, gain: float, dt: float) -> None:
    """||e_k|| / ||e_0|| against the sampled law (1 - lambda dt)^k (to 2e-3 in log) and
    exp(-lambda t) up to the sampling term k (lambda dt)^2 / 2."""
    log_ratio = np.log(norms / norms[0])
    k = np.arange(norms.size)
    assert np.all(np.abs(log_ratio - k * np.log1p(-gain * dt)) <= 2e-3)
    assert np.all(np.abs(log_ratio + gain * dt * k) <= 2e-3 + 0.6 * k * (gain * dt) ** 2)


def run_free_rvc(seed: int, gain: float, dt: float, steps: int,
                 through_vvs: bool) -> np.ndarray:
    """Servo a free-flying RVC with law (18), the twist held over each step and integrated
    exactly (T_w_rvc <- T_w_rvc exp(dt [v_rvc])), from 1 cm / 1 deg off the goal; returns
    ||s_u - s_u*|| (normalised) at every step. ``through_vvs``: s_u from the mini-robot
    camera's image by VVS (warm-started with the previous estimate) and M_O^RVC, with the
    mini-robot camera wandering on a circle of 5 cm around its mount."""
    rng = np.random.default_rng(seed)
    T_w_obj = random_pose(rng)
    T_rvc_obj_goal = facing_view(rng)
    uv_star = learn_desired_features(INTR, T_rvc_obj_goal, P_U)
    xy_star = INTR.to_normalized(uv_star)
    T_w_rvc = T_w_obj @ inv_T(T_rvc_obj_goal) @ small_motion(rng, 0.01, np.deg2rad(1.0))
    T_mc_obj_goal = facing_view(rng, 10.0)
    T_rvc_mc0 = T_rvc_obj_goal @ inv_T(T_mc_obj_goal)  # mount: the mini camera sees P_P
    T_mc_obj_est = T_mc_obj_goal
    norms = []
    for k in range(steps + 1):
        if through_vvs:
            phi = 2.0 * np.pi * k / steps
            T_rvc_mc = T_rvc_mc0 @ trans(0.05 * np.cos(phi), 0.05 * np.sin(phi), 0.0) @ Rz(phi)
            T_w_mc = T_w_rvc @ T_rvc_mc
            uv_mc, _ = project_points(INTR, T_w_mc, transform_points(T_w_obj, P_P))
            T_rvc_obj, res = estimate_object_pose_in_rvc(P_P, uv_mc, INTR, T_mc_obj_est,
                                                         T_rvc_mc, eps=1e-20)
            assert res.converged
            T_mc_obj_est = res.T_cam_obj
        else:
            T_rvc_obj = inv_T(T_w_rvc) @ T_w_obj
        f = rvc_features(INTR, T_rvc_obj, P_U)
        norms.append(np.linalg.norm(f.xy - xy_star))
        v_rvc = rvc_velocity(f, uv_star, INTR, gain)
        T_w_rvc = T_w_rvc @ se3_exp(dt * v_rvc)
    return np.array(norms)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("through_vvs", [False, True])
def test_free_flying_rvc_decays_exponentially(seed: int, through_vvs: bool) -> None:
    """Law (18) on a free-flying RVC: ||e(t)|| / ||e(0)|| follows the sampled law
    (1 - lambda dt)^k to 2e-3 in log (measured 8e-5), i.e. exp(-lambda t) up to the sampling
    term k (lambda dt)^2 / 2; the same through VVS on a moving mini-robot camera."""
    gain, dt, steps = 0.5, 0.02, 200
    norms = run_free_rvc(seed, gain, dt, steps, through_vvs)
    assert_sampled_exponential(norms, gain, dt)
    assert norms[-1] / norms[0] < 1.1 * np.exp(-gain * dt * steps)


def test_vvs_path_gives_the_direct_trajectory() -> None:
    """The features through VVS + M_O^RVC are the directly computed ones: same loop."""
    direct = run_free_rvc(0, 0.5, 0.02, 50, False)
    via_vvs = run_free_rvc(0, 0.5, 0.02, 50, True)
    np.testing.assert_allclose(via_vvs, direct, rtol=1e-9)  # measured 8e-12


class DHChain:
    """A random 6-DoF revolute chain in standard DH (theta_i = q_i + offset_i):
    T_w_e(q) = prod_i Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)."""

    def __init__(self, rng: np.random.Generator, n: int = 6) -> None:
        self.offset = rng.uniform(-np.pi, np.pi, n)
        self.d = rng.uniform(-0.3, 0.3, n)
        self.a = rng.uniform(-0.3, 0.3, n)
        self.alpha = rng.uniform(-np.pi, np.pi, n)

    def pose(self, q: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        for qi, off, d, a, al in zip(q, self.offset, self.d, self.a, self.alpha, strict=True):
            T = T @ Rz(qi + off) @ trans(0.0, 0.0, d) @ trans(a, 0.0, 0.0) @ Rx(al)
        return T

    def local_jacobian(self, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
        """(6, n) flange Jacobian in the flange frame, numerically (central differences):
        column i is the body twist of T^-1 dT/dq_i, linear part first."""
        T_inv = inv_T(self.pose(q))
        cols = []
        for i in range(q.size):
            dq = np.zeros(q.size)
            dq[i] = h
            M = T_inv @ (self.pose(q + dq) - self.pose(q - dq)) / (2.0 * h)
            W = M[:3, :3]
            w = np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2.0
            cols.append(np.r_[M[:3, 3], w])
        return np.array(cols).T


def chain_setup(seed: int) -> tuple[DHChain, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A chain, a goal q, the RVC mount T_e_rvc and the object pose T_w_obj placing the
    object in front of the RVC at the goal, and s_u* [px]."""
    rng = np.random.default_rng(seed)
    chain = DHChain(rng)
    q_goal = rng.uniform(-1.0, 1.0, 6)
    T_e_rvc = random_pose(rng, 0.1)
    T_rvc_obj_goal = facing_view(rng)
    T_w_obj = chain.pose(q_goal) @ T_e_rvc @ T_rvc_obj_goal
    return chain, q_goal, T_e_rvc, T_w_obj, learn_desired_features(INTR, T_rvc_obj_goal, P_U)


def features_at(chain: DHChain, q: np.ndarray, T_e_rvc: np.ndarray,
                T_w_obj: np.ndarray) -> RVCFeatures:
    return rvc_features(INTR, inv_T(chain.pose(q) @ T_e_rvc) @ T_w_obj, P_U)


@pytest.mark.parametrize("seed", range(10))
def test_rvc_feature_jacobian_matches_finite_differences(seed: int) -> None:
    """d s_u / dt along a random qd through a random 6-DoF chain equals J_s qd."""
    chain, q_goal, T_e_rvc, T_w_obj, _ = chain_setup(seed)
    rng = np.random.default_rng(seed + 100)
    q, qd = q_goal + 0.1 * rng.normal(size=6), rng.normal(size=6)
    J_s = rvc_feature_jacobian(features_at(chain, q, T_e_rvc, T_w_obj), T_e_rvc,
                               chain.local_jacobian(q))
    assert J_s.shape == (2 * P_U.shape[0], 6)
    h = 1e-5
    s_dot = ((features_at(chain, q + h * qd, T_e_rvc, T_w_obj).xy
              - features_at(chain, q - h * qd, T_e_rvc, T_w_obj).xy) / (2.0 * h)).ravel()
    assert np.linalg.norm(J_s @ qd - s_dot) <= 1e-6 * np.linalg.norm(s_dot)


@pytest.mark.parametrize("seed", SEEDS)
def test_rvc_joint_velocity_is_the_rvc_twist_through_the_arm(seed: int) -> None:
    """For a non-singular 6-DoF arm, qd = -lambda J_s^+ e equals eJ_e^-1 eV_rvc v_rvc."""
    chain, q_goal, T_e_rvc, T_w_obj, uv_star = chain_setup(seed)
    q = q_goal + 0.1 * np.random.default_rng(seed + 200).normal(size=6)
    f = features_at(chain, q, T_e_rvc, T_w_obj)
    eJ_e = chain.local_jacobian(q)
    assert np.linalg.cond(eJ_e) < 1e3
    qd = rvc_joint_velocity(f, uv_star, INTR, 0.7, T_e_rvc, eJ_e)
    v_rvc = rvc_velocity(f, uv_star, INTR, 0.7)
    np.testing.assert_allclose(qd, np.linalg.solve(eJ_e, twist_transform(T_e_rvc) @ v_rvc),
                               rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(
        rvc_joint_velocity(f, uv_star, INTR, 0.7, T_e_rvc, eJ_e, 1e-3, "scale"),
        qd * 1e-3 / np.max(np.abs(qd)), rtol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_rvc_joint_space_loop_converges(seed: int) -> None:
    """Law (18) through the arm (Euler on q from ~1 cm off the goal): the error follows
    (1 - lambda dt)^k ~ exp(-lambda t) at first order (8 features, 6 joints; measured
    deviation in log <= 2e-4)."""
    chain, q_goal, T_e_rvc, T_w_obj, uv_star = chain_setup(seed)
    gain, dt, steps = 1.0, 0.02, 150
    q = q_goal + 0.01 * np.random.default_rng(seed + 300).normal(size=6)
    xy_star = INTR.to_normalized(uv_star)
    norms = []
    for _ in range(steps + 1):
        f = features_at(chain, q, T_e_rvc, T_w_obj)
        norms.append(np.linalg.norm(f.xy - xy_star))
        q = q + dt * rvc_joint_velocity(f, uv_star, INTR, gain, T_e_rvc,
                                        chain.local_jacobian(q))
    assert_sampled_exponential(np.array(norms), gain, dt)


def test_law_rejects_bad_desired_features() -> None:
    f = rvc_features(INTR, facing_view(np.random.default_rng(0)), P_U)
    bad = f.uv.copy()
    bad[1, 0] = np.nan
    with pytest.raises(NonFiniteInputError, match="s_u"):
        rvc_velocity(f, bad, INTR, 1.0)
    with pytest.raises(ValueError, match="uv_star"):
        rvc_velocity(f, f.uv[:3], INTR, 1.0)
