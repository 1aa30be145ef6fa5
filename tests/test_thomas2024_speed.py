"""The faster thomas2024 controller step (issue 15, item 4) computes what the previous code
computed, to the bit, but for the normal estimator (below).

Each fast piece is compared with a verbatim copy of the code it replaced (the references
below) or with the NumPy call it stands for, on seeded random data and on replayed states of
the cases; timings are not tested (``make bench`` measures them).

- the interaction matrix of eqs. (2), (5), (6) (a compiled loop: the same IEEE operations);
- the normal estimator of eqs. (3)-(4) is the exception: its compiled kernel (no LAPACK)
  rounds differently from the NumPy/LAPACK code it replaced and agrees with it within
  measured tolerances (case 2 was remade with it);
- the controller's QP (10) (one Jacobian per link, ``ndarray.dot``, pixel normalisation),
  its dual stopping test, and the QP layer's cheaper checks (bounds, finiteness, the KKT
  check's reused buffers, DAQP's certified "solved").
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import experiments.thomas2024.config as C
from experiments.thomas2024 import scene as sc
from experiments.thomas2024.bench import _mover_poses
from experiments.thomas2024.run import Thomas2024Controller, build
from repro.control import qp as Q
from repro.control.proximity_features import (
    MODELS,
    SOURCE_FIT,
    SOURCE_HELD,
    SOURCE_NONE,
    NormalEstimator,
    NormalEstimatorConfig,
    ring_interaction_matrix,
)
from repro.control.qp import QPProblem, QPSolution, QPSolver, kkt_residuals
from repro.geometry import Rx, Ry, Rz, make_T
from repro.sensors.proximity import RingSpec
from repro.vision.features import interaction_matrix_points
from repro.vision.ibvs import feature_jacobian

RESULTS = Path(__file__).parents[1] / "results"


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal shapes, dtypes and bytes: NaN == NaN, and 0.0 != -0.0."""
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


# --------------------------------------------------------------------------------------
# References: the code the fast path replaced (repro/control/proximity_features.py before
# issue 15 item 4), verbatim but for names
# --------------------------------------------------------------------------------------

_YZX = np.array([1, 2, 0])
_ZXY = np.array([2, 0, 1])


def reference_ring_interaction_matrix(n_S: np.ndarray, delta: np.ndarray, r: float, model: str,
                                      normals: np.ndarray | None = None) -> np.ndarray:
    m = n_S.shape[0]
    L = np.zeros((m, 6))
    L[:, :3] = -n_S  # eq. (6)
    if model == "coarse" or normals is None:
        return L
    ok = np.isfinite(normals).all(axis=1)
    if not ok.any():
        return L
    n_T = normals[ok]
    m_T = (delta[ok] + r)[:, None] * n_S[ok]
    rows = np.empty((n_T.shape[0], 6))  # eq. (5): [n_T, m_T x n_T]
    rows[:, :3] = n_T
    rows[:, 3:] = m_T[:, _YZX] * n_T[:, _ZXY] - m_T[:, _ZXY] * n_T[:, _YZX]
    if model == "exact":
        rows *= (-1.0 / np.einsum("ij,ij->i", n_T, n_S[ok]))[:, None]  # beta, eq. (2)
    L[ok] = rows
    return L


