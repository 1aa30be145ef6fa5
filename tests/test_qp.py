"""Tests of repro.control.qp: known solutions, CBF-like random QPs, infeasibility, warm start."""

from __future__ import annotations

import time
from typing import Any

import daqp  # exact active-set reference; dev dependency in pyproject.toml
import numpy as np
import pytest

from repro.control.qp import (
    SOLVERS,
    QPDimensionError,
    QPProblem,
    QPSolution,
    QPSolver,
    _RawResult,
    kkt_residuals,
    lower_multipliers,
)
from repro.errors import ConfigError, UnknownChoiceError

# Franka Emika Panda joint velocity limits [rad/s] (official datasheet).
V_MAX = np.array([2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26])
N_JOINTS, N_SENSORS = 7, 36
#: Exact (active-set) backends: answers to rounding, infeasibility certified.
ACTIVE_SET = ("daqp", "quadprog")
#: Backends whose "solved" is accepted on their exit, without recomputing the residuals.
CERTIFIED = ACTIVE_SET
#: Backends with a warm start (quadprog has none: every solve is cold).
WARM = tuple(s for s in SOLVERS if s != "quadprog")


def _assert_kkt_small(problem: QPProblem, sol: QPSolution, tol: float = 1e-6) -> None:
    res = kkt_residuals(problem, sol)
    assert set(res) == {"stationarity", "primal_infeasibility", "complementarity", "dual_sign"}
    assert all(v >= 0.0 for v in res.values()), res
    assert max(res.values()) < tol, res


