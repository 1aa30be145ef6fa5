"""One pomares2011 run: the PA-10 under the Reference Virtual Camera (joint velocities), the
RRR mini-robot under the direct hybrid visual servo (joint torques at 1 kHz), the eye-in-hand
camera at 200 fps, and the shared episode runner.

``run(config, out_dir)`` is the one code path used by the CLI, the tests and the benchmarks.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.pomares2011 import scene as sc
from experiments.pomares2011.columns import declare_columns
from experiments.pomares2011.config import Pomares2011Config
from repro.config import validate
from repro.control.hybrid_vs import HybridVSConfig, HybridVSController, gains_from_inertia
from repro.control.rvc import rvc_features, rvc_joint_velocity
from repro.errors import ConfigError
from repro.geometry import inv_T
from repro.sensors.camera import Camera
from repro.sim.drives import TorqueDrive, VelocityDrive
from repro.sim.episode import CameraRig, Episode, Observation, StepResult, View, run_episode
from repro.sim.pa10 import MINI_JOINTS, PA10_JOINTS
from repro.sim.robot import JointGroup, Robot
from repro.sim.scene import Scene
from repro.sim.world import WorldConfig
from repro.vision.features import interaction_matrix_points
from repro.vision.pose import pose_from_points
from repro.vision.vvs import vvs_pose

N = 4  # pomares2011 Sec. 7: four image points


def check_config(config: Pomares2011Config) -> None:
    """Reject a malformed config before anything runs."""
    validate(config)
    if config.experiment == "exp2":
        raise ConfigError("pomares2011 exp2 (the human) is not built yet: issue 8 is open")


def pixel_interaction_matrix(uv: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """(2N, 6) interaction matrix of image points in pixels: rows of the normalised-point
    matrix scaled by fu, fv (L_px = diag(fu, fv, ...) L_x)."""
    x = sc.INTRINSICS.to_normalized(uv)
    scale = np.tile([sc.INTRINSICS.fu, sc.INTRINSICS.fv], len(uv))
    return scale[:, None] * interaction_matrix_points(x, Z)


class Pomares2011Controller:
    """Camera frame -> VVS pose (22)-(24) -> RVC law (18) for the PA-10; the direct hybrid
    controller (1)-(5) for the mini-robot at every control step (features held between
    frames). ``__call__`` is the episode runner's controller."""

    def __init__(self, config: Pomares2011Config, chain: Robot, arm: JointGroup,
                 mini: JointGroup) -> None:
        self.config, self.chain, self.arm, self.mini = config, chain, arm, mini
        self.T_mc_obj: np.ndarray | None = None
        self.qd_arm = np.zeros(arm.n)
        self.rvc_cols: dict[str, float | int | bool] = {}
        self.hybrid: HybridVSController | None = None
        self.lost = False

    def _gains(self, q: np.ndarray, L_px: np.ndarray) -> HybridVSController:
        """The mini-robot's gains from its inertia at the first step (our rule)."""
        J_g = self.chain.frame_jacobian("mini_camera_optical", q)[:, self.mini.idx]
        M = self.chain.mass_matrix(q)[np.ix_(self.mini.idx, self.mini.idx)]
        g = gains_from_inertia(M, L_px @ J_g, self.config.omega_max, self.config.zeta)
        alpha = self.config.push_force * self.config.dmin / g.k_P
        return HybridVSController(HybridVSConfig(sc.S_STAR.ravel(), g.k_P, g.K_v, alpha,
                                                 self.config.dmin))

    def _rvc(self, q: np.ndarray, uv: np.ndarray) -> None:
        """A new frame: the object pose by VVS, then the RVC features and law (18)."""
        if self.T_mc_obj is None:  # first frame: a PnP pose starts the VVS
            self.T_mc_obj = pose_from_points(sc.POINTS_P, uv, sc.INTRINSICS.K())
            if self.T_mc_obj is None:
                return  # no pose yet: the arm waits (qd_arm stays 0)
        res = vvs_pose(sc.POINTS_P, uv, sc.INTRINSICS, self.T_mc_obj)
        self.T_mc_obj = res.T_cam_obj
        T_world_rvc = self.chain.frame_pose("pa10_flange", q) @ sc.T_FLANGE_RVC
        T_world_mc = self.chain.frame_pose("mini_camera_optical", q)
        T_rvc_obj = inv_T(T_world_rvc) @ T_world_mc @ res.T_cam_obj  # M_O^RVC (Sec. 5.1)
        feats = rvc_features(sc.RVC_INTRINSICS, T_rvc_obj, sc.POINTS_U)  # (19)-(21)
        eJ_e = self.chain.frame_jacobian("pa10_flange", q)[:, self.arm.idx]
        self.qd_arm = rvc_joint_velocity(feats, sc.S_U_STAR, sc.RVC_INTRINSICS,
                                         self.config.rvc_gain, sc.T_FLANGE_RVC, eJ_e,
                                         np.asarray(self.arm.limits.qd_max), "scale")  # (18)
        T_true = inv_T(T_world_mc) @ sc.OBJECT.T_world  # audit: the true object pose
        true_u = rvc_features(sc.RVC_INTRINSICS, inv_T(T_world_rvc) @ sc.OBJECT.T_world,
                              sc.POINTS_U).uv  # audit: s_u with the true object pose
        cols: dict[str, float | int | bool] = {
            "vvs_iter": res.iterations, "vvs_residual_px": res.residual_px,
            "vvs_converged": res.converged,
            "vvs_pos_err_m": float(np.linalg.norm(res.T_cam_obj[:3, 3] - T_true[:3, 3])),
            "e_u_px": float(np.sqrt(np.mean(np.sum((feats.uv - sc.S_U_STAR) ** 2, axis=1))))}
        for i in range(N):
            cols[f"su{i + 1}_u"], cols[f"su{i + 1}_v"] = feats.uv[i]
            cols[f"su{i + 1}_u_true"], cols[f"su{i + 1}_v_true"] = true_u[i]
        self.rvc_cols = cols

    def __call__(self, obs: Observation) -> StepResult:
        q, f = obs.q["pa10"], obs.features["camera"]
        events: list[tuple[str, str]] = []
        if not f.found.all():
            if not self.lost:
                events.append(("feature_lost", f"dots {(np.flatnonzero(~f.found) + 1).tolist()}"
                               " (1-based) not found: arm stops, mini-robot holds"))
            self.lost = True
            return StepResult({"arm": np.zeros(self.arm.n),
                               "mini": self.mini.gravity_torques()}, {}, events, fallback=True)
        self.lost = False
        if obs.step % self.config.camera_period == 0:
            self._rvc(q, f.uv)
        if self.T_mc_obj is None:
            return StepResult({"arm": np.zeros(self.arm.n), "mini": self.mini.gravity_torques()},
                              {}, [("no_pose", "PnP found no object pose: waiting")],
                              fallback=True)
        P_c = sc.POINTS_P @ self.T_mc_obj[:3, :3].T + self.T_mc_obj[:3, 3]
        L_px = pixel_interaction_matrix(f.uv, P_c[:, 2])  # depths from the VVS pose
        if self.hybrid is None:
            self.hybrid = self._gains(q, L_px)
        J_g = self.chain.frame_jacobian("mini_camera_optical", q)[:, self.mini.idx]
        M = self.chain.mass_matrix(q)[np.ix_(self.mini.idx, self.mini.idx)]
        tau, diag = self.hybrid.step(q[self.mini.idx], obs.qd["mini"], f.uv.ravel(), L_px,
                                     J_g, self.mini.gravity_torques(), M)
        cols: dict[str, float | int | str | bool] = dict(self.rvc_cols)
        cols.update(V=diag["V"], e_s_px=float(np.sqrt(np.mean(np.sum(
            (f.uv - sc.S_STAR) ** 2, axis=1)))), e2=diag["e2"], secondary_active=diag["active"])
        return StepResult({"arm": self.qd_arm, "mini": tau}, cols, events)