class ReferenceEstimator:
    """The NumPy/LAPACK normal estimator the compiled kernel replaced (einsum sums of
    eq. (4), LAPACK eigenvalues and pseudo-inverse of every B), verbatim but for names."""

    def __init__(self, n_S: np.ndarray, radius: float, config: NormalEstimatorConfig) -> None:
        self.n_S, self.radius, self.config = n_S, radius, config
        self._past: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._current: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        m = n_S.shape[0]
        self._held = np.full((m, 3), np.nan)
        self.cond = np.full(m, np.nan)
        self.spread = np.full(m, np.nan)
        self.source = np.zeros(m, dtype=int)

    def update(self, T_world_ring: np.ndarray, delta: np.ndarray, detected: np.ndarray) -> None:
        if self._current is not None and self.config.history > 0:
            if self._past is None:
                self._past = (self._current[0][None], self._current[1][None],
                              self._current[2][None])
            elif len(self._past[0]) < self.config.history:
                self._past = (np.concatenate((self._past[0], self._current[0][None])),
                              np.concatenate((self._past[1], self._current[1][None])),
                              np.concatenate((self._past[2], self._current[2][None])))
            else:
                for buf, new in zip(self._past, self._current, strict=True):
                    buf[:-1] = buf[1:]
                    buf[-1] = new
        pts = (delta + self.radius)[:, None] * self.n_S
        self._current = (T_world_ring.copy(), pts, detected.copy())

    def normals(self) -> np.ndarray:
        m = self.n_S.shape[0]
        out = np.full((m, 3), np.nan)
        self.cond[:], self.spread[:], self.source[:] = np.nan, np.nan, SOURCE_NONE
        if self._current is None:
            return out
        cfg = self.config
        T_now, pts_now, det_now = self._current
        self._held[~det_now] = np.nan
        if not np.any(det_now):
            return out
        T_now_inv = np.linalg.inv(T_now)
        if self._past is None:
            P, D = pts_now[None], det_now[None]
        else:
            T_then, p_then, d_then = self._past
            T_rel = T_now_inv @ T_then
            p_rel = p_then @ T_rel[:, :3, :3].transpose(0, 2, 1) + T_rel[:, None, :3, 3]
            P = np.concatenate((pts_now[None], p_rel))
            D = np.concatenate((det_now[None], d_then))
        sensors = np.flatnonzero(det_now)
        offsets = np.arange(-cfg.neighbours, cfg.neighbours + 1)
        nbr = (sensors[:, None] + offsets[None, :]) % m
        cand = P[:, nbr]
        valid = D[:, nbr]
        p_i = pts_now[sensors]
        diff = cand - p_i[None, :, None, :]
        dist = np.sqrt(np.add.reduce(diff * diff, axis=-1))
        keep = valid & (dist <= cfg.max_separation)
        keep[1:] &= dist[1:] >= cfg.min_separation
        w = keep.astype(float)
        B = np.einsum("ksw,kswa,kswb->sab", w, cand, cand)
        b = np.einsum("ksw,kswa->sa", w, cand)
        count = w.sum(axis=(0, 2))
        n_plane = np.einsum("sab,sb->sa", np.linalg.pinv(B, rcond=1e-6), b)
        norm = np.linalg.norm(n_plane, axis=1)
        eig = np.linalg.eigvalsh(B)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.cond[sensors] = eig[:, -1] / np.maximum(eig[:, 0], 1e-16 * eig[:, -1])
            spread = np.sqrt(np.maximum(eig[:, 0], 0.0) / count)
        self.spread[sensors] = spread
        posed = spread >= cfg.min_spread
        good = (count >= 2) & np.isfinite(norm) & (norm > 1e-12) & posed
        n_T = -n_plane / np.where(good, norm, 1.0)[:, None]
        facing = np.einsum("sa,sa->s", n_T, self.n_S[sensors]) <= -cfg.min_facing
        good &= facing
        out[sensors[good]] = n_T[good]
        self.source[sensors[good]] = SOURCE_FIT
        R = T_now[:3, :3]
        self._held[sensors[good]] = n_T[good] @ R.T
        hold = sensors[~good & ~np.isnan(self._held[sensors, 0])]
        out[hold] = self._held[hold] @ R
        self.source[hold] = SOURCE_HELD
        return out


# --------------------------------------------------------------------------------------
# The normal estimator, eqs. (3)-(4)
# --------------------------------------------------------------------------------------


