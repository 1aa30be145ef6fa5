"""Pose of a known point model from its image (PnP), and the point depths it gives.

Used by every paper that needs the depths ``Z`` of the interaction matrix from a measured
image (thomas2024: depths of the four dots from a PnP pose in render mode).

Conventions follow :mod:`repro.sensors.camera`: ``T_camera_object`` is the 4x4 pose of the
object frame in the camera frame ``{c}`` (``+z`` optical axis, ``+x`` right, ``+y`` down),
so that ``P_camera = T_camera_object @ P_object``; lengths in metres; image points ``uv``
in pixels [px] with ``(0, 0)`` the centre of the top-left pixel; ``K`` the 3x3 calibration
matrix (:meth:`repro.sensors.camera.Intrinsics.K`), no lens distortion.

Solvers (OpenCV ``cv2.solvePnP``):

* ``"ippe"``: T. Collins and A. Bartoli, "Infinitesimal Plane-based Pose Estimation", IJCV
  109(3):252-286, 2014 (``SOLVEPNP_IPPE``): for N >= 4 *coplanar* points, closed form and
  optimal, no initial guess.
* ``"iterative"``: Levenberg-Marquardt minimisation of the reprojection error
  (``SOLVEPNP_ITERATIVE``), N >= 4 points in any configuration (DLT or homography start),
  or from ``T_init`` (then N >= 3).
* ``"auto"``: ``"ippe"`` when the points are coplanar, ``"iterative"`` otherwise.
"""

from __future__ import annotations

import cv2
import numpy as np

from repro.errors import ConfigError, UnknownChoiceError

#: PnP methods of :func:`pose_from_points`.
PNP_METHODS = ("auto", "ippe", "iterative")

#: Points count as coplanar (collinear) when their RMS distance to the best-fit plane (line)
#: is below this fraction of their RMS distance to their centroid [-].
DEGENERACY_RTOL = 1e-6


