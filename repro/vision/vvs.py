"""Pose of a known point model by virtual visual servoing (VVS).

pomares2011 Sec. 5.1, step (1), eqs. (22)-(24): the extrinsic parameters ``M_O^MC`` of the
mini-robot camera (the pose of the object frame ``{o}`` in the camera frame ``{c}``) are
found by servoing a *virtual* camera until the model points, projected with the current
estimate, fall on the measured image points. Same method as ViSP's ``vpPose::poseVirtualVS``
and OpenCV's ``cv2.solvePnPRefineVVS``.

Conventions follow :mod:`repro.sensors.camera` and :mod:`repro.vision.features`:

* ``T_cam_obj`` (4x4) is ``M_O^C``: ``P_cam = T_cam_obj @ P_obj``, lengths in metres.
* Features are *normalised* image coordinates ``x = X / Z``, ``y = Y / Z`` [-] (pomares2011
  eq. (20) with ``f = 1``); measured pixels [px] are converted with
  :meth:`Intrinsics.to_normalized` (eq. (21) inverted). Stacked as ``x1, y1, x2, ...``.
* A twist ``V = (v, w)`` (6,) is linear [m] then angular [rad] (per iteration: the VVS "time"
  step is 1), expressed in the current virtual camera frame ``{c}``.

The iteration (Marchand & Chaumette 2002):

.. math::

    e_v = s(r) - s_{meas}, \\qquad v = -\\lambda L_s^{+} e_v, \\qquad
    T_{obj,cam} \\leftarrow T_{obj,cam} \\exp([v]), \\;\\text{i.e.}\\;
    T_{cam,obj} \\leftarrow \\exp(-[v]) \\, T_{cam,obj}

with ``L_s`` the point interaction matrix (:func:`repro.vision.features.interaction_matrix_points`)
at the projected points ``s(r)`` and their depths ``Z`` under the current estimate: the
virtual camera moves with the twist ``v`` (its pose in the object frame is right-multiplied,
as for any body twist), so the object's pose in the camera frame is left-multiplied by the
inverse. Then ``de_v/dt = L_s v = -lambda e_v`` (eq. (23)-(24); ``lambda_2`` there).

Stopping rule (ViSP ``vpPose::poseVirtualVS``): stop when ``| ||e_{k-1}||^2 - ||e_k||^2 | <
eps`` (normalised units), then -- as ViSP does -- apply the step computed at that last pose;
or after ``max_iter`` steps. Defaults ``lambda = 0.9``, ``eps = 1e-8``, ``max_iter = 200``
(ViSP). The rule is loose: measured with f ~ 1080 px at 0.55-0.8 m from a 5 cm / 10 deg
off start, the defaults stop within ~3 um of the true pose on exact data, but with 0.5 px
noise up to ~1.5e-4 m (4 coplanar points, 10 cm square; ~1e-6 m with 10 points) short of
the least-squares pose, since ``||e||^2`` then levels off at the noise floor while the pose
still moves. ``eps = 1e-20`` reaches the least-squares pose (exact data: ~1e-12 m) in about
twice the iterations (~12).

References:
    E. Marchand and F. Chaumette, "Virtual visual servoing: a framework for real-time
    augmented reality", Computer Graphics Forum 21(3):289-298 (Eurographics), 2002.
    J. Pomares et al., Sensors 11(10), 2011, Sec. 5.1, eqs. (19)-(24).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from repro.sensors.camera import Intrinsics
from repro.vision.features import interaction_matrix_points, skew
from repro.vision.ibvs import require_finite

#: ViSP's defaults (pomares2011_facts.md): gain, stop on the change of ||e||^2 [-], steps.
VVS_GAIN = 0.9
VVS_EPS = 1e-8
VVS_MAX_ITER = 200


class VVSResult(NamedTuple):
    """Outcome of :func:`vvs_pose`.

    Attributes:
        T_cam_obj: 4x4 estimated pose of the object in the camera frame [m]; the last
            iterate (check ``converged`` before using it).
        iterations: pose updates applied [-].
        residual_px: RMS reprojection error of the points at ``T_cam_obj`` [px],
            ``sqrt(sum_i ||uv_i(T) - uv_i||^2 / N)``; ``inf`` if a model point is not in front
            of the camera there.
        converged: True when the stopping rule was met within ``max_iter`` with every model
            point in front of the camera at every iterate. A stationary point is not
            necessarily the global minimum: also check ``residual_px`` against the noise.
        error_norms: ``||e_v||`` [-] (normalised coordinates) at every evaluated pose, the
            start first and ``T_cam_obj`` last (pomares2011 claim: ``e_v -> 0``).
    """

    T_cam_obj: np.ndarray
    iterations: int
    residual_px: float
    converged: bool
    error_norms: np.ndarray


def se3_exp(V: np.ndarray) -> np.ndarray:
    """4x4 ``exp([V])`` of a twist ``V = (v, w)`` (6,), closed form (Rodrigues).

    .. math::

        \\exp\\begin{bmatrix} [w]_\\times & v \\\\ 0 & 0 \\end{bmatrix} =
        \\begin{bmatrix} R & G v \\\\ 0 & 1 \\end{bmatrix}, \\quad
        R = I + a W + b W^2, \\quad G = I + b W + c W^2,

        a = \\frac{\\sin\\theta}{\\theta}, \\quad b = \\frac{1 - \\cos\\theta}{\\theta^2}, \\quad
        c = \\frac{\\theta - \\sin\\theta}{\\theta^3}

    with ``W = [w]_x``, ``theta = ||w||`` [rad]; ``v`` in [m]. For a body twist expressed in
    frame ``b`` held for a unit time, ``T_world_b(t + 1) = T_world_b(t) @ se3_exp(V)``.
    Series expansions below ``theta = 1e-4`` keep full precision near 0.
    """
    V = np.asarray(V, dtype=float).reshape(6)
    v, w = V[:3], V[3:]
    th2 = float(w @ w)
    th = math.sqrt(th2)
    W = skew(w)
    W2 = W @ W
    if th < 1e-4:
        a = 1.0 - th2 / 6.0
        b = 0.5 - th2 / 24.0
        c = 1.0 / 6.0 - th2 / 120.0
    else:
        a = math.sin(th) / th
        b = (1.0 - math.cos(th)) / th2
        c = (th - math.sin(th)) / (th2 * th)
    T = np.eye(4)
    T[:3, :3] = _EYE3 + a * W + b * W2
    T[:3, 3] = (_EYE3 + b * W + c * W2) @ v
    return T


_EYE3 = np.eye(3)
_EYE3.setflags(write=False)


def pinv(a: np.ndarray) -> np.ndarray:
    """``numpy.linalg.pinv(a)`` of a real 2-D array (default cut 1e-15 of the largest
    singular value): numpy's own steps (LAPACK's SVD, the same cut, products and order), to
    the bit, without its wrapper's generality; four per VVS frame at 200 Hz."""
    u, s, vt = np.linalg.svd(a, full_matrices=False)
    large = s > 1e-15 * s.max()
    s = np.divide(1, s, where=large, out=s)
    s[~large] = 0
    return vt.T @ (s[:, None] * u.T)


