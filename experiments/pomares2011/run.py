"""One pomares2011 run: the PA-10 under the Reference Virtual Camera (joint velocities), the
RRR mini-robot under the direct hybrid visual servo (joint torques at 1 kHz), the eye-in-hand
camera at 200 fps, and the shared episode runner.

``run(config, out_dir)`` is the one code path used by the CLI, the tests and the benchmarks.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from experiments.pomares2011 import scene as sc
from experiments.pomares2011.columns import declare_columns
from experiments.pomares2011.config import Pomares2011Config
from repro.config import validate
from repro.control.hybrid_vs import (
    HybridVSConfig,
    HybridVSController,
    distance_gradient_from_joints,
    gains_from_inertia,
    lyapunov,
)
from repro.control.indirect_vs import (
    IndirectVSConfig,
    IndirectVSController,
    pd_gains_from_inertia,
)
from repro.control.rvc import learn_desired_features, rvc_features, rvc_joint_velocity
from repro.errors import ConfigError, SensorError
from repro.geometry import inv_T
from repro.planning.capsules import Capsule, capsule_closest_points, min_distance
from repro.sensors.camera import Camera, check_scene_colors
from repro.sim import barrett as B
from repro.sim.drives import PositionReferenceDrive, TorqueDrive, VelocityDrive
from repro.sim.episode import CameraRig, Episode, Observation, StepResult, View, run_episode
from repro.sim.human import HumanMotion, add_tracking_noise
from repro.sim.pa10 import ALL_JOINTS, HAND_JOINTS, MINI_CAPSULES, MINI_JOINTS, PA10_JOINTS
from repro.sim.robot import JointGroup, Robot
from repro.sim.scene import Scene
from repro.sim.world import WorldConfig
from repro.vision.features import interaction_matrix_points, skew
from repro.vision.pose import pose_from_points
from repro.vision.vvs import vvs_pose

N = 4  # pomares2011 Sec. 7: four image points
#: The tracked human-robot distance this far from the distance with the true skeleton is
#: an event [m]. ours: 2 cm, ~4 std of the largest tracking noise we try.
TRACKING_EVENT_M = 0.02
#: Positions of the mini-robot's joints in ALL_JOINTS (q of the whole chain).
_MINI_IDX = np.array([ALL_JOINTS.index(j) for j in MINI_JOINTS])
#: Positions of the hand's joints in ALL_JOINTS.
HAND_IDX = np.array([ALL_JOINTS.index(j) for j in HAND_JOINTS])


def check_config(config: Pomares2011Config) -> None:
    """Reject a malformed config before anything runs."""
    validate(config)
    if config.log_every % config.camera_period:
        raise ConfigError(f"log_every = {config.log_every} must be a multiple of camera_period "
                          f"= {config.camera_period} (every trace row is then a fresh frame)")
    if config.experiment == "exp2" and not config.human:
        raise ConfigError("pomares2011 exp2 is the experiment with the operator: human=false "
                          "is experiment 1 (use pomares2011.exp1)")
    if config.experiment == "exp1" and config.human:
        raise ConfigError("pomares2011 exp1 has no human (Sec. 7.1): use pomares2011.exp2")


def pixel_interaction_matrix(uv: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """(2N, 6) interaction matrix of image points in pixels: rows of the normalised-point
    matrix scaled by fu, fv (L_px = diag(fu, fv, ...) L_x)."""
    x = sc.INTRINSICS.to_normalized(uv)
    scale = np.tile([sc.INTRINSICS.fu, sc.INTRINSICS.fv], len(uv))
    return scale[:, None] * interaction_matrix_points(x, Z)


class HumanDistance(NamedTuple):
    """The controller's human-robot distance (pomares2011 Sec. 4) at one step."""

    dist: float  # [m] min over the tracked human capsules x the mini-robot capsules
    grad: np.ndarray  # (6,) d(dist)/dr, camera twist (repro.control.hybrid_vs)
    pair: str  # "<mini capsule>|<human capsule>" of the closest pair
    dist_true: float  # [m] audit: the same with the true (noise-free) skeleton


