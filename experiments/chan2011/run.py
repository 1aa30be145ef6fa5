"""One chan2011 run: the scene, the NMPC (+ DCC) or IBVS controller, and the shared episode
runner (camera -> controller -> quintic references tracked at 1 kHz). ``run(config,
out_dir)`` is the one code path used by the CLI, the tests and the benchmarks.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from experiments.chan2011 import scene as sc
from experiments.chan2011.columns import declare_columns
from experiments.chan2011.config import Chan2011Config
from experiments.chan2011.layout import (
    conrod_parts,
    goal_configuration,
    non_default_layout,
    same_branch,
    setting_for,
)
from repro.config import validate
from repro.control.nmpc import NMPCConfig, NMPCSolution, VisualNMPC
from repro.errors import ConfigError, ReproError
from repro.geometry import inv_T
from repro.planning.dcc import (
    CollisionModel,
    certify_segment,
    check_segment,
    free_box,
    static_links,
)
from repro.sensors.camera import Camera, check_scene_colors, project_points
from repro.sim.casadi_kinematics import frame_pose_casadi
from repro.sim.crs_a465 import (
    CRS_JOINTS,
    CRS_LIMITS,
    T_FLANGE_CAMERA,
    crs_urdf_path,
    velocity_limits,
)
from repro.sim.drives import PositionReferenceDrive
from repro.sim.episode import CameraRig, Episode, Observation, StepResult, View, run_episode
from repro.sim.robot import Robot
from repro.sim.scene import Scene
from repro.sim.world import WorldConfig
from repro.vision.features import interaction_matrix_points, twist_transform
from repro.vision.ibvs import feature_jacobian, ibvs_joint_velocity

__all__ = ["Chan2011Controller", "build", "check_config", "conrod_parts", "run",
           "same_branch", "scaled_estimate"]

N = sc.N_POINTS
Q_MIN, Q_MAX = np.asarray(CRS_LIMITS.q_min), np.asarray(CRS_LIMITS.q_max)


def check_config(config: Chan2011Config) -> None:
    """Reject a malformed config, or a layout the paper's scene could not be, before anything
    runs. The experiment's layout (experiments/chan2011/layout.py) is refused when its conrod
    rests on nothing or inside an obstacle, a dot leaves its face, or the start has a point
    less than 40 px inside the image, collides, or is off the goal's IK branch (geometric
    checks only, cached per layout)."""
    validate(config)
    steps = config.dt * config.physics_rate
    if abs(steps - round(steps)) > 1e-6:
        raise ConfigError(f"dt = {config.dt} s is not a whole number of physics steps at "
                          f"{config.physics_rate} Hz")
    if config.setting != "experiment" and non_default_layout(config):
        raise ConfigError(f"{', '.join(non_default_layout(config))}: the experiment's layout "
                          f"applies only to setting='experiment', not {config.setting!r}")
    if config.dcc and not sc.SETTINGS[config.setting].obstacles:
        raise ConfigError(f"dcc=True needs obstacles; setting {config.setting!r} has none")
    setting_for(config)  # the experiment's layout: derived and checked (ConfigError)





def best_iterate(*sols: NMPCSolution) -> NMPCSolution | None:
    """The usable solution (:attr:`NMPCSolution.usable`) of lowest cost (eq. (12)) among
    ``sols``, None if none is."""
    ok = [s for s in sols if s.usable]
    return min(ok, key=lambda s: s.cost) if ok else None

class Chan2011Controller:
    """Image points -> NMPC (chan2011 eqs. (9)-(12)) with DCC (Sec. IV), or classical IBVS."""

    def __init__(self, config: Chan2011Config, robot: Robot, setting: sc.Setting,
                 p_d: np.ndarray, nmpc: VisualNMPC | None, dcc: CollisionModel | None) -> None:
        self.config, self.robot, self.setting, self.p_d = config, robot, setting, p_d
        self.nmpc, self.dcc = nmpc, dcc
        self.qd_max = velocity_limits(config.velocity_fraction)
        self.dcc_failing = False
        self.below_since: float | None = None

    def _ibvs(self, q: np.ndarray, p_k: np.ndarray) -> np.ndarray:
        """Classical IBVS with the controller's (uncalibrated) camera model and the depths
        of the estimated object pose (Chaumette & Hutchinson 2006)."""
        intr = sc.CONTROLLER_INTRINSICS
        x, xd = intr.to_normalized(p_k.reshape(N, 2)), intr.to_normalized(self.p_d.reshape(N, 2))
        T_wc = self.robot.frame_pose("flange", q) @ T_FLANGE_CAMERA
        Z = (self.setting.target.points_world(self.setting.T_object_estimate)
             - T_wc[:3, 3]) @ T_wc[:3, 2]
        Z = np.where(Z > 0.02, Z, 0.02)  # ours: depths floored at 2 cm (a point behind the model camera)
        J_s = feature_jacobian(interaction_matrix_points(x, Z),
                               twist_transform(inv_T(T_FLANGE_CAMERA)),
                               self.robot.frame_jacobian("flange", q))
        if self.config.controller != "ibvs_saturated":  # the drive clips each joint
            return ibvs_joint_velocity(J_s, (x - xd).ravel(), self.config.ibvs_gain)
        return ibvs_joint_velocity(J_s, (x - xd).ravel(), self.config.ibvs_gain, self.qd_max,
                                   saturation=getattr(self.config, "ibvs_saturation", "scale"))

    def _nmpc(self, q: np.ndarray, p_k: np.ndarray, cols: dict, events: list
              ) -> tuple[np.ndarray, bool]:
        """(qdot, solved): the NMPC command, or zeros when no solve succeeded."""
        assert self.nmpc is not None
        s = self.setting
        P = s.target.points_target
        d_k = self.nmpc.disturbance(p_k, q, s.T_object_estimate, P)  # eq. (11)
        sol = self.nmpc.solve(q, self.p_d, d_k, s.T_object_estimate, P)
        lo = hi = None
        if self.dcc is not None and sol.usable:
            # Sec. IV-B: certify the planned motion with eq. (20); if it fails, bisect: the
            # first certified sub-segment [q_k, q_a] bounds a collision-free hyper-rectangle
            # that replaces the joint limits (8) in a new solve (or the box around q_k).
            cols["d_fcl"] = d = self.dcc.distance(q)
            direct = certify_segment(self.dcc, q, sol.q_pred[-1], d_i=d)
            cols.update(dcc_free=direct, dcc_checks=1)
            if not direct:
                res = check_segment(self.dcc, q, sol.q_pred[-1], d_i=d)
                cols["dcc_checks"] = 1 + res.n_checks
                if res.free and res.segments:
                    q_a = res.segments[0][1]
                    lo, hi = np.maximum(np.minimum(q, q_a), Q_MIN), np.minimum(np.maximum(q, q_a), Q_MAX)
                else:
                    lo, hi = free_box(self.dcc, q, d, Q_MIN, Q_MAX)
                cols.update(dcc_box=True, dcc_box_halfwidth=float(np.max(hi - lo) / 2))
                sol = self.nmpc.solve(q, self.p_d, d_k, s.T_object_estimate, P, q_lo=lo, q_hi=hi)
                if not self.dcc_failing:
                    events.append(("dcc_fail", f"eq. (20) fails over the horizon (d = {d:.3f} m); "
                                   f"bisection: free={res.free}, collision={res.collision}; joint "
                                   "bounds replaced by the collision-free hyper-rectangle"))
            elif self.dcc_failing:
                events.append(("dcc_ok", "eq. (20) holds over the horizon again"))
            self.dcc_failing = not direct
        solve_s = sol.solve_time_s
        if not sol.success:  # retry once from a cold start (a stale warm start can stall)
            first = sol
            self.nmpc.reset()
            sol = self.nmpc.solve(q, self.p_d, d_k, s.T_object_estimate, P, q_lo=lo, q_hi=hi)
            solve_s += sol.solve_time_s
            events.append(("nmpc_retry", f"cold retry: {sol.status}"))
            if not sol.success:
                sol = best_iterate(first, sol) or sol
        cols.update(status=sol.status, iterations=sol.iterations, solve_s=solve_s,
                    cost=sol.cost, max_violation=sol.max_violation)
        if sol.success:
            cols["nmpc_command"] = "converged"
            return sol.qdot, True
        if sol.usable:
            cols["nmpc_command"] = "feasible_iterate"
            events.append(("nmpc_feasible_iterate",
                           f"{sol.status} after {sol.iterations} iterations; the last iterate "
                           f"is feasible (max violation {sol.max_violation:.2e} <= feas_tol, "
                           f"cost {sol.cost:.4g}): applied"))
            return sol.qdot, True
        cols["nmpc_command"] = "zero"
        events.append(("nmpc_failed", f"{sol.status} (max violation {sol.max_violation:.2e}); "
                       "no feasible iterate: fallback qdot = 0"))
        return np.zeros(self.robot.n), False

    def __call__(self, obs: Observation) -> StepResult:
        q, f = obs.q["crs_a465"], obs.features["camera"]
        cols: dict = {"nmpc_command": "", "dcc_free": True, "dcc_checks": 0, "dcc_box": False,
                      "dcc_box_halfwidth": float("nan"), "d_fcl": float("nan")}
        events: list[tuple[str, str]] = []
        if not f.found.all():
            return StepResult({"crs_a465": np.zeros(self.robot.n)},
                              {**cols, "status": "no_features", "e_rms_px": float("nan")}, [],
                              ("feature_lost", f"points {(np.flatnonzero(~f.found) + 1).tolist()} "
                               "(1-based) not found; run stopped"), fallback=True)
        p_k = f.uv.ravel()
        e_rms = float(np.sqrt(np.mean(np.sum((p_k - self.p_d).reshape(N, 2) ** 2, axis=1))))
        tic = time.perf_counter()
        if self.nmpc is not None:
            qdot, solved = self._nmpc(q, p_k, cols, events)
            fallback = not solved
        else:
            qdot, fallback = self._ibvs(q, p_k), False
            cols.update(status=self.config.controller, iterations=0,
                        solve_s=time.perf_counter() - tic)
        cols["e_rms_px"] = e_rms
        stop = None  # ours: converged when the RMS error stays under stop_px for 0.2 s
        self.below_since = (obs.t if self.below_since is None else self.below_since) if (
            e_rms < self.config.stop_px) else None
        if self.below_since is not None and obs.t - self.below_since >= 0.2:
            stop = ("converged", f"converged: RMS pixel error < {self.config.stop_px} px for 0.2 s")
        return StepResult({"crs_a465": qdot}, cols, events, stop, fallback=fallback)


def scaled_estimate(setting: sc.Setting, translation_scale: float, rotation_scale: float
                    ) -> sc.Setting:
    """``setting`` with its estimated object pose's error (relative to the actual pose, in the
    object's frame) scaled: the translation by ``translation_scale``, the rotation angle by
    ``rotation_scale`` about the same axis. Scales of 1 return the setting as printed
    (Sec. III-A's estimate, bit for bit)."""
    if translation_scale == 1.0 and rotation_scale == 1.0:
        return setting
    from scipy.spatial.transform import Rotation

    A = setting.T_object_actual
    D = inv_T(A) @ setting.T_object_estimate
    D_new = np.eye(4)
    D_new[:3, :3] = Rotation.from_rotvec(
        rotation_scale * Rotation.from_matrix(D[:3, :3]).as_rotvec()).as_matrix()
    D_new[:3, 3] = translation_scale * D[:3, 3]
    return dataclasses.replace(setting, T_object_estimate=A @ D_new)


def build(config: Chan2011Config, out_dir: Path) -> Episode:
    """The scene, robot, camera, reference image and controller of ``config.setting``."""
    check_config(config)
    setting = scaled_estimate(setting_for(config), config.estimate_translation_scale,
                              config.estimate_rotation_scale)
    scene = Scene(WorldConfig(physics_dt=1.0 / config.physics_rate, control_dt=config.dt,
                              solver_iterations=50), render=config.camera_mode == "render",
                  run_dir=out_dir)
    robot = scene.add_urdf("crs_a465", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    for box in setting.obstacles:
        scene.add_box(box.name, box.size, box.T_world, sc.OBSTACLE_RGBA)
    scene.add_compound("conrod", conrod_parts(), setting.T_object_actual, sc.CONROD_RGBA,
                       obstacle=False)
    scene.add_dot_target("conrod_dots", setting.target, setting.T_object_actual)
    scene.check_colors(check_scene_colors)
    scene.add_mount("camera", "crs_a465", "flange", T_FLANGE_CAMERA @ sc.T_MOUNT_ERROR,
                    "true camera optical frame (x right, y down, z forward); the controller "
                    "uses T_FLANGE_CAMERA without the mounting error")
    rig = CameraRig("camera", "p", Camera(sc.TRUE_INTRINSICS, mode=config.camera_mode), robot,
                    "flange", T_FLANGE_CAMERA @ sc.T_MOUNT_ERROR, "conrod_dots",
                    log_view_angle=True)
    q_goal = goal_configuration(robot, setting)
    # The reference image: what the real camera sees at the goal (Fig. 2 / Fig. 3 'x').
    T_goal_cam = rig.pose(q_goal)
    uv_d, found_d, _ = rig.camera.measure(scene.render_client, T_goal_cam, setting.target,
                                          setting.T_object_actual)
    uv_true, _ = project_points(sc.TRUE_INTRINSICS, T_goal_cam,
                                setting.target.points_world(setting.T_object_actual))
    if not np.all(found_d) or np.max(np.linalg.norm(uv_d - uv_true, axis=1)) > rig.tol_px:
        raise ReproError("the reference image does not show every feature point where its "
                         f"model projects: found {found_d.tolist()}, errors "
                         f"{np.linalg.norm(uv_d - uv_true, axis=1).round(2).tolist()} px")
    qd_max = velocity_limits(config.velocity_fraction)
    nmpc = None
    if config.controller == "nmpc":
        fk = frame_pose_casadi(pin.buildModelFromUrdf(str(robot.urdf_path)), "flange",
                               CRS_JOINTS, T_frame_child=T_FLANGE_CAMERA)
        nmpc = VisualNMPC(fk, sc.CONTROLLER_INTRINSICS, N, CRS_LIMITS.q_min, CRS_LIMITS.q_max,
                          qd_max, NMPCConfig(Np=config.Np, dt=config.dt, Q_weight=config.Q_weight,
                                             W_weight=config.W_weight, solver=config.nlp_solver,
                                             qpsol=config.qpsol, max_iter=config.nlp_max_iter,
                                             fov_margin=config.fov_margin),
                          image_bounds=sc.CONTROLLER_IMAGE_BOUNDS)
    # issue 17: the links no joint moves (the base) are left out of d(q); their fixed
    # 0.19 m to the books capped d(q) at every configuration (the ground-truth audit keeps them)
    skip = static_links(robot.urdf_path)
    dcc = (CollisionModel(robot.urdf_path, CRS_JOINTS, setting.obstacles, skip_links=skip)
           if config.dcc else None)
    robot.reset(np.deg2rad(setting.q0_deg))
    ctrl = Chan2011Controller(config, robot, setting, uv_d.ravel(), nmpc, dcc)
    scene.extra.update(
        desired_pixels=uv_d, q_goal_deg=np.rad2deg(q_goal), q0_deg=setting.q0_deg,
        controller_model={"table_I": sc.TABLE_I, "T_flange_camera": T_FLANGE_CAMERA,
                          "T_base_object_estimate": setting.T_object_estimate,
                          "qd_max_used": qd_max},
        dcc_radii=dcc.radii() if dcc is not None else None,
        dcc_model=None if dcc is None else {
            "library": "python-fcl", "margin": dcc.margin, "skip_links": list(skip),
            "skip_reason": "links no joint moves (the root link and links fixed to it): "
                           "their distance to the obstacles is the same at every q, so in "
                           "d(q) it is only a cap; the *_dist_* audit columns keep them"})
    return Episode(scene, {"crs_a465": PositionReferenceDrive(robot, config.inner_loop,
                                                              config.pd_gain)},
                   ctrl, declare_columns(), config.duration, cameras=[rig], video=config.video,
                   view=View((0.0, 0.3, 0.35), 1.0, 200, -25, 480, 360, 50),
                   snapshot_period=config.snapshot_period)


def run(config: Chan2011Config, out_dir: Path, experiment: str | None = None) -> Path:
    """Run one chan2011 experiment and write its run files (see repro.sim.episode)."""
    check_config(config)
    ep = build(config, Path(out_dir))
    return run_episode(ep, Path(out_dir), paper="chan2011", config=config, experiment=experiment)
