"""pomares2011 direct hybrid visual servoing (repro.control.hybrid_vs): finite-difference
checks of every Jacobian, the W / null-space projector invariants, the secondary task (17),
the Lyapunov function (10), and closed-loop torque-control runs of the CRS-A465 at 1 kHz."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from repro.control.hybrid_vs import (
    HybridVSConfig,
    HybridVSController,
    distance_gradient,
    gains_from_inertia,
    lyapunov,
    primary_task,
    secondary_task,
    task_function,
    task_jacobian,
    weight_matrix,
)
from repro.errors import ConfigError
from repro.runs.columns import Columns
from repro.runs.trace import load_run
from repro.sensors.camera import Intrinsics, project_points
from repro.sim.crs_a465 import CRS_JOINTS, CRS_LIMITS, T_FLANGE_CAMERA, crs_urdf_path
from repro.sim.drives import TorqueDrive
from repro.sim.episode import Episode, Observation, StepResult, run_episode
from repro.sim.robot import Robot
from repro.sim.scene import Scene
from repro.sim.world import World, WorldConfig
from repro.vision.features import interaction_matrix_points, twist_transform
from repro.vision.ibvs import feature_jacobian

# pomares2011 Sec. 7: the mini-robot camera, 640 x 480 px.
INTR = Intrinsics(640, 480, 1082.3, 1073.7, 298.0, 225.0)
# ours: the target, a 10 cm square of 4 points 0.35 m in front of the camera at the goal.
P_GOAL_C = np.array([[-0.05, -0.05, 0.35], [0.05, -0.05, 0.35], [0.05, 0.05, 0.35],
                     [-0.05, 0.05, 0.35]])
Q_GOAL = np.array([0.3, 0.5, 0.8, 0.2, -0.4, 0.1])
# ours: start offset [rad], ~190 px of image error (norm over the 8 coordinates).
DQ_START = np.array([0.025, -0.025, 0.025, 0.05, -0.05, 0.05])
OMEGA_MAX = 100.0  # ours: fastest closed-loop mode [rad/s], 1/10 of the 1 kHz loop
ZETA = 1.0  # ours: every mode critically damped
DMIN = 0.3  # ours: [m]
F_PUSH = 1.0  # ours: virtual push at contact [N], alpha = F_PUSH * DMIN / k_P


def _transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _pixel_L(uv: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """(2N, 6) interaction matrix of pixel features: the normalised one (true depths), rows
    scaled by fu (u rows) and fv (v rows) -- exact for a pinhole without skew."""
    L = interaction_matrix_points(INTR.to_normalized(uv), Z)
    return L * np.tile([INTR.fu, INTR.fv], len(Z))[:, None]


def _features(T_wc: np.ndarray, P_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """s (2N,) [px], rows u1, v1, u2, ..., and L_s (2N, 6) [px per camera-twist unit]."""
    uv, Z = project_points(INTR, T_wc, P_w)
    return uv.reshape(-1), _pixel_L(uv, Z)


def _points_world(T_wc: np.ndarray) -> np.ndarray:
    return P_GOAL_C @ T_wc[:3, :3].T + T_wc[:3, 3]


# ----------------------------------------------------------------------------- Jacobians
def _random_chain(rng: np.random.Generator, n: int = 6):  # type: ignore[no-untyped-def]
    """A random serial chain of revolute joints (standard DH) with a camera at its end."""
    dh = rng.uniform([-np.pi, 0.0, 0.0, -np.pi], [np.pi, 0.3, 0.3, np.pi], size=(n, 4))
    mount = pin.SE3(pin.exp3(rng.normal(size=3) * 0.3), rng.normal(size=3) * 0.05).homogeneous

    def T_wc(q: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        for qi, (off, d, a, al) in zip(q, dh, strict=True):
            c, s = np.cos(qi + off), np.sin(qi + off)
            ca, sa = np.cos(al), np.sin(al)
            T = T @ np.array([[c, -s * ca, s * sa, a * c], [s, c * ca, -c * sa, a * s],
                              [0, sa, ca, d], [0, 0, 0, 1.0]])
        return T @ mount

    return T_wc


def _numeric_camera_jacobian(T_wc, q: np.ndarray, h: float = 1e-6) -> np.ndarray:  # type: ignore[no-untyped-def]
    """J_g (6, n) by central differences of log6(T_wc(q)^-1 T_wc(q +- h e_i)): the camera
    twist (v, w) in the camera frame per joint velocity."""
    T0_inv = np.linalg.inv(T_wc(q))
    cols = []
    for i in range(q.size):
        dq = np.zeros(q.size)
        dq[i] = h
        plus = pin.log6(pin.SE3(T0_inv @ T_wc(q + dq))).vector
        minus = pin.log6(pin.SE3(T0_inv @ T_wc(q - dq))).vector
        cols.append((plus - minus) / (2 * h))
    return np.array(cols).T


def _fd(f, x: np.ndarray, h: float = 1e-6) -> np.ndarray:  # type: ignore[no-untyped-def]
    cols = []
    for i in range(x.size):
        dx = np.zeros(x.size)
        dx[i] = h
        cols.append((np.atleast_1d(f(x + dx)) - np.atleast_1d(f(x - dx))) / (2 * h))
    return np.array(cols).T


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_task_jacobian_matches_finite_differences_on_a_random_chain(seed: int) -> None:
    rng = np.random.default_rng(seed)
    T_wc = _random_chain(rng)
    q = rng.uniform(-np.pi, np.pi, 6)
    P_w = _points_world(T_wc(q)) + rng.normal(size=(4, 3)) * 0.02
    s, L_s = _features(T_wc(q), P_w)
    J = task_jacobian(L_s, _numeric_camera_jacobian(T_wc, q))  # eq. (6), numeric J_g
    J_fd = _fd(lambda x: _features(T_wc(x), P_w)[0], q)
    assert np.abs(J_fd).max() > 10.0  # pixels per rad: not a trivial case
    np.testing.assert_allclose(J, J_fd, atol=1e-5 * np.abs(J_fd).max())


def test_task_jacobian_of_the_crs_matches_finite_differences() -> None:
    with World(WorldConfig(1e-3, 1e-3)) as world:
        robot = Robot(world, crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
        rng = np.random.default_rng(7)
        P_w = _points_world(robot.frame_pose("camera_optical", Q_GOAL))
        for _ in range(3):
            q = Q_GOAL + rng.uniform(-0.3, 0.3, 6)
            _, L_s = _features(robot.frame_pose("camera_optical", q), P_w)
            J_g = robot.frame_jacobian("camera_optical", q, "local")
            J = task_jacobian(L_s, J_g)
            J_fd = _fd(lambda x: _features(robot.frame_pose("camera_optical", x), P_w)[0], q)
            np.testing.assert_allclose(J, J_fd, atol=1e-5 * np.abs(J_fd).max())
            # the same as the flange Jacobian moved to the camera (T_FLANGE_CAMERA)
            cV_e = twist_transform(np.linalg.inv(T_FLANGE_CAMERA))
            np.testing.assert_allclose(
                J, feature_jacobian(L_s, cV_e, robot.frame_jacobian("flange", q, "local")),
                atol=1e-9 * np.abs(J).max())


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    return pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3)).homogeneous


def _e2_of_pose(T_wc: np.ndarray, p_c: np.ndarray, h_w: np.ndarray, alpha: float) -> float:
    dist = float(np.linalg.norm(T_wc[:3, :3] @ p_c + T_wc[:3, 3] - h_w))
    return secondary_task(dist, np.zeros(6), alpha, DMIN)[0]


def _e2_and_gradient(T_wc: np.ndarray, p_c: np.ndarray, h_w: np.ndarray, alpha: float
                     ) -> tuple[float, np.ndarray]:
    d_w = T_wc[:3, :3] @ p_c + T_wc[:3, 3] - h_w
    dist = float(np.linalg.norm(d_w))
    n_c = T_wc[:3, :3].T @ d_w / dist
    return secondary_task(dist, distance_gradient(p_c, n_c), alpha, DMIN)


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_secondary_task_gradient_matches_finite_differences(seed: int) -> None:
    """de2/dr (17) against central differences over camera twists, T exp(h xi)."""
    rng = np.random.default_rng(seed)
    T_wc = _random_pose(rng)
    p_c = rng.normal(size=3) * 0.05  # a point of the camera body [m]
    u = rng.normal(size=3)
    h_w = T_wc[:3, :3] @ p_c + T_wc[:3, 3] + rng.uniform(0.05, 0.25) * u / np.linalg.norm(u)
    alpha = 2.0
    e2, grad = _e2_and_gradient(T_wc, p_c, h_w, alpha)
    assert e2 > 0 and np.linalg.norm(grad) > 0

    def e2_of_twist(xi: np.ndarray) -> float:
        return _e2_of_pose(T_wc @ pin.exp6(xi).homogeneous, p_c, h_w, alpha)

    np.testing.assert_allclose(grad, _fd(e2_of_twist, np.zeros(6))[0], atol=1e-7)


def test_secondary_task_gradient_in_joint_space_of_the_crs() -> None:
    """de2/dq = de2/dr J_g: the gradient w.r.t. the robot position, by finite differences."""
    with World(WorldConfig(1e-3, 1e-3)) as world:
        robot = Robot(world, crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
        p_c = np.array([0.02, -0.03, -0.04])
        T0 = robot.frame_pose("camera_optical", Q_GOAL)
        h_w = T0[:3, :3] @ p_c + T0[:3, 3] + np.array([0.1, -0.08, 0.05])
        e2, grad = _e2_and_gradient(T0, p_c, h_w, 3.0)
        assert e2 > 0
        analytic = grad @ robot.frame_jacobian("camera_optical", Q_GOAL, "local")
        numeric = _fd(lambda x: _e2_of_pose(robot.frame_pose("camera_optical", x), p_c, h_w,
                                            3.0), Q_GOAL)[0]
        assert np.abs(numeric).max() > 1.0
        np.testing.assert_allclose(analytic, numeric, atol=1e-6)


# ----------------------------------------------------------------------------- W, e, e2, V
def _L_four_points(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    P_c = P_GOAL_C + rng.normal(size=(4, 3)) * 0.01
    uv = INTR.to_pixels(P_c[:, :2] / P_c[:, 2:])
    return _pixel_L(uv, P_c[:, 2]), rng.normal(size=8) * 20.0


def test_full_primary_task_uses_every_dof() -> None:
    """4 points, 6-DoF camera: rank 6, W^+ W = I (experiment 1); e = L_s^T e_s and the
    secondary task has no effect."""
    L_s, e_s = _L_four_points()
    W = weight_matrix(L_s)
    assert W.shape == (6, 6)
    np.testing.assert_allclose(W.T @ W, np.eye(6), atol=1e-12)  # W^+ W, W^+ = W^T
    np.testing.assert_allclose(np.linalg.pinv(W), W.T, atol=1e-12)
    e1 = primary_task(W, L_s, e_s)
    np.testing.assert_allclose(e1, W @ L_s.T @ e_s)  # eq. (2), B = W L_s^T
    e = task_function(W, e1)
    np.testing.assert_allclose(e, L_s.T @ e_s, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(task_function(W, e1, np.ones(6) * 1e3), e, atol=1e-9)


@pytest.mark.parametrize("rows, m", [((1,), 1), ((0, 1, 2, 3), 4)])
def test_reduced_primary_task_leaves_a_null_space(rows: tuple[int, ...], m: int) -> None:
    L_s, e_s = _L_four_points(1)
    W = weight_matrix(L_s, rows)
    assert W.shape == (m, 6)
    W_pinv = np.linalg.pinv(W)
    P_null = np.eye(6) - W_pinv @ W
    np.testing.assert_allclose(P_null @ W_pinv, 0.0, atol=1e-12)  # (I - W^+W) W^+ = 0
    np.testing.assert_allclose(W @ P_null, 0.0, atol=1e-12)
    np.testing.assert_allclose(P_null @ P_null, P_null, atol=1e-12)  # a projector
    assert np.linalg.matrix_rank(P_null) == 6 - m
    # the secondary term does not move the primary features (first order), e.g. f1y
    de2_dr = np.random.default_rng(2).normal(size=6)
    e = task_function(W, primary_task(W, L_s[list(rows)], e_s[list(rows)]), de2_dr)
    e_primary = task_function(W, primary_task(W, L_s[list(rows)], e_s[list(rows)]))
    scale = np.abs(L_s).max() * np.abs(e - e_primary).max()
    np.testing.assert_allclose(L_s[list(rows)] @ (e - e_primary), 0.0, atol=1e-10 * scale)
    assert np.linalg.norm(e - e_primary) > 0.1  # ... but it does act


def test_secondary_task_is_zero_beyond_dmin_and_continuous_at_dmin() -> None:
    g = np.array([0.3, -0.2, 0.9, 0.1, 0.0, -0.2])
    alpha = 7.0
    for dist in (DMIN, 1.01 * DMIN, 5.0):
        e2, grad = secondary_task(dist, g, alpha, DMIN)
        assert e2 == 0.0 and not grad.any()
    assert secondary_task(DMIN * (1 - 1e-9), g, alpha, DMIN)[0] == pytest.approx(0.0, abs=1e-7)
    assert secondary_task(0.0, g, alpha, DMIN)[0] == pytest.approx(alpha)
    e2, grad = secondary_task(0.25 * DMIN, g, alpha, DMIN)
    assert e2 == pytest.approx(0.75 * alpha)
    np.testing.assert_allclose(grad, -alpha / DMIN * g)


def test_secondary_term_moves_the_camera_away_from_the_human() -> None:
    """Our sign reading of (3): the commanded camera motion increases dist."""
    L_s, e_s = _L_four_points(3)
    W = weight_matrix(L_s, (1,))
    grad_dist = distance_gradient(np.array([0.0, 0.0, -0.03]), np.array([0.6, 0.0, 0.8]))
    _, de2_dr = secondary_task(0.1, grad_dist, 5.0, DMIN)
    e_sec = task_function(W, np.zeros(1), de2_dr)
    assert grad_dist @ e_sec > 0.0


def test_lyapunov_on_known_values() -> None:
    M = np.array([[2.0, 0.5], [0.5, 3.0]])
    qd = np.array([1.0, -2.0])
    e_s = np.array([3.0, 4.0, 0.0])
    # 1/2 (2 - 2*0.5*2 + 12) + 1/2 * 0.5 * 25 = 6 + 6.25
    assert lyapunov(qd, M, e_s, 0.5) == pytest.approx(12.25)
    assert lyapunov(np.zeros(2), M, np.zeros(3), 0.5) == 0.0


def test_gains_from_inertia_set_the_fastest_mode_and_damp_every_mode() -> None:
    rng = np.random.default_rng(4)
    A = rng.normal(size=(6, 6))
    M = A @ A.T + 0.1 * np.eye(6)
    J = rng.normal(size=(8, 6)) * 500.0
    k_P, K_v = gains_from_inertia(M, J, 50.0, 0.7)
    lam = np.linalg.eigvals(np.linalg.solve(M, k_P * J.T @ J)).real
    assert np.sqrt(lam.max()) == pytest.approx(50.0)
    assert np.linalg.eigvalsh(K_v).min() > 0
    # linearised closed loop: every pole has damping ratio 0.7
    n = 6
    Acl = np.block([[np.zeros((n, n)), np.eye(n)],
                    [-np.linalg.solve(M, k_P * J.T @ J), -np.linalg.solve(M, K_v)]])
    poles = np.linalg.eigvals(Acl)
    np.testing.assert_allclose(-poles.real / np.abs(poles), 0.7, atol=1e-6)
    with pytest.raises(ConfigError, match="omega_max"):
        gains_from_inertia(M, J, -1.0)


def test_config_rejects_bad_gains() -> None:
    with pytest.raises(ConfigError, match="K_v"):
        HybridVSConfig(np.zeros(8), 1.0, -np.ones(6), 1.0, DMIN)
    with pytest.raises(ConfigError, match="k_P"):
        HybridVSConfig(np.zeros(8), 0.0, np.ones(6), 1.0, DMIN)
    with pytest.raises(ConfigError, match="avoid_rows"):
        HybridVSConfig(np.zeros(8), 1.0, np.ones(6), 1.0, DMIN, avoid_rows=(8,))


# ----------------------------------------------------------------------------- closed loop
@dataclass
class ServoRun:
    t: np.ndarray  # (T,) [s]
    err_px: np.ndarray  # (T,) |s* - s| over the rows in use [px]
    f1y_err: np.ndarray  # (T,) f1y* - f1y [px]
    V: np.ndarray  # (T,) eq. (10) [J]
    dist: np.ndarray  # (T,) human-camera distance [m] (inf: no human)
    active: np.ndarray  # (T,) bool
    q: np.ndarray  # (T, 6) [rad]
    tau: np.ndarray  # (T, 6) [N m]
    G: np.ndarray  # (T, 6) [N m]
    n_sat: np.ndarray  # (T,) joints clipped by the drive
    k_P: float


def _servo(tmp: Path, q_start: np.ndarray, duration: float,
           human_w: np.ndarray | None = None, avoid_rows: tuple[int, ...] | None = (1,),
           f_push: float = F_PUSH) -> ServoRun:
    """The CRS-A465 in a Scene at physics = control = 1 kHz with a TorqueDrive, servoing
    its camera (exact projection) on 4 virtual points seen from Q_GOAL. ``human_w``: a
    static point "human" [m, world]; dist is measured from the camera origin (ours)."""
    scene = Scene(WorldConfig(physics_dt=1e-3, control_dt=1e-3), run_dir=tmp)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    assert [robot.model.joints[robot.model.getJointId(j)].idx_q for j in CRS_JOINTS] == list(
        range(6))  # pinocchio q order = control order
    robot.reset(q_start)
    frame = "camera_optical"
    P_w = _points_world(robot.frame_pose(frame, Q_GOAL))
    s_star, _ = _features(robot.frame_pose(frame, Q_GOAL), P_w)
    data = robot.model.createData()

    def inertia(q: np.ndarray) -> np.ndarray:
        M = pin.crba(robot.model, data, q)
        return np.triu(M) + np.triu(M, 1).T

    # ours: gains from the inertia and the task Jacobian at the start (gains_from_inertia)
    _, L0 = _features(robot.frame_pose(frame, q_start), P_w)
    k_P, K_v = gains_from_inertia(inertia(q_start), task_jacobian(
        L0, robot.frame_jacobian(frame, q_start, "local")), OMEGA_MAX, ZETA)
    ctrl = HybridVSController(HybridVSConfig(s_star, k_P, K_v, alpha=f_push * DMIN / k_P,
                                             dmin=DMIN, avoid_rows=avoid_rows))
    log: dict[str, list] = {k: [] for k in ("t", "err", "f1y", "V", "dist", "active", "q",
                                            "tau", "G")}

    def step(obs: Observation) -> StepResult:
        q, qd = obs.q["crs"], obs.qd["crs"]
        T_wc = robot.frame_pose(frame, q)
        s, L_s = _features(T_wc, P_w)
        J_g = robot.frame_jacobian(frame, q, "local")
        dist, grad = None, None
        if human_w is not None:
            d_w = T_wc[:3, 3] - human_w
            dist = float(np.linalg.norm(d_w))
            grad = distance_gradient(np.zeros(3), T_wc[:3, :3].T @ d_w / dist)
        G = robot.gravity_torques(q)
        tau, diag = ctrl.step(q, qd, s, L_s, J_g, G, inertia(q), dist, grad)
        for key, v in (("t", obs.t), ("err", np.linalg.norm(diag["e_s"])),
                       ("f1y", s_star[1] - s[1]), ("V", diag["V"]),
                       ("dist", np.inf if dist is None else dist), ("active", diag["active"]),
                       ("q", q), ("tau", tau), ("G", G)):
            log[key].append(v)
        return StepResult({"crs": tau})

    run_episode(Episode(scene, {"crs": TorqueDrive(robot)}, step, Columns(), duration), tmp,
                experiment="test", paper="pomares2011", config={"k_P": k_P}, seed=0)
    n_sat = load_run(tmp).trace["n_sat"].to_numpy()
    a = {k: np.asarray(v) for k, v in log.items()}
    return ServoRun(a["t"], a["err"], a["f1y"], a["V"], a["dist"], a["active"], a["q"],
                    a["tau"], a["G"], n_sat, k_P)


def test_closed_loop_converges_and_V_is_non_increasing(tmp_path: Path) -> None:
    """Experiment-1-like undisturbed run (W^+W = I, static scene): the image error
    decreases to a small fraction and V (10) is non-increasing (pomares2011 claim 2)."""
    run = _servo(tmp_path, Q_GOAL + DQ_START, 2.0)
    assert not run.active.any()
    assert (run.n_sat == 0).all()  # eq. (15) needs the torques as commanded
    assert run.err_px[0] > 150.0
    ratio = run.err_px[-1] / run.err_px[0]
    assert ratio < 0.05, ratio
    dV = np.diff(run.V)
    assert dV.max() <= 1e-6 * run.V[0], (dV.max(), run.V[0])
    assert run.V[-1] < 0.01 * run.V[0]
    print(f"error {run.err_px[0]:.1f} -> {run.err_px[-1]:.2f} px (ratio {ratio:.4f}); "
          f"V {run.V[0]:.4g} -> {run.V[-1]:.3g} J; max dV {dV.max():.3g} J "
          f"({dV.max() / run.V[0]:.2g} V0); k_P {run.k_P:.3g}")


def test_gravity_compensation_alone_holds_the_robot_at_the_goal(tmp_path: Path) -> None:
    """s = s*, qd = 0: (5) reduces to tau = G(q) and the robot stays still."""
    run = _servo(tmp_path, Q_GOAL, 0.5)
    np.testing.assert_allclose(run.tau[0], run.G[0], atol=1e-9)
    drift = np.abs(run.q - Q_GOAL).max()
    assert drift < 1e-6, drift
    assert run.err_px.max() < 1e-3


@pytest.mark.parametrize("avoid_rows", [(1,), None])
def test_secondary_task_needs_the_reduced_W_to_push_the_camera_away(
        tmp_path: Path, avoid_rows: tuple[int, ...] | None) -> None:
    """A static point "human" 0.2 m (< dmin) beside the camera at the goal. With the reduced
    W (f1y alone, experiment 2) the secondary task moves the camera away; with all 8 rows
    (rank 6, W^+W = I) its term is projected out and the robot stays at the goal."""
    with World(WorldConfig(1e-3, 1e-3)) as world:
        T_wc = Robot(world, crs_urdf_path(), CRS_JOINTS, CRS_LIMITS).frame_pose(
            "camera_optical", Q_GOAL)
    human_w = T_wc[:3, 3] + 0.2 * T_wc[:3, 0]  # along the camera's +x
    run = _servo(tmp_path, Q_GOAL, 1.0, human_w, avoid_rows)
    assert run.active[0] and (run.n_sat == 0).all()
    gain = run.dist[-1] - run.dist[0]
    print(f"avoid_rows {avoid_rows}: dist {run.dist[0]:.3f} -> {run.dist[-1]:.3f} m (min "
          f"{run.dist.min():.4f}); max |f1y* - f1y| {np.abs(run.f1y_err).max():.1f} px")
    if avoid_rows is None:
        assert abs(gain) < 1e-6 and np.abs(run.q - Q_GOAL).max() < 1e-6
    else:
        assert gain > 0.08, gain
        assert run.dist.min() >= run.dist[0] - 1e-6