def human_distance(chain: Robot, q: np.ndarray, tracked: list[tuple[str, Capsule]],
                   truth: list[tuple[str, Capsule]]) -> HumanDistance:
    """``dist`` of eq. (17) between the mini-robot's capsules at ``q`` and the tracked
    human capsules (``tracked is truth``: no tracking noise; python-fcl,
    :func:`repro.planning.capsules.min_distance`), and its gradient w.r.t. the camera pose
    from the closest pair's witness points: the exact joint gradient of the closest point
    on its own link, mapped to the camera-twist space
    (:func:`repro.control.hybrid_vs.distance_gradient_from_joints`)."""
    mini = sc.mini_capsules(chain, q)
    d, i, j = min_distance([c for _, c in mini], [c for _, c in tracked], method="fcl")
    _, x_r, x_h = capsule_closest_points(mini[i][1], tracked[j][1])
    n = x_r - x_h
    if np.linalg.norm(n) < 1e-9:  # touching segments: push along the robot capsule's normal
        n = mini[i][1].centre - tracked[j][1].centre
    n = n / np.linalg.norm(n)
    link = MINI_CAPSULES[i][0]
    idx = _MINI_IDX
    J_link = chain.frame_jacobian(link, q, "local_world_aligned")[:, idx]  # world axes
    o_link = chain.frame_pose(link, q)[:3, 3]
    J_p = J_link[:3] - skew(x_r - o_link) @ J_link[3:]  # velocity of the point x_r
    R = chain.frame_pose("mini_camera_optical", q)[:3, :3]
    J_g = chain.frame_jacobian("mini_camera_optical", q)[:, idx]
    grad = distance_gradient_from_joints(J_g, R.T @ J_p, R.T @ n)
    d_true = d if tracked is truth else min_distance([c_ for _, c_ in mini],
                                                     [c_ for _, c_ in truth])[0]
    return HumanDistance(float(d), grad, f"{mini[i][0]}|{tracked[j][0]}", float(d_true))


class Learned(NamedTuple):
    """The learning stage's outcome (pomares2011 Sec. 5.1, step 4)."""

    s_u_star: np.ndarray  # (4, 2) [px] learned desired RVC features
    uv_goal: np.ndarray  # (4, 2) [px] what the camera detected at the goal
    vvs_residual_px: float
    vvs_pos_err_m: float  # audit: VVS position error vs the true object pose


def learn_s_u_star(scene: Scene, chain: Robot, rig: CameraRig, layout: sc.Layout = sc.LAYOUT
                   ) -> Learned:
    """s_u* by the learning stage: the robot placed at its goal configuration
    (:data:`scene.Q_GOAL`), one camera frame (rendered and detected like every frame of the
    run), the object pose by PnP + VVS (22)-(24), M_O^RVC from the kinematics, and the
    projection of P_u (19)-(21) (:func:`repro.control.rvc.learn_desired_features`). The
    robot is put back where it was.

    Raises:
        SensorError: the camera does not see the four dots at the goal, or no pose is found.
    """
    q0 = chain.q()
    chain.reset(np.asarray(layout.q_goal, float))
    try:
        body = scene[rig.target]
        assert body.dot_target is not None
        T_wc = rig.pose(chain.q())
        uv, found, _ = rig.camera.measure(scene.render_client, T_wc, body.dot_target,
                                          body.T_world)
        if not found.all():
            raise SensorError(f"learning stage: dots {(np.flatnonzero(~found) + 1).tolist()} "
                              "not detected with the robot at its goal")
        T0 = pose_from_points(sc.POINTS_P, uv, sc.INTRINSICS.K())
        if T0 is None:
            raise SensorError("learning stage: PnP found no object pose at the goal")
        res = vvs_pose(sc.POINTS_P, uv, sc.INTRINSICS, T0)
        q = chain.q()
        T_world_rvc = chain.frame_pose("pa10_flange", q) @ sc.T_FLANGE_RVC
        T_rvc_obj = inv_T(T_world_rvc) @ T_wc @ res.T_cam_obj  # M_O^RVC at the goal
        s_u = learn_desired_features(sc.RVC_INTRINSICS, T_rvc_obj, layout.points_u)
        T_true = inv_T(T_wc) @ sc.OBJECT.T_world
        err = float(np.linalg.norm(res.T_cam_obj[:3, 3] - T_true[:3, 3]))
        return Learned(np.asarray(s_u), uv, float(res.residual_px), err)
    finally:
        chain.reset(q0)