def build(config: Pomares2011Config, out_dir: Path) -> tuple[Episode, Pomares2011Controller]:
    """The scene (robot, table, part, dots), the drives, the camera and the controller."""
    check_config(config)
    dt = 1.0 / config.physics_rate
    scene = Scene(WorldConfig(physics_dt=dt, control_dt=dt),
                  render=config.camera_mode == "render", run_dir=out_dir)
    chain = sc.build_scene(scene, sc.Q_START)
    arm = scene.add_joint_group("pa10", "arm", PA10_JOINTS, "pa10_", owns_base=True)
    mini = scene.add_joint_group("pa10", "mini", MINI_JOINTS, "mini_")
    scene.add_mount("camera", "pa10", "mini_camera_optical", np.eye(4),
                    "the mini-robot camera (x right, y down, z forward)")
    scene.add_mount("rvc", "pa10", "pa10_flange", sc.T_FLANGE_RVC,
                    "the Reference Virtual Camera (virtual: nothing is rendered)")
    rig = CameraRig("camera", "s", Camera(sc.INTRINSICS, mode=config.camera_mode), chain,
                    "mini_camera_optical", np.eye(4), "dots", period=config.camera_period)
    ctrl = Pomares2011Controller(config, chain, arm, mini)
    scene.extra.update(s_star_px=sc.S_STAR, s_u_star_px=sc.S_U_STAR,
                       points_u_object=sc.POINTS_U, q_goal=sc.Q_GOAL,
                       rvc={"mount": "rvc", "intrinsics": "same as the camera's"})
    ep = Episode(scene, {"arm": VelocityDrive(arm), "mini": TorqueDrive(mini)}, ctrl,
                 declare_columns(), config.duration, cameras=[rig], video=config.video,
                 video_every=33, view=View((0.5, 0.0, 0.3), 1.6, 60, -25))
    return ep, ctrl


def run(config: Pomares2011Config, out_dir: Path, experiment: str | None = None) -> Path:
    """Run one pomares2011 experiment and write its run files (see repro.sim.episode)."""
    check_config(config)
    ep = build(config, Path(out_dir))[0]
    return run_episode(ep, Path(out_dir), paper="pomares2011", config=config, experiment=experiment)
