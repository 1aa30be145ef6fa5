r"""Small dense QP layer for the CBF-QP controllers (proxsuite, OSQP, DAQP and quadprog
backends).

Problem solved, with :math:`x \in \mathbb{R}^n` and :math:`m` inequality rows:

.. math::

    \min_x \; \tfrac12 x^\top H x + g^\top x
    \quad \text{s.t.} \quad l \le C x \le u, \qquad lb \le x \le ub

Bounds may be :math:`\pm\infty` (a one-sided row has ``l = -inf`` or ``u = +inf``). The
CBF-QP of Thomas & Chaumette (2024), eq. (10), :math:`a_k^\top u \ge b_k`, is the case
``C = [a_k^T]``, ``l = b``, ``u = +inf``.

Backends (:data:`SOLVERS`): ``"proxsuite"`` (ProxQP, the paper's solver: proximal augmented
Lagrangian, the default), ``"osqp"`` (ADMM, polished), ``"daqp"`` (dual active set, exact up
to rounding, warm-started from the previous working set) and ``"quadprog"`` (Goldfarb-Idnani
dual active set, exact up to rounding, always cold; needs ``H`` positive definite; GPL-2.0+,
so an optional dev dependency, imported only when chosen).

Dual sign convention (proxsuite's; OSQP's ``y`` and DAQP's ``lam`` have the same sign;
quadprog's one-sided multipliers ``lambda >= 0`` are recombined into it, see
:class:`_QuadprogBackend`; all four checked in ``tests/test_qp.py`` against closed forms and
against each other). The solution carries ``z`` (one per row of ``C``) and ``z_box``
(one per variable) such that

.. math::

    H x + g + C^\top z + z_{box} = 0,

with :math:`z_i \le 0` where the lower bound :math:`l_i` is active, :math:`z_i \ge 0` where
the upper bound :math:`u_i` is active and :math:`z_i = 0` on inactive rows (same for
``z_box`` with ``lb``/``ub``). The paper writes its rows as :math:`a_k^\top x \ge b_k` with
the Lagrangian :math:`L = \tfrac12 x^\top H x + g^\top x - \sum_k \kappa_k (a_k^\top x - b_k)`,
:math:`\kappa_k \ge 0`; hence :math:`\kappa = \max(-z, 0)`, see :func:`lower_multipliers`.

Statuses: ``"solved"`` (converged *and* the KKT residuals recomputed here are small --
or, for the exact active-set backends DAQP and quadprog, certified by their exit),
``"infeasible"`` (primal or dual infeasibility certified, or ``l > u``, ``l = +inf``,
``u = -inf``), ``"max_iter"``
(iteration budget spent), ``"failed"`` (anything else, including a backend that claims
success with large KKT residuals, and non-finite data). DAQP (exit flag -1) and quadprog
(its "constraints are inconsistent" error) certify the infeasible CBF-QPs of two opposite
sensors in a few active-set iterations, OSQP within ~50 iterations; proxsuite 0.8.0 did not
certify any in our tests and runs to ``max_iter`` outer iterations (about 20-45 ms for
``max_iter=1000`` with n = 7, m = 36, i.e. more than one 30 Hz period: lower ``max_iter``
if that matters).

What counts as an iteration, and the budget ``max_iter`` (per attempt, see
:meth:`QPSolver.solve`); a solve never reports ``"solved"`` with more than ``max_iter``
(and, but for quadprog's ``"max_iter"``, never reports more than ``max_iter``):

- proxsuite: one *outer* (proximal augmented-Lagrangian) iteration, ``info.iter_ext``,
  capped by its ``settings.max_iter``. Each outer iteration runs an inner semi-smooth
  Newton loop, capped by ``settings.max_iter_in`` (``QPSolver(max_iter_in=...)``, default
  ``max_iter``; proxsuite's own default, 1500, let one solve of a nearly degenerate
  CBF-QP take 276,099 Newton steps and 1.9 s). The Newton steps (proxsuite's
  ``info.iter``, at most ``max_iter * (max_iter_in + 1)``) are reported separately as
  ``inner_iterations``: they are the work, each a KKT solve.
- OSQP: one ADMM iteration (``info.iter``; both stages of ``_OsqpBackend``, so at most
  ``max_iter`` in all; the polishing solve is not counted). ``inner_iterations`` equals
  ``iterations``.
- DAQP: one active-set iteration (``info["iterations"]``): one row added to or removed from
  the working set, an update of its LDL' factors; capped by its ``iter_limit``. A
  warm-started solve of a slowly changing sequence takes 1-2 (cold: ~10-25 for n = 7,
  m = 36). ``inner_iterations`` equals ``iterations``.
- quadprog: one main Goldfarb-Idnani iteration (``iter[0]``): pick the most violated row and
  step until it is active (the final check that finds none counts too, so an unconstrained
  QP takes 1). quadprog has no iteration limit: a solve that took more than ``max_iter`` is
  ``"max_iter"``, reported with its true count. ``inner_iterations`` adds the rows dropped on
  the way (``iter[1]``): the factor updates.
:meth:`QPSolver.solve` never raises for these: the controller applies its fallback. When
the status is not ``"solved"``, ``x``, ``z`` and ``z_box`` are the backend's last iterate
with non-finite entries replaced by 0; they must not be applied as a command.

Backends are imported lazily, so importing this module costs only NumPy.
"""

from __future__ import annotations

import math
import time
from typing import Any, Literal, NamedTuple, Protocol, TypeGuard

import numpy as np

from repro.errors import ConfigError, ReproError, UnknownChoiceError

SOLVERS: tuple[str, ...] = ("proxsuite", "osqp", "daqp", "quadprog")
"""Valid values of ``QPSolver(solver=...)``."""

QPStatus = Literal["solved", "infeasible", "max_iter", "failed"]
STATUSES: tuple[str, ...] = ("solved", "infeasible", "max_iter", "failed")

KKT_TOL: float = 1e-5
"""Default relative tolerance above which a backend "success" is downgraded to "failed"."""

OSQP_ADMM_EPS: float = 1e-5
"""Absolute ADMM tolerance of OSQP's first stage, before polishing (see ``_OsqpBackend``)."""


class QPDimensionError(ReproError, ValueError):
    """A QP array has the wrong shape for the solver it is given to."""