def _scan(T: np.ndarray, spec: RingSpec, planes: list[tuple[np.ndarray, float]],
          noise: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Ranges (m,) [m] and detections (m,) of the ring at pose ``T`` (world) among the planes
    ``n . p = c`` (exact ray-plane intersections, plus Gaussian noise on the hits)."""
    n_S = spec.directions()
    o = T[:3, 3] + (spec.radius * n_S) @ T[:3, :3].T
    d = n_S @ T[:3, :3].T
    best = np.full(len(n_S), np.inf)
    for n, c in planes:
        den = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (c - o @ n) / den
        hit = (den != 0) & (t > 0) & (t < spec.max_range) & (t < best)
        best = np.where(hit, t, best)
    detected = np.isfinite(best)
    delta = np.where(detected, best + noise * rng.normal(size=best.shape), spec.max_range)
    return delta, detected


def _ring_path(rng: np.random.Generator, steps: int) -> list[np.ndarray]:
    """Ring poses: a random walk of small steps (1-2 cm, a few degrees), with still spells
    (degenerate fits: the estimator holds its last normal) and a trip away from every plane
    (no detection: it forgets them)."""
    T = make_T(t=(0.0, 0.0, 0.0))
    poses = []
    for k in range(steps):
        if k % 40 >= 30:  # still
            pass
        elif 60 <= k < 70:  # away, out of range of the planes
            T = T @ make_T(t=(0.0, 0.0, 0.2))
        elif 70 <= k < 80:
            T = T @ make_T(t=(0.0, 0.0, -0.2))
        else:
            a = rng.normal(0.0, np.radians(2.0), 3)
            T = T @ make_T(t=rng.normal(0.0, 0.012, 3)) @ Rx(a[0]) @ Ry(a[1]) @ Rz(a[2])
        poses.append(T.copy())
    return poses


def _planes(rng: np.random.Generator) -> list[tuple[np.ndarray, float]]:
    """Three boards around the ring's start: a tilted wall each side and one ahead."""
    out = []
    for centre in ((0.25, 0.0, 0.05), (-0.22, 0.05, 0.0), (0.0, 0.3, 0.1)):
        n = -np.asarray(centre) + rng.normal(0.0, 0.15, 3)  # facing the ring, tilted
        n /= np.linalg.norm(n)
        out.append((n, float(n @ np.asarray(centre))))
    return out


#: Agreement of the compiled estimator with the LAPACK code (ReferenceEstimator), measured
#: 2026-12-05 over the walks below and 20 more seeds (72000 sensor-steps, AMD EPYC): normals
#: within 7.0e-11 (fits of cond(B) up to ~1e5 carry that rounding), spreads within 1.4e-8 m
#: (a degenerate fit's lambda_min is rounding, ~1e-16 lambda_max, and its square root
#: ~1e-8 m), cond(B) where below 1e8 within a relative 1.1e-8 (~eps cond), the same source
#: for every sensor. Tolerances 10x those: a real change of the estimate (a 1 % gain, a
#: flipped sign, one point more or less) moves a normal by >= 1e-4.
NORMAL_TOL = 1e-9
SPREAD_TOL = 1e-7  # [m]
COND_REL_TOL = 1e-7  # where cond(B) < 1e8


@pytest.mark.parametrize(("history", "neighbours", "noise", "seed"), [
    (15, 1, 0.0, 1), (15, 1, 0.002, 2), (5, 2, 0.002, 3), (30, 1, 0.0005, 4), (0, 1, 0.0, 5)])
def test_normal_estimator_agrees_with_the_lapack_code(
        history: int, neighbours: int, noise: float, seed: int) -> None:
    """Normals, cond(B), spreads, sources and the held (world) normals after every step of a
    seeded random walk among three tilted planes, against the NumPy/LAPACK code, within the
    measured tolerances above."""
    rng = np.random.default_rng(seed)
    spec = RingSpec("ring2", sc.RING2_RADIUS, 18, 1.0, 0.0, 0.0, noise)
    cfg = NormalEstimatorConfig(history=history, neighbours=neighbours, range_noise=noise)
    fast = NormalEstimator(spec.directions(), spec.radius, cfg)
    ref = ReferenceEstimator(spec.directions(), spec.radius, cfg)
    planes = _planes(rng)
    sources = np.zeros(3, dtype=int)
    for T in _ring_path(rng, 160):
        delta, detected = _scan(T, spec, planes, noise, rng)
        for est in (fast, ref):
            est.update(T, delta, detected)
        got, want = fast.normals(), ref.normals()
        assert np.array_equal(fast.source, ref.source)
        for a, b in ((got, want), (fast._held, ref._held)):
            assert np.array_equal(np.isnan(a), np.isnan(b))
            np.testing.assert_allclose(a, b, rtol=0.0, atol=NORMAL_TOL)
        assert np.array_equal(np.isnan(fast.spread), np.isnan(ref.spread))
        np.testing.assert_allclose(fast.spread, ref.spread, rtol=0.0, atol=SPREAD_TOL)
        assert np.array_equal(np.isnan(fast.cond), np.isnan(ref.cond))
        fit = ref.cond < 1e8
        np.testing.assert_allclose(fast.cond[fit], ref.cond[fit], rtol=COND_REL_TOL)
        assert np.all(fast.cond[~fit & ~np.isnan(ref.cond)] > 1e7)
        sources += np.bincount(fast.source, minlength=3)
    # the walk exercises every branch: fits used, normals held, sensors without any (with no
    # history every fit is of one scan, degenerate: none is used)
    assert sources[SOURCE_NONE] > 0
    assert (sources[SOURCE_FIT] > 0 and sources[SOURCE_HELD] > 0) == (history > 0)


def test_the_agreement_test_sees_a_one_percent_change() -> None:
    """The tolerances above are tight enough: the estimator with every point 1 % off along
    one axis (an anisotropic error, so the plane tilts) fails them."""
    rng = np.random.default_rng(2)
    spec = RingSpec("ring2", sc.RING2_RADIUS, 18, 1.0, 0.0, 0.0, 0.002)
    cfg = NormalEstimatorConfig(range_noise=0.002)
    fast = NormalEstimator(spec.directions(), spec.radius, cfg)
    fast.n_S = fast.n_S * np.array([1.01, 1.0, 1.0])
    ref = ReferenceEstimator(spec.directions(), spec.radius, cfg)
    planes = _planes(rng)
    worst = 0.0
    for T in _ring_path(rng, 60):
        delta, detected = _scan(T, spec, planes, 0.002, rng)
        for est in (fast, ref):
            est.update(T, delta, detected)
        got, want = fast.normals(), ref.normals()
        both = (fast.source == SOURCE_FIT) & (ref.source == SOURCE_FIT)
        if both.any():
            worst = max(worst, float(np.abs(got[both] - want[both]).max()))
    assert worst > 1e3 * NORMAL_TOL


def test_ring_interaction_matrix_equals_the_previous_code_to_the_bit() -> None:
    rng = np.random.default_rng(11)
    for _ in range(300):
        m = int(rng.integers(1, 40))
        n_S = RingSpec("r", 0.07, m, theta0=float(rng.uniform(0, 2 * np.pi))).directions()
        delta = rng.uniform(0.0, 1.0, m)
        normals = rng.normal(size=(m, 3))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        normals[rng.random(m) < 0.4] = np.nan  # no estimate: the coarse row
        normals[rng.integers(m), rng.integers(3)] = np.nan  # one NaN entry is enough
        r = float(rng.uniform(0.01, 0.2))
        for model in MODELS:
            for nrm in (normals, None, np.full((m, 3), np.nan)):
                assert same_bits(ring_interaction_matrix(n_S, delta, r, model, nrm),
                                 reference_ring_interaction_matrix(n_S, delta, r, model, nrm))


# --------------------------------------------------------------------------------------
# The controller step: QP (10) and the stopping test on replayed states
# --------------------------------------------------------------------------------------


def _reference_qp(ctrl: Thomas2024Controller, q: np.ndarray, uv: np.ndarray, Z: np.ndarray,
                  readings: list, normals: tuple) -> tuple[np.ndarray, ...]:
    """H, g, C, l of QP (10) as the previous step built them (``@``, ``to_normalized``,
    one Jacobian call per use, rows written into preallocated arrays)."""
    cfg, m, n = ctrl.config, ctrl.m, ctrl.n
    x = sc.INTRINSICS.to_normalized(uv)
    e_4p = (x - ctrl.s_star).ravel()
    A, b = np.empty((m, n)), np.empty(m)
    row = 0
    for k, (ring, reading) in enumerate(zip(ctrl.rings, readings, strict=True)):
        L = ctrl._ring_L[k]
        if L is None:
            L = reference_ring_interaction_matrix(ctrl.dirs[k], reading.delta, ring.spec.radius,
                                                  cfg.ring_models[k], normals[k])
        link = sc.RING_PARENTS[ring.spec.name][0]
        J_S = ctrl.ring_V[ring.spec.name] @ ctrl.robot.frame_jacobian(link, q)
        A[row:row + len(L)] = L @ J_S
        b[row:row + len(L)] = -cfg.ring_gains[k] * (reading.delta - cfg.thresholds[k])
        row += len(L)
    J_4p = feature_jacobian(interaction_matrix_points(x, Z), ctrl.cV_e,
                            ctrl.robot.frame_jacobian("panda_link8", q))
    G = J_4p.T @ J_4p
    G.flat[:: n + 1] += cfg.mu
    return G, cfg.lambda_4p * J_4p.T @ e_4p, A, b


def replayed_inputs(ep, df: pd.DataFrame):  # type: ignore[no-untyped-def]
    """For each row of a committed thomas2024 trace ``df``: the robot (and case 3's hand)
    put where the row has them in ``ep``'s scene, then ``(k, q, uv, found, Z, readings)``,
    the inputs of ``Thomas2024Controller.step`` there (the exact camera's measurement, every
    ring's reading). The caller closes the scene."""
    rig, scene = ep.cameras[0], ep.scene
    target = scene[rig.target]
    assert target.dot_target is not None
    movers = _mover_poses(df, ["hand"])
    for k, q in enumerate(df[[f"q{i}" for i in range(1, 8)]].to_numpy(dtype=float)):
        rig.robot.reset(q)
        for name, poses in movers.items():
            scene.move(name, poses[k])
        uv, found, Z = rig.camera.measure(scene.render_client, rig.pose(q),
                                          target.dot_target, target.T_world)
        yield k, q, uv, found, Z, [s.read(0.0, {rig.robot.name: q}) for s in ep.sensors]


@pytest.mark.parametrize(("case", "models", "solver"), [
    ("case1", None, "proxsuite"), ("case2", None, "proxsuite"),
    ("case2", ("exact", "exact"), "daqp"), ("case3", None, "daqp")])
def test_controller_qp_and_stop_test_equal_the_previous_code_to_the_bit(
        case: str, models: tuple[str, str] | None, solver: str, tmp_path: Path) -> None:
    """Replay the first 2 s of a committed run (its joint positions, one state in two; case
    3's hand where it was): every hard QP the step builds, and ||grad L(0, kappa*)||, equal
    the previous formulas' to the bit, step after step (a stale Jacobian, normal or buffer
    would differ as soon as q or the scan changes)."""
    trace = RESULTS / "thomas2024" / case / "trace.csv"
    df = pd.read_csv(trace).iloc[:60:2]
    cfg = {"case1": C.Case1Config, "case2": C.Case2Config, "case3": C.Case3Config}[case]()
    cfg = replace(cfg, camera_mode="exact", qp_solver=solver)
    if models is not None:
        cfg = replace(cfg, ring_models=models)
    ep, ctrl = build(cfg, tmp_path / "run")
    problems: list[QPProblem] = []
    solve = ctrl.qp.hard.solve

    def recording(problem: QPProblem) -> QPSolution:
        problems.append(problem)
        return solve(problem)

    ctrl.qp.hard.solve = recording  # type: ignore[method-assign]
    n_estimated = 0
    try:
        for _, q, uv, found, Z, readings in replayed_inputs(ep, df):
            out = ctrl.step(q, uv, found, Z, readings)
            if out.status == "no_features":
                continue
            p = problems[-1]
            normals = tuple(out.normals)
            n_estimated += sum(int(np.isfinite(nr).all(axis=1).sum()) for nr in normals
                               if nr is not None)
            for got, want in zip((p.H, p.g, p.C, p.l),
                                 _reference_qp(ctrl, q, uv, Z, readings, normals), strict=True):
                assert same_bits(got, want)
            if out.status == "solved":
                r = p.g - p.C.T @ out.kappa
                assert out.grad_L0 == math.sqrt(r @ r)
    finally:
        ep.scene.close()
    assert len(problems) >= 20
    if models is not None:
        assert n_estimated > 0, "no estimated normal reached the QP"


def test_to_normalized_equals_its_formula_to_the_bit() -> None:
    """Intrinsics.to_normalized's no-skew broadcast gives the bits of the general formula
    (x = (u - u0 - s y) / fu, y = (v - v0) / fv), exact zeros and non-finite pixels included."""
    K = sc.INTRINSICS

    def formula(uv: np.ndarray) -> np.ndarray:
        y = (uv[..., 1] - K.v0) / K.fv
        return np.stack([(uv[..., 0] - K.u0 - K.skew * y) / K.fu, y], axis=-1)

    assert K.skew == 0.0 and K.u0 != 0.0  # the fast branch is the one tested
    rng = np.random.default_rng(3)
    for _ in range(200):
        uv = rng.uniform(-50.0, 700.0, (4, 2))
        whole = rng.random((4, 2)) < 0.2
        uv[whole] = np.round(uv[whole])
        assert same_bits(K.to_normalized(uv), formula(uv))
    uv = np.array([[K.u0, K.v0]] * 4)  # exact zeros
    assert same_bits(K.to_normalized(uv), formula(uv))
    uv[1] = (np.nan, np.inf)  # a lost dot: NaN x as the formula gives (0 * inf)
    with np.errstate(invalid="ignore"):
        assert same_bits(K.to_normalized(uv), formula(uv))


# --------------------------------------------------------------------------------------
# The QP layer's checks
# --------------------------------------------------------------------------------------

_SPECIAL = (-np.inf, -2.0, -1e-300, -0.0, 0.0, 3.0, 1e308, np.inf, np.nan)


def test_bounds_test_is_the_previous_three_conditions() -> None:
    """l <= u, no l = +inf, no u = -inf, no NaN: every pair of special values, and random
    vectors mixing them."""
    for lo in _SPECIAL:
        for hi in _SPECIAL:
            a, b = np.array([lo]), np.array([hi])
            old = bool((a <= b).all() and not (a == np.inf).any() and not (b == -np.inf).any())
            assert Q._bounds_consistent(a, b) == old, (lo, hi)
    rng = np.random.default_rng(5)
    for _ in range(500):
        a, b = rng.choice(_SPECIAL, 8), rng.choice(_SPECIAL, 8)
        old = bool((a <= b).all() and not (a == np.inf).any() and not (b == -np.inf).any())
        assert Q._bounds_consistent(a, b) == old


def test_all_finite_is_isfinite_all() -> None:
    rng = np.random.default_rng(6)
    for _ in range(300):
        arrays = [rng.choice(_SPECIAL, size=tuple(rng.integers(0, 4, int(rng.integers(1, 3)))))
                  for _ in range(int(rng.integers(1, 4)))]
        assert Q.all_finite(*arrays) == all(bool(np.isfinite(a).all()) for a in arrays)


def _random_problem(rng: np.random.Generator, n: int = 7, m: int = 36) -> QPProblem:
    """A CBF-like QP, feasible by construction (x0 inside every row and the box), rows
    mostly one-sided; its unconstrained optimum lies outside, so rows and bounds bind."""
    J = rng.normal(size=(8, n))
    qd = rng.uniform(1.0, 3.0, n)
    x0 = rng.uniform(-0.5, 0.5, n) * qd
    C = rng.normal(size=(m, n))
    l = C @ x0 - rng.uniform(0.0, 0.3, m)
    u = np.where(rng.random(m) < 0.7, np.inf, C @ x0 + rng.uniform(0.0, 0.3, m))
    return QPProblem(J.T @ J + 0.01 * np.eye(n), 5.0 * rng.normal(size=n), C, l, u, -qd, qd)


def _reference_kkt(p: QPProblem, x: np.ndarray, z: np.ndarray, z_box: np.ndarray
                   ) -> dict[str, float]:
    """The residuals of :func:`kkt_residuals` from their definitions, row by row."""
    H = 0.5 * (p.H + p.H.T)
    stat = np.abs(H @ x + p.g + p.C.T @ z + z_box).max()
    v, y = np.concatenate((p.C @ x, x)), np.concatenate((z, z_box))
    lo, hi = np.concatenate((p.l, p.lb)), np.concatenate((p.u, p.ub))
    viol = max(0.0, float(np.max(lo - v)), float(np.max(v - hi)))
    compl = dual = 0.0
    for vi, yi, li, ui in zip(v, y, lo, hi, strict=True):
        neg, pos = max(-yi, 0.0), max(yi, 0.0)
        compl = max(compl, neg * abs(vi - li) if np.isfinite(li) else 0.0,
                    pos * abs(ui - vi) if np.isfinite(ui) else 0.0)
        dual = max(dual, 0.0 if np.isfinite(li) else neg, 0.0 if np.isfinite(ui) else pos)
    return {"stationarity": stat, "primal_infeasibility": viol, "complementarity": compl,
            "dual_sign": dual}


def test_kkt_check_buffers_are_reused_without_stale_values() -> None:
    """One QPSolver's KKT buffers serve every solve: the residuals of each (x, z, z_box) are
    those computed with fresh buffers, whatever was computed before them (another problem, a
    larger or a smaller residual), and those of the definitions."""
    rng = np.random.default_rng(8)
    work = Q._KKTWork(7, 36)
    for _ in range(100):
        p = _random_problem(rng)
        d = Q._as_dense(p, 7, 36)
        x, z, zb = rng.normal(size=7), rng.normal(size=36), rng.normal(size=7)
        z[rng.random(36) < 0.7] = 0.0
        reused, fresh = Q._kkt_full(d, x, z, zb, work), Q._kkt_full(d, x, z, zb)
        assert reused == fresh
        ref = _reference_kkt(p, x, z, zb)
        for key, value in reused.as_dict().items():
            assert value == pytest.approx(ref[key], rel=1e-12, abs=1e-12), key
    other = Q._KKTWork(3, 2)  # another size: fresh buffers instead
    assert Q._kkt_full(d, x, z, zb, other) == Q._kkt_full(d, x, z, zb)


def test_active_set_solved_is_certified_and_kept_correct() -> None:
    """DAQP's and quadprog's "solved" are accepted on their exit (residuals not recomputed:
    NaN), and are the optimum: their recomputed residuals are tiny and they agree with
    proxsuite's checked solution. proxsuite and OSQP are checked every time."""
    assert {s for s in Q.SOLVERS if Q._BACKENDS[s].certifies_kkt} == {"daqp", "quadprog"}
    rng = np.random.default_rng(9)
    solvers = {s: QPSolver(7, 36, s, max_iter=200) for s in ("daqp", "quadprog", "proxsuite")}
    for _ in range(30):
        p = _random_problem(rng)
        sols = {s: qp.solve(p) for s, qp in solvers.items()}
        if sols["proxsuite"].status != "solved":
            continue
        assert sols["proxsuite"].primal_residual < 1e-6
        for s in ("daqp", "quadprog"):
            sol = sols[s]
            assert sol.status == "solved"
            assert math.isnan(sol.primal_residual) and math.isnan(sol.dual_residual)
            assert max(kkt_residuals(p, sol).values()) < 1e-8
            np.testing.assert_allclose(sol.x, sols["proxsuite"].x, atol=1e-6)


def test_a_certified_solved_with_a_non_finite_solution_is_checked_as_zeros() -> None:
    """No certificate without a finite solution: NaN entries become 0 and the KKT check
    decides (here: not the optimum, so "failed", with a finite x)."""
    p = QPProblem(np.eye(2), np.array([-1.0, -1.0]))  # optimum x = (1, 1)
    qp = QPSolver(2, 0, "daqp")

    class _NaNSolver:
        certifies_kkt = True
        is_warm = False

        def solve(self, d: Q._Dense) -> Q._RawResult:
            return Q._RawResult(np.array([np.nan, 1.0]), np.zeros(0), np.zeros(2), "solved",
                                1, 1)

        def reset(self) -> None:
            pass

    qp._backend = _NaNSolver()  # type: ignore[assignment]
    sol = qp.solve(p)
    assert sol.status == "failed" and np.array_equal(sol.x, [0.0, 1.0])
    assert math.isfinite(sol.dual_residual)


def test_daqp_equality_rows_switch_the_setup_and_stay_exact() -> None:
    """DAQP's warm model is set up again when the rows that are equalities change (their
    mask is compared as bytes): a sequence switching a row between inequality and equality
    gives each QP's cold answer."""
    rng = np.random.default_rng(10)
    base = _random_problem(rng, 7, 6)
    warm = QPSolver(7, 6, "daqp", max_iter=200)
    for k in range(12):
        u = base.u.copy()
        if k % 3 == 1:
            u[2] = base.l[2]  # row 2 an equality
        if k % 4 == 2:
            u[4] = base.l[4]
        p = base._replace(u=u, g=base.g + 0.1 * k)
        got = warm.solve(p)
        cold = QPSolver(7, 6, "daqp", max_iter=200, warm_start=False).solve(p)
        assert got.status == cold.status
        if got.status == "solved":
            np.testing.assert_allclose(got.x, cold.x, atol=1e-9)
            np.testing.assert_allclose(got.z, cold.z, atol=1e-8)


def test_a_certified_backends_non_finite_solved_reaches_the_check(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """DAQP and quadprog hand a "solved" over as it is (not zeroed): a NaN in it voids the
    certificate, the KKT check decides (on zeros in its place), and a warm DAQP retries cold."""
    p = QPProblem(np.eye(2), np.array([-1.0, -1.0]), np.array([[1.0, 0.0]]), np.array([-5.0]),
                  np.array([np.inf]))  # optimum x = (1, 1)

    class NaNModel:  # a daqp.Model whose next solution has x1 = NaN
        def __init__(self, model: object) -> None:
            self.model = model

        def update(self, **data: np.ndarray) -> int:
            return int(self.model.update(**data))  # type: ignore[attr-defined]

        def solve(self) -> tuple:
            x, fval, flag, info = self.model.solve()  # type: ignore[attr-defined]
            return np.array([np.nan, x[1]]), fval, flag, info

    qp = QPSolver(2, 1, "daqp")
    assert qp.solve(p).status == "solved"  # sets the model up
    qp._backend._model = NaNModel(qp._backend._model)  # type: ignore[attr-defined]
    sol = qp.solve(p)
    assert (sol.status, sol.attempts, qp.cold_retries) == ("solved", 2, 1)
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=1e-12)

    import quadprog

    def nan_qp(*args: object) -> tuple:
        out = list(quadprog.solve_qp(*args))
        out[0] = np.array([np.nan, out[0][1]])
        return tuple(out)

    qp = QPSolver(2, 1, "quadprog")
    monkeypatch.setattr(qp._backend, "_solve_qp", nan_qp)
    sol = qp.solve(p)
    assert sol.status == "failed" and np.array_equal(sol.x, [0.0, 1.0])
