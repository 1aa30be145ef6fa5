"""One chan2011 run: scene -> control loop (camera -> NMPC (+ DCC) or IBVS -> quintic
references -> joint PD at 1 kHz) -> trace files. ``run(config, out_dir)`` is the one code
path used by the CLI, the tests and the benchmarks.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as p

from experiments.chan2011 import scene as sc
from experiments.chan2011.config import Chan2011Config
from repro.config import validate
from repro.control.interpolation import quintic
from repro.control.nmpc import CameraModel, NMPCConfig, NMPCSolution, VisualNMPC
from repro.errors import ConfigError, ReproError
from repro.geometry import inv_T
from repro.planning.dcc import CollisionModel, certify_segment, check_segment, free_box
from repro.runs.trace import TraceRecorder, add_vector
from repro.sensors.camera import Camera, project_points, render_rgb, spawn_dot_target
from repro.sim.casadi_kinematics import frame_pose_casadi
from repro.sim.crs_a465 import (
    CRS_JOINTS,
    CRS_LIMITS,
    T_FLANGE_CAMERA,
    crs_urdf_path,
    velocity_limits,
)
from repro.sim.robot import Robot, solve_ik
from repro.sim.world import World, WorldConfig, pose_to_pb
from repro.vision.features import interaction_matrix_points, twist_transform

N = sc.N_POINTS


@dataclass
class Setup:
    """Live objects of a run (never used by figures or claims)."""

    world: World
    robot: Robot
    render: World | None
    camera: Camera
    setting: sc.Setting
    obstacle_ids: dict[str, int]
    cam_model: CameraModel
    nmpc: VisualNMPC | None
    dcc: CollisionModel | None
    p_d: np.ndarray  # (2N,) desired pixels (the reference image) [px]
    q_goal: np.ndarray
    qd_max: np.ndarray
    urdf: Path


def _add_conrod(client: int, T_world_object: np.ndarray, collision: bool) -> list[int]:
    """The conrod's parts (boxes/cylinders, grey) at ``T_world_object``."""
    ids = []
    for shape, size, centre in sc.CONROD_PARTS:
        T = T_world_object @ np.array([[1, 0, 0, centre[0]], [0, 1, 0, centre[1]],
                                       [0, 0, 1, centre[2]], [0, 0, 0, 1.0]])
        pos, quat = pose_to_pb(T)
        if shape == "cylinder":
            vis = p.createVisualShape(p.GEOM_CYLINDER, radius=size[0], length=size[1],
                                      rgbaColor=[0.45, 0.45, 0.5, 1], physicsClientId=client)
            col = (p.createCollisionShape(p.GEOM_CYLINDER, radius=size[0], height=size[1],
                                          physicsClientId=client) if collision else -1)
        else:
            half = [s / 2 for s in size]
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half,
                                      rgbaColor=[0.45, 0.45, 0.5, 1], physicsClientId=client)
            col = (p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
                   if collision else -1)
        ids.append(p.createMultiBody(0.0, col, vis, pos, quat, physicsClientId=client))
    return ids


def check_config(config: Chan2011Config) -> None:
    """Reject a malformed config before anything runs."""
    validate(config)
    steps = config.dt * config.physics_rate
    if abs(steps - round(steps)) > 1e-6:
        raise ConfigError(f"dt = {config.dt} s is not a whole number of physics steps at "
                          f"{config.physics_rate} Hz")
    if config.dcc and not sc.SETTINGS[config.setting].obstacles:
        raise ConfigError(f"dcc=True needs obstacles; setting {config.setting!r} has none")


def _goal_configuration(robot: Robot, setting: sc.Setting) -> np.ndarray:
    """An IK solution for the goal flange pose (seeded, deterministic)."""
    T_goal = sc.goal_flange_pose(setting)
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(CRS_LIMITS.q_min), np.asarray(CRS_LIMITS.q_max)
    for _ in range(200):
        try:
            return solve_ik(robot, "flange", T_goal, rng.uniform(0.9 * lo, 0.9 * hi), 300)
        except ReproError:
            continue
    raise ReproError(f"no IK solution for the goal flange pose {T_goal[:3, 3]}")


def true_camera_pose(robot: Robot, q: np.ndarray) -> np.ndarray:
    """T_world_camera of the simulated (real) camera: eT_c with our mounting error."""
    return robot.frame_pose("flange", q) @ T_FLANGE_CAMERA @ sc.T_MOUNT_ERROR


