"""pomares2011 experiment 3 (Sec. 6, 7.3; Figs. 11-12): the Barrett hand grasps a cylinder by
automatic closing, then a planned finger trajectory translates it across the fingers under
the tactile control of Algorithm 1 (30 Hz), and the same trajectory without it (ablation).

The scene (all ours, the paper gives none of it; every value is a config field below):

* the standalone BH8-282 (``repro/assets/barrett_bh8``) with its base fixed in the world,
  **palm facing down** (hand z = world -z), spread 0: fingers 1-2 side by side on the hand's
  -y side, finger 3 opposite on +y. The PA-10 is still during manipulation (Table 1), so a
  fixed hand base is the paper's situation; the hand is "situated over this object" (Sec. 6);
* a solid cylinder lying along the hand's x axis (across the fingers) under the palm, first on
  a narrow support rail; the rail is lowered away once every finger presses the cylinder, so
  that it then hangs in the three fingertips only: the distal pads touch it ~50 deg beyond its
  sides and cradle it against gravity, which pulls it away from the palm (a lost contact is a
  drop; nothing holds it by construction);
* contacts: PyBullet's soft contact (stiffness, damping per contact point) and Coulomb
  friction, stated on the cylinder (the other bodies carry friction 1, so the pair's friction,
  PyBullet's product of the two, is the cylinder's value).

The drive: one motor angle target per finger [rad of the motor] (``motor_u{i}``), through the
TorqueSwitch and the gear constraints of :mod:`repro.sim.barrett` (:class:`BarrettHandDrive`);
the measured motor angle ``motor_q{i}`` is ``93.75 (q_proximal + q_distal)`` of the simulated
joints and the motor counts ``counts{i}`` = motor angle x 4096 / (2 pi).

The controller (:class:`Exp3Controller`), in phases:

1. ``closing``: every finger closes from a pre-shape at a slow constant speed; a finger stops
   when its maximum pressure (30 Hz sample) reaches ``grasp_kpa`` or its TorqueSwitch broke
   away (frames 1-4 of Fig. 11);
2. ``support``: fingers held, the support rail is lowered away, the cylinder settles in the
   fingers;
3. ``manipulation``: the planned trajectory (:func:`plan_contact_motor_angles`, ours, standing
   in for the geometric planner of [25]) under Algorithm 1
   (:class:`repro.control.tactile_control.TactileController`), one tick per tactile sample;
   or, without tactile control, one trajectory step per tick;
4. ``stopped`` (line 13) or ``done``: the fingers hold; the run ends ``hold_s`` later.

Files beside the runner's: ``pressure_images.npz`` (every 30 Hz pressure map of the seven pads
and the chosen instants, see :data:`PRESSURE_IMAGES`) and ``frames/`` (snapshots for Fig. 11).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as p

from experiments.pomares2011.exp3_audit import FingerTorqueSensor, GraspAudit
from experiments.pomares2011.exp3_columns import declare_columns
from experiments.pomares2011.exp3_config import (
    CYLINDER_RGBA,
    DROP_M,
    DT,
    EXPERIMENTS_EXP3,
    PAPER,
    SUPPORT_RGBA,
    SUPPORT_SIZE,
    T_WORLD_HAND,
    Exp3Config,
    Exp3NoTactileConfig,
    check_config,
    check_manipulation,
    config_for,
    cylinder_centre_height,
    planned_dy,
)
from experiments.pomares2011.exp3_controller import Exp3Controller
from experiments.pomares2011.exp3_planner import plan_contact_motor_angles
from experiments.pomares2011.object_rest import (
    SETTLE_S,
    cylinder_dynamics,
    settle_before_start,
)
from repro.geometry import make_T, rot_y
from repro.sensors.tactile import (
    BH8_PAD_NAMES,
    TactileSensor,
    bh8_pads,
    mount_pads,
)
from repro.sim import barrett as B
from repro.sim.barrett import BarrettHandDrive, FingerMotors
from repro.sim.episode import Episode, View, run_episode
from repro.sim.scene import Part, Scene, pose_json
from repro.sim.world import WorldConfig

#: The experiment's pieces live in exp3_config, exp3_planner, exp3_audit, exp3_columns and
#: exp3_controller; this module builds and runs it and re-exports what others use.
__all__ = [
    "DROP_M", "DT", "EXPERIMENTS_EXP3", "PAPER", "PRESSURE_IMAGES", "SUPPORT_RGBA",
    "SUPPORT_SIZE", "T_WORLD_HAND", "BarrettHandDrive", "Exp3Config", "Exp3Controller",
    "Exp3NoTactileConfig", "FingerMotors", "FingerTorqueSensor", "GraspAudit", "build",
    "check_config", "check_manipulation", "config_for", "cylinder_centre_height",
    "declare_columns", "plan_contact_motor_angles", "planned_dy", "run",
    "write_pressure_images",
]


PRESSURE_IMAGES = {
    "file": "pressure_images.npz",
    "t_s": "(n,) time of each tactile sample [s] (every 33 ms sample of the run)",
    "<pad>": "(n, n_tactels) reported pressure of each tactel of pad <pad> [kPa] (float32; "
             "0-140 kPa, 0.7 kPa steps), tactel order of repro.sensors.tactile: row-major "
             "(rows along the pad's x, towards the fingertip), extra cells last (the distal "
             "tip cell); pads: " + ", ".join(BH8_PAD_NAMES),
    "<pad>_rows, <pad>_cols": "grid shape of pad <pad> (the extra cells are not in the grid)",
    "instant_names, instant_t_s": "chosen instants (grasp, manipulation_start, "
                                  "first_readjust<i>, stopped / done, end) and their times [s]",
    "layouts": "see sensors.tactile.pads in this file (tactel centres, areas, frames)",
}


def build(config: Exp3Config, out_dir: Path) -> tuple[Episode, Exp3Controller]:
    """The scene (hand, cylinder, support), the drive, the sensors and the controller."""
    check_config(config)
    zc = cylinder_centre_height(config)
    plan = plan_contact_motor_angles(config.cylinder_radius, config.cylinder_length, zc,
                                     planned_dy(config))
    preshape = plan[0] - B.J2_RATIO * math.radians(config.preshape_clearance_deg)
    scene = Scene(WorldConfig(physics_dt=DT, control_dt=DT), render=False, run_dir=out_dir)
    hand = scene.add_urdf("hand", B.bh8_urdf_path(), B.BH8_JOINTS, B.BH8_LIMITS, T_WORLD_HAND,
                          column_prefix="hand_")
    c = hand.client
    hand.reset(B.hand_joints_from_motors(preshape))
    couplings = B.add_coupling_constraints(hand.body, c)
    for link in range(-1, p.getNumJoints(hand.body, physicsClientId=c)):
        # friction 1 on the hand: the pair's friction (PyBullet multiplies the two) is the
        # cylinder's; no rolling or spinning friction of its own.
        p.changeDynamics(hand.body, link, lateralFriction=1.0, rollingFriction=0.0,
                         spinningFriction=0.0, physicsClientId=c)
    T_world_cyl = T_WORLD_HAND @ make_T(rot_y(math.pi / 2), (0.0, 0.0, zc))
    T_support = make_T(None, (T_world_cyl[0, 3], T_world_cyl[1, 3],
                              T_world_cyl[2, 3] - config.cylinder_radius - SUPPORT_SIZE[2] / 2))
    scene.add_dynamic("cylinder", Part("cylinder", (config.cylinder_radius,
                                                    config.cylinder_length)),
                      config.cylinder_mass, T_world_cyl, CYLINDER_RGBA, cylinder_dynamics(config))
    support = scene.add_box("support", SUPPORT_SIZE, T_support, SUPPORT_RGBA, moving=True)
    p.changeDynamics(support.ids[0], -1, lateralFriction=1.0, physicsClientId=c)
    motors = FingerMotors(hand)
    drive = BarrettHandDrive(motors, couplings)
    tactile = TactileSensor(c, mount_pads(c, hand.body, bh8_pads()),
                            rate=1000.0 / config.tactile_period_ms)
    scene.add_sensor("tactile", tactile.describe())
    ctrl = Exp3Controller(config, preshape, plan)
    audit = GraspAudit(scene, hand, "cylinder", "support",
                       reference_now=lambda: ctrl.t_manipulation is not None,
                       lost_after=config.tactile_period_ms)
    scene.add_sensor("finger_torque", {"kind": "joint_motor_torques", "columns":
                                       "tau_prox{i}, tau_dist{i}, tau{i}", "source":
                                       "PyBullet appliedJointMotorTorque of the last step"})
    scene.add_sensor("grasp_audit", {"kind": "ground_truth", "frame": "bh8_palm link frame",
                                     "drop_m": DROP_M, **audit.describe()})

    def support_pose(t: float) -> np.ndarray:
        T = T_support.copy()
        T[2, 3] -= ctrl.support_offset(t)
        return T

    scene.extra["exp3"] = {
        "hand_base": pose_json(T_WORLD_HAND), "hand_base_meaning": "palm facing down: hand z "
        "(approach) = world -z; spread 0 (fingers 1-2 on the hand's -y, finger 3 on +y)",
        "cylinder": {"radius_m": config.cylinder_radius, "length_m": config.cylinder_length,
                     "mass_kg": config.cylinder_mass, "axis": "its frame's z, along the hand's "
                     "x", "centre_in_hand_frame_m": [0.0, 0.0, zc],
                     "lateral_friction": config.friction,
                     "rolling_friction_m": config.rolling_friction,
                     "spinning_friction_m": config.spinning_friction,
                     "contact_stiffness_n_per_m": config.contact_stiffness,
                     "contact_damping_n_s_per_m": config.contact_damping, "restitution": 0.0,
                     "friction_rule": "PyBullet multiplies the two bodies' lateral frictions; "
                     "the hand links and the support carry 1.0, so every pair's coefficient is "
                     "the cylinder's; rolling / spinning friction of the hand and support 0",
                     "dynamic": "a free body: its pose columns cylinder_* are read from "
                     "PyBullet every step",
                     "start": f"at rest on the support: released touching it at "
                     f"released_at, left to settle for {SETTLE_S} s before t = 0 with the hand "
                     "held still (object_rest.settle_before_start)",
                     "released_at": pose_json(T_world_cyl)},
        "support": {"size_m": list(SUPPORT_SIZE), "lowered_by_m": config.support_drop_m,
                    "speed_m_s": config.support_speed_m_s, "starts": "support_delay_s after "
                    "every finger stopped closing (pose columns support_*)"},
        "plan": {"meaning": "contact motor angles [rad] of fingers 1-3 (engaged clutch, first "
                 "touch) at each planned cylinder pose (0, plan_dy, z_centre) in the hand frame;"
                 " trajectory = the grasp's motor targets + (plan - plan[0])",
                 "plan_dy_m": planned_dy(config), "contact_motor_rad": plan,
                 "preshape_motor_rad": preshape},
        "drive": drive.describe(),
        "pressure_images": PRESSURE_IMAGES,
        "frames": "frames/scene_<control step>.png every snapshot_period (Fig. 11)",
    }
    # issue 17 item 9: the run starts with the cylinder at rest on its rail
    settle_before_start(scene)
    scene.extra["exp3"]["cylinder"]["start_pose"] = pose_json(scene["cylinder"].T_world)
    # ours: looking along the cylinder's axis, finger 3 on the left, fingers 1-2 on the right
    view = View(target=(0.0, 0.0, 0.30), distance=0.36, yaw=90.0, pitch=-10.0, width=320,
                height=240, fov=36.0)
    cols = declare_columns()
    tactile.declare(cols)
    ep = Episode(scene, {"fingers": drive}, ctrl, cols, config.duration,
                 sensors=[tactile, FingerTorqueSensor(hand), audit],
                 movers={"support": support_pose}, video=config.video,
                 view=view, snapshot_period=config.snapshot_period,
                 log_every=config.log_every)
    return ep, ctrl


def write_pressure_images(path: Path, ctrl: Exp3Controller) -> None:
    """Every tactile sample of the run and the chosen instants (:data:`PRESSURE_IMAGES`)."""
    from repro.sensors.tactile import BH8_DISTAL, BH8_PALM, BH8_PROXIMAL

    layouts = {"palm": BH8_PALM, "proximal": BH8_PROXIMAL, "distal": BH8_DISTAL}
    arrays: dict[str, np.ndarray] = {"t_s": np.array([t for t, _ in ctrl.samples])}
    for name in BH8_PAD_NAMES:
        lay = layouts[name.rsplit("_", 1)[-1]]
        arrays[name] = (np.stack([s[name] for _, s in ctrl.samples]) if ctrl.samples
                        else np.zeros((0, lay.n_tactels), np.float32))
        arrays[f"{name}_rows"] = np.array(lay.rows)
        arrays[f"{name}_cols"] = np.array(lay.cols)
    arrays["instant_names"] = np.array(list(ctrl.instants), dtype=str)
    arrays["instant_t_s"] = np.array(list(ctrl.instants.values()), dtype=float)
    np.savez_compressed(path, **arrays)  # type: ignore[arg-type]


def run(config: Exp3Config, out_dir: Path, experiment: str | None = None) -> Path:
    """Run experiment 3 (or its ablation) and write its run files (see repro.sim.episode),
    plus ``pressure_images.npz``."""
    check_config(config)
    out_dir = Path(out_dir)
    (out_dir / PRESSURE_IMAGES["file"]).unlink(missing_ok=True)
    ep, ctrl = build(config, out_dir)
    try:
        return run_episode(ep, out_dir, paper=PAPER, config=config,
                           experiment=experiment or config.experiment)
    finally:
        if ctrl.samples:
            write_pressure_images(out_dir / PRESSURE_IMAGES["file"], ctrl)
