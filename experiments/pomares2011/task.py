"""pomares2011 Table 1, the whole task as one run: the approach (the PA-10 under the RVC,
the mini-robot under the direct hybrid controller, the hand idle: its motors hold the fingers
half open), then, once the RVC has reached s_u* (the PA-10 stops for good), the manipulation
of experiment 3 (the PA-10 still, the mini-robot still under its hybrid controller, the hand
pre-shapes, closes and executes the planned trajectory under Algorithm 1).

**The layout (all ours; the paper gives none).** Experiment 1's goal leaves the palm 0.24 m
above the part, out of the fingers' reach, and its hand axis passes through the dots: an
object there would hide them from the camera (measured in a first trial: from experiment 1's
start the cylinder hid all four dots for 0.3-0.55 s, and the oblique approach swept finger 3
into it at t = 2.5 s). So the task has its own goal, :data:`TASK_LAYOUT`:

* the cylinder of experiment 3 lies on a support rail (10 mm wide, experiment 3's) on the
  table, 0.35 m to the side of the part (world +y), :data:`STAND_HEIGHT` up, its axis along
  the world x; the part with its dots stays where experiment 1 has it;
* the goal: the hand axis straight down through the cylinder's axis, the palm ``palm_gap``
  over it (experiment 3's grasp, in the hand frame); the mini-robot turned to the part's side
  (q1 90 deg), leaning back (q2 -30 deg), pointing at the part from 0.14-0.17 m;
* the start: the PA-10 0.25 m straight above the goal, turned 5 deg about the hand axis (the
  approach comes down the hand axis, so the open fingers pass either side of the cylinder;
  a 15 deg turn brought finger 1 within 2.2 mm of it in a trial, half-way down); the
  mini-robot at (80, -30, 7.25) deg: the four dots ~100 px from s*, 0.36 m away;
* s* are the exact projections of the dots at the goal (a taught image); P_u are the rays of
  the paper's s_u* from the RVC at the goal cut with the plane of the part's top face
  (experiment 1's construction), and the learning stage re-learns s_u* before the run.

Once every finger presses the cylinder the rail is lowered into the table (a retracting
stand), so that the cylinder then hangs in the fingers as in experiment 3. The cylinder is a
free body from the start: if the approach touches it, it moves (audited).

Trace: the columns of experiment 1, of experiment 3 and ``task_phase``; a row every
``log_every`` control steps and at every Algorithm-1 tick (``StepResult.log_row``).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p

from experiments.pomares2011 import exp3 as e3
from experiments.pomares2011 import scene as sc
from experiments.pomares2011.columns import declare_columns as approach_columns
from experiments.pomares2011.config import Pomares2011Config
from experiments.pomares2011.controller import HAND_IDX, Pomares2011Controller
from experiments.pomares2011.object_rest import SETTLE_S, cylinder_dynamics, settle_before_start
from experiments.pomares2011.run import build_parts
from repro.config import param, validate
from repro.errors import ConfigError
from repro.geometry import Rx, Rz, make_T, rot_y, trans
from repro.sensors.camera import project_points
from repro.sensors.tactile import TactileSensor, bh8_pads, mount_pads
from repro.sim import barrett as B
from repro.sim.episode import Episode, Observation, StepResult, View, run_episode
from repro.sim.pa10 import PALM_HEIGHT
from repro.sim.robot import JointGroup
from repro.sim.scene import Part, Scene, pose_json

__all__ = ["TASK_LAYOUT", "TASK_PHASES", "TaskConfig", "TaskController", "build", "check_config",
           "run"]

DEG = math.pi / 180.0
#: Height of the support rail's top above the table [m]. ours: the camera then looks at the
#: part from 0.14-0.17 m at the goal, 0.15 m above the table.
STAND_HEIGHT = 0.20
#: Where the cylinder's centre is over the table (world x, y) [m]. ours: 0.35 m to the side
#: of the part, within the table (|y| < 0.5 m).
CYLINDER_XY = (0.55, 0.35)
#: The mini-robot at the goal and at the start [deg]. ours: see the module docstring; q3 puts
#: the part's top-face centre at v = 265 px (goal) and 230 px (start).
MINI_GOAL_DEG = (90.0, -30.0, -17.6)
MINI_START_DEG = (80.0, -30.0, 7.25)
#: The start: this far above the goal along the world z [m], turned about the hand axis [deg].
#: ours: the approach comes down the hand axis; a 15 deg turn brought finger 1 within 2.2 mm
#: of the cylinder half-way down (trial), 5 deg leaves it ~9 mm.
START_RISE, START_TURN_DEG = 0.25, 5.0


def flange_goal(radius: float = 0.040, palm_gap: float = 0.005) -> np.ndarray:
    """The PA-10's goal ``T_world_flange`` [m]: hand axis straight down through the cylinder's
    axis, flange x along the world x, the palm ``palm_gap`` over the cylinder of ``radius``."""
    z = STAND_HEIGHT + 2.0 * radius + palm_gap + PALM_HEIGHT
    return trans(CYLINDER_XY[0], CYLINDER_XY[1], z) @ Rx(math.pi)


def flange_start() -> np.ndarray:
    """The PA-10's start ``T_world_flange`` [m] (:data:`START_RISE`, :data:`START_TURN_DEG`)."""
    return trans(0.0, 0.0, START_RISE) @ flange_goal() @ Rz(START_TURN_DEG * DEG)


