r"""Nonlinear MPC for eye-in-hand image-based visual servoing (chan2011, Sections II-III).

The optimisation problem is built **once** with CasADi (safe-control-gym style); at every
control step :meth:`VisualNMPC.solve` only sets the parameters and the bounds and
warm-starts the solver from the previous solution (primal and dual).

Notation: here ``n`` is the number of joints and ``N`` (``n_points``) the number of feature
points -- chan2011 writes them the other way round (N joints, n points).

Model (chan2011 eqs. (1)-(3), (9)):

.. math::

    q_{k+i|k} = q_k + i\,\delta_t\,\dot q, \qquad i = 0, \dots, N_p - 1
    \quad \text{(eq. (9), control horizon } N_c = 1\text{: one } \dot q \text{ held)}

    (u_j, v_j, 1)^T \propto C \,[I_3 | 0]\, {}^cT_b(q)\, {}^bT_o\, {}^oP_j, \qquad
    {}^cT_b(q) = ({}^bT_c(q))^{-1}

with :math:`{}^bT_c(q)` given by ``fk_camera`` (pose of the camera frame in the base frame,
camera frame x right, y down, z forward, as :mod:`repro.sensors.camera`), the camera
matrix :math:`C` of eq. (1) = ``intrinsics.K()`` (a :class:`repro.sensors.camera.Intrinsics`;
:meth:`~repro.sensors.camera.Intrinsics.from_pixel_pitch` builds it from f, k_u, k_v,
u_0, v_0, beta) and the pixel vector :math:`\bar p = (u_1, v_1, \dots, u_N, v_N)` (eq. (3)).

Problem solved at step k (eqs. (10), (12), constraints (4)-(7)), decision variable
:math:`\dot q \in \mathbb{R}^n`:

.. math::

    \min_{\dot q} \; \tfrac12 \sum_{i=1}^{N_p-1}
        \left(\epsilon_i^T Q \epsilon_i + \dot q^T W \dot q\right), \qquad
    \epsilon_i = \bar p(q_{k+i|k}) - \bar p^d + d_k

    \text{s.t.} \quad q^{lo} \le q_{k+i|k} \le q^{hi}, \quad
    \dot q^{lo} \le \dot q \le \dot q^{hi}, \quad
    u^{\min} + m \le u_j \le u^{\max} - m, \quad v^{\min} + m \le v_j \le v^{\max} - m, \quad
    Z_j(q_{k+i|k}) \ge Z_{\min}

for :math:`i = 1..N_p-1` and every point j (:math:`m` = ``fov_margin``; the bounds
:math:`u^{\min}, \dots` are the ``image_bounds`` given to :class:`VisualNMPC`). ``q_lo, q_hi`` are
the joint limits (4), or the DCC collision-free hyper-rectangle (chan2011 eq. (20)) that
replaces (8). The FOV rows apply to the corrected prediction :math:`\bar p(q) + d_k` (the
best estimate of what the camera will see) unless ``NMPCConfig.fov_on_corrected`` is False.
The depth rows :math:`Z_j > 0` are ours (the projection is undefined behind the camera).

**Sign of the disturbance term** :math:`d_k`. Here

.. math:: d_k = \bar p_k - \bar p(q_{k|k-1}) \quad \text{(measured minus model)},

so that at :math:`i = 0` (with :math:`q_{k|k} = q_{k|k-1}`) the corrected error equals the
measured error: :math:`\epsilon_{0|k} = \bar p_k - \bar p^d`. This is the usual
output-disturbance (DMC) correction. chan2011 prints eq. (11) as
:math:`d_k = \bar p(q_{k|k-1}) - \bar p_k` *and* adds it in eq. (10); taken literally that
gives :math:`\epsilon_{0|k} = 2\bar p(q_k) - \bar p_k - \bar p^d`, which doubles the model
error instead of cancelling it, so we read one of the two printed signs as a typo: our
:math:`d_k` is the negative of the printed (11), added as in (10). Use
:meth:`VisualNMPC.disturbance` to compute it.

**Solvers.** ``solver="sqp"``: CasADi ``sqpmethod`` with a Gauss-Newton Hessian — the
cost is written as :math:`\tfrac12\|r(\dot q)\|^2` with
:math:`r = (\sqrt{Q}\epsilon_1, \dots, \sqrt{Q}\epsilon_{N_p-1}, \sqrt{(N_p-1)W}\,\dot q)`
and the option ``hess_lag`` is given the function
:math:`\sigma_f J_r^T J_r` (positive semidefinite, constraint curvature ignored), so every
QP is convex; gradients and Jacobians are exact (CasADi AD). The QP solver is ``qpsol``
(qpOASES by default, silenced). ``solver="ipopt"``: the same NLP with IPOPT, Hessian
``NMPCConfig.hessian`` (Gauss-Newton, exact or limited-memory), silenced. Both see the cost
divided by a scale set at each solve (the mean curvature of the Gauss-Newton model at the
initial guess), so that their absolute tolerances are relative to the problem.

Measured (tests/test_nmpc.py, Panda n = 7, N = 10): Gauss-Newton SQP + qpOASES or DAQP
takes about 1 ms (Np = 5) and 2.3 ms (Np = 10) per warm-started closed-loop solve, IPOPT
5-17 ms. Gauss-Newton converges linearly when the residuals are large (a far desired
image), hence 5-10 SQP iterations; ``hessian="exact"`` (convexified by eigenvalue
clipping) needs 2-3 iterations there, but on hard cold starts with active FOV constraints
its QPs failed more often (38/50 vs 47/50 successes). DAQP needs its primal tolerance
lowered (set here) to meet ``feas_tol``. With OSQP (inexact ADMM QP solutions) the SQP
rarely reached ``tol`` within 20 iterations; proxqp, HiGHS and qrqp work but were slower
or failed more often in a short closed-loop check.
A returned solution is only flagged ``success`` if it meets every bound within
``NMPCConfig.feas_tol``: the caller must fall back (e.g. zero velocity) otherwise.
"""