class QPProblem(NamedTuple):
    r"""Dense QP :math:`\min \tfrac12 x^\top H x + g^\top x` s.t. ``l <= C x <= u``,
    ``lb <= x <= ub``.

    Attributes:
        H: (n, n) symmetric positive (semi)definite Hessian.
        g: (n,) linear term.
        C: (m, n) inequality rows, or None when m = 0.
        l: (m,) lower bounds of ``C x`` (entries may be ``-inf``); None means all ``-inf``.
        u: (m,) upper bounds of ``C x`` (entries may be ``+inf``); None means all ``+inf``.
        lb: (n,) lower bound on ``x`` (entries may be ``-inf``); None means no bound.
        ub: (n,) upper bound on ``x`` (entries may be ``+inf``); None means no bound.
    """

    H: np.ndarray
    g: np.ndarray
    C: np.ndarray | None = None
    l: np.ndarray | None = None
    u: np.ndarray | None = None
    lb: np.ndarray | None = None
    ub: np.ndarray | None = None


class QPSolution(NamedTuple):
    """Result of :meth:`QPSolver.solve`.

    Attributes:
        x: (n,) primal solution.
        z: (m,) duals of the ``C`` rows (sign convention in the module docstring).
        z_box: (n,) duals of the box bounds.
        status: one of :data:`STATUSES`.
        iterations: iterations of the one backend attempt that produced ``x`` (the cold
            retry when there was one), at most ``max_iter`` (quadprog: also more, then with
            status ``"max_iter"``); proxsuite: outer ALM iterations, OSQP: ADMM iterations,
            DAQP and quadprog: active-set iterations (see the module docstring).
        solve_time_s: wall time of the whole :meth:`QPSolver.solve` call [s], including
            data transfer to the backend, both attempts and the KKT check.
        primal_residual: max bound violation of ``C x`` and ``x``, recomputed here on the
            unscaled problem (infinity norm); NaN for a "solved" of DAQP or quadprog,
            accepted on the active-set method's certificate without recomputing it (see
            :meth:`QPSolver.solve`; :func:`kkt_residuals` computes it).
        dual_residual: infinity norm of ``H x + g + C^T z + z_box``, recomputed here (NaN
            as ``primal_residual``).
        inner_iterations: proxsuite: Newton steps of that attempt (``info.iter``), at most
            ``max_iter * (max_iter_in + 1)``; quadprog: ``iterations`` plus the rows dropped
            from the active set; OSQP, DAQP: equal to ``iterations``.
        total_iterations: ``iterations`` summed over the attempts of this call (warm
            attempt plus cold retry): the work of the call, at most ``2 * max_iter``.
        attempts: backend attempts of this call: 0 (data rejected before the backend),
            1, or 2 (a warm attempt that was not accepted, then a cold retry).
    """

    x: np.ndarray
    z: np.ndarray
    z_box: np.ndarray
    status: QPStatus
    iterations: int
    solve_time_s: float
    primal_residual: float
    dual_residual: float
    inner_iterations: int
    total_iterations: int
    attempts: int


class _Dense(NamedTuple):
    """A QPProblem with every optional part filled in (infinite bounds kept as inf).

    ``bounds`` stacks the bounds of ``v = [x; C x]`` as ``[lb; l; ub; u]`` (so ``bounds[:k]``
    are the lower and ``bounds[k:]`` the upper bounds of ``v``, ``k = n + m``: DAQP's order,
    which it is given as views); it serves the checks of :meth:`QPSolver.solve` and the KKT
    check (:func:`_kkt_full`).
    """

    H: np.ndarray
    g: np.ndarray
    C: np.ndarray
    l: np.ndarray
    u: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    bounds: np.ndarray


class _RawResult(NamedTuple):
    """What a backend returns before the status is checked against the KKT conditions."""

    x: np.ndarray
    z: np.ndarray
    z_box: np.ndarray
    status: QPStatus
    iterations: int  # proxsuite: outer; OSQP: ADMM; DAQP, quadprog: active-set iterations
    inner_iterations: int  # proxsuite: Newton steps; quadprog: + dropped rows; else = iterations


_F64 = np.dtype(float)


def _is_f64(a: Any, shape: tuple[int, ...]) -> TypeGuard[np.ndarray]:
    """``a`` is already a float64 ndarray of ``shape`` (nothing to convert or reshape)."""
    return type(a) is np.ndarray and a.dtype == _F64 and a.shape == shape


_Arrays7 = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                 np.ndarray]


def _plain(problem: QPProblem, n: int, m: int) -> _Arrays7 | None:
    """``problem``'s arrays when every one is already a float64 ndarray of its (n, m) shape
    (none None: :func:`_as_dense` would have nothing to convert, fill or reshape), else
    None."""
    H, g, C, l, u, lb, ub = problem
    f = _is_f64
    if (f(H, (n, n)) and f(g, (n,)) and f(C, (m, n)) and f(l, (m,)) and f(u, (m,))
            and f(lb, (n,)) and f(ub, (n,))):
        return H, g, C, l, u, lb, ub
    return None


def _vec(v: np.ndarray | None, size: int, fill: float, name: str) -> np.ndarray:
    if v is None:
        return np.full(size, fill)
    out = np.asarray(v, dtype=float).reshape(-1)
    if out.shape != (size,):
        raise QPDimensionError(f"{name} has shape {out.shape}, expected ({size},)")
    return out


def _as_dense(problem: QPProblem, n: int | None = None, m: int | None = None) -> _Dense:
    """Fill the optional parts of ``problem`` and check every shape.

    Raises:
        QPDimensionError: when a shape disagrees with ``n`` / ``m`` (inferred from ``H``
            and ``C`` when not given).
    """
    H = problem.H  # (np.asarray(., dtype=float) only where it would make a new array)
    if type(H) is not np.ndarray or H.dtype != _F64:
        H = np.asarray(H, dtype=float)
    if H.ndim == 2 and H.shape[0] == H.shape[1]:
        H = H + H.T  # OSQP reads only the upper triangle, proxsuite all of H
        H *= 0.5
    g = problem.g
    if type(g) is not np.ndarray or g.dtype != _F64 or g.ndim != 1:
        g = np.asarray(g, dtype=float).reshape(-1)
    if n is None:
        n = H.shape[0] if H.ndim == 2 else -1
    if H.shape != (n, n):
        raise QPDimensionError(f"H has shape {H.shape}, expected ({n}, {n})")
    if g.shape != (n,):
        raise QPDimensionError(f"g has shape {g.shape}, expected ({n},)")
    if problem.C is None:
        C = np.zeros((0, n))
    else:
        C = problem.C
        if type(C) is not np.ndarray or C.dtype != _F64:
            C = np.asarray(C, dtype=float)
        if C.ndim == 1 and C.size == n:
            C = C.reshape(1, n)
    if m is None:
        m = C.shape[0]
    if C.shape != (m, n):
        raise QPDimensionError(f"C has shape {C.shape}, expected ({m}, {n})")
    l, u, lb, ub = problem.l, problem.u, problem.lb, problem.ub  # float (size,): as they are
    if not _is_f64(l, (m,)):
        l = _vec(l, m, -np.inf, "l")
    if not _is_f64(u, (m,)):
        u = _vec(u, m, np.inf, "u")
    if not _is_f64(lb, (n,)):
        lb = _vec(lb, n, -np.inf, "lb")
    if not _is_f64(ub, (n,)):
        ub = _vec(ub, n, np.inf, "ub")
    return _Dense(H, g, C, l, u, lb, ub, np.concatenate((lb, l, ub, u)))