class Pomares2011Controller:
    """Camera frame -> VVS pose (22)-(24) -> RVC law (18) for the PA-10; the direct hybrid
    controller (1)-(5), (17) for the mini-robot at every control step (features held between
    frames), or the indirect baseline; the hand's finger motors hold ``hand_hold`` [rad]
    (Table 1, approaching: "no control"). ``__call__`` is the episode runner's controller."""

    def __init__(self, config: Pomares2011Config, chain: Robot, arm: JointGroup,
                 mini: JointGroup, human: _Bones | None = None,
                 s_u_star: np.ndarray | None = None, layout: sc.Layout = sc.LAYOUT) -> None:
        self.config, self.chain, self.arm, self.mini = config, chain, arm, mini
        #: the goal, the desired features s* and the RVC's points P_u (experiments 1-2: the
        #: paper's; the whole task: its own, scene.Layout)
        self.layout = layout
        self.s_star = np.asarray(layout.s_star, dtype=float)
        self.hand_hold = np.full(3, sc.HAND_APPROACH_MOTOR)  # the finger motors' targets
        #: the RVC's desired features [px]: the learning stage's (default: the paper's)
        self.s_u_star = np.asarray(layout.s_u_star if s_u_star is None else s_u_star, float)
        self.human = human
        self.rng = np.random.default_rng(config.seed)
        self.T_mc_obj: np.ndarray | None = None
        self.qd_arm = np.zeros(arm.n)
        self.arm_reached = False
        self.rvc_cols: dict[str, float | int | bool] = {}
        self.hybrid: HybridVSController | None = None
        self.indirect: IndirectVSController | None = None
        self.lost = False
        self.was_active = False
        self.held_human: tuple[HumanDistance, dict[str, float | str]] | None = None

    def _gains(self, q: np.ndarray, L_px: np.ndarray) -> None:
        """The mini-robot's gains from its inertia at the first step (our rule)."""
        cfg = self.config
        J_g = self.chain.frame_jacobian("mini_camera_optical", q)[:, self.mini.idx]
        M = self.chain.mass_matrix(q)[np.ix_(self.mini.idx, self.mini.idx)]
        g = gains_from_inertia(M, L_px @ J_g, cfg.omega_max, cfg.zeta)
        alpha = cfg.push_force * cfg.dmin / g.k_P
        K_v_active = 2.0 * cfg.zeta * cfg.avoid_omega * 0.5 * (M + M.T)
        self.hybrid = HybridVSController(HybridVSConfig(self.s_star.ravel(), g.k_P, g.K_v, alpha,
                                                        cfg.dmin, K_v_active=K_v_active))
        if cfg.mini_controller == "indirect":
            pd = pd_gains_from_inertia(M, cfg.omega_max, cfg.zeta)
            self.indirect = IndirectVSController(IndirectVSConfig(
                self.s_star.ravel(), cfg.indirect_gain, pd.K_p, pd.K_d,
                np.asarray(self.mini.limits.qd_max), 1.0 / cfg.physics_rate,
                np.asarray(self.mini.limits.q_min), np.asarray(self.mini.limits.q_max)))

    def _rvc(self, q: np.ndarray, uv: np.ndarray, t: float,
             events: list[tuple[str, str]]) -> None:
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
        feats = rvc_features(sc.RVC_INTRINSICS, T_rvc_obj, self.layout.points_u)  # (19)-(21)
        e_u = float(np.sqrt(np.mean(np.sum((feats.uv - self.s_u_star) ** 2, axis=1))))
        if not self.arm_reached and e_u < self.config.arm_stop_px:
            self.arm_reached = True  # s_u* reached: the approach is over, the arm stays
            events.append(("rvc_reached", f"RVC error {e_u:.2f} px < arm_stop_px = "
                           f"{self.config.arm_stop_px} px: the PA-10 stops"))
        if self.arm_reached:
            self.qd_arm = np.zeros(self.arm.n)
        else:
            eJ_e = self.chain.frame_jacobian("pa10_flange", q)[:, self.arm.idx]
            self.qd_arm = rvc_joint_velocity(feats, self.s_u_star, sc.RVC_INTRINSICS,
                                             self.config.rvc_gain, sc.T_FLANGE_RVC, eJ_e,
                                             np.asarray(self.arm.limits.qd_max), "scale")  # (18)
        T_true = inv_T(T_world_mc) @ sc.OBJECT.T_world  # audit: the true object pose
        true_u = rvc_features(sc.RVC_INTRINSICS, inv_T(T_world_rvc) @ sc.OBJECT.T_world,
                              self.layout.points_u).uv  # audit: s_u with the true pose
        cols: dict[str, float | int | bool] = {
            "vvs_iter": res.iterations, "vvs_residual_px": res.residual_px,
            "vvs_converged": res.converged,
            "vvs_pos_err_m": float(np.linalg.norm(res.T_cam_obj[:3, 3] - T_true[:3, 3])),
            "e_u_px": e_u, "arm_reached": self.arm_reached}
        for i in range(N):
            cols[f"su{i + 1}_u"], cols[f"su{i + 1}_v"] = feats.uv[i]
            cols[f"su{i + 1}_u_true"], cols[f"su{i + 1}_v_true"] = true_u[i]
        self.rvc_cols = cols

    def _human(self, q: np.ndarray, t: float, step: int, events: list[tuple[str, str]]
               ) -> tuple[HumanDistance | None, dict[str, float | str]]:
        """The tracked skeleton (with its noise) and the distance of eq. (17), sampled every
        ``tracker_period`` steps and held in between."""
        if self.human is None:
            return None, {}
        if self.held_human is not None and step % self.config.tracker_period:
            return self.held_human
        truth = self.human.capsules(t)
        tracked = (truth if self.config.tracking_noise == 0.0
                   else add_tracking_noise(truth, self.config.tracking_noise, self.rng))
        hd = human_distance(self.chain, q, tracked, truth)
        if abs(hd.dist - hd.dist_true) > TRACKING_EVENT_M:
            events.append(("human_distance_off", f"tracked distance {hd.dist:.3f} m vs "
                           f"{hd.dist_true:.3f} m with the true skeleton"))
        self.held_human = (hd, {"dist_m": hd.dist, "dist_true_m": hd.dist_true,
                                "dist_pair": hd.pair})
        return self.held_human

    def _lost(self, q: np.ndarray, obs: Observation, events: list[tuple[str, str]]
              ) -> StepResult:
        """No image: the arm stops; the mini-robot holds against gravity with the active
        damping, plus the secondary task alone when the human is within dmin."""
        G = self.mini.gravity_torques()
        hd, cols = self._human(q, obs.t, obs.step, events)
        tau = G
        if self.hybrid is not None:
            J_g = self.chain.frame_jacobian("mini_camera_optical", q)[:, self.mini.idx]
            tau = G - self.hybrid.damping(True) @ obs.qd["mini"]
            active = (hd is not None and self.config.secondary_task
                      and hd.dist < self.config.dmin)
            if active:
                assert hd is not None
                tau, e2 = self.hybrid.avoid_only(obs.qd["mini"], J_g, G, hd.dist, hd.grad)
                cols = {**cols, "e2": e2}
            cols = {**cols, "secondary_active": bool(active)}
        return StepResult({"arm": np.zeros(self.arm.n), "mini": tau,
                           "fingers": self.hand_hold.copy()}, dict(cols), events, fallback=True)

    def __call__(self, obs: Observation) -> StepResult:
        q, f = obs.q["pa10"], obs.features["camera"]
        events: list[tuple[str, str]] = []
        if not f.found.all():
            if not self.lost:
                events.append(("feature_lost", f"dots {(np.flatnonzero(~f.found) + 1).tolist()}"
                               " (1-based) not found: arm stops, mini-robot holds (and keeps "
                               "avoiding the human if he is within dmin)"))
            self.lost = True
            return self._lost(q, obs, events)
        self.lost = False
        if obs.step % self.config.camera_period == 0:
            self._rvc(q, f.uv, obs.t, events)
        if self.T_mc_obj is None:
            return StepResult({"arm": np.zeros(self.arm.n), "mini": self.mini.gravity_torques(),
                               "fingers": self.hand_hold.copy()},
                              {}, [("no_pose", "PnP found no object pose: waiting")], fallback=True)
        P_c = sc.POINTS_P @ self.T_mc_obj[:3, :3].T + self.T_mc_obj[:3, 3]
        L_px = pixel_interaction_matrix(f.uv, P_c[:, 2])  # depths from the VVS pose
        if self.hybrid is None:
            self._gains(q, L_px)
        assert self.hybrid is not None
        J_g = self.chain.frame_jacobian("mini_camera_optical", q)[:, self.mini.idx]
        M = self.chain.mass_matrix(q)[np.ix_(self.mini.idx, self.mini.idx)]
        G = self.mini.gravity_torques()
        hd, cols_h = self._human(q, obs.t, obs.step, events)
        use = hd if (hd is not None and self.config.secondary_task) else None
        if self.indirect is None:
            tau, diag = self.hybrid.step(q[self.mini.idx], obs.qd["mini"], f.uv.ravel(), L_px,
                                         J_g, G, M, use.dist if use else None,
                                         use.grad if use else None)
        else:  # the baseline has no secondary task; V (10) with the direct gain, to compare
            tau, _ = self.indirect.step(q[self.mini.idx], obs.qd["mini"], f.uv.ravel(), L_px,
                                        J_g, G, M)
            diag = {"V": lyapunov(obs.qd["mini"], M, self.s_star.ravel() - f.uv.ravel(),
                                  self.hybrid.config.k_P), "e2": 0.0, "active": False}
        active = bool(diag["active"])
        if active != self.was_active and hd is not None:
            events.append(("secondary_task_on" if active else "secondary_task_off",
                           f"dist = {hd.dist:.3f} m {'<' if active else '>='} dmin = "
                           f"{self.config.dmin} m ({hd.pair})"))
        self.was_active = active
        e_y = float(f.uv[0, 1] - self.s_star[0, 1])
        flange = self.chain.frame_pose("pa10_flange", q)[:3, 3]
        cols: dict[str, float | int | str | bool] = dict(self.rvc_cols)
        cols.update(V=diag["V"], e_s_px=float(np.sqrt(np.mean(np.sum(
            (f.uv - self.s_star) ** 2, axis=1)))), e_f1y_px=e_y, e2=diag["e2"],
            secondary_active=active, flange_x=flange[0], flange_y=flange[1],
            flange_z=flange[2], **cols_h)
        return StepResult({"arm": self.qd_arm, "mini": tau, "fingers": self.hand_hold.copy()},
                          cols, events)