from __future__ import annotations

import contextlib
import io
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from repro.errors import ConfigError, UnknownChoiceError
from repro.runs.signals import deferred
from repro.sensors.camera import ImageBounds, Intrinsics

#: Valid ``NMPCConfig.solver`` values.
SOLVERS: tuple[str, ...] = ("sqp", "ipopt")
#: Valid ``NMPCConfig.hessian`` values.
HESSIANS: tuple[str, ...] = ("gauss-newton", "exact", "limited-memory")

#: Options that keep each CasADi QP plugin quiet (used by sqpmethod's ``qpsol_options``).
_QUIET_QPSOL: dict[str, dict[str, Any]] = {
    "qpoases": {"printLevel": "none"},
    "daqp": {"daqp": {"primal_tol": 1e-9}},  # default 1e-6 left 6e-6 px FOV violations
    "osqp": {"osqp": {"verbose": False}},
    "proxqp": {},
    "qrqp": {"print_iter": False, "print_header": False, "print_info": False},
    "highs": {"highs": {"output_flag": False}},
}


@dataclass(frozen=True)
class NMPCConfig:
    """Tuning of :class:`VisualNMPC` (defaults: chan2011 Section III-A simulations).

    Attributes:
        Np: prediction horizon N_p (>= 2); the cost sums i = 1..Np-1 (eq. (12)).
        dt: prediction time step delta_t [s] (eq. (9)).
        Q_weight: Q = Q_weight * I on the pixel errors [1/px^2].
        W_weight: W = W_weight * I on the joint velocities [s^2/rad^2].
        fov_margin: the FOV constraints are tightened by this much on each side [px].
        min_depth: minimum predicted depth of every point in the camera frame [m] (ours).
        fov_on_corrected: FOV constraints on p(q) + d_k (True) or on the raw model p(q).
        solver: "sqp" (casadi sqpmethod) or "ipopt".
        qpsol: QP solver of sqpmethod ("qpoases", "daqp", "osqp", "proxqp", "qrqp", "highs").
        hessian: "gauss-newton" (J_r^T J_r, default), "exact" (of the Lagrangian) or
            "limited-memory" (BFGS).
        max_iter: iteration limit of the NLP solver (SQP iterations or IPOPT iterations).
        tol: sqpmethod tol_pr/tol_du, IPOPT tol.
        feas_tol: a returned solution violating a bound by more than this [rad, px, m,
            rad/s] is reported as failed, whatever the solver says.
    """

    Np: int = 5
    dt: float = 0.01
    Q_weight: float = 1.0
    W_weight: float = 2500.0
    fov_margin: float = 0.0
    min_depth: float = 1e-3
    fov_on_corrected: bool = True
    solver: str = "sqp"
    qpsol: str = "qpoases"
    hessian: str = "gauss-newton"
    max_iter: int = 20
    tol: float = 1e-6
    feas_tol: float = 1e-6

    def __post_init__(self) -> None:
        if self.solver not in SOLVERS:
            raise UnknownChoiceError("NMPC solver", self.solver, SOLVERS)
        if self.hessian not in HESSIANS:
            raise UnknownChoiceError("NMPC Hessian", self.hessian, HESSIANS)
        if self.solver == "sqp" and self.qpsol not in _QUIET_QPSOL:
            raise UnknownChoiceError("sqpmethod QP solver", self.qpsol, _QUIET_QPSOL)
        if self.Np < 2:
            raise ConfigError(f"prediction horizon Np must be >= 2, got {self.Np}")
        if not self.dt > 0:
            raise ConfigError(f"dt must be > 0 s, got {self.dt}")
        if not (self.Q_weight > 0 and self.W_weight > 0):
            raise ConfigError(f"Q_weight and W_weight must be > 0, got {self.Q_weight}, "
                              f"{self.W_weight}")
        if self.fov_margin < 0 or self.min_depth < 0:
            raise ConfigError(f"fov_margin and min_depth must be >= 0, got {self.fov_margin}, "
                              f"{self.min_depth}")
        if self.max_iter < 1:
            raise ConfigError(f"max_iter must be >= 1, got {self.max_iter}")


