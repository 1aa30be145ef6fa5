"""Image-based visual servoing (IBVS): the feature Jacobian and the classical control law.

One of each for every paper (STYLE.md, habit 7): thomas2024 builds its QP objective on
:func:`feature_jacobian` (eq. (7)); chan2011's IBVS baselines are the classical law, either
:func:`ibvs_camera_velocity` followed by the pseudo-inverse of the camera Jacobian, or
:func:`ibvs_joint_velocity` on ``J_s`` (the same command when the 6x6 camera Jacobian is
invertible), with or without a saturator.

Frames and twists follow :mod:`repro.vision.features`: a twist ``(v, w)`` (6,) is ordered
linear [m/s] then angular [rad/s], expressed in a named frame.

* ``{c}``: camera frame (``+z`` optical axis, ``+x`` right, ``+y`` down in the image).
* ``{e}``: the flange / end-effector frame the camera is rigidly mounted on.
* ``eJ_e`` (6, n): Jacobian of ``{e}`` expressed in ``{e}`` -- pinocchio's ``LOCAL``
  reference frame (``Robot.frame_jacobian(frame, q, "local")``), so that the twist of the
  flange is ``V_e = eJ_e qd`` with ``T_world_e(t + dt) = T_world_e(t) exp(dt [V_e])``.
* ``cV_e`` (6, 6): twist transformation from ``{e}`` to ``{c}``,
  ``twist_transform(T_c_e) = twist_transform(inv_T(T_e_c))`` with ``T_e_c`` the camera mount.

Feature errors ``e = s - s*`` are in the units of the features the interaction matrix was
built for (normalised image coordinates [-] for :func:`interaction_matrix_points`); the gain
``lambda`` is in [1/s], so that ``e`` decays as ``exp(-lambda t)`` near the goal.

References:
    F. Chaumette and S. Hutchinson, "Visual servo control, Part I: Basic approaches", IEEE
    Robotics & Automation Magazine, 13(4):82-90, 2006 -- eq. (3)-(5), the control law
    ``v_c = -lambda L^+ e``.
    F. Chaumette and S. Hutchinson, "Visual servo control, Part II: Advanced approaches",
    IEEE Robotics & Automation Magazine, 14(1):109-118, 2007 -- section on eye-in-hand
    systems controlled in the joint space, ``J_s = L_s cV_e eJ_e``.
"""

from __future__ import annotations

import numpy as np

from repro.control.kernels import finite
from repro.errors import NonFiniteInputError, UnknownChoiceError
from repro.vision.features import interaction_matrix_points

#: Ways :func:`ibvs_joint_velocity` and :func:`saturate` bound a joint velocity vector.
SATURATIONS = ("clip", "scale")


_F64 = np.dtype(float)


def require_finite(name: str, a: np.ndarray) -> np.ndarray:
    """``a`` as a float array; raises :class:`NonFiniteInputError` naming the bad entries."""
    a = np.asarray(a, dtype=float)
    if not finite(a):
        bad = np.argwhere(~np.isfinite(a)).tolist()
        raise NonFiniteInputError(f"{name} must be finite; non-finite entries at {bad}")
    return a


def _matrix(name: str, a: np.ndarray, rows: int | None, cols: int | None) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or (rows is not None and a.shape[0] != rows) or (
            cols is not None and a.shape[1] != cols):
        want = f"({'k' if rows is None else rows}, {'n' if cols is None else cols})"
        raise ValueError(f"{name} must have shape {want}, got {a.shape}")
    return require_finite(name, a)


def _gain(gain: float) -> float:
    g = float(gain)
    if not np.isfinite(g):
        raise NonFiniteInputError(f"gain must be finite, got {gain!r}")
    if g < 0.0:
        raise ValueError(f"gain lambda must be >= 0 [1/s], got {g}")
    return g


def _error(e: np.ndarray, k: int) -> np.ndarray:
    e = np.asarray(e, dtype=float).reshape(-1)
    if e.shape[0] != k:
        raise ValueError(f"error e must have {k} entries (rows of the Jacobian), got {e.shape[0]}")
    return require_finite("error e", e)


