"""One thomas2024 run: the scene, the CBF-QP controller, and the shared episode runner.

``run(config, out_dir)`` is the one code path used by the CLI, the tests and the
benchmarks; the loop itself is :func:`repro.sim.episode.run_episode`.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from experiments.thomas2024 import scene as sc
from experiments.thomas2024.columns import declare_columns
from experiments.thomas2024.config import RING_MODELS, Thomas2024Config
from experiments.thomas2024.layout import (
    BOARD_RGBA,
    case3_hand,
    planes,
    start_view,
)
from repro.config import validate
from repro.control.cbf_qp import CBFQPController, Inequalities, cbf_inequalities, ibvs_objective
from repro.control.proximity_features import (
    NormalEstimator,
    NormalEstimatorConfig,
    ring_interaction_matrix,
)
from repro.errors import ConfigError, UnknownChoiceError
from repro.geometry import inv_T
from repro.sensors.camera import Camera, check_scene_colors, project_points
from repro.sensors.proximity import ProximityRing, RingReading, RingSensor, exclude_from_rays
from repro.sim.drives import VelocityDrive
from repro.sim.episode import CameraRig, Episode, Observation, StepResult, View, run_episode
from repro.sim.panda import PANDA_JOINTS, PANDA_LIMITS
from repro.sim.robot import Robot, solve_ik
from repro.sim.scene import Scene
from repro.sim.world import WorldConfig
from repro.vision.features import twist_transform
from repro.vision.ibvs import PointFeatureJacobian
from repro.vision.pose import point_depths

RING_NAMES = ("ring1", "ring2")
#: the link the camera is fixed to: eJ_e of eq. (7) is its Jacobian
CAMERA_LINK = sc.CAMERA_PARENT[0]
HAND_RGBA = (0.9, 0.75, 0.65, 1.0)  # ours: skin


#: The shortest board a case-1 layout may have [m] (ours: wider than a ToF sensor's spot)
MIN_BOARD_M = 0.01


def check_config(config: Thomas2024Config) -> None:
    """Reject a malformed config before anything runs (ranges, choices, lengths)."""
    validate(config)
    if len(config.ring_gains) != 2 or len(config.thresholds) != 2 or len(config.ring_models) != 2:
        raise ConfigError("ring_gains, thresholds and ring_models need one value per ring (2), "
                          f"got {config.ring_gains}, {config.thresholds}, {config.ring_models}")
    bad = [m for m in config.ring_models if m not in RING_MODELS]
    if bad:
        raise UnknownChoiceError("ring model", bad[0], RING_MODELS)
    hand = sc.SCENES[config.case].hand
    if hand is not None:
        spans = sorted((t0, t0 + d * config.case3_duration_scale)
                       for _, t0, d, _ in hand.approaches)
        clash = [(a, b) for a, b in zip(spans, spans[1:], strict=False) if b[0] < a[1]]
        if clash:
            raise ConfigError(f"case3_duration_scale = {config.case3_duration_scale:g}: the "
                              f"hand's approach at {clash[0][0][0]:g} s lasts until "
                              f"{clash[0][0][1]:.2f} s, after the next starts "
                              f"({clash[0][1][0]:g} s)")
    for side in ("right", "left"):
        length = getattr(config, f"case1_{side}_back") + config.case1_front
        if length < MIN_BOARD_M:
            raise ConfigError(f"case 1's {side} board spans {length:g} m along the corridor "
                              f"(case1_{side}_back + case1_front): at least {MIN_BOARD_M:g} m")
    if len(config.q0_deg) != 7:
        raise ConfigError(f"q0_deg needs 7 joint angles [deg], got {len(config.q0_deg)}")
    q0 = np.deg2rad(config.q0_deg)
    lo, hi = np.asarray(PANDA_LIMITS.q_min), np.asarray(PANDA_LIMITS.q_max)
    if np.any(q0 < lo) or np.any(q0 > hi):
        raise ConfigError(f"q0_deg {config.q0_deg} is outside the Panda's joint limits "
                          f"[{np.rad2deg(lo).round(1).tolist()}, {np.rad2deg(hi).round(1).tolist()}] deg")
    start = start_view(config)
    if start is None:
        return
    touching = {n: d for n, d in start.distances.items() if d <= 0.0}
    if touching:  # a swept layout through the start pose is not the paper's scene
        raise ConfigError(
            f"{config.case}: the start configuration touches "
            + ", ".join(f"{n} ({d * 100:.1f} cm)" for n, d in sorted(touching.items()))
            + ": the paper's robot starts free of the obstacles (Sec. V-A, Fig. 4a)")
    if start.hidden.any():  # ours: the paper's camera, not the exact projection, decides
        raise ConfigError(
            f"{config.case}: the camera does not find target dot(s) "
            f"{(np.flatnonzero(start.hidden) + 1).tolist()} at the start configuration "
            "though they lie inside the image (rendered frame: a board hides them): the "
            "paper's visual task uses all four points from t = 0 (Sec. V, Figs. 7b, 8b)")


class _RingStep(NamedTuple):
    """What a control step needs of ring ``k`` (made once by the controller)."""

    k: int
    L: np.ndarray | None  # its interaction matrix (6) when constant (the coarse model)
    V: np.ndarray  # jV_Nj (9)
    link: str  # the link its frame S_j is fixed to
    model: str
    radius: float  # [m]
    threshold: float  # delta* [m]
    gain: float  # lambda_j [1/s]
    rows: slice  # its rows of A and b


@dataclass
class StepOutput:
    """What one control step computed (for the trace)."""

    u: np.ndarray
    status: str
    e_4p: np.ndarray  # (8,) normalised; NaN when a dot is lost
    kappa: np.ndarray  # (36,) or zeros without proximity
    grad_L0: float
    iterations: int
    solve_s: float
    max_slack: float
    qp_status: str
    #: per ring, the (m, 3) normals the interaction matrix used (ring frame; NaN rows: the
    #: coarse model (6)), None for a ring on the coarse model
    normals: tuple[np.ndarray | None, ...] = ()


class Thomas2024Controller:
    """Features and ring readings -> CBF-QP (10) -> joint velocities (thomas2024 Sec. III).

    ``step`` is what ``make bench`` times; ``__call__`` adapts it to the episode runner.
    """

    def __init__(self, config: Thomas2024Config, robot: Robot, rings: list[ProximityRing],
                 estimators: list[NormalEstimator], s_star: np.ndarray,
                 Z_star: np.ndarray, target_points: np.ndarray) -> None:
        self.config, self.robot, self.rings, self.estimators = config, robot, rings, estimators
        self.s_star, self.Z_star, self.target_points = s_star, Z_star, target_points
        self.n = robot.n
        self.m = sum(r.spec.n_sensors for r in rings) if config.proximity else 0
        self.qp = CBFQPController(self.n, self.m, solver=config.qp_solver,
                                  max_iter=config.qp_max_iter)
        self.qd_max = np.asarray(PANDA_LIMITS.qd_max)
        # thomas2024 eqs. (7), (9): cV_e flange -> camera, jV_Nj ring link -> ring frame S_j.
        self.cV_e = twist_transform(inv_T(sc.T_FLANGE_CAMERA))
        self.ring_V = {name: twist_transform(inv_T(T)) for name, (_, T) in sc.RING_PARENTS.items()}
        self.dirs = [r.spec.directions() for r in rings]
        self._ring_L: list[np.ndarray | None] = []  # eq. (6) does not depend on the reading
        for k, ring in enumerate(rings):
            L = None
            if config.proximity and config.ring_models[k] == "coarse":
                L = ring_interaction_matrix(self.dirs[k], np.zeros(ring.spec.n_sensors),
                                            ring.spec.radius, "coarse")
            self._ring_L.append(L)
        # Per ring: the link its frame S_j is fixed to, and jV_Nj (eq. (9)).
        self._ring_links = [sc.RING_PARENTS[r.spec.name][0] for r in rings]
        self._ring_Vs = [self.ring_V[r.spec.name] for r in rings]
        #: the links whose Jacobian a step needs, each asked of pinocchio once per step (the
        #: flange carries both ring 2 and the camera)
        self._jac_links = tuple(dict.fromkeys([*(self._ring_links if config.proximity else []),
                                               CAMERA_LINK]))
        # Per ring, what a step needs of it, and its rows of A and b (in ring order)
        ends = np.cumsum([r.spec.n_sensors for r in rings]).tolist()
        self._ring_steps = [
            _RingStep(k, self._ring_L[k], self._ring_Vs[k], self._ring_links[k],
                      config.ring_models[k], ring.spec.radius, config.thresholds[k],
                      config.ring_gains[k], slice(end - ring.spec.n_sensors, end))
            for k, (ring, end) in enumerate(zip(rings, ends, strict=True))]
        self._feature_jacobian = PointFeatureJacobian(self.cV_e, len(target_points))
        self.prev_status = "solved"

    def step(self, q: np.ndarray, uv: np.ndarray, found: np.ndarray, Z_exact: np.ndarray,
             readings: list[RingReading]) -> StepOutput:
        """One control step: thomas2024 eqs. (7)-(10)."""
        cfg, n, m = self.config, self.n, self.m
        if np.count_nonzero(found) != np.size(found):  # a dot lost
            return StepOutput(np.zeros(n), "no_features", np.full(8, np.nan), np.zeros(m),
                              float("nan"), 0, 0.0, 0.0, "")
        x = sc.INTRINSICS.to_normalized(uv)
        e_4p = (x - self.s_star).ravel()
        # eJ_e of eq. (7) and J_Nj of eq. (9), one pinocchio call per link
        frame_jacobian, J = self.robot.frame_jacobian, {}
        for link in self._jac_links:
            J[link] = frame_jacobian(link, q)
        used: list[np.ndarray | None] = [None] * len(self.rings)
        if cfg.proximity:
            ineq = self._ring_rows(J, readings, used)
        else:
            ineq = Inequalities(np.empty((0, n)), np.empty(0))
        # Depths for L_x: PnP pose of the detected dots (render), exact geometry otherwise.
        Z = Z_exact if cfg.camera_mode == "exact" else point_depths(
            self.target_points, uv, sc.INTRINSICS.K(), self.Z_star)
        J_4p = self._feature_jacobian(x, Z, J[CAMERA_LINK])  # eq. (7)
        res = self.qp.step(ibvs_objective(J_4p, e_4p, cfg.lambda_4p, cfg.mu), ineq, self.qd_max)
        # (the slack is all zeros when the hard QP is solved)
        max_slack = float(res.slack.max()) if m and res.status != "solved" else 0.0
        return StepOutput(res.u, res.status, e_4p, res.kappa, res.grad_L0,
                          res.iterations, res.solve_time_s, max_slack, res.qp_status,
                          tuple(used))

    def _ring_rows(self, J: dict[str, np.ndarray], readings: list[RingReading],
                   used: list[np.ndarray | None]) -> Inequalities:
        """The CBF rows (9) of every ring, stacked in ring order: A (m, n), b (m,) [m/s].

        Each ring's rows are written into its rows of fresh arrays (the QP's: the caller may
        keep them); a ring whose rows do not fit there (:func:`cbf_inequalities`) gets
        arrays of its own, and the rings' rows are then concatenated (the QP rejects a
        wrong length). ``used[k]``: ring k's estimated normals (m_k, 3), if any.
        """
        A, b = np.empty((self.m, self.n)), np.empty(self.m)
        rows: list[Inequalities] = []
        in_place = True
        for rs, reading in zip(self._ring_steps, readings, strict=True):
            L, delta = rs.L, reading.delta
            if L is None:
                normals = (self.estimators[rs.k].normals() if rs.model != "coarse"
                           else None)
                used[rs.k] = normals
                L = ring_interaction_matrix(self.dirs[rs.k], delta, rs.radius, rs.model,
                                            normals)
            J_S = rs.V.dot(J[rs.link])  # (9): jV_Nj J_Nj
            b_k = b[rs.rows]
            rows.append(cbf_inequalities(L, J_S, delta, rs.threshold, rs.gain,
                                         (A[rs.rows], b_k)))
            in_place = in_place and rows[-1].b is b_k
        if in_place:
            return Inequalities(A, b)
        return Inequalities(np.concatenate([r.A for r in rows]),
                            np.concatenate([r.b for r in rows]))

    def normal_columns(self, out: StepOutput, readings: list[RingReading]
                       ) -> dict[str, float | int]:
        """Audit of the normal estimates (issue 17 item 6), rings that use them: cond(B),
        the fit's least extent, where each normal came from, its angle to the true one."""
        cols: dict[str, float | int] = {}
        for k, est in enumerate(self.estimators):
            if self.config.ring_models[k] == "coarse" or not self.config.proximity:
                continue
            used = out.normals[k] if k < len(out.normals) else None
            mS = self.rings[k].spec.n_sensors
            ang = np.full(mS, np.nan)
            true, T = readings[k].true_normal, est.T_world_ring
            if used is not None and true is not None and T is not None:
                with np.errstate(invalid="ignore"):
                    ang = np.degrees(np.arccos(np.clip(
                        np.einsum("ij,ij->i", used @ T[:3, :3].T, true), -1.0, 1.0)))
            for i in range(mS):
                pre = f"r{k + 1}_"
                cols[f"{pre}ncond{i + 1}"] = float(est.cond[i])
                cols[f"{pre}nspread{i + 1}"] = float(est.spread[i])
                cols[f"{pre}nsrc{i + 1}"] = int(est.source[i]) if used is not None else 0
                cols[f"{pre}nerr{i + 1}"] = float(ang[i])
        return cols

    def __call__(self, obs: Observation) -> StepResult:
        cfg, f = self.config, obs.features["camera"]
        out = self.step(obs.q["panda"], f.uv, f.found, f.Z_exact,
                        [obs.sensors[name] for name in RING_NAMES])
        events, stop = [], None
        if not f.found.all() and self.prev_status != "no_features":
            events.append(("feature_lost", f"dots not found (1-based): "
                           f"{(np.flatnonzero(~f.found) + 1).tolist()}; fallback u = 0"))
        if out.status != self.prev_status and out.status not in ("solved", "no_features"):
            events.append(("qp_" + out.status, f"hard QP {out.qp_status}; " + (
                f"slack-relaxed CBFs, max slack {out.max_slack:.3g} m/s"
                if out.status == "relaxed" else "fallback u = 0")))
        self.prev_status = out.status
        e_norm = float(np.linalg.norm(out.e_4p))
        if cfg.stop_conditions and f.found.all():  # Sec. III-C
            if e_norm <= cfg.eps_4p:
                stop = ("stop_e4p", f"||e_4p|| = {e_norm:.3g} <= eps_4p = {cfg.eps_4p}")
            elif out.status == "solved" and out.grad_L0 <= cfg.eps_qd:
                stop = ("stop_lagrangian", f"||grad L(0, kappa*)|| = {out.grad_L0:.3g} <= "
                        f"eps_qd = {cfg.eps_qd}")
        cols: dict[str, float | int | str | bool] = {"e_norm": e_norm, "n_found": int(f.found.sum())}
        for i in range(4):
            cols[f"e{i + 1}_u"] = out.e_4p[2 * i] * sc.INTRINSICS.fu
            cols[f"e{i + 1}_v"] = out.e_4p[2 * i + 1] * sc.INTRINSICS.fv
        kappa = out.kappa if out.kappa.size == 2 * sc.N_SENSORS else np.zeros(2 * sc.N_SENSORS)
        for i, kap in enumerate(kappa):
            cols[f"r{i // sc.N_SENSORS + 1}_kappa{i % sc.N_SENSORS + 1}"] = float(kap)
        cols.update(qp_status=out.status, qp_iter=out.iterations, qp_max_slack=out.max_slack,
                    qp_solve_s=out.solve_s, grad_L0=out.grad_L0)
        cols.update(self.normal_columns(out, [obs.sensors[name] for name in RING_NAMES]))
        return StepResult({"panda": out.u}, cols, events, stop,
                          fallback=out.status in ("failed", "no_features"))


