"""Image point features and their interaction matrix; twist (velocity screw) transforms.

Frames follow :mod:`repro.sensors.camera`: the camera frame ``{c}`` has ``+z`` along the
optical axis, ``+x`` right and ``+y`` down in the image; a point feature is the pair of
normalised coordinates ``x = X / Z``, ``y = Y / Z`` of a 3-D point ``(X, Y, Z)`` of ``{c}``.

A *twist* ``V = (v, w)`` (6,) of a rigid body "expressed in frame b" is ordered linear then
angular: ``w`` [rad/s] is the body's angular velocity and ``v`` [m/s] the velocity of the
body point that coincides with the origin of ``b`` at this instant, both in the axes of
``b``. For a frame ``b`` fixed to the body this is ``v = R_world_b^T d(p_world_b)/dt``,
``[w]_x = R_world_b^T dR_world_b/dt``, i.e. ``T_world_b(t + dt) = T_world_b(t) exp(dt [V])``.

Reference: F. Chaumette and S. Hutchinson, "Visual servo control, Part I: Basic approaches",
IEEE Robotics & Automation Magazine, 13(4):82-90, 2006 -- eq. (11) for the interaction matrix
of a point; the paper uses twist transformation matrices (e.g. cV_e) of the form built by
:func:`twist_transform`.
"""

from __future__ import annotations

import math

import numpy as np

from repro.errors import SensorError


def skew(v: np.ndarray) -> np.ndarray:
    """3x3 skew-symmetric matrix of a 3-vector, so that ``skew(a) @ b == cross(a, b)``.

    .. math::

        [v]_\\times = \\begin{bmatrix} 0 & -v_3 & v_2 \\\\ v_3 & 0 & -v_1 \\\\
                                     -v_2 & v_1 & 0 \\end{bmatrix}
    """
    v = np.asarray(v, dtype=float).reshape(3)
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def twist_transform(T_a_b: np.ndarray) -> np.ndarray:
    """6x6 twist transformation ``aV_b`` (the adjoint of ``T_a_b``).

    Maps the twist ``(v_b, w_b)`` of a rigid body expressed in frame ``b`` (``v_b``: velocity
    of the body point at the origin of ``b``, axes of ``b``) to the twist of the *same* motion
    expressed in frame ``a`` (``v_a``: velocity of the body point at the origin of ``a``, axes
    of ``a``). With ``R, t`` the rotation and translation of ``T_a_b`` (pose of ``b`` in
    ``a``, translation in metres):

    .. math::

        \\begin{bmatrix} v_a \\\\ \\omega_a \\end{bmatrix} =
        \\begin{bmatrix} R & [t]_\\times R \\\\ 0 & R \\end{bmatrix}
        \\begin{bmatrix} v_b \\\\ \\omega_b \\end{bmatrix},
        \\qquad v_a = R v_b + t \\times (R \\omega_b)

    since the point at ``a``'s origin sits at ``-t`` from ``b``'s origin. Typical use: the
    camera is fixed to the end effector (``T_e_c``, mount), then ``twist_transform(T_e_c) @
    V_c`` is the end-effector twist for the camera twist ``V_c`` (both frames on one body).
    Note ``twist_transform(T_world_c) @ V_c`` gives the velocity of the body point at the
    *world origin*; for the velocity of the camera origin in world axes use
    :func:`rotate_twist` instead.
    """
    T = np.asarray(T_a_b, dtype=float)
    if T.shape != (4, 4):
        raise ValueError(f"T_a_b must be 4x4, got shape {T.shape}")
    R, t = T[:3, :3], T[:3, 3]
    X = np.zeros((6, 6))
    X[:3, :3] = R
    X[:3, 3:] = skew(t) @ R
    X[3:, 3:] = R
    return X


def rotate_twist(R_a_b: np.ndarray) -> np.ndarray:
    """6x6 ``blockdiag(R, R)``: re-expresses the axes of a twist, keeping its reference point.

    Maps ``(v, w)`` in the axes of ``b`` to the same vectors in the axes of ``a`` (the linear
    velocity still refers to the same point, e.g. the origin of ``b``).
    """
    R = np.asarray(R_a_b, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"R_a_b must be 3x3, got shape {R.shape}")
    X = np.zeros((6, 6))
    X[:3, :3] = R
    X[3:, 3:] = R
    return X


