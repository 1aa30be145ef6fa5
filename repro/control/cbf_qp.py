"""Vision + proximity CBF-QP controller of thomas2024 (Sec. III).

The cost is the 4-point IBVS task, the constraints one control-barrier-function
inequality per proximity sensor plus the joint-velocity bounds:

.. math::

    \\dot q = \\arg\\min_u \\tfrac12 u^T G u + u^T c
    \\quad \\text{s.t.}\\quad a_k^T u \\ge b_k,\\; u_{lower} \\le u \\le u_{upper}   (10)

    G = J_{4p}^T J_{4p} + \\mu I,\\quad c = \\lambda_{4p} J_{4p}^T e_{4p},\\quad
    a_k^T = L_{\\delta_{ij}}\\, {}^jV_{N_j} J_{N_j},\\quad b_k = -\\lambda_j (\\delta_{ij} - \\delta^*_{ij})   (9)

Like pink's tasks and barriers, each piece returns plain arrays; the
controller is a plain function that builds the QP, solves it and returns the
command with the QP's dual solution (for the stopping test, Sec. III-C).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from repro.control.qp import QPProblem, QPSolution, QPSolver, lower_multipliers


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
    return Objective(J_4p.T @ J_4p + mu * np.eye(n), lambda_4p * J_4p.T @ e_4p)


def cbf_inequalities(L_delta: np.ndarray, J_S: np.ndarray, delta: np.ndarray,
                     delta_star: float, gain: float) -> Inequalities:
    """thomas2024 eqs. (8)-(9): rows L_delta J_S u >= -gain (delta - delta*).

    Args:
        L_delta: (m, 6) interaction matrix of the ring's distances (ring frame).
        J_S: (6, n) Jacobian of the ring frame's twist expressed in the ring frame
            (= jV_Nj J_Nj).
        delta: (m,) measured distances [m].
        delta_star: threshold distance delta* [m].
        gain: lambda_j [1/s] of the class-K function alpha(e) = lambda_j e.
    """
    return Inequalities(L_delta @ J_S, -gain * (delta - delta_star))


@dataclass(frozen=True)
class CBFQPResult:
    """One control step of the CBF-QP.

    Attributes:
        u: commanded joint velocities (n,) [rad/s] (zero when the QP failed).
        status: the QP status ("solved", "infeasible", "max_iter", "failed").
        kappa: (m,) multipliers of the CBF rows (>= 0, thomas2024 eq. (13)).
        grad_L0: ||grad_u L(0, kappa*)|| = ||c - A^T kappa*|| (Sec. III-C stopping test).
        solution: the raw QP solution.
    """

    u: np.ndarray
    status: str
    kappa: np.ndarray
    grad_L0: float
    solution: QPSolution


def solve_cbf_qp(solver: QPSolver, objective: Objective, ineq: Inequalities,
                 qd_max: np.ndarray) -> CBFQPResult:
    """Solve eq. (10) with box bounds -qd_max <= u <= qd_max [rad/s].

    A QP that is not solved (infeasible, e.g. two opposite sensors both under
    their threshold; or failed) yields the stated fallback u = 0 and its status,
    which the caller logs as an event.
    """
    m = ineq.A.shape[0]
    problem = QPProblem(
        H=objective.H, g=objective.g, C=ineq.A, l=ineq.b, u=np.full(m, np.inf),
        lb=-qd_max, ub=qd_max,
    )
    sol = solver.solve(problem)
    kappa = lower_multipliers(sol)
    grad_L0 = float(np.linalg.norm(objective.g - ineq.A.T @ kappa))  # eq. (14) at u = 0
    if sol.status != "solved" or not np.all(np.isfinite(sol.x)):
        u = np.zeros_like(objective.g)
    else:
        u = sol.x
    return CBFQPResult(u=u, status=sol.status, kappa=kappa, grad_L0=grad_L0, solution=sol)


def least_squares_ibvs(objective: Objective) -> np.ndarray:
    """thomas2024 eq. (19): the unconstrained solution -G^-1 c."""
    return -np.linalg.solve(objective.H, objective.g)