class ApproachParts(NamedTuple):
    """The pieces of a pomares2011 run that the whole task shares (:func:`build_parts`)."""

    scene: Scene
    chain: Robot
    drives: dict[str, Any]
    rig: CameraRig
    ctrl: Pomares2011Controller
    movers: dict[str, Callable[[float], np.ndarray]]


def build_parts(config: Pomares2011Config, out_dir: Path,
                extra_bodies: Callable[[Scene], None] | None = None,
                layout: sc.Layout = sc.LAYOUT) -> ApproachParts:
    """The scene (robot, table, part, dots, the human if any), the drives (PA-10, mini-robot,
    hand), the camera, the learning stage and the controller. ``extra_bodies`` adds the
    caller's bodies to the scene before the learning stage (it renders a frame); ``layout``
    the start, the goal and the desired features (default: experiments 1-2)."""
    dt = 1.0 / config.physics_rate
    scene = Scene(WorldConfig(physics_dt=dt, control_dt=dt),
                  render=config.camera_mode == "render", run_dir=out_dir)
    human = sc.human_motion() if config.human else None
    chain, bodies = sc.build_scene(scene, layout.q_start, human=human)
    if extra_bodies is not None:
        extra_bodies(scene)
        scene.check_colors(check_scene_colors)
    arm = scene.add_joint_group("pa10", "arm", PA10_JOINTS, "pa10_", owns_base=True)
    mini = scene.add_joint_group("pa10", "mini", MINI_JOINTS, "mini_")
    hand_drive = add_hand(scene, chain)
    scene.add_mount("camera", "pa10", "mini_camera_optical", np.eye(4),
                    "the mini-robot camera (x right, y down, z forward)")
    scene.add_mount("rvc", "pa10", "pa10_flange", sc.T_FLANGE_RVC,
                    "the Reference Virtual Camera (virtual: nothing is rendered)")
    rig = CameraRig("camera", "s", Camera(sc.INTRINSICS, mode=config.camera_mode), chain,
                    "mini_camera_optical", np.eye(4), "dots", period=config.camera_period)
    learned = learn_s_u_star(scene, chain, rig, layout)  # Sec. 5.1 step (4), before the run
    bones = _Bones(human) if human is not None else None
    ctrl = Pomares2011Controller(config, chain, arm, mini, bones, learned.s_u_star,
                                 layout=layout)
    scene.extra.update(s_star_px=layout.s_star, s_u_star_px=learned.s_u_star,
                       s_u_star_paper_px=sc.S_U_STAR, layout=layout.name,
                       s_u_star_learning={
                           "what": "s_u_star_px is learned before the run (pomares2011 Sec. "
                                   "5.1 step 4): the robot at q_goal, one camera frame, PnP + "
                                   "VVS object pose, P_u projected through the RVC",
                           "q": layout.q_goal, "detected_uv_px": learned.uv_goal,
                           "vvs_residual_px": learned.vvs_residual_px,
                           "vvs_pos_err_m": learned.vvs_pos_err_m},
                       points_u_object=layout.points_u, q_goal=layout.q_goal,
                       rvc={"mount": "rvc", "intrinsics": "same as the camera's"},
                       mini_capsules=[{"link": link, "p0": p0, "p1": p1, "radius": r}
                                      for link, p0, p1, r in MINI_CAPSULES],
                       mini_capsules_frame="each end point in its URDF link's frame [m]")
    movers: dict[str, Callable[[float], np.ndarray]] = {}
    if human is not None and bones is not None and bodies is not None:
        scene.extra["human"] = {"bodies": bodies.names, "stature_m": human.body.stature,
                                "path": dataclasses.asdict(sc.HUMAN_PATH),
                                "floor_z_m": sc.FLOOR_Z}
        for name, _ in human.capsules(0.0):
            movers[bodies.prefix + name] = bones.pose(name)
    drives = {"arm": _arm_drive(arm, config.arm_drive), "mini": TorqueDrive(mini),
              "fingers": hand_drive}
    return ApproachParts(scene, chain, drives, rig, ctrl, movers)


