"""Tests of repro.vision.features: interaction matrix and twist transform by finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from repro.errors import SensorError
from repro.vision.features import (
    interaction_matrix_point,
    interaction_matrix_points,
    rotate_twist,
    skew,
    twist_transform,
)

H_FD = 1e-5  # finite-difference step [s] for a unit-rate twist
REL_TOL = 1e-6


def hat(V: np.ndarray) -> np.ndarray:
    """4x4 se(3) matrix of a twist (v, w)."""
    M = np.zeros((4, 4))
    M[:3, :3] = skew(V[3:])
    M[:3, 3] = V[:3]
    return M


def vee_so3(W: np.ndarray) -> np.ndarray:
    return np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2.0


def random_pose(rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.uniform(-scale, scale, 3)
    return T


def normalized(T_world_camera: np.ndarray, P_world: np.ndarray) -> np.ndarray:
    """(N, 2) normalised coordinates x = X/Z, y = Y/Z of world points."""
    P_c = (P_world - T_world_camera[:3, 3]) @ T_world_camera[:3, :3]
    return P_c[:, :2] / P_c[:, 2:3]


def relerr(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-12))


def fd_feature_rate(T_wc: np.ndarray, P_w: np.ndarray, V_c: np.ndarray) -> np.ndarray:
    """Central difference of the stacked features (x1, y1, x2, ...) when the camera moves
    with the twist V_c expressed in the camera frame: T_wc(t) = T_wc exp(t [V_c])."""
    xp = normalized(T_wc @ expm(H_FD * hat(V_c)), P_w)
    xm = normalized(T_wc @ expm(-H_FD * hat(V_c)), P_w)
    return ((xp - xm) / (2.0 * H_FD)).reshape(-1)


def scene(seed: int, n_points: int = 6):
    """A random camera pose, points 0.2-1.5 m in front of it, a random camera twist."""
    rng = np.random.default_rng(seed)
    T_wc = random_pose(rng)
    Z = rng.uniform(0.2, 1.5, n_points)
    xy = rng.uniform(-0.6, 0.6, (n_points, 2))
    P_c = np.column_stack([xy * Z[:, None], Z])
    P_w = P_c @ T_wc[:3, :3].T + T_wc[:3, 3]
    V_c = np.concatenate([rng.normal(0, 0.3, 3), rng.normal(0, 0.5, 3)])
    return T_wc, P_w, xy, Z, V_c


def test_skew_is_cross_product() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=3), rng.normal(size=3)
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b), atol=1e-15)
    np.testing.assert_allclose(skew(a), -skew(a).T)


def test_interaction_matrix_point_formula() -> None:
    x, y, Z = 0.1, -0.2, 0.5
    expected = np.array([
        [-1 / Z, 0.0, x / Z, x * y, -(1 + x**2), y],
        [0.0, -1 / Z, y / Z, 1 + y**2, -x * y, -x],
    ])
    L = interaction_matrix_point(x, y, Z)
    assert L.shape == (2, 6)
    np.testing.assert_allclose(L, expected, rtol=0, atol=1e-15)


def test_interaction_matrix_points_row_order() -> None:
    _, _, xy, Z, _ = scene(1, n_points=4)
    L = interaction_matrix_points(xy, Z)
    assert L.shape == (8, 6)
    rows = [interaction_matrix_point(x, y, z) for (x, y), z in zip(xy, Z, strict=True)]
    stacked = np.vstack(rows)
    np.testing.assert_array_equal(L, stacked)


@pytest.mark.parametrize("seed", range(10))
def test_interaction_matrix_points_finite_difference(seed: int) -> None:
    T_wc, P_w, xy, Z, V_c = scene(seed)
    np.testing.assert_allclose(normalized(T_wc, P_w), xy, atol=1e-12)  # scene sanity
    fd = fd_feature_rate(T_wc, P_w, V_c)
    L = interaction_matrix_points(xy, Z)
    assert relerr(L @ V_c, fd) < REL_TOL
    # The check discriminates: a sign error in one entry or a twist taken in the wrong
    # frame (the world frame) is rejected by the same tolerance.
    L_bad = L.copy()
    L_bad[0::2, 5] *= -1.0
    assert relerr(L_bad @ V_c, fd) > 1e3 * REL_TOL
    assert relerr(L @ rotate_twist(T_wc[:3, :3]) @ V_c, fd) > 1e3 * REL_TOL


@pytest.mark.parametrize("bad_Z", [0.0, -0.3, np.nan])
def test_interaction_matrix_rejects_unusable_depth(bad_Z: float) -> None:
    with pytest.raises(SensorError):
        interaction_matrix_points(np.array([[0.1, 0.1], [0.0, 0.2]]), np.array([0.5, bad_Z]))


def test_interaction_matrix_rejects_lost_feature() -> None:
    with pytest.raises(SensorError):
        interaction_matrix_points(np.array([[np.nan, np.nan]]), np.array([0.5]))


@pytest.mark.parametrize("seed", range(10))
def test_twist_transform_finite_difference(seed: int) -> None:
    """Frames a and b fixed on one rigid body moving with twist V_b (expressed in b):
    twist_transform(T_a_b) @ V_b is the FD velocity of a's origin and the angular velocity,
    both in a's axes."""
    rng = np.random.default_rng(100 + seed)
    T_wb = random_pose(rng)
    T_ab = random_pose(rng, scale=0.5)
    T_ba = np.linalg.inv(T_ab)
    V_b = np.concatenate([rng.normal(0, 0.3, 3), rng.normal(0, 0.5, 3)])

    T_wa_p = T_wb @ expm(H_FD * hat(V_b)) @ T_ba
    T_wa_m = T_wb @ expm(-H_FD * hat(V_b)) @ T_ba
    R_wa = (T_wb @ T_ba)[:3, :3]
    v_a = R_wa.T @ (T_wa_p[:3, 3] - T_wa_m[:3, 3]) / (2.0 * H_FD)
    w_a = vee_so3(R_wa.T @ (T_wa_p[:3, :3] - T_wa_m[:3, :3]) / (2.0 * H_FD))
    fd = np.concatenate([v_a, w_a])

    X = twist_transform(T_ab)
    assert relerr(X @ V_b, fd) < REL_TOL
    # Discriminates: the transpose convention ([[R, 0], [skew(t) R, R]]) is rejected.
    X_bad = np.zeros((6, 6))
    X_bad[:3, :3] = X_bad[3:, 3:] = T_ab[:3, :3]
    X_bad[3:, :3] = skew(T_ab[:3, 3]) @ T_ab[:3, :3]
    assert relerr(X_bad @ V_b, fd) > 1e3 * REL_TOL


