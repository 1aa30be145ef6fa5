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
    """
    s = np.clip(t, 0.0, T)
    h = q1 - q0
    c0, c1, c2 = q0, v0, 0.0
    c3 = (20 * h - (8 * v1 + 12 * v0) * T) / (2 * T**3)
    c4 = (-30 * h + (14 * v1 + 16 * v0) * T) / (2 * T**4)
    c5 = (12 * h - 6 * (v1 + v0) * T) / (2 * T**5)
    q = c0 + c1 * s + c2 * s**2 + c3 * s**3 + c4 * s**4 + c5 * s**5
    qd = c1 + 2 * c2 * s + 3 * c3 * s**2 + 4 * c4 * s**3 + 5 * c5 * s**4
    return q, qd