class _KKT(NamedTuple):
    """KKT residuals (see :func:`kkt_residuals`) and the scales of :meth:`QPSolver._kkt_ok`."""

    stationarity: float
    primal_infeasibility: float
    complementarity: float
    dual_sign: float
    s_d: float  # 1 + max(|H x|, |g|, |C^T z|, |z_box|)
    s_p: float  # 1 + max(|C x|, |x|)

    def as_dict(self) -> dict[str, float]:
        return {"stationarity": self.stationarity,
                "primal_infeasibility": self.primal_infeasibility,
                "complementarity": self.complementarity, "dual_sign": self.dual_sign}


class _KKTWork:
    """The buffers of :func:`_kkt_full` for one problem size (n variables, m rows), made once
    per :class:`QPSolver`: the same arithmetic as fresh arrays, without allocating or slicing
    them on every solve. Each row of ``W`` is written on the same slice every call, so its
    zero padding stays zero."""

    def __init__(self, n: int, m: int) -> None:
        k = m + n
        self.n, self.m = n, m
        self.W = W = np.zeros((6, max(2 * k, 4 * n)))
        self.stat = W[0, :n]  # |H x + g + C^T z + z_box|
        self.E = W[1, :2 * k]  # [lo - v; v - hi]
        self.E_lo = self.E[:k]
        self.compl = W[2, :2 * k]  # Y |E| (|E| = 0 on infinite bounds)
        self.dual_sign = W[3, :2 * k]  # Y [bound infinite]
        self.S = W[4, :4 * n]  # |[H x; g; C^T z; z_box]|
        self.v_abs = W[5, :k]  # |v|
        self.vv = np.empty(2 * k)  # [v; v], v = [x; C x]
        self.v = self.vv[:k]
        self.Y = np.empty(2 * k)  # [max(-y, 0); max(y, 0)], y = [z_box; z]
        self.Y_lo = self.Y[:k]
        self.A = np.empty(2 * k)  # |E|


def _kkt_full(d: _Dense, x: np.ndarray, z: np.ndarray, z_box: np.ndarray,
              work: _KKTWork | None = None) -> _KKT:
    """KKT residuals of ``(x, z, z_box)`` and their scales, rows and box stacked.

    With ``v = [x; C x]``, ``y = [z_box; z]`` and the stacked bounds ``lo <= v <= hi``
    (``d.bounds = [lo; hi]``), the lower and upper sides are handled together on doubled
    vectors: ``E = [lo - v; v - hi]`` (bound violations; primal infeasibility
    ``max(0, max E)``), ``Y = [max(-y, 0); max(y, 0)]`` (multipliers of the lower / upper
    bounds), complementarity ``max(Y |E|)`` with ``|E|`` taken as 0 on infinite bounds, dual
    sign ``max(Y [bound infinite])`` (a multiplier on an infinite bound). The six infinity
    norms are the row maxima of one zero-padded (6, .) array (all entries but ``E``'s are
    >= 0, and ``E`` is clamped at 0 anyway), i.e. a single NumPy reduction. ``work``: the
    buffers to use (a :class:`QPSolver`'s own; None or another size: fresh ones).
    """
    C = d.C
    Cx = C.dot(x)  # (ndarray.dot: BLAS as @, without the matmul ufunc's overhead)
    Hx = d.H.dot(x)
    CTz = C.T.dot(z)
    n, m = x.shape[0], Cx.shape[0]
    if work is None or work.n != n or work.m != m:
        work = _KKTWork(n, m)
    stat = Hx + d.g  # H x + g + C^T z + z_box, summed in this order
    stat += CTz
    stat += z_box
    np.abs(stat, out=work.stat)
    vv, E, Y, A = work.vv, work.E, work.Y, work.A
    np.concatenate((x, Cx, x, Cx), out=vv)
    np.subtract(vv, d.bounds, out=E)  # [v - lo; v - hi]
    np.negative(work.E_lo, out=work.E_lo)  # [lo - v; v - hi]
    np.concatenate((z_box, z, z_box, z), out=Y)
    np.negative(work.Y_lo, out=work.Y_lo)
    np.maximum(Y, 0.0, out=Y)
    np.abs(E, out=A)
    inf = ~np.isfinite(d.bounds)
    A[inf] = 0.0  # infinite bounds never bind
    np.multiply(Y, inf, out=work.dual_sign)  # (0 on finite bounds; NaN for a NaN multiplier)
    np.multiply(A, Y, out=work.compl)
    S = work.S
    np.concatenate((Hx, d.g, CTz, z_box), out=S)
    np.abs(S, out=S)
    np.abs(work.v, out=work.v_abs)
    stat_max, violation, compl, dual_sign, s_d, s_p = work.W.max(axis=1).tolist()
    return _KKT(
        stationarity=stat_max,
        primal_infeasibility=max(violation, 0.0) + 0.0,
        complementarity=compl,
        dual_sign=dual_sign,
        s_d=1.0 + s_d,
        s_p=1.0 + s_p,
    )


#: The residuals of a "solved" accepted on an active-set backend's certificate: not
#: recomputed (NaN; :func:`kkt_residuals` computes them on demand).
_CERTIFIED = _KKT(*(math.nan,) * 6)


def _kkt(d: _Dense, x: np.ndarray, z: np.ndarray, z_box: np.ndarray) -> dict[str, float]:
    """KKT residuals of ``(x, z, z_box)``, rows and box stacked (see :func:`kkt_residuals`)."""
    return _kkt_full(d, x, z, z_box).as_dict()


