"""Interaction matrices of proximity-sensor distances (the normal estimator of Sec. II-A1 is
in :mod:`repro.control.normal_estimator`, re-exported here).

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

import numpy as np
from numba import njit

from repro.control.normal_estimator import (
    SOURCE_FIT,
    SOURCE_HELD,
    SOURCE_NONE,
    NormalEstimator,
    NormalEstimatorConfig,
    fit_plane_normal,
)
from repro.errors import UnknownChoiceError

__all__ = ["MODELS", "SOURCE_FIT", "SOURCE_HELD", "SOURCE_NONE", "L_delta_beta1",
           "L_delta_coarse", "L_delta_exact", "NormalEstimator", "NormalEstimatorConfig",
           "fit_plane_normal", "ring_interaction_matrix"]

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
    _estimated_rows(np.asarray(n_S, dtype=float), np.asarray(delta, dtype=float), float(r),
                    np.asarray(normals, dtype=float), model == "exact", L)
    return L


@njit(cache=True, error_model="numpy")
def _estimated_rows(n_S: np.ndarray, delta: np.ndarray, r: float, normals: np.ndarray,
                    exact: bool, L: np.ndarray) -> None:
    """Overwrite the rows of ``L`` (m, 6) whose estimated normal is finite with eq. (5)
    [n_T, m_T x n_T], m_T = (delta + r) n_S, times beta = -1 / (n_T . n_S) (eq. (2)) if
    ``exact``. Each entry is the IEEE operations of the NumPy formulas, in their order (no
    fused multiply-add): the same bits as NumPy's vectorised rows."""
    for i in range(n_S.shape[0]):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        if not (np.isfinite(nx) and np.isfinite(ny) and np.isfinite(nz)):
            continue  # no estimate: the coarse row stays
        d = delta[i] + r
        mx, my, mz = d * n_S[i, 0], d * n_S[i, 1], d * n_S[i, 2]
        row = (nx, ny, nz, my * nz - mz * ny, mz * nx - mx * nz, mx * ny - my * nx)
        if exact:
            beta = -1.0 / (nx * n_S[i, 0] + ny * n_S[i, 1] + nz * n_S[i, 2])
            for j in range(6):
                L[i, j] = row[j] * beta
        else:
            for j in range(6):
                L[i, j] = row[j]