def build(config: Chan2011Config, out_dir: Path) -> Setup:
    check_config(config)
    setting = sc.SETTINGS[config.setting]
    world = World(WorldConfig(physics_dt=1.0 / config.physics_rate, control_dt=config.dt,
                              solver_iterations=50))
    urdf = out_dir / "crs_a465.urdf"
    shutil.copyfile(crs_urdf_path(), urdf)
    robot = Robot(world, urdf, CRS_JOINTS, CRS_LIMITS)
    obstacle_ids = {}
    for box in setting.obstacles:
        obstacle_ids[box.name] = world.add_box(tuple(s / 2 for s in box.size), box.T_world,
                                               (0.7, 0.55, 0.35, 1.0))
    conrod_ids = _add_conrod(world.client, setting.T_object_actual, collision=True)
    render = None
    if config.camera_mode == "render":
        render = World(WorldConfig(physics_dt=world.config.physics_dt, control_dt=config.dt))
        for box in setting.obstacles:
            render.add_box(tuple(s / 2 for s in box.size), box.T_world, (0.7, 0.55, 0.35, 1.0),
                           collision=False)
        _add_conrod(render.client, setting.T_object_actual, collision=False)
        spawn_dot_target(render.client, sc.CONROD, setting.T_object_actual)
    spawn_dot_target(world.client, sc.CONROD, setting.T_object_actual)  # for scene snapshots
    obstacle_ids["conrod"] = conrod_ids[0]
    camera = Camera(sc.TRUE_INTRINSICS, mode=config.camera_mode)
    cam_model = CameraModel(**sc.TABLE_I)
    qd_max = velocity_limits(config.velocity_fraction)
    q_goal = _goal_configuration(robot, setting)
    # The reference image: what the real camera sees at the goal (Fig. 2 / Fig. 3 'x').
    T_goal_cam = true_camera_pose(robot, q_goal)
    if render is not None:
        uv_d, found_d, _ = camera.measure(render.client, T_goal_cam, sc.CONROD,
                                          setting.T_object_actual)
        if not np.all(found_d):
            raise ReproError("the reference image does not show every feature point")
    else:
        uv_d, _ = project_points(sc.TRUE_INTRINSICS, T_goal_cam,
                                 sc.CONROD.points_world(setting.T_object_actual))
    nmpc = None
    if config.controller == "nmpc":
        model = pin.buildModelFromUrdf(str(urdf))
        fk = frame_pose_casadi(model, "flange", CRS_JOINTS, T_frame_child=T_FLANGE_CAMERA)
        nmpc = VisualNMPC(fk, cam_model, N, CRS_LIMITS.q_min, CRS_LIMITS.q_max, qd_max,
                          NMPCConfig(Np=config.Np, dt=config.dt, Q_weight=config.Q_weight,
                                     W_weight=config.W_weight, solver=config.nlp_solver,
                                     qpsol=config.qpsol, max_iter=config.nlp_max_iter))
    dcc = CollisionModel(urdf, CRS_JOINTS, setting.obstacles) if config.dcc else None
    robot.reset(np.deg2rad(setting.q0_deg))
    return Setup(world, robot, render, camera, setting, obstacle_ids, cam_model, nmpc, dcc,
                 uv_d.ravel(), q_goal, qd_max, urdf)


def _pose(T: np.ndarray) -> dict[str, list[float]]:
    pos, quat = pose_to_pb(T)
    return {"position": pos, "quaternion_xyzw": quat}