def feature_jacobian(L_s: np.ndarray, cV_e: np.ndarray, eJ_e: np.ndarray) -> np.ndarray:
    """(k, n) feature Jacobian of an eye-in-hand camera: features rate per joint velocity.

    thomas2024 eq. (7) (``J_4p = L_x cV_e J``); Chaumette & Hutchinson 2007 (Part II),
    eye-in-hand camera controlled in the joint space:

    .. math::

        \\dot s = J_s \\dot q, \\qquad J_s = L_s \\; {}^c V_e \\; {}^e J_e

    Args:
        L_s: (k, 6) interaction matrix, ``ds/dt = L_s v_c`` for the camera twist ``v_c``
            expressed in ``{c}`` (e.g. :func:`repro.vision.features.interaction_matrix_points`,
            rows ``x1, y1, x2, ...`` in normalised coordinates [-]).
        cV_e: (6, 6) twist transformation from the flange frame ``{e}`` to the camera frame
            ``{c}``: ``twist_transform(T_c_e)``, lengths in metres.
        eJ_e: (6, n) flange Jacobian expressed in ``{e}`` (pinocchio ``LOCAL``; rows
            ``v`` [m/s per joint unit] then ``w`` [rad/s per joint unit]).

    Returns:
        ``J_s`` (k, n): feature units per joint unit (e.g. [1/rad] for revolute joints and
        normalised features).

    Raises:
        ValueError: a shape is wrong.
        NonFiniteInputError: an entry is NaN or inf.
    """
    L_s = _matrix("L_s", L_s, None, 6)
    cV_e = _matrix("cV_e", cV_e, 6, 6)
    eJ_e = _matrix("eJ_e", eJ_e, 6, None)
    return L_s @ (cV_e @ eJ_e)


class PointFeatureJacobian:
    """:func:`feature_jacobian` of the interaction matrix of N points
    (:func:`repro.vision.features.interaction_matrix_points`) for one camera mount ``cV_e``,
    made once for a control loop (thomas2024 eq. (7)): the same two matrix products on
    arrays of the same shapes and layout, hence the same bits, with fewer calls.

    ``cV_e`` is copied (read-only) and checked once here. A call writes ``L_s`` into its own
    buffer in one compiled call (:func:`repro.vision.point_kernels.fill_interaction_matrix`:
    points within bounds that make every entry finite) and checks that ``eJ_e`` is a finite
    (6, n) array; anything else (a lost point's NaN, a non-finite Jacobian, other shapes or
    types) goes through ``feature_jacobian(interaction_matrix_points(xy, Z), cV_e, eJ_e)``,
    which raises what it raises.

    Args:
        cV_e: (6, 6) twist transformation flange -> camera (see :func:`feature_jacobian`).
        n_points: N, the points of every call.
    """

    def __init__(self, cV_e: np.ndarray, n_points: int) -> None:
        from repro.vision.point_kernels import fill_interaction_matrix  # lazy: numba

        self._fill = fill_interaction_matrix
        self.cV_e = np.array(cV_e)  # (a constant of the loop: its checks are made here)
        self.cV_e.flags.writeable = False
        self.n_points = n_points
        self._checked = (self.cV_e.dtype == _F64 and self.cV_e.shape == (6, 6)
                         and finite(self.cV_e))
        self._L = np.empty((2 * n_points, 6))  # L_s, rows x1, y1, x2, ... (C order)

    def __call__(self, xy: np.ndarray, Z: np.ndarray, eJ_e: np.ndarray) -> np.ndarray:
        """``J_s`` (2N, n) for normalised points ``xy`` (N, 2) [-], depths ``Z`` (N,) [m] and
        the flange Jacobian ``eJ_e`` (6, n) (see :func:`feature_jacobian`)."""
        N, L_s = self.n_points, self._L
        if (self._checked and type(xy) is np.ndarray and xy.dtype == _F64
                and xy.shape == (N, 2) and type(Z) is np.ndarray and Z.dtype == _F64
                and Z.shape == (N,) and type(eJ_e) is np.ndarray and eJ_e.dtype == _F64
                and eJ_e.ndim == 2 and eJ_e.shape[0] == 6 and finite(eJ_e)
                and self._fill(xy, Z, L_s)):
            return L_s @ (self.cV_e @ eJ_e)
        return feature_jacobian(interaction_matrix_points(xy, Z), self.cV_e, eJ_e)


