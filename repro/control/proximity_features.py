"""Interaction matrices of proximity-sensor distances, and obstacle-normal estimation.

thomas2024 Sec. II. All vectors are expressed in the ring frame F_Sj (origin at
the ring centre S_j); the twist v_Sj = (v, w) is that of F_Sj expressed in F_Sj
[m/s, rad/s]. A row L satisfies  d(delta)/dt = L v_Sj.

.. math::

    L_\\delta = \\beta [n_T^T, (m_T \\times n_T)^T],\\quad
    \\beta = -1 / (n_T \\cdot n_S),\\quad m_T = (\\delta + r) n_S      (2)

with n_T the obstacle surface normal at the detected point, pointing back
towards the sensor (so that n_T = -n_S for a surface facing the sensor).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from repro.errors import UnknownChoiceError

#: Interaction-matrix models of thomas2024: "exact" eq. (2) with the estimated
#: normal, "beta1" eq. (5) (beta = 1, estimated normal), "coarse" eq. (6).
MODELS = ("exact", "beta1", "coarse")


def L_delta_exact(n_S: np.ndarray, n_T: np.ndarray, delta: float, r: float) -> np.ndarray:
    """thomas2024 eq. (2): (6,) row; n_S, n_T unit (3,), delta, r [m]."""
    beta = -1.0 / float(n_T @ n_S)
    m_T = (delta + r) * n_S
    return beta * np.concatenate([n_T, np.cross(m_T, n_T)])


def L_delta_beta1(n_S: np.ndarray, n_T: np.ndarray, delta: float, r: float) -> np.ndarray:
    """thomas2024 eq. (5): eq. (2) with beta = 1."""
    m_T = (delta + r) * n_S
    return np.concatenate([n_T, np.cross(m_T, n_T)])


def L_delta_coarse(n_S: np.ndarray) -> np.ndarray:
    """thomas2024 eq. (6): n_T = -n_S gives L = [-n_S^T, 0]."""
    return np.concatenate([-n_S, np.zeros(3)])


def ring_interaction_matrix(
    n_S: np.ndarray,
    delta: np.ndarray,
    r: float,
    model: str,
    normals: np.ndarray | None = None,
) -> np.ndarray:
    """Stack the (m, 6) interaction matrix of a ring's m distances (vectorised
    eqs. (2), (5), (6); row i equals the single-sensor functions above).

    Args:
        n_S: (m, 3) sensor axes in the ring frame.
        delta: (m,) distances [m].
        r: ring radius [m].
        model: one of :data:`MODELS`.
        normals: (m, 3) estimated surface normals n_T (ring frame), required for
            "exact" and "beta1"; a NaN row means "no estimate": the coarse
            normal -n_S is used for that sensor.
    """
    if model not in MODELS:
        raise UnknownChoiceError("proximity model", model, MODELS)
    m = n_S.shape[0]
    L = np.zeros((m, 6))
    L[:, :3] = -n_S  # eq. (6)
    if model == "coarse" or normals is None:
        return L
    ok = np.all(np.isfinite(normals), axis=1)
    if not np.any(ok):
        return L
    n_T = normals[ok]
    m_T = (delta[ok] + r)[:, None] * n_S[ok]
    rows = np.hstack([n_T, np.cross(m_T, n_T)])  # eq. (5)
    if model == "exact":
        rows *= (-1.0 / np.einsum("ij,ij->i", n_T, n_S[ok]))[:, None]  # beta, eq. (2)
    L[ok] = rows
    return L


def fit_plane_normal(points: np.ndarray, rcond: float = 1e-6) -> np.ndarray | None:
    """thomas2024 eq. (4) (Badino et al. 2011): n = B^-1 b / |B^-1 b|.

    ``points`` (N, 3) lie on a plane n^T p = d that does not contain the
    origin; returns the unit normal pointing from the origin towards the plane,
    or None with fewer than two points. When all points lie on a line through
    a common plane with the origin (one ring instant: B has rank 2), B^-1 is
    replaced by the pseudo-inverse, which gives the normal within that plane.

    .. math:: B = \\sum_s p_s p_s^T,\\qquad b = \\sum_s p_s
    """
    if points.shape[0] < 2:
        return None
    B = points.T @ points
    b = points.sum(axis=0)
    n, *_ = np.linalg.lstsq(B, b, rcond=rcond)
    norm = np.linalg.norm(n)
    if not np.isfinite(norm) or norm < 1e-12:
        return None
    return n / norm


@dataclass(frozen=True)
class NormalEstimatorConfig:
    """Parameters of the surface-normal estimator (thomas2024 Sec. II-A1).

    Attributes:
        history: number of past control steps kept [steps]. # ours: ~0.5 s at 30 Hz
        neighbours: adjacent sensors on each side used with sensor i.  # ours
        min_separation: past points closer than this to the current detection
            are dropped (the paper's threshold) [m].  # ours
        max_separation: points farther than this from the current detection are
            taken to belong to another object [m].  # ours
        min_facing: an estimate with n_T . n_S > -min_facing is rejected (a
            surface seen edge-on or from behind) and the coarse normal is used.
    """

    history: int = 15
    neighbours: int = 1
    min_separation: float = 0.005
    max_separation: float = 0.12
    min_facing: float = 0.2


class NormalEstimator:
    """Per-ring estimator of obstacle normals from current and past detections.

    Call :meth:`update` once per control step with the ring pose and reading,
    then :meth:`normals` for the (m, 3) estimates in the current ring frame.
    """

    def __init__(self, n_S: np.ndarray, radius: float,
                 config: NormalEstimatorConfig | None = None) -> None:
        self.n_S = n_S
        self.radius = radius
        self.config = config or NormalEstimatorConfig()
        self._past: deque[tuple[np.ndarray, np.ndarray, np.ndarray]] = deque(
            maxlen=self.config.history
        )
        self._current: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def update(self, T_world_ring: np.ndarray, delta: np.ndarray, detected: np.ndarray) -> None:
        """Store this step's detections: points (delta + r) n_S in the ring frame."""
        if self._current is not None:
            self._past.append(self._current)
        pts = (delta + self.radius)[:, None] * self.n_S
        self._current = (T_world_ring.copy(), pts, detected.copy())

    def normals(self) -> np.ndarray:
        """(m, 3) estimated n_T in the current ring frame; NaN rows where none.

        For each detected sensor i, the candidate points are the current and past
        detections of sensors i-k..i+k, past points moved into the current ring frame
        (tp_T_tq = T_now^-1 T_then); past points closer than ``min_separation`` to the
        current detection are dropped (thomas2024 Sec. II-A1), so are points farther
        than ``max_separation`` (another object). Vectorised over sensors.
        """
        m = self.n_S.shape[0]
        out = np.full((m, 3), np.nan)
        if self._current is None:
            return out
        cfg = self.config
        T_now, pts_now, det_now = self._current
        if not np.any(det_now):
            return out
        T_now_inv = np.linalg.inv(T_now)
        pts = [pts_now]
        det = [det_now]
        for T_then, p_then, d_then in self._past:
            T_rel = T_now_inv @ T_then
            pts.append(p_then @ T_rel[:3, :3].T + T_rel[:3, 3])
            det.append(d_then)
        P = np.stack(pts)  # (K, m, 3), K = 1 + history; index 0 = now
        D = np.stack(det)  # (K, m)
        sensors = np.flatnonzero(det_now)
        offsets = np.arange(-cfg.neighbours, cfg.neighbours + 1)
        nbr = (sensors[:, None] + offsets[None, :]) % m  # (s, w)
        cand = P[:, nbr]  # (K, s, w, 3)
        valid = D[:, nbr]  # (K, s, w)
        p_i = pts_now[sensors]  # (s, 3)
        dist = np.linalg.norm(cand - p_i[None, :, None, :], axis=-1)
        keep = valid & (dist <= cfg.max_separation)
        keep[1:] &= dist[1:] >= cfg.min_separation  # past points near the current one dropped
        w = keep.astype(float)
        B = np.einsum("ksw,kswa,kswb->sab", w, cand, cand)  # eq. (4): sum p p^T
        b = np.einsum("ksw,kswa->sa", w, cand)  # sum p
        count = w.sum(axis=(0, 2))
        n_plane = np.einsum("sab,sb->sa", np.linalg.pinv(B, rcond=1e-6), b)
        norm = np.linalg.norm(n_plane, axis=1)
        good = (count >= 2) & np.isfinite(norm) & (norm > 1e-12)
        n_T = -n_plane / np.where(good, norm, 1.0)[:, None]  # n_T faces the sensor
        facing = np.einsum("sa,sa->s", n_T, self.n_S[sensors]) <= -cfg.min_facing
        good &= facing
        out[sensors[good]] = n_T[good]
        return out
