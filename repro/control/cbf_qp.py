r"""Vision + proximity CBF-QP controller of thomas2024 (Sec. III).

The cost is the 4-point IBVS task, the constraints one control-barrier-function
inequality per proximity sensor plus the joint-velocity bounds:

.. math::

    \dot q = \arg\min_u \tfrac12 u^T G u + u^T c
    \quad \text{s.t.}\quad a_k^T u \ge b_k,\; u_{lower} \le u \le u_{upper}   (10)

    G = J_{4p}^T J_{4p} + \mu I,\quad c = \lambda_{4p} J_{4p}^T e_{4p},\quad
    a_k^T = L_{\delta_{ij}}\, {}^jV_{N_j} J_{N_j},\quad
    b_k = -\lambda_j (\delta_{ij} - \delta^*_{ij})   (9)

Like pink's tasks and barriers, each piece returns plain arrays; the
controller is a plain function that builds the QP, solves it and returns the
command with the QP's dual solution (for the stopping test, Sec. III-C).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from repro.control import kernels
from repro.control.qp import QPProblem, QPSolution, QPSolver, lower_multipliers

_F64 = np.dtype(float)


class Objective(NamedTuple):
    """Quadratic cost 1/2 u^T H u + g^T u."""

    H: np.ndarray
    g: np.ndarray


class Inequalities(NamedTuple):
    """Rows A u >= b."""

    A: np.ndarray
    b: np.ndarray


def ibvs_objective(J_4p: np.ndarray, e_4p: np.ndarray, lambda_4p: float, mu: float) -> Objective:
    """thomas2024 eq. (10) cost: G = J^T J + mu I, c = lambda_4p J^T e.

    Args:
        J_4p: (8, n) feature Jacobian d(e_4p)/dq (normalised image coordinates / rad).
        e_4p: (8,) feature error s - s* (normalised coordinates).
        lambda_4p: IBVS gain [1/s].
        mu: regularisation (thomas2024: 0.01).
    """
    n = J_4p.shape[1]
    # (ndarray.dot: the BLAS calls of @ -- syrk for J^T J, gemv --, without the matmul
    # ufunc's overhead on these small arrays; the same bits)
    G = J_4p.T.dot(J_4p)  # (a fresh C-contiguous array)
    if not (G.dtype == _F64 and isinstance(mu, float | int)
            and kernels.add_to_diagonal(G, float(mu))):  # + mu I, compiled
        G.ravel()[:: n + 1] += mu  # (a view of G's diagonal; the same operation)
    return Objective(G, (lambda_4p * J_4p.T).dot(e_4p))


def cbf_inequalities(L_delta: np.ndarray, J_S: np.ndarray, delta: np.ndarray,
                     delta_star: float, gain: float,
                     out: tuple[np.ndarray, np.ndarray] | None = None) -> Inequalities:
    """thomas2024 eqs. (8)-(9): rows L_delta J_S u >= -gain (delta - delta*).

    Args:
        L_delta: (m, 6) interaction matrix of the ring's distances (ring frame).
        J_S: (6, n) Jacobian of the ring frame's twist expressed in the ring frame
            (= jV_Nj J_Nj).
        delta: (m,) measured distances [m].
        delta_star: threshold distance delta* [m].
        gain: lambda_j [1/s] of the class-K function alpha(e) = lambda_j e.
        out: None, or ``(A, b)``: arrays (m, n) and (m,) (e.g. a ring's rows of the whole
            QP's; not overlapping the inputs) to write the rows into, with the same
            operations, when the rows fit them (float64 arrays throughout, ``A`` C-contiguous,
            ``L_delta`` (m, 6), ``J_S`` (6, n), ``delta`` (m,); ``delta_star`` and ``gain``
            Python floats or integers): the result then holds ``out``; otherwise fresh
            arrays, as with None.
    """
    if out is None or not _rows_fit(L_delta, J_S, delta, delta_star, gain, out):
        return Inequalities(L_delta.dot(J_S), -gain * (delta - delta_star))  # .dot: @ for 2-D
    A, b = out
    L_delta.dot(J_S, out=A)
    if not kernels.cbf_offsets(delta, float(delta_star), float(-gain), b):
        np.subtract(delta, delta_star, out=b)  # (non-finite values: NumPy's operations)
        np.multiply(-gain, b, out=b)
    return Inequalities(A, b)


def _rows_fit(L_delta: np.ndarray, J_S: np.ndarray, delta: np.ndarray, delta_star: float,
              gain: float, out: tuple[np.ndarray, np.ndarray]) -> bool:
    """:func:`cbf_inequalities`' rows can be written into ``out`` (see there)."""
    A, b = out
    m, n = A.shape
    nd = np.ndarray
    return (isinstance(delta_star, float | int) and isinstance(gain, float | int)
            and type(L_delta) is nd and type(J_S) is nd and type(delta) is nd
            and L_delta.dtype == J_S.dtype == delta.dtype == A.dtype == b.dtype == _F64
            and A.flags.c_contiguous and L_delta.ndim == 2 and L_delta.shape[0] == m
            and J_S.shape == (L_delta.shape[1], n) and delta.shape == b.shape == (m,))


@dataclass(frozen=True)
class CBFQPResult:
    """One control step of the CBF-QP.

    Attributes:
        u: commanded joint velocities (n,) [rad/s].
        status: "solved"; "relaxed" when the hard QP was infeasible (or not solved
            within its iteration budget) and the slack-relaxed QP gave u; "failed"
            when both failed (then u = 0, the stated fallback).
        qp_status: the hard QP's own status ("solved", "infeasible", "max_iter", "failed").
        kappa: (m,) multipliers of the CBF rows (>= 0, thomas2024 eq. (13)); from the
            relaxed QP when status is "relaxed".
        grad_L0: ||grad_u L(0, kappa*)|| = ||c - A^T kappa*|| (Sec. III-C stopping test).
        slack: (m,) CBF violations accepted by the relaxed QP [same units as b] (0 if solved).
        solution: the hard QP's raw solution (``solution.iterations`` is the hard QP's,
            also when u comes from the relaxed QP: use :attr:`iterations` for the command's).
        relaxed_solution: the slack-relaxed QP's solution when it was tried (hard QP not
            solved), else None.
    """

    u: np.ndarray
    status: str
    qp_status: str
    kappa: np.ndarray
    grad_L0: float
    slack: np.ndarray
    solution: QPSolution
    relaxed_solution: QPSolution | None = None

    @property
    def command_solution(self) -> QPSolution | None:
        """The solve whose ``x`` is u: the hard QP when "solved", the relaxed QP when
        "relaxed", None when "failed" (u = 0)."""
        if self.status == "solved":
            return self.solution
        if self.status == "relaxed":
            return self.relaxed_solution
        return None

    @property
    def iterations(self) -> int:
        """Iterations of the one solve whose solution is u (:attr:`command_solution`; the
        hard QP's when "failed"), at most that solve's ``max_iter``: outer ALM iterations
        for proxsuite, ADMM iterations for OSQP, active-set iterations for DAQP and quadprog
        (see :mod:`repro.control.qp`)."""
        sol = self.command_solution
        return (self.solution if sol is None else sol).iterations

    @property
    def solve_time_s(self) -> float:
        """Wall time of every QP solve of this step (hard, plus relaxed if tried) [s]."""
        t = self.solution.solve_time_s
        return t if self.relaxed_solution is None else t + self.relaxed_solution.solve_time_s


#: Default iteration budgets of the hard QP per solver.
DEFAULT_MAX_ITER = {"proxsuite": 200, "osqp": 10000, "daqp": 200, "quadprog": 200}


class CBFQPController:
    r"""Solves eq. (10) each control step, warm-started, with a stated fallback.

    The hard QP of eq. (10) can be infeasible: two opposite sensors both under
    their threshold ask for a_k^T u >= b_k > 0 and -a_k^T u >= b_k' > 0. The
    paper does not say what its controller did then; ours (a standard CBF-QP
    practice) re-solves with one non-negative slack s_k per CBF row,

    .. math:: \min_{u, s} \tfrac12 u^T G u + c^T u + \tfrac{\rho}{2} \|s\|^2
              \;\text{s.t.}\; a_k^T u + s_k \ge b_k,\; s \ge 0,\; u_{lower} \le u \le u_{upper}

    which is always feasible; the run logs the event. If that fails too, u = 0.

    Iteration budgets: a hard solve that runs out of ``max_iter`` is "max_iter", never
    "solved", and goes to the fallback; its warm attempt and cold retry each get the budget
    (``QPSolver.solve``). The relaxed QP has its own, larger budget ``relaxed_max_iter``,
    so :attr:`CBFQPResult.iterations` is at most ``max_iter`` when the status is "solved"
    and at most ``relaxed_max_iter`` when it is "relaxed".

    Args:
        n: joints; m: CBF rows.
        solver: one of :data:`repro.control.qp.SOLVERS`: "proxsuite" (the paper's),
            "osqp", "daqp" or "quadprog".
        max_iter: iteration budget of each hard solve (bounds the time an infeasible QP
            costs); None = the solver's default: 200 outer iterations (and at most 200
            Newton steps in each) for proxsuite, 10000 ADMM iterations for OSQP (its count
            is of much cheaper steps), 200 active-set iterations for DAQP and quadprog.
        slack_weight: rho. # ours: 1e4 makes a 1 mm/s violation cost like 0.1 rad/s of task error
    """

    def __init__(self, n: int, m: int, solver: str = "proxsuite", max_iter: int | None = None,
                 slack_weight: float = 1e4) -> None:
        self.n, self.m = n, m
        if max_iter is None:
            max_iter = DEFAULT_MAX_ITER.get(solver, 200)
        self.max_iter = max_iter
        self.hard = QPSolver(n, m, solver=solver, max_iter=max_iter)
        # Always feasible, used rarely: cold-started, with a larger budget (OSQP's ADMM
        # needs ~16000 iterations on it for m = 36 because of the slack weight's scale).
        self.relaxed_max_iter = max(40000 if solver == "osqp" else 2000, 10 * max_iter)
        self.relaxed = (QPSolver(n + m, m, solver=solver, max_iter=self.relaxed_max_iter,
                                 warm_start=False) if m else None)
        self.slack_weight = slack_weight
        self._u_inf = np.full(m, np.inf)
        self._u_inf.flags.writeable = False
        self._no_slack = np.zeros(m)  # the slack of a solved hard QP (read-only, shared)
        self._no_slack.flags.writeable = False

    def step(self, objective: Objective, ineq: Inequalities, qd_max: np.ndarray) -> CBFQPResult:
        """Solve eq. (10) with box bounds -qd_max <= u <= qd_max [rad/s]."""
        n, m = self.n, self.m
        # H, g, C, l, u, lb, ub (positional: cheaper)
        problem = QPProblem(objective.H, objective.g, ineq.A, ineq.b, self._u_inf, -qd_max, qd_max)
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


def least_squares_ibvs(objective: Objective) -> np.ndarray:
    """thomas2024 eq. (19): the unconstrained solution -G^-1 c."""
    return -np.linalg.solve(objective.H, objective.g)
