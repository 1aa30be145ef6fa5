r"""Indirect (kinematic) image-based visual servoing tracked by a joint-space torque loop:
the baseline that pomares2011 argues against (Sec. 1 and 3.2: "indirect" schemes send
joint velocities to the robot's own joint controller; the direct controller of
:mod:`repro.control.hybrid_vs` computes the torques from the image error itself).

Two nested loops, both at the control rate:

.. math::

    \dot q_{ref} &= \mathrm{sat}\big(-\lambda\, J^{+} (s - s^*)\big),
        \qquad J = L_s J_g                                    && \text{(IBVS)}\\
    q_{ref} &\leftarrow \mathrm{clip}(q_{ref} + \dot q_{ref}\, dt,\ q_{min}, q_{max})
                                                         && \text{(reference)}\\
    \tau &= K_p (q_{ref} - q) + K_d (\dot q_{ref} - \dot q) + G(q) && \text{(joint PD)}

``sat`` scales the whole velocity so that no joint exceeds its speed limit (the direction
is kept); the integrated reference stays inside the joint limits (a reference past a limit
would wind up: the PD would push into the limit stop harder and harder). ``J^+`` is the
damped pseudo-inverse (``mu`` below). The PD gains come from the
robot's inertia at the first step (:func:`pd_gains_from_inertia`): every joint-space mode
of ``M q'' + K_d q' + K_p q = 0`` has natural frequency ``omega`` and damping ratio
``zeta``, the same rule (and the same numbers, in the experiment) as the direct
controller's fastest mode.

Units as :mod:`repro.control.hybrid_vs`: features in pixels (with ``L_s`` in pixels),
``J_g`` the camera Jacobian in the camera frame, joint quantities in [rad], [rad/s], [N m].
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from repro.errors import ConfigError

__all__ = ["IndirectVSConfig", "IndirectVSController", "PDGains", "ibvs_velocity_reference",
           "pd_gains_from_inertia"]


class PDGains(NamedTuple):
    """Joint PD gains ``K_p`` [N m/rad] and ``K_d`` [N m s/rad], (n, n) each."""

    K_p: np.ndarray
    K_d: np.ndarray


def _sqrtm_spd(M: np.ndarray) -> np.ndarray:
    d, Q = np.linalg.eigh(0.5 * (M + M.T))
    if d.min() <= 0:
        raise ConfigError(f"M must be positive definite, eigenvalues {d.tolist()}")
    return np.asarray(Q @ np.diag(np.sqrt(d)) @ Q.T)


def pd_gains_from_inertia(M: np.ndarray, omega: float, zeta: float = 1.0) -> PDGains:
    """``K_p = omega^2 M``, ``K_d = 2 zeta omega M`` (M at the first configuration): every
    mode of the linearised joint loop has natural frequency ``omega`` [rad/s] and damping
    ratio ``zeta`` [-]. # ours: the paper gives no joint-controller gains."""
    if not (np.isfinite(omega) and omega > 0 and np.isfinite(zeta) and zeta > 0):
        raise ConfigError(f"need omega > 0 and zeta > 0, got {omega}, {zeta}")
    M = np.asarray(M, dtype=float)
    _sqrtm_spd(M)  # positive definite
    Ms = 0.5 * (M + M.T)
    return PDGains(omega**2 * Ms, 2.0 * zeta * omega * Ms)


def ibvs_velocity_reference(J: np.ndarray, e: np.ndarray, gain: float,
                            qd_max: np.ndarray | None = None, mu: float = 0.0
                            ) -> np.ndarray:
    """``qd_ref = -gain J^+ e`` (n,) [rad/s] with ``e = s - s*`` and the damped least-squares
    inverse ``J^+ = (J^T J + mu I)^{-1} J^T``, scaled down as a whole if a joint would
    exceed ``qd_max``.

    Args:
        J: (k, n) task Jacobian ``L_s J_g`` [px/rad].
        e: (k,) feature error ``s - s*`` [px].
        gain: lambda [1/s], > 0.
        qd_max: (n,) joint speed limits [rad/s]; None: no scaling.
        mu: damping relative to the largest eigenvalue of ``J^T J`` [-], >= 0 (the
            damping added is ``mu * lambda_max(J^T J)``).
    """
    J = np.asarray(J, dtype=float)
    e = np.asarray(e, dtype=float).reshape(-1)
    if J.ndim != 2 or J.shape[0] != e.size:
        raise ValueError(f"J {J.shape} and e ({e.size},) do not match")
    if not (np.isfinite(J).all() and np.isfinite(e).all()):
        raise ValueError("J and e must be finite")
    n = J.shape[1]
    JtJ = J.T @ J
    damping = mu * float(np.linalg.eigvalsh(JtJ)[-1])
    qd = -gain * np.linalg.solve(JtJ + damping * np.eye(n), J.T @ e)
    if qd_max is not None:
        ratio = float(np.max(np.abs(qd) / np.asarray(qd_max, dtype=float)))
        if ratio > 1.0:
            qd = qd / ratio
    return np.asarray(qd)


