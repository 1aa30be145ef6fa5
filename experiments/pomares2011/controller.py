"""The pomares2011 controller of experiments 1-2 and the task's approach: the RVC law (18)
for the PA-10 from the camera's VVS pose, the direct hybrid visual servo (1)-(5), (17) of
the mini-robot (or the indirect baseline), the hand idle."""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from experiments.pomares2011 import scene as sc
from experiments.pomares2011.config import Pomares2011Config
from experiments.pomares2011.human_tracking import (
    TRACKING_EVENT_M,
    Bones,
    HumanDistance,
    human_distance,
)
from repro.control.hybrid_vs import (
    SAMPLES_PER_MODE,
    HybridVSConfig,
    HybridVSController,
    gains_from_inertia,
    lyapunov,
    sampled_loop_omega,
    torque_bounded_omega,
)
from repro.control.indirect_vs import (
    IndirectVSConfig,
    IndirectVSController,
    pd_gains_from_inertia,
)
from repro.control.rvc import rvc_features, rvc_joint_velocity
from repro.geometry import inv_T
from repro.sensors.camera import project_points
from repro.sim.episode import Observation, StepResult
from repro.sim.human import add_tracking_noise
from repro.sim.pa10 import ALL_JOINTS, HAND_JOINTS
from repro.sim.robot import JointGroup, Robot
from repro.sim.world import pose_to_pb
from repro.vision.features import interaction_matrix_points
from repro.vision.pose import pose_from_points
from repro.vision.vvs import vvs_pose

N = 4  # pomares2011 Sec. 7: four image points
#: Positions of the hand's joints in ALL_JOINTS.
HAND_IDX = np.array([ALL_JOINTS.index(j) for j in HAND_JOINTS])