def scene_description(setup: Setup, config: Chan2011Config) -> dict:
    s = setup.setting
    return {
        "bodies": [
            {"name": "crs_a465", "kind": "urdf", "urdf": setup.urdf.name,
             "base_pose": _pose(np.eye(4)), "joints": list(CRS_JOINTS),
             "note": "joint positions over time: q1..q6 columns of trace.csv"},
            *({"name": b.name, "kind": "box", "size": b.size, "pose": _pose(b.T_world)}
              for b in s.obstacles),
            {"name": "conrod", "kind": "compound", "pose": _pose(s.T_object_actual),
             "parts": [{"shape": sh, "size": sz, "centre": c} for sh, sz, c in sc.CONROD_PARTS]},
        ],
        "target": {"points_object": sc.CONROD_POINTS, "colors": sc.CONROD.colors,
                   "dot_radius": sc.CONROD.dot_radius,
                   "T_base_object_actual": s.T_object_actual,
                   "T_base_object_estimate": s.T_object_estimate},
        "camera_true": {"intrinsics": {"width": sc.IMAGE_W, "height": sc.IMAGE_H,
                                       "fu": sc.TRUE_INTRINSICS.fu, "fv": sc.TRUE_INTRINSICS.fv,
                                       "u0": sc.TRUE_INTRINSICS.u0, "v0": sc.TRUE_INTRINSICS.v0},
                        "T_flange_camera": T_FLANGE_CAMERA @ sc.T_MOUNT_ERROR},
        "camera_controller": {"table_I": sc.TABLE_I, "T_flange_camera": T_FLANGE_CAMERA},
        "desired_pixels": setup.p_d.reshape(N, 2),
        "q_goal_deg": np.rad2deg(setup.q_goal),
        "q0_deg": s.q0_deg,
        "joint_limits": {"q_min": CRS_LIMITS.q_min, "q_max": CRS_LIMITS.q_max,
                         "qd_max_used": setup.qd_max},
        "dcc_radii": setup.dcc.radii() if setup.dcc is not None else None,
        "world": {"physics_dt": setup.world.config.physics_dt, "control_dt": config.dt},
    }


def _ibvs(setup: Setup, config: Chan2011Config, q: np.ndarray, p_k: np.ndarray) -> np.ndarray:
    """Classical IBVS (Chaumette & Hutchinson 2006) with the controller's camera model:
    v_c = -lambda L^+ e, qdot = J_c^+ v_c; depths from the estimated object pose."""
    K = setup.cam_model.matrix()
    Kinv = np.linalg.inv(K)
    x = (np.c_[p_k.reshape(N, 2), np.ones(N)] @ Kinv.T)[:, :2]
    xd = (np.c_[setup.p_d.reshape(N, 2), np.ones(N)] @ Kinv.T)[:, :2]
    T_wc = setup.robot.frame_pose("flange", q) @ T_FLANGE_CAMERA
    P_est = sc.CONROD.points_world(setup.setting.T_object_estimate)
    Z = (P_est - T_wc[:3, 3]) @ T_wc[:3, 2]
    Z = np.where(Z > 0.02, Z, 0.02)  # ours: depths floored at 2 cm (a point behind the model camera)
    L = interaction_matrix_points(x, Z)
    v_c = -config.ibvs_gain * np.linalg.pinv(L) @ (x - xd).ravel()
    J_c = twist_transform(inv_T(T_FLANGE_CAMERA)) @ setup.robot.frame_jacobian("flange", q)
    qdot = np.linalg.pinv(J_c) @ v_c
    if config.controller == "ibvs_saturated":
        qdot = np.clip(qdot, -setup.qd_max, setup.qd_max)
    return qdot


def run(config: Chan2011Config, out_dir: Path) -> Path:
    """Run one chan2011 experiment and write its trace files."""
    check_config(config)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(out_dir / "frames", ignore_errors=True)  # no stale snapshots
    with TraceRecorder(out_dir, experiment=out_dir.name.split("__")[0], paper="chan2011",
                       config=config, seed=config.seed) as rec:
        setup = build(config, out_dir)
        try:
            rec.set_scene(scene_description(setup, config))
            status, reason = _loop(setup, config, rec, out_dir)
        finally:
            setup.world.close()
            if setup.render is not None:
                setup.render.close()
        rec.close(status, reason)
    return out_dir


def _snapshot(setup: Setup, q: np.ndarray, out_dir: Path, k: int) -> None:
    """Save the camera image and a third-person view (figs 12-13) as PNG files."""
    import imageio.v2 as imageio

    frames = out_dir / "frames"
    frames.mkdir(exist_ok=True)
    if setup.render is not None:
        rgb = render_rgb(setup.render.client, sc.TRUE_INTRINSICS, true_camera_pose(setup.robot, q))
        imageio.imwrite(frames / f"camera_{k:05d}.png", rgb)
    view = p.computeViewMatrixFromYawPitchRoll([0.0, 0.3, 0.35], 1.0, 200, -25, 0, 2)
    proj = p.computeProjectionMatrixFOV(50, 4 / 3, 0.05, 5.0)
    img = p.getCameraImage(480, 360, view, proj, renderer=p.ER_TINY_RENDERER,
                           physicsClientId=setup.world.client)
    imageio.imwrite(frames / f"scene_{k:05d}.png",
                    np.reshape(np.asarray(img[2], dtype=np.uint8), (360, 480, 4))[:, :, :3])


