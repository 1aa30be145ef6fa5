"""Tests of repro.control.cbf_qp: the IBVS cost and CBF rows of thomas2024 eqs. (8)-(10),
the controller's solution against closed forms (eq. (19), one active row, the eq. (21)
local minimum), its infeasibility fallback, and an exact active-set reference (daqp) on
random QPs of the paper's size.
"""

from __future__ import annotations

import time
from typing import Any

import daqp  # exact active-set reference; dev dependency in pyproject.toml
import numpy as np
import pytest

from repro.control.cbf_qp import (
    CBFQPController,
    Inequalities,
    Objective,
    cbf_inequalities,
    ibvs_objective,
    least_squares_ibvs,
)
from repro.control.qp import SOLVERS
from repro.errors import UnknownChoiceError
from repro.sim.panda import PANDA_LIMITS

N, M = 7, 36  # Panda joints; 2 rings x 18 sensors (thomas2024)
QD_MAX = np.array(PANDA_LIMITS.qd_max)  # Franka: 2.175 x 4, 2.61 x 3 [rad/s]
WIDE = np.full(N, 1e3)  # a box that never binds [rad/s]
BIG_BUDGET = 5000  # CBFQPController(max_iter=...) large enough for OSQP on these QPs

def _well_conditioned_J(rng: np.random.Generator) -> np.ndarray:
    """A random (8, N) feature Jacobian with singular values in [0.5, 2].

    The QP backends stop on an absolute dual residual eps_abs = 1e-9, so u is accurate to
    about eps_abs / lambda_min(G); these tests ask for 1e-8 on u, hence lambda_min(G) >= 0.25
    (the paper's rank-6 case, lambda_min(G) = mu, is test_rank_deficient_task_accuracy).
    """
    U, _, Vt = np.linalg.svd(rng.normal(size=(8, N)), full_matrices=False)
    return U @ np.diag(rng.uniform(0.5, 2.0, N)) @ Vt


def _objective(rng: np.random.Generator, scale: float = 1.0) -> tuple[Objective, np.ndarray,
                                                                       np.ndarray]:
    J = _well_conditioned_J(rng)
    e = scale * rng.normal(size=8)
    return ibvs_objective(J, e, lambda_4p=0.8, mu=0.01), J, e


def _kkt_check(obj: Objective, A: np.ndarray, b: np.ndarray, u: np.ndarray,
               kappa: np.ndarray, tol: float) -> None:
    """KKT of min 1/2 u'Gu + c'u s.t. A u >= b (box inactive): G u + c - A' kappa = 0,
    kappa >= 0, A u >= b, kappa (A u - b) = 0."""
    np.testing.assert_allclose(obj.H @ u + obj.g - A.T @ kappa, 0.0, atol=tol)
    assert np.all(kappa >= 0.0)
    assert np.all(A @ u >= b - tol)
    np.testing.assert_allclose(kappa * (A @ u - b), 0.0, atol=tol)


# --------------------------------------------------------------------------------------
# The pieces
# --------------------------------------------------------------------------------------