def ibvs_camera_velocity(L: np.ndarray, e: np.ndarray, gain: float) -> np.ndarray:
    """(6,) camera twist of the classical IBVS law (Chaumette & Hutchinson 2006, eq. (5)).

    .. math::

        v_c = -\\lambda \\, L^{+} e

    ``L`` is the interaction matrix the controller believes (true or estimated depths, or the
    one at the goal). With ``L`` of full column rank and ``e`` in its range (true near the
    goal) this gives ``de/dt = L v_c = -lambda e``: an exponential decrease of the error.

    Args:
        L: (k, 6) interaction matrix (``k >= 6`` for a unique solution), camera frame.
        e: (k,) feature error ``s - s*`` in the features' units.
        gain: ``lambda`` [1/s], >= 0.

    Returns:
        ``v_c`` (6,): ``(v [m/s], w [rad/s])`` expressed in the camera frame ``{c}``.

    Raises:
        ValueError: a shape is wrong or the gain is negative.
        NonFiniteInputError: ``L``, ``e`` or ``gain`` holds NaN or inf.
    """
    L = _matrix("L", L, None, 6)
    e = _error(e, L.shape[0])
    return -_gain(gain) * (np.linalg.pinv(L) @ e)


def saturate(qd: np.ndarray, qd_max: float | np.ndarray, mode: str = "clip") -> np.ndarray:
    """Bound a joint velocity vector by ``|qd_i| <= qd_max_i`` (a "saturator").

    * ``"clip"``: each joint on its own, ``qd_i <- clip(qd_i, -qd_max_i, qd_max_i)``; joints
      within their limit are unchanged, but the direction of ``qd`` (hence of the
      feature motion) changes as soon as one joint saturates.
    * ``"scale"``: the whole vector uniformly, keeping its direction:

      .. math:: \\dot q \\leftarrow \\dot q \\, \\min\\left(1, \\min_i
                \\frac{\\dot q_{max,i}}{|\\dot q_i|}\\right)

    Args:
        qd: (n,) joint velocities [rad/s or m/s].
        qd_max: scalar or (n,) velocity limits, > 0, same units.
        mode: one of :data:`SATURATIONS`.

    Returns:
        (n,) bounded joint velocities.
    """
    if mode not in SATURATIONS:
        raise UnknownChoiceError("saturation", mode, SATURATIONS)
    qd = require_finite("qd", np.asarray(qd, dtype=float).reshape(-1))
    lim = require_finite("qd_max", np.broadcast_to(np.asarray(qd_max, dtype=float), qd.shape))
    if np.any(lim <= 0.0):
        raise ValueError(f"qd_max must be > 0, got {lim.tolist()}")
    if mode == "clip":
        return np.clip(qd, -lim, lim)
    ratio = np.max(np.abs(qd) / lim) if qd.size else 0.0
    return qd / ratio if ratio > 1.0 else qd.copy()


def ibvs_joint_velocity(J_s: np.ndarray, e: np.ndarray, gain: float,
                        qd_max: float | np.ndarray | None = None,
                        saturation: str = "clip") -> np.ndarray:
    """(n,) joint velocities of the classical IBVS law on the feature Jacobian.

    .. math::

        \\dot q = -\\lambda \\, J_s^{+} e, \\qquad J_s = L_s \\, {}^c V_e \\, {}^e J_e

    (Chaumette & Hutchinson 2006, eq. (5), with the joint-space Jacobian of Part II 2007;
    chan2011's IBVS baseline.) For ``J_s`` of full row rank (``n >= k``; the pseudo-inverse
    picks the minimum-norm joint velocity) ``de/dt = -lambda e`` exactly; for a redundant
    set of features (``k > n``) at first order near the goal.

    Args:
        J_s: (k, n) feature Jacobian (:func:`feature_jacobian`).
        e: (k,) feature error ``s - s*``.
        gain: ``lambda`` [1/s], >= 0.
        qd_max: None (no saturator) or the velocity limits, scalar or (n,), > 0
            [rad/s or m/s per joint].
        saturation: how to respect ``qd_max`` (see :func:`saturate`): ``"clip"`` each joint
            (chan2011's "saturated IBVS"), or ``"scale"`` the whole vector, which keeps the
            direction of ``J_s^+ e`` and slows the servo down instead.

    Returns:
        ``qd`` (n,) joint velocities [rad/s or m/s].

    Raises:
        ValueError: a shape is wrong, the gain is negative or a limit is not > 0.
        UnknownChoiceError: ``saturation`` is not one of :data:`SATURATIONS`.
        NonFiniteInputError: an input holds NaN or inf.
    """
    if saturation not in SATURATIONS:
        raise UnknownChoiceError("saturation", saturation, SATURATIONS)
    J_s = _matrix("J_s", J_s, None, None)
    e = _error(e, J_s.shape[0])
    qd = -_gain(gain) * (np.linalg.pinv(J_s) @ e)
    if qd_max is None:
        return qd
    return saturate(qd, qd_max, saturation)
