"""One thomas2024 run: scene -> control loop (sensors -> CBF-QP -> robot) -> trace files.

``run(config, out_dir)`` is the one code path used by the CLI, the tests and
the benchmarks.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pybullet as p

from experiments.thomas2024 import scene as sc
from experiments.thomas2024.config import RING_MODELS, Thomas2024Config
from repro.config import validate
from repro.control.cbf_qp import (
    CBFQPController,
    Inequalities,
    cbf_inequalities,
    ibvs_objective,
)
from repro.control.proximity_features import NormalEstimator, ring_interaction_matrix
from repro.errors import ConfigError, UnknownChoiceError
from repro.geometry import inv_T
from repro.runs.trace import TraceRecorder, add_vector
from repro.sensors.camera import Camera, spawn_dot_target
from repro.sensors.proximity import ProximityRing, RingReading, exclude_from_rays
from repro.sim.panda import PANDA_JOINTS, PANDA_LIMITS
from repro.sim.robot import Robot, solve_ik
from repro.sim.world import World, WorldConfig, pose_to_pb
from repro.vision.features import interaction_matrix_points, twist_transform

RING_NAMES = ("ring1", "ring2")


@dataclass
class Setup:
    """Live objects of a run (never used by figures or claims)."""

    world: World
    robot: Robot
    render: World | None
    rings: list[ProximityRing]
    estimators: list[NormalEstimator]
    camera: Camera
    scene: sc.Scene
    planes: tuple[sc.Plane, ...]
    obstacle_ids: dict[str, int]
    render_ids: dict[str, int]
    target_ids: list[int]
    T_world_target: np.ndarray
    s_star: np.ndarray  # (4, 2) desired normalised coordinates
    Z_star: np.ndarray  # (4,) desired depths [m]
    q_goal: np.ndarray
    ring_start_poses: dict[str, np.ndarray] = field(default_factory=dict)


def _pose_list(T: np.ndarray) -> dict[str, list[float]]:
    pos, quat = pose_to_pb(T)
    return {"position": pos, "quaternion_xyzw": quat}


def check_config(config: Thomas2024Config) -> None:
    """Reject a malformed config before anything runs (ranges, choices, lengths)."""
    validate(config)
    if len(config.ring_gains) != 2 or len(config.thresholds) != 2 or len(config.ring_models) != 2:
        raise ConfigError("ring_gains, thresholds and ring_models need one value per ring (2), "
                          f"got {config.ring_gains}, {config.thresholds}, {config.ring_models}")
    bad = [m for m in config.ring_models if m not in RING_MODELS]
    if bad:
        raise UnknownChoiceError("ring model", bad[0], RING_MODELS)
    if len(config.q0_deg) != 7:
        raise ConfigError(f"q0_deg needs 7 joint angles [deg], got {len(config.q0_deg)}")
    q0 = np.deg2rad(config.q0_deg)
    lo, hi = np.asarray(PANDA_LIMITS.q_min), np.asarray(PANDA_LIMITS.q_max)
    if np.any(q0 < lo) or np.any(q0 > hi):
        raise ConfigError(f"q0_deg {config.q0_deg} is outside the Panda's joint limits "
                          f"[{np.rad2deg(lo).round(1).tolist()}, {np.rad2deg(hi).round(1).tolist()}] deg")


def build(config: Thomas2024Config, out_dir: Path) -> Setup:
    """Create the world, robot, sensors and obstacles of ``config.case``."""
    check_config(config)
    scene = sc.SCENES[config.case]
    wcfg = WorldConfig(physics_dt=1.0 / config.physics_rate, control_dt=1.0 / config.control_rate)
    world = World(wcfg)
    urdf = sc.write_urdf(out_dir / "panda_rings.urdf")
    robot = Robot(world, urdf, PANDA_JOINTS, PANDA_LIMITS)
    exclude_from_rays(world.client, robot.body)

    q_goal = np.deg2rad(scene.q_goal_deg)
    T_goal_cam = robot.frame_pose("camera_optical", q_goal)
    T_world_target = sc.target_pose(T_goal_cam, scene.target_depth)
    planes = scene.planes
    if config.case == "parallel":
        planes = sc.parallel_planes(robot.frame_pose("ring2", q_goal), config.thresholds[1])
    elif config.case == "case1":
        planes = sc.case1_planes(robot.frame_pose("ring2", q_goal))
    elif config.case == "case2":
        planes = sc.case2_planes(robot.frame_pose("ring2", q_goal), config.thresholds[1])

    ss = np.random.SeedSequence(config.seed)
    rngs = [np.random.default_rng(s) for s in ss.spawn(2)]
    specs = sc.ring_specs(config.max_range, config.proximity_noise)
    rings = [ProximityRing(s, r) for s, r in zip(specs, rngs, strict=True)]
    estimators = [NormalEstimator(s.directions(), s.radius) for s in specs]

    obstacle_ids: dict[str, int] = {}
    for pl in planes:
        obstacle_ids[pl.name] = world.add_box(pl.half_extents(), pl.T_world, (0.8, 0.7, 0.55, 1.0))
    if scene.hand is not None:
        obstacle_ids["hand"] = world.add_box(tuple(s / 2 for s in scene.hand.size), sc.PARKED_HAND,
                                             (0.9, 0.75, 0.65, 1.0))

    camera = Camera(sc.INTRINSICS, T_link_camera=np.eye(4), mode=config.camera_mode)
    # The eye-in-hand camera renders in a mirror client that holds what it can see: the
    # target and the obstacles, not the robot carrying it (its meshes would cost ~20 ms
    # a frame and are behind the camera).
    render = None
    render_ids: dict[str, int] = {}
    target_ids: list[int] = []
    if config.camera_mode == "render":
        render = World(WorldConfig(physics_dt=wcfg.physics_dt, control_dt=wcfg.control_dt))
        target_ids = spawn_dot_target(render.client, scene.target, T_world_target)
        for pl in planes:
            render_ids[pl.name] = render.add_box(pl.half_extents(), pl.T_world,
                                                 (0.8, 0.7, 0.55, 1.0), collision=False)
        if scene.hand is not None:
            render_ids["hand"] = render.add_box(tuple(s / 2 for s in scene.hand.size),
                                                sc.PARKED_HAND, (0.9, 0.75, 0.65, 1.0),
                                                collision=False)

    from repro.sensors.camera import project_points

    uv_star, Z_star = project_points(sc.INTRINSICS, T_goal_cam,
                                     scene.target.points_world(T_world_target))
    s_star = sc.INTRINSICS.to_normalized(uv_star)

    q0 = np.deg2rad(config.q0_deg)
    if config.case == "parallel":
        # Start with ring 2 backed away from the goal along its axis, so that it moves
        # between the boards towards a goal at the threshold distance from both.
        T_start = robot.frame_pose("ring2", q_goal) @ sc.trans(0.0, 0.0, -sc.PARALLEL_RETREAT)
        q0 = solve_ik(robot, "ring2", T_start, q_goal)
    robot.reset(q0)
    setup = Setup(world, robot, render, rings, estimators, camera, scene, planes, obstacle_ids,
                  render_ids, target_ids, T_world_target, s_star, Z_star, q_goal)
    setup.ring_start_poses = {n: robot.frame_pose(n, q0) for n in RING_NAMES}
    return setup


def scene_description(setup: Setup, config: Thomas2024Config, urdf: Path) -> dict:
    """Everything needed to replay and audit the run (scene.json)."""
    r = setup.robot
    bodies = [{
        "name": "panda", "kind": "urdf", "urdf": urdf.name,
        "base_pose": _pose_list(r.T_world_base), "joints": list(r.joint_names),
        "joint_limits": {"q_min": r.limits.q_min, "q_max": r.limits.q_max,
                         "qd_max": r.limits.qd_max, "tau_max": r.limits.tau_max},
        "note": "joint positions over time are the q1..q7 columns of trace.csv",
    }]
    for pl in setup.planes:
        bodies.append({"name": pl.name, "kind": "box", "half_extents": pl.half_extents(),
                       "pose": _pose_list(pl.T_world), "static": True})
    if setup.scene.hand is not None:
        bodies.append({"name": "hand", "kind": "box",
                       "half_extents": [s / 2 for s in setup.scene.hand.size],
                       "static": False,
                       "note": "pose over time: hand_x, hand_y, hand_z, hand_qx..hand_qw columns"})
    tgt = setup.scene.target
    bodies.append({"name": "target", "kind": "dot_target", "pose": _pose_list(setup.T_world_target),
                   "points_target": tgt.points_target, "points_world":
                   tgt.points_world(setup.T_world_target), "colors": tgt.colors,
                   "dot_radius": tgt.dot_radius, "plate_size": tgt.plate_size,
                   "collision": False})
    intr = sc.INTRINSICS
    rings = []
    for ring in setup.rings:
        parent, T = sc.RING_PARENTS[ring.spec.name]
        rings.append({"name": ring.spec.name, "parent_link": parent, "T_parent_ring": T,
                      "radius": ring.spec.radius, "n_sensors": ring.spec.n_sensors,
                      "max_range": ring.spec.max_range, "noise_std": ring.spec.noise_std,
                      "sensor_axes_ring_frame": ring.spec.directions()})
    cam_parent, T_cam = sc.CAMERA_PARENT
    return {
        "bodies": bodies,
        "proximity_rings": rings,
        "camera": {"frame": "camera_optical", "parent_link": cam_parent,
                   "T_parent_camera": T_cam @ np.array([[1, 0, 0, 0], [0, 1, 0, 0],
                                                        [0, 0, 1, sc.CAMERA_BODY[2] / 2],
                                                        [0, 0, 0, 1]]),
                   "intrinsics": {"width": intr.width, "height": intr.height, "fu": intr.fu,
                                  "fv": intr.fv, "u0": intr.u0, "v0": intr.v0},
                   "mode": config.camera_mode,
                   "convention": "x right, y down, z forward; pixel (0,0) = centre of the "
                                 "top-left pixel"},
        "desired_features_px": sc.INTRINSICS.to_pixels(setup.s_star),
        "q_goal_deg": setup.scene.q_goal_deg,
        "world": {"gravity": setup.world.config.gravity,
                  "physics_dt": setup.world.config.physics_dt,
                  "control_dt": setup.world.config.control_dt},
    }


def _depths(setup: Setup, uv: np.ndarray, Z_exact: np.ndarray) -> np.ndarray:
    """Point depths for the interaction matrix: from a PnP pose of the detected dots
    (render mode; cv2.SOLVEPNP_IPPE for 4 coplanar points), exact geometry otherwise."""
    if setup.camera.mode == "exact":
        return Z_exact
    K = sc.INTRINSICS.K()
    ok, rvec, tvec = cv2.solvePnP(setup.scene.target.points_target, uv.astype(np.float64), K,
                                  None, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return setup.Z_star
    R, _ = cv2.Rodrigues(rvec)
    P_c = setup.scene.target.points_target @ R.T + tvec.ravel()
    return P_c[:, 2]


def _move_hand(setup: Setup, t: float) -> np.ndarray:
    hand = setup.scene.hand
    assert hand is not None
    radii = {r.spec.name: r.spec.radius for r in setup.rings}
    T = sc.hand_pose(hand, t, setup.ring_start_poses, radii)
    T = sc.PARKED_HAND if T is None else T
    pos, quat = pose_to_pb(T)
    p.resetBasePositionAndOrientation(setup.obstacle_ids["hand"], pos, quat,
                                      physicsClientId=setup.world.client)
    if setup.render is not None:
        p.resetBasePositionAndOrientation(setup.render_ids["hand"], pos, quat,
                                          physicsClientId=setup.render.client)
    return T


def run(config: Thomas2024Config, out_dir: Path) -> Path:
    """Run one thomas2024 case and write trace.csv, events.csv, manifest.json, scene.json."""
    check_config(config)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with TraceRecorder(out_dir, experiment=out_dir.name.split("__")[0], paper="thomas2024",
                       config=config,
                       seed=config.seed) as rec:
        setup = build(config, out_dir)
        try:
            rec.set_scene(scene_description(setup, config, out_dir / "panda_rings.urdf"))
            status, reason = _loop(setup, config, rec, out_dir)
        finally:
            setup.world.close()
            if setup.render is not None:
                setup.render.close()
        rec.close(status, reason)
    return out_dir


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


class Thomas2024Controller:
    """Sensors -> features -> CBF-QP (10) for one robot state.

    ``step`` takes the measurements (image points, ring readings) and returns the
    joint-velocity command; it is what ``make bench`` times.
    """

    def __init__(self, setup: Setup, config: Thomas2024Config) -> None:
        self.setup, self.config = setup, config
        self.n = setup.robot.n
        self.m = sum(r.spec.n_sensors for r in setup.rings) if config.proximity else 0
        self.qp = CBFQPController(self.n, self.m, solver=config.qp_solver,
                                  max_iter=config.qp_max_iter)
        self.qd_max = np.asarray(PANDA_LIMITS.qd_max)
        # Twist transformations (thomas2024 eq. (7), (9)): cV_e from the flange to the
        # camera, jV_Nj from the ring's link to the ring frame S_j.
        self.cV_e = twist_transform(inv_T(sc.CAMERA_PARENT[1] @ _optical_offset()))
        self.ring_V = {name: twist_transform(inv_T(T)) for name, (_, T) in sc.RING_PARENTS.items()}
        self.dirs = [r.spec.directions() for r in setup.rings]
        # Constant per-step data, looked up once: ring parent links, the coarse model's
        # interaction matrices (eq. (6) does not depend on the reading), pixel -> normalised.
        self._ring_parents = [sc.RING_PARENTS[r.spec.name][0] for r in setup.rings]
        self._ring_L: list[np.ndarray | None] = []
        for k, ring in enumerate(setup.rings):
            L = None
            if config.proximity and config.ring_models[k] == "coarse":
                L = ring_interaction_matrix(self.dirs[k], np.zeros(ring.spec.n_sensors),
                                            ring.spec.radius, "coarse")
                L.flags.writeable = False
            self._ring_L.append(L)
        self._uv0 = np.array([sc.INTRINSICS.u0, sc.INTRINSICS.v0])
        self._f_uv = np.array([sc.INTRINSICS.fu, sc.INTRINSICS.fv])

    def read_rings(self, q: np.ndarray) -> list[RingReading]:
        """Ray-cast every ring at configuration ``q`` and update the normal estimators."""
        out = []
        for ring, est in zip(self.setup.rings, self.setup.estimators, strict=True):
            T_wr = self.setup.robot.frame_pose(ring.spec.name, q)
            reading = ring.read(self.setup.world.client, T_wr)
            est.update(T_wr, reading.delta, reading.detected)
            out.append(reading)
        return out

    def step(self, q: np.ndarray, uv: np.ndarray, found: np.ndarray, Z_exact: np.ndarray,
             readings: list[RingReading]) -> StepOutput:
        """One control step: thomas2024 eqs. (7)-(10)."""
        setup, cfg, robot = self.setup, self.config, self.setup.robot
        n, m = self.n, self.m
        if not np.asarray(found).all():
            return StepOutput(np.zeros(n), "no_features", np.full(8, np.nan), np.zeros(m),
                              float("nan"), 0, 0.0, 0.0, "")
        x = (np.asarray(uv, dtype=float) - self._uv0) / self._f_uv  # INTRINSICS.to_normalized
        e_4p = (x - setup.s_star).ravel()
        jacobians: dict[str, np.ndarray] = {}  # J_N (local) per link, each computed once

        def jacobian(link: str) -> np.ndarray:
            J = jacobians.get(link)
            if J is None:
                J = jacobians[link] = robot.frame_jacobian(link, q, "local")
            return J

        A = np.empty((m, n))
        b = np.empty(m)
        if cfg.proximity:
            row = 0
            for k, (ring, reading) in enumerate(zip(setup.rings, readings, strict=True)):
                name = ring.spec.name
                L = self._ring_L[k]
                if L is None:
                    model = cfg.ring_models[k]
                    normals = setup.estimators[k].normals() if model != "coarse" else None
                    L = ring_interaction_matrix(self.dirs[k], reading.delta, ring.spec.radius,
                                                model, normals)
                J_S = self.ring_V[name] @ jacobian(self._ring_parents[k])  # jV_Nj J_Nj
                ineq = cbf_inequalities(L, J_S, reading.delta, cfg.thresholds[k],
                                        cfg.ring_gains[k])
                A[row:row + ineq.A.shape[0]] = ineq.A
                b[row:row + ineq.A.shape[0]] = ineq.b
                row += ineq.A.shape[0]
            if row != m:
                raise ValueError(f"the rings gave {row} CBF rows, expected {m}")
        Z = _depths(setup, uv, Z_exact)
        L_x = interaction_matrix_points(x, Z)
        J_4p = L_x @ self.cV_e @ jacobian("panda_link8")  # eq. (7)
        obj = ibvs_objective(J_4p, e_4p, cfg.lambda_4p, cfg.mu)
        res = self.qp.step(obj, Inequalities(A, b), self.qd_max)
        return StepOutput(res.u, res.status, e_4p, res.kappa, res.grad_L0,
                          res.solution.iterations, res.solution.solve_time_s,
                          float(res.slack.max()) if m else 0.0, res.qp_status)


def _loop(setup: Setup, config: Thomas2024Config, rec: TraceRecorder,
          out_dir: Path) -> tuple[str, str]:
    robot, world = setup.robot, setup.world
    intr = sc.INTRINSICS
    n = robot.n
    ctrl = Thomas2024Controller(setup, config)
    n_kappa = sum(r.spec.n_sensors for r in setup.rings)
    dt = world.config.control_dt
    n_steps = int(round(config.duration / dt))
    frames: list[np.ndarray] = []
    stop_reason = ""
    t_ctrl_total = 0.0
    lost_before = False
    prev_status = "solved"
    step = 0
    for step in range(n_steps + 1):
        t = step * dt
        q, qd = robot.q(), robot.qd()
        row: dict[str, float | int | str | bool] = {"t": t, "step": step}
        add_vector(row, "q", q)
        add_vector(row, "qd", qd)
        T_hand = _move_hand(setup, t) if setup.scene.hand is not None else None
        # --- sensors
        tic = time.perf_counter()
        T_wc = robot.frame_pose("camera_optical", q)
        uv, found, Z_exact = setup.camera.measure(
            setup.render.client if setup.render is not None else world.client,
            T_wc, setup.scene.target, setup.T_world_target)
        t_render = time.perf_counter() - tic
        readings = ctrl.read_rings(q)
        for ring, reading in zip(setup.rings, readings, strict=True):
            if np.any(reading.invalid):
                rec.event(t, step, "sensor_nan", f"{ring.spec.name} sensors "
                          f"{(np.flatnonzero(reading.invalid) + 1).tolist()} held last value")
        all_found = bool(np.all(found))
        if not all_found and not lost_before:
            rec.event(t, step, "feature_lost",
                      f"dots not found: {np.flatnonzero(~found).tolist()}; fallback u = 0")
        lost_before = not all_found
        # --- controller
        tic = time.perf_counter()
        out = ctrl.step(q, uv, found, Z_exact, readings)
        t_ctrl = time.perf_counter() - tic
        t_ctrl_total += t_ctrl
        if out.status != prev_status and out.status not in ("solved", "no_features"):
            rec.event(t, step, "qp_" + out.status,
                      f"hard QP {out.qp_status}; " + ("slack-relaxed CBFs, max slack "
                      f"{out.max_slack:.3g} m/s" if out.status == "relaxed" else "fallback u = 0"))
        prev_status = out.status
        u, e_4p = out.u, out.e_4p
        e_norm = float(np.linalg.norm(e_4p)) if all_found else float("nan")
        # --- log
        for i in range(n):
            row[f"u{i + 1}"] = u[i]
        for i in range(4):
            row[f"e{i + 1}_u"] = e_4p[2 * i] * intr.fu
            row[f"e{i + 1}_v"] = e_4p[2 * i + 1] * intr.fv
        for i in range(4):
            row[f"s{i + 1}_u"] = uv[i, 0]
            row[f"s{i + 1}_v"] = uv[i, 1]
        row["e_norm"] = e_norm
        row["n_found"] = int(np.sum(found))
        for k, (ring, reading) in enumerate(zip(setup.rings, readings, strict=True)):
            for i in range(ring.spec.n_sensors):
                row[f"r{k + 1}_d{i + 1}"] = reading.delta[i]
            for i in range(ring.spec.n_sensors):
                row[f"r{k + 1}_cbf{i + 1}"] = reading.delta[i] - config.thresholds[k]
        kap = out.kappa if out.kappa.size == n_kappa else np.zeros(n_kappa)
        for k, ring in enumerate(setup.rings):
            off = k * ring.spec.n_sensors
            for i in range(ring.spec.n_sensors):
                row[f"r{k + 1}_kappa{i + 1}"] = kap[off + i]
        row["qp_status"] = out.status
        row["qp_iter"] = out.iterations
        row["qp_max_slack"] = out.max_slack
        row["qp_solve_s"] = out.solve_s
        row["grad_L0"] = out.grad_L0
        row["ctrl_s"] = t_ctrl
        row["render_s"] = t_render
        dists = {name: robot.min_distance(bid) for name, bid in setup.obstacle_ids.items()}
        for name, d in dists.items():
            row[f"dist_{name}"] = d
        row["dist_min"] = min(dists.values()) if dists else float("nan")
        if T_hand is not None:
            pos, quat = pose_to_pb(T_hand)
            for a, v in zip(("x", "y", "z"), pos, strict=True):
                row[f"hand_{a}"] = v
            for a, v in zip(("qx", "qy", "qz", "qw"), quat, strict=True):
                row[f"hand_{a}"] = v
        for name, d in dists.items():
            if d <= 0.0 and not rec.summary.get(f"collided_{name}"):
                rec.summary[f"collided_{name}"] = True
                rec.event(t, step, "collision", f"robot touches {name} (distance {d:.4f} m)")
        rec.record(row)
        if config.video and step % 3 == 0:
            frames.append(_third_person_frame(setup))
        # --- stopping conditions (Sec. III-C)
        if config.stop_conditions and all_found:
            if e_norm <= config.eps_4p:
                stop_reason = f"||e_4p|| = {e_norm:.3g} <= eps_4p = {config.eps_4p}"
                rec.event(t, step, "stop_e4p", stop_reason)
                break
            if out.status == "solved" and out.grad_L0 <= config.eps_qd:
                stop_reason = (f"||grad L(0, kappa*)|| = {out.grad_L0:.3g} <= eps_qd = "
                               f"{config.eps_qd}")
                rec.event(t, step, "stop_lagrangian", stop_reason)
                break
        robot.set_velocity_command(u)
        world.step_control()
    rec.summary["n_steps"] = step + 1
    rec.summary["sim_time_s"] = step * dt
    rec.summary["mean_control_s"] = t_ctrl_total / (step + 1)
    rec.summary["stop_reason"] = stop_reason or "duration reached"
    if frames:
        import imageio.v2 as imageio

        imageio.mimsave(out_dir / "video.gif", frames, duration=3 * dt)
    return "completed", stop_reason or "duration reached"


def _optical_offset() -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = sc.CAMERA_BODY[2] / 2
    return T


def _third_person_frame(setup: Setup) -> np.ndarray:
    """A 320x240 view of the whole scene for --video (TinyRenderer, ~50 ms)."""
    view = p.computeViewMatrixFromYawPitchRoll([0.35, 0.0, 0.5], 1.6, 50, -25, 0, 2)
    proj = p.computeProjectionMatrixFOV(55, 320 / 240, 0.05, 5.0)
    img = p.getCameraImage(320, 240, view, proj, renderer=p.ER_TINY_RENDERER,
                           physicsClientId=setup.world.client)
    return np.reshape(np.asarray(img[2], dtype=np.uint8), (240, 320, 4))[:, :, :3]
