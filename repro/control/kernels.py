"""Compiled pieces of the CBF-QP layer (numba), each one call instead of several NumPy calls
on the small arrays of a control step:

- :func:`plain_dense`, :func:`all_finite3`: the filling and checks of a QP's data and the
  finiteness test of a solution in :meth:`repro.control.qp.QPSolver.solve`;
- :func:`finite` (:func:`all_finite`): ``np.isfinite(a).all()`` in one call, for the input
  checks of a control step (pomares2011's hybrid law, the runner's command check);
- :func:`cbf_offsets`: the right-hand sides of :func:`repro.control.cbf_qp.cbf_inequalities`;
- :func:`add_to_diagonal`: the ``+ mu I`` of :func:`repro.control.cbf_qp.ibvs_objective`.

Each computes what the NumPy code it stands for computes, to the bit: copies, comparisons,
and arithmetic as the same IEEE operations per entry in the same order (numba compiles
without fast-math: no reassociation, no fused multiply-add), on finite values with finite
results only: given anything else it returns False and the caller takes the NumPy code
(which also warns of an overflow), so no NaN's sign or payload depends on the compiler.
:mod:`repro.control.qp` imports this module lazily (importing it costs only NumPy).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def plain_dense(H: np.ndarray, g: np.ndarray, C: np.ndarray, l: np.ndarray, u: np.ndarray,
                lb: np.ndarray, ub: np.ndarray, H_sym: np.ndarray, bounds: np.ndarray) -> bool:
    """Fill ``H_sym = (H + H^T) * 0.5`` (n, n) and ``bounds = [lb; l; ub; u]`` (2 (n + m),)
    and test the data, for float64 arrays of the shapes (n, n), (n,), (m, n), (m,), (m,),
    (n,), (n,).

    Returns:
        True when ``H``, ``H_sym``, ``g`` and ``C`` are finite and every bound pair is
        consistent (``lo <= hi``, no ``lo = +inf``, no ``hi = -inf``, no NaN: as
        ``repro.control.qp._bounds_consistent``); then ``H_sym`` and ``bounds`` hold what
        ``H + H.T``, ``*= 0.5`` and ``np.concatenate((lb, l, ub, u))`` give. False
        otherwise (the outputs are then not to be used).
    """
    n, m = g.shape[0], l.shape[0]
    k = n + m
    for i in range(n):
        for j in range(n):
            if not math.isfinite(H[i, j]):
                return False
    for i in range(n):
        for j in range(n):
            s = (H[i, j] + H[j, i]) * 0.5  # (two roundings, as H + H.T, then *= 0.5)
            if not math.isfinite(s):
                return False
            H_sym[i, j] = s
        if not math.isfinite(g[i]):
            return False
        bounds[i], bounds[k + i] = lb[i], ub[i]
    for i in range(m):
        for j in range(n):
            if not math.isfinite(C[i, j]):
                return False
        bounds[n + i], bounds[k + n + i] = l[i], u[i]
    for i in range(k):
        lo, hi = bounds[i], bounds[k + i]
        if not (lo <= hi and lo < math.inf and hi > -math.inf):
            return False
    return True


@njit(cache=True, error_model="numpy")
def all_finite(a: np.ndarray) -> bool:
    """Every entry of the float64 array ``a`` (any shape and layout) is finite: what
    ``np.isfinite(a).all()`` says, in one call (~0.35 against ~2 us on a control step's
    small arrays)."""
    for v in a.flat:
        if not math.isfinite(v):
            return False
    return True


def finite(a: np.ndarray) -> bool:
    """``np.isfinite(a).all()`` for any array: :func:`all_finite` on a float64 one."""
    if type(a) is np.ndarray and a.dtype == np.float64:
        return bool(all_finite(a))
    return bool(np.isfinite(a).all())


@njit(cache=True, error_model="numpy")
def all_finite3(x: np.ndarray, z: np.ndarray, z_box: np.ndarray) -> bool:
    """Every entry of the float64 vectors ``x``, ``z`` and ``z_box`` is finite."""
    for i in range(x.shape[0]):
        if not math.isfinite(x[i]):
            return False
    for i in range(z.shape[0]):
        if not math.isfinite(z[i]):
            return False
    for i in range(z_box.shape[0]):
        if not math.isfinite(z_box[i]):
            return False
    return True


@njit(cache=True, error_model="numpy")
def cbf_offsets(delta: np.ndarray, delta_star: float, minus_gain: float, b: np.ndarray) -> bool:
    """Write ``b = (-gain) * (delta - delta_star)`` (m,) [m/s] for distances ``delta`` (m,)
    [m]: the two operations per entry of ``-gain * (delta - delta_star)``.

    Returns:
        True when ``delta_star``, ``minus_gain``, every ``delta`` and every result are
        finite (then ``b`` holds them), else False (``b`` is then not to be used).
    """
    if not (math.isfinite(delta_star) and math.isfinite(minus_gain)):
        return False
    for i in range(delta.shape[0]):
        d = delta[i]
        if not math.isfinite(d):
            return False
        v = minus_gain * (d - delta_star)
        if not math.isfinite(v):
            return False
        b[i] = v
    return True


@njit(cache=True, error_model="numpy")
def add_to_diagonal(G: np.ndarray, mu: float) -> bool:
    """``G[i, i] += mu`` for a square ``G`` when ``mu``, the diagonal and the sums are finite
    (the operation of ``G.ravel()[:: n + 1] += mu``); returns False (``G`` unchanged)
    otherwise."""
    n = G.shape[0]
    for i in range(n):
        if not math.isfinite(G[i, i] + mu):  # (also False for a non-finite G[i, i] or mu)
            return False
    for i in range(n):
        G[i, i] = G[i, i] + mu
    return True