#: PA-10 joints at the goal and the start [deg]: solve_ik(pa10_flange, flange_goal(),
#: scene.Q_GOAL) and solve_ik(pa10_flange, flange_start(), goal) (re-solved in the tests).
PA10_GOAL_DEG = (32.471192, -30.029457, -91.382745, 0.0, -58.587798, 32.471192)
PA10_START_DEG = (32.471192, -19.991957, -75.043175, 0.0, -84.964868, 37.471192)


def task_layout() -> sc.Layout:
    """:data:`TASK_LAYOUT` from the numbers above (pinocchio forward kinematics only)."""
    q_goal = np.r_[np.array(PA10_GOAL_DEG + MINI_GOAL_DEG) * DEG, sc.Q_HAND]
    q_start = np.r_[np.array(PA10_START_DEG + MINI_START_DEG) * DEG, sc.Q_HAND]
    frames = sc.kinematic_frames(q_goal)
    s_star, _ = project_points(sc.INTRINSICS, frames["mini_camera_optical"],
                               sc.DOTS.points_world(sc.OBJECT.T_world))
    points_u = sc.backproject_to_plane(sc.RVC_INTRINSICS, frames["rvc"], sc.S_U_STAR,
                                       sc.OBJECT.T_world, sc.OBJECT.top_z)
    for a in (q_goal, q_start, s_star, points_u):
        a.setflags(write=False)
    return sc.Layout("task", q_start, q_goal, s_star, np.asarray(sc.S_U_STAR), points_u)


#: The whole task's start, goal and desired features.
TASK_LAYOUT = task_layout()
#: The cylinder's colour. ours: desaturated (HSV saturation 39/255), experiment 3's orange
#: is a dot hue.
TASK_CYLINDER_RGBA = (0.66, 0.62, 0.56, 1.0)
#: The snapshots' view. ours: the hand, the cylinder and the part from the robot's right
#: front, the hand's start 0.25 m above the goal in the frame.
TASK_VIEW = View(target=(0.55, 0.20, 0.36), distance=1.0, yaw=60.0, pitch=-20.0, width=320,
                 height=240, fov=45.0)
#: Column ``task_phase``.
TASK_PHASES = {
    "approach": "Table 1, approaching: RVC (PA-10), direct hybrid controller (mini-robot), "
                "the hand's motors hold (no control)",
    "manipulation": "Table 1, manipulation: the PA-10 still (its drive holds the reached "
                    "pose), the mini-robot's hybrid controller, the hand's tactile control",
}


