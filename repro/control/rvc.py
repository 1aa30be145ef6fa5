"""Reference Virtual Camera (RVC): eye-in-hand IBVS for an arm that carries no camera.

pomares2011 Sec. 5.1: the camera sits at the end of a mini-robot mounted on the arm (PA-10);
a *virtual* camera, the RVC, is fixed to the arm's end effector, and the arm is servoed on
what the RVC would see. Per control step:

1. the object pose in the real (mini-robot) camera, ``M_O^MC``, by virtual visual servoing
   (:func:`repro.vision.vvs.vvs_pose`, eqs. (22)-(24));
2. the object pose in the RVC, ``M_O^RVC = M_MC^RVC M_O^MC`` (:func:`object_pose_in_rvc`),
   ``M_MC^RVC`` from the mini-robot's forward kinematics;
3. the RVC features ``s_u``: the model's characteristic points ``P_u^O`` projected through
   the RVC, eqs. (19)-(21) (:func:`rvc_features`);
4. the IBVS law (18), ``v^RVC = -lambda L_s^+ (s_u - s_u*)`` (:func:`rvc_velocity`), and the
   arm's joint velocities through the RVC feature Jacobian (:func:`rvc_joint_velocity`).

``s_u*`` is learned once by moving the arm to the goal and doing steps 1-3 there (step (4)
of the paper; :func:`learn_desired_features`).

Frames (``T_a_b``: pose of ``b`` in ``a``, ``P_a = T_a_b @ P_b``, metres):

* ``{o}`` object, ``{mc}`` real camera at the mini-robot end, ``{rvc}`` the virtual camera
  (camera convention of :mod:`repro.sensors.camera`: ``+z`` optical axis, ``+x`` right,
  ``+y`` down), ``{e}`` the arm's end effector (flange) the RVC is rigidly fixed to.
* paper -> code: ``M_O^MC = T_mc_obj``, ``M_MC^RVC = T_rvc_mc``, ``M_O^RVC = T_rvc_obj``.
* Twists ``(v, w)`` (6,): linear [m/s] then angular [rad/s]; ``v_rvc`` is the RVC's twist
  expressed in ``{rvc}`` (:mod:`repro.vision.features`); ``eJ_e`` the flange Jacobian in
  ``{e}`` (pinocchio ``LOCAL``).

Intrinsics of the RVC: the paper projects ``P_u`` with eqs. (20)-(21) and "the camera
intrinsic parameters" ``(f_u, f_v, u_0, v_0)``, the symbols of the real camera (Sec. 7:
640 x 480 px, (u0, v0) = (298, 225) px, (fu, fv) = (1082.3, 1073.7) px), and its ``s_u*``
lie inside a 640 x 480 image: it implies the RVC uses the real camera's intrinsics. Here they
are a parameter; being virtual, the RVC has no image bounds (a point outside the 640 x 480
frame still has features), only ``Z > 0`` is needed. Reading eqs. (20)-(21) as the usual
pinhole model, ``u = u_0 + f_u X / Z`` with ``f_u = f s_x`` in [px] (eq. (20) taken with
``f = 1``: normalised coordinates).

Units of the law (ours): the error of (18) is taken in *normalised* coordinates
``x = (u - u_0) / f_u`` with the classical point interaction matrix at the current points
and their depths in ``{rvc}`` -- all known exactly from ``P_u^RVC``: the RVC has no depth
problem. The paper reports ``s_u``, ``s_u*`` in pixels; with ``f_u != f_v`` a pixel error
with the pixel interaction matrix gives the same law up to a weighting of the two image
axes (identical at first order near the goal).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from repro.errors import SensorError
from repro.geometry import inv_T
from repro.sensors.camera import Intrinsics
from repro.vision.features import interaction_matrix_points, twist_transform
from repro.vision.ibvs import (
    NonFiniteInputError,
    feature_jacobian,
    ibvs_camera_velocity,
    ibvs_joint_velocity,
)
from repro.vision.vvs import (
    VVS_EPS,
    VVS_GAIN,
    VVS_MAX_ITER,
    VVSResult,
    project_normalized,
    vvs_pose,
)


class RVCFeatures(NamedTuple):
    """The features ``s_u`` of the RVC (pomares2011 eqs. (19)-(21)) and their depths.

    Attributes:
        uv: (N, 2) pixel coordinates [px], eq. (21) (the paper's ``s_u``).
        xy: (N, 2) normalised coordinates ``X / Z, Y / Z`` [-], eq. (20) with ``f = 1``.
        Z: (N,) depths of ``P_u`` along the RVC's optical axis [m].
    """

    uv: np.ndarray
    xy: np.ndarray
    Z: np.ndarray


def _pose(name: str, T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4):
        raise ValueError(f"{name} must be 4x4, got shape {T.shape}")
    if not np.isfinite(T).all():
        raise NonFiniteInputError(f"{name} must be finite")
    return T


def rvc_from_mounts(T_e_rvc: np.ndarray, T_e_mc: np.ndarray) -> np.ndarray:
    """``M_MC^RVC = T_rvc_mc``: the real camera's pose in the RVC, from the two mounts.

    .. math:: T_{rvc,mc} = T_{e,rvc}^{-1} \\, T_{e,mc}

    Args:
        T_e_rvc: 4x4 pose of the RVC in the arm's flange frame (a fixed mount we choose) [m].
        T_e_mc: 4x4 pose of the real camera in the flange frame: the mini-robot's base mount
            times its forward kinematics at the current joint angles [m].
    """
    return inv_T(_pose("T_e_rvc", T_e_rvc)) @ _pose("T_e_mc", T_e_mc)


def object_pose_in_rvc(T_rvc_mc: np.ndarray, T_mc_obj: np.ndarray) -> np.ndarray:
    """``M_O^RVC = M_MC^RVC M_O^MC`` (pomares2011 Sec. 5.1, step (2)).

    .. math:: T_{rvc,obj} = T_{rvc,mc} \\, T_{mc,obj}

    Args:
        T_rvc_mc: 4x4 pose of the real (mini-robot) camera in the RVC frame [m]
            (:func:`rvc_from_mounts`).
        T_mc_obj: 4x4 pose of the object in the real camera frame [m] (e.g. by VVS).

    Returns:
        4x4 pose of the object in the RVC frame [m].
    """
    return _pose("T_rvc_mc", T_rvc_mc) @ _pose("T_mc_obj", T_mc_obj)


def rvc_features(intrinsics: Intrinsics, T_rvc_obj: np.ndarray,
                 points_u_obj: np.ndarray) -> RVCFeatures:
    """Project the characteristic points ``P_u`` through the RVC (pomares2011 eqs. (19)-(21)).

    .. math::

        P_u^{RVC} = M_O^{RVC} P_u^O, \\qquad
        (x, y) = \\left(\\frac{X}{Z}, \\frac{Y}{Z}\\right), \\qquad
        (u, v) = (u_0 + f_u x + s\\,y, \\; v_0 + f_v y)

    Args:
        intrinsics: intrinsics of the RVC (pomares2011 implies the real camera's; see the
            module doc). Image bounds are not applied.
        T_rvc_obj: 4x4 pose of the object in the RVC frame [m].
        points_u_obj: (N, 3) characteristic points ``P_u^O`` in the object frame [m].

    Returns:
        :class:`RVCFeatures` ``(uv [px], xy [-], Z [m])``.

    Raises:
        SensorError: a point is not in front of the RVC (``Z <= 0``: no image).
        NonFiniteInputError: a non-finite pose or point.
    """
    T = _pose("T_rvc_obj", T_rvc_obj)
    P = np.asarray(points_u_obj, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points_u_obj must have shape (N, 3), got {P.shape}")
    if not np.isfinite(P).all():
        raise NonFiniteInputError("points_u_obj must be finite")
    xy, Z = project_normalized(P, T)  # eqs. (19)-(20)
    if not np.all(Z > 0.0):
        bad = np.flatnonzero(~(Z > 0.0)).tolist()
        raise SensorError(f"points {bad} of P_u are not in front of the RVC: Z = {Z[bad].tolist()}")
    return RVCFeatures(intrinsics.to_pixels(xy), xy, Z)  # eq. (21)


def learn_desired_features(intrinsics: Intrinsics, T_rvc_obj_goal: np.ndarray,
                           points_u_obj: np.ndarray) -> np.ndarray:
    """``s_u*`` of the learning stage (pomares2011 Sec. 5.1, step (4)) [px].

    The paper moves the arm to the goal and runs steps 1-3 there; whatever the mini-robot's
    pose, the outcome is the projection of ``P_u`` through the RVC at the goal, i.e. a
    function of the object pose in the RVC at the goal only (for a measured ``T_rvc_obj_goal``
    use :func:`estimate_object_pose_in_rvc` at the goal first).

    Args:
        intrinsics: intrinsics of the RVC.
        T_rvc_obj_goal: 4x4 pose of the object in the RVC frame with the arm at the goal [m].
        points_u_obj: (N, 3) characteristic points in the object frame [m].

    Returns:
        (N, 2) desired features ``s_u*`` [px].
    """
    return rvc_features(intrinsics, T_rvc_obj_goal, points_u_obj).uv


def estimate_object_pose_in_rvc(points_p_obj: np.ndarray, uv_mc: np.ndarray,
                                intrinsics_mc: Intrinsics, T_mc_obj_init: np.ndarray,
                                T_rvc_mc: np.ndarray, gain: float = VVS_GAIN,
                                eps: float = VVS_EPS,
                                max_iter: int = VVS_MAX_ITER) -> tuple[np.ndarray, VVSResult]:
    """Steps (1)-(2) of pomares2011 Sec. 5.1: VVS in the real camera, then ``M_O^RVC``.

    Args:
        points_p_obj: (N, 3) model points ``P_p^O`` the real camera sees [m].
        uv_mc: (N, 2) their measured image points in the real camera [px].
        intrinsics_mc: the real camera's intrinsics.
        T_mc_obj_init: 4x4 initial estimate ``(M_O^MC)_i`` [m] (the previous step's).
        T_rvc_mc: 4x4 pose of the real camera in the RVC [m].
        gain, eps, max_iter: as in :func:`repro.vision.vvs.vvs_pose` (ViSP's defaults).

    Returns:
        ``(T_rvc_obj, vvs_result)``; check ``vvs_result.converged`` before using the pose.
    """
    res = vvs_pose(points_p_obj, uv_mc, intrinsics_mc, T_mc_obj_init, gain, eps, max_iter)
    return object_pose_in_rvc(T_rvc_mc, res.T_cam_obj), res


def _error(features: RVCFeatures, uv_star: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    uv_star = np.asarray(uv_star, dtype=float)
    if uv_star.shape != features.xy.shape:
        raise ValueError(f"uv_star must have shape {features.xy.shape}, got {uv_star.shape}")
    if not np.isfinite(uv_star).all():
        raise NonFiniteInputError("uv_star (s_u*) must be finite")
    return np.asarray((features.xy - intrinsics.to_normalized(uv_star)).ravel(), dtype=float)


def rvc_velocity(features: RVCFeatures, uv_star: np.ndarray, intrinsics: Intrinsics,
                 gain: float) -> np.ndarray:
    """(6,) twist of the RVC by the IBVS law (pomares2011 eq. (18)).

    .. math::

        v^{RVC} = -\\lambda L_s^{+} (s_u - s_u^*)

    with the error in normalised coordinates and ``L_s`` the point interaction matrix at the
    current ``s_u`` and depths (see the module doc).

    Args:
        features: current ``s_u`` (:func:`rvc_features`).
        uv_star: (N, 2) desired features ``s_u*`` [px] (:func:`learn_desired_features`).
        intrinsics: intrinsics of the RVC (to normalise ``s_u*``).
        gain: ``lambda`` [1/s], >= 0.

    Returns:
        ``v_rvc`` (6,): ``(v [m/s], w [rad/s])`` of the RVC, expressed in ``{rvc}``.
    """
    L_s = interaction_matrix_points(features.xy, features.Z)
    return ibvs_camera_velocity(L_s, _error(features, uv_star, intrinsics), gain)


def rvc_feature_jacobian(features: RVCFeatures, T_e_rvc: np.ndarray,
                         eJ_e: np.ndarray) -> np.ndarray:
    """(2N, n) Jacobian of the RVC features (normalised) w.r.t. the arm's joints.

    The RVC is rigidly fixed to the flange, and ``M_O^RVC`` does not depend on the
    mini-robot (its motion changes ``M_MC^RVC`` and ``M_O^MC`` but not their product), so
    this is the eye-in-hand Jacobian:

    .. math::

        \\dot s_u = J_s \\dot q, \\qquad
        J_s = L_s \\; {}^{rvc}V_e \\; {}^e J_e, \\qquad
        {}^{rvc}V_e = \\mathrm{twist\\_transform}(T_{e,rvc}^{-1})

    Args:
        features: current ``s_u`` (:func:`rvc_features`).
        T_e_rvc: 4x4 pose of the RVC in the flange frame [m].
        eJ_e: (6, n) flange Jacobian in the flange frame (pinocchio ``LOCAL``).
    """
    L_s = interaction_matrix_points(features.xy, features.Z)
    return feature_jacobian(L_s, twist_transform(inv_T(_pose("T_e_rvc", T_e_rvc))), eJ_e)


def rvc_joint_velocity(features: RVCFeatures, uv_star: np.ndarray, intrinsics: Intrinsics,
                       gain: float, T_e_rvc: np.ndarray, eJ_e: np.ndarray,
                       qd_max: float | np.ndarray | None = None,
                       saturation: str = "clip") -> np.ndarray:
    """(n,) arm joint velocities of the RVC servo: law (18) through the feature Jacobian.

    .. math:: \\dot q = -\\lambda J_s^{+} (s_u - s_u^*)

    (:func:`repro.vision.ibvs.ibvs_joint_velocity` on :func:`rvc_feature_jacobian`). For a
    6-DoF arm away from singularities, ``J_s^+ = ({}^{rvc}V_e {}^eJ_e)^{-1} L_s^+``: the same
    as ``eJ_e^{-1} {}^eV_{rvc} v^{RVC}`` with ``v^{RVC}`` of :func:`rvc_velocity`.

    Args:
        features, uv_star, intrinsics, gain: as in :func:`rvc_velocity`.
        T_e_rvc, eJ_e: as in :func:`rvc_feature_jacobian`.
        qd_max, saturation: optional joint velocity limits [rad/s] and how to respect them
            (:func:`repro.vision.ibvs.saturate`).

    Returns:
        ``qd`` (n,) [rad/s].
    """
    J_s = rvc_feature_jacobian(features, T_e_rvc, eJ_e)
    return ibvs_joint_velocity(J_s, _error(features, uv_star, intrinsics), gain, qd_max,
                               saturation)
