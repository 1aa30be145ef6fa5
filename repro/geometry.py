"""Homogeneous transforms: small helpers shared by every paper.

Naming: ``T_a_b`` is the 4x4 pose of frame b expressed in frame a, so that
``p_a = T_a_b @ p_b`` (homogeneous points). Angles in radians.
"""

from __future__ import annotations

import numpy as np


def rot_x(angle: float) -> np.ndarray:
    """3x3 rotation about x by ``angle`` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> np.ndarray:
    """3x3 rotation about y by ``angle`` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> np.ndarray:
    """3x3 rotation about z by ``angle`` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def make_T(
    R: np.ndarray | None = None, t: np.ndarray | tuple[float, ...] | None = None
) -> np.ndarray:
    """4x4 transform from a rotation (3x3, default identity) and translation [m]."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if t is not None:
        T[:3, 3] = np.asarray(t, dtype=float)
    return T


def trans(x: float, y: float, z: float) -> np.ndarray:
    """Pure translation T(x, y, z) [m], as papers write it."""
    return make_T(t=(x, y, z))


def Rx(angle: float) -> np.ndarray:
    """Pure rotation about x as a 4x4 transform [rad]."""
    return make_T(rot_x(angle))


def Ry(angle: float) -> np.ndarray:
    """Pure rotation about y as a 4x4 transform [rad]."""
    return make_T(rot_y(angle))


def Rz(angle: float) -> np.ndarray:
    """Pure rotation about z as a 4x4 transform [rad]."""
    return make_T(rot_z(angle))


def inv_T(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform."""
    R, t = T[:3, :3], T[:3, 3]
    Ti = np.eye(4)
    Ti[:3, :3] = R.T
    Ti[:3, 3] = -R.T @ t
    return Ti


def transform_points(T_a_b: np.ndarray, P_b: np.ndarray) -> np.ndarray:
    """Points (N,3) in frame b -> (N,3) in frame a."""
    P_b = np.atleast_2d(P_b)
    return P_b @ T_a_b[:3, :3].T + T_a_b[:3, 3]