def project_normalized(points_obj: np.ndarray,
                       T_cam_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised image coordinates and depths of model points (pomares2011 eqs. (19)-(20),
    ``f = 1``).

    .. math:: P^C = T_{cam,obj} P^O, \\qquad (x, y) = (X / Z, Y / Z)

    Args:
        points_obj: (N, 3) model points in the object frame [m].
        T_cam_obj: 4x4 pose of the object in the camera frame [m].

    Returns:
        ``(xy, Z)``: (N, 2) normalised coordinates [-] (NaN rows where ``Z <= 0``: no image)
        and (N,) depths [m].
    """
    P = np.asarray(points_obj, dtype=float)
    T = np.asarray(T_cam_obj, dtype=float)
    P_c = P @ T[:3, :3].T + T[:3, 3]
    Z = P_c[:, 2].copy()
    ok = Z > 0.0
    if ok.all():  # (every point in front: no masking, the same quotients)
        return P_c[:, :2] / Z[:, None], Z
    xy = np.full((P.shape[0], 2), np.nan)
    xy[ok] = P_c[ok, :2] / Z[ok, None]
    return xy, Z


def vvs_error_and_jacobian(points_obj: np.ndarray, xy_measured: np.ndarray,
                           T_cam_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """VVS error ``e_v`` (pomares2011 eq. (22)) and its interaction matrix (eq. (23)).

    .. math::

        e_v = s(T_{cam,obj}) - s_{meas}, \\qquad
        \\frac{d e_v}{d h}\\Big|_{h=0} = L_s V \\;\\text{ for }\\;
        T_{cam,obj}(h) = \\exp(-h [V]) \\, T_{cam,obj}

    i.e. ``L_s`` maps the twist ``V = (v, w)`` of the virtual camera, expressed in the camera
    frame, to the feature rate.

    Args:
        points_obj: (N, 3) model points in the object frame [m].
        xy_measured: (N, 2) measured normalised image coordinates [-].
        T_cam_obj: 4x4 current pose estimate [m].

    Returns:
        ``(e_v (2N,) [-], L_s (2N, 6))``, or None if a model point is not in front of the
        camera (``Z <= 0``) at ``T_cam_obj``.
    """
    xy, Z = project_normalized(points_obj, T_cam_obj)
    if not np.all(Z > 0.0):
        return None
    e = (xy - np.asarray(xy_measured, dtype=float)).ravel()
    return e, interaction_matrix_points(xy, Z)


def vvs_pose(points_obj: np.ndarray, uv: np.ndarray, intrinsics: Intrinsics,
             T_init: np.ndarray, gain: float = VVS_GAIN, eps: float = VVS_EPS,
             max_iter: int = VVS_MAX_ITER) -> VVSResult:
    """Pose of a point model from its image by virtual visual servoing (see module doc).

    pomares2011 eqs. (22)-(24): ``e_v = s_p - s``, ``dr/dt = -lambda_2 L_s^+ e_v``, with
    ``s_p`` the projection of the model under the current estimate ``(M_O^MC)_i``.

    Args:
        points_obj: (N, 3) model points in the object frame [m], N >= 3 (4 or more for a
            unique pose).
        uv: (N, 2) their measured image points [px], same order.
        intrinsics: the camera's intrinsics (pixels -> normalised coordinates).
        T_init: 4x4 initial estimate of ``T_cam_obj`` [m] (e.g. the previous frame's pose).
        gain: ``lambda`` [-] per iteration, in (0, 2) (the linearised error is multiplied by
            ``1 - lambda`` at each step).
        eps: stop when the change of ``||e_v||^2`` (normalised units) between two iterates
            is below this [-], > 0.
        max_iter: at most this many pose updates, >= 1.

    Returns:
        :class:`VVSResult`. A start or an iterate with a model point at ``Z <= 0`` (behind
        the camera: the projection there is the mirror image and the iteration would drift
        to a wrong pose) ends the iteration with ``converged=False`` and ``residual_px=inf``.

    Raises:
        NonFiniteInputError (a ValueError): a non-finite model point, image point (a lost
            feature: pass the found points only), pose, intrinsic or parameter.
        ValueError: malformed shapes, fewer than 3 points, or a parameter out of range.
    """
    P = require_finite("points_obj", points_obj)
    uv = np.asarray(uv, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or uv.shape != (P.shape[0], 2):
        raise ValueError(f"need points_obj (N, 3) and uv (N, 2), got {P.shape} and {uv.shape}")
    if P.shape[0] < 3:
        raise ValueError(f"VVS needs at least 3 points (6 equations), got {P.shape[0]}")
    uv = require_finite("uv", uv)
    T = require_finite("T_init", T_init)
    if T.shape != (4, 4):
        raise ValueError(f"T_init must be 4x4, got shape {T.shape}")
    require_finite("intrinsics K", intrinsics.K())
    gain = float(require_finite("gain", np.asarray(gain)))
    eps = float(require_finite("eps", np.asarray(eps)))
    if not 0.0 < gain < 2.0:
        raise ValueError(f"gain lambda must be in (0, 2), got {gain}")
    if eps <= 0.0:
        raise ValueError(f"eps must be > 0, got {eps}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise ValueError(f"max_iter must be an integer >= 1, got {max_iter!r}")
    xy_meas = intrinsics.to_normalized(uv)

    T = T.copy()
    norms: list[float] = []
    r_prev = math.inf
    iterations = 0
    stop_now = False
    while True:
        ev = vvs_error_and_jacobian(P, xy_meas, T)
        if ev is None:
            return VVSResult(T, iterations, math.inf, False, np.array(norms))
        e, L = ev
        r = float(e @ e)
        norms.append(math.sqrt(r))
        if stop_now:  # the pose after ViSP's final step: report it
            break
        if iterations >= max_iter:
            break
        stop_now = abs(r_prev - r) < eps
        v = -gain * (pinv(L) @ e)  # eq. (24), twist of the virtual camera in {c}
        T = se3_exp(-v) @ T  # T_obj_cam <- T_obj_cam exp([v])
        iterations += 1
        r_prev = r
    xy, _ = project_normalized(P, T)
    res = intrinsics.to_pixels(xy) - uv
    residual_px = math.sqrt(float(np.sum(res * res)) / P.shape[0])
    return VVSResult(T, iterations, residual_px, stop_now, np.array(norms))
