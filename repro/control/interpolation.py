"""Quintic-polynomial joint references between two controller updates.

chan2011 Sec. II-A2 / V-A5: the outer (visual) loop's joint targets are
interpolated with quintic polynomials for the 1 kHz inner loop.
"""

from __future__ import annotations

import numpy as np


def quintic(q0: np.ndarray, v0: np.ndarray, q1: np.ndarray, v1: np.ndarray, T: float,
            t: float) -> tuple[np.ndarray, np.ndarray]:
    r"""Position [rad] and velocity [rad/s] at time ``t`` in [0, T] [s] of the quintic with
    q(0) = q0, q'(0) = v0, q''(0) = 0, q(T) = q1, q'(T) = v1, q''(T) = 0.

    .. math:: q(t) = \sum_{i=0}^{5} c_i t^i

    Evaluated joint by joint in Python floats: the same IEEE operations in the same order as
    numpy's element-wise form (:func:`quintic_reference`, to the bit; a scalar ``s**k`` is
    libm's ``pow`` in both), without numpy's per-call overhead on a 7-vector at 1 kHz.
    """
    got = quintic_lists(q0, v0, q1, v1, T, t)
    if got is None:  # (a zero period divides by zero: numpy's inf/NaN, as before)
        return quintic_reference(q0, v0, q1, v1, T, t)
    return np.array(got[0]), np.array(got[1])


def quintic_lists(q0: np.ndarray, v0: np.ndarray, q1: np.ndarray, v1: np.ndarray, T: float,
                  t: float) -> tuple[list[float], list[float]] | None:
    """:func:`quintic` as lists of Python floats (for a caller that sends them on); None
    when ``T`` is not > 0."""
    T = float(T)
    if not T > 0.0:
        return None
    s = min(max(float(t), 0.0), T)  # np.clip's value
    s2, s3, s4, s5 = s**2, s**3, s**4, s**5
    d3, d4, d5 = 2 * T**3, 2 * T**4, 2 * T**5
    c2 = 0.0
    q: list[float] = []
    qd: list[float] = []
    for c0, c1, a1, b1 in zip(np.asarray(q0, dtype=float).tolist(),
                              np.asarray(v0, dtype=float).tolist(),
                              np.asarray(q1, dtype=float).tolist(),
                              np.asarray(v1, dtype=float).tolist(), strict=True):
        h = a1 - c0
        c3 = (20 * h - (8 * b1 + 12 * c1) * T) / d3
        c4 = (-30 * h + (14 * b1 + 16 * c1) * T) / d4
        c5 = (12 * h - 6 * (b1 + c1) * T) / d5
        q.append(c0 + c1 * s + c2 * s2 + c3 * s3 + c4 * s4 + c5 * s5)
        qd.append(c1 + 2 * c2 * s + 3 * c3 * s2 + 4 * c4 * s3 + 5 * c5 * s4)
    return q, qd


def quintic_reference(q0: np.ndarray, v0: np.ndarray, q1: np.ndarray, v1: np.ndarray,
                      T: float, t: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`quintic` in numpy's element-wise form (the definition; tests compare with it)."""
    s = np.clip(t, 0.0, T)
    h = q1 - q0
    c0, c1, c2 = q0, v0, 0.0
    c3 = (20 * h - (8 * v1 + 12 * v0) * T) / (2 * T**3)
    c4 = (-30 * h + (14 * v1 + 16 * v0) * T) / (2 * T**4)
    c5 = (12 * h - 6 * (v1 + v0) * T) / (2 * T**5)
    q = c0 + c1 * s + c2 * s**2 + c3 * s**3 + c4 * s**4 + c5 * s**5
    qd = c1 + 2 * c2 * s + 3 * c3 * s**2 + 4 * c4 * s**3 + 5 * c5 * s**4
    return q, qd