def kkt_residuals(problem: QPProblem, sol: QPSolution) -> dict[str, float]:
    r"""KKT residuals of ``sol`` for ``problem`` (infinity norms, unscaled).

    .. math::

        \text{stationarity} &= \| H x + g + C^\top z + z_{box} \|_\infty \\
        \text{primal\_infeasibility} &= \max\big(0,\ l - Cx,\ Cx - u,\ lb - x,\ x - ub\big) \\
        \text{complementarity} &= \max_i \big( z_i^- \,|C_i x - l_i|,\ z_i^+ \,|u_i - C_i x| \big)
            \ \text{(and the same for the box)} \\
        \text{dual\_sign} &= \max_i \big( z_i^+ [u_i = +\infty],\ z_i^- [l_i = -\infty] \big)

    with :math:`z^\pm = \max(\pm z, 0)`. Each is >= 0 and ~0 at an exact optimum.

    Returns:
        dict with keys ``"stationarity"``, ``"primal_infeasibility"``, ``"complementarity"``,
        ``"dual_sign"``.
    """
    d = _as_dense(problem)
    x = np.asarray(sol.x, dtype=float)
    z = np.asarray(sol.z, dtype=float).reshape(-1)
    z_box = np.asarray(sol.z_box, dtype=float).reshape(-1)
    if z.shape != (d.C.shape[0],) or z_box.shape != x.shape:
        raise QPDimensionError(
            f"solution duals have shapes z {z.shape}, z_box {z_box.shape}; expected "
            f"({d.C.shape[0]},) and {x.shape}"
        )
    return _kkt(d, x, z, z_box)


def lower_multipliers(sol: QPSolution) -> np.ndarray:
    r"""Multipliers :math:`\kappa \ge 0` of the rows written as :math:`C x \ge l`.

    This is the paper's convention, with Lagrangian
    :math:`L = \tfrac12 x^\top H x + g^\top x - \sum_k \kappa_k (a_k^\top x - b_k)`, so

    .. math::

        \kappa = \max(-z, 0).

    Returns:
        (m,) array, 0 on rows whose lower bound is inactive.
    """
    return np.maximum(-np.asarray(sol.z, dtype=float), 0.0)


def _finite_or_zero(v: Any, size: int) -> np.ndarray:
    """Copy of ``v`` as a float (size,) array with non-finite entries (or a missing ``v``)
    replaced by 0."""
    if v is None:
        return np.zeros(size)
    out = np.array(v, dtype=float).reshape(-1)
    if out.shape != (size,):
        return np.zeros(size)
    finite = np.isfinite(out)
    if not finite.all():
        out[~finite] = 0.0
    return out


def all_finite(*arrays: np.ndarray) -> bool:
    """Every entry of ``arrays`` is finite: ``np.isfinite(a).all()`` for each, in one pass
    over their entries, counted with ``np.count_nonzero`` (about half the time on the
    CBF-QP's small arrays)."""
    flat = np.concatenate([a.ravel() for a in arrays]) if len(arrays) > 1 else arrays[0]
    return bool(np.count_nonzero(np.isfinite(flat)) == flat.size)


#: The largest double: the bounds test of :meth:`QPSolver.solve` clips infinities to it.
_BIG = float(np.finfo(float).max)


def _bounds_consistent(lo: np.ndarray, hi: np.ndarray) -> bool:
    """``lo <= hi`` everywhere, with no ``lo = +inf``, no ``hi = -inf`` and no NaN.

    With the infinities clipped to the largest double, ``max(lo, -BIG) <= min(hi, BIG)``
    fails exactly there: ``lo = +inf`` stays above any clipped ``hi``, ``hi = -inf`` below
    any clipped ``lo``, a NaN compares false, and finite bounds compare as they are.
    """
    return bool(np.count_nonzero(np.maximum(lo, -_BIG) <= np.minimum(hi, _BIG)) == lo.size)


class _ProxsuiteBackend:
    """proxsuite dense ``QP`` class, warm-started from the previous result.

    ``init`` on the first call (and after :meth:`reset`), ``update`` + ``solve`` after. The
    initial-guess setting is written before ``init`` (writing it between ``init`` and the
    first ``solve`` segfaults proxsuite 0.8.0). ``results.z`` has length m + n with
    ``box_constraints=True``: the first m entries are the row duals, the last n the box duals.

    proxsuite 0.8.0 (``dense/solver.hpp``) runs at most ``settings.max_iter`` outer
    iterations, counted in ``info.iter_ext`` (reset by every ``solve``); each runs at most
    ``settings.max_iter_in`` Newton steps and adds them (``max_iter_in + 1`` when it hits
    that cap) to ``info.iter``. The status stays ``PROXQP_MAX_ITER_REACHED`` when the outer
    loop runs out, so ``info.iter_ext <= max_iter`` always and ``== max_iter`` then.
    """

    certifies_kkt = False
    """An approximate (augmented-Lagrangian) solve: every KKT condition is checked, including
    the multipliers' signs (a warm-started proxsuite 0.8.0 "solved" once had a wrong-sign one)."""

    def __init__(self, n: int, m: int, eps_abs: float, max_iter: int, warm_start: bool,
                 max_iter_in: int) -> None:
        import proxsuite  # lazy: heavy import

        self._proxqp = proxsuite.proxqp
        self.n, self.m = n, m
        self.eps_abs, self.max_iter, self.warm_start = eps_abs, max_iter, warm_start
        self.max_iter_in = max_iter_in
        self._qp: Any = None

    @property
    def is_warm(self) -> bool:
        return self.warm_start and self._qp is not None

    def reset(self) -> None:
        self._qp = None

    def _new_qp(self) -> Any:
        pq = self._proxqp
        qp = pq.dense.QP(self.n, 0, self.m, True)
        qp.settings.initial_guess = (
            pq.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            if self.warm_start
            else pq.InitialGuess.NO_INITIAL_GUESS
        )
        qp.settings.eps_abs = self.eps_abs
        qp.settings.eps_rel = 0.0
        qp.settings.max_iter = self.max_iter  # outer iterations (info.iter_ext)
        qp.settings.max_iter_in = self.max_iter_in  # Newton steps per outer iteration
        qp.settings.verbose = False
        # Without the duality-gap check a cold "solved" can keep a complementarity
        # residual of ~4e-6 (u off by ~2e-6); with it, errors stay under 1e-8.
        qp.settings.check_duality_gap = True
        qp.settings.eps_duality_gap_abs = self.eps_abs
        qp.settings.eps_duality_gap_rel = 0.0
        return qp

    def solve(self, d: _Dense) -> _RawResult:
        pq = self._proxqp
        # proxsuite accepts +-inf bounds directly (checked in the tests).
        if self._qp is None or not self.warm_start:
            self._qp = self._new_qp()
            self._qp.init(d.H, d.g, None, None, d.C, d.l, d.u, d.lb, d.ub)
        else:
            self._qp.update(d.H, d.g, None, None, d.C, d.l, d.u, d.lb, d.ub)
        self._qp.solve()
        res = self._qp.results
        info = res.info
        st = info.status
        if st == pq.PROXQP_SOLVED:
            status: QPStatus = "solved"
        elif st in (pq.PROXQP_PRIMAL_INFEASIBLE, pq.PROXQP_DUAL_INFEASIBLE):
            status = "infeasible"
        elif st == pq.PROXQP_MAX_ITER_REACHED:
            status = "max_iter"
        else:  # PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE, PROXQP_NOT_RUN
            status = "failed"
        # res.x and res.z are views of proxsuite's buffers: copy them.
        x = np.array(res.x, dtype=float)
        z_all = np.array(res.z, dtype=float)
        m = self.m
        outer, inner = int(info.iter_ext), int(info.iter)
        if (x.shape == (self.n,) and z_all.shape == (m + self.n,)
                and np.isfinite(x).all() and np.isfinite(z_all).all()):
            return _RawResult(x, z_all[:m], z_all[m:], status, outer, inner)
        z_all = z_all.reshape(-1)
        return _RawResult(
            x=_finite_or_zero(x, self.n),
            z=_finite_or_zero(z_all[:m], m),
            z_box=_finite_or_zero(z_all[m:], self.n),
            status=status,
            iterations=outer,
            inner_iterations=inner,
        )