@dataclass(frozen=True)
class IndirectVSConfig:
    """Parameters of the indirect baseline.

    Attributes:
        s_star: (k,) desired features [px].
        gain: lambda of the kinematic IBVS [1/s]. ours (see the experiment's config).
        K_p, K_d: (n, n) joint PD gains (:func:`pd_gains_from_inertia`).
        qd_max: (n,) joint speed limits the velocity reference respects [rad/s].
        dt: control period [s] (integration of the reference).
        q_min, q_max: (n,) joint position limits the reference stays within [rad].
        mu: relative damping of the least-squares inverse (:func:`ibvs_velocity_reference`).
            ours: 1e-3, i.e. directions the image sees 30x less than the best one are
            damped; the mini-robot's visual modes span 600 : 1 (0.1 to 60 rad/s with the
            direct gains), and undamped the least-squares step asks for large motions along
            the nearly invisible direction, which leave the linear regime.
    """

    s_star: np.ndarray
    gain: float
    K_p: np.ndarray
    K_d: np.ndarray
    qd_max: np.ndarray
    dt: float
    q_min: np.ndarray
    q_max: np.ndarray
    mu: float = 1e-3  # ours: see the docstring (directions seen 30x less than the best are damped)

    def __post_init__(self) -> None:
        for name in ("gain", "dt"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"{name} must be finite and > 0, got {v!r}")
        object.__setattr__(self, "s_star", np.asarray(self.s_star, dtype=float).reshape(-1))
        for name in ("qd_max", "q_min", "q_max"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float).reshape(-1))
        if not np.all(self.q_min < self.q_max):
            raise ConfigError(f"need q_min < q_max, got {self.q_min} and {self.q_max}")


class IndirectVSController:
    """Kinematic IBVS -> integrated joint reference -> joint PD with gravity compensation.

    Holds the reference ``q_ref`` (initialised to the first measured ``q``)."""

    def __init__(self, config: IndirectVSConfig) -> None:
        self.config = config
        self.q_ref: np.ndarray | None = None

    def step(self, q: np.ndarray, qd: np.ndarray, s: np.ndarray, L_s: np.ndarray,
             J_g: np.ndarray, G: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
        """Joint torques (n,) [N m] and diagnostics: ``qd_ref`` [rad/s], ``q_ref`` [rad],
        ``kinetic`` = 1/2 qd^T M qd [J], ``e_s`` = s* - s [px].

        Args: as :meth:`repro.control.hybrid_vs.HybridVSController.step` (``M`` only for
        the kinetic energy).
        """
        cfg = self.config
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        if self.q_ref is None:
            self.q_ref = q.copy()
        e = np.asarray(s, dtype=float).reshape(-1) - cfg.s_star
        J = np.asarray(L_s, dtype=float) @ np.asarray(J_g, dtype=float)  # J = L_s J_g
        qd_ref = ibvs_velocity_reference(J, e, cfg.gain, cfg.qd_max, cfg.mu)
        q_next = np.clip(self.q_ref + qd_ref * cfg.dt, cfg.q_min, cfg.q_max)
        qd_ref = (q_next - self.q_ref) / cfg.dt  # stopped at a limit: no speed past it
        self.q_ref = q_next
        tau = cfg.K_p @ (self.q_ref - q) + cfg.K_d @ (qd_ref - qd) + np.asarray(G, float)
        kinetic = float(0.5 * qd @ np.asarray(M, float) @ qd)
        return tau, {"qd_ref": qd_ref, "q_ref": self.q_ref.copy(), "kinetic": kinetic,
                     "e_s": -e}
