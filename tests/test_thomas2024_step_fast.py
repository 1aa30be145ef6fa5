"""The faster thomas2024 controller step (``Thomas2024Controller.step``, about 100 -> 75 us
with DAQP in cases 1 and 3) returns what the code before it returned, to the bit.

Each replaced piece is compared with a verbatim copy of the code before the change (the
``*_before`` references below), on seeded random data, on edge values (zeros, signed zeros,
NaN, inf, huge and tiny values, other dtypes, layouts and shapes, the QP backends' statuses)
and on replayed states of the committed runs; errors are compared by type and message.
Timings are not tested (``make bench`` measures them).

- ``Intrinsics.to_normalized``: a compiled loop for (N, 2) pixels;
- ``ibvs_objective`` (``+ mu I`` compiled) and ``cbf_inequalities`` (rows written into the
  caller's arrays, right-hand sides compiled);
- ``PointFeatureJacobian``: ``feature_jacobian(interaction_matrix_points(...))`` with ``L``
  filled in a buffer by a compiled loop;
- ``QPSolver.solve``: the data filled and checked in one compiled call, the solution's
  finiteness too; ``_DaqpBackend.solve`` copies ``C`` with ``ndarray.copy``;
- ``CBFQPController.step`` and ``Thomas2024Controller.step`` built on them.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from test_thomas2024_speed import _random_problem, replayed_inputs

import experiments.thomas2024.config as C
from experiments.thomas2024 import scene as sc
from experiments.thomas2024.run import CAMERA_LINK, StepOutput, Thomas2024Controller, build
from repro.control import kernels
from repro.control import qp as Q
from repro.control.cbf_qp import (
    CBFQPController,
    CBFQPResult,
    Inequalities,
    Objective,
    cbf_inequalities,
    ibvs_objective,
)
from repro.control.proximity_features import ring_interaction_matrix
from repro.control.qp import (
    _CERTIFIED,
    QPProblem,
    QPSolution,
    QPSolver,
    QPStatus,
    _as_dense,
    _bounds_consistent,
    _DaqpBackend,
    _Dense,
    _finite_or_zero,
    _is_f64,
    _kkt_full,
    _RawResult,
    all_finite,
    lower_multipliers,
)
from repro.errors import NonFiniteInputError, SensorError
from repro.geometry import inv_T, make_T, rot_x, rot_y, rot_z
from repro.sensors.camera import Intrinsics
from repro.vision.features import twist_transform
from repro.vision.ibvs import PointFeatureJacobian
from repro.vision.pose import point_depths

RESULTS = Path(__file__).parents[1] / "results"
#: the edge inputs made here (float32 copies of huge values); the functions' own warnings
#: are recorded and compared (:func:`outcome`)
pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered in cast",
                                        "ignore:invalid value encountered in cast")
SPECIAL = (0.0, -0.0, 1e-310, -1e-300, 1.0, -3.5, 1e150, -1e200, 1e308, -1e308,
           np.inf, -np.inf, np.nan)


def same(a: Any, b: Any) -> bool:
    """The same bits: shapes, dtypes and bytes (NaN == NaN, 0.0 != -0.0); floats too."""
    if isinstance(a, float) or isinstance(b, float):
        return type(a) is type(b) and np.float64(a).tobytes() == np.float64(b).tobytes()
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def outcome(f: Any, *args: Any) -> tuple[str, Any, list[tuple[type, str]]]:
    """``("ok", result, warnings)`` or ``("raised", (type, message), warnings)``: NumPy's
    warnings (e.g. of an overflow) are part of the behaviour compared."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result: tuple[str, Any] = ("ok", f(*args))
        except Exception as err:  # noqa: BLE001 -- compared by type and message
            result = ("raised", (type(err), str(err)))
    return (*result, [(w.category, str(w.message)) for w in caught])


def same_outcome(a: tuple[str, Any, Any], b: tuple[str, Any, Any]) -> bool:
    if a[0] != b[0] or a[2] != b[2]:
        return False
    if a[0] == "raised":
        return bool(a[1] == b[1])
    x, y = a[1], b[1]
    if isinstance(x, tuple):  # Objective, Inequalities
        return type(x) is type(y) and all(same(p, r) for p, r in zip(x, y, strict=True))
    return same(x, y)


# --------------------------------------------------------------------------------------
# References: the code before this change, verbatim but for names (and ``self`` -> ``K``)
# --------------------------------------------------------------------------------------

def to_normalized_before(K: Intrinsics, uv: np.ndarray) -> np.ndarray:
    """Intrinsics.to_normalized."""
    uv = np.asarray(uv, dtype=float)
    if (K.skew == 0.0 and K.u0 != 0.0 and uv.shape[-1:] == (2,)
            and np.count_nonzero(np.isfinite(uv)) == uv.size):
        # no skew, finite pixels: one broadcast, the same bits as the formula below (its
        # "- s y" subtracts a zero, and u - u0 is never -0 when u0 != 0)
        return (uv - np.array((K.u0, K.v0))) / np.array((K.fu, K.fv))
    y = (uv[..., 1] - K.v0) / K.fv
    return np.stack([(uv[..., 0] - K.u0 - K.skew * y) / K.fu, y], axis=-1)


def ibvs_objective_before(J_4p: np.ndarray, e_4p: np.ndarray, lambda_4p: float,
                          mu: float) -> Objective:
    n = J_4p.shape[1]
    # (ndarray.dot: the BLAS calls of @ -- syrk for J^T J, gemv --, without the matmul
    # ufunc's overhead on these small arrays; the same bits)
    G = J_4p.T.dot(J_4p)
    G.flat[:: n + 1] += mu  # + mu I (adding 0 off the diagonal changes nothing)
    return Objective(G, (lambda_4p * J_4p.T).dot(e_4p))


def cbf_inequalities_before(L_delta: np.ndarray, J_S: np.ndarray, delta: np.ndarray,
                            delta_star: float, gain: float) -> Inequalities:
    return Inequalities(L_delta.dot(J_S), -gain * (delta - delta_star))  # .dot: @ for 2-D


def _all_finite_before(a: np.ndarray) -> bool:  # repro.vision.ibvs._all_finite
    return bool(np.count_nonzero(np.isfinite(a)) == a.size)