@dataclass(frozen=True)
class NMPCSolution:
    """Result of one :meth:`VisualNMPC.solve`.

    Attributes:
        qdot: (n,) joint velocity to apply over the next step [rad/s]. When ``success`` is
            False it is the solver's last iterate (non-finite entries set to 0): apply it
            only when :attr:`usable`, else use a fallback (e.g. zero velocity).
        success: the solver converged and the solution satisfies every bound within
            ``NMPCConfig.feas_tol``.
        status: the solver's ``return_status`` (or the exception message).
        iterations: SQP or IPOPT iterations.
        solve_time_s: wall-clock time of the solver call [s].
        cost: value of the cost (12) at ``qdot``.
        p_pred: (Np, 2N) predicted pixels p(q_{k+i|k}) + d_k, i = 0..Np-1 [px], row i laid
            out (u_1, v_1, ..., u_N, v_N); row 0 is the measured p_k when d_k is consistent.
        q_pred: (Np, n) predicted joint positions q_k + i dt qdot [rad].
        max_violation: largest bound violation of the returned point [mixed units].
        feasible: the returned point is finite and within ``feas_tol`` of every bound
            (whether or not the solver converged).
        iteration_limit: the solver stopped on its iteration limit (``max_iter``) rather
            than converging or failing: its last iterate may still be feasible (an
            SQP iterate of a convex-constrained step is a valid, if suboptimal, command).
    """

    qdot: np.ndarray
    success: bool
    status: str
    iterations: int
    solve_time_s: float
    cost: float
    p_pred: np.ndarray
    q_pred: np.ndarray
    max_violation: float
    feasible: bool = False
    iteration_limit: bool = False

    @property
    def usable(self) -> bool:
        """Whether ``qdot`` may be commanded: converged and feasible, or the last iterate of
        a solve stopped on its iteration limit that meets every constraint within
        ``feas_tol`` (chan2011, issue 17: discarding such iterates stalled variant runs for
        good; an iterate inside the constraints is a motion they allow, if not the optimal
        one). Otherwise fall back (e.g. zero velocity)."""
        return self.success or (self.feasible and self.iteration_limit)


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Discard what CasADi prints inside the block (CasADi routes its plugins' output,
    including qpOASES's, through Python's ``sys.stdout``)."""
    with contextlib.redirect_stdout(io.StringIO()):
        yield


def _vec(a: np.ndarray | Sequence[float], shape: tuple[int, ...], name: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.shape != shape:
        raise ConfigError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.isfinite(a).all():
        raise ConfigError(f"{name} has non-finite entries: {a}")
    return a


class VisualNMPC:
    """chan2011 NMPC visual servoing controller (see the module docstring for the math).

    Args:
        fk_camera: CasADi function ``q (n,) -> T_base_camera (4x4)`` (e.g.
            :func:`repro.sim.casadi_kinematics.frame_pose_casadi` with ``T_frame_child`` the
            camera mounting); MX functions are expanded to SX.
        intrinsics: the controller's camera model, C = ``intrinsics.K()`` (eq. (1); any
            skew included). Only fu, fv, u0, v0 and skew are used.
        n_points: number N of feature points.
        q_min, q_max: (n,) default joint bounds of the predicted configurations [rad].
        qd_max: (n,) default joint velocity bound magnitude [rad/s] (qd in [-qd_max, qd_max]).
        config: tuning.
        image_bounds: (keyword, required) the field of view u in [u_min, u_max],
            v in [v_min, v_max] [px] of the constraints (6)-(7), e.g. the paper's Table I
            bounds or the whole image, ``intrinsics.image_bounds()``.

    The NLP parameters are ``q_k`` (n), ``p_d`` (2N), ``d_k`` (2N), ``T_base_object`` (3x4
    top rows), the object points (3xN, object frame) and the cost scale (set by
    :meth:`solve`, see the module docstring); the bounds ``q_lo, q_hi`` (on
    the rows q_{k+i|k}) and ``qd_lo, qd_hi`` (on the decision variable) are set through the
    solver's ``lbg/ubg`` and ``lbx/ubx`` inputs at every call.
    """

    def __init__(self, fk_camera: ca.Function, intrinsics: Intrinsics, n_points: int,
                 q_min: Sequence[float] | np.ndarray, q_max: Sequence[float] | np.ndarray,
                 qd_max: Sequence[float] | np.ndarray,
                 config: NMPCConfig | None = None, *, image_bounds: ImageBounds) -> None:
        self.config = cfg = NMPCConfig() if config is None else config
        self.intrinsics = intrinsics
        self.image_bounds = bounds = ImageBounds(*(float(b) for b in image_bounds))
        if not (bounds.u_min < bounds.u_max and bounds.v_min < bounds.v_max):
            raise ConfigError(f"empty field of view: u in [{bounds.u_min}, {bounds.u_max}], "
                              f"v in [{bounds.v_min}, {bounds.v_max}] px")
        if n_points < 1:
            raise ConfigError(f"n_points must be >= 1, got {n_points}")
        self.n_points = m = int(n_points)
        if fk_camera.n_in() != 1 or fk_camera.n_out() < 1:
            raise ConfigError(f"fk_camera must map q to a 4x4 pose, got {fk_camera}")
        self.n = n = fk_camera.size1_in(0) * fk_camera.size2_in(0)
        if fk_camera.size_out(0) != (4, 4):
            raise ConfigError(f"fk_camera must return a 4x4 pose, got {fk_camera.size_out(0)}")
        self._fk = fk_camera if fk_camera.is_a("SXFunction") else fk_camera.expand()
        self.q_min = _vec(q_min, (n,), "q_min")
        self.q_max = _vec(q_max, (n,), "q_max")
        self.qd_max = _vec(qd_max, (n,), "qd_max")
        Np = cfg.Np

        # ---- symbols
        qdot = ca.SX.sym("qdot", n)
        q_k = ca.SX.sym("q_k", n)
        p_d = ca.SX.sym("p_d", 2 * m)
        d_k = ca.SX.sym("d_k", 2 * m)
        T_bo = ca.SX.sym("T_base_object", 3, 4)
        P_o = ca.SX.sym("P_object", 3, m)
        params = ca.vertcat(q_k, p_d, d_k, ca.vec(T_bo), ca.vec(P_o))
        cost_scale = ca.SX.sym("cost_scale")  # see below
        nlp_params = ca.vertcat(params, cost_scale)

        # ---- model p(q), Z(q) (chan2011 eq. (2))
        q_sym = ca.SX.sym("q", n)
        pix, depth = self._project(q_sym, T_bo, P_o)
        self._pixels_fun = ca.Function("pixels", [q_sym, T_bo, P_o], [pix, depth],
                                       ["q", "T_base_object", "P_object"], ["p", "Z"])
        self._pixels_jac_fun = ca.Function("pixels_jac", [q_sym, T_bo, P_o],
                                           [ca.jacobian(pix, q_sym)])

        # ---- prediction (eq. (9)), errors (eq. (10)), residual of the cost (eq. (12))
        q_rows, fov_rows, depth_rows, res, p_pred, q_pred = [], [], [], [], [], []
        for i in range(Np):
            q_i = q_k + i * cfg.dt * qdot
            p_i, Z_i = self._pixels_fun(q_i, T_bo, P_o)
            q_pred.append(q_i.T)
            p_pred.append((p_i + d_k).T)
            if i == 0:
                continue
            res.append(math.sqrt(cfg.Q_weight) * (p_i - p_d + d_k))
            q_rows.append(q_i)
            fov_rows.append(p_i + d_k if cfg.fov_on_corrected else p_i)
            depth_rows.append(Z_i)
        res.append(math.sqrt((Np - 1) * cfg.W_weight) * qdot)
        r = ca.vertcat(*res)
        cost = 0.5 * ca.dot(r, r)
        # ours: the solvers see cost / s with s = trace(J_r^T J_r) / n at the initial guess
        # (the mean curvature of the Gauss-Newton model, >= (Np-1) W), set at every solve,
        # so that the absolute tolerances of the solvers are relative to the problem's
        # scale: with an inactive set, |qdot - qdot*| <~ tol * s / lambda_min(J_r^T J_r)
        # [rad/s], whatever the weights and the pixel scale.
        J_r_unscaled = ca.jacobian(r, qdot)
        self._scale_fun = ca.Function("cost_scale", [qdot, params],
                                      [ca.sumsqr(J_r_unscaled) / n])
        r_scaled = r / ca.sqrt(cost_scale)
        g = ca.vertcat(*q_rows, *fov_rows, *depth_rows)
        self._ng = g.numel()
        self._g_fun = ca.Function("constraints", [qdot, params], [g])
        self._traj_fun = ca.Function("trajectory", [qdot, params],
                                     [ca.vertcat(*q_pred), ca.vertcat(*p_pred), cost])

        # constant FOV bounds (6)-(7) and depth bounds, tightened by the margin
        fov_lo = np.tile([bounds.u_min + cfg.fov_margin, bounds.v_min + cfg.fov_margin],
                         m * (Np - 1))
        fov_hi = np.tile([bounds.u_max - cfg.fov_margin, bounds.v_max - cfg.fov_margin],
                         m * (Np - 1))
        if np.any(fov_lo > fov_hi):
            raise ConfigError(f"fov_margin {cfg.fov_margin} px leaves an empty field of view")
        self._fov_lo, self._fov_hi = fov_lo, fov_hi

        # ---- solver
        nlp = {"x": qdot, "p": nlp_params, "f": 0.5 * ca.dot(r_scaled, r_scaled), "g": g}
        opts: dict[str, Any] = {"print_time": False, "error_on_fail": False}
        if cfg.hessian == "gauss-newton":
            sigma = ca.SX.sym("lam_f")
            lam_g = ca.SX.sym("lam_g", self._ng)
            J_r = ca.jacobian(r_scaled, qdot)
            H = ca.densify(sigma * ca.mtimes(J_r.T, J_r))
            if cfg.solver == "ipopt":  # IPOPT takes the upper triangle, sqpmethod all of it
                H = ca.triu(H)
            opts["hess_lag"] = ca.Function("nlp_hess_l", [qdot, nlp_params, sigma, lam_g], [H],
                                           ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])
        if cfg.solver == "sqp":
            opts.update({
                "qpsol": cfg.qpsol,
                "qpsol_options": {**_QUIET_QPSOL[cfg.qpsol], "error_on_fail": False},
                "max_iter": cfg.max_iter,
                "tol_pr": cfg.tol,
                "tol_du": cfg.tol,
                "print_header": False,
                "print_iteration": False,
                "print_status": False,
            })
            if cfg.hessian == "limited-memory":
                opts["hessian_approximation"] = "limited-memory"
            elif cfg.hessian == "exact":
                # the exact Lagrangian Hessian may be indefinite: make the QPs convex
                # ("regularize" stalled at linear convergence in our tests, eigen-clip did not)
                opts["convexify_strategy"] = "eigen-clip"
            with _quiet_stdout():  # qpOASES prints its licence banner when constructed
                self._solver = ca.nlpsol("visual_nmpc", "sqpmethod", nlp, opts)
        else:
            ipopt: dict[str, Any] = {
                "print_level": 0,
                "sb": "yes",
                "max_iter": cfg.max_iter,
                "tol": cfg.tol,
                "constr_viol_tol": 0.1 * cfg.feas_tol,
                "bound_relax_factor": 0.0,
                "warm_start_init_point": "yes",
                "mu_init": 1e-3,
            }
            if cfg.hessian == "limited-memory":
                ipopt["hessian_approximation"] = "limited-memory"
            opts["ipopt"] = ipopt
            self._solver = ca.nlpsol("visual_nmpc", "ipopt", nlp, opts)
        self._nlp, self._solver_opts = nlp, opts
        self._warm: dict[str, np.ndarray] | None = None

    # ------------------------------------------------------------------ model
    def _project(self, q: ca.SX, T_bo: ca.SX, P_o: ca.SX) -> tuple[ca.SX, ca.SX]:
        """Symbolic pixels (2N,) and depths (N,) of the object points at q (eq. (2))."""
        m = self.n_points
        T_bc = self._fk(q)
        R_bc, t_bc = T_bc[:3, :3], T_bc[:3, 3]
        P_b = ca.mtimes(T_bo[:, :3], P_o) + ca.repmat(T_bo[:, 3], 1, m)
        # cT_b = (bT_c)^-1: P_c = R_bc^T (P_b - t_bc)
        P_c = ca.mtimes(R_bc.T, P_b - ca.repmat(t_bc, 1, m))
        X, Y, Z = P_c[0, :], P_c[1, :], P_c[2, :]
        C = self.intrinsics.K()  # chan2011 eq. (1)
        x, y = X / Z, Y / Z
        u = C[0, 0] * x + C[0, 1] * y + C[0, 2]
        v = C[1, 1] * y + C[1, 2]
        return ca.vec(ca.vertcat(u, v)), Z.T

    def _pose_points(self, T_base_object: np.ndarray, points: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
        T = _vec(T_base_object, (4, 4), "T_base_object")
        P = _vec(points, (self.n_points, 3), "points")
        return T[:3, :], P.T

    def predict_pixels(self, q: np.ndarray, T_base_object: np.ndarray,
                       points: np.ndarray) -> np.ndarray:
        """Model output p(q) (2N,) [px] = (u_1, v_1, ..., u_N, v_N), chan2011 eqs. (2)-(3).

        Args:
            q: (n,) joint positions [rad].
            T_base_object: 4x4 (estimated) pose of the object frame in the base frame [m].
            points: (N, 3) feature points in the object frame [m].
        """
        T, P = self._pose_points(T_base_object, points)
        return np.asarray(self._pixels_fun(_vec(q, (self.n,), "q"), T, P)[0]).ravel()

    def predict_depths(self, q: np.ndarray, T_base_object: np.ndarray,
                       points: np.ndarray) -> np.ndarray:
        """Depths Z_j (N,) of the points in the camera frame at q [m]."""
        T, P = self._pose_points(T_base_object, points)
        return np.asarray(self._pixels_fun(_vec(q, (self.n,), "q"), T, P)[1]).ravel()

    def image_jacobian(self, q: np.ndarray, T_base_object: np.ndarray,
                       points: np.ndarray) -> np.ndarray:
        """d p(q) / d q (2N, n) [px/rad]: image Jacobian times robot Jacobian, by CasADi AD."""
        T, P = self._pose_points(T_base_object, points)
        return np.asarray(self._pixels_jac_fun(_vec(q, (self.n,), "q"), T, P))

    def disturbance(self, p_measured: np.ndarray, q_model: np.ndarray,
                    T_base_object: np.ndarray, points: np.ndarray) -> np.ndarray:
        """d_k = p_k - p(q_{k|k-1}) (2N,) [px]: measured minus model output.

        The negative of chan2011's printed eq. (11); see the module docstring. ``q_model``
        is the configuration the model predicted for time k (q_{k|k-1}); with a kinematic
        model and perfectly tracked velocities it is the measured q_k.
        """
        p_k = _vec(p_measured, (2 * self.n_points,), "p_measured")
        return p_k - self.predict_pixels(q_model, T_base_object, points)

    def reset(self) -> None:
        """Forget the warm start (the next solve starts from qdot = 0, zero multipliers)."""
        self._warm = None

    # ------------------------------------------------------------------ solve
    def solve(self, q_k: np.ndarray, p_d: np.ndarray, d_k: np.ndarray,
              T_base_object: np.ndarray, points: np.ndarray,
              q_lo: np.ndarray | None = None, q_hi: np.ndarray | None = None,
              qd_lo: np.ndarray | None = None, qd_hi: np.ndarray | None = None,
              warm_start: bool = True) -> NMPCSolution:
        """Solve the NMPC problem at step k (:meth:`_solve`). A SIGINT / SIGTERM that comes
        while CasADi runs is held until it returns (:func:`repro.runs.signals.deferred`): a
        KeyboardInterrupt raised inside CasADi would be swallowed or corrupt its result."""
        with deferred():
            return self._solve(q_k, p_d, d_k, T_base_object, points, q_lo, q_hi, qd_lo,
                               qd_hi, warm_start)

    def _solve(self, q_k: np.ndarray, p_d: np.ndarray, d_k: np.ndarray,
               T_base_object: np.ndarray, points: np.ndarray,
               q_lo: np.ndarray | None, q_hi: np.ndarray | None,
               qd_lo: np.ndarray | None, qd_hi: np.ndarray | None,
               warm_start: bool) -> NMPCSolution:
        """Solve the NMPC problem at step k.

        Args:
            q_k: (n,) current joint positions [rad].
            p_d: (2N,) desired pixels (u_1, v_1, ...) [px].
            d_k: (2N,) disturbance correction p_k - p(q_{k|k-1}) [px] (:meth:`disturbance`).
            T_base_object: 4x4 estimated object pose in the base frame [m].
            points: (N, 3) feature points in the object frame [m].
            q_lo, q_hi: (n,) bounds of q_{k+i|k}, i >= 1 [rad] (default: the joint limits;
                chan2011 replaces them by the DCC hyper-rectangle when (20) fails).
            qd_lo, qd_hi: (n,) bounds of qdot [rad/s] (default: -qd_max, qd_max).
            warm_start: start from the previous solution (primal and dual) if there is one.

        Returns:
            :class:`NMPCSolution`; solver failures are reported, never raised.

        Raises:
            ConfigError: wrong shapes, non-finite inputs, or a lower bound above its upper bound.
        """
        cfg, n, m, Np = self.config, self.n, self.n_points, self.config.Np
        q_k = _vec(q_k, (n,), "q_k")
        p_d = _vec(p_d, (2 * m,), "p_d")
        d_k = _vec(d_k, (2 * m,), "d_k")
        T, P = self._pose_points(T_base_object, points)
        q_lo = self.q_min if q_lo is None else _vec(q_lo, (n,), "q_lo")
        q_hi = self.q_max if q_hi is None else _vec(q_hi, (n,), "q_hi")
        qd_lo = -self.qd_max if qd_lo is None else _vec(qd_lo, (n,), "qd_lo")
        qd_hi = self.qd_max if qd_hi is None else _vec(qd_hi, (n,), "qd_hi")
        for name, lo, hi in (("q", q_lo, q_hi), ("qd", qd_lo, qd_hi)):
            if np.any(lo > hi):
                raise ConfigError(f"{name}_lo > {name}_hi: {lo} > {hi}")

        params = np.concatenate([q_k, p_d, d_k, T.ravel(order="F"), P.ravel(order="F")])
        lbg = np.concatenate([np.tile(q_lo, Np - 1), self._fov_lo,
                              np.full((Np - 1) * m, cfg.min_depth)])
        ubg = np.concatenate([np.tile(q_hi, Np - 1), self._fov_hi,
                              np.full((Np - 1) * m, np.inf)])
        t0 = time.perf_counter()
        warm = self._warm if warm_start else None
        x0 = np.clip(np.zeros(n) if warm is None else warm["x"], qd_lo, qd_hi)
        scale = float(self._scale_fun(x0, params))
        args: dict[str, Any] = {"x0": x0, "p": np.append(params, scale), "lbx": qd_lo,
                                "ubx": qd_hi, "lbg": lbg, "ubg": ubg}
        if warm is not None:  # multipliers of cost / s scale as 1 / s
            args["lam_x0"] = warm["lam_x"] * (warm["scale"] / scale)
            args["lam_g0"] = warm["lam_g"] * (warm["scale"] / scale)
        try:
            sol = self._solver(**args)
            try:
                stats = self._solver.stats()
            except RuntimeError as exc:  # sqpmethod after a failed QP: no return_status
                stats = {"success": False, "return_status": f"no status ({exc})"}
            status, solver_ok = str(stats.get("return_status", "")), bool(stats["success"])
            if not solver_ok and status == "Solve_Succeeded":
                # sqpmethod leaves a stale return_status when it stops on a failed QP
                status = f"failed ({stats.get('unified_return_status', 'unknown')})"
            iterations = int(stats.get("iter_count", -1))
            x = np.asarray(sol["x"]).ravel()
            lam_x = np.asarray(sol["lam_x"]).ravel()
            lam_g = np.asarray(sol["lam_g"]).ravel()
        except RuntimeError as exc:  # evaluation errors (NaN in the model...)
            status, solver_ok, iterations = f"exception: {exc}", False, -1
            x, lam_x, lam_g = args["x0"], np.zeros(n), np.zeros(self._ng)
        solve_time = time.perf_counter() - t0

        x = np.where(np.isfinite(x), x, 0.0)
        q_pred, p_pred, cost = self._traj_fun(x, params)
        g_val = np.asarray(self._g_fun(x, params)).ravel()
        violation = max(
            float(np.max(np.maximum(lbg - g_val, 0.0), initial=0.0)),
            float(np.max(np.maximum(g_val - ubg, 0.0), initial=0.0)),
            float(np.max(np.maximum(qd_lo - x, 0.0))),
            float(np.max(np.maximum(x - qd_hi, 0.0))),
        )
        if not np.isfinite(g_val).all():
            violation = math.inf
        feasible = bool(violation <= cfg.feas_tol and math.isfinite(float(cost)))
        success = solver_ok and feasible
        # sqpmethod and IPOPT both report "Maximum_Iterations_Exceeded"
        iteration_limit = "maximum_iterations" in status.lower()
        if np.isfinite(lam_x).all() and np.isfinite(lam_g).all() and solver_ok:
            self._warm = {"x": x.copy(), "lam_x": lam_x, "lam_g": lam_g,
                          "scale": np.array(scale)}
        return NMPCSolution(
            qdot=x, success=success, status=status, iterations=iterations,
            solve_time_s=solve_time, cost=float(cost), p_pred=np.asarray(p_pred),
            q_pred=np.asarray(q_pred), max_violation=violation, feasible=feasible,
            iteration_limit=iteration_limit,
        )