@dataclass(frozen=True)
class TaskConfig(e3.Exp3Config, Pomares2011Config):
    """The whole task (Table 1): every field of experiment 1 (the approach) and of experiment
    3 (the manipulation); the values below are the task's own."""

    experiment: str = param("task", choices=("task",),
                            help="the whole task of Table 1: approach, then manipulation")
    tactile_control: bool = param(True, help="Algorithm 1 on (the paper's manipulation)")
    duration: float = param(60.0, unit="s", range=(0.01, 300.0),
                            help="longest run time (the run ends hold_s after the hand's "
                                 "task ends)")  # ours: the approach takes ~18 s (exp1), the manipulation ~12 s (exp3)
    log_every: int = param(10, range=(1, 100),
                           help="control steps between trace rows (a multiple of "
                                "camera_period); every Algorithm-1 tick is a row too")  # ours: 100 Hz as experiments 1-2
    preshape_speed_deg_s: float = param(20.0, unit="deg/s", range=(1.0, 140.0),
                                        help="proximal speed of the pre-shaping, from the "
                                             "approach pose to the pre-shape")  # ours: a brisk move in free space (the hand's maximum: 140 deg/s), ~2 s
    snapshot_period: float = param(1.0, unit="s", range=(0.0, 60.0),
                                   help="period of the rendered snapshots (0: none)",
                                   output_only=True)  # ours: one frame per second of the task


def check_config(config: TaskConfig) -> None:
    """Reject a malformed config before anything is written."""
    validate(config)
    if config.log_every % config.camera_period:
        raise ConfigError(f"log_every = {config.log_every} must be a multiple of camera_period "
                          f"= {config.camera_period}")
    if config.human:
        raise ConfigError("the whole task runs without the operator (experiment 1's approach)")
    if not config.tactile_control:
        raise ConfigError("the whole task is the paper's: tactile_control must be true")
    e3.check_manipulation(config)
    if (config.cylinder_radius, config.palm_gap) != (0.040, 0.005):
        raise ConfigError("the task's layout (TASK_LAYOUT: its IK solutions and desired "
                          "features) is solved for cylinder_radius = 0.04 m and palm_gap = "
                          "0.005 m; other values need a layout of their own")


def cylinder_pose(config: TaskConfig) -> np.ndarray:
    """The cylinder's world pose [m]: in the hand frame at the goal, its axis along the hand's
    x, ``palm_gap`` under the palm (:func:`exp3.cylinder_centre_height`)."""
    T_goal = flange_goal(config.cylinder_radius, config.palm_gap)
    return T_goal @ make_T(rot_y(math.pi / 2), (0.0, 0.0, e3.cylinder_centre_height(config)))


def support_pose(config: TaskConfig) -> np.ndarray:
    """The support rail's world pose [m] (box centre): from the table up to the cylinder's
    underside, under its axis."""
    c = cylinder_pose(config)[:3, 3]
    bottom = c[2] - config.cylinder_radius
    return make_T(None, (c[0], c[1], 0.5 * bottom))


def support_size(config: TaskConfig) -> tuple[float, float, float]:
    """The rail's full size [m]: experiment 3's length and width, up to the cylinder."""
    return (e3.SUPPORT_SIZE[0], e3.SUPPORT_SIZE[1],
            float(cylinder_pose(config)[2, 3] - config.cylinder_radius))


