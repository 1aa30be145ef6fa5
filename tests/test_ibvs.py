"""Tests of repro.vision.ibvs: feature Jacobian by finite differences on a synthetic chain,
exponential convergence of the IBVS law, saturators, and the non-finite guard."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from repro.errors import UnknownChoiceError
from repro.geometry import inv_T, transform_points
from repro.vision.features import interaction_matrix_points, skew, twist_transform
from repro.vision.ibvs import (
    NonFiniteInputError,
    feature_jacobian,
    ibvs_camera_velocity,
    ibvs_joint_velocity,
    saturate,
)

SEEDS = range(5)


def hat(V: np.ndarray) -> np.ndarray:
    """4x4 se(3) matrix of a twist (v, w)."""
    M = np.zeros((4, 4))
    M[:3, :3] = skew(V[3:])
    M[:3, 3] = V[:3]
    return M


def exp_se3(V: np.ndarray) -> np.ndarray:
    """4x4 exp([V]) of a twist (v, w) in closed form (Rodrigues; faster than scipy's expm)."""
    v, w = V[:3], V[3:]
    th = np.linalg.norm(w)
    W = skew(w)
    if th < 1e-9:
        R, G = np.eye(3) + W, np.eye(3) + W / 2.0
    else:
        a, b = np.sin(th) / th, (1.0 - np.cos(th)) / th**2
        R = np.eye(3) + a * W + b * W @ W
        G = np.eye(3) + b * W + (th - np.sin(th)) / th**3 * W @ W
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, G @ v
    return T


def vee(M: np.ndarray) -> np.ndarray:
    """Twist (v, w) of a 4x4 se(3) matrix (its skew part averaged)."""
    W = M[:3, :3]
    w = np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2.0
    return np.concatenate([M[:3, 3], w])


def random_pose(rng: np.random.Generator, scale: float = 0.5) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.uniform(-scale, scale, 3)
    return T


class Chain:
    """Robot-free serial chain as a product of exponentials (revolute joints):
    ``T_world_e(q) = exp([xi_1] q_1) ... exp([xi_n] q_n) M``."""

    def __init__(self, rng: np.random.Generator, n: int) -> None:
        self.xi = []
        for _ in range(n):
            w = rng.normal(size=3)
            w /= np.linalg.norm(w)
            p = rng.uniform(-0.5, 0.5, 3)  # a point on the joint axis [m]
            self.xi.append(np.concatenate([-np.cross(w, p), w]))
        self.M = random_pose(rng)

    def pose(self, q: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        for xi, qi in zip(self.xi, q, strict=True):
            T = T @ exp_se3(xi * qi)
        return T @ self.M

    def local_jacobian(self, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
        """(6, n) flange Jacobian in the flange frame, numerically: column i is the body
        twist vee(T^-1 dT/dq_i) (central differences), linear part first."""
        T_inv = inv_T(self.pose(q))
        cols = []
        for i in range(q.size):
            dq = np.zeros(q.size)
            dq[i] = h
            dT = (self.pose(q + dq) - self.pose(q - dq)) / (2.0 * h)
            cols.append(vee(T_inv @ dT))
        return np.array(cols).T


def camera_setup(rng: np.random.Generator, chain: Chain, q: np.ndarray, n_points: int = 6):
    """Camera mount T_e_c and world points 0.3-1 m in front of the camera at q."""
    T_e_c = random_pose(rng, 0.1)
    P_c = np.c_[rng.uniform(-0.2, 0.2, (n_points, 2)), rng.uniform(0.3, 1.0, n_points)]
    P_w = transform_points(chain.pose(q) @ T_e_c, P_c)
    return T_e_c, P_w


def features(T_world_camera: np.ndarray, P_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) normalised coordinates and (N,) depths of world points."""
    P_c = transform_points(inv_T(T_world_camera), P_w)
    return P_c[:, :2] / P_c[:, 2:3], P_c[:, 2]


@pytest.mark.parametrize("seed", SEEDS)
def test_feature_jacobian_matches_finite_differences(seed: int) -> None:
    """ds/dt of the projected points as the chain moves with qd equals J_s qd."""
    rng = np.random.default_rng(seed)
    n = 7
    chain = Chain(rng, n)
    q, qd = rng.uniform(-1.0, 1.0, n), rng.normal(size=n)
    T_e_c, P_w = camera_setup(rng, chain, q)
    x, Z = features(chain.pose(q) @ T_e_c, P_w)
    J_s = feature_jacobian(interaction_matrix_points(x, Z), twist_transform(inv_T(T_e_c)),
                           chain.local_jacobian(q))
    assert J_s.shape == (2 * P_w.shape[0], n)
    h = 1e-5
    xp, _ = features(chain.pose(q + h * qd) @ T_e_c, P_w)
    xm, _ = features(chain.pose(q - h * qd) @ T_e_c, P_w)
    s_dot = ((xp - xm) / (2.0 * h)).ravel()
    assert np.linalg.norm(J_s @ qd - s_dot) <= 1e-6 * np.linalg.norm(s_dot)


def test_feature_jacobian_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match="L_s"):
        feature_jacobian(np.zeros((8, 5)), np.eye(6), np.zeros((6, 7)))
    with pytest.raises(ValueError, match="eJ_e"):
        feature_jacobian(np.zeros((8, 6)), np.eye(6), np.zeros((3, 7)))


@pytest.mark.parametrize("seed", SEEDS)
def test_camera_velocity_known_solution(seed: int) -> None:
    """For e = L delta with L of full column rank, v_c = -lambda delta."""
    rng = np.random.default_rng(seed)
    L, delta, gain = rng.normal(size=(8, 6)), rng.normal(size=6), rng.uniform(0.1, 2.0)
    np.testing.assert_allclose(ibvs_camera_velocity(L, L @ delta, gain), -gain * delta,
                               rtol=1e-10, atol=1e-12)


def run_pure_camera(seed: int, gain: float, dt: float, steps: int, pos_err: float,
                    ang_err: float) -> np.ndarray:
    """Servo a free camera on 4 coplanar points from a random start near the goal, with
    perfect integration of v_c over each step; returns ||e_k||, k = 0..steps."""
    rng = np.random.default_rng(seed)
    a = 0.05
    P_w = np.array([[-a, -a, 0.0], [a, -a, 0.0], [a, a, 0.0], [-a, a, 0.0]])
    T_goal = np.eye(4)
    T_goal[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking down -z at the target
    T_goal[:3, 3] = (0.0, 0.0, 0.5)
    x_star, _ = features(T_goal, P_w)
    T_start = np.eye(4)
    T_start[:3, :3] = Rotation.from_rotvec(ang_err * Rotation.random(
        random_state=rng).apply([1.0, 0.0, 0.0])).as_matrix()
    T_start[:3, 3] = pos_err * Rotation.random(random_state=rng).apply([1.0, 0.0, 0.0])
    T = T_goal @ T_start
    norms = []
    for _ in range(steps + 1):
        x, Z = features(T, P_w)
        e = (x - x_star).ravel()
        norms.append(np.linalg.norm(e))
        v_c = ibvs_camera_velocity(interaction_matrix_points(x, Z), e, gain)
        T = T @ exp_se3(dt * v_c)
    return np.array(norms)


def assert_exponential(log_ratio: np.ndarray, gain: float, dt: float) -> None:
    """log(||e_k|| / ||e_0||) against the first-order prediction: (1 - lambda dt)^k for the
    sampled law (to 2e-3, the second-order effect of a ~1 cm start), and exp(-lambda t)
    up to the sampling term k (lambda dt)^2 / 2."""
    k = np.arange(log_ratio.size)
    t = dt * k
    assert np.all(np.abs(log_ratio - k * np.log1p(-gain * dt)) <= 2e-3)
    assert np.all(np.abs(log_ratio + gain * t) <= 2e-3 + 0.6 * k * (gain * dt) ** 2)


@pytest.mark.parametrize("seed", SEEDS)
def test_ibvs_pure_camera_decays_exponentially(seed: int) -> None:
    """Near the goal (1 cm, 1 deg start), ||e(t)|| / ||e(0)|| = exp(-lambda t) at first
    order: 8 features, 6 dof, e in the range of L at first order."""
    gain, dt, steps = 0.5, 0.02, 200
    norms = run_pure_camera(seed, gain, dt, steps, 0.01, np.deg2rad(1.0))
    log_ratio = np.log(norms / norms[0])
    assert_exponential(log_ratio, gain, dt)


@pytest.mark.parametrize("seed", SEEDS)
def test_ibvs_pure_camera_converges_from_far(seed: int) -> None:
    """From 10 cm, 20 deg away the error still decreases monotonically to ~exp(-lambda T)."""
    gain, dt, steps = 1.0, 0.02, 200
    norms = run_pure_camera(seed, gain, dt, steps, 0.10, np.deg2rad(20.0))
    assert np.all(np.diff(norms) < 0.0)
    assert norms[-1] / norms[0] < 3.0 * np.exp(-gain * dt * steps)


@pytest.mark.parametrize("seed", SEEDS)
def test_ibvs_joint_space_decays_exponentially(seed: int) -> None:
    """Closed loop through feature_jacobian on a redundant 7-joint chain (Euler on q), 3
    points = 6 features: J_s has full row rank, so de/dt = -lambda e up to the sampling."""
    rng = np.random.default_rng(seed)
    n, gain, dt, steps = 7, 1.0, 0.01, 200
    chain = Chain(rng, n)
    q_goal = rng.uniform(-1.0, 1.0, n)
    T_e_c, P_w = camera_setup(rng, chain, q_goal, n_points=3)  # 6 features < 7 joints
    cV_e = twist_transform(inv_T(T_e_c))
    x_star, _ = features(chain.pose(q_goal) @ T_e_c, P_w)
    q = q_goal + 0.02 * rng.normal(size=n)
    norms = []
    for _ in range(steps + 1):
        x, Z = features(chain.pose(q) @ T_e_c, P_w)
        e = (x - x_star).ravel()
        norms.append(np.linalg.norm(e))
        J_s = feature_jacobian(interaction_matrix_points(x, Z), cV_e, chain.local_jacobian(q))
        q = q + dt * ibvs_joint_velocity(J_s, e, gain)
    log_ratio = np.log(np.array(norms) / norms[0])
    assert_exponential(log_ratio, gain, dt)


def unsaturated(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    J_s, e = rng.normal(size=(8, 7)), rng.normal(size=8)
    qd_max = rng.uniform(0.5, 1.5, 7)
    return J_s, e, qd_max


@pytest.mark.parametrize("seed", SEEDS)
def test_saturation_clip(seed: int) -> None:
    J_s, e, qd_max = unsaturated(seed)
    gain = 5.0
    free = ibvs_joint_velocity(J_s, e, gain)
    assert np.any(np.abs(free) > qd_max)  # the test needs an active limit
    qd = ibvs_joint_velocity(J_s, e, gain, qd_max, "clip")
    assert np.all(np.abs(qd) <= qd_max)
    inside = np.abs(free) <= qd_max
    np.testing.assert_array_equal(qd[inside], free[inside])
    np.testing.assert_allclose(np.abs(qd[~inside]), qd_max[~inside])
    np.testing.assert_array_equal(np.sign(qd), np.sign(free))


@pytest.mark.parametrize("seed", SEEDS)
def test_saturation_scale_keeps_direction(seed: int) -> None:
    J_s, e, qd_max = unsaturated(seed)
    gain = 5.0
    free = ibvs_joint_velocity(J_s, e, gain)
    qd = ibvs_joint_velocity(J_s, e, gain, qd_max, "scale")
    assert np.all(np.abs(qd) <= qd_max * (1.0 + 1e-12))
    assert np.max(np.abs(qd) / qd_max) == pytest.approx(1.0)  # the binding joint at its limit
    cos = qd @ free / (np.linalg.norm(qd) * np.linalg.norm(free))
    assert cos == pytest.approx(1.0, abs=1e-12)
    assert np.linalg.norm(qd) < np.linalg.norm(free)


@pytest.mark.parametrize("mode", ["clip", "scale"])
def test_saturation_inactive_within_limits(mode: str) -> None:
    J_s, e, _ = unsaturated(0)
    free = ibvs_joint_velocity(J_s, e, 0.1)
    qd = ibvs_joint_velocity(J_s, e, 0.1, 2.0 * np.abs(free) + 1e-3, mode)
    np.testing.assert_array_equal(qd, free)
    np.testing.assert_allclose(free, -0.1 * np.linalg.pinv(J_s) @ e)


def test_saturation_rejects_bad_choices() -> None:
    with pytest.raises(UnknownChoiceError, match="clip, scale"):
        ibvs_joint_velocity(np.eye(6), np.ones(6), 1.0, 1.0, "tanh")
    with pytest.raises(ValueError, match="qd_max"):
        saturate(np.ones(3), np.array([1.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="gain"):
        ibvs_camera_velocity(np.eye(6), np.ones(6), -1.0)


def with_nan(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flat[a.size // 2] = np.nan
    return a


@pytest.mark.parametrize("bad", ["L_s", "cV_e", "eJ_e"])
def test_feature_jacobian_rejects_nan(bad: str) -> None:
    args = {"L_s": np.ones((8, 6)), "cV_e": np.eye(6), "eJ_e": np.ones((6, 7))}
    args[bad] = with_nan(args[bad])
    with pytest.raises(NonFiniteInputError, match=bad):
        feature_jacobian(**args)


@pytest.mark.parametrize("bad", ["L", "e", "gain"])
def test_camera_velocity_rejects_nan(bad: str) -> None:
    args = {"L": np.eye(6), "e": np.ones(6), "gain": np.array(1.0)}
    args[bad] = with_nan(args[bad])
    with pytest.raises(NonFiniteInputError):
        ibvs_camera_velocity(args["L"], args["e"], float(args["gain"]))


@pytest.mark.parametrize("bad", ["J_s", "e", "gain", "qd_max"])
@pytest.mark.parametrize("mode", ["clip", "scale"])
def test_joint_velocity_rejects_nan(bad: str, mode: str) -> None:
    args = {"J_s": np.ones((6, 7)), "e": np.ones(6), "gain": np.array(1.0),
            "qd_max": np.ones(7)}
    args[bad] = with_nan(args[bad])
    with pytest.raises(NonFiniteInputError) as info:
        ibvs_joint_velocity(args["J_s"], args["e"], float(args["gain"]), args["qd_max"], mode)
    assert isinstance(info.value, ValueError)


def test_exp_se3_matches_expm() -> None:
    V = np.random.default_rng(0).normal(size=6)
    np.testing.assert_allclose(exp_se3(V), expm(hat(V)), atol=1e-12)