def _loop(setup: Setup, config: Chan2011Config, rec: TraceRecorder,
          out_dir: Path) -> tuple[str, str]:
    robot, world = setup.robot, setup.world
    s = setup.setting
    n = robot.n
    dt = config.dt
    n_steps = int(round(config.duration / dt))
    P_est = sc.CONROD_POINTS
    q_min, q_max = np.asarray(CRS_LIMITS.q_min), np.asarray(CRS_LIMITS.q_max)
    q_ref = robot.q()
    v_ref = np.zeros(n)
    snap_every = max(1, int(round(config.snapshot_period / dt))) if config.snapshot_period else 0
    below_since: float | None = None
    dcc_failing = False
    reason = "duration reached"
    k = 0
    for k in range(n_steps + 1):
        t = k * dt
        q, qd = robot.q(), robot.qd()
        row: dict[str, float | int | str | bool] = {"t": t, "step": k}
        add_vector(row, "q", q)
        add_vector(row, "qd", qd)
        T_wc = true_camera_pose(robot, q)
        client = setup.render.client if setup.render is not None else world.client
        uv, found, _ = setup.camera.measure(client, T_wc, sc.CONROD, s.T_object_actual)
        p_k = uv.ravel()
        err = (p_k - setup.p_d).reshape(N, 2)
        e_rms = float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) if found.all() else float("nan")
        status, iters, solve_s, dcc_free, dcc_checks, box = "", 0, 0.0, True, 0, False
        lo = hi = np.zeros(n)
        d_fcl = float("nan")
        box_halfwidth = float("nan")
        qdot = np.zeros(n)
        if not found.all():
            uv_e, Z_e = project_points(sc.TRUE_INTRINSICS, T_wc,
                                       sc.CONROD.points_world(s.T_object_actual))
            inside = sc.TRUE_INTRINSICS.in_image(uv_e) & (Z_e > 0)
            lost = np.flatnonzero(~found).tolist()
            why = ("occluded (inside the image)" if np.all(inside[~found])
                   else "outside the image")
            rec.event(t, k, "feature_lost", f"points {lost} not found: {why}; run stopped")
            reason = f"feature lost ({why})"
            status = "no_features"
        elif setup.nmpc is not None:
            d_k = setup.nmpc.disturbance(p_k, q, s.T_object_estimate, P_est)  # eq. (11)
            sol = setup.nmpc.solve(q, setup.p_d, d_k, s.T_object_estimate, P_est)
            if setup.dcc is not None and sol.success:
                # chan2011 Sec. IV-B: check the planned motion (q_k to the end of the
                # horizon) with eq. (20) before executing it. If (20) fails ("DCC fails"),
                # bisect; the first certified sub-segment [q_k, q_a] bounds a collision-free
                # hyper-rectangle (every q in the box with corners q_k, q_a is free when (20)
                # holds for them), which replaces the joint limits (8) in a new solve. If the
                # bisection cannot certify anything, use the box around q_k from (20).
                d_fcl = setup.dcc.distance(q)
                q_end = sol.q_pred[-1]
                direct = certify_segment(setup.dcc, q, q_end, d_i=d_fcl)
                dcc_checks = 1
                if not direct:
                    res = check_segment(setup.dcc, q, q_end, d_i=d_fcl)
                    dcc_checks += res.n_checks
                    if res.free and res.segments:
                        q_a = res.segments[0][1]
                        lo = np.maximum(np.minimum(q, q_a), q_min)
                        hi = np.minimum(np.maximum(q, q_a), q_max)
                    else:
                        lo, hi = free_box(setup.dcc, q, d_fcl, q_min, q_max)
                    box, box_halfwidth = True, float(np.max(hi - lo) / 2)
                    sol = setup.nmpc.solve(q, setup.p_d, d_k, s.T_object_estimate, P_est,
                                           q_lo=lo, q_hi=hi)
                    if not dcc_failing:
                        rec.event(t, k, "dcc_fail", f"eq. (20) fails over the horizon "
                                  f"(d = {d_fcl:.3f} m); bisection: free={res.free}, "
                                  f"collision={res.collision}; joint bounds replaced by the "
                                  "collision-free hyper-rectangle")
                elif dcc_failing:
                    rec.event(t, k, "dcc_ok", "eq. (20) holds over the horizon again")
                dcc_free = direct
                dcc_failing = not direct
            if not sol.success:  # retry once from a cold start (a stale warm start can stall)
                setup.nmpc.reset()
                retry = setup.nmpc.solve(q, setup.p_d, d_k, s.T_object_estimate, P_est,
                                         q_lo=lo if box else None, q_hi=hi if box else None)
                retry_time = sol.solve_time_s + retry.solve_time_s
                sol = retry
                rec.event(t, k, "nmpc_retry", f"cold retry: {retry.status}")
            else:
                retry_time = sol.solve_time_s
            status, iters, solve_s = sol.status, sol.iterations, retry_time
            if sol.success:
                qdot = sol.qdot
            else:
                rec.event(t, k, "nmpc_failed", f"{sol.status}; fallback qdot = 0")
            _log_prediction(row, sol)
        else:
            tic = time.perf_counter()
            qdot = _ibvs(setup, config, q, p_k)
            solve_s = time.perf_counter() - tic
            status = config.controller
        for i in range(n):
            row[f"u{i + 1}"] = qdot[i]
        for i in range(n):
            row[f"qref{i + 1}"] = q_ref[i]
        for j in range(N):
            row[f"p{j + 1}_u"] = uv[j, 0]
            row[f"p{j + 1}_v"] = uv[j, 1]
        row["e_rms_px"] = e_rms
        pos, quat = pose_to_pb(T_wc)
        for a, v in zip(("x", "y", "z"), pos, strict=True):
            row[f"cam_{a}"] = v
        for a, v in zip(("qx", "qy", "qz", "qw"), quat, strict=True):
            row[f"cam_{a}"] = v
        row["status"] = status
        row["iterations"] = iters
        row["solve_s"] = solve_s
        row["dcc_free"] = dcc_free
        row["dcc_checks"] = dcc_checks
        row["dcc_box"] = box
        row["dcc_box_halfwidth"] = box_halfwidth
        row["d_fcl"] = d_fcl
        dists = {name: robot.min_distance(bid) for name, bid in setup.obstacle_ids.items()}
        for name, d in dists.items():
            row[f"dist_{name}"] = d
        obst = [d for name, d in dists.items() if name != "conrod"]
        row["dist_min"] = min(obst) if obst else float("nan")
        rec.record(row)
        if snap_every and (k % snap_every == 0):
            _snapshot(setup, q, out_dir, k)
        if status == "no_features":
            break
        # stop once converged (RMS pixel error under stop_px for 0.2 s)
        if e_rms < config.stop_px:
            below_since = t if below_since is None else below_since
            if t - below_since >= 0.2:
                reason = f"converged: RMS pixel error < {config.stop_px} px for 0.2 s"
                rec.event(t, k, "converged", reason)
                break
        else:
            below_since = None
        # inner loop (Sec. V-A5): quintic reference from (q_ref, v_ref) to
        # (q_ref + dt qdot, qdot), tracked by the joint PD at the physics rate.
        q_target = np.clip(q_ref + dt * qdot, q_min, q_max)
        steps = world.steps_per_control
        for s_i in range(1, steps + 1):
            qr, vr = quintic(q_ref, v_ref, q_target, qdot, dt, s_i * world.config.physics_dt)
            if config.inner_loop == "kinematic":
                robot.reset(qr, vr)  # perfect tracking, as in the paper's simulation
            else:
                robot.set_position_command(qr, vr, position_gain=config.pd_gain)
            world.step_physics()
        q_ref, v_ref = q_target, qdot
        for name, d in dists.items():
            if d <= 0 and name != "conrod" and not rec.summary.get(f"collided_{name}"):
                rec.summary[f"collided_{name}"] = True
                rec.event(t, k, "collision", f"robot touches {name}")
    rec.summary["n_steps"] = k + 1
    rec.summary["sim_time_s"] = k * dt
    rec.summary["stop_reason"] = reason
    return "completed", reason


def _log_prediction(row: dict, sol: NMPCSolution) -> None:
    row["cost"] = sol.cost
    row["max_violation"] = sol.max_violation