def _require_finite_before(name: str, a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if not _all_finite_before(a):
        bad = np.argwhere(~np.isfinite(a)).tolist()
        raise NonFiniteInputError(f"{name} must be finite; non-finite entries at {bad}")
    return a


def _matrix_before(name: str, a: np.ndarray, rows: int | None, cols: int | None
                   ) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or (rows is not None and a.shape[0] != rows) or (
            cols is not None and a.shape[1] != cols):
        want = f"({'k' if rows is None else rows}, {'n' if cols is None else cols})"
        raise ValueError(f"{name} must have shape {want}, got {a.shape}")
    return _require_finite_before(name, a)


def feature_jacobian_before(L_s: np.ndarray, cV_e: np.ndarray, eJ_e: np.ndarray
                            ) -> np.ndarray:
    L_s = _matrix_before("L_s", L_s, None, 6)
    cV_e = _matrix_before("cV_e", cV_e, 6, 6)
    eJ_e = _matrix_before("eJ_e", eJ_e, 6, None)
    return L_s @ (cV_e @ eJ_e)


def _interaction_matrix_small_before(xy: np.ndarray, Z: np.ndarray) -> np.ndarray | None:
    inf = math.inf
    rows: list[tuple[float, ...]] = []
    for (x, y), z in zip(xy.tolist(), Z.tolist(), strict=True):
        if not (0.0 < z < inf and -inf < x < inf and -inf < y < inf):
            return None
        inv_z = 1.0 / z
        rows.append((-inv_z, 0.0, x * inv_z, x * y, -(1.0 + x * x), y))
        rows.append((0.0, -inv_z, y * inv_z, 1.0 + y * y, -x * y, -x))
    return np.array(rows, dtype=float).reshape(-1, 6)


def interaction_matrix_points_before(xy: np.ndarray, Z: np.ndarray) -> np.ndarray:
    xy = np.asarray(xy, dtype=float)
    Z = np.asarray(Z, dtype=float).reshape(-1)
    if xy.ndim != 2 or xy.shape[1] != 2 or Z.shape[0] != xy.shape[0]:
        raise ValueError(f"need xy (N, 2) and Z (N,), got {xy.shape} and {Z.shape}")
    if xy.shape[0] <= 16:
        L = _interaction_matrix_small_before(xy, Z)
        if L is not None:
            return L
    bad = ~(np.isfinite(Z) & (Z > 0) & np.all(np.isfinite(xy), axis=1))
    if np.any(bad):
        idx = np.flatnonzero(bad).tolist()
        raise SensorError(f"interaction matrix needs finite xy and Z > 0; bad points {idx}: "
                          f"xy={xy[bad].tolist()}, Z={Z[bad].tolist()}")
    x, y = xy[:, 0], xy[:, 1]
    inv_z = 1.0 / Z
    L = np.zeros((x.size, 2, 6))
    L[:, 0, 0] = -inv_z
    L[:, 0, 2] = x * inv_z
    L[:, 0, 3] = x * y
    L[:, 0, 4] = -(1.0 + x * x)
    L[:, 0, 5] = y
    L[:, 1, 1] = -inv_z
    L[:, 1, 2] = y * inv_z
    L[:, 1, 3] = 1.0 + y * y
    L[:, 1, 4] = -x * y
    L[:, 1, 5] = -x
    return L.reshape(-1, 6)


class DaqpBefore(_DaqpBackend):
    """_DaqpBackend.solve before the change."""

    def solve(self, d: _Dense) -> _RawResult:
        n, m = self.n, self.m
        # The Model keeps pointers to what it is given: only arrays of this call (d.H is
        # already one, d.g and d.C may be the caller's).
        k = n + m
        blower, bupper = d.bounds[:k], d.bounds[k:]  # [lb; l], [ub; u]
        f, A = d.g.copy(), np.array(d.C, dtype=float, order="C")
        # QPSolver.solve has refused NaN bounds, l = +inf and u = -inf: equal bounds are finite
        eq = blower == bupper
        eq_key = eq.tobytes()
        if self._model is None or not self.warm_start or eq_key != self._eq:
            model = self._daqp.Model()
            sense = np.where(eq, Q._DAQP_EQUALITY, 0).astype(np.intc)
            flag, _ = model.setup(d.H, f, A, bupper, blower, sense)
            if flag < 0:  # setup rejected the data (e.g. a non-convex H)
                self.reset()
                return _RawResult(np.zeros(n), np.zeros(m), np.zeros(n), "failed", 0, 0)
            model.settings = {"primal_tol": self.eps_abs, "iter_limit": self.max_iter}
            self._model, self._eq = model, eq_key
        elif self._model.update(H=d.H, f=f, A=A, bupper=bupper, blower=blower) < 0:
            self.reset()
            return _RawResult(np.zeros(n), np.zeros(m), np.zeros(n), "failed", 0, 0)
        x, _, exitflag, info = self._model.solve()
        status = Q._DAQP_STATUS.get(int(exitflag), "failed")
        lam = info["lam"]
        if not _is_f64(lam, (n + m,)):
            lam = np.asarray(lam, dtype=float).reshape(-1)
        iterations = int(info["iterations"])  # equals iter_limit on EXIT_ITERLIMIT
        if status == "solved" and _is_f64(x, (n,)) and lam.shape == (n + m,):
            # daqp returns fresh arrays (copies of its buffers): as they are, QPSolver._attempt
            # checks that they are finite before it accepts them (certifies_kkt)
            return _RawResult(x, lam[n:], lam[:n], status, iterations, iterations)
        return _RawResult(
            x=_finite_or_zero(x, n),
            z=_finite_or_zero(lam[n:], m),
            z_box=_finite_or_zero(lam[:n], n),
            status=status,
            iterations=iterations,
            inner_iterations=iterations,
        )


class QPSolverBefore(QPSolver):
    """QPSolver.solve and _attempt before the change (DAQP: its backend before it)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if self.solver == "daqp":
            b = self._backend
            self._backend = DaqpBefore(b.n, b.m, b.eps_abs, b.max_iter,  # type: ignore
                                       b.warm_start, self.max_iter_in)  # type: ignore

    def solve(self, problem: QPProblem) -> QPSolution:
        t0 = Q.time.perf_counter()
        d = _as_dense(problem, self.n, self.m)
        k = self.m + self.n
        attempts = total = 0
        if not all_finite(d.H, d.g, d.C):
            raw, status, kkt = self._trivial(d, "failed")
        elif not _bounds_consistent(d.bounds[:k], d.bounds[k:]):
            # some l > u, a NaN bound, or l = +inf or u = -inf (no x satisfies the row;
            # OSQP would raise on it)
            raw, status, kkt = self._trivial(
                d, "failed" if np.isnan(d.bounds).any() else "infeasible")
        else:
            was_warm = self._backend.is_warm
            raw, status, kkt = self._attempt(d)
            attempts, total = 1, raw.iterations
            # A warm start can also stall a solvable problem (proxsuite: max_iter, or a
            # false "infeasible") when the previous QP was very different: retry cold.
            if status != "solved" and was_warm:
                self.cold_retries += 1
                self._backend.reset()
                raw, status, kkt = self._attempt(d)
                attempts, total = 2, total + raw.iterations
        if status != "solved":
            self._backend.reset()  # never warm-start from a failed iterate
        return QPSolution(  # x, z, z_box, status, iterations, solve_time_s, primal_residual,
            # dual_residual, inner_iterations, total_iterations, attempts (positional: cheaper)
            raw.x, raw.z, raw.z_box, status, raw.iterations, Q.time.perf_counter() - t0,
            kkt.primal_infeasibility, kkt.stationarity, raw.inner_iterations, total, attempts)

    def _attempt(self, d: _Dense) -> tuple[_RawResult, QPStatus, Q._KKT]:
        raw = self._backend.solve(d)
        if self._certified and raw.status == "solved":
            if all_finite(raw.x, raw.z, raw.z_box):
                if raw.iterations <= self.max_iter:
                    return raw, "solved", _CERTIFIED  # see _DaqpBackend.certifies_kkt
            else:  # no certificate without a finite solution: zeros instead, checked below
                n, m = self.n, self.m
                raw = raw._replace(x=_finite_or_zero(raw.x, n), z=_finite_or_zero(raw.z, m),
                                   z_box=_finite_or_zero(raw.z_box, n))
        kkt = _kkt_full(d, raw.x, raw.z, raw.z_box, self._kkt_work)
        status = raw.status
        if status == "solved" and raw.iterations > self.max_iter:
            status = "max_iter"
        elif status == "solved" and not self._kkt_ok(kkt):
            status = "failed"
        return raw, status, kkt


class CBFQPBefore(CBFQPController):
    """CBFQPController.step before the change, on QPSolverBefore."""

    def __init__(self, n: int, m: int, solver: str = "proxsuite", max_iter: int | None = None,
                 slack_weight: float = 1e4) -> None:
        super().__init__(n, m, solver, max_iter, slack_weight)
        self.hard = QPSolverBefore(n, m, solver=solver, max_iter=self.max_iter)
        self.relaxed = (QPSolverBefore(n + m, m, solver=solver, max_iter=self.relaxed_max_iter,
                                       warm_start=False) if m else None)

    def step(self, objective: Objective, ineq: Inequalities, qd_max: np.ndarray) -> CBFQPResult:
        n, m = self.n, self.m
        problem = QPProblem(
            H=objective.H, g=objective.g, C=ineq.A, l=ineq.b, u=self._u_inf,
            lb=-qd_max, ub=qd_max,
        )
        sol = self.hard.solve(problem)
        if sol.status == "solved":  # (QPSolver: a "solved" x, z, z_box are finite)
            kappa = lower_multipliers(sol)
            r = objective.g - ineq.A.T.dot(kappa)
            grad_L0 = math.sqrt(r.dot(r))  # eq. (14), u = 0; = np.linalg.norm(r)
            return CBFQPResult(sol.x, "solved", sol.status, kappa, grad_L0, self._no_slack, sol)
        if self.relaxed is not None:
            H = np.zeros((n + m, n + m))
            H[:n, :n] = objective.H
            H[n:, n:] = self.slack_weight * np.eye(m)
            relaxed = QPProblem(
                H=H, g=np.concatenate([objective.g, np.zeros(m)]),
                C=np.hstack([ineq.A, np.eye(m)]), l=ineq.b, u=np.full(m, np.inf),
                lb=np.concatenate([-qd_max, np.zeros(m)]),
                ub=np.concatenate([qd_max, np.full(m, np.inf)]),
            )
            rs = self.relaxed.solve(relaxed)
            if rs.status == "solved" and np.isfinite(rs.x).all():
                kappa = lower_multipliers(rs)
                grad_L0 = float(np.linalg.norm(objective.g - ineq.A.T @ kappa))
                return CBFQPResult(rs.x[:n], "relaxed", sol.status, kappa, grad_L0,
                                   rs.x[n:], sol, rs)
            return CBFQPResult(np.zeros(n), "failed", sol.status, np.zeros(m), float("nan"),
                               np.zeros(m), sol, rs)
        return CBFQPResult(np.zeros(n), "failed", sol.status, np.zeros(m), float("nan"),
                           np.zeros(m), sol)


def step_before(self: Thomas2024Controller, q: np.ndarray, uv: np.ndarray, found: np.ndarray,
                Z_exact: np.ndarray, readings: list) -> StepOutput:
    """Thomas2024Controller.step before the change, on the pieces before it (``self.qp`` a
    CBFQPBefore)."""
    cfg, n, m = self.config, self.n, self.m
    if np.count_nonzero(found) != np.size(found):  # a dot lost
        return StepOutput(np.zeros(n), "no_features", np.full(8, np.nan), np.zeros(m),
                          float("nan"), 0, 0.0, 0.0, "")
    x = to_normalized_before(sc.INTRINSICS, uv)
    e_4p = (x - self.s_star).ravel()
    # eJ_e of eq. (7) and J_Nj of eq. (9), one pinocchio call per link
    J = {link: self.robot.frame_jacobian(link, q) for link in self._jac_links}
    used: list[np.ndarray | None] = [None] * len(self.rings)
    if cfg.proximity:
        rows: list[Inequalities] = []
        for k, (ring, reading) in enumerate(zip(self.rings, readings, strict=True)):
            L = self._ring_L[k]
            if L is None:
                normals = (self.estimators[k].normals() if cfg.ring_models[k] != "coarse"
                           else None)
                used[k] = normals
                L = ring_interaction_matrix(self.dirs[k], reading.delta, ring.spec.radius,
                                            cfg.ring_models[k], normals)
            J_S = self._ring_Vs[k].dot(J[self._ring_links[k]])  # (9): jV_Nj J_Nj
            rows.append(cbf_inequalities_before(L, J_S, reading.delta, cfg.thresholds[k],
                                                cfg.ring_gains[k]))
        ineq = Inequalities(np.concatenate([r.A for r in rows]),
                            np.concatenate([r.b for r in rows]))
    else:
        ineq = Inequalities(np.empty((0, n)), np.empty(0))
    # Depths for L_x: PnP pose of the detected dots (render), exact geometry otherwise.
    Z = Z_exact if cfg.camera_mode == "exact" else point_depths(
        self.target_points, uv, sc.INTRINSICS.K(), self.Z_star)
    J_4p = feature_jacobian_before(interaction_matrix_points_before(x, Z), self.cV_e,
                                   J[CAMERA_LINK])  # eq. (7)
    res = self.qp.step(ibvs_objective_before(J_4p, e_4p, cfg.lambda_4p, cfg.mu), ineq,
                       self.qd_max)
    # (the slack is all zeros when the hard QP is solved)
    max_slack = float(res.slack.max()) if m and res.status != "solved" else 0.0
    return StepOutput(res.u, res.status, e_4p, res.kappa, res.grad_L0,
                      res.iterations, res.solve_time_s, max_slack, res.qp_status,
                      tuple(used))


# --------------------------------------------------------------------------------------
# Comparisons of results
# --------------------------------------------------------------------------------------

_TIMES = ("solve_time_s", "solve_s")


def same_fields(a: Any, b: Any) -> bool:
    """Field by field, the same bits (timings skipped; nested results compared too)."""
    if a is None or b is None:
        return a is b
    names = a._fields if hasattr(a, "_fields") else list(vars(a))
    assert type(a) is type(b)
    for name in names:
        if name in _TIMES:
            continue
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, QPSolution | CBFQPResult) or x is None:
            ok = same_fields(x, y)
        elif isinstance(x, tuple):  # StepOutput.normals
            ok = len(x) == len(y) and all(
                (p is None and r is None) or same(p, r) for p, r in zip(x, y, strict=True))
        elif isinstance(x, str | int) and not isinstance(x, bool):
            ok = type(x) is type(y) and x == y
        else:
            ok = same(x, y)
        if not ok:
            return False
    return True


class Recorder:
    """A QP backend that records what it is given and what it returns (and whether it was
    warm), for :class:`Replay`."""

    def __init__(self, backend: Any) -> None:
        self.backend = backend
        self.certifies_kkt = backend.certifies_kkt
        self.calls: list[tuple[bool, _Dense, _RawResult]] = []

    @property
    def is_warm(self) -> bool:
        return bool(self.backend.is_warm)

    def reset(self) -> None:
        self.backend.reset()

    def solve(self, d: _Dense) -> _RawResult:
        warm = self.is_warm
        raw = self.backend.solve(d)
        self.calls.append((warm, _Dense(*(np.array(a) for a in d)), raw))
        return raw


class Replay:
    """A QP backend that checks it is given, to the bit, what a :class:`Recorder` was given,
    and returns what it returned. proxsuite 0.8.0 rounds differently from one solver object
    to another in a process (its own allocations: two QPSolvers of the code *before* the
    change disagree on most random QPs, while a run's process repeats itself): the QP layer
    around it is compared on the same backend results."""

    def __init__(self, recorder: Recorder) -> None:
        self.recorder, self.i = recorder, 0
        self.certifies_kkt = recorder.certifies_kkt

    @property
    def is_warm(self) -> bool:
        calls = self.recorder.calls
        return calls[self.i][0] if self.i < len(calls) else False

    def reset(self) -> None:
        pass

    def solve(self, d: _Dense) -> _RawResult:
        _, given, raw = self.recorder.calls[self.i]
        self.i += 1
        assert all(same(a, b) for a, b in zip(d, given, strict=True))
        return raw


def pair(new: QPSolver | None, old: QPSolver | None) -> None:
    """Let ``old`` replay the backend of ``new`` (see :class:`Replay`) if it is proxsuite."""
    if new is None or old is None or new.solver != "proxsuite":
        return
    rec = Recorder(new._backend)
    new._backend, old._backend = rec, Replay(rec)  # type: ignore[assignment]


# --------------------------------------------------------------------------------------
# Intrinsics.to_normalized
# --------------------------------------------------------------------------------------

INTRINSICS = (sc.INTRINSICS, Intrinsics.centered(640, 480, 500.0),
              Intrinsics(640, 480, 431, 429, 322, 236),  # integers: int arrays
              Intrinsics(640, 480, 431.0, 429.5, 322.3, 236.8, skew=0.7),
              Intrinsics(640, 480, 431.0, 429.5, 0.0, 236.8),  # u0 = 0
              Intrinsics(64, 48, 1e-300, 1e300, 1e308, -1e308))


def _pixels(rng: np.random.Generator, K: Intrinsics) -> list[Any]:
    N = int(rng.integers(0, 9))
    uv = rng.uniform(-50.0, 700.0, (N, 2))
    whole = rng.random((N, 2)) < 0.3
    uv[whole] = np.round(uv[whole])
    if N:
        uv[rng.integers(N)] = (K.u0, K.v0)  # exact zeros
        uv[rng.random((N, 2)) < 0.15] = rng.choice(SPECIAL)
    return [uv, uv.tolist(), uv.astype(np.float32), np.asfortranarray(uv), uv[::2],
            uv.reshape(-1)[:2] if N else uv, np.round(uv).astype(int) if np.isfinite(uv).all()
            else uv, np.repeat(uv[None], 3, axis=0), np.zeros((N, 3)), _readonly(uv)]


def _readonly(a: np.ndarray) -> np.ndarray:
    a = a.copy()
    a.flags.writeable = False
    return a


def test_to_normalized_equals_the_code_before() -> None:
    rng = np.random.default_rng(0)
    for K in INTRINSICS:
        for _ in range(300):
            for uv in _pixels(rng, K):
                got = outcome(K.to_normalized, uv)
                assert same_outcome(got, outcome(to_normalized_before, K, uv)), (K, uv)
    x = sc.INTRINSICS.to_normalized(np.array([[1.0, 2.0], [3.0, 4.0]]))
    assert x.flags.writeable and x.flags.owndata  # a fresh array each call
    assert not same(x, sc.INTRINSICS.to_normalized(np.array([[1.0, 2.0], [3.0, 5.0]])))


# --------------------------------------------------------------------------------------
# ibvs_objective, cbf_inequalities
# --------------------------------------------------------------------------------------

def _matrix(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    a = rng.normal(size=shape) * rng.choice([1e-300, 1e-3, 1.0, 1e3, 5e153, 1e160])
    a[rng.random(shape) < 0.1] = 0.0
    a[rng.random(shape) < 0.05] = -0.0
    if rng.random() < 0.2:
        a[rng.random(shape) < 0.1] = rng.choice(SPECIAL)
    return a


def test_ibvs_objective_equals_the_code_before() -> None:
    rng = np.random.default_rng(1)
    mus: tuple[Any, ...] = (0.01, 0.0, -0.0, 1e-300, 1e308, -1e308, np.inf, np.nan, 0, 3,
                            True, np.float64(0.5), np.float32(0.25), np.array(0.01))
    for _ in range(400):
        n, k = int(rng.integers(0, 9)), int(rng.integers(1, 10))
        J, e = _matrix(rng, (k, n)), rng.normal(size=k)
        lam = float(rng.choice([0.0, -0.0, 1.0, 0.5, np.inf]))
        for JJ in (J, J.astype(np.float32), np.asfortranarray(J), J[:, ::-1], _readonly(J)):
            mu = mus[int(rng.integers(len(mus)))]
            got = outcome(ibvs_objective, JJ, e, lam, mu)
            assert same_outcome(got, outcome(ibvs_objective_before, JJ, e, lam, mu)), (JJ, mu)


def test_cbf_inequalities_equal_the_code_before_in_place_or_not() -> None:
    """Into a whole QP's rows (a ring's block of fresh (m, n) and (m,) arrays) or on their
    own: the rows before the change; rows that do not fit go to fresh arrays."""
    rng = np.random.default_rng(2)
    specials: tuple[Any, ...] = (0.2, 0, 1, -0.0, 0.0, np.inf, np.nan, 1e308, np.float64(0.05),
                                 np.float32(0.05), np.int64(2), np.full(3, 0.1))
    for _ in range(600):
        m, n = int(rng.integers(1, 20)), int(rng.integers(1, 9))
        L, J_S = _matrix(rng, (m, 6)), _matrix(rng, (6, n))
        delta = rng.uniform(0.0, 0.5, m) * rng.choice([1.0, 1e308])
        delta[rng.random(m) < 0.1] = rng.choice(SPECIAL)
        ds = specials[int(rng.integers(len(specials)))]
        gain = specials[int(rng.integers(len(specials)))]
        if isinstance(ds, np.ndarray) and ds.shape != (m,) and isinstance(gain, np.ndarray):
            gain = 1.0
        variants = [(L, J_S, delta), (L, J_S, delta.astype(np.float32)), (L, J_S, delta[:-1]),
                    (L.astype(np.float32), J_S, delta), (L[:, :5], J_S, delta),
                    (L, J_S.T.copy().T, delta), (L[::-1], J_S, delta[::-1]),
                    (L, J_S, list(delta))]
        for LL, JJ, dd in variants:
            want = outcome(cbf_inequalities_before, LL, JJ, dd, ds, gain)
            assert same_outcome(outcome(cbf_inequalities, LL, JJ, dd, ds, gain), want)
            top = int(rng.integers(0, 4))
            A, b = np.empty((top + m + 2, n)), np.empty(top + m + 2)
            out = (A[top:top + m], b[top:top + m])
            got = outcome(cbf_inequalities, LL, JJ, dd, ds, gain, out)
            assert same_outcome(got, want), (LL, JJ, dd, ds, gain)
            if (got[0] == "ok" and isinstance(dd, np.ndarray) and dd.dtype == np.float64
                    and dd.shape == (m,) and LL.dtype == np.float64 and LL.shape == (m, 6)
                    and isinstance(ds, float | int) and isinstance(gain, float | int)):
                assert got[1].A is out[0] and got[1].b is out[1]  # written in place


# --------------------------------------------------------------------------------------
# The feature Jacobian of eq. (7)
# --------------------------------------------------------------------------------------

def _cV_e(rng: np.random.Generator) -> np.ndarray:
    T = make_T(rot_z(rng.uniform(-3, 3)) @ rot_y(rng.uniform(-3, 3)) @ rot_x(rng.uniform(-3, 3)),
               rng.normal(size=3) * 0.1)
    return twist_transform(inv_T(T))


def _feature_jacobian_of_points_before(cV_e: np.ndarray, xy: np.ndarray, Z: np.ndarray,
                                       eJ_e: np.ndarray) -> np.ndarray:
    """What the step called before the change (eq. (7))."""
    return feature_jacobian_before(interaction_matrix_points_before(xy, Z), cV_e, eJ_e)


def test_point_feature_jacobian_equals_the_code_before() -> None:
    """Valid points, points at and beyond the bounds of the compiled loop, lost points,
    non-finite Jacobians, other shapes and types: the result, or the error, of
    ``feature_jacobian(interaction_matrix_points(...))`` before the change."""
    rng = np.random.default_rng(3)
    edges = (0.0, -0.0, 1e150, -1e150, 1.0000000000000002e150, 1e151, -1e200, 1e-320,
             np.inf, -np.inf, np.nan)
    z_edges = (1e-150, 9.999999999999999e-151, 1e-160, 1e-310, 0.0, -0.0, -1.0, 1e308,
               np.inf, np.nan)
    for _ in range(40):
        cV_e = _cV_e(rng)
        fj = PointFeatureJacobian(cV_e, 4)
        for _ in range(60):
            xy = rng.uniform(-0.8, 0.8, (4, 2))
            Z = rng.uniform(0.05, 2.0, 4)
            eJ = rng.normal(size=(6, 7))
            r = rng.random()
            if r < 0.3:
                xy[rng.integers(4), rng.integers(2)] = rng.choice(edges)
            elif r < 0.5:
                Z[rng.integers(4)] = rng.choice(z_edges)
            elif r < 0.6:
                eJ[rng.integers(6), rng.integers(7)] = rng.choice(SPECIAL)
            for args in ((xy, Z, eJ), (xy.astype(np.float32), Z, eJ), (xy, Z[:, None], eJ),
                         (xy[:3], Z[:3], eJ), (xy, Z, eJ[:5]), (xy, Z, eJ[:, :3]),
                         (xy.tolist(), list(Z), eJ), (xy, Z, np.asfortranarray(eJ))):
                want = outcome(_feature_jacobian_of_points_before, cV_e, *args)
                assert same_outcome(outcome(fj, *args), want), args
    bad = _cV_e(rng)
    bad[2, 4] = np.nan  # checked once: the call still raises as before
    xy, Z, eJ = rng.uniform(-0.5, 0.5, (4, 2)), rng.uniform(0.1, 1, 4), rng.normal(size=(6, 7))
    with pytest.raises(NonFiniteInputError):
        PointFeatureJacobian(bad, 4)(xy, Z, eJ)
    fj = PointFeatureJacobian(_cV_e(rng), 4)
    J1 = fj(xy, Z, eJ)
    kept = J1.copy()
    fj(xy + 0.1, Z, eJ)  # its buffer is reused; the result handed out is not
    assert same(J1, kept) and not same(J1, fj(xy + 0.1, Z, eJ))
    with pytest.raises(ValueError):
        fj.cV_e[0, 0] = 1.0  # the constant the checks were made on cannot change


def test_the_interaction_matrix_kernel_equals_the_numpy_rows() -> None:
    """The compiled loop against the vectorised rows (N > 16) and the small-N loop, signed
    zeros and subnormals included, for N from 1 to 40."""
    from repro.vision.point_kernels import fill_interaction_matrix

    rng = np.random.default_rng(4)
    for _ in range(2000):
        N = int(rng.integers(1, 41))
        xy = rng.normal(size=(N, 2)) * rng.choice([1e-310, 1e-5, 1.0, 1e3, 1e100, 1e149],
                                                  size=(N, 2))
        xy[rng.random((N, 2)) < 0.2] = rng.choice([0.0, -0.0, 1e150, -1e150])
        Z = rng.uniform(0.01, 3.0, N) * rng.choice([1e-148, 1e-3, 1.0, 1e300], size=N)
        L = np.full((2 * N, 6), np.nan)
        if fill_interaction_matrix(xy, Z, L):
            assert same(L, interaction_matrix_points_before(xy, Z))
        else:
            assert (Z < 1e-150).any() or (np.abs(xy) > 1e150).any()


# --------------------------------------------------------------------------------------
# QPSolver.solve, the DAQP backend, CBFQPController.step
# --------------------------------------------------------------------------------------

def _problem(rng: np.random.Generator, n: int, m: int) -> QPProblem:
    """A CBF-like QP, feasible by construction, rows mostly one-sided
    (tests/test_thomas2024_speed.py's), often changed to stress a check or a status."""
    p = _random_problem(rng, n, m)
    return _perturbed(rng, p) if rng.random() < 0.5 else p


def _perturbed(rng: np.random.Generator, p: QPProblem) -> QPProblem:
    H, g, C, l, u, lb, ub = (None if a is None else np.array(a) for a in p)
    assert H is not None and g is not None and C is not None and l is not None
    assert u is not None and lb is not None and ub is not None
    n, m = g.size, l.size
    r = int(rng.integers(0, 16))
    if r == 0:
        H[rng.integers(n), rng.integers(n)] = rng.choice(SPECIAL)
    elif r == 1 and m:
        C[rng.integers(m), rng.integers(n)] = rng.choice(SPECIAL)
    elif r == 2:
        g[rng.integers(n)] = rng.choice(SPECIAL)
    elif r == 3 and m:
        i = rng.integers(m)
        l[i], u[i] = rng.choice(SPECIAL), rng.choice(SPECIAL)
    elif r == 4:
        i = rng.integers(n)
        lb[i], ub[i] = rng.choice(SPECIAL), rng.choice(SPECIAL)
    elif r == 5 and m:
        u[: m // 2] = l[: m // 2]  # equality rows
    elif r == 6 and m > 1:
        C[1] = -C[0]
        l[0], l[1], u[0], u[1] = 1.0, 1.0, np.inf, np.inf  # infeasible
    elif r == 7:
        H = H + np.triu(rng.normal(size=(n, n)), 1) * 1e-3  # not symmetric
        H[0, 1] = -0.0
    elif r == 8:
        return QPProblem(H, g, None if rng.random() < 0.5 else C, None, None,
                         None if rng.random() < 0.5 else lb, None)
    elif r == 9:
        return QPProblem(H.tolist(), list(g), C.tolist(), list(l), list(u), list(lb), list(ub))
    elif r == 10:
        return QPProblem(np.asfortranarray(H), g[::-1].copy()[::-1], np.asfortranarray(C),
                         _readonly(l), _readonly(u), lb, _readonly(ub))
    elif r == 11:
        return QPProblem(H.astype(np.float32), g.astype(np.float32), C.astype(np.float32), l,
                         u, lb, ub)
    elif r == 12:
        H *= 1e306  # H + H.T overflows
    elif r == 13:
        lb[0] = ub[0] = 0.1  # a fixed variable
    elif r == 14:
        return QPProblem(H, g[:-1], C, l, u, lb, ub)  # a shape error
    elif r == 15:
        return QPProblem(H.astype(int), g.astype(int), C, l, u, lb, ub)
    return QPProblem(H, g, C, l, u, lb, ub)


@pytest.mark.parametrize("solver", Q.SOLVERS)
@pytest.mark.parametrize("max_iter", [200, 2])
def test_qp_solver_equals_the_code_before(solver: str, max_iter: int) -> None:
    """A warm-started sequence of QPs, valid, non-finite, inconsistent, infeasible, with
    equality rows, None parts, lists, other dtypes and layouts, wrong shapes: every field of
    every solution (but its wall time), or the error, as before; and the cold retries."""
    rng = np.random.default_rng(5)
    n, m = 7, 12
    new, old = QPSolver(n, m, solver, max_iter=max_iter), QPSolverBefore(n, m, solver,
                                                                          max_iter=max_iter)
    pair(new, old)
    statuses = set()
    for _ in range(250 if solver != "osqp" else 80):
        p = _problem(rng, n, m)
        got, want = outcome(new.solve, p), outcome(old.solve, p)
        assert got[0] == want[0] and got[2] == want[2], p
        if got[0] == "raised":
            assert got[1] == want[1]
            continue
        assert same_fields(got[1], want[1]), (p, got[1], want[1])
        statuses.add(got[1].status)
        assert new.cold_retries == old.cold_retries
    assert {"failed", "infeasible"} <= statuses
    assert ("solved" if max_iter == 200 else "max_iter") in statuses


@pytest.mark.parametrize("solver", ["proxsuite", "osqp", "quadprog"])
def test_qp_solver_without_rows_equals_the_code_before(solver: str) -> None:
    rng = np.random.default_rng(6)
    new, old = QPSolver(4, 0, solver), QPSolverBefore(4, 0, solver)
    pair(new, old)
    for _ in range(60):
        p = _problem(rng, 4, 0)
        got, want = outcome(new.solve, p), outcome(old.solve, p)
        assert got[0] == want[0] and got[2] == want[2]
        assert got[1] == want[1] if got[0] == "raised" else same_fields(got[1], want[1])


def test_the_data_kernel_is_the_checks_before() -> None:
    """plain_dense: True exactly when H, g, C are finite (after the symmetrisation) and the
    bounds consistent, and then the symmetrised H and the stacked bounds of _as_dense."""
    rng = np.random.default_rng(7)
    n, m = 5, 6
    seen = set()
    for _ in range(3000):
        p = _problem(rng, n, m)
        H, g, C, l, u, lb, ub = p
        if not all(isinstance(a, np.ndarray) and a.dtype == np.float64 for a in p) or \
                g.shape != (n,):
            continue
        with np.errstate(over="ignore"):  # (H + H.T may overflow: then not plain)
            d = _as_dense(p, n, m)
        k = n + m
        old = all_finite(d.H, d.g, d.C) and _bounds_consistent(d.bounds[:k], d.bounds[k:])
        H_sym, bounds = np.full((n, n), np.nan), np.full(2 * k, np.nan)
        got = kernels.plain_dense(H, g, C, l, u, lb, ub, H_sym, bounds)
        assert got == old
        seen.add(got)
        if got:
            assert same(H_sym, d.H) and same(bounds, d.bounds)
    assert seen == {True, False}


def test_the_solution_check_is_all_finite() -> None:
    rng = np.random.default_rng(8)
    for _ in range(500):
        x, z, zb = (rng.choice(SPECIAL[:6] + SPECIAL[-3:], int(rng.integers(0, 5)))
                    for _ in range(3))
        assert kernels.all_finite3(x, z, zb) == all_finite(x, z, zb)


def _relaxable(rng: np.random.Generator, n: int, m: int) -> tuple[Objective, Inequalities,
                                                                  np.ndarray]:
    J = rng.normal(size=(8, n))
    obj = ibvs_objective_before(J, rng.normal(size=8) * 0.1, 0.5, 0.01)
    A, b = rng.normal(size=(m, n)), rng.uniform(-0.3, 0.1, m)
    r = rng.random()
    if r < 0.25 and m > 1:
        A[1], b[0], b[1] = -A[0], 0.2, 0.2  # the hard QP is infeasible: relaxed
    elif r < 0.3:
        b[0] = np.nan  # failed
    elif r < 0.35:
        obj = Objective(obj.H, obj.g * np.inf)
    return obj, Inequalities(A, b), rng.uniform(0.5, 2.0, n)


@pytest.mark.parametrize("solver", Q.SOLVERS)
def test_cbf_qp_step_equals_the_code_before(solver: str) -> None:
    """Solved, relaxed and failed steps, warm started in sequence: every field of the
    result and of its solutions as before."""
    rng = np.random.default_rng(9)
    n, m = 7, 10
    new, old = CBFQPController(n, m, solver), CBFQPBefore(n, m, solver)
    pair(new.hard, old.hard)
    pair(new.relaxed, old.relaxed)
    statuses = set()
    for _ in range(120 if solver != "osqp" else 40):
        obj, ineq, qd_max = _relaxable(rng, n, m)
        got, want = new.step(obj, ineq, qd_max), old.step(obj, ineq, qd_max)
        assert same_fields(got, want), (got, want)
        statuses.add(got.status)
    assert statuses == {"solved", "relaxed", "failed"}


# --------------------------------------------------------------------------------------
# The controller step on replayed states
# --------------------------------------------------------------------------------------

def _replay(cfg: C.Thomas2024Config, df: pd.DataFrame, tmp: Path,
            new: Thomas2024Controller | None = None
            ) -> tuple[Thomas2024Controller, list[StepOutput]]:
    """Build a fresh controller and step it on the trace's states (robot, hand, sensors
    reset to each row); ``new``: a controller so stepped, then this one's step and its
    pieces are those before the change (replaying its proxsuite, see :func:`pair`). Two
    lost dots are made up on the way."""
    ep, ctrl = build(cfg, tmp)
    before = new is not None
    if new is not None:
        ctrl.qp = CBFQPBefore(ctrl.n, ctrl.m, solver=cfg.qp_solver, max_iter=cfg.qp_max_iter)
        for a, b in ((new.qp.hard, ctrl.qp.hard), (new.qp.relaxed, ctrl.qp.relaxed)):
            if a is not None and isinstance(a._backend, Recorder):
                assert b is not None
                b._backend = Replay(a._backend)  # type: ignore[assignment]
    elif cfg.qp_solver == "proxsuite":
        for qp in (ctrl.qp.hard, ctrl.qp.relaxed):
            if qp is not None:
                qp._backend = Recorder(qp._backend)  # type: ignore[assignment]
    outs = []
    try:
        for k, q, uv, found, Z, readings in replayed_inputs(ep, df):
            if k in (5, 6):
                found = found.copy()
                found[k - 5] = False
            outs.append(step_before(ctrl, q, uv, found, Z, readings) if before
                        else ctrl.step(q, uv, found, Z, readings))
    finally:
        ep.scene.close()
    return ctrl, outs


@pytest.mark.parametrize(("case", "overrides"), [
    ("case1", {"qp_solver": "daqp"}), ("case3", {"qp_solver": "daqp"}),
    ("case1", {}), ("case3", {"camera_mode": "render"}),
    ("case2", {"ring_models": ("exact", "beta1")}), ("case2", {"qp_solver": "quadprog"}),
    ("case1_no_proximity", {})])
def test_controller_step_equals_the_code_before(case: str, overrides: dict[str, Any],
                                                tmp_path: Path) -> None:
    """The first 3 s of a committed run, one state in two (case 3's hand where it was):
    every field of every step's output (but the QP's wall time) as the step before the
    change gave it, step after step (warm starts, estimated normals, lost dots)."""
    df = pd.read_csv(RESULTS / "thomas2024" / case / "trace.csv").iloc[:90:2]
    cls = {"case1": C.Case1Config, "case2": C.Case2Config, "case3": C.Case3Config,
           "case1_no_proximity": C.Case1NoProximityConfig}[case]
    cfg = replace(cls(), **{"camera_mode": "exact", **overrides})
    ctrl, got = _replay(cfg, df, tmp_path / "new")
    want = _replay(cfg, df, tmp_path / "old", ctrl)[1]
    assert len(got) == len(df) > 30
    assert {o.status for o in got} >= {"solved", "no_features"}
    if "ring_models" in overrides:  # estimated normals reached the QP
        assert any(nr is not None and np.isfinite(nr).all(axis=1).any()
                   for o in got for nr in o.normals)
    for a, b in zip(got, want, strict=True):
        assert same_fields(a, b), (a, b)


def test_the_step_hands_out_fresh_rows(tmp_path: Path) -> None:
    """The QP's rows are new arrays every step: a QP kept from one step does not change
    with the next."""
    df = pd.read_csv(RESULTS / "thomas2024" / "case1" / "trace.csv").iloc[:20:4]
    ep, ctrl = build(replace(C.Case1Config(), camera_mode="exact", qp_solver="daqp"),
                     tmp_path)
    kept: list[tuple[QPProblem, QPProblem]] = []
    solve = ctrl.qp.hard.solve

    def recording(problem: QPProblem) -> QPSolution:
        kept.append((problem, QPProblem(*(np.array(a) for a in problem))))
        return solve(problem)

    ctrl.qp.hard.solve = recording  # type: ignore[method-assign]
    rig, scene = ep.cameras[0], ep.scene
    target = scene[rig.target]
    assert target.dot_target is not None
    try:
        for q in df[[f"q{i}" for i in range(1, 8)]].to_numpy(dtype=float):
            rig.robot.reset(q)
            uv, found, Z = rig.camera.measure(scene.render_client, rig.pose(q),
                                              target.dot_target, target.T_world)
            ctrl.step(q, uv, found, Z, [s.read(0.0, {rig.robot.name: q}) for s in ep.sensors])
    finally:
        scene.close()
    assert len(kept) == len(df)
    for problem, copy in kept:
        assert all(same(a, b) for a, b in zip(problem, copy, strict=True))
    assert len({id(p.C) for p, _ in kept}) == len(kept)


def test_readings_that_do_not_fit_the_rows_give_what_they_gave(tmp_path: Path) -> None:
    """A ring's distances of another dtype, length or type, or non-finite: the step's
    result, or its error, as before (rows concatenated, or NumPy's operations in place)."""
    df = pd.read_csv(RESULTS / "thomas2024" / "case1" / "trace.csv").iloc[[40]]
    cfg = replace(C.Case1Config(), camera_mode="exact", qp_solver="daqp")
    ep, new = build(cfg, tmp_path / "new")
    old = build(cfg, tmp_path / "old")[1]
    rig, scene = ep.cameras[0], ep.scene
    target = scene[rig.target]
    assert target.dot_target is not None
    q = df[[f"q{i}" for i in range(1, 8)]].to_numpy(dtype=float)[0]
    try:
        rig.robot.reset(q)
        uv, found, Z = rig.camera.measure(scene.render_client, rig.pose(q), target.dot_target,
                                          target.T_world)
        readings = [s.read(0.0, {rig.robot.name: q}) for s in ep.sensors]
        d = readings[1].delta
        nan = d.copy()
        nan[3] = np.nan
        for delta in (d.astype(np.float32), d[:-1], np.append(d, 0.1), list(d), nan,
                      np.full_like(d, np.inf), d * 1e308):
            changed = [readings[0], replace(readings[1], delta=delta)]
            new.qp = CBFQPController(new.n, new.m, "daqp", cfg.qp_max_iter)  # cold, both
            old.qp = CBFQPBefore(old.n, old.m, "daqp", cfg.qp_max_iter)
            got = outcome(new.step, q, uv, found, Z, changed)
            want = outcome(step_before, old, q, uv, found, Z, changed)
            assert got[0] == want[0] and got[2] == want[2], delta
            assert got[1] == want[1] if got[0] == "raised" else same_fields(got[1], want[1])
    finally:
        scene.close()


def test_finite_is_numpy_s_isfinite_all_on_every_shape_and_layout() -> None:
    """kernels.finite: ``np.isfinite(a).all()`` on float64 arrays of every rank, contiguous
    or strided, with a NaN or an infinity anywhere, and on other dtypes (NumPy's own)."""
    from repro.control.kernels import finite

    rng = np.random.default_rng(5)
    bases = [rng.normal(size=(7,)), rng.normal(size=(6, 4)), rng.normal(size=(3, 4, 5)),
             np.array(2.0), np.empty((0,)), np.array([-0.0, 1e308])]
    for base in bases:
        views = [base, base.T, base[::2] if base.ndim else base]
        for a in views:
            assert finite(a) == bool(np.isfinite(a).all())
            for bad in (np.nan, np.inf, -np.inf):
                if a.size:
                    b = a.copy()
                    b.flat[rng.integers(a.size)] = bad
                    assert finite(b) is False
                    assert finite(b.T) is False
    assert finite(np.array([1, 2])) is True and finite(np.array([1.0, np.nan],
                                                                dtype=np.float32)) is False