class _OsqpBackend:
    """OSQP 1.x with the box stacked as identity rows under ``C``.

    The constraint matrix ``A = [C; I]`` and the upper triangle of ``P = H`` are stored as
    CSC matrices with a fixed pattern (dense ``C``, diagonal ``I``, dense upper ``H``), so
    later problems only change values (``update(Px=..., Ax=...)``) and the warm start
    survives. ``y`` has proxsuite's sign convention, ``y = [z; z_box]``.

    Two stages, because OSQP's ADMM (with its duality-gap check) needs thousands of
    iterations to reach 1e-9 on these problems while its polishing step (an active-set
    solve of the reduced KKT system) is exact once ADMM has found the active set: ADMM runs
    to ``max(eps_abs, OSQP_ADMM_EPS)`` and is polished; only if polishing fails does ADMM
    continue to ``eps_abs`` within the remaining iteration budget, so the ADMM iterations of
    both stages add up to at most ``max_iter``.
    """

    certifies_kkt = False
    """ADMM is approximate: every KKT condition is checked."""

    def __init__(self, n: int, m: int, eps_abs: float, max_iter: int, warm_start: bool,
                 max_iter_in: int) -> None:
        del max_iter_in  # ADMM has no inner loop
        import osqp  # lazy: heavy import

        self._osqp = osqp
        self.n, self.m = n, m
        self.eps_abs, self.max_iter, self.warm_start = eps_abs, max_iter, warm_start
        self.eps_admm = max(eps_abs, OSQP_ADMM_EPS)
        self._solver: Any = None
        # Upper triangle of H, column-major: column j holds rows 0..j.
        self._p_cols = np.repeat(np.arange(n), np.arange(1, n + 1))
        self._p_rows = np.concatenate([np.arange(j + 1) for j in range(n)]).astype(np.int64)
        self._p_indptr = np.concatenate([[0], np.cumsum(np.arange(1, n + 1))]).astype(np.int64)
        # A = [C; I]: column j holds rows 0..m-1 (dense C) and row m + j (identity).
        self._a_indices = np.concatenate(
            [np.concatenate([np.arange(m), [m + j]]) for j in range(n)]
        ).astype(np.int64)
        self._a_indptr = (np.arange(n + 1) * (m + 1)).astype(np.int64)

    @property
    def is_warm(self) -> bool:
        return self.warm_start and self._solver is not None

    def reset(self) -> None:
        self._solver = None

    def _px(self, H: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(H[self._p_rows, self._p_cols])

    def _ax(self, C: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.vstack([C, np.ones((1, self.n))]).T.reshape(-1))

    def solve(self, d: _Dense) -> _RawResult:
        import scipy.sparse as sp

        osqp = self._osqp
        lo = np.concatenate([d.l, d.lb])  # OSQP clips +-inf to its OSQP_INFTY itself
        hi = np.concatenate([d.u, d.ub])
        px, ax = self._px(d.H), self._ax(d.C)
        if self._solver is None or not self.warm_start:
            n, m = self.n, self.m
            P = sp.csc_matrix((px, self._p_rows, self._p_indptr), shape=(n, n))
            A = sp.csc_matrix((ax, self._a_indices, self._a_indptr), shape=(m + n, n))
            self._solver = osqp.OSQP()
            self._solver.setup(
                P,
                d.g.copy(),
                A,
                lo,
                hi,
                eps_abs=self.eps_admm,
                eps_rel=self.eps_admm,
                max_iter=self.max_iter,
                polishing=True,
                verbose=False,
                warm_starting=True,  # warm_start=False is a fresh setup per solve
            )
        else:
            self._solver.update(q=d.g.copy(), l=lo, u=hi, Px=px, Ax=ax)
        S = osqp.SolverStatus
        res = self._solver.solve(raise_error=False)
        iterations = int(res.info.iter)
        if (
            res.info.status_val == S.OSQP_SOLVED
            and res.info.status_polish != 1
            and self.eps_abs < self.eps_admm
            and iterations < self.max_iter
        ):
            # Polishing failed: continue ADMM from its last iterate to the full tolerance.
            self._solver.update_settings(
                eps_abs=self.eps_abs, eps_rel=0.0, max_iter=self.max_iter - iterations
            )
            res = self._solver.solve(raise_error=False)
            iterations += int(res.info.iter)
            self._solver.update_settings(
                eps_abs=self.eps_admm, eps_rel=self.eps_admm, max_iter=self.max_iter
            )
        sv = res.info.status_val
        if sv == S.OSQP_SOLVED:
            status: QPStatus = "solved"
        elif sv in (
            S.OSQP_PRIMAL_INFEASIBLE,
            S.OSQP_PRIMAL_INFEASIBLE_INACCURATE,
            S.OSQP_DUAL_INFEASIBLE,
            S.OSQP_DUAL_INFEASIBLE_INACCURATE,
        ):
            status = "infeasible"
        elif sv in (
            S.OSQP_MAX_ITER_REACHED,
            S.OSQP_TIME_LIMIT_REACHED,
            S.OSQP_SOLVED_INACCURATE,  # returned instead of MAX_ITER when close to eps
        ):
            status = "max_iter"
        else:  # NON_CVX, SIGINT, UNSOLVED
            status = "failed"
        y = None if res.y is None else np.asarray(res.y, dtype=float).reshape(-1)
        return _RawResult(
            x=_finite_or_zero(res.x, self.n),
            z=_finite_or_zero(None if y is None else y[: self.m], self.m),
            z_box=_finite_or_zero(None if y is None else y[self.m :], self.n),
            status=status,
            iterations=iterations,
            inner_iterations=iterations,
        )


#: DAQP exit flags (``include/constants.h`` of DAQP 0.11) and what they mean here.
_DAQP_STATUS: dict[int, QPStatus] = {
    1: "solved",  # EXIT_OPTIMAL
    -1: "infeasible",  # EXIT_INFEASIBLE: primal infeasibility certified
    -3: "infeasible",  # EXIT_UNBOUNDED: dual infeasible (only with a singular H)
    -4: "max_iter",  # EXIT_ITERLIMIT
    -7: "max_iter",  # EXIT_TIMELIMIT (no time limit is set)
}  # 2 SOFT_OPTIMAL (no soft rows here), -2 CYCLE, -5 NONCONVEX, -6 OVERDETERMINED: "failed"

#: DAQP's ``sense`` value for an equality row: active and immutable (1 | 4).
_DAQP_EQUALITY = 5


class _DaqpBackend:
    r"""DAQP 0.11 (Arnström, Bemporad & Axehill 2022: a dual active-set method) through its
    reusable ``daqp.Model`` workspace.

    DAQP solves :math:`\min \tfrac12 x^\top H x + f^\top x` s.t.
    :math:`b_{lower} \le [I; A] x \le b_{upper}`, the first n bounds being simple bounds on
    ``x``; it is given ``A = C``, ``b_upper = [ub; u]``, ``b_lower = [lb; l]`` (``+-inf``
    passed as such, checked in the tests). Its multipliers ``lam = [lam_box;
    lam_rows]`` satisfy :math:`H x + f + [I; A]^\top \lambda = 0` with :math:`\lambda \le 0`
    at an active lower and :math:`\ge 0` at an active upper bound, i.e. this module's
    convention: ``z_box = lam[:n]``, ``z = lam[n:]``, no sign change (checked in
    ``tests/test_qp.py`` against the closed forms and against proxsuite).

    Equality rows (``l == u``, and ``lb == ub``) get DAQP's ``sense`` 5 (active, immutable:
    a free-sign multiplier). Warm start: the workspace keeps the working set of the previous
    solve and ``update`` changes the data only, so a slowly changing sequence is re-solved in
    one or two iterations; a change of which rows are equalities is a new setup (cold).
    ``eps_abs`` is DAQP's ``primal_tol`` (a row counts as violated beyond it), ``max_iter``
    its ``iter_limit``. A singular ``H`` is regularised by DAQP's proximal-point iterations
    (its default ``eps_prox < 0``: automatic).
    """

    certifies_kkt = True
    """DAQP's exit "optimal" certifies the KKT conditions that :meth:`QPSolver.solve` would
    recompute: it is the exact optimum (to rounding) of the final working set -- x solves that
    set's equality-constrained KKT system (stationarity), every multiplier off the set is
    exactly 0 and every row on it holds with equality (complementarity) -- a dual active-set
    method keeps each multiplier on the side of its active bound (dual sign, to DAQP's
    ``dual_tol``), and it stops only when no row is violated by more than ``primal_tol`` =
    ``eps_abs`` (1e-9, absolute: tighter than the check's 1e-5 relative). So a DAQP "solved"
    with finite x and multipliers is accepted as it is. The mapping of the data and of the
    multipliers onto DAQP's is checked in ``tests/test_qp.py`` against closed forms, an exact
    KKT solve and proxsuite; ``bench.py``'s QP table compares every CBF-QP of the cases with
    a cold DAQP solve."""

    def __init__(self, n: int, m: int, eps_abs: float, max_iter: int, warm_start: bool,
                 max_iter_in: int) -> None:
        del max_iter_in  # one loop: each iteration adds or removes one row of the working set
        import daqp  # lazy

        self._daqp = daqp
        self.n, self.m = n, m
        self.eps_abs, self.max_iter, self.warm_start = eps_abs, max_iter, warm_start
        self._model: Any = None
        self._eq: bytes | None = None  # equality mask [box; rows] of the current setup

    @property
    def is_warm(self) -> bool:
        return self.warm_start and self._model is not None

    def reset(self) -> None:
        self._model = None
        self._eq = None

    def solve(self, d: _Dense) -> _RawResult:
        n, m = self.n, self.m
        # The Model keeps pointers to what it is given: only arrays of this call (d.H is
        # already one, d.g and d.C may be the caller's).
        k = n + m
        blower, bupper = d.bounds[:k], d.bounds[k:]  # [lb; l], [ub; u]
        f, A = d.g.copy(), d.C.copy()  # (float64 already; a copy is in C order)
        # QPSolver.solve has refused NaN bounds, l = +inf and u = -inf: equal bounds are finite
        eq = blower == bupper
        eq_key = eq.tobytes()
        if self._model is None or not self.warm_start or eq_key != self._eq:
            model = self._daqp.Model()
            sense = np.where(eq, _DAQP_EQUALITY, 0).astype(np.intc)
            flag, _ = model.setup(d.H, f, A, bupper, blower, sense)
            if flag < 0:  # setup rejected the data (e.g. a non-convex H)
                self.reset()
                return _RawResult(np.zeros(n), np.zeros(m), np.zeros(n), "failed", 0, 0)
            model.settings = {"primal_tol": self.eps_abs, "iter_limit": self.max_iter}
            self._model, self._eq = model, eq_key
        elif self._model.update(H=d.H, f=f, A=A if m else None, bupper=bupper,
                                blower=blower) < 0:  # (daqp 0.11: an empty A fails update)
            self.reset()
            return _RawResult(np.zeros(n), np.zeros(m), np.zeros(n), "failed", 0, 0)
        x, _, exitflag, info = self._model.solve()
        status = _DAQP_STATUS.get(int(exitflag), "failed")
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


class _QuadprogBackend:
    r"""quadprog 0.1 (Goldfarb & Idnani 1983, Turlach's QuadProg): a dual active-set method,
    exact up to rounding, with no tolerance, no iteration limit and no warm start.

    quadprog solves :math:`\min \tfrac12 x^\top G x - a^\top x` s.t.
    :math:`C_q^\top x \ge b_q`, the first ``meq`` columns as equalities, and returns
    multipliers :math:`\lambda` with :math:`G x - a = C_q \lambda`, :math:`\lambda \ge 0` on
    the inequalities (free sign on the equalities). It is given ``G = H``, ``a = -g`` and
    one-sided columns, infinite bounds dropped: equality rows ``c_i^T x = l_i`` (``l == u``,
    and ``lb == ub``) first, then ``c_i^T x >= l_i`` for each finite lower and
    ``-c_i^T x >= -u_i`` for each finite upper bound (the same with unit vectors for the box).
    Stationarity :math:`H x + g - C_q \lambda = 0` then gives this module's duals:

    .. math::

        z_i = \lambda^{upper}_i - \lambda^{lower}_i, \qquad z_i = -\lambda^{eq}_i,

    (and ``z_box`` alike), so ``z <= 0`` at an active lower bound and ``z >= 0`` at an active
    upper bound (checked in ``tests/test_qp.py``).

    ``H`` must be positive definite (quadprog starts from a Cholesky factor): otherwise
    quadprog raises ``ValueError("matrix G is not positive definite")``, reported as
    ``"failed"`` (the CBF-QPs have ``H = J^T J + mu I``, ``mu > 0``). Its ``ValueError(
    "constraints are inconsistent, no solution")`` certifies infeasibility: ``"infeasible"``;
    either error carries no iterate: ``x = 0``, iterations 0. ``eps_abs`` is not used.
    quadprog cannot be stopped: ``max_iter`` is applied to its count afterwards (a solve that
    needed more main iterations is ``"max_iter"``, with its true count). ``warm_start`` is
    ignored (every solve is cold, :attr:`is_warm` is always False).
    """

    certifies_kkt = True
    """As DAQP's (:attr:`_DaqpBackend.certifies_kkt`): Goldfarb-Idnani returns the exact
    optimum of its final active set when no row is violated, multipliers >= 0 on it (dual
    feasible throughout) and 0 off it; the recombination above puts them on the side of
    their bound."""

    def __init__(self, n: int, m: int, eps_abs: float, max_iter: int, warm_start: bool,
                 max_iter_in: int) -> None:
        del eps_abs, warm_start, max_iter_in  # see the class docstring
        import quadprog  # lazy

        self._solve_qp = quadprog.solve_qp
        self.n, self.m, self.max_iter = n, m, max_iter
        self._eye = np.eye(n)

    @property
    def is_warm(self) -> bool:
        return False

    def reset(self) -> None:
        pass  # no state between solves

    def solve(self, d: _Dense) -> _RawResult:
        n, m = self.n, self.m
        lo = np.concatenate([d.l, d.lb])  # bounds of v = [C; I] x; QPSolver.solve has
        hi = np.concatenate([d.u, d.ub])  # rejected lo > hi, lo = +inf and hi = -inf
        V = np.vstack([d.C, self._eye])  # (m + n, n)
        eq = np.isfinite(lo) & (lo == hi)
        low = np.isfinite(lo) & ~eq
        up = np.isfinite(hi) & ~eq
        Cq = np.vstack([V[eq], V[low], -V[up]]).T  # columns: equalities first
        bq = np.concatenate([lo[eq], lo[low], -hi[up]])
        k_eq, k_low = int(eq.sum()), int(low.sum())
        try:
            if bq.size:
                x, _, _, iters, lam, _ = self._solve_qp(d.H, -d.g, Cq, bq, k_eq)
            else:  # quadprog cannot take an empty C
                x, _, _, iters, lam, _ = self._solve_qp(d.H, -d.g)
                lam = np.zeros(0)
        except ValueError as err:
            status: QPStatus = "infeasible" if "inconsistent" in str(err) else "failed"
            return _RawResult(np.zeros(n), np.zeros(m), np.zeros(n), status, 0, 0)
        lam = np.asarray(lam, dtype=float)
        y = np.zeros(m + n)  # [z; z_box]
        y[eq] = -lam[:k_eq]
        y[low] -= lam[k_eq:k_eq + k_low]
        y[up] += lam[k_eq + k_low:]
        main, dropped = int(iters[0]), int(iters[1])
        status = "solved" if main <= self.max_iter else "max_iter"
        x = np.asarray(x, dtype=float)
        if status == "solved" and x.shape == (n,):
            # as they are: QPSolver._attempt checks that they are finite before it accepts
            # them (certifies_kkt)
            return _RawResult(x, y[:m], y[m:], status, main, main + dropped)
        return _RawResult(
            x=_finite_or_zero(x, n),
            z=_finite_or_zero(y[:m], m),
            z_box=_finite_or_zero(y[m:], n),
            status=status,
            iterations=main,
            inner_iterations=main + dropped,
        )


class _Backend(Protocol):
    """What :class:`QPSolver` needs of a backend."""

    certifies_kkt: bool
    """A "solved" of this backend is the exact optimum of an active-set method (its exit
    certifies the KKT conditions): :meth:`QPSolver.solve` does not recompute them."""

    def __init__(self, n: int, m: int, eps_abs: float, max_iter: int, warm_start: bool,
                 max_iter_in: int) -> None: ...

    @property
    def is_warm(self) -> bool:
        """The next :meth:`solve` starts from the previous one's state."""
        ...

    def reset(self) -> None:
        """Forget the warm start."""
        ...

    def solve(self, d: _Dense) -> _RawResult:
        """One attempt on ``d``; never raises for infeasible or unsolvable data."""
        ...


_BACKENDS: dict[str, type[_Backend]] = {
    "proxsuite": _ProxsuiteBackend,
    "osqp": _OsqpBackend,
    "daqp": _DaqpBackend,
    "quadprog": _QuadprogBackend,
}


class QPSolver:
    """Solve a stream of QPs of fixed size (n variables, m rows), warm-started in sequence.

    Args:
        n: number of variables (7 joint velocities [rad/s] for the Panda).
        m: number of rows of ``C`` (36 proximity-sensor rows in thomas2024); may be 0.
        solver: one of :data:`SOLVERS`.
        eps_abs: absolute tolerance handed to the backend (``eps_rel`` is 0).
        max_iter: iteration budget per attempt (proxsuite: outer ALM iterations; OSQP: ADMM
            iterations; DAQP, quadprog: active-set iterations, see the module docstring);
            bounds the time spent on an infeasible problem (not for quadprog, which cannot
            be stopped: its count is checked afterwards). An attempt that runs out is
            ``"max_iter"``, never ``"solved"``.
        max_iter_in: proxsuite only: Newton steps per outer iteration; None = ``max_iter``.
            Together they bound the work of one attempt to ``max_iter * (max_iter_in + 1)``
            Newton steps.
        warm_start: start each solve from the previous solution (DAQP: from its working
            set; ignored by quadprog, always cold). The warm start is forgotten by
            :meth:`reset` and after any solve whose status is not ``"solved"``.
        kkt_tol: relative tolerance of the check applied to every backend "success"; see
            :meth:`solve`.

    Raises:
        UnknownChoiceError: ``solver`` is not in :data:`SOLVERS`.
        ConfigError: ``max_iter`` or ``max_iter_in`` is < 1.
    """

    def __init__(
        self,
        n: int,
        m: int,
        solver: str = "proxsuite",
        eps_abs: float = 1e-9,
        max_iter: int = 1000,
        warm_start: bool = True,
        kkt_tol: float = KKT_TOL,
        max_iter_in: int | None = None,
    ) -> None:
        if solver not in _BACKENDS:
            raise UnknownChoiceError("QP solver", solver, SOLVERS)
        if n < 1 or m < 0:
            raise QPDimensionError(f"need n >= 1 and m >= 0, got n={n}, m={m}")
        if max_iter_in is None:
            max_iter_in = max_iter
        for name, value in (("max_iter", max_iter), ("max_iter_in", max_iter_in)):
            if int(value) != value or value < 1:
                raise ConfigError(f"QP solver {name} must be an integer >= 1, got {value!r}")
        self.n, self.m, self.solver = int(n), int(m), solver
        self.max_iter, self.max_iter_in = int(max_iter), int(max_iter_in)
        self.kkt_tol = float(kkt_tol)
        self.cold_retries = 0
        """How many warm solves failed the KKT check and were repeated cold (for logging)."""
        self._backend = _BACKENDS[solver](self.n, self.m, eps_abs, self.max_iter, warm_start,
                                          self.max_iter_in)
        self._kkt_work = _KKTWork(self.n, self.m)
        from repro.control import kernels  # lazy: numba

        self._plain_dense, self._all_finite3 = kernels.plain_dense, kernels.all_finite3
        self._certified = bool(getattr(self._backend, "certifies_kkt", False))

    def reset(self) -> None:
        """Forget the warm start: the next solve starts cold (fresh backend state)."""
        self._backend.reset()

    def solve(self, problem: QPProblem) -> QPSolution:
        r"""Solve ``problem``; never raises for an infeasible or unsolvable problem.

        A backend "success" is accepted only if the KKT residuals recomputed on the unscaled
        problem satisfy, with :math:`\epsilon` = ``kkt_tol`` and infinity norms,

        .. math::

            \text{stationarity} &\le \epsilon\, s_d, \quad
            s_d = 1 + \max(\|Hx\|, \|g\|, \|C^\top z\|, \|z_{box}\|) \\
            \text{primal\_infeasibility} &\le \epsilon\, s_p, \quad
            s_p = 1 + \max(\|Cx\|, \|x\|) \\
            \text{dual\_sign} &\le \epsilon\, s_d, \qquad
            \text{complementarity} \le \epsilon\, s_d\, s_p.

        This check is made on every proxsuite and OSQP "success". A "solved" of the
        active-set backends, DAQP and quadprog, is the exact optimum of their final working
        set, certified by their exit (see ``_DaqpBackend.certifies_kkt``): it is accepted
        without recomputing the residuals (``primal_residual`` and ``dual_residual`` are then
        NaN: :func:`kkt_residuals` computes them) once its x and multipliers are finite.
        A "solved" solution is always finite.

        Otherwise -- and whenever a warm-started solve ends in anything but "solved" --
        the solve is repeated once cold (proxsuite 0.8.0 occasionally reports "solved"
        from a warm start with a wrong-sign multiplier and a wrong ``x``, and a warm start
        from a dissimilar previous QP can stall at max_iter or be declared infeasible);
        if the check still fails the status is ``"failed"``.

        Args:
            problem: shapes (n, n), (n,), (m, n), (m,), (m,), (n,), (n,).

        Returns:
            the solution of the last attempt: ``x``, ``status`` and ``iterations`` all come
            from it; ``total_iterations`` sums the attempts and ``solve_time_s`` covers them.

        Raises:
            QPDimensionError: a shape does not match ``(n, m)``.
        """
        t0 = time.perf_counter()
        d, checked = self._dense(problem)
        k = self.m + self.n
        attempts = total = 0
        if not checked and not all_finite(d.H, d.g, d.C):
            raw, status, kkt = self._trivial(d, "failed")
        elif not checked and not _bounds_consistent(d.bounds[:k], d.bounds[k:]):
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
            raw.x, raw.z, raw.z_box, status, raw.iterations, time.perf_counter() - t0,
            kkt.primal_infeasibility, kkt.stationarity, raw.inner_iterations, total, attempts)

    def _dense(self, problem: QPProblem) -> tuple[_Dense, bool]:
        """``_as_dense(problem, n, m)``, and True when its data are known to pass the checks
        of :meth:`solve` (``H``, ``g``, ``C`` finite, bounds consistent). Float64 arrays of
        the right shapes are filled and checked in one compiled call
        (:func:`repro.control.kernels.plain_dense`: the same bits); anything else, or
        data that fail, take :func:`_as_dense` (False: :meth:`solve` checks them)."""
        n, m = self.n, self.m
        arrays = _plain(problem, n, m)
        if arrays is not None:
            H, g, C, l, u, lb, ub = arrays
            H_sym, bounds = np.empty((n, n)), np.empty(2 * (n + m))
            if self._plain_dense(H, g, C, l, u, lb, ub, H_sym, bounds):
                return _Dense(H_sym, g, C, l, u, lb, ub, bounds), True
        return _as_dense(problem, n, m), False

    def _finite(self, x: np.ndarray, z: np.ndarray, z_box: np.ndarray) -> bool:
        """``all_finite(x, z, z_box)``; one compiled call for float64 vectors
        (:func:`repro.control.kernels.all_finite3`)."""
        if (type(x) is np.ndarray and type(z) is np.ndarray and type(z_box) is np.ndarray
                and x.dtype == _F64 and z.dtype == _F64 and z_box.dtype == _F64
                and x.ndim == 1 and z.ndim == 1 and z_box.ndim == 1):
            return bool(self._all_finite3(x, z, z_box))
        return all_finite(x, z, z_box)

    def _attempt(self, d: _Dense) -> tuple[_RawResult, QPStatus, _KKT]:
        """One backend solve, its KKT residuals and its status after the KKT check.

        A "solved" beyond the budget (no backend reports one; a guard on the counts above)
        becomes "max_iter".
        """
        raw = self._backend.solve(d)
        if self._certified and raw.status == "solved":
            if self._finite(raw.x, raw.z, raw.z_box):
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

    def _trivial(self, d: _Dense, status: QPStatus) -> tuple[_RawResult, QPStatus, _KKT]:
        """A zero result for data the backends are not given (non-finite, or ``l > u``)."""
        raw = _RawResult(np.zeros(self.n), np.zeros(self.m), np.zeros(self.n), status, 0, 0)
        with np.errstate(invalid="ignore"):
            kkt = _kkt_full(d, raw.x, raw.z, raw.z_box, self._kkt_work)
        return raw, status, kkt

    def _kkt_ok(self, kkt: _KKT) -> bool:
        """The acceptance test of :meth:`solve` (scales ``s_d``, ``s_p`` from :func:`_kkt_full`)."""
        eps = self.kkt_tol
        s_d, s_p = kkt.s_d, kkt.s_p
        return (
            kkt.stationarity <= eps * s_d
            and kkt.primal_infeasibility <= eps * s_p
            and kkt.dual_sign <= eps * s_d
            and kkt.complementarity <= eps * s_d * s_p
        )
