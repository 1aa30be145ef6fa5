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


#: columns (y, z, x) then (z, x, y) of a 3-vector: a x b = a_yzx b_zxy - a_zxy b_yzx
_YZX_ZXY = np.array([1, 2, 0, 2, 0, 1])
_ZXY_YZX = np.array([2, 0, 1, 1, 2, 0])


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
    ok = np.logical_and.reduce(np.isfinite(normals), axis=1).nonzero()[0]
    if not ok.size:
        return L
    n_T = normals[ok]
    rows = np.empty((ok.size, 6))  # eq. (5): [n_T, m_T x n_T]
    rows[:, :3] = n_T
    # m_T x n_T = m_T,yzx n_T,zxy - m_T,zxy n_T,yzx: the products and differences of np.cross,
    # without its overhead; m_T = (delta + r) n_S is formed in both column orders at once
    m_T = (delta[ok] + r)[:, None] * n_S[ok[:, None], _YZX_ZXY]  # (s, 6): yzx | zxy
    n_T6 = n_T[:, _ZXY_YZX]  # zxy | yzx
    np.subtract(m_T[:, :3] * n_T6[:, :3], m_T[:, 3:] * n_T6[:, 3:], out=rows[:, 3:])
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
        range_noise: standard deviation of the range readings [m] (the ring's noise_std):
            sets the degeneracy test below.
        spread_sigmas: a fit is degenerate when its points' least RMS extent,
            ``sqrt(lambda_min(B) / count)``, is under ``spread_sigmas`` range-noise
            standard deviations (or under ``spread_floor`` when the ring is noise-free):
            in that direction the points are noise, so the plane through them is not
            determined (a still ring's points lie on one line: the ring plane cuts the
            surface along it, and eq. (4) then returns a normal in the ring plane).
            # ours: 3 sigma, the usual gate for "distinguishable from noise"
        spread_floor: the least extent of a noise-free fit [m].
            # ours: 1e-6 m, 30x the float32 resolution of a ray-cast hit at 1 m range
    """

    history: int = 15
    neighbours: int = 1
    min_separation: float = 0.005
    max_separation: float = 0.12
    min_facing: float = 0.2
    range_noise: float = 0.0
    spread_sigmas: float = 3.0
    spread_floor: float = 1e-6

    @property
    def min_spread(self) -> float:
        """The least RMS extent [m] of a well-posed fit."""
        return max(self.spread_sigmas * self.range_noise, self.spread_floor)


#: Where a sensor's normal came from (:attr:`NormalEstimator.source`).
SOURCE_NONE, SOURCE_FIT, SOURCE_HELD = 0, 1, 2


class NormalEstimator:
    """Per-ring estimator of obstacle normals from current and past detections.

    Call :meth:`update` once per control step with the ring pose and reading,
    then :meth:`normals` for the (m, 3) estimates in the current ring frame.

    A degenerate fit (see :class:`NormalEstimatorConfig`: its points do not span a plane)
    is not used: the sensor keeps its last well-posed normal, held fixed in the world
    (the obstacle does not turn) for as long as the sensor keeps detecting, and falls back
    to the coarse model (6) (a NaN row) when it never had one. After :meth:`normals`,
    :attr:`cond` (cond(B) of eq. (4)), :attr:`spread` (the least RMS extent [m]) and
    :attr:`source` (SOURCE_NONE / SOURCE_FIT / SOURCE_HELD) describe every sensor's
    estimate (NaN / SOURCE_NONE where nothing was fitted).
    """

    def __init__(self, n_S: np.ndarray, radius: float,
                 config: NormalEstimatorConfig | None = None) -> None:
        self.n_S = n_S
        self.radius = radius
        self.config = config or NormalEstimatorConfig()
        # The last ``history`` past steps, oldest first, stacked: ring poses (K, 4, 4),
        # points in their ring frame (K, m, 3), detection flags (K, m); None before any.
        self._past: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._current: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        m = n_S.shape[0]
        self._held = np.full((m, 3), np.nan)  # last well-posed normal per sensor, world frame
        self.cond = np.full(m, np.nan)
        self.spread = np.full(m, np.nan)
        self.source = np.zeros(m, dtype=int)
        k = self.config.neighbours
        #: the sensors whose points join sensor i's fit, i-k..i+k (mod m), in column i: (w, m)
        self._neighbours = (np.arange(-k, k + 1)[:, None] + np.arange(m)) % m

    @property
    def T_world_ring(self) -> np.ndarray | None:
        """The ring pose of the last :meth:`update` (None before any)."""
        return None if self._current is None else self._current[0]

    def update(self, T_world_ring: np.ndarray, delta: np.ndarray, detected: np.ndarray) -> None:
        """Store this step's detections: points (delta + r) n_S in the ring frame."""
        if self._current is not None and self.config.history > 0:
            if self._past is None:
                self._past = (self._current[0][None], self._current[1][None],
                              self._current[2][None])
            elif len(self._past[0]) < self.config.history:
                self._past = (np.concatenate((self._past[0], self._current[0][None])),
                              np.concatenate((self._past[1], self._current[1][None])),
                              np.concatenate((self._past[2], self._current[2][None])))
            else:  # full: drop the oldest (these arrays are private, shifted in place)
                for buf, new in zip(self._past, self._current, strict=True):
                    buf[:-1] = buf[1:]
                    buf[-1] = new
        pts = (delta + self.radius)[:, None] * self.n_S
        self._current = (T_world_ring.copy(), pts, detected.copy())

    def normals(self) -> np.ndarray:
        """(m, 3) estimated n_T in the current ring frame; NaN rows where none.

        For each detected sensor i, the candidate points are the current and past
        detections of sensors i-k..i+k, past points moved into the current ring frame
        (tp_T_tq = T_now^-1 T_then); past points closer than ``min_separation`` to the
        current detection are dropped (thomas2024 Sec. II-A1), so are points farther
        than ``max_separation`` (another object). Vectorised over sensors.

        Eq. (4) is solved (B^-1 b, with the pseudo-inverse) only for the sensors whose fit
        is well posed -- at least two points, least extent above the degeneracy threshold --
        which the eigenvalues of B decide first: the others keep their held normal or none
        whatever B^-1 b is (in case 2, ring 2 has no such sensor in four steps out of five).
        The pseudo-inverse is one LAPACK SVD per matrix, the same bits for a subset of the
        stack; every other array keeps its shape for all detected sensors. The estimates
        are those of the previous, einsum-based code to the bit
        (tests/test_thomas2024_speed.py).
        """
        m = self.n_S.shape[0]
        out = np.full((m, 3), np.nan)
        self.cond.fill(np.nan)
        self.spread.fill(np.nan)
        self.source.fill(SOURCE_NONE)
        if self._current is None:
            return out
        cfg = self.config
        T_now, pts_now, det_now = self._current
        self._held[~det_now] = np.nan  # a sensor that lost its obstacle forgets its normal
        if not det_now.any():
            return out
        T_now_inv = np.linalg.inv(T_now)
        if self._past is None:
            P, D = pts_now[None], det_now[None]
        else:
            T_then, p_then, d_then = self._past
            T_rel = T_now_inv @ T_then  # (K - 1, 4, 4): tp_T_tq
            p_rel = p_then @ T_rel[:, :3, :3].transpose(0, 2, 1) + T_rel[:, None, :3, 3]
            P = np.concatenate((pts_now[None], p_rel))  # (K, m, 3), K = 1 + history; 0 = now
            D = np.concatenate((det_now[None], d_then))  # (K, m)
        sensors = det_now.nonzero()[0]
        nbr = self._neighbours[:, sensors]  # (w, s)
        cand = P[:, nbr].transpose(1, 0, 2, 3).copy()  # (w, K, s, 3): neighbour, time, sensor
        diff = cand - pts_now[sensors]
        dist = np.sqrt(np.add.reduce(diff * diff, axis=-1))  # = np.linalg.norm(diff, axis=-1)
        keep = D[:, nbr].transpose(1, 0, 2) & (dist <= cfg.max_separation)  # (w, K, s)
        keep[:, 1:] &= dist[:, 1:] >= cfg.min_separation  # past points near now: dropped
        # eq. (4): B = sum p p^T and b = sum p over each sensor's kept points (weights w = 0
        # or 1), summed from 0 one term at a time, neighbour by neighbour and in time within
        # each: np.add.reduce along the first axis of the (w K, s, ...) stack. That is the
        # order, hence the bits, in which np.einsum("ksw,kswa,kswb->sab", w, cand, cand) and
        # np.einsum("ksw,kswa->sa", w, cand) sum the (K, s, w) arrays of P[:, nbr] (laid out
        # s, w, K in memory by advanced indexing, einsum runs over K innermost), without
        # einsum's generic loop.
        W, K, S = keep.shape
        wp = keep[..., None] * cand  # w p: p or 0
        B = np.add.reduce((wp[..., :, None] * cand[..., None, :]).reshape(W * K, S, 3, 3),
                          axis=0, initial=0.0)
        b = np.add.reduce(wp.reshape(W * K, S, 3), axis=0, initial=0.0)
        count = np.add.reduce(keep.reshape(W * K, S), axis=0, dtype=float)
        eig = np.linalg.eigvalsh(B)  # ascending, per sensor
        with np.errstate(divide="ignore", invalid="ignore"):
            # capped at 1e16 (double precision): a singular B has eig[:, 0] <= 0
            self.cond[sensors] = eig[:, -1] / np.maximum(eig[:, 0], 1e-16 * eig[:, -1])
            spread = np.sqrt(np.maximum(eig[:, 0], 0.0) / count)
        self.spread[sensors] = spread
        posed = (count >= 2) & (spread >= cfg.min_spread)  # NaN (count 0) is not
        R = T_now[:3, :3]
        if posed.any():
            B_inv = np.zeros_like(B)  # eq. (4)'s B^-1 (pseudo-inverse) where the fit is posed
            B_inv[posed] = np.linalg.pinv(B[posed], rcond=1e-6)
            n_plane = np.einsum("sab,sb->sa", B_inv, b)
            norm = np.linalg.norm(n_plane, axis=1)
            good = posed & np.isfinite(norm) & (norm > 1e-12)
            n_T = -n_plane / np.where(good, norm, 1.0)[:, None]  # n_T faces the sensor
            facing = np.einsum("sa,sa->s", n_T, self.n_S[sensors]) <= -cfg.min_facing
            good &= facing
            out[sensors[good]] = n_T[good]
            self.source[sensors[good]] = SOURCE_FIT
            self._held[sensors[good]] = n_T[good] @ R.T
        else:
            good = posed  # all False
        # a degenerate fit keeps the sensor's last well-posed normal (world-fixed)
        hold = sensors[~good & ~np.isnan(self._held[sensors, 0])]
        if hold.size:
            out[hold] = self._held[hold] @ R
            self.source[hold] = SOURCE_HELD
        return out