def estimated_rings(config: Thomas2024Config) -> tuple[int, ...]:
    """1-based rings whose interaction matrix uses estimated normals (not model (6))."""
    if not config.proximity:
        return ()
    return tuple(k + 1 for k, m in enumerate(config.ring_models) if m != "coarse")


def build(config: Thomas2024Config, out_dir: Path) -> tuple[Episode, Thomas2024Controller]:
    """The scene, robot, sensors and controller of ``config.case``."""
    check_config(config)
    case = sc.SCENES[config.case]
    scene = Scene(WorldConfig(physics_dt=1.0 / config.physics_rate,
                              control_dt=1.0 / config.control_rate),
                  render=config.camera_mode == "render", run_dir=out_dir)
    with tempfile.TemporaryDirectory() as tmp:
        robot = scene.add_urdf("panda", sc.write_urdf(Path(tmp) / "panda.urdf"), PANDA_JOINTS,
                               PANDA_LIMITS)
    exclude_from_rays(scene.physics.client, robot.body)
    q_goal = np.deg2rad(case.q_goal_deg)
    T_goal_cam = robot.frame_pose("camera_optical", q_goal)
    T_ring2_goal = robot.frame_pose("ring2", q_goal)
    for pl in planes(config, T_ring2_goal):
        scene.add_box(pl.name, (*pl.size, pl.thickness), pl.T_world, BOARD_RGBA)
    movers = {}
    if case.hand is not None:
        hand = case3_hand(config, case.hand)
        scene.add_box("hand", hand.size, sc.PARKED_HAND, HAND_RGBA, moving=True)
        movers["hand"] = sc.hand_motion(hand, {n: robot.frame_pose(n, np.deg2rad(
            config.q0_deg)) for n in RING_NAMES})
    T_target = sc.target_pose(T_goal_cam, case.target_depth)
    scene.add_dot_target("target", case.target, T_target)
    scene.check_colors(check_scene_colors)
    q0 = np.deg2rad(config.q0_deg)
    if config.case == "parallel":  # ring 2 starts backed away from the goal along its axis
        q0 = solve_ik(robot, "ring2", T_ring2_goal @ sc.trans(0, 0, -sc.PARALLEL_RETREAT), q_goal)
    robot.reset(q0)
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(config.seed).spawn(2)]
    specs = sc.ring_specs(config.max_range, config.proximity_noise, config.tof_fov_deg)
    rings = [ProximityRing(s, r) for s, r in zip(specs, rngs, strict=True)]
    estimators = [NormalEstimator(s.directions(), s.radius, NormalEstimatorConfig(
        history=config.normal_history, neighbours=config.normal_neighbours,
        range_noise=s.noise_std)) for s in specs]
    sensors = [RingSensor(ring, robot, ring.spec.name, scene.physics.client, f"r{k + 1}_",
                          config.thresholds[k],
                          lambda T, r, est=est: est.update(T, r.delta, r.detected))
               for k, (ring, est) in enumerate(zip(rings, estimators, strict=True))]
    for s in sensors:
        parent, T = sc.RING_PARENTS[s.name]
        scene.add_mount(s.name, "panda", parent, T, "ring frame S_j: z along the ring axis")
        scene.add_sensor(s.name, s.describe())
    scene.add_mount("camera", "panda", "panda_link8", sc.T_FLANGE_CAMERA,
                    "camera optical frame (x right, y down, z forward) = URDF frame "
                    "camera_optical")
    rig = CameraRig("camera", "s", Camera(sc.INTRINSICS, mode=config.camera_mode), robot,
                    "camera_optical", np.eye(4), "target")
    uv_star, Z_star = project_points(sc.INTRINSICS, T_goal_cam, case.target.points_world(T_target))
    ctrl = Thomas2024Controller(config, robot, rings, estimators,
                                sc.INTRINSICS.to_normalized(uv_star), Z_star,
                                case.target.points_target)
    scene.extra.update(desired_features_px=uv_star, q_goal_deg=case.q_goal_deg)
    ep = Episode(scene, {"panda": VelocityDrive(robot)}, ctrl,
                 declare_columns(robot.n, config.proximity, estimated_rings(config)),
                 config.duration, cameras=[rig],
                 sensors=sensors, movers=movers, video=config.video,
                 view=View((0.35, 0.0, 0.5), 1.6, 50, -25))
    for s in sensors:
        s.declare(ep.columns)
    return ep, ctrl


def run(config: Thomas2024Config, out_dir: Path, experiment: str | None = None) -> Path:
    """Run one thomas2024 case and write its run files (see repro.sim.episode)."""
    ep = build(config, Path(out_dir))[0]  # build checks the config first (start clearance too)
    return run_episode(ep, Path(out_dir), paper="thomas2024", config=config, experiment=experiment)