def test_ibvs_objective_formula() -> None:
    rng = np.random.default_rng(0)
    J = rng.normal(size=(8, N))
    e = rng.normal(size=8)
    obj = ibvs_objective(J, e, lambda_4p=1.7, mu=0.01)
    assert isinstance(obj, Objective)
    np.testing.assert_allclose(obj.H, J.T @ J + 0.01 * np.eye(N), rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(obj.g, 1.7 * J.T @ e, rtol=1e-14, atol=1e-14)
    # eq. (19): the unconstrained minimiser -G^-1 c.
    u = least_squares_ibvs(obj)
    np.testing.assert_allclose(obj.H @ u, -obj.g, atol=1e-12)


def test_cbf_inequalities_formula() -> None:
    rng = np.random.default_rng(1)
    L = rng.normal(size=(18, 6))
    J_S = rng.normal(size=(6, N))
    delta = rng.uniform(0.0, 1.0, 18)
    ineq = cbf_inequalities(L, J_S, delta, delta_star=0.15, gain=2.5)
    assert isinstance(ineq, Inequalities)
    np.testing.assert_allclose(ineq.A, L @ J_S, atol=1e-14)
    np.testing.assert_allclose(ineq.b, -2.5 * (delta - 0.15), atol=1e-15)
    # Above the threshold u = 0 is allowed (b < 0); below, the sensor must move away (b > 0).
    assert np.all((ineq.b < 0) == (delta > 0.15))


# --------------------------------------------------------------------------------------
# Closed forms, every solver
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("solver", SOLVERS)
def test_no_active_constraint_gives_least_squares(solver: str) -> None:
    rng = np.random.default_rng(2)
    ctrl = CBFQPController(N, M, solver=solver)
    for _ in range(5):
        obj, _, _ = _objective(rng, scale=0.05)
        u_ls = least_squares_ibvs(obj)
        assert np.all(np.abs(u_ls) < QD_MAX)  # the box does not bind either
        A = rng.normal(size=(M, N))
        b = A @ u_ls - rng.uniform(0.1, 1.0, M)  # every row strictly satisfied at u_ls
        res = ctrl.step(obj, Inequalities(A, b), QD_MAX)
        assert res.status == "solved" and res.qp_status == "solved"
        np.testing.assert_allclose(res.u, u_ls, atol=1e-8)
        np.testing.assert_allclose(res.kappa, 0.0, atol=1e-8)
        np.testing.assert_array_equal(res.slack, 0.0)
        assert res.grad_L0 == pytest.approx(np.linalg.norm(obj.g), rel=1e-6)


@pytest.mark.parametrize("solver", SOLVERS)
def test_rank_deficient_task_accuracy(solver: str) -> None:
    """The paper's structure: J_4p = J_image (8x6) J_robot (6x7) has rank 6, so
    lambda_min(G) = mu = 0.01. The backends stop on an absolute dual residual of 1e-9, so
    eq. (19) is reproduced to ~1e-9 / mu = 1e-7 rad/s only (proxsuite: 4e-8 measured)."""
    rng = np.random.default_rng(7)
    ctrl = CBFQPController(N, M, solver=solver)
    for _ in range(5):
        J = rng.normal(size=(8, 6)) @ rng.normal(size=(6, N))
        obj = ibvs_objective(J, 0.05 * rng.normal(size=8), lambda_4p=0.8, mu=0.01)
        assert np.linalg.eigvalsh(obj.H)[0] == pytest.approx(0.01, rel=1e-6)
        u_ls = least_squares_ibvs(obj)
        A = rng.normal(size=(M, N))
        res = ctrl.step(obj, Inequalities(A, A @ u_ls - 1.0), WIDE)
        assert res.status == "solved"
        assert np.max(np.abs(obj.H @ res.u + obj.g)) < 2e-9  # the solvers' tolerance
        np.testing.assert_allclose(res.u, u_ls, atol=1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_single_active_row_matches_closed_form(solver: str) -> None:
    """min 1/2 u'Gu + c'u s.t. a'u >= b with the row active:
    kappa = (b - a'u_ls) / (a'G^-1 a), u = u_ls + kappa G^-1 a."""
    rng = np.random.default_rng(3)
    ctrl = CBFQPController(N, 3, solver=solver)
    for _ in range(5):
        obj, _, _ = _objective(rng)
        u_ls = least_squares_ibvs(obj)
        a = rng.normal(size=N)
        b = float(a @ u_ls) + rng.uniform(0.2, 1.0)  # u_ls violates the row
        Ginv_a = np.linalg.solve(obj.H, a)
        kappa = (b - a @ u_ls) / (a @ Ginv_a)
        u = u_ls + kappa * Ginv_a
        # Two more rows, inactive at the solution.
        A = np.vstack([a, rng.normal(size=(2, N))])
        bb = np.r_[b, A[1:] @ u - 0.5]
        res = ctrl.step(obj, Inequalities(A, bb), WIDE)
        assert res.status == "solved"
        np.testing.assert_allclose(res.u, u, atol=1e-8)
        np.testing.assert_allclose(res.kappa, [kappa, 0.0, 0.0], atol=1e-7 * max(1.0, kappa))
        assert a @ res.u == pytest.approx(b, abs=1e-8 * np.abs(a).sum())  # |u - u*| <= 1e-8
        _kkt_check(obj, A, bb, res.u, res.kappa, 1e-7)
        assert res.grad_L0 == pytest.approx(np.linalg.norm(obj.g - A.T @ res.kappa), abs=1e-12)


@pytest.mark.parametrize(("solver", "max_iter"), [
    ("proxsuite", 200),
    ("osqp", None),
    ("osqp", BIG_BUDGET),
    ("daqp", None),
    ("quadprog", None),
])
def test_blocked_optimum_is_a_local_minimum(solver: str, max_iter: int | None) -> None:
    """thomas2024 eq. (21): c = kappa0 a and b = 0 (a sensor at its threshold, the task
    pushing straight into it): u* = 0, kappa = kappa0 and grad_u L(0, kappa) = 0."""
    rng = np.random.default_rng(4)
    ctrl = CBFQPController(N, M, solver=solver, max_iter=max_iter)
    for _ in range(5):
        J = _well_conditioned_J(rng)
        a = rng.normal(size=N)
        kappa0 = rng.uniform(0.1, 2.0)
        lam = 0.8
        e = np.linalg.pinv(J.T) @ (kappa0 * a) / lam  # lambda J^T e = kappa0 a
        obj = ibvs_objective(J, e, lam, 0.01)
        np.testing.assert_allclose(obj.g, kappa0 * a, atol=1e-12)
        assert np.linalg.norm(least_squares_ibvs(obj)) > 0.01  # the task alone would move
        A = np.vstack([a, rng.normal(size=(M - 1, N))])
        u_rev = np.linalg.solve(obj.H, obj.g)  # unconstrained optimum of the reversed task
        # The other sensors far away: inactive at u = 0 and at u_rev.
        b = np.r_[0.0, np.minimum(A[1:] @ u_rev, 0.0) - rng.uniform(0.1, 1.0, M - 1)]
        res = ctrl.step(obj, Inequalities(A, b), QD_MAX)
        assert res.status == "solved"
        np.testing.assert_allclose(res.u, 0.0, atol=1e-8)
        assert res.kappa[0] == pytest.approx(kappa0, rel=1e-6)
        np.testing.assert_allclose(res.kappa[1:], 0.0, atol=1e-8)
        assert res.grad_L0 == pytest.approx(np.linalg.norm(obj.g - A.T @ res.kappa), abs=1e-12)
        assert res.grad_L0 < 1e-6 * np.linalg.norm(obj.g)
        # Not a local minimum when the task pulls the other way (a'u_rev > 0: the row is
        # inactive): u = u_rev, kappa = 0 and grad_L0 = ||c||.
        assert a @ u_rev > 0
        res2 = ctrl.step(Objective(obj.H, -obj.g), Inequalities(A, b), WIDE)
        assert res2.status == "solved"
        np.testing.assert_allclose(res2.u, u_rev, atol=1e-8)
        np.testing.assert_allclose(res2.kappa, 0.0, atol=1e-8)
        assert res2.grad_L0 == pytest.approx(np.linalg.norm(obj.g), rel=1e-6)


# --------------------------------------------------------------------------------------
# Infeasible CBF rows: the relaxed fallback
# --------------------------------------------------------------------------------------


def _daqp(H: np.ndarray, g: np.ndarray, A: np.ndarray, b: np.ndarray, lb: np.ndarray,
          ub: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact solution of min 1/2 x'Hx + g'x s.t. A x >= b, lb <= x <= ub, and the row
    multipliers kappa >= 0 (daqp's lam has proxsuite's sign: kappa = -lam)."""
    n, m = H.shape[0], A.shape[0]
    x, _, exitflag, info = daqp.solve(
        np.ascontiguousarray(H), np.ascontiguousarray(g), np.ascontiguousarray(A),
        np.r_[ub, np.full(m, np.inf)], np.r_[lb, b],
    )  # fmt: skip
    assert exitflag == 1, exitflag
    return np.asarray(x), np.maximum(-np.asarray(info["lam"])[n:], 0.0)


@pytest.mark.parametrize(("solver", "max_iter"), [
    ("proxsuite", 200),
    ("osqp", None),
    ("osqp", BIG_BUDGET),
    ("daqp", None),
    ("quadprog", None),
])
def test_infeasible_rows_are_relaxed(solver: str, max_iter: int | None) -> None:
    """Two opposite sensors both under their threshold: a'u >= 0.5 and -a'u >= 0.5."""
    rng = np.random.default_rng(5)
    ctrl = CBFQPController(N, M, solver=solver, max_iter=max_iter)
    obj, _, _ = _objective(rng, scale=0.1)
    A = rng.normal(size=(M, N))
    A[1] = -A[0]
    b = np.r_[0.5, 0.5, np.full(M - 2, -10.0)]
    # Warm up (imports, first setup) on a feasible problem, then time the infeasible one.
    assert ctrl.step(obj, Inequalities(A, np.full(M, -10.0)), QD_MAX).status == "solved"
    t0 = time.perf_counter()
    res = ctrl.step(obj, Inequalities(A, b), QD_MAX)
    elapsed = time.perf_counter() - t0
    assert elapsed < 0.5
    assert res.status == "relaxed"
    assert res.qp_status in ("infeasible", "max_iter")
    if solver in ("daqp", "quadprog"):  # the active-set backends certify it
        assert res.qp_status == "infeasible"
    assert np.all(np.isfinite(res.u))
    assert np.all(np.abs(res.u) <= QD_MAX + 1e-9)
    assert res.slack.shape == (M,)
    assert np.all(res.slack >= -1e-9)
    assert res.slack[0] > 0 and res.slack[1] > 0
    assert res.slack[0] + res.slack[1] >= 1.0 - 1e-6  # the two rows conflict by 1
    np.testing.assert_allclose(res.slack[2:], 0.0, atol=1e-8)
    assert np.all(A @ res.u + res.slack >= b - 1e-8)
    # It is the slack QP's exact solution (rho = slack_weight).
    H = np.zeros((N + M, N + M))
    H[:N, :N] = obj.H
    H[N:, N:] = ctrl.slack_weight * np.eye(M)
    x_ref, kappa_ref = _daqp(H, np.r_[obj.g, np.zeros(M)], np.hstack([A, np.eye(M)]), b,
                             np.r_[-QD_MAX, np.zeros(M)], np.r_[QD_MAX, np.full(M, np.inf)])
    np.testing.assert_allclose(res.u, x_ref[:N], atol=1e-6)
    np.testing.assert_allclose(res.slack, x_ref[N:], atol=1e-6)
    np.testing.assert_allclose(res.kappa, kappa_ref, atol=1e-5 * max(1.0, kappa_ref.max()))
    # u is the relaxed QP's: so are the reported iterations, each solve within its budget.
    assert res.relaxed_solution is not None and res.command_solution is res.relaxed_solution
    assert res.iterations == res.relaxed_solution.iterations <= ctrl.relaxed_max_iter
    assert res.solution.iterations <= ctrl.max_iter
    # The controller recovers once the conflict is gone.
    res3 = ctrl.step(obj, Inequalities(A, np.full(M, -10.0)), QD_MAX)
    assert res3.status == "solved"
    np.testing.assert_allclose(res3.u, least_squares_ibvs(obj), atol=1e-8)


# --------------------------------------------------------------------------------------
# Random CBF-QPs of the paper's size vs daqp
# --------------------------------------------------------------------------------------


def _random_cbf_qp(rng: np.random.Generator, max_scale: float = 8.0
                   ) -> tuple[Objective, Inequalities]:
    """IBVS cost (often pushing beyond the velocity limits) and 36 CBF rows: about a
    third of the sensors near or under their threshold, built around a feasible u0."""
    obj, _, _ = _objective(rng, scale=rng.uniform(0.2, max_scale))
    L = rng.normal(size=(M, 6))
    L[:, :3] /= np.linalg.norm(L[:, :3], axis=1, keepdims=True)
    J_S = rng.normal(size=(6, N)) * 0.5
    A = L @ J_S
    u0 = rng.uniform(-0.5, 0.5, N) * QD_MAX
    b = A @ u0 - rng.exponential(0.2, M)
    far = rng.random(M) < 0.65
    b[far] -= rng.uniform(1.0, 3.0, far.sum())  # nothing detected: far from binding
    return obj, Inequalities(A, b)


@pytest.mark.parametrize(("solver", "max_iter", "fresh"), [
    ("proxsuite", 200, False),
    ("proxsuite", BIG_BUDGET, False),
    ("osqp", None, False),
    ("proxsuite", 200, True),
    ("osqp", BIG_BUDGET, False),
    ("daqp", None, False),
    ("daqp", None, True),
    ("quadprog", None, False),
])
def test_random_cbf_qps_match_daqp(solver: str, max_iter: int | None, fresh: bool) -> None:
    """100 independent random QPs through one warm-started controller, or a fresh
    controller per QP (``fresh``, i.e. cold starts); 200 is the controller's default
    budget."""
    rng = np.random.default_rng(6)
    ctrl = CBFQPController(N, M, solver=solver, max_iter=max_iter)
    n_active_rows = n_active_box = 0
    for k in range(100):
        obj, ineq = _random_cbf_qp(rng)
        x_ref, kappa_ref = _daqp(obj.H, obj.g, ineq.A, ineq.b, -QD_MAX, QD_MAX)
        if fresh:
            ctrl = CBFQPController(N, M, solver=solver, max_iter=max_iter)
        res = ctrl.step(obj, ineq, QD_MAX)
        assert res.status == "solved", (k, res.qp_status)
        np.testing.assert_allclose(res.u, x_ref, atol=1e-6, err_msg=f"problem {k}")
        row_active = np.abs(ineq.A @ x_ref - ineq.b) < 1e-9
        box_active = np.abs(np.abs(x_ref) - QD_MAX) < 1e-9
        n_active_rows += int(row_active.any())
        n_active_box += int(box_active.any())
        if row_active.sum() + box_active.sum() <= N:  # LICQ: unique multipliers
            np.testing.assert_allclose(res.kappa, kappa_ref,
                                       atol=1e-5 * max(1.0, kappa_ref.max()),
                                       err_msg=f"problem {k}")
        assert res.grad_L0 == pytest.approx(np.linalg.norm(obj.g - ineq.A.T @ kappa_ref),
                                            rel=1e-4, abs=1e-6)
    # The set exercises both kinds of constraint.
    assert n_active_rows > 50 and n_active_box > 20, (n_active_rows, n_active_box)


def test_proxsuite_cold_solution_is_accurate() -> None:
    """One QP (13th of the seed-6 stream with costs up to 3x) solved cold by proxsuite:
    within 1e-6 of the exact active-set solution, like every other QP above."""
    rng = np.random.default_rng(6)
    for _ in range(14):
        obj, ineq = _random_cbf_qp(rng, max_scale=3.0)
    x_ref, _ = _daqp(obj.H, obj.g, ineq.A, ineq.b, -QD_MAX, QD_MAX)
    res = CBFQPController(N, M, solver="proxsuite").step(obj, ineq, QD_MAX)
    assert res.status == "solved"
    np.testing.assert_allclose(res.u, x_ref, atol=1e-6)


# Budgets between what the easy step needs and what the hard QP needs (seed 8): proxsuite
# 2 and 11 outer iterations, OSQP 75 and 375 ADMM iterations (convergence checked every 25),
# DAQP 1 and 14 active-set iterations (warm after the easy step as cold), quadprog 1 and 10
# (always cold: one attempt, its true count, see the next test).
_SMALL_CAP = {"proxsuite": 4, "osqp": 100, "daqp": 4, "quadprog": 4}


@pytest.mark.parametrize("solver", [s for s in SOLVERS if s != "quadprog"])
def test_hard_qp_over_budget_goes_to_the_fallback(solver: str) -> None:
    """The hard QP needs more iterations than max_iter: it is "max_iter" (never "solved"),
    after a warm attempt and a cold retry each within the budget, and u comes from the
    relaxed QP, whose iterations are the ones reported for the command."""
    cap = _SMALL_CAP[solver]
    rng = np.random.default_rng(8)
    obj, ineq = _random_cbf_qp(rng)
    needs = CBFQPController(N, M, solver=solver, max_iter=10000).step(obj, ineq, QD_MAX)
    assert needs.status == "solved" and needs.solution.iterations > cap
    ctrl = CBFQPController(N, M, solver=solver, max_iter=cap)
    easy_obj, _, _ = _objective(rng, scale=0.05)
    easy = ctrl.step(easy_obj, Inequalities(ineq.A, np.full(M, -10.0)), QD_MAX)
    assert easy.status == "solved" and easy.solution.iterations <= cap
    # Now warm: the hard QP runs out twice (warm, then cold).
    res = ctrl.step(obj, ineq, QD_MAX)
    assert res.solution.iterations == cap
    # The step within the budget: u is the hard QP's, so are the iterations and the time.
    assert easy.relaxed_solution is None and easy.command_solution is easy.solution
    assert easy.iterations == easy.solution.iterations
    assert easy.solve_time_s == easy.solution.solve_time_s
    assert res.qp_status == "max_iter" and res.solution.status == "max_iter"
    assert res.solution.attempts == 2 and res.solution.total_iterations == 2 * cap
    assert res.status == "relaxed"
    rs = res.relaxed_solution
    assert rs is not None and rs.status == "solved"
    assert res.iterations == rs.iterations <= ctrl.relaxed_max_iter
    assert res.solve_time_s == res.solution.solve_time_s + rs.solve_time_s
    # u is the slack QP's exact solution (daqp); the QP was feasible, so the slack is tiny.
    x_ref = _slack_qp_reference(obj, ineq, ctrl.slack_weight)
    np.testing.assert_allclose(res.u, x_ref[:N], atol=1e-6)
    np.testing.assert_allclose(res.slack, x_ref[N:], atol=1e-6)
    np.testing.assert_allclose(res.u, needs.u, atol=1e-2)


def _slack_qp_reference(obj: Any, ineq: Any, slack_weight: float) -> np.ndarray:
    """The relaxed (slack) CBF-QP's exact solution [u; slack] by daqp."""
    H = np.zeros((N + M, N + M))
    H[:N, :N] = obj.H
    H[N:, N:] = slack_weight * np.eye(M)
    x_ref, _ = _daqp(H, np.r_[obj.g, np.zeros(M)], np.hstack([ineq.A, np.eye(M)]), ineq.b,
                     np.r_[-QD_MAX, np.zeros(M)], np.r_[QD_MAX, np.full(M, np.inf)])
    return x_ref


def test_quadprog_hard_qp_over_budget_goes_to_the_fallback() -> None:
    """quadprog runs to completion: a hard QP needing 10 main iterations with a budget of 4
    is "max_iter" with its true count in one (cold) attempt, and u comes from the relaxed QP,
    the exact slack-QP solution (as for the backends that stop at the budget)."""
    cap = _SMALL_CAP["quadprog"]
    rng = np.random.default_rng(8)
    obj, ineq = _random_cbf_qp(rng)
    needs = CBFQPController(N, M, solver="quadprog").step(obj, ineq, QD_MAX)
    assert needs.status == "solved" and needs.solution.iterations > cap
    ctrl = CBFQPController(N, M, solver="quadprog", max_iter=cap)
    res = ctrl.step(obj, ineq, QD_MAX)
    assert res.qp_status == "max_iter" and res.status == "relaxed"
    assert res.solution.iterations == needs.solution.iterations
    assert res.solution.attempts == 1
    rs = res.relaxed_solution
    assert rs is not None and rs.status == "solved"
    assert res.iterations == rs.iterations <= ctrl.relaxed_max_iter
    x_ref = _slack_qp_reference(obj, ineq, ctrl.slack_weight)
    np.testing.assert_allclose(res.u, x_ref[:N], atol=1e-9)
    np.testing.assert_allclose(res.u, needs.u, atol=1e-2)


def test_unknown_solver_is_refused_with_the_choices() -> None:
    with pytest.raises(UnknownChoiceError,
                       match="unknown QP solver 'gurobi'; valid choices: daqp, osqp, proxsuite, "
                             "quadprog"):  # fmt: skip
        CBFQPController(N, M, solver="gurobi")


def test_failed_step_reports_the_hard_qp() -> None:
    """Both QPs unsolved (NaN cost): u = 0, and iterations are the hard QP's (0 here: the
    data never reach the backend)."""
    ctrl = CBFQPController(N, M, solver="proxsuite")
    obj = Objective(np.eye(N), np.full(N, np.nan))
    res = ctrl.step(obj, Inequalities(np.ones((M, N)), np.zeros(M)), QD_MAX)
    assert res.status == "failed" and res.command_solution is None
    np.testing.assert_array_equal(res.u, 0.0)
    assert res.relaxed_solution is not None and res.relaxed_solution.status == "failed"
    assert res.iterations == res.solution.iterations == 0
