"""Obstacle surface normals from current and past proximity detections (thomas2024 Sec. II-A1).

For each sensor i of a ring that detects an obstacle, the points detected by sensors
i-k..i+k now and at the last ``history`` control steps, moved into the current ring frame
(tp_T_tq = T_now^-1 T_then), are fitted by a plane:

.. math::

    \\hat n_T = B^{-1} b / \\|B^{-1} b\\|,\\qquad B = \\sum_s p_s p_s^T,\\quad
    b = \\sum_s p_s          \\qquad\\text{thomas2024 eq. (4) (Badino et al. 2011)}

Past points closer than a threshold to the current detection are dropped (the paper's rule);
so are points too far from it to be on the same object (ours). A fit whose points do not
span a plane (degenerate) is not used: see :class:`NormalEstimatorConfig`.

The fit runs as one compiled kernel (numba, :func:`_estimate`): gathering the points, the
sums of eq. (4), the 3x3 symmetric eigen-decomposition of B (cyclic Jacobi) and B's
pseudo-inverse applied to b. The kernel uses no BLAS or LAPACK: its rounding does not depend
on the CPU's BLAS kernels (numba compiles without fast-math, so no reassociation or fused
multiply-add).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from repro.errors import ConfigError

#: Where a sensor's normal came from (:attr:`NormalEstimator.source`).
SOURCE_NONE, SOURCE_FIT, SOURCE_HELD = 0, 1, 2

#: Eigenvalues of B below ``PINV_RCOND`` times the largest are dropped from B^-1 (the
#: pseudo-inverse's cutoff, numpy.linalg.pinv's rcond). ours: kept from the first
#: implementation; with 2 mm range noise a well-posed fit has lambda_min >= 3e-5 lambda_max
#: (points within 1.1 m of the ring centre), so it acts only on noise-free rings.
PINV_RCOND = 1e-6

#: Cap on the cyclic Jacobi sweeps of a 3x3 eigen-decomposition. ours: a numerical rule,
#: Jacobi converges quadratically and a 3x3 needs 3-6 sweeps to full double precision; the
#: cap only bounds a NaN input.
JACOBI_SWEEPS = 30


def fit_plane_normal(points: np.ndarray, rcond: float = 1e-6) -> np.ndarray | None:
    """thomas2024 eq. (4) (Badino et al. 2011): n = B^-1 b / |B^-1 b|, for one point set.

    ``points`` (N, 3) [m] lie on a plane n^T p = d that does not contain the origin; returns
    the unit normal pointing from the origin towards the plane, or None with fewer than two
    points. When all points lie on a line through a common plane with the origin (one ring
    instant: B has rank 2), B^-1 is replaced by the pseudo-inverse, which gives the normal
    within that plane. (The estimator below applies the same formula in its kernel.)
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

    def __post_init__(self) -> None:
        if int(self.history) != self.history or self.history < 0:
            raise ConfigError(f"normal estimator history must be an integer >= 0 steps, "
                              f"got {self.history!r}")
        if int(self.neighbours) != self.neighbours or self.neighbours < 0:
            raise ConfigError(f"normal estimator neighbours must be an integer >= 0, "
                              f"got {self.neighbours!r}")
        for name in ("min_separation", "max_separation", "min_facing", "range_noise",
                     "spread_sigmas", "spread_floor"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ConfigError(f"normal estimator {name} must be finite and >= 0, got {v!r}")

    @property
    def min_spread(self) -> float:
        """The least RMS extent [m] of a well-posed fit."""
        return max(self.spread_sigmas * self.range_noise, self.spread_floor)


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
        self.n_S = np.ascontiguousarray(n_S, dtype=float)
        self.radius = float(radius)
        self.config = config or NormalEstimatorConfig()
        m, h = self.n_S.shape[0], int(self.config.history)
        # Past steps in a circular buffer (oldest at (slot - count) % h): ring poses
        # (h, 4, 4) [m], points in their ring frame (h, m, 3) [m], detection flags (h, m).
        self._T_past = np.zeros((h, 4, 4))
        self._p_past = np.zeros((h, m, 3))
        self._d_past = np.zeros((h, m), dtype=np.bool_)
        self._slot = self._count = 0
        self._current: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._held = np.full((m, 3), np.nan)  # last well-posed normal per sensor, world frame
        self.cond = np.full(m, np.nan)
        self.spread = np.full(m, np.nan)
        self.source = np.zeros(m, dtype=np.int64)
        c = self.config
        # the kernel's parameters: neighbours k, max and min separation [m], min facing,
        # min spread [m], the pseudo-inverse's rcond, the Jacobi sweep cap
        self._params = np.array([c.neighbours, c.max_separation, c.min_separation,
                                 c.min_facing, c.min_spread, PINV_RCOND, JACOBI_SWEEPS],
                                dtype=float)

    @property
    def T_world_ring(self) -> np.ndarray | None:
        """The ring pose of the last :meth:`update` (None before any)."""
        return None if self._current is None else self._current[0]

    def update(self, T_world_ring: np.ndarray, delta: np.ndarray, detected: np.ndarray) -> None:
        """Store this step's detections: points (delta + r) n_S in the ring frame [m]; the
        previous step's go to the history (the oldest is dropped when it is full)."""
        m = self.n_S.shape[0]
        T = np.array(T_world_ring, dtype=float)
        delta = np.asarray(delta, dtype=float)
        det = np.array(detected, dtype=np.bool_)
        if T.shape != (4, 4) or delta.shape != (m,) or det.shape != (m,):
            raise ValueError(f"normal estimator: need a (4, 4) pose and ({m},) readings, got "
                             f"{T.shape}, {delta.shape}, {det.shape}")  # (nothing stored)
        h = self._T_past.shape[0]
        if self._current is not None and h > 0:
            s = self._slot
            self._T_past[s], self._p_past[s], self._d_past[s] = self._current
            self._slot = (s + 1) % h
            self._count = min(self._count + 1, h)
        self._current = (T, (delta + self.radius)[:, None] * self.n_S, det)

    def normals(self) -> np.ndarray:
        """(m, 3) estimated n_T in the current ring frame; NaN rows where none.

        For each detected sensor i, the candidate points are the current and past
        detections of sensors i-k..i+k, past points moved into the current ring frame
        (tp_T_tq = T_now^-1 T_then); past points closer than ``min_separation`` to the
        current detection are dropped (thomas2024 Sec. II-A1), so are points farther
        than ``max_separation`` (another object). Eq. (4) is applied where the fit is well
        posed (at least two points, least extent at least ``min_spread``) and the normal
        faces the sensor; otherwise the sensor keeps its held normal, or has none.
        """
        if self._current is None:
            self.cond.fill(np.nan)
            self.spread.fill(np.nan)
            self.source.fill(SOURCE_NONE)
            return np.full((self.n_S.shape[0], 3), np.nan)
        T_now, pts_now, det_now = self._current
        return _estimate(self.n_S, T_now, pts_now, det_now, self._T_past, self._p_past,
                         self._d_past, self._slot, self._count, self._params, self._held,
                         self.cond, self.spread, self.source)


# ------------------------------------------------------------------------------------------
# The compiled kernel
# ------------------------------------------------------------------------------------------


@njit(cache=True, error_model="numpy")
def _jacobi_eig3(A: np.ndarray, lam: np.ndarray, V: np.ndarray, sweeps: int) -> None:
    """Eigen-decomposition of the symmetric 3x3 ``A`` (destroyed): eigenvalues ``lam`` (3,)
    ascending, unit eigenvectors in the columns of ``V`` (3, 3). Cyclic Jacobi rotations
    (Golub & Van Loan, Alg. 8.5.3 with the stable tangent of Rutishauser) until every
    off-diagonal entry is below the rounding of its diagonal pair, i.e. to the relative
    accuracy Jacobi gives a positive semi-definite matrix (Demmel & Veselic 1992)."""
    for i in range(3):
        for j in range(3):
            V[i, j] = 1.0 if i == j else 0.0
    eps = 2.220446049250313e-16
    for _ in range(sweeps):
        rotated = False
        for pair in range(3):  # (p, q) = (0, 1), (0, 2), (1, 2)
            p, q = (0, 1) if pair == 0 else ((0, 2) if pair == 1 else (1, 2))
            apq = A[p, q]
            app, aqq = A[p, p], A[q, q]
            if abs(apq) <= eps * np.sqrt(abs(app * aqq)) or apq == 0.0:
                A[p, q] = A[q, p] = 0.0
                continue
            rotated = True
            theta = (aqq - app) / (2.0 * apq)
            if abs(theta) > 1e150:  # theta**2 would overflow
                t = 0.5 / theta
            else:
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            tau = s / (1.0 + c)
            A[p, p] = app - t * apq
            A[q, q] = aqq + t * apq
            A[p, q] = A[q, p] = 0.0
            r = 3 - p - q  # the third index
            g, h = A[r, p], A[r, q]
            A[r, p] = A[p, r] = g - s * (h + g * tau)
            A[r, q] = A[q, r] = h + s * (g - h * tau)
            for k in range(3):
                g, h = V[k, p], V[k, q]
                V[k, p] = g - s * (h + g * tau)
                V[k, q] = h + s * (g - h * tau)
        if not rotated:
            break
    # ascending order (three entries: a sorting network)
    i0, i1, i2 = 0, 1, 2
    if A[i1, i1] < A[i0, i0]:
        i0, i1 = i1, i0
    if A[i2, i2] < A[i1, i1]:
        i1, i2 = i2, i1
    if A[i1, i1] < A[i0, i0]:
        i0, i1 = i1, i0
    lam[0], lam[1], lam[2] = A[i0, i0], A[i1, i1], A[i2, i2]
    for k in range(3):
        x0, x1, x2 = V[k, i0], V[k, i1], V[k, i2]
        V[k, 0], V[k, 1], V[k, 2] = x0, x1, x2


@njit(cache=True, error_model="numpy")
def _estimate(n_S: np.ndarray, T_now: np.ndarray, pts_now: np.ndarray, det_now: np.ndarray,
              T_past: np.ndarray, p_past: np.ndarray, d_past: np.ndarray, slot: int,
              count_past: int, params: np.ndarray, held: np.ndarray, cond: np.ndarray,
              spread: np.ndarray, source: np.ndarray) -> np.ndarray:
    """:meth:`NormalEstimator.normals` for one ring: returns the (m, 3) normals (NaN rows
    where there is no estimate), fills ``cond``, ``spread`` [m], ``source`` (m,) and updates
    ``held`` (m, 3, world frame); ``params`` as ``NormalEstimator._params``. Points are
    summed now first, then the past steps oldest first, neighbours i-k..i+k within each."""
    k, max_sep, min_sep = int(params[0]), params[1], params[2]
    min_facing, min_spread, rcond, sweeps = params[3], params[4], params[5], int(params[6])
    m = n_S.shape[0]
    out = np.empty((m, 3))
    h = T_past.shape[0]
    nt = 1 + count_past
    # every stored point in the current ring frame: P[t] = R_now^T (R_t p + t_t - t_now)
    P = np.empty((nt, m, 3))
    D = np.empty((nt, m), dtype=np.bool_)
    P[0] = pts_now
    D[0] = det_now
    need = np.zeros(m, dtype=np.bool_)  # the neighbours of a detecting sensor
    for i in range(m):
        if det_now[i]:
            for o in range(-k, k + 1):
                need[(i + o) % m] = True
    Mr = np.empty((3, 3))
    c = np.empty(3)
    for j in range(count_past):
        e = (slot - count_past + j) % h
        for a in range(3):
            for b in range(3):
                Mr[a, b] = (T_now[0, a] * T_past[e, 0, b] + T_now[1, a] * T_past[e, 1, b]
                            + T_now[2, a] * T_past[e, 2, b])
            c[a] = (T_now[0, a] * (T_past[e, 0, 3] - T_now[0, 3])
                    + T_now[1, a] * (T_past[e, 1, 3] - T_now[1, 3])
                    + T_now[2, a] * (T_past[e, 2, 3] - T_now[2, 3]))
        for i in range(m):
            D[j + 1, i] = d_past[e, i] and need[i]
            if not D[j + 1, i]:
                continue
            x, y, z = p_past[e, i, 0], p_past[e, i, 1], p_past[e, i, 2]
            for a in range(3):
                P[j + 1, i, a] = Mr[a, 0] * x + Mr[a, 1] * y + Mr[a, 2] * z + c[a]
    max_sep2, min_sep2 = max_sep * max_sep, min_sep * min_sep
    B = np.empty((3, 3))
    lam = np.empty(3)
    V = np.empty((3, 3))
    bv = np.empty(3)
    for i in range(m):
        out[i, 0] = out[i, 1] = out[i, 2] = np.nan
        cond[i] = np.nan
        spread[i] = np.nan
        source[i] = 0  # SOURCE_NONE
        if not det_now[i]:
            held[i, 0] = held[i, 1] = held[i, 2] = np.nan  # lost its obstacle: forgets it
            continue
        # eq. (4)'s sums over the kept points
        B[:, :] = 0.0
        bv[:] = 0.0
        n = 0
        xi, yi, zi = pts_now[i, 0], pts_now[i, 1], pts_now[i, 2]
        for t in range(nt):
            for o in range(-k, k + 1):
                l = (i + o) % m  # noqa: E741
                if not D[t, l]:
                    continue
                px, py, pz = P[t, l, 0], P[t, l, 1], P[t, l, 2]
                dx, dy, dz = px - xi, py - yi, pz - zi
                d2 = dx * dx + dy * dy + dz * dz  # squared distance to the detection [m^2]
                if d2 > max_sep2 or (t > 0 and d2 < min_sep2):
                    continue
                n += 1
                B[0, 0] += px * px
                B[0, 1] += px * py
                B[0, 2] += px * pz
                B[1, 1] += py * py
                B[1, 2] += py * pz
                B[2, 2] += pz * pz
                bv[0] += px
                bv[1] += py
                bv[2] += pz
        B[1, 0], B[2, 0], B[2, 1] = B[0, 1], B[0, 2], B[1, 2]
        _jacobi_eig3(B, lam, V, sweeps)
        lmin, lmax = lam[0], lam[2]
        cond[i] = lmax / max(lmin, 1e-16 * lmax)  # capped at 1e16: a singular B has lmin <= 0
        sp = np.sqrt(max(lmin, 0.0) / n)
        spread[i] = sp
        good = False
        if n >= 2 and sp >= min_spread:
            # eq. (4) with B's pseudo-inverse: sum of v (v . b) / lambda over the kept lambdas
            big = rcond * max(abs(lam[0]), abs(lam[2]))
            nx = ny = nz = 0.0
            for a in range(3):
                if abs(lam[a]) > big:
                    f = (V[0, a] * bv[0] + V[1, a] * bv[1] + V[2, a] * bv[2]) / lam[a]
                    nx += f * V[0, a]
                    ny += f * V[1, a]
                    nz += f * V[2, a]
            norm = np.sqrt(nx * nx + ny * ny + nz * nz)
            if np.isfinite(norm) and norm > 1e-12:
                nx, ny, nz = -nx / norm, -ny / norm, -nz / norm  # n_T faces the sensor
                if nx * n_S[i, 0] + ny * n_S[i, 1] + nz * n_S[i, 2] <= -min_facing:
                    good = True
                    out[i, 0], out[i, 1], out[i, 2] = nx, ny, nz
                    source[i] = 1  # SOURCE_FIT
                    for a in range(3):  # world frame: R n_T
                        held[i, a] = T_now[a, 0] * nx + T_now[a, 1] * ny + T_now[a, 2] * nz
        if not good and not np.isnan(held[i, 0]):  # a degenerate fit keeps the held normal
            for a in range(3):  # ring frame: R^T n_held
                out[i, a] = T_now[0, a] * held[i, 0] + T_now[1, a] * held[i, 1] \
                    + T_now[2, a] * held[i, 2]
            source[i] = 2  # SOURCE_HELD
    return out