def test_twist_transform_group_properties() -> None:
    rng = np.random.default_rng(7)
    T1, T2 = random_pose(rng), random_pose(rng)
    np.testing.assert_allclose(twist_transform(T1 @ T2), twist_transform(T1) @ twist_transform(T2),
                               atol=1e-12)
    np.testing.assert_allclose(twist_transform(np.linalg.inv(T1)),
                               np.linalg.inv(twist_transform(T1)), atol=1e-12)


def test_rotate_twist_gives_origin_velocity_in_other_axes() -> None:
    """rotate_twist(R_w_b) @ V_b is the world-axes velocity of b's origin (FD)."""
    rng = np.random.default_rng(3)
    T_wb = random_pose(rng)
    V_b = rng.normal(size=6)
    p_p = (T_wb @ expm(H_FD * hat(V_b)))[:3, 3]
    p_m = (T_wb @ expm(-H_FD * hat(V_b)))[:3, 3]
    v_w = (p_p - p_m) / (2.0 * H_FD)
    assert relerr((rotate_twist(T_wb[:3, :3]) @ V_b)[:3], v_w) < REL_TOL


@pytest.mark.parametrize("seed", range(5))
def test_eye_in_hand_chain_finite_difference(seed: int) -> None:
    """Features of a camera mounted on the end effector (T_e_c) when the end effector moves
    with twist V_e in its own frame: x_dot = L cV_e V_e with cV_e = twist_transform(T_c_e)."""
    T_wc, P_w, xy, Z, _ = scene(200 + seed)
    rng = np.random.default_rng(300 + seed)
    T_ec = random_pose(rng, scale=0.1)
    T_we = T_wc @ np.linalg.inv(T_ec)
    V_e = np.concatenate([rng.normal(0, 0.3, 3), rng.normal(0, 0.5, 3)])
    xp = normalized(T_we @ expm(H_FD * hat(V_e)) @ T_ec, P_w)
    xm = normalized(T_we @ expm(-H_FD * hat(V_e)) @ T_ec, P_w)
    fd = ((xp - xm) / (2.0 * H_FD)).reshape(-1)
    L = interaction_matrix_points(xy, Z)
    assert relerr(L @ twist_transform(np.linalg.inv(T_ec)) @ V_e, fd) < REL_TOL
