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
from experiments.pomares2011.config import Exp2Config, Pomares2011Config
from experiments.pomares2011.controller import Pomares2011Controller
from experiments.pomares2011.human_tracking import Bones
from experiments.pomares2011.learning import learn_s_u_star
from repro.config import validate
from repro.errors import ConfigError
from repro.sensors.camera import Camera, check_scene_colors
from repro.sensors.camera_window import WindowPolicy
from repro.sim import barrett as B
from repro.sim.drives import PositionReferenceDrive, TorqueDrive, VelocityDrive
from repro.sim.episode import CameraRig, Episode, View, run_episode
from repro.sim.pa10 import HAND_JOINTS, MINI_CAPSULES, MINI_JOINTS, PA10_JOINTS
from repro.sim.robot import JointGroup, Robot
from repro.sim.scene import Scene
from repro.sim.world import WorldConfig


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
    path = (sc.human_path(config.human_gap, config.human_t_enter)
            if isinstance(config, Exp2Config) else sc.HUMAN_PATH)
    human = sc.human_motion(path) if config.human else None
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
    window = (WindowPolicy.for_camera_speed(
        sc.INTRINSICS, config.camera_period / config.physics_rate, sc.WINDOW_OMEGA_MAX,
        sc.WINDOW_V_MAX, sc.WINDOW_Z_MIN)
        if config.camera_mode == "render" and config.camera_windows else None)
    rig = CameraRig("camera", "s", Camera(sc.INTRINSICS, mode=config.camera_mode,
                                          window=window), chain,
                    "mini_camera_optical", np.eye(4), "dots", period=config.camera_period)
    learned = learn_s_u_star(scene, chain, rig, layout)  # Sec. 5.1 step (4), before the run
    rig.camera.reset_windows()  # the run's first frame is full, whatever the learning saw
    bones = Bones(human) if human is not None else None
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
                 view=VIEW, log_every=config.log_every)
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



def run(config: Pomares2011Config, out_dir: Path, experiment: str | None = None) -> Path:
    """Run one pomares2011 experiment and write its run files (see repro.sim.episode)."""
    check_config(config)
    ep = build(config, Path(out_dir))[0]
    return run_episode(ep, Path(out_dir), paper="pomares2011", config=config, experiment=experiment)
