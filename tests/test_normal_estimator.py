"""The compiled pieces of the normal estimator (repro.control.normal_estimator): the 3x3
Jacobi eigen-decomposition against LAPACK, the kernel's arithmetic (no fused multiply-add,
so its rounding does not depend on the CPU), and the config's validation. The estimator's
agreement with the NumPy/LAPACK code it replaced is in tests/test_thomas2024_speed.py; its
behaviour on walls and still rings in tests/test_proximity.py."""

from __future__ import annotations

import platform
import re

import numpy as np
import pytest
from numba import njit

from repro.control.normal_estimator import (
    JACOBI_SWEEPS,
    NormalEstimator,
    NormalEstimatorConfig,
    _estimate,
    _jacobi_eig3,
)
from repro.control.proximity_features import _estimated_rows
from repro.errors import ConfigError

EPS = np.finfo(float).eps


def _eig(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lam, V = np.empty(3), np.empty((3, 3))
    _jacobi_eig3(A.copy(), lam, V, JACOBI_SWEEPS)
    return lam, V


def _matrices(rng: np.random.Generator) -> list[np.ndarray]:
    """Symmetric 3x3 test matrices: eq. (4)'s B of random point sets (full rank, rank 2:
    collinear points and the origin in a plane, rank 1), scaled from 1e-12 to 1e6, plus
    indefinite, diagonal, zero and repeated-eigenvalue ones."""
    out = []
    for _ in range(300):
        n = int(rng.integers(1, 50))
        P = rng.normal(size=(n, 3)) * rng.uniform(0.001, 1.0, 3) + rng.normal(size=3)
        if rng.random() < 0.3:  # points on a line: B of rank <= 2
            P = P[:1] + rng.normal(size=(n, 1)) * rng.normal(size=3)
        out.append(P.T @ P * 10.0 ** rng.uniform(-12, 6))
        S = rng.normal(size=(3, 3))
        out.append(S + S.T)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    out += [np.zeros((3, 3)), np.diag([3.0, -1.0, 2.0]), Q @ np.diag([2.0, 2.0, 1e-9]) @ Q.T,
            np.eye(3) * 5.0, np.outer([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])]
    return out


def test_jacobi_eigen_decomposition_matches_lapack() -> None:
    """Eigenvalues (ascending) within 8 eps |A| of LAPACK's (both are backward stable: each
    is exact for a matrix within a few eps |A|), eigenvectors orthonormal and A V = V diag
    within 8 eps |A|."""
    rng = np.random.default_rng(3)
    for A in _matrices(rng):
        lam, V = _eig(A)
        scale = max(np.abs(A).max(), np.finfo(float).tiny)
        assert np.all(np.diff(lam) >= 0)
        np.testing.assert_allclose(lam, np.linalg.eigvalsh(A), rtol=0, atol=8 * EPS * scale)
        np.testing.assert_allclose(V.T @ V, np.eye(3), rtol=0, atol=8 * EPS)
        np.testing.assert_allclose(A @ V, V * lam, rtol=0, atol=8 * EPS * scale)


def test_jacobi_keeps_a_small_eigenvalue_of_a_graded_matrix() -> None:
    """The property the degeneracy gate needs: a positive definite B whose least eigenvalue
    is 1e-13 of the largest (a noise-free fit just above the spread floor) keeps it to a few
    per cent (Jacobi's relative accuracy on graded PSD matrices)."""
    rng = np.random.default_rng(4)
    for _ in range(50):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        D = np.diag([1.0, 1e-3, 1e-13])
        A = Q @ D @ Q.T
        A = (A + A.T) / 2
        lam, _ = _eig(A)
        # |A| ~ 1: LAPACK's absolute bound alone (~1e-16) would allow 1e-3 relative error
        assert abs(lam[0] / 1e-13 - 1.0) < 0.05


def test_jacobi_stops_on_nan() -> None:
    """A NaN entry ends in NaN eigenvalues after at most the sweep cap, not a hang."""
    A = np.eye(3)
    A[0, 1] = A[1, 0] = np.nan
    lam, _ = _eig(A)
    assert np.isnan(lam).any()


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64", "aarch64", "arm64"),
                    reason="instruction names known for x86-64 and ARM64 only")
def test_kernels_are_compiled_without_fused_multiply_add() -> None:
    """numba compiles without fast-math, so LLVM neither reassociates nor contracts a * b + c
    into an FMA: the kernels round the same on every CPU (with AVX2/AVX-512 or not). Fresh,
    uncached compilations of the kernels are inspected."""
    for kernel, args in (
        (_jacobi_eig3, (np.eye(3), np.empty(3), np.empty((3, 3)), JACOBI_SWEEPS)),
        (_estimated_rows, (np.ones((2, 3)), np.ones(2), 0.1, np.ones((2, 3)), True,
                           np.zeros((2, 6)))),
    ):
        fresh = njit(error_model="numpy")(kernel.py_func)
        fresh(*args)
        asm = "".join(fresh.inspect_asm().values())
        assert "mulsd" in asm or "fmul" in asm  # scalar double products are there
        assert not re.search(r"vfn?m(add|sub)|\bfn?m(add|sub)\b", asm)


def test_estimate_is_compiled_once_for_the_estimators_types() -> None:
    """One signature: the estimator hands the kernel arrays of fixed dtypes and layouts (a
    second compilation would cost seconds per run)."""
    est = NormalEstimator(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]), 0.1,
                          NormalEstimatorConfig(history=3))
    for _ in range(5):
        est.update(np.eye(4), np.array([0.2, 0.3, 1.0]), np.array([True, True, False]))
        est.normals()
    est.update(np.eye(4).astype(np.float32), [0.2, 0.3, 1.0], [1, 1, 0])  # other input types
    est.normals()
    assert len(_estimate.signatures) == 1


@pytest.mark.parametrize("field", ["history", "neighbours"])
@pytest.mark.parametrize("value", [-1, 1.5])
def test_config_rejects_bad_counts(field: str, value: float) -> None:
    with pytest.raises(ConfigError, match=field):
        NormalEstimatorConfig(**{field: value})


@pytest.mark.parametrize("field", ["min_separation", "max_separation", "min_facing",
                                   "range_noise", "spread_sigmas", "spread_floor"])
@pytest.mark.parametrize("value", [-0.1, np.nan, np.inf])
def test_config_rejects_bad_values(field: str, value: float) -> None:
    with pytest.raises(ConfigError, match=field):
        NormalEstimatorConfig(**{field: value})


def test_bad_readings_are_refused_before_anything_is_stored() -> None:
    """A reading of the wrong length raises, and the history is what it was."""
    est = NormalEstimator(np.eye(3), 0.1, NormalEstimatorConfig(history=3))
    est.update(np.eye(4), np.array([0.2, 0.3, 1.0]), np.array([True, True, False]))
    est.update(np.eye(4), np.array([0.2, 0.3, 1.0]), np.array([True, True, False]))
    before = (est._slot, est._count, est._current)
    with pytest.raises(ValueError, match="readings"):
        est.update(np.eye(4), np.array([0.2, 0.3]), np.array([True, True]))
    assert (est._slot, est._count, est._current) == before