#: The third-person view of the videos and snapshots of experiments 1-2 and the task.
VIEW = View((0.5, -0.3, 0.3), 2.0, 20, -25)


def build(config: Pomares2011Config, out_dir: Path) -> tuple[Episode, Pomares2011Controller]:
    """The scene (robot, table, part, dots), the drives, the camera and the controller."""
    check_config(config)
    parts = build_parts(config, out_dir)
    ep = Episode(parts.scene, parts.drives, parts.ctrl, declare_columns(config.human),
                 config.duration, cameras=[parts.rig], movers=parts.movers, video=config.video,
                 video_every=33, view=VIEW, log_every=config.log_every)
    return ep, parts.ctrl


def add_hand(scene: Scene, chain: Robot) -> B.BarrettHandDrive:
    """The BH8-282 on the flange as the scene's joint group ``hand`` (no drive of its own: the
    runner logs its joints ``bh8_q{i}``, ``bh8_qd{i}`` and distances ``bh8_dist_*``) and its
    three finger motors (:class:`repro.sim.barrett.FingerMotors`,
    columns ``motor_*``) driven through the gear constraints and the TorqueSwitch
    (:class:`repro.sim.barrett.BarrettHandDrive`), spread 0."""
    scene.add_joint_group("pa10", "hand", HAND_JOINTS, "bh8_")
    couplings = B.add_coupling_constraints(chain.body, chain.client)
    drive = B.BarrettHandDrive(B.FingerMotors(chain), couplings)
    scene.extra["hand"] = {"model": "Barrett BH8-282 (repro/assets/barrett_bh8), root bh8_base "
                           "= pa10_flange", "drive": drive.describe(),
                           "approach_motor_rad": sc.HAND_APPROACH_MOTOR,
                           "approach": "Table 1, approaching: no control; the finger motors "
                                       "hold every finger half open (proximal 60 deg, distal "
                                       "20 deg)"}
    return drive