class TaskController:
    """Table 1 in one controller: experiment 1's controller every step (the PA-10's RVC, the
    mini-robot's hybrid controller; the arm stays still once it has reached s_u*), and the
    hand's experiment-3 controller, which waits during the approach and begins when the arm
    has stopped."""

    def __init__(self, approach: Pomares2011Controller, hand: e3.Exp3Controller) -> None:
        self.approach, self.hand = approach, hand
        self.phase = "approach"
        self.t_manipulation: float | None = None

    def __call__(self, obs: Observation) -> StepResult:
        a = self.approach(obs)
        events = list(a.events)
        if self.phase == "approach" and self.approach.arm_reached:
            self.phase, self.t_manipulation = "manipulation", obs.t
            events.append(("task_manipulation", "the PA-10 has reached s_u* and stays still: "
                           "the hand begins (Table 1, manipulation)"))
            self.hand.begin(obs.t, events)
        h = self.hand(obs)
        command = {**a.command, "fingers": h.command["fingers"]}
        phase = self.phase

        def columns() -> dict[str, Any]:
            """The approach's columns, the hand's, the phase (for a row that is written)."""
            return {**a.trace_columns(), **h.columns, "task_phase": phase}

        return StepResult(command, {}, events + list(h.events), h.stop, a.fallback,
                          log_row=bool(h.columns.get("tick", False)), lazy_columns=columns)


