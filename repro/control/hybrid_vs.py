r"""Direct (torque-level) hybrid visual servoing of pomares2011 (Secs. 3-4).

The mini-robot controller of pomares2011: an image-based primary task ``e1`` and a
human-avoidance secondary task ``e2`` combined in one task function ``e`` in the space of
the camera pose ``r`` (Sec. 3.1), regulated by a Jacobian-transpose torque law with
gravity compensation (Sec. 3.2):

.. math::

    e_s &= s^* - s,\qquad e_1 = B\,e_s,\qquad B = W L_s^T                      && (1),(2)\\
    e &= W^+ e_1 - (I_6 - W^+ W)\Big(\frac{\partial e_2}{\partial r}\Big)^T && (3)^{ours}\\
    \tau &= K_P J_g^T e + \tau_{ff} - K_v \dot q + G(q)                           && (5)\\
    J &= L_s J_g                                                                   && (6)\\
    V &= \tfrac12 \dot q^T M(q) \dot q + \tfrac12 e_s^T K_P e_s                   && (10)\\
    e_2 &= \alpha\,(1 - dist/d_{min}) \text{ if } dist < d_{min}, \text{ else } 0  && (17)

Frames and units (as :mod:`repro.vision.features`): the camera frame ``{c}`` has ``+z``
along the optical axis, ``+x`` right, ``+y`` down; a camera twist ``v_c = (v, w)`` is
expressed in ``{c}`` (linear [m/s] then angular [rad/s]); ``L_s`` (k, 6) gives
``ds/dt = L_s v_c``; ``J_g`` (6, n) gives ``v_c = J_g qd`` (pinocchio ``LOCAL`` Jacobian of
the camera frame, or ``cV_e eJ_e``). The features ``s`` may be pixels [px] (the paper's
unit) or normalised coordinates [-], as long as ``s``, ``s*`` and ``L_s`` agree; the units
of ``K_P`` follow (pixels: ``[N m rad / px^2]`` for revolute joints).

Readings we had to make (each marked ``# ours:`` at the code):

* The paper writes ``K_P`` (n x n) both in joint space, eq. (5), and in feature space,
  eq. (10), where ``e_s`` has k entries; the cancellation in eq. (15),
  ``qd^T K_P J^T e_s - e_s^T K_P J qd = 0``, holds only for ``K_P = k_P I``. We take
  ``K_P = k_P I`` (a scalar ``k_P > 0``); ``K_v`` is any symmetric positive-definite matrix.
* Sign of the secondary term in (3): with ``e_1 = B (s* - s)`` and ``tau = +K_P J_g^T e``,
  the primary term ``L_s^T (s* - s)`` is the *negative* gradient of ``1/2 |s - s*|^2``; the
  paper's ``+(I - W^+W)(de2/dr)^T`` would climb ``e2`` (towards the human), contradicting
  Sec. 4 ("this task moves the mini-robot away from the human"). We use ``-(de2/dr)^T``,
  the form of Espiau/Samson's task function once the sign of ``e_1`` is flipped.
* ``W`` (Sec. 3.1): its rows are an orthonormal basis of the row space of the primary-task
  rows of ``L_s`` (SVD), so ``W^+ = W^T``. Then ``W^+ B e_s = W^+ W L_s^T e_s = L_s^T e_s``
  (``L_s^T e_s`` already lies in that row space): ``W`` only decides the projector
  ``I - W^+ W`` left to the secondary task. Four points (k = 8) and a 6-DoF camera give
  rank 6: ``W^+ W = I_6`` and ``e2`` has no effect (experiment 1, the CRS-A465 with 4 points
  included). For ``e2`` to act, the primary task must keep fewer rows: experiment 2 keeps
  one image coordinate (pomares2011 Sec. 7.2's "f*_1py = 272 px"; the suite holds f2y,
  row 3, see experiments/pomares2011/scene.py), rank 1, a 5-dimensional null space for
  ``e2``.
* When the reduced primary task applies: whenever the secondary task is active
  (``dist < d_min``); otherwise all rows (the paper: after the human leaves, "only the
  primary task is employed"). ``e_s`` in ``V`` (10) is the error of the rows in use.
* ``de2/dr``: the paper gives no formula. ``dist`` is the distance between the robot's and
  the human's closest points; we treat the robot's closest point ``p`` as fixed to the
  camera frame (exact for a point on the camera or last link) so that
  ``d(dist)/dt = n^T (v + w x p) = [n^T, (p x n)^T] v_c`` with ``n`` the unit vector from
  the human's to the robot's closest point (camera axes): :func:`distance_gradient`.
* The feed-forward terms of (5), ``J_g^T W^+ de1_hat/dt - J_g^T (I - W^+W) dGr(e2)/dt``,
  vanish for a static scene (the paper's assumption (1) and all its experiments); the hook
  ``tau_ff`` of :meth:`HybridVSController.step` takes them precomputed (the estimation of
  the target motion, the paper's ref. [27], is not implemented).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from repro.control.kernels import finite
from repro.errors import ConfigError

__all__ = ["Gains", "HybridVSConfig", "HybridVSController", "distance_gradient",
           "distance_gradient_from_joints",
           "gains_from_inertia", "hybrid_torque", "lyapunov", "primary_task",
           "secondary_task", "task_function", "task_jacobian", "weight_matrix"]

#: Dimension of the camera pose ``r`` (and of a camera twist): the paper's ``n`` in (3).
N_R = 6


def _matrix(name: str, a: np.ndarray, shape: tuple[int | None, int | None]) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or any(want is not None and got != want
                          for got, want in zip(a.shape, shape, strict=True)):
        raise ValueError(f"{name} must have shape {shape} (None: any), got {a.shape}")
    if not finite(a):
        raise ValueError(f"{name} must be finite; non-finite entries at "
                         f"{np.argwhere(~np.isfinite(a)).tolist()}")
    return a


def _vector(name: str, a: np.ndarray, n: int) -> np.ndarray:
    a = np.asarray(a, dtype=float).reshape(-1)
    if a.shape != (n,):
        raise ValueError(f"{name} must have {n} entries, got {a.shape[0]}")
    if not finite(a):
        raise ValueError(f"{name} must be finite, got {a.tolist()}")
    return a


# ----------------------------------------------------------------------------- Sec. 3.1
def weight_matrix(L_s: np.ndarray, rows: Sequence[int] | None = None,
                  rank_tol: float = 1e-9) -> np.ndarray:
    """pomares2011 Sec. 3.1: ``W`` (m, 6), rows = an orthonormal basis of the row space of
    the primary-task rows of ``L_s``.

    ``W`` has the kernel of ``L_s[rows]`` and full rank ``m = rank(L_s[rows])``; its rows
    are orthonormal, so ``W^+ = W^T`` and ``W^+ W`` is the orthogonal projector onto that
    row space (``= I_6`` when ``m = 6``, e.g. 4 points in general position).

    Args:
        L_s: (k, 6) interaction matrix, rows ``x1, y1, x2, ...`` (any consistent units).
        rows: indices of the rows of ``L_s`` the primary task keeps (None: all), e.g.
            ``(1,)`` for ``y1`` alone.
        rank_tol: singular values below ``rank_tol * sigma_max`` count as zero.

    Returns:
        ``W`` (m, 6).
    """
    L = _matrix("L_s", L_s, (None, N_R))
    if rows is not None:
        L = L[list(rows)]
    _, sigma, Vt = np.linalg.svd(L, full_matrices=False)
    if sigma.size == 0 or sigma[0] == 0.0:
        raise ValueError("the primary-task rows of L_s are all zero: no DoF to servo")
    m = int(np.sum(sigma > rank_tol * sigma[0]))
    return Vt[:m]


def primary_task(W: np.ndarray, L_s: np.ndarray, e_s: np.ndarray) -> np.ndarray:
    """pomares2011 eqs. (1)-(2): ``e1 = B e_s`` (m,), ``B = W L_s^T``, ``e_s = s* - s``.

    Args:
        W: (m, 6) from :func:`weight_matrix` (same rows of ``L_s``).
        L_s: (k, 6) interaction matrix of the primary-task rows.
        e_s: (k,) ``s* - s`` of those rows, in the units of ``L_s``.
    """
    L = _matrix("L_s", L_s, (None, N_R))
    W = _matrix("W", W, (None, N_R))
    return W @ (L.T @ _vector("e_s", e_s, L.shape[0]))  # B e_s, B = W L_s^T


def task_function(W: np.ndarray, e1: np.ndarray, de2_dr: np.ndarray | None = None
                  ) -> np.ndarray:
    """pomares2011 eq. (3): the hybrid task function ``e`` (6,), camera-twist space.

    .. math::

        e = W^+ e_1 - (I_6 - W^+ W) \\Big(\\frac{\\partial e_2}{\\partial r}\\Big)^T

    Args:
        W: (m, 6) with orthonormal rows (:func:`weight_matrix`), so ``W^+ = W^T``.
        e1: (m,) primary task (:func:`primary_task`).
        de2_dr: (6,) gradient of ``e2`` w.r.t. the camera pose (:func:`secondary_task`);
            None: no secondary task.
    """
    W = _matrix("W", W, (None, N_R))
    W_pinv = W.T  # orthonormal rows: W^+ = W^T
    e = W_pinv @ _vector("e1", e1, W.shape[0])
    if de2_dr is not None:
        P_null = np.eye(N_R) - W_pinv @ W  # projector onto the kernel of W
        # ours: minus sign (see the module docstring): the secondary term descends e2.
        e = e - P_null @ _vector("de2_dr", de2_dr, N_R)
    return e


# ----------------------------------------------------------------------------- Sec. 3.2
def task_jacobian(L_s: np.ndarray, J_g: np.ndarray) -> np.ndarray:
    """pomares2011 eq. (6): ``J = L_s J_g`` (k, n), ``ds/dt = J qd``.

    Args:
        L_s: (k, 6) interaction matrix (camera twist in ``{c}`` -> feature rates).
        J_g: (6, n) geometric Jacobian of the camera frame, eq. (7): ``v_c = J_g qd``,
            expressed in ``{c}``.
    """
    return _matrix("L_s", L_s, (None, N_R)) @ _matrix("J_g", J_g, (N_R, None))


def hybrid_torque(k_P: float, J_g: np.ndarray, e: np.ndarray, K_v: np.ndarray,
                  qd: np.ndarray, G: np.ndarray, tau_ff: np.ndarray | None = None
                  ) -> np.ndarray:
    """pomares2011 eq. (5): joint torques [N m] of the direct hybrid controller.

    .. math::

        \\tau = K_P J_g^T e + \\tau_{ff} - K_v \\dot q + G(q), \\qquad K_P = k_P I

    Args:
        k_P: proportional gain (``K_P = k_P I``, see the module docstring).
        J_g: (6, n) camera Jacobian in ``{c}``.
        e: (6,) task function (:func:`task_function`).
        K_v: (n, n) derivative gain, symmetric positive definite [N m s/rad].
        qd: (n,) joint velocities [rad/s].
        G: (n,) gravity torques at ``q`` [N m].
        tau_ff: (n,) the feed-forward terms of (5) for a moving target, ``J_g^T W^+
            de1_hat/dt - J_g^T (I - W^+W) dGr(e2)/dt`` [N m]; None: static scene (zero).
    """
    J_g = _matrix("J_g", J_g, (N_R, None))
    n = J_g.shape[1]
    tau = k_P * (J_g.T @ _vector("e", e, N_R)) - _matrix("K_v", K_v, (n, n)) @ _vector(
        "qd", qd, n) + _vector("G", G, n)
    if tau_ff is not None:
        tau = tau + _vector("tau_ff", tau_ff, n)
    return tau


def lyapunov(qd: np.ndarray, M: np.ndarray, e_s: np.ndarray, k_P: float) -> float:
    """pomares2011 eq. (10): ``V = 1/2 qd^T M(q) qd + 1/2 e_s^T K_P e_s``, ``K_P = k_P I``.

    Kinetic energy [J] plus the image potential ``k_P |s* - s|^2 / 2`` [J]. Along the
    undisturbed closed loop (static scene, ``W^+W = I``, torques unsaturated) eq. (15)
    gives ``dV/dt = -qd^T K_v qd <= 0``.

    Args:
        qd: (n,) joint velocities [rad/s].
        M: (n, n) joint-space inertia matrix at ``q`` [kg m^2] (pinocchio ``crba``).
        e_s: (k,) ``s* - s`` of the primary-task rows, units of ``L_s``.
        k_P: the proportional gain of (5).
    """
    qd = np.asarray(qd, dtype=float).reshape(-1)
    M = _matrix("M", M, (qd.size, qd.size))
    e_s = np.asarray(e_s, dtype=float).reshape(-1)
    return float(0.5 * qd @ M @ qd + 0.5 * k_P * (e_s @ e_s))


class Gains(NamedTuple):
    """Gains of (5): ``K_P = k_P I`` and ``K_v`` (n, n) [N m s/rad]."""

    k_P: float
    K_v: np.ndarray


def gains_from_inertia(M: np.ndarray, J: np.ndarray, omega_max: float, zeta: float = 1.0,
                       floor: float = 1e-6) -> Gains:
    """Our tuning rule for ``K_P``, ``K_v`` relative to the robot's inertia (the paper: the
    gains "are estimated by the user").

    Linearised about a configuration ``q0`` (static scene, all rows, gravity compensated),
    the closed loop of (5) is ``M dq'' + K_v dq' + k_P J^T J dq = 0``. We choose

    .. math::

        k_P = \\frac{\\omega_{max}^2}{\\lambda_{max}(M^{-1} J^T J)}, \\qquad
        K_v = 2 \\zeta\\, M^{1/2} \\big(M^{-1/2} k_P J^T J M^{-1/2}\\big)^{1/2} M^{1/2}

    so that the fastest mode of that linearisation has natural frequency ``omega_max`` (keep
    ``omega_max * dt << 1``: well inside the stability of the 1 kHz loop, and the torques of
    the light wrist stay bounded) and *every* mode has damping ratio ``zeta``. ``K_v`` is
    symmetric positive definite: modes ``J`` does not see (eigenvalues of
    ``M^{-1/2} J^T J M^{-1/2}`` below ``floor * lambda_max``) are damped as if they had
    that floor.

    Args:
        M: (n, n) inertia matrix at ``q0`` [kg m^2].
        J: (k, n) task Jacobian (6) at ``q0``, in the feature units of the controller.
        omega_max: natural frequency of the fastest mode [rad/s].
        zeta: damping ratio of every mode [-].
        floor: relative eigenvalue floor [-].
    """
    if not (omega_max > 0 and zeta > 0 and 0 < floor < 1):
        raise ConfigError(f"need omega_max > 0, zeta > 0, 0 < floor < 1; got "
                          f"omega_max={omega_max}, zeta={zeta}, floor={floor}")
    J = _matrix("J", J, (None, None))
    n = J.shape[1]
    M = _matrix("M", M, (n, n))
    d, Q = np.linalg.eigh(0.5 * (M + M.T))
    if d.min() <= 0:
        raise ConfigError(f"M must be positive definite, eigenvalues {d.tolist()}")
    M_half = Q @ np.diag(np.sqrt(d)) @ Q.T
    M_mhalf = Q @ np.diag(1.0 / np.sqrt(d)) @ Q.T
    A = M_mhalf @ (J.T @ J) @ M_mhalf  # eigenvalues of M^-1 J^T J
    lam, U = np.linalg.eigh(0.5 * (A + A.T))
    if lam[-1] <= 0:
        raise ConfigError("J is zero: the primary task sees no joint")
    k_P = omega_max**2 / lam[-1]
    omega = np.sqrt(k_P * np.maximum(lam, floor * lam[-1]))  # modal frequencies [rad/s]
    K_v = 2.0 * zeta * M_half @ U @ np.diag(omega) @ U.T @ M_half
    return Gains(float(k_P), 0.5 * (K_v + K_v.T))


#: Sample rate over closed-loop bandwidth of a digital loop that should behave like its
#: continuous design (Franklin, Powell & Workman, Digital Control of Dynamic Systems, 3rd ed.,
#: Sec. 11.3: 20-40x for a smooth response; we take the least, 20).
SAMPLES_PER_MODE = 20.0


def sampled_loop_omega(sample_rate_hz: float, ratio: float = SAMPLES_PER_MODE) -> float:
    """The fastest mode [rad/s] a loop fed at ``sample_rate_hz`` should be given:
    ``2 pi f / ratio``."""
    if not (sample_rate_hz > 0 and ratio > 0):
        raise ConfigError(f"need sample_rate_hz > 0 and ratio > 0, got {sample_rate_hz}, {ratio}")
    return 2.0 * np.pi * sample_rate_hz / ratio


def torque_bounded_omega(tau_unit: np.ndarray, G: np.ndarray, tau_max: np.ndarray) -> float:
    """The largest ``omega`` [rad/s] with ``|omega^2 tau_unit + G| <= tau_max`` in every joint:
    the fastest mode whose first command, at rest, stays inside the drive's torque limits.
    ``tau_unit``: the task torque of (5) at rest with the gains of ``omega = 1 rad/s``
    (:func:`gains_from_inertia`; it scales with ``omega^2``) [N m]; ``G`` the gravity
    torques [N m]. inf when no joint is loaded by the task.

    Raises:
        ConfigError: gravity alone exceeds a limit.
    """
    a, g, lim = (np.asarray(x, dtype=float) for x in (tau_unit, G, tau_max))
    if np.any(np.abs(g) > lim):
        raise ConfigError(f"gravity torques {g.tolist()} exceed the limits {lim.tolist()}")
    w2 = np.inf
    for ai, gi, li in zip(a, g, lim, strict=True):
        if ai != 0.0:
            w2 = min(w2, (li - np.sign(ai) * gi) / abs(ai))
    return float(np.sqrt(w2))


# ----------------------------------------------------------------------------- Sec. 4
def distance_gradient(p_c: np.ndarray, n_c: np.ndarray) -> np.ndarray:
    """``d(dist)/dr`` (6,): rate of the human-robot distance per camera twist.

    .. math::

        \\dot{dist} = n^T (v + \\omega \\times p) = [n^T, (p \\times n)^T]\\, v_c

    # ours: the robot's closest point ``p`` is taken as fixed to the camera frame (the
    paper does not say how it differentiates ``dist``).

    Args:
        p_c: (3,) the robot's closest point, camera frame [m].
        n_c: (3,) unit vector from the human's closest point to the robot's, camera axes.
    """
    p = _vector("p_c", p_c, 3)
    n = _vector("n_c", n_c, 3)
    norm = np.linalg.norm(n)
    if not abs(norm - 1.0) < 1e-6:
        raise ValueError(f"n_c must be a unit vector, got norm {norm}")
    return np.concatenate([n, np.cross(p, n)])


def distance_gradient_from_joints(J_g: np.ndarray, J_p: np.ndarray, n: np.ndarray,
                                  rank_tol: float = 1e-9) -> np.ndarray:
    """``d(dist)/dr`` (6,) consistent with the joints, for a closest point on *any* link.

    :func:`distance_gradient` assumes the robot's closest point moves with the camera; on a
    link before the camera (a mini-robot's second link) that assumption invents a lever arm
    and a torque on joints that do not move the point. Here the exact joint gradient
    ``g_q = J_p^T n`` (n,) (``J_p``: the point's linear Jacobian, ``n``: the unit vector from
    the human's closest point to the robot's, both in one frame) is mapped to the camera-twist
    space through the least-squares inverse of ``J_g``:

    .. math::

        g_r = J_g (J_g^T J_g)^{+} g_q, \\qquad g_r^T (J_g \\dot q) = g_q^T \\dot q
        = \\dot{dist}

    (``J_g`` of full column rank n <= 6: ``J_g^T g_r = g_q``). # ours: the paper does not
    say how it differentiates ``dist``; this is the minimum-norm twist-space gradient that
    gives the true rate of ``dist`` along every motion the robot can make.

    Args:
        J_g: (6, n) camera Jacobian in ``{c}`` (eq. 7).
        J_p: (3, n) linear Jacobian of the robot's closest point [m/rad], axes of ``{c}``.
        n: (3,) unit vector from the human's closest point to the robot's, axes of ``{c}``.
        rank_tol: relative singular-value cut of the pseudo-inverse.
    """
    J_g = _matrix("J_g", J_g, (N_R, None))
    J_p = _matrix("J_p", J_p, (3, J_g.shape[1]))
    n = _vector("n", n, 3)
    if not abs(np.linalg.norm(n) - 1.0) < 1e-6:
        raise ValueError(f"n must be a unit vector, got norm {np.linalg.norm(n)}")
    g_q = J_p.T @ n
    return np.asarray(J_g @ np.linalg.pinv(J_g.T @ J_g, rcond=rank_tol) @ g_q)


def secondary_task(dist: float, grad_dist: np.ndarray, alpha: float, dmin: float
                   ) -> tuple[float, np.ndarray]:
    """pomares2011 eq. (17): ``e2 = alpha (1 - dist/dmin)`` if ``dist < dmin``, else 0,
    and its gradient w.r.t. the camera pose ``de2/dr = -(alpha/dmin) d(dist)/dr``.

    ``e2`` is continuous (0 at ``dist = dmin``); its gradient jumps there from 0 to
    ``-(alpha/dmin) grad_dist``.

    Args:
        dist: human-robot distance [m].
        grad_dist: (6,) ``d(dist)/dr`` (:func:`distance_gradient`) [m per camera-twist unit].
        alpha: gain, > 0 (units of ``e``: [px^2] when the features are in pixels).
        dmin: distance below which the task acts [m], > 0.

    Returns:
        ``(e2, de2_dr)``: the cost and its (6,) gradient.
    """
    g = _vector("grad_dist", grad_dist, N_R)
    if dist < dmin:
        return alpha * (1.0 - dist / dmin), -(alpha / dmin) * g
    return 0.0, np.zeros(N_R)


# ----------------------------------------------------------------------------- controller
@dataclass(frozen=True)
class HybridVSConfig:
    """Parameters of the direct hybrid controller.

    Attributes:
        s_star: (k,) desired features ``s*``, rows ``x1, y1, x2, ...`` (units of ``L_s``;
            the paper: pixels).
        k_P: proportional gain, ``K_P = k_P I`` (units: [N m rad / px^2] with pixels);
            ours, see :func:`gains_from_inertia`.
        K_v: (n, n) or (n,) (diagonal) derivative gain, symmetric positive definite
            [N m s/rad]; ours, see :func:`gains_from_inertia`.
        alpha: gain of (17) (units of ``e``), > 0; ours. A rule: ``alpha = F * dmin / k_P``
            pushes the closest point away with a virtual force ``F`` [N] at contact.
        dmin: threshold of (17) [m], > 0; ours.
        avoid_rows: rows of ``s`` the primary task keeps while the secondary task is active
            (default ``(1,)``, ``y1`` alone; pomares2011 experiment 2 passes its own); None:
            all rows (then ``W^+W = I`` and ``e2`` cannot act).
        K_v_active: (n, n) derivative gain used instead of ``K_v`` while the secondary task
            is active [N m s/rad]; None: ``K_v``. ours: ``K_v`` of
            :func:`gains_from_inertia` damps each visual mode in proportion to its
            stiffness, so the directions the reduced primary task no longer holds (the
            null space the secondary task moves in) are barely damped and a constant push
            accelerates them without bound; a stronger damping there is any SPD ``K_v``,
            so (15) still holds.
    """

    s_star: np.ndarray
    k_P: float
    K_v: np.ndarray
    alpha: float
    dmin: float
    avoid_rows: tuple[int, ...] | None = (1,)
    K_v_active: np.ndarray | None = None
    rank_tol: float = field(default=1e-9)

    def __post_init__(self) -> None:
        s_star = np.asarray(self.s_star, dtype=float).reshape(-1)
        if not np.isfinite(s_star).all():
            raise ConfigError(f"s_star must be finite, got {s_star.tolist()}")
        K_v = np.asarray(self.K_v, dtype=float)
        K_v = np.diag(K_v) if K_v.ndim == 1 else K_v
        if K_v.ndim != 2 or K_v.shape[0] != K_v.shape[1] or not np.allclose(K_v, K_v.T):
            raise ConfigError(f"K_v must be a symmetric (n, n) matrix or (n,), got {K_v}")
        if np.linalg.eigvalsh(K_v).min() <= 0:
            raise ConfigError(f"K_v must be positive definite, eigenvalues "
                              f"{np.linalg.eigvalsh(K_v).tolist()}")
        for name in ("k_P", "alpha", "dmin"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"{name} must be finite and > 0, got {v!r}")
        if self.avoid_rows is not None and (
                not self.avoid_rows or min(self.avoid_rows) < 0
                or max(self.avoid_rows) >= s_star.size):
            raise ConfigError(f"avoid_rows must be non-empty indices into s* (0.."
                              f"{s_star.size - 1}), got {self.avoid_rows}")
        object.__setattr__(self, "s_star", s_star)
        object.__setattr__(self, "K_v", K_v)
        if self.K_v_active is not None:
            Ka = np.asarray(self.K_v_active, dtype=float)
            if Ka.shape != K_v.shape or not np.allclose(Ka, Ka.T) or (
                    np.linalg.eigvalsh(Ka).min() <= 0):
                raise ConfigError(f"K_v_active must be a symmetric positive-definite "
                                  f"{K_v.shape} matrix, got {Ka}")
            object.__setattr__(self, "K_v_active", Ka)


class HybridVSController:
    """The direct hybrid visual servoing controller of pomares2011 (eqs. (1)-(17)).

    Plain arrays in, joint torques out; no simulator inside. One call per control step
    (the torque is meant to be applied at the physics rate, pomares2011: 1 kHz here).
    """

    def __init__(self, config: HybridVSConfig) -> None:
        self.config = config
        #: ``W`` of the last (L_s, rows): between camera frames the features, and so L_s,
        #: are held, and the SVD of Sec. 3.1 would give the same W again
        self._W_memo: tuple[bytes, tuple[int, ...], np.ndarray] | None = None
        #: (e_s, W, e1) of eqs. (1)-(2) for the last bit-identical (s, L_s, rows), and e of
        #: (3) without the secondary task (None until asked): the same between frames
        self._primary_memo: tuple[tuple[Any, ...],
                                  tuple[np.ndarray, np.ndarray, np.ndarray],
                                  np.ndarray | None] | None = None

    def _weight_matrix(self, L_s: np.ndarray, rows: list[int]) -> np.ndarray:
        """:func:`weight_matrix` of ``L_s[rows]``, memoised on the last bit-identical input."""
        key, r = L_s.tobytes(), tuple(rows)
        memo = self._W_memo
        if memo is not None and memo[0] == key and memo[1] == r:
            return memo[2]
        W = weight_matrix(L_s, rows, self.config.rank_tol)
        self._W_memo = (key, r, W)
        return W

    def damping(self, active: bool) -> np.ndarray:
        """``K_v`` of (5): ``K_v_active`` while the secondary task acts (if given)."""
        cfg = self.config
        return cfg.K_v_active if (active and cfg.K_v_active is not None) else cfg.K_v

    def step(self, q: np.ndarray, qd: np.ndarray, s: np.ndarray, L_s: np.ndarray,
             J_g: np.ndarray, G: np.ndarray, M: np.ndarray | None, dist: float | None = None,
             grad_dist: np.ndarray | None = None, *, tau_ff: np.ndarray | None = None
             ) -> tuple[np.ndarray, dict[str, Any]]:
        """Joint torques of eq. (5) and the diagnostics to log.

        Args:
            q: (n,) joint positions [rad] (``J_g``, ``G``, ``M`` must be evaluated there).
            qd: (n,) joint velocities [rad/s].
            s: (k,) measured features, rows ``x1, y1, ...`` (units of ``L_s``).
            L_s: (k, 6) interaction matrix at ``s`` (current depths).
            J_g: (6, n) camera Jacobian in ``{c}``, eq. (7).
            G: (n,) gravity torques ``G(q)`` [N m].
            M: (n, n) inertia matrix ``M(q)`` [kg m^2] (only for ``V``); None: ``V`` is
                not computed (NaN; a caller that logs ``V`` only on some steps computes it
                there with :func:`lyapunov` and ``diag["e_s"]``).
            dist: human-robot distance [m]; None: no human tracked.
            grad_dist: (6,) ``d(dist)/dr`` (:func:`distance_gradient`); needed when
                ``dist < dmin``.
            tau_ff: feed-forward hook of (5) for a moving target [N m]; None: static scene.

        Returns:
            ``(tau, diag)``: ``tau`` (n,) [N m]; ``diag`` with ``e`` (6,), ``e_s`` (rows in
            use), ``e1``, ``V`` (10) [J], ``e2`` (17), ``active`` (secondary task on),
            ``m`` (rank of ``W``) and ``rows`` (primary-task rows).
        """
        cfg = self.config
        k = cfg.s_star.size
        n = cfg.K_v.shape[0]
        _vector("q", q, n)
        s = np.asarray(s, dtype=float)
        L_s = np.asarray(L_s, dtype=float)
        active = dist is not None and dist < cfg.dmin
        rows = list(cfg.avoid_rows) if (active and cfg.avoid_rows is not None) else list(
            range(k))
        key = (s.shape, s.tobytes(), L_s.shape, L_s.tobytes(), tuple(rows))
        memo = self._primary_memo
        if memo is None or memo[0] != key:  # (the features are held between camera frames)
            s = _vector("s", s, k)
            L_s = _matrix("L_s", L_s, (k, N_R))
            e_s = cfg.s_star[rows] - s[rows]  # eq. (1): e_s = s* - s
            W = self._weight_matrix(L_s, rows)  # Sec. 3.1
            e1 = primary_task(W, L_s[rows], e_s)  # eqs. (1)-(2)
            memo = self._primary_memo = (key, (e_s, W, e1), None)
        e_s, W, e1 = memo[1]
        e2, de2_dr = 0.0, None
        if active:
            assert dist is not None
            if grad_dist is None:
                raise ValueError(f"dist = {dist} m < dmin = {cfg.dmin} m needs grad_dist")
            e2, de2_dr = secondary_task(dist, grad_dist, cfg.alpha, cfg.dmin)  # eq. (17)
            e = task_function(W, e1, de2_dr)  # eq. (3)
        else:
            e_memo = memo[2]
            if e_memo is None:
                e_memo = task_function(W, e1, None)  # eq. (3)
                self._primary_memo = (key, memo[1], e_memo)
            e = e_memo
        tau = hybrid_torque(cfg.k_P, J_g, e, self.damping(active), qd, G, tau_ff)  # eq. (5)
        V = math.nan if M is None else lyapunov(qd, M, e_s, cfg.k_P)  # eq. (10)
        return tau, {"e": e, "e_s": e_s, "e1": e1, "V": V, "e2": e2, "active": active,
                     "m": W.shape[0], "rows": rows}

    def avoid_only(self, qd: np.ndarray, J_g: np.ndarray, G: np.ndarray, dist: float,
                   grad_dist: np.ndarray) -> tuple[np.ndarray, float]:
        """Torques of the secondary task alone, ``e = -(de2/dr)^T`` (no image: the features
        are lost while the human is within ``dmin``), with the active damping. # ours: the
        paper does not say what happens then; safety does not need the camera.

        Returns:
            ``(tau, e2)``.
        """
        cfg = self.config
        e2, de2_dr = secondary_task(dist, grad_dist, cfg.alpha, cfg.dmin)
        return hybrid_torque(cfg.k_P, J_g, -de2_dr, self.damping(True), qd, G), e2