def _points(points_object: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    P = np.asarray(points_object, dtype=float)
    uv = np.asarray(uv, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or uv.shape != (P.shape[0], 2):
        raise ConfigError(f"need points_object (N, 3) and uv (N, 2), got {P.shape} and {uv.shape}")
    if not np.isfinite(P).all():
        raise ConfigError("points_object must be finite")
    return P, uv


def _singular_values(P: np.ndarray) -> np.ndarray:
    """Singular values of the centred point set (descending), divided by sqrt(N) [m]:
    the RMS spread along the principal axes."""
    if P.shape[0] == 0:
        return np.zeros(P.shape[1])
    s = np.linalg.svd(P - P.mean(axis=0), compute_uv=False) / np.sqrt(P.shape[0])
    return np.pad(s, (0, P.shape[1] - s.size))


def is_coplanar(points: np.ndarray) -> bool:
    """True when the (N, 3) points lie on one plane (up to :data:`DEGENERACY_RTOL`)."""
    s = _singular_values(np.asarray(points, dtype=float))
    return bool(s[2] <= DEGENERACY_RTOL * max(float(np.linalg.norm(s)), 1e-300))


def is_collinear(points: np.ndarray) -> bool:
    """True when the (N, 2) or (N, 3) points lie on one line (or coincide)."""
    s = _singular_values(np.asarray(points, dtype=float))
    return bool(s[1] <= DEGENERACY_RTOL * max(float(np.linalg.norm(s)), 1e-300))


def pose_from_points(points_object: np.ndarray, uv: np.ndarray, K: np.ndarray,
                     method: str = "auto",
                     T_init: np.ndarray | None = None) -> np.ndarray | None:
    """Pose of a known point model from its pixel projections (Perspective-n-Point).

    Finds ``T_camera_object = [R t; 0 1]`` minimising the reprojection error

    .. math::

        \\sum_i \\left\\| \\begin{bmatrix} u_i \\\\ v_i \\end{bmatrix} -
        \\pi\\left(K (R P_i + t)\\right) \\right\\|^2, \\qquad
        \\pi(X, Y, Z) = (X / Z, Y / Z)

    Args:
        points_object: (N, 3) model points in the object frame [m].
        uv: (N, 2) their measured image points [px], same order.
        K: 3x3 calibration matrix [px].
        method: one of :data:`PNP_METHODS`: ``"ippe"`` (N >= 4 coplanar points), ``"iterative"``
            or ``"auto"`` (``"ippe"`` if the model is coplanar, else ``"iterative"``).
        T_init: optional 4x4 initial guess of ``T_camera_object`` [m]: then
            ``SOLVEPNP_ITERATIVE`` refines it (``useExtrinsicGuess``), whatever ``method``
            (IPPE takes no guess); useful to stay on the branch of the previous frame.

    Returns:
        ``T_camera_object`` (4x4), or None when the pose cannot be determined: fewer than 4
        points (3 with ``T_init``), a non-finite ``uv`` (a lost feature: pass the found
        points only), collinear model or image points (a rotation about the line is free),
        an OpenCV failure, a non-finite result, or a model centroid not in front of the
        camera.

    Raises:
        ConfigError: malformed shapes, non-finite model or ``K``, or ``method="ippe"`` with a
            non-coplanar model.
        UnknownChoiceError: ``method`` is not one of :data:`PNP_METHODS`.
    """
    if method not in PNP_METHODS:
        raise UnknownChoiceError("PnP method", method, PNP_METHODS)
    P, uv = _points(points_object, uv)
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 3) or not np.isfinite(K).all():
        raise ConfigError(f"K must be a finite 3x3 calibration matrix, got shape {K.shape}")
    coplanar = is_coplanar(P)
    if method == "ippe" and not coplanar:
        raise ConfigError("method 'ippe' needs coplanar model points; use 'iterative' or 'auto'")
    n_min = 3 if T_init is not None else 4
    if P.shape[0] < n_min or not np.isfinite(uv).all() or is_collinear(P) or is_collinear(uv):
        return None
    P = np.ascontiguousarray(P)
    uv = np.ascontiguousarray(uv)
    try:
        if T_init is not None:
            T0 = np.asarray(T_init, dtype=float)
            if T0.shape != (4, 4) or not np.isfinite(T0).all():
                raise ConfigError(f"T_init must be a finite 4x4 pose, got shape {T0.shape}")
            rvec0, _ = cv2.Rodrigues(T0[:3, :3])
            ok, rvec, tvec = cv2.solvePnP(P, uv, K, None, rvec0, T0[:3, 3].reshape(3, 1).copy(),
                                          useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
        else:
            flag = cv2.SOLVEPNP_IPPE if (method != "iterative" and coplanar) \
                else cv2.SOLVEPNP_ITERATIVE
            ok, rvec, tvec = cv2.solvePnP(P, uv, K, None, flags=flag)
    except cv2.error:
        return None
    if not ok or rvec is None or tvec is None:
        return None
    rvec, tvec = np.asarray(rvec, dtype=float).reshape(3), np.asarray(tvec, dtype=float).reshape(3)
    if not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
        return None
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec
    if depths_from_pose(P.mean(axis=0, keepdims=True), T)[0] <= 0.0:
        return None
    return T


def depths_from_pose(points_object: np.ndarray, T_camera_object: np.ndarray) -> np.ndarray:
    """(N,) depths ``Z`` [m] of model points in the camera frame for a pose of the object.

    .. math:: Z_i = e_3^T (R P_i + t), \\qquad T_{camera,object} = [R \\; t]

    Args:
        points_object: (N, 3) model points in the object frame [m].
        T_camera_object: 4x4 pose of the object in the camera frame [m].
    """
    P = np.asarray(points_object, dtype=float)
    T = np.asarray(T_camera_object, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or T.shape != (4, 4):
        raise ConfigError(f"need points_object (N, 3) and a 4x4 pose, got {P.shape} and {T.shape}")
    return np.asarray(P @ T[2, :3] + T[2, 3], dtype=float)


def point_depths(points_object: np.ndarray, uv: np.ndarray, K: np.ndarray,
                 fallback_Z: float | np.ndarray, method: str = "auto",
                 T_init: np.ndarray | None = None) -> np.ndarray:
    """(N,) depths [m] for the interaction matrix: from a PnP pose, or a fallback.

    The PnP depths (:func:`pose_from_points`, then :func:`depths_from_pose`) when the pose
    is found and every depth is finite and > 0; otherwise ``fallback_Z`` (typically the
    depths at the goal, ``Z*``, as in thomas2024).

    Args:
        points_object: (N, 3) model points in the object frame [m].
        uv: (N, 2) measured image points [px]; a NaN row (lost feature) gives the fallback.
        K: 3x3 calibration matrix [px].
        fallback_Z: scalar or (N,) depths [m] used when PnP fails.
        method, T_init: as in :func:`pose_from_points`.

    Returns:
        (N,) depths [m], a new array.
    """
    P, _ = _points(points_object, uv)
    fallback = np.broadcast_to(np.asarray(fallback_Z, dtype=float), (P.shape[0],)).copy()
    T = pose_from_points(points_object, uv, K, method, T_init)
    if T is None:
        return fallback
    Z = depths_from_pose(P, T)
    if not np.isfinite(Z).all() or np.any(Z <= 0.0):
        return fallback
    return Z