def interaction_matrix_point(x: float, y: float, Z: float) -> np.ndarray:
    """(2, 6) interaction matrix of one image point (Chaumette & Hutchinson 2006, eq. 11).

    For a static 3-D point of normalised image coordinates ``(x, y)`` [-] and depth ``Z`` [m]
    in the camera frame, and the camera twist ``v_c = (v, w)`` expressed in the camera frame
    (``v`` [m/s]: velocity of the camera origin; ``w`` [rad/s]):

    .. math::

        \\begin{bmatrix} \\dot x \\\\ \\dot y \\end{bmatrix} = L \\, v_c, \\qquad
        L = \\begin{bmatrix}
            -1/Z & 0 & x/Z & x y & -(1 + x^2) & y \\\\
            0 & -1/Z & y/Z & 1 + y^2 & -x y & -x
        \\end{bmatrix}

    Raises:
        SensorError: ``Z`` is not a finite positive depth or ``x, y`` are not finite.
    """
    return interaction_matrix_points(np.array([[x, y]], dtype=float), np.array([Z], dtype=float))


_SMALL_N = 16
"""Up to this many points, :func:`interaction_matrix_points` works on Python floats (the
same IEEE operations as the vectorised code, without NumPy's per-call overhead)."""


def _interaction_matrix_small(xy: np.ndarray, Z: np.ndarray) -> np.ndarray | None:
    """The (2N, 6) matrix of :func:`interaction_matrix_points` built from Python floats, or
    None when a point is invalid (the caller then raises its error)."""
    inf = math.inf
    rows: list[tuple[float, ...]] = []
    for (x, y), z in zip(xy.tolist(), Z.tolist(), strict=True):
        if not (0.0 < z < inf and -inf < x < inf and -inf < y < inf):
            return None
        inv_z = 1.0 / z
        rows.append((-inv_z, 0.0, x * inv_z, x * y, -(1.0 + x * x), y))
        rows.append((0.0, -inv_z, y * inv_z, 1.0 + y * y, -x * y, -x))
    return np.array(rows, dtype=float).reshape(-1, 6)


def interaction_matrix_points(xy: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """(2N, 6) stacked interaction matrices of N image points, rows ``x1, y1, x2, y2, ...``.

    Args:
        xy: (N, 2) normalised image coordinates [-].
        Z: (N,) depths of the points in the camera frame [m].

    Returns:
        ``L`` with ``d(xy).ravel()/dt = L @ v_c`` for the camera twist ``v_c`` in the camera
        frame (see :func:`interaction_matrix_point`).

    Raises:
        SensorError: a depth is not finite and positive, or a coordinate is not finite
            (e.g. a lost feature's NaN): select the found features first.
    """
    xy = np.asarray(xy, dtype=float)
    Z = np.asarray(Z, dtype=float).reshape(-1)
    if xy.ndim != 2 or xy.shape[1] != 2 or Z.shape[0] != xy.shape[0]:
        raise ValueError(f"need xy (N, 2) and Z (N,), got {xy.shape} and {Z.shape}")
    if xy.shape[0] <= _SMALL_N:
        L = _interaction_matrix_small(xy, Z)
        if L is not None:
            return L
    bad = ~(np.isfinite(Z) & (Z > 0) & np.all(np.isfinite(xy), axis=1))
    if np.any(bad):
        idx = np.flatnonzero(bad).tolist()
        raise SensorError(f"interaction matrix needs finite xy and Z > 0; bad points {idx}: "
                          f"xy={xy[bad].tolist()}, Z={Z[bad].tolist()}")
    x, y = xy[:, 0], xy[:, 1]
    inv_z = 1.0 / Z
    L = np.zeros((x.size, 2, 6))
    L[:, 0, 0] = -inv_z
    L[:, 0, 2] = x * inv_z
    L[:, 0, 3] = x * y
    L[:, 0, 4] = -(1.0 + x * x)
    L[:, 0, 5] = y
    L[:, 1, 1] = -inv_z
    L[:, 1, 2] = y * inv_z
    L[:, 1, 3] = 1.0 + y * y
    L[:, 1, 4] = -x * y
    L[:, 1, 5] = -x
    return L.reshape(-1, 6)