def build(config: TaskConfig, out_dir: Path) -> tuple[Episode, TaskController]:
    """Experiment 1's scene plus the cylinder on its stand, the drives, the camera, the
    tactile pads, the finger torques, the grasp audit and the controller."""
    check_config(config)
    zc = e3.cylinder_centre_height(config)
    plan = e3.plan_contact_motor_angles(config.cylinder_radius, config.cylinder_length, zc,
                                        e3.planned_dy(config))
    preshape = plan[0] - B.J2_RATIO * math.radians(config.preshape_clearance_deg)
    T_support = support_pose(config)
    T_cyl = cylinder_pose(config)

    def add_object(scene: Scene) -> None:
        scene.add_dynamic("cylinder", Part("cylinder", (config.cylinder_radius,
                                                        config.cylinder_length)),
                          config.cylinder_mass, T_cyl, TASK_CYLINDER_RGBA,
                          cylinder_dynamics(config))
        scene.add_box("support", support_size(config), T_support, e3.SUPPORT_RGBA,
                      moving=True)

    parts = build_parts(config, out_dir, add_object, TASK_LAYOUT)
    scene, chain = parts.scene, parts.chain
    c = chain.client
    for link in range(-1, p.getNumJoints(chain.body, physicsClientId=c)):
        # as experiment 3: friction 1 on the robot, so each pair's coefficient is the
        # cylinder's (PyBullet multiplies the two); no rolling or spinning friction of its own
        p.changeDynamics(chain.body, link, lateralFriction=1.0, rollingFriction=0.0,
                         spinningFriction=0.0, physicsClientId=c)
    p.changeDynamics(scene["support"].ids[0], -1, lateralFriction=1.0, physicsClientId=c)
    tactile = TactileSensor(c, mount_pads(c, chain.body, bh8_pads()),
                            rate=1000.0 / config.tactile_period_ms)
    scene.add_sensor("tactile", tactile.describe())
    hand_ctrl = e3.Exp3Controller(config, preshape, plan, hand_body="pa10", hand_idx=HAND_IDX,
                                  start=np.full(3, sc.HAND_APPROACH_MOTOR),
                                  preshape_rate=B.J2_RATIO
                                  * math.radians(config.preshape_speed_deg_s),
                                  hand_columns=False)
    ctrl = TaskController(parts.ctrl, hand_ctrl)
    # the grasp audit's distances: the hand's links (its joint group, plus the base and the
    # palm, which ride on the flange)
    hand_links: JointGroup = copy.copy(scene.joint_groups["hand"])
    hand_links.links = sorted(set(hand_links.links) | {chain.pb_link_index("bh8_base"),
                                                        chain.pb_link_index("bh8_palm")})
    audit = e3.GraspAudit(scene, chain, "cylinder", "support",
                          reference_now=lambda: hand_ctrl.t_manipulation is not None,
                          lost_after=config.tactile_period_ms, dist_of=hand_links)
    scene.add_sensor("finger_torque", {"kind": "joint_motor_torques", "columns":
                                       "tau_prox{i}, tau_dist{i}, tau{i}", "source":
                                       "PyBullet appliedJointMotorTorque of the last step"})
    scene.add_sensor("grasp_audit", {"kind": "ground_truth", "frame": "bh8_palm link frame",
                                     "drop_m": e3.DROP_M, **audit.describe()})
    movers = dict(parts.movers)
    movers["support"] = _lowered(T_support, hand_ctrl)
    scene.extra["task"] = {
        "phases": TASK_PHASES,
        "cylinder": {"released_at": pose_json(T_cyl),
                     "start": f"at rest on the support: released touching it at released_at, "
                     f"left to settle for {SETTLE_S} s before t = 0 with the robots held still "
                     "(object_rest.settle_before_start); start_pose: where it came to rest",
                     "radius_m": config.cylinder_radius,
                     "length_m": config.cylinder_length, "mass_kg": config.cylinder_mass,
                     "placement": "in the hand frame at the task's goal (layout.goal_flange): "
                     "axis along the hand's x, centre on the hand axis palm_gap under the palm",
                     "dynamics": "as experiment 3: friction, rolling and spinning friction, "
                     "contact stiffness and damping are the config's fields"},
        "support": {"size_m": list(support_size(config)), "lowered_by_m": config.support_drop_m,
                    "speed_m_s": config.support_speed_m_s, "starts": "support_delay_s after "
                    "every finger stopped closing (pose columns support_*); it sinks into the "
                    "table (a retracting stand)"},
        "layout": {"start": "the PA-10 0.25 m above its goal, turned 5 deg about the hand "
                   "axis", "goal_flange": pose_json(flange_goal(config.cylinder_radius,
                                                                config.palm_gap)),
                   "s_star": "exact projections of the dots at q_goal (scene extra s_star_px)",
                   "points_u": "rays of the paper's s_u* from the RVC at q_goal cut with the "
                   "plane of the part's top face (scene extra points_u_object)"},
        "plan": {"plan_dy_m": e3.planned_dy(config), "contact_motor_rad": plan,
                 "preshape_motor_rad": preshape,
                 "meaning": "as experiment 3, in the hand frame at the goal"},
        "pressure_images": e3.PRESSURE_IMAGES,
    }
    cols = approach_columns(False).extend(e3.declare_columns(hand_joints=False))
    tactile.declare(cols)
    cols.add("task_phase", "text", "Table 1 phase: " + "; ".join(
        f"{k}: {v}" for k, v in TASK_PHASES.items()))
    # issue 17 item 9: the run starts with the cylinder at rest on its rail
    settle_before_start(scene)
    scene.extra["task"]["cylinder"]["start_pose"] = pose_json(scene["cylinder"].T_world)
    ep = Episode(scene, parts.drives, ctrl, cols, config.duration, cameras=[parts.rig],
                 sensors=[tactile, e3.FingerTorqueSensor(chain), audit], movers=movers,
                 video=config.video, view=TASK_VIEW,
                 snapshot_period=config.snapshot_period, log_every=config.log_every)
    return ep, ctrl


def _lowered(T0: np.ndarray, hand: e3.Exp3Controller):  # type: ignore[no-untyped-def]
    def pose(t: float) -> np.ndarray:
        T = T0.copy()
        T[2, 3] -= hand.support_offset(t)
        return T
    return pose


def run(config: TaskConfig, out_dir: Path, experiment: str | None = None) -> Path:
    """Run the whole task and write its run files, plus ``pressure_images.npz``."""
    check_config(config)
    out_dir = Path(out_dir)
    (out_dir / e3.PRESSURE_IMAGES["file"]).unlink(missing_ok=True)
    ep, ctrl = build(config, out_dir)
    try:
        return run_episode(ep, out_dir, paper=e3.PAPER, config=config,
                           experiment=experiment or "task")
    finally:
        if ctrl.hand.samples:
            e3.write_pressure_images(out_dir / e3.PRESSURE_IMAGES["file"], ctrl.hand)