def pixel_interaction_matrix(uv: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """(2N, 6) interaction matrix of image points in pixels: rows of the normalised-point
    matrix scaled by fu, fv (L_px = diag(fu, fv, ...) L_x)."""
    x = sc.INTRINSICS.to_normalized(uv)
    scale = np.tile([sc.INTRINSICS.fu, sc.INTRINSICS.fv], len(uv))
    return scale[:, None] * interaction_matrix_points(x, Z)



class Pomares2011Controller:
    """Camera frame -> VVS pose (22)-(24) -> RVC law (18) for the PA-10; the direct hybrid
    controller (1)-(5), (17) for the mini-robot at every control step (features held between
    frames), or the indirect baseline; the hand's finger motors hold ``hand_hold`` [rad]
    (Table 1, approaching: "no control"). ``__call__`` is the episode runner's controller."""

    def __init__(self, config: Pomares2011Config, chain: Robot, arm: JointGroup,
                 mini: JointGroup, human: Bones | None = None,
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
        self.rvc_cols: Callable[[], dict[str, float | int | bool]] = dict  # no frame yet
        self.hybrid: HybridVSController | None = None
        self.indirect: IndirectVSController | None = None
        self.lost = False
        self.was_active = False
        self.held_human: tuple[HumanDistance, dict[str, float | str]] | None = None
        self._L_memo: tuple[bytes, np.ndarray] | None = None
        self._mini_ix = np.ix_(mini.idx, mini.idx)
        #: audit: the dots' model points in the world (the part is fixed) [m], for V_true
        self._P_world = sc.POINTS_P @ sc.OBJECT.T_world[:3, :3].T + sc.OBJECT.T_world[:3, 3]

    def _mini_mass(self, q: np.ndarray) -> np.ndarray:
        """The mini-robot's block of the chain's joint-space inertia M(q) [kg m^2]."""
        return self.chain.mass_matrix(q)[self._mini_ix]

    def _interaction(self, uv: np.ndarray, T_mc_obj: np.ndarray) -> np.ndarray:
        """L_px at the detected points with the depths of the VVS pose; between frames both
        are held, so the matrix of the last bit-identical (uv, pose) is reused."""
        key = uv.tobytes() + T_mc_obj.tobytes()
        if self._L_memo is None or self._L_memo[0] != key:
            P_c = sc.POINTS_P @ T_mc_obj[:3, :3].T + T_mc_obj[:3, 3]
            self._L_memo = (key, pixel_interaction_matrix(uv, P_c[:, 2]))  # VVS depths
        return self._L_memo[1]

    def _gains(self, q: np.ndarray, uv: np.ndarray, L_px: np.ndarray) -> tuple[str, str]:
        """The mini-robot's gains from its inertia at the first step (our rule); returns the
        ``gain_rule`` event that states them.

        ours (issue 17 item 11): the fastest closed-loop mode, unless ``omega_max`` fixes it,
        is the smaller of (a) the bandwidth the loop's feedback rate allows: the torques are
        computed at 1 kHz but the image error they act on is sampled by the 200 fps camera
        and held, so the visual loop is a 200 Hz loop: 2 pi 200 / 20 = 62.8 rad/s
        (SAMPLES_PER_MODE); (b) the fastest mode whose first torque command, at rest with
        the start's image error, stays inside the mini-robot's torque limits (the design
        stays linear). The sweep varies omega_max around it."""
        cfg = self.config
        J_g = self.chain.frame_jacobian("mini_camera_optical", q)[:, self.mini.idx]
        M = self.chain.mass_matrix(q)[np.ix_(self.mini.idx, self.mini.idx)]
        G = self.mini.gravity_torques()
        rows = (sc.PRIMARY_TASK_ROW,)
        f_feedback = cfg.physics_rate / cfg.camera_period
        w_s = sampled_loop_omega(f_feedback)
        g1 = gains_from_inertia(M, L_px @ J_g, 1.0, cfg.zeta)
        unit = HybridVSController(HybridVSConfig(self.s_star.ravel(), g1.k_P, g1.K_v, 1.0,
                                                 cfg.dmin, avoid_rows=rows))
        tau1, _ = unit.step(q[self.mini.idx], np.zeros(len(self.mini.idx)), uv.ravel(), L_px,
                            J_g, np.zeros(len(self.mini.idx)), M)
        w_t = torque_bounded_omega(tau1, G, np.asarray(self.mini.limits.tau_max))
        omega = cfg.omega_max if cfg.omega_max > 0 else min(w_s, w_t)
        g = gains_from_inertia(M, L_px @ J_g, omega, cfg.zeta)
        alpha = cfg.push_force * cfg.dmin / g.k_P
        K_v_active = 2.0 * cfg.zeta * cfg.avoid_omega * 0.5 * (M + M.T)
        self.hybrid = HybridVSController(HybridVSConfig(self.s_star.ravel(), g.k_P, g.K_v, alpha,
                                                        cfg.dmin, avoid_rows=rows,
                                                        K_v_active=K_v_active))
        if cfg.mini_controller == "indirect":
            pd = pd_gains_from_inertia(M, omega, cfg.zeta)
            self.indirect = IndirectVSController(IndirectVSConfig(
                self.s_star.ravel(), cfg.indirect_gain, pd.K_p, pd.K_d,
                np.asarray(self.mini.limits.qd_max), 1.0 / cfg.physics_rate,
                np.asarray(self.mini.limits.q_min), np.asarray(self.mini.limits.q_max)))
        tau0 = omega**2 * tau1 + G
        how = ("fixed by omega_max" if cfg.omega_max > 0 else
               f"min(feedback-rate bound 2 pi {f_feedback:g} Hz / {SAMPLES_PER_MODE:g} = "
               f"{w_s:.1f}, torque bound {w_t:.1f}) rad/s")
        return ("gain_rule", f"mini-robot gains at t = 0 (gains_from_inertia): omega_max = "
                f"{omega:.2f} rad/s ({how}), zeta = {cfg.zeta}; k_P = {g.k_P:.6g} "
                f"N m/px^2, K_v = {np.round(g.K_v, 9).tolist()} N m s/rad, alpha = {alpha:.6g};"
                f" first torque {np.round(tau0, 4).tolist()} N m of limits "
                f"{list(self.mini.limits.tau_max)}; M = the mini-robot block of the chain's "
                "joint-space inertia (pinocchio CRBA of the run's URDF) at the start")

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
        reached = self.arm_reached

        def audit() -> dict[str, float | int | bool]:
            """This frame's RVC columns: the VVS pose and its error against the true pose
            (audit), the RVC features, with the true pose's beside them."""
            T_true = inv_T(T_world_mc) @ sc.OBJECT.T_world  # audit: the true object pose
            true_u = rvc_features(sc.RVC_INTRINSICS, inv_T(T_world_rvc) @ sc.OBJECT.T_world,
                                  self.layout.points_u).uv  # audit: s_u with the true pose
            cols: dict[str, float | int | bool] = {
                "vvs_iter": res.iterations, "vvs_residual_px": res.residual_px,
                "vvs_converged": res.converged,
                "vvs_pos_err_m": float(np.linalg.norm(res.T_cam_obj[:3, 3] - T_true[:3, 3])),
                "vvs_rot_err_deg": float(np.degrees(np.arccos(np.clip(
                    0.5 * (np.trace(res.T_cam_obj[:3, :3].T @ T_true[:3, :3]) - 1.0),
                    -1.0, 1.0)))),
                "e_u_px": e_u, "arm_reached": reached}
            for pre, T in (("vvs_", res.T_cam_obj), ("vvs_true_", T_true)):  # issue 17 item 12
                pos, quat = pose_to_pb(T)
                for a, v in zip(("x", "y", "z", "qx", "qy", "qz", "qw"), (*pos, *quat),
                                strict=True):
                    cols[f"{pre}{a}"] = float(v)
            for i in range(N):
                cols[f"su{i + 1}_u"], cols[f"su{i + 1}_v"] = feats.uv[i]
                cols[f"su{i + 1}_u_true"], cols[f"su{i + 1}_v_true"] = true_u[i]
            return cols

        self.rvc_cols = functools.cache(audit)  # computed if a row of this frame is written

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
        L_px = self._interaction(f.uv, self.T_mc_obj)
        if self.hybrid is None:
            events.append(self._gains(q, f.uv, L_px))
        assert self.hybrid is not None
        J_g = self.chain.frame_jacobian("mini_camera_optical", q)[:, self.mini.idx]
        G = self.mini.gravity_torques()
        hd, cols_h = self._human(q, obs.t, obs.step, events)
        use = hd if (hd is not None and self.config.secondary_task) else None
        M_now: np.ndarray | None = None  # M(q), for V (10) only: found when a row needs it
        if self.indirect is None:
            tau, diag = self.hybrid.step(q[self.mini.idx], obs.qd["mini"], f.uv.ravel(), L_px,
                                         J_g, G, None, use.dist if use else None,
                                         use.grad if use else None)
        else:  # the baseline has no secondary task; V (10) with the direct gain, to compare
            M_now = self._mini_mass(q)
            tau, _ = self.indirect.step(q[self.mini.idx], obs.qd["mini"], f.uv.ravel(), L_px,
                                        J_g, G, M_now)
            diag = {"V": lyapunov(obs.qd["mini"], M_now, self.s_star.ravel() - f.uv.ravel(),
                                  self.hybrid.config.k_P), "e2": 0.0, "active": False}
        active = bool(diag["active"])
        if active != self.was_active and hd is not None:
            events.append(("secondary_task_on" if active else "secondary_task_off",
                           f"dist = {hd.dist:.3f} m {'<' if active else '>='} dmin = "
                           f"{self.config.dmin} m ({hd.pair})"))
        self.was_active = active
        rvc_cols, qd_mini, k_P = self.rvc_cols, obs.qd["mini"], self.hybrid.config.k_P

        def columns() -> dict[str, float | int | str | bool]:
            """The step's columns (for a row that is written): the RVC's, V (10) and its
            audit twin, the image errors, the flange position, the human distance."""
            # audit (issue 18): V (10) with the exact projections through the true camera
            # pose in place of the detected points (eq. (15) is about the law with exact
            # features)
            M = self._mini_mass(q) if M_now is None else M_now
            V = lyapunov(qd_mini, M, diag["e_s"], k_P) if M_now is None else diag["V"]  # (10)
            uv_true, _ = project_points(sc.INTRINSICS, self.chain.frame_pose(
                "mini_camera_optical", q), self._P_world)
            rows = diag.get("rows", list(range(self.s_star.size)))
            e_true = (self.s_star.ravel() - uv_true.ravel())[rows]
            V_true = lyapunov(qd_mini, M, e_true, k_P)
            e_y = float(f.uv.ravel()[sc.PRIMARY_TASK_ROW] - sc.PRIMARY_TASK_TARGET_PX)
            flange = self.chain.frame_pose("pa10_flange", q)[:3, 3]
            cols: dict[str, float | int | str | bool] = dict(rvc_cols())
            cols.update(V=V, V_true=V_true, e_s_px=float(np.sqrt(np.mean(np.sum(
                (f.uv - self.s_star) ** 2, axis=1)))), e_f2y_px=e_y, e2=diag["e2"],
                secondary_active=active, flange_x=flange[0], flange_y=flange[1],
                flange_z=flange[2], **cols_h)
            return cols

        return StepResult({"arm": self.qd_arm, "mini": tau, "fingers": self.hand_hold.copy()},
                          {}, events, lazy_columns=columns)

