"""Compiled loops over image points (numba) for a control step's small arrays: one call
instead of several NumPy calls.

- :func:`normalize_points`: :meth:`repro.sensors.camera.Intrinsics.to_normalized` without
  skew;
- :func:`fill_interaction_matrix`: :func:`repro.vision.features.interaction_matrix_points`
  into a caller's buffer.

Each writes what the NumPy code gives, to the bit: the same IEEE operations per entry in the
same order (numba compiles without fast-math: no reassociation, no fused multiply-add), on
finite inputs with finite results only (else it returns False and the caller takes the
NumPy code, which also warns of an overflow), so no NaN's sign or payload depends on the
compiler. Imported lazily by their users (importing the
vision and sensor modules costs only NumPy).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Within these bounds every entry of a point's interaction matrix is finite: ``|x|, |y| <=
#: 1e150`` [-] and ``Z >= 1e-150`` [m] keep ``1/Z``, ``x/Z``, ``x y`` and ``1 + x^2`` below
#: 1e300 (ours: far outside any image and any depth).
FINITE_XY_MAX, FINITE_Z_MIN = 1e150, 1e-150


@njit(cache=True, error_model="numpy")
def fill_interaction_matrix(xy: np.ndarray, Z: np.ndarray, L: np.ndarray) -> bool:
    """Write the (2N, 6) interaction matrix of N points into ``L`` (Chaumette & Hutchinson
    2006, eq. (11); rows ``x1, y1, x2, ...``).

    Args:
        xy: (N, 2) normalised image coordinates [-], float64.
        Z: (N,) depths [m], float64.
        L: (2N, 6) float64 output.

    Returns:
        True when every point lies within :data:`FINITE_XY_MAX` and :data:`FINITE_Z_MIN`
        (NaN excluded), then ``L`` holds ``interaction_matrix_points(xy, Z)``'s bits; False
        otherwise (``L`` is then not to be used: that function decides, and raises for an
        invalid point).
    """
    xy_max, z_min = FINITE_XY_MAX, FINITE_Z_MIN
    for i in range(Z.shape[0]):
        x, y, z = xy[i, 0], xy[i, 1], Z[i]
        if not (z_min <= z < math.inf and -xy_max <= x <= xy_max and -xy_max <= y <= xy_max):
            return False
        inv_z = 1.0 / z
        r = 2 * i
        L[r, 0], L[r, 1], L[r, 2] = -inv_z, 0.0, x * inv_z
        L[r, 3], L[r, 4], L[r, 5] = x * y, -(1.0 + x * x), y
        L[r + 1, 0], L[r + 1, 1], L[r + 1, 2] = 0.0, -inv_z, y * inv_z
        L[r + 1, 3], L[r + 1, 4], L[r + 1, 5] = 1.0 + y * y, -x * y, -x
    return True


@njit(cache=True, error_model="numpy")
def normalize_points(uv: np.ndarray, u0: float, v0: float, fu: float, fv: float,
                     x: np.ndarray) -> bool:
    """Write ``x = (u - u0) / fu``, ``y = (v - v0) / fv`` for (N, 2) pixels ``uv`` [px] into
    ``x`` (N, 2) [-]: ``(uv - (u0, v0)) / (fu, fv)``, the same two operations per entry.

    Returns:
        True when every pixel and every result is finite (then ``x`` holds the results),
        else False (``x`` is then not to be used).
    """
    for i in range(uv.shape[0]):
        u, v = uv[i, 0], uv[i, 1]
        if not (math.isfinite(u) and math.isfinite(v)):
            return False
        xi, yi = (u - u0) / fu, (v - v0) / fv
        if not (math.isfinite(xi) and math.isfinite(yi)):
            return False  # (an overflow: NumPy's operations, and its warning)
        x[i, 0], x[i, 1] = xi, yi
    return True