# --------------------------------------------------------------------------------------
# 1. Known solutions
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("with_rows", [False, True])
def test_unconstrained(solver: str, with_rows: bool) -> None:
    H = np.array([[4.0, 1.0], [1.0, 2.0]])
    g = np.array([1.0, -1.0])
    x_star = -np.linalg.solve(H, g)  # = [-3/7, 5/7]
    if with_rows:  # an inactive row and an infinite box: still the unconstrained optimum
        problem = QPProblem(
            H, g, np.array([[1.0, 1.0]]), np.array([-10.0]), np.array([np.inf]),
            np.full(2, -np.inf), np.full(2, np.inf),
        )  # fmt: skip
        m = 1
    else:
        problem = QPProblem(H, g, None, None, None, None, None)
        m = 0
    sol = QPSolver(2, m, solver).solve(problem)
    assert sol.status == "solved"
    np.testing.assert_allclose(sol.x, x_star, atol=1e-8)
    np.testing.assert_allclose(sol.x, [-3.0 / 7.0, 5.0 / 7.0], atol=1e-8)
    assert sol.z.shape == (m,) and sol.z_box.shape == (2,)
    np.testing.assert_allclose(sol.z, 0.0, atol=1e-8)
    np.testing.assert_allclose(sol.z_box, 0.0, atol=1e-8)
    _assert_kkt_small(problem, sol, 1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_single_active_lower_row(solver: str) -> None:
    """min 1/2 |x|^2 s.t. a^T x >= b, b > 0: x = b a / |a|^2, kappa = b / |a|^2."""
    a, b = np.array([1.0, 2.0]), 5.0
    problem = QPProblem(np.eye(2), np.zeros(2), a[None, :], np.array([b]), np.array([np.inf]),
                        None, None)  # fmt: skip
    sol = QPSolver(2, 1, solver).solve(problem)
    assert sol.status == "solved"
    np.testing.assert_allclose(sol.x, [1.0, 2.0], atol=1e-8)
    # Lower bound active -> z < 0 (proxsuite convention); paper's kappa = -z = 1.
    np.testing.assert_allclose(sol.z, [-1.0], atol=1e-8)
    np.testing.assert_allclose(lower_multipliers(sol), [1.0], atol=1e-8)
    np.testing.assert_allclose(sol.z_box, 0.0, atol=1e-8)
    _assert_kkt_small(problem, sol, 1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_single_active_upper_row(solver: str) -> None:
    """min 1/2 |x|^2 s.t. a^T x <= -5: x = -[1, 2], upper bound active -> z = +1, kappa = 0."""
    a = np.array([1.0, 2.0])
    problem = QPProblem(np.eye(2), np.zeros(2), a[None, :], np.array([-np.inf]),
                        np.array([-5.0]), None, None)  # fmt: skip
    sol = QPSolver(2, 1, solver).solve(problem)
    assert sol.status == "solved"
    np.testing.assert_allclose(sol.x, [-1.0, -2.0], atol=1e-8)
    np.testing.assert_allclose(sol.z, [1.0], atol=1e-8)
    np.testing.assert_allclose(lower_multipliers(sol), [0.0], atol=1e-12)
    _assert_kkt_small(problem, sol, 1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_active_box_bounds(solver: str) -> None:
    """H = diag(2, 1), g = (-6, 2): free optimum (3, -2), box [-1, 1]^2 -> x = (1, -1).

    Stationarity: 2*1 - 6 + zb_1 = 0 -> zb_1 = +4 (upper active); 1*(-1) + 2 + zb_2 = 0 ->
    zb_2 = -1 (lower active).
    """
    problem = QPProblem(np.diag([2.0, 1.0]), np.array([-6.0, 2.0]), None, None, None,
                        np.array([-1.0, -1.0]), np.array([1.0, 1.0]))  # fmt: skip
    sol = QPSolver(2, 0, solver).solve(problem)
    assert sol.status == "solved"
    np.testing.assert_allclose(sol.x, [1.0, -1.0], atol=1e-8)
    np.testing.assert_allclose(sol.z_box, [4.0, -1.0], atol=1e-8)
    assert sol.z.shape == (0,)
    _assert_kkt_small(problem, sol, 1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_row_and_box_duals_are_split(solver: str) -> None:
    """One active row and one active box bound at once: duals land in z and z_box.

    min 1/2 |x|^2 - 3 x_2 s.t. x_1 + x_2 >= 4, x_2 <= 2: x = (2, 2), z = -2, zb = (0, +3).
    (Stationarity: x_1 - kappa = 0 -> kappa = 2; x_2 - 3 - kappa + zb_2 = 0 -> zb_2 = 3.)
    """
    problem = QPProblem(np.eye(2), np.array([0.0, -3.0]), np.array([[1.0, 1.0]]),
                        np.array([4.0]), np.array([np.inf]), np.array([-10.0, -10.0]),
                        np.array([10.0, 2.0]))  # fmt: skip
    sol = QPSolver(2, 1, solver).solve(problem)
    assert sol.status == "solved"
    np.testing.assert_allclose(sol.x, [2.0, 2.0], atol=1e-8)
    np.testing.assert_allclose(sol.z, [-2.0], atol=1e-8)
    np.testing.assert_allclose(sol.z_box, [0.0, 3.0], atol=1e-8)
    np.testing.assert_allclose(lower_multipliers(sol), [2.0], atol=1e-8)
    _assert_kkt_small(problem, sol, 1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_infinite_and_large_finite_bounds_agree(solver: str) -> None:
    """+-inf bounds are accepted as such and give the same answer as +-1e20."""
    base = QPProblem(np.eye(2), np.zeros(2), np.array([[1.0, 2.0]]), np.array([5.0]),
                     np.array([np.inf]), np.full(2, -np.inf), np.full(2, np.inf))  # fmt: skip
    big = base._replace(u=np.array([1e20]), lb=np.full(2, -1e20), ub=np.full(2, 1e20))
    s_inf = QPSolver(2, 1, solver).solve(base)
    s_big = QPSolver(2, 1, solver).solve(big)
    assert s_inf.status == s_big.status == "solved"
    np.testing.assert_allclose(s_inf.x, [1.0, 2.0], atol=1e-8)
    np.testing.assert_allclose(s_big.x, s_inf.x, atol=1e-8)
    np.testing.assert_allclose(s_big.z, s_inf.z, atol=1e-8)


@pytest.mark.parametrize("solver", SOLVERS)
def test_two_sided_row_at_either_bound(solver: str) -> None:
    """min 1/2 |x|^2 + g'x s.t. -1 <= x_1 + x_2 <= 2, both sides finite on one row.

    g = (-3, -3): free optimum (3, 3), a'x = 6 > 2: x = (1, 1), 1 - 3 + z = 0 -> z = +2
    (upper active). g = (3, 3): a'x = -6 < -1: x = (-1/2, -1/2), z = -5/2 (lower active).
    """
    C, l, u = np.array([[1.0, 1.0]]), np.array([-1.0]), np.array([2.0])
    qp = QPSolver(2, 1, solver)
    for g, x_star, z_star in (([-3.0, -3.0], [1.0, 1.0], 2.0),
                              ([3.0, 3.0], [-0.5, -0.5], -2.5)):  # fmt: skip
        problem = QPProblem(np.eye(2), np.array(g), C, l, u, None, None)
        sol = qp.solve(problem)
        assert sol.status == "solved"
        np.testing.assert_allclose(sol.x, x_star, atol=1e-8)
        np.testing.assert_allclose(sol.z, [z_star], atol=1e-8)
        np.testing.assert_allclose(lower_multipliers(sol), [max(-z_star, 0.0)], atol=1e-8)
        _assert_kkt_small(problem, sol, 1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_equality_row_and_fixed_variable(solver: str) -> None:
    """l == u on a row and lb == ub on a variable: free-sign multipliers.

    min 1/2 |x|^2 s.t. x_1 + 2 x_2 = 5, x_2 = 1/2 (box), |x_1| <= 10: x = (4, 1/2);
    stationarity x_1 + z = 0 -> z = -4, x_2 + 2 z + zb_2 = 0 -> zb_2 = +7.5. With the row
    at -5 instead: x = (-6, 1/2), z = +6 (the multiplier changes sign), zb_2 = -12.5.
    """
    qp = QPSolver(2, 1, solver)
    for b, x_star, z_star, zb_star in ((5.0, [4.0, 0.5], [-4.0], [0.0, 7.5]),
                                       (-5.0, [-6.0, 0.5], [6.0], [0.0, -12.5])):  # fmt: skip
        problem = QPProblem(np.eye(2), np.zeros(2), np.array([[1.0, 2.0]]), np.array([b]),
                            np.array([b]), np.array([-10.0, 0.5]), np.array([10.0, 0.5]))
        sol = qp.solve(problem)
        assert sol.status == "solved", b
        np.testing.assert_allclose(sol.x, x_star, atol=1e-8)
        np.testing.assert_allclose(sol.z, z_star, atol=1e-8)
        np.testing.assert_allclose(sol.z_box, zb_star, atol=1e-8)
        _assert_kkt_small(problem, sol, 1e-7)


def test_osqp_and_proxsuite_raw_duals_have_the_same_sign() -> None:
    """The backends themselves (not this module) share the sign convention, as does daqp.

    Row 1 lower-active, row 2 upper-active, box upper-active on x_2.
    """
    import osqp
    import proxsuite
    import scipy.sparse as sp

    H = np.diag([1.0, 2.0, 3.0])
    g = np.array([1.0, -1.0, 0.5])
    C = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    l, u = np.array([1.0, -1e20]), np.array([1e20, -1.0])
    lb, ub = np.full(3, -10.0), np.array([10.0, 0.2, 10.0])

    qp = proxsuite.proxqp.dense.QP(3, 0, 2, True)
    qp.settings.eps_abs = 1e-10
    qp.init(H, g, None, None, C, l, u, lb, ub)
    qp.solve()
    z_prox = np.asarray(qp.results.z)
    assert z_prox.shape == (5,)  # m row duals then n box duals

    solver = osqp.OSQP()
    A = sp.csc_matrix(np.vstack([C, np.eye(3)]))
    solver.setup(sp.csc_matrix(np.triu(H)), g, A, np.r_[l, lb], np.r_[u, ub], eps_abs=1e-10,
                 eps_rel=0.0, polishing=True, verbose=False)  # fmt: skip
    y_osqp = np.asarray(solver.solve(raise_error=False).y)

    np.testing.assert_allclose(qp.results.x, [0.8, 0.2, -1.0], atol=1e-7)
    np.testing.assert_allclose(z_prox, [-1.8, 2.5, 0.0, 2.4, 0.0], atol=1e-6)
    np.testing.assert_allclose(y_osqp, z_prox, atol=1e-6)
    # The test reference (daqp) too, with the box duals first: lam = [z_box; z].
    _, _, exitflag, info = daqp.solve(H, g, C, np.r_[ub, u], np.r_[lb, l])
    assert exitflag == 1
    np.testing.assert_allclose(np.r_[info["lam"][3:], info["lam"][:3]], z_prox, atol=1e-6)
    for y in (z_prox, y_osqp):  # H x + g + [C; I]^T y = 0
        np.testing.assert_allclose(H @ qp.results.x + g + np.vstack([C, np.eye(3)]).T @ y, 0.0,
                                   atol=1e-6)  # fmt: skip


def test_quadprog_raw_multipliers_recombine_into_the_convention() -> None:
    """quadprog itself: min 1/2 x'Gx - a'x s.t. Cq'x >= b returns lambda >= 0 with
    G x - a = Cq lambda. The problem of the previous test, written one-sided (lower rows
    ``c'x >= l``, upper rows ``-c'x >= -u``): z = lambda_upper - lambda_lower gives proxsuite's
    duals exactly, and that is what the backend returns."""
    import quadprog

    H = np.diag([1.0, 2.0, 3.0])
    g = np.array([1.0, -1.0, 0.5])
    C = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    lb, ub = np.full(3, -10.0), np.array([10.0, 0.2, 10.0])
    # Columns: row 1 >= 1, box x >= lb, then row 2 <= -1 and box x <= ub as -(.) >= -(.).
    Cq = np.hstack([C[:1].T, np.eye(3), -C[1:].T, -np.eye(3)])
    bq = np.r_[1.0, lb, 1.0, -ub]
    x, _, _, iters, lam, _ = quadprog.solve_qp(H, -g, Cq, bq, 0)
    np.testing.assert_allclose(x, [0.8, 0.2, -1.0], atol=1e-12)
    assert np.all(lam >= 0.0) and iters[0] >= 1
    np.testing.assert_allclose(H @ x + g - Cq @ lam, 0.0, atol=1e-12)
    z = np.r_[-lam[0], lam[4]]  # lower row: -lambda; upper row: +lambda
    z_box = lam[5:8] - lam[1:4]
    np.testing.assert_allclose(np.r_[z, z_box], [-1.8, 2.5, 0.0, 2.4, 0.0], atol=1e-12)
    problem = QPProblem(H, g, C, np.array([1.0, -np.inf]), np.array([np.inf, -1.0]), lb, ub)
    sol = QPSolver(3, 2, "quadprog").solve(problem)
    assert sol.status == "solved"
    np.testing.assert_allclose(sol.z, z, atol=1e-12)
    np.testing.assert_allclose(sol.z_box, z_box, atol=1e-12)


# --------------------------------------------------------------------------------------
# 2. Random CBF-like QPs of the paper's size, warm-started in sequence
# --------------------------------------------------------------------------------------


def _cbf_sequence(seed: int, count: int = 200, step: float = 0.02) -> list[QPProblem]:
    """``count`` CBF-like QPs (n = 7, m = 36), each a small perturbation of the previous.

    H = J^T J + 0.01 I, g = 0.4 J^T e, rows a_k^T x >= b_k with b = A x0 - slack for a
    feasible x0 strictly inside the Panda's velocity box, slack > 0.
    """
    rng = np.random.default_rng(seed)
    J = rng.standard_normal((8, N_JOINTS))
    e = rng.standard_normal(8)
    A = rng.standard_normal((N_SENSORS, N_JOINTS))
    x0 = rng.uniform(-0.5, 0.5, N_JOINTS) * V_MAX
    slack = rng.exponential(1.0, N_SENSORS) + 1e-3
    problems = []
    for _ in range(count):
        problems.append(
            QPProblem(
                H=J.T @ J + 0.01 * np.eye(N_JOINTS),
                g=0.4 * J.T @ e,
                C=A.copy(),
                l=A @ x0 - slack,
                u=np.full(N_SENSORS, np.inf),
                lb=-V_MAX,
                ub=V_MAX.copy(),
            )
        )
        J = J + step * rng.standard_normal(J.shape)
        e = e + step * rng.standard_normal(e.shape)
        A = A + step * rng.standard_normal(A.shape)
        x0 = np.clip(x0 + step * rng.standard_normal(N_JOINTS), -0.9 * V_MAX, 0.9 * V_MAX)
        slack = np.abs(slack + step * rng.standard_normal(N_SENSORS)) + 1e-3
    return problems


def _reference(p: QPProblem) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact active-set solution (x, z, z_box) from daqp (a dual active-set solver).

    daqp solves min 1/2 x'Hx + f'x s.t. blower <= [I; A] x <= bupper (simple bounds first)
    and returns lam = [lam_box; lam_rows] in this module's sign convention (negative on an
    active lower bound, checked in test_osqp_and_proxsuite_raw_duals_have_the_same_sign).
    """
    n = p.H.shape[0]
    C = np.zeros((0, n)) if p.C is None else p.C
    m = C.shape[0]
    l = np.full(m, -np.inf) if p.l is None else p.l
    u = np.full(m, np.inf) if p.u is None else p.u
    lb = np.full(n, -np.inf) if p.lb is None else p.lb
    ub = np.full(n, np.inf) if p.ub is None else p.ub
    x, _, exitflag, info = daqp.solve(
        np.ascontiguousarray(p.H, dtype=float), np.asarray(p.g, dtype=float),
        np.ascontiguousarray(C, dtype=float), np.concatenate([ub, u]), np.concatenate([lb, l]),
    )  # fmt: skip
    assert exitflag == 1, exitflag
    lam = np.asarray(info["lam"])
    return np.asarray(x), lam[n:], lam[:n]


@pytest.fixture(scope="module")
def cbf_problems() -> list[tuple[QPProblem, tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    problems = _cbf_sequence(seed=20240917)
    return [(p, _reference(p)) for p in problems]


@pytest.mark.parametrize(
    ("solver", "max_iter"),
    # OSQP's ADMM needs > 1000 iterations on ~1% of these strongly constrained problems
    # (they come back as "max_iter" with the default budget, see the next test).
    [("proxsuite", 1000), ("osqp", 10000), ("daqp", 1000), ("quadprog", 1000)],
)
def test_random_cbf_qps_match_active_set_solver(solver: str, max_iter: int, cbf_problems) -> None:
    qp = QPSolver(N_JOINTS, N_SENSORS, solver, max_iter=max_iter)
    n_active = []
    for p, (x_ref, z_ref, zb_ref) in cbf_problems:
        sol = qp.solve(p)
        assert sol.status == "solved"
        np.testing.assert_allclose(sol.x, x_ref, atol=1e-6, rtol=0)
        _assert_kkt_small(p, sol, 1e-6)
        # Multipliers agree with daqp's (unique here: < 7 active rows, generic data).
        kappa = lower_multipliers(sol)
        np.testing.assert_allclose(kappa, -z_ref, atol=1e-5 * (1 + np.abs(z_ref).max()))
        np.testing.assert_allclose(sol.z_box, zb_ref, atol=1e-5 * (1 + np.abs(zb_ref).max()))
        assert np.all(kappa >= 0.0)
        if solver in CERTIFIED:  # accepted on the active-set exit: residuals not recomputed
            assert np.isnan(sol.primal_residual) and np.isnan(sol.dual_residual)
        else:
            assert sol.primal_residual < 1e-6 and sol.dual_residual < 1e-6
        n_active.append(int(np.sum(kappa > 1e-8)))
    # The sequence exercises the constraints: rows are active in most problems.
    assert np.mean(n_active) > 1.0
    # Warm solves are right nearly always; a rare wrong "solved" (seen with proxsuite) is
    # caught by the KKT check and repeated cold. Many retries would mean a broken update.
    assert qp.cold_retries <= 0.02 * len(cbf_problems)


def test_random_cbf_qps_osqp_default_budget_never_wrong(cbf_problems) -> None:
    """With the default 1000 iterations OSQP may run out, but "solved" is always right."""
    qp = QPSolver(N_JOINTS, N_SENSORS, "osqp")
    statuses = []
    for p, (x_ref, _, _) in cbf_problems:
        sol = qp.solve(p)
        statuses.append(sol.status)
        assert sol.status in ("solved", "max_iter")
        assert sol.iterations <= 1000  # the budget holds for the attempt that gave x
        assert sol.total_iterations <= 2 * 1000  # a warm attempt plus at most one cold retry
        if sol.status == "solved":
            np.testing.assert_allclose(sol.x, x_ref, atol=1e-6, rtol=0)
    assert statuses.count("solved") >= 0.95 * len(statuses)


def test_wrong_backend_success_is_downgraded_to_failed() -> None:
    """A backend that says "solved" with a wrong-sign multiplier is not believed."""
    problem = QPProblem(np.eye(2), np.zeros(2), np.array([[1.0, 2.0]]), np.array([5.0]),
                        np.array([np.inf]), None, None)  # fmt: skip
    qp = QPSolver(2, 1, "proxsuite")

    class _Liar:
        is_warm = True
        calls = 0

        def solve(self, d):
            _Liar.calls += 1
            # Feasible, active x = (1, 2), but z = +1 on a row with u = +inf (wrong sign).
            return _RawResult(np.array([1.0, 2.0]), np.array([1.0]), np.zeros(2), "solved",
                              2 + _Liar.calls, 5)

        def reset(self):
            self.is_warm = False

    qp._backend = _Liar()  # type: ignore[assignment]
    sol = qp.solve(problem)
    res = kkt_residuals(problem, sol)
    assert res["dual_sign"] == pytest.approx(1.0)
    assert res["stationarity"] == pytest.approx(4.0)  # x + a z = (2, 4)
    assert res["primal_infeasibility"] == 0.0
    assert sol.status == "failed"
    assert _Liar.calls == 2  # warm attempt, then one cold retry
    # The reported iterations are the retry's (the attempt sol.x comes from), not a sum.
    assert (sol.iterations, sol.inner_iterations) == (4, 5)
    assert (sol.total_iterations, sol.attempts) == (3 + 4, 2)


def test_kkt_residuals_detect_each_violation() -> None:
    """At the exact optimum all four residuals vanish; each perturbation shows up."""
    problem = QPProblem(np.eye(2), np.zeros(2), np.array([[1.0, 2.0]]), np.array([5.0]),
                        np.array([np.inf]), np.full(2, -10.0), np.full(2, 10.0))  # fmt: skip
    exact = QPSolution(np.array([1.0, 2.0]), np.array([-1.0]), np.zeros(2), "solved", 0, 0.0,
                       0.0, 0.0, 0, 0, 1)  # fmt: skip
    assert max(kkt_residuals(problem, exact).values()) < 1e-14
    infeasible = exact._replace(x=np.array([0.5, 1.0]))  # a'x = 2.5 < 5
    res = kkt_residuals(problem, infeasible)
    assert res["stationarity"] == pytest.approx(1.0)  # x + a z = (-0.5, -1)
    assert res["primal_infeasibility"] == pytest.approx(2.5)
    assert res["complementarity"] == pytest.approx(2.5)  # kappa = 1 times gap |2.5 - 5|
    wrong_sign = exact._replace(z=np.array([1.0]))
    assert kkt_residuals(problem, wrong_sign)["dual_sign"] == pytest.approx(1.0)
    box_gap = exact._replace(z_box=np.array([0.0, 1e-3]))  # upper box dual, box inactive
    assert kkt_residuals(problem, box_gap)["complementarity"] == pytest.approx(8e-3)


# --------------------------------------------------------------------------------------
# 3. Infeasible problems
# --------------------------------------------------------------------------------------


def _infeasible_cbf() -> QPProblem:
    """Two opposite proximity sensors both under threshold: a'x >= b and -a'x >= b, b > 0."""
    p = _cbf_sequence(seed=7, count=1)[0]
    assert p.C is not None and p.l is not None
    C, l = p.C.copy(), p.l.copy()
    C[1] = -C[0]
    l[0] = l[1] = 0.3
    return p._replace(C=C, l=l)


@pytest.mark.parametrize("solver", SOLVERS)
def test_infeasible_is_reported_not_raised(solver: str) -> None:
    feasible = _cbf_sequence(seed=7, count=1)[0]
    infeasible = _infeasible_cbf()
    qp = QPSolver(N_JOINTS, N_SENSORS, solver)
    assert qp.solve(feasible).status == "solved"  # so the infeasible one is warm-started
    t0 = time.perf_counter()
    sol = qp.solve(infeasible)
    elapsed = time.perf_counter() - t0
    assert sol.status in ("infeasible", "max_iter")
    if solver in ACTIVE_SET:  # certified (DAQP exit flag -1, quadprog's ValueError)
        assert sol.status == "infeasible"
    assert elapsed < 1.0
    assert sol.iterations <= 1000  # the default budget, per attempt
    assert sol.total_iterations <= 2 * 1000  # a warm attempt plus at most one cold retry
    assert np.all(np.isfinite(sol.x)) and np.all(np.isfinite(sol.z))
    assert np.all(np.isfinite(sol.z_box))
    # The controller carries on: the next feasible problem is solved again, from a cold
    # start (the failed iterate is not used as a warm start): same work as a fresh solver.
    after = qp.solve(feasible)
    assert after.status == "solved"
    np.testing.assert_allclose(after.x, _reference(feasible)[0], atol=1e-6)
    fresh = QPSolver(N_JOINTS, N_SENSORS, solver).solve(feasible)
    assert after.iterations == fresh.iterations


@pytest.mark.parametrize("solver", SOLVERS)
def test_max_iter_bounds_the_work_on_infeasible_problems(solver: str) -> None:
    infeasible = _infeasible_cbf()
    work = {}
    for max_iter in (20, 1000):
        sol = QPSolver(N_JOINTS, N_SENSORS, solver, max_iter=max_iter).solve(infeasible)
        assert sol.status in ("infeasible", "max_iter")
        assert sol.iterations <= max_iter
        if sol.status == "max_iter":
            assert sol.iterations == max_iter
        work[max_iter] = sol.inner_iterations
    assert work[20] <= work[1000]
    if solver == "proxsuite":  # never certifies infeasibility here: it runs out of budget
        assert work[20] < work[1000]
        assert work[20] <= 20 * (20 + 1)  # max_iter_in defaults to max_iter


@pytest.mark.parametrize("solver", SOLVERS)
def test_crossed_bounds_and_nan_data_do_not_raise(solver: str) -> None:
    base = QPProblem(np.eye(2), np.zeros(2), np.array([[1.0, 0.0]]), np.array([1.0]),
                     np.array([0.0]), None, None)  # fmt: skip
    qp = QPSolver(2, 1, solver)
    assert qp.solve(base).status == "infeasible"  # l > u
    nan = base._replace(g=np.array([np.nan, 0.0]), u=np.array([np.inf]))
    sol = qp.solve(nan)
    assert sol.status == "failed"
    assert np.all(np.isfinite(sol.x))


@pytest.mark.parametrize("solver", SOLVERS)
def test_warm_sequence_follows_changing_data(solver: str) -> None:
    """Every part of the problem (H, g, C, l, u, lb, ub) is passed on to a warm backend."""
    base = QPProblem(np.diag([2.0, 1.0]), np.array([-6.0, 2.0]), np.array([[1.0, 1.0]]),
                     np.array([-5.0]), np.array([5.0]), np.array([-1.0, -1.0]),
                     np.array([1.0, 1.0]))  # fmt: skip
    changes = [
        {},
        {"ub": np.array([0.5, 1.0]), "lb": np.array([-1.0, -0.25])},
        {"H": np.diag([1.0, 4.0]), "g": np.array([-0.3, 0.2])},
        {"C": np.array([[1.0, -1.0]]), "l": np.array([0.9]), "u": np.array([1.1])},
        {"C": np.array([[1.0, -1.0]]), "l": np.array([-1.1]), "u": np.array([-0.9])},
        {"l": np.array([0.4]), "u": np.array([0.4])},  # an equality row (DAQP: new setup)
        {"l": np.array([0.4]), "u": np.array([0.4]), "g": np.array([1.0, 3.0])},
        {"lb": np.array([-1.0, 0.3]), "ub": np.array([1.0, 0.3])},  # a fixed variable
    ]
    qp = QPSolver(2, 1, solver)
    for change in changes:
        problem = base._replace(**change)
        sol = qp.solve(problem)
        x_ref, z_ref, zb_ref = _reference(problem)
        assert sol.status == "solved", change
        np.testing.assert_allclose(sol.x, x_ref, atol=1e-7, err_msg=str(change))
        np.testing.assert_allclose(sol.z, z_ref, atol=1e-6, err_msg=str(change))
        np.testing.assert_allclose(sol.z_box, zb_ref, atol=1e-6, err_msg=str(change))


@pytest.mark.parametrize("solver", SOLVERS)
def test_warm_sequence_without_rows(solver: str) -> None:
    """m = 0 (a controller with no CBF rows, e.g. thomas2024 case 1 without proximity): a warm
    sequence of box-constrained QPs, each the clip of the unconstrained optimum (DAQP's
    ``update`` failed on an empty A before it was given None)."""
    rng = np.random.default_rng(5)
    qp = QPSolver(7, 0, solver)
    box = np.linspace(0.5, 2.0, 7)
    for _ in range(6):
        g = rng.normal(size=7) * 2.0
        H = np.diag(rng.uniform(0.5, 2.0, 7))
        sol = qp.solve(QPProblem(H, g, np.empty((0, 7)), np.empty(0), np.empty(0), -box, box))
        assert sol.status == "solved"
        np.testing.assert_allclose(sol.x, np.clip(-g / np.diag(H), -box, box), atol=1e-7)
        assert sol.z.shape == (0,)


# --------------------------------------------------------------------------------------
# 4. Bad configuration
# --------------------------------------------------------------------------------------


def test_unknown_solver_name_lists_valid_ones() -> None:
    with pytest.raises(UnknownChoiceError) as info:
        QPSolver(7, 36, solver="gurobi")
    err = info.value
    assert isinstance(err, ConfigError)
    assert err.kind == "QP solver" and err.value == "gurobi"
    assert err.choices == sorted(SOLVERS)
    assert set(SOLVERS) == {"proxsuite", "osqp", "daqp", "quadprog"}
    for name in SOLVERS:
        assert name in str(err)
    with pytest.raises(UnknownChoiceError, match="daqp, osqp, proxsuite, quadprog"):
        QPSolver(2, 1, solver="DAQP")  # names are case-sensitive


def test_wrong_shapes_raise() -> None:
    qp = QPSolver(2, 1, "proxsuite")
    with pytest.raises(QPDimensionError):
        qp.solve(QPProblem(np.eye(3), np.zeros(3), None, None, None, None, None))
    with pytest.raises(QPDimensionError):
        qp.solve(QPProblem(np.eye(2), np.zeros(2), np.ones((2, 2)), None, None, None, None))


# --------------------------------------------------------------------------------------
# 5. Warm start and reset
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("solver", SOLVERS)
def test_warm_start_and_reset(solver: str) -> None:
    problem = _cbf_sequence(seed=3, count=1)[0]
    qp = QPSolver(N_JOINTS, N_SENSORS, solver)
    first = qp.solve(problem)
    second = qp.solve(problem)
    assert first.status == second.status == "solved"
    assert second.iterations <= first.iterations
    assert first.iterations > 0
    np.testing.assert_allclose(second.x, first.x, atol=1e-7)
    qp.reset()
    again = qp.solve(problem)  # cold again: same work as the very first solve
    assert again.status == "solved"
    assert again.iterations == first.iterations
    np.testing.assert_allclose(again.x, first.x, atol=1e-9)


@pytest.mark.parametrize("solver", SOLVERS)
def test_no_warm_start_repeats_the_cold_solve(solver: str) -> None:
    problem = _cbf_sequence(seed=3, count=1)[0]
    qp = QPSolver(N_JOINTS, N_SENSORS, solver, warm_start=False)
    first, second = qp.solve(problem), qp.solve(problem)
    assert first.status == second.status == "solved"
    assert second.iterations == first.iterations


# --------------------------------------------------------------------------------------
# 6. The iteration budget, and what counts as an iteration
# --------------------------------------------------------------------------------------


def _two_walls(rng: np.random.Generator) -> QPProblem:
    """A nearly degenerate CBF-QP: two rings of 18 sensors facing two parallel walls.

    The rows of each ring are one row ``+a`` or ``-a`` up to 1e-3 and nearly all active at
    a feasible ``u0`` (margins ~1e-4), the cost has the paper's rank-6 task Jacobian. proxsuite
    runs long inner Newton loops on these (the thomas2024 ``parallel`` run logged up to
    276,099 Newton steps for one "solved" QP with ``max_iter = 200``).
    """
    J = rng.normal(size=(8, 6)) @ rng.normal(size=(6, N_JOINTS))
    a = rng.normal(size=N_JOINTS)
    C = np.vstack([a + 1e-3 * rng.normal(size=(18, N_JOINTS)),
                   -a + 1e-3 * rng.normal(size=(18, N_JOINTS))])  # fmt: skip
    u0 = rng.uniform(-0.3, 0.3, N_JOINTS)
    return QPProblem(H=J.T @ J + 0.01 * np.eye(N_JOINTS),
                     g=0.08 * J.T @ rng.normal(size=8), C=C,
                     l=C @ u0 - rng.exponential(1e-4, N_SENSORS),
                     u=np.full(N_SENSORS, np.inf), lb=-V_MAX, ub=V_MAX)  # fmt: skip


def test_solved_degenerate_qps_stay_within_the_budget() -> None:
    """proxsuite, warm-started over 20 two-wall QPs with a budget of 30: no attempt reports
    more than 30 iterations, "solved" ones are KKT points (and agree with a large budget),
    the others ran out ("max_iter" at exactly 30). Before the fix proxsuite's inner Newton
    steps were reported: 41, 108, ... for QPs it called "solved"."""
    cap = 30
    rng = np.random.default_rng(0)
    qp = QPSolver(N_JOINTS, N_SENSORS, "proxsuite", max_iter=cap)
    statuses = []
    n_many_newton_steps = 0
    for k in range(20):
        p = _two_walls(rng)
        sol = qp.solve(p)
        statuses.append(sol.status)
        assert sol.iterations <= cap, (k, sol.status, sol.iterations)
        assert sol.total_iterations <= sol.attempts * cap
        assert sol.inner_iterations <= cap * (cap + 1)  # max_iter_in defaults to max_iter
        assert sol.status in ("solved", "max_iter"), k
        if sol.status == "max_iter":
            assert sol.iterations == cap
            continue
        n_many_newton_steps += sol.inner_iterations > cap
        _assert_kkt_small(p, sol, 1e-6)
        ref = QPSolver(N_JOINTS, N_SENSORS, "proxsuite", max_iter=10000).solve(p)
        assert ref.status == "solved"
        np.testing.assert_allclose(sol.x, ref.x, atol=1e-6, err_msg=f"problem {k}")
    # The set exercises both outcomes, and solves whose Newton steps exceed the budget.
    assert statuses.count("solved") >= 10 and "max_iter" in statuses, statuses
    assert n_many_newton_steps >= 5


# Budgets between the easy QP's needs and the hard one's (cold and warm): proxsuite needs 2
# outer iterations on _EASY, >= 9 on _cbf_sequence(3); OSQP checks convergence every 25
# ADMM iterations: 100 on _EASY, >= 175 on _cbf_sequence(3); DAQP 1 and 11 active-set
# iterations (warm after _EASY as cold: its working set there is empty).
_SMALL_CAP = {"proxsuite": 4, "osqp": 125, "daqp": 4}
_EASY = QPProblem(np.eye(N_JOINTS), np.full(N_JOINTS, 0.01), np.ones((N_SENSORS, N_JOINTS)),
                  np.full(N_SENSORS, -1.0), np.full(N_SENSORS, np.inf), -V_MAX, V_MAX)


@pytest.mark.parametrize("solver", WARM)
def test_over_budget_is_max_iter_even_after_a_cold_retry(solver: str) -> None:
    """A QP that needs more than the budget, warm-started: the warm attempt and the cold
    retry each run out; the result is "max_iter" with the retry's count (= the budget),
    not the sum of both (2x the budget before the fix)."""
    cap = _SMALL_CAP[solver]
    hard = _cbf_sequence(seed=3, count=1)[0]
    needs = QPSolver(N_JOINTS, N_SENSORS, solver, max_iter=10000).solve(hard)
    assert needs.status == "solved" and needs.iterations > cap
    qp = QPSolver(N_JOINTS, N_SENSORS, solver, max_iter=cap)
    easy = qp.solve(_EASY)
    assert easy.status == "solved" and easy.iterations <= cap  # now warm
    sol = qp.solve(hard)
    assert sol.status == "max_iter"
    assert sol.iterations == cap
    assert qp.cold_retries == 1 and sol.attempts == 2
    assert sol.total_iterations == 2 * cap
    assert np.all(np.isfinite(sol.x))


def _starve_warm_backend(qp: QPSolver) -> None:
    """Give the warm backend state a budget of 1 iteration for its next solve, so that the
    warm attempt fails and :meth:`QPSolver.solve` retries cold with the real budget."""
    backend: Any = qp._backend
    if qp.solver == "proxsuite":
        backend._qp.settings.max_iter = 1
    elif qp.solver == "daqp":
        backend._model.settings = {"iter_limit": 1}
    else:
        backend._solver.update_settings(max_iter=1)


@pytest.mark.parametrize("solver", WARM)
def test_iterations_are_those_of_the_cold_retry(solver: str) -> None:
    """After a failed warm attempt the solution, status and iterations are the cold
    retry's: the same as a fresh solver's on that QP (cold solves are deterministic);
    the warm attempt's iteration shows only in total_iterations."""
    first, second = _cbf_sequence(seed=11, count=2, step=0.5)
    qp = QPSolver(N_JOINTS, N_SENSORS, solver, max_iter=10000)
    assert qp.solve(first).status == "solved"
    _starve_warm_backend(qp)
    sol = qp.solve(second)
    fresh = QPSolver(N_JOINTS, N_SENSORS, solver, max_iter=10000).solve(second)
    assert fresh.status == sol.status == "solved"
    assert sol.iterations == fresh.iterations > 1
    assert (qp.cold_retries, sol.attempts) == (1, 2)
    assert sol.inner_iterations == fresh.inner_iterations
    assert sol.total_iterations == 1 + fresh.iterations
    np.testing.assert_allclose(sol.x, fresh.x, atol=1e-12)
    np.testing.assert_allclose(sol.x, _reference(second)[0], atol=1e-6)  # daqp
    # The real budget is back for the warm solves that follow.
    again = qp.solve(second)
    assert again.status == "solved" and again.attempts == 1


def test_proxsuite_budget_sets_both_loops() -> None:
    """max_iter caps proxsuite's outer loop, max_iter_in (default max_iter) its inner one."""
    p = _cbf_sequence(seed=3, count=1)[0]
    qp = QPSolver(N_JOINTS, N_SENSORS, "proxsuite", max_iter=50)
    assert qp.solve(p).status == "solved"
    settings = qp._backend._qp.settings  # type: ignore[attr-defined]
    assert (settings.max_iter, settings.max_iter_in) == (50, 50)
    qp2 = QPSolver(N_JOINTS, N_SENSORS, "proxsuite", max_iter=50, max_iter_in=7)
    sol = qp2.solve(p)
    assert qp2._backend._qp.settings.max_iter_in == 7  # type: ignore[attr-defined]
    assert sol.iterations <= sol.inner_iterations <= 50 * (7 + 1)


@pytest.mark.parametrize("bad", [0, -3, 2.5])
def test_bad_budget_is_rejected(bad: float) -> None:
    with pytest.raises(ConfigError, match="max_iter"):
        QPSolver(2, 1, "proxsuite", max_iter=bad)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="max_iter_in"):
        QPSolver(2, 1, "proxsuite", max_iter_in=bad)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------
# 7. The exact active-set backends (DAQP, quadprog)
# --------------------------------------------------------------------------------------


def _random_general_qp(rng: np.random.Generator) -> QPProblem:
    """A strictly convex QP (n = 7, m = 12) with every kind of row, feasible by construction.

    Rows around a feasible x0: two-sided ``l < u`` (~40%), lower-only, upper-only, and up to
    two equality rows ``l == u``; a box [-1, 1] with sometimes one fixed variable; a linear
    term large enough that several rows and bounds are active, at either side.
    """
    n, m = N_JOINTS, 12
    M = rng.standard_normal((n, n))
    C = rng.standard_normal((m, n))
    x0 = rng.uniform(-0.5, 0.5, n)
    c0 = C @ x0
    kind = rng.choice(4, size=m, p=[0.4, 0.25, 0.25, 0.1])  # two-sided, lower, upper, eq
    kind[np.flatnonzero(kind == 3)[2:]] = 0
    l = c0 - rng.exponential(0.3, m)
    u = c0 + rng.exponential(0.3, m)
    l[kind == 2] = -np.inf
    u[kind == 1] = np.inf
    l[kind == 3] = u[kind == 3] = c0[kind == 3]
    lb, ub = np.full(n, -1.0), np.full(n, 1.0)
    if rng.random() < 0.3:
        lb[0] = ub[0] = x0[0]
    return QPProblem(M @ M.T + 0.1 * np.eye(n), 4.0 * rng.standard_normal(n), C, l, u, lb, ub)


def _exact_kkt_solution(p: QPProblem, x_guess: np.ndarray, tol: float = 1e-9
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The optimum from the KKT equations on the active set of ``x_guess``, certified.

    With the active rows ``A_act x = b_act`` of ``v = [C; I] x`` (equalities, and bounds met
    within ``tol``), solves ``[[H, A_act^T], [A_act, 0]] [x; y] = [-g; b_act]`` exactly (no
    QP solver): ``y`` are the duals in this module's convention. Returns (x, z, z_box,
    side), side = -1 / +1 / 0 for a lower-active / upper-active / inactive entry of v, after
    checking that x is feasible and every y has its side's sign (then, H being positive
    definite, x is the optimum and, with linearly independent active rows, y is unique);
    None when the active rows are dependent (the duals are not unique).
    """
    assert p.C is not None and p.l is not None and p.u is not None
    assert p.lb is not None and p.ub is not None
    n, m = p.H.shape[0], p.C.shape[0]
    V = np.vstack([p.C, np.eye(n)])
    lo, hi = np.r_[p.l, p.lb], np.r_[p.u, p.ub]
    v = V @ x_guess
    at_lo, at_hi = np.abs(v - lo) <= tol, np.abs(v - hi) <= tol
    act = at_lo | at_hi
    A, b = V[act], np.where(at_lo, lo, hi)[act]
    if np.linalg.matrix_rank(A) < A.shape[0]:
        return None
    k = A.shape[0]
    K = np.block([[p.H, A.T], [A, np.zeros((k, k))]])
    sol = np.linalg.solve(K, np.r_[-p.g, b])
    x, y = sol[:n], np.zeros(m + n)
    y[act] = sol[n:]
    side = np.where(at_lo & ~at_hi, -1, np.where(at_hi & ~at_lo, 1, 0))
    side[act & at_lo & at_hi] = 0  # equality: free sign
    assert np.all(V @ x >= lo - 1e-9) and np.all(V @ x <= hi + 1e-9)
    assert np.all(y[side == -1] <= 1e-12) and np.all(y[side == 1] >= -1e-12)
    np.testing.assert_allclose(p.H @ x + p.g + V.T @ y, 0.0, atol=1e-10)
    side[~act] = 0
    return x, y[:m], y[m:], np.where(act, side, 2)


@pytest.mark.parametrize("solver", ACTIVE_SET)
def test_random_qps_match_the_exact_kkt_solution_and_proxsuite(solver: str) -> None:
    """100 seeded random QPs with two-sided, one-sided and equality rows and an active box:
    x and both duals agree with the exact KKT solve to 1e-9 (1e-7 asked), have the module's
    signs (z <= 0 at an active lower, >= 0 at an active upper bound, 0 on inactive rows), and
    agree with proxsuite (to proxsuite's own accuracy at eps_abs = 1e-9: 1e-6)."""
    rng = np.random.default_rng(20250101)
    qp = QPSolver(N_JOINTS, 12, solver)
    prox = QPSolver(N_JOINTS, 12, "proxsuite")
    seen = {"lower": 0, "upper": 0, "equality": 0, "box": 0, "unique": 0, "proxsuite": 0}
    for k in range(100):
        p = _random_general_qp(rng)
        sol = qp.solve(p)
        assert sol.status == "solved", k
        _assert_kkt_small(p, sol, 1e-9)
        ref = _exact_kkt_solution(p, sol.x)
        if ref is None:
            continue
        x_ref, z_ref, zb_ref, side = ref
        seen["unique"] += 1
        scale = 1.0 + np.abs(np.r_[z_ref, zb_ref]).max()
        np.testing.assert_allclose(sol.x, x_ref, atol=1e-9, err_msg=f"problem {k}")
        np.testing.assert_allclose(sol.z, z_ref, atol=1e-9 * scale, err_msg=f"problem {k}")
        np.testing.assert_allclose(sol.z_box, zb_ref, atol=1e-9 * scale, err_msg=f"problem {k}")
        y = np.r_[sol.z, sol.z_box]
        assert np.all(y[side == -1] <= 1e-12) and np.all(y[side == 1] >= -1e-12), k
        np.testing.assert_array_equal(y[side == 2], 0.0)  # inactive: exactly 0
        m = sol.z.shape[0]
        seen["lower"] += int(np.any(side[:m] == -1))
        seen["upper"] += int(np.any(side[:m] == 1))
        seen["equality"] += int(np.any(np.asarray(p.l) == np.asarray(p.u)))
        seen["box"] += int(np.any(side[m:] != 2))
        ps = prox.solve(p)
        if ps.status != "solved":  # proxsuite 0.8.0 calls problem 6 "infeasible"; OSQP solves it
            continue
        seen["proxsuite"] += 1
        np.testing.assert_allclose(sol.x, ps.x, atol=1e-7, err_msg=f"problem {k}")
        np.testing.assert_allclose(y, np.r_[ps.z, ps.z_box], atol=1e-6 * scale,
                                   err_msg=f"problem {k}")  # fmt: skip
    # Every kind of active constraint is exercised, with unique duals nearly always.
    assert seen["unique"] >= 90 and seen["proxsuite"] >= seen["unique"] - 2, seen
    assert min(seen["lower"], seen["upper"], seen["equality"], seen["box"]) >= 20, seen


def test_daqp_and_quadprog_agree_on_the_cbf_sequence(cbf_problems) -> None:
    """Two independent exact methods (warm-started DAQP, cold quadprog): same x and duals."""
    a = QPSolver(N_JOINTS, N_SENSORS, "daqp")
    b = QPSolver(N_JOINTS, N_SENSORS, "quadprog")
    for k, (p, _) in enumerate(cbf_problems):
        sa, sb = a.solve(p), b.solve(p)
        assert sa.status == sb.status == "solved", k
        np.testing.assert_allclose(sa.x, sb.x, atol=1e-10, err_msg=f"problem {k}")
        np.testing.assert_allclose(sa.z, sb.z, atol=1e-9, err_msg=f"problem {k}")
        np.testing.assert_allclose(sa.z_box, sb.z_box, atol=1e-9, err_msg=f"problem {k}")


@pytest.mark.parametrize("solver", ACTIVE_SET)
def test_contradictory_rows_are_certified_infeasible(solver: str) -> None:
    """x_1 + x_2 >= 1 and x_1 + x_2 <= 0 on two rows (each row alone is fine, so the layer's
    l <= u check passes them on): the backend certifies it, never "solved"."""
    problem = QPProblem(np.eye(2), np.zeros(2), np.array([[1.0, 1.0], [1.0, 1.0]]),
                        np.array([1.0, -np.inf]), np.array([np.inf, 0.0]), None, None)  # fmt: skip
    qp = QPSolver(2, 2, solver)
    sol = qp.solve(problem)
    assert sol.status == "infeasible"
    assert sol.attempts == 1 and np.all(np.isfinite(sol.x))
    # Warm (DAQP) from a feasible QP: the warm attempt and the cold retry both certify it.
    feasible = problem._replace(u=np.array([np.inf, 5.0]))
    assert qp.solve(feasible).status == "solved"
    again = qp.solve(problem)
    assert again.status == "infeasible"
    assert again.attempts == (2 if solver == "daqp" else 1)
    assert qp.solve(feasible).status == "solved"  # and recovers


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("field", ["H", "g", "C", "l", "ub"])
def test_non_finite_data_is_failed(solver: str, field: str) -> None:
    """NaN (or inf in H, g, C) anywhere is "failed", decided before the backend is called."""
    base = QPProblem(np.eye(2), np.zeros(2), np.array([[1.0, 1.0]]), np.array([1.0]),
                     np.array([np.inf]), np.full(2, -1.0), np.full(2, 1.0))  # fmt: skip
    bad = np.array(getattr(base, field), dtype=float)
    bad.flat[0] = np.inf if field in ("H", "C") else np.nan
    qp = QPSolver(2, 1, solver)
    sol = qp.solve(base._replace(**{field: bad}))
    assert sol.status == "failed" and sol.attempts == 0
    assert np.all(np.isfinite(sol.x)) and np.all(np.isfinite(sol.z))
    assert qp.solve(base).status == "solved"


@pytest.mark.parametrize("solver", SOLVERS)
def test_unsatisfiable_infinite_bound_is_infeasible(solver: str) -> None:
    """A row with l = +inf (or a variable with ub = -inf) is infeasible, not an error."""
    row = QPProblem(np.eye(2), np.zeros(2), np.array([[1.0, 0.0]]), np.array([np.inf]),
                    np.array([np.inf]), None, None)  # fmt: skip
    box = QPProblem(np.eye(2), np.zeros(2), None, None, None, np.full(2, -np.inf),
                    np.array([-np.inf, 1.0]))  # fmt: skip
    assert QPSolver(2, 1, solver).solve(row).status == "infeasible"
    assert QPSolver(2, 0, solver).solve(box).status == "infeasible"


def test_quadprog_needs_a_positive_definite_hessian() -> None:
    """A singular H is "failed" for quadprog (its ValueError), solved by DAQP (proximal
    iterations); an indefinite H is "failed" for both."""
    problem = QPProblem(np.diag([1.0, 0.0]), np.array([1.0, 1.0]), np.array([[0.0, 1.0]]),
                        np.array([0.0]), np.array([np.inf]), np.full(2, -5.0), np.full(2, 5.0))
    sol = QPSolver(2, 1, "quadprog").solve(problem)
    assert sol.status == "failed" and sol.attempts == 1
    sol = QPSolver(2, 1, "daqp").solve(problem)  # x = (-1, 0), z = -1
    assert sol.status == "solved"
    np.testing.assert_allclose(sol.x, [-1.0, 0.0], atol=1e-8)
    np.testing.assert_allclose(sol.z, [-1.0], atol=1e-8)
    indefinite = problem._replace(H=np.diag([1.0, -1.0]))
    for solver in ACTIVE_SET:
        assert QPSolver(2, 1, solver).solve(indefinite).status == "failed", solver


def test_quadprog_over_budget_is_max_iter_with_its_true_count() -> None:
    """quadprog cannot be stopped: a QP needing 9 main iterations with a budget of 4 is
    "max_iter" (never "solved"), reported with the 9 it took, in one (cold) attempt."""
    hard = _cbf_sequence(seed=3, count=1)[0]
    needs = QPSolver(N_JOINTS, N_SENSORS, "quadprog").solve(hard)
    assert needs.status == "solved" and needs.iterations > 4
    assert needs.inner_iterations >= needs.iterations  # + the rows dropped on the way
    qp = QPSolver(N_JOINTS, N_SENSORS, "quadprog", max_iter=4)
    assert qp.solve(_EASY).status == "solved"
    sol = qp.solve(hard)
    assert sol.status == "max_iter"
    assert sol.iterations == needs.iterations and sol.attempts == 1
    assert qp.cold_retries == 0
    np.testing.assert_allclose(sol.x, needs.x, atol=0)


def test_daqp_warm_start_reuses_the_working_set(cbf_problems) -> None:
    """Warm-started DAQP re-solves the slowly changing sequence in a fraction of the cold
    iterations, with the same answers; its settings are the layer's budget and tolerance."""
    warm = QPSolver(N_JOINTS, N_SENSORS, "daqp", eps_abs=1e-9, max_iter=321)
    cold = QPSolver(N_JOINTS, N_SENSORS, "daqp", warm_start=False)
    n_warm, n_cold = [], []
    for p, _ in cbf_problems:
        sw, sc = warm.solve(p), cold.solve(p)
        assert sw.status == sc.status == "solved"
        np.testing.assert_allclose(sw.x, sc.x, atol=1e-10)
        n_warm.append(sw.iterations)
        n_cold.append(sc.iterations)
    assert np.mean(n_warm) < 0.3 * np.mean(n_cold), (np.mean(n_warm), np.mean(n_cold))
    assert warm.cold_retries == 0
    settings = warm._backend._model.settings  # type: ignore[attr-defined]
    assert settings["iter_limit"] == 321 and settings["primal_tol"] == 1e-9
    model = warm._backend._model  # type: ignore[attr-defined]
    p = cbf_problems[0][0]
    assert p.C is not None
    warm.solve(p)
    assert warm._backend._model is model  # type: ignore[attr-defined]  # same workspace
    l = np.array(p.l)
    l[0] = (p.C @ warm.solve(p).x)[0]
    u = np.full(N_SENSORS, np.inf)
    u[0] = l[0]
    eq = p._replace(l=l, u=u)  # row 0 becomes an equality: a new setup
    sol = warm.solve(eq)
    assert sol.status == "solved" and warm._backend._model is not model  # type: ignore[attr-defined]
    np.testing.assert_allclose(sol.x, _reference(eq)[0], atol=1e-9)


@pytest.mark.parametrize("solver", ACTIVE_SET)
def test_active_set_backends_solve_the_degenerate_two_wall_qps(solver: str) -> None:
    """The nearly degenerate two-wall CBF-QPs (where proxsuite runs long Newton loops) are
    solved exactly within the default budget: KKT residuals at rounding level, x as
    proxsuite's with a large budget."""
    rng = np.random.default_rng(0)
    qp = QPSolver(N_JOINTS, N_SENSORS, solver)
    for k in range(20):
        p = _two_walls(rng)
        sol = qp.solve(p)
        assert sol.status == "solved", k
        assert sol.iterations <= 100
        _assert_kkt_small(p, sol, 1e-9)
        ref = QPSolver(N_JOINTS, N_SENSORS, "proxsuite", max_iter=10000).solve(p)
        np.testing.assert_allclose(sol.x, ref.x, atol=1e-6, err_msg=f"problem {k}")