def _arm_drive(arm: JointGroup, kind: str) -> VelocityDrive | PositionReferenceDrive:
    """The PA-10's drive: the RVC's joint velocities through PyBullet's velocity motors, or
    integrated into a position reference tracked by the joint PD at the physics rate (a
    servo drive with a position loop, as chan2011's inner loop)."""
    if kind == "velocity":
        return VelocityDrive(arm)
    return PositionReferenceDrive(arm, "pd")


class _Bones:
    """The human's capsules at time t, computed once per time for the bones' movers and the
    controller's tracker (the same call at the same t would otherwise be made 13 times)."""

    def __init__(self, human: HumanMotion) -> None:
        self.human = human
        self.t = float("nan")
        self.list: list[tuple[str, Capsule]] = []
        self.caps: dict[str, Capsule] = {}
        self.poses: dict[str, tuple[Capsule, np.ndarray]] = {}  # its capsule, its pose

    def capsules(self, t: float) -> list[tuple[str, Capsule]]:
        """:meth:`repro.sim.human.HumanMotion.capsules` at ``t`` [s], cached."""
        if t != self.t:
            self.t, self.list = t, self.human.capsules(t)
            self.caps = dict(self.list)
        return self.list

    def pose(self, name: str) -> Callable[[float], np.ndarray]:
        def pose(t: float) -> np.ndarray:
            self.capsules(t)
            cap = self.caps[name]
            seen = self.poses.get(name)
            if seen is None or seen[0] is not cap:  # a capsule of a new body state
                seen = self.poses[name] = (cap, np.asarray(cap.T_world()))
            return seen[1]
        return pose


def run(config: Pomares2011Config, out_dir: Path, experiment: str | None = None) -> Path:
    """Run one pomares2011 experiment and write its run files (see repro.sim.episode)."""
    check_config(config)
    ep = build(config, Path(out_dir))[0]
    return run_episode(ep, Path(out_dir), paper="pomares2011", config=config, experiment=experiment)
