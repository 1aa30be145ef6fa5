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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pybullet as p

from experiments.pomares2011.object_rest import (
    SETTLE_S,
    cylinder_dynamics,
    settle_before_start,
    support_distance,
)
from repro.config import param, validate
from repro.control.tactile_control import (
    LOG_FIELDS,
    PAPER_READJUST_THRESHOLD_KPA,
    PAPER_SAFETY_THRESHOLD_KPA,
    TactileControlConfig,
    TactileController,
)
from repro.errors import ConfigError
from repro.geometry import inv_T, make_T, rot_y
from repro.runs.columns import Columns
from repro.sensors.tactile import (
    BH8_PAD_NAMES,
    TactileReading,
    TactileSensor,
    bh8_pads,
    mount_pads,
)
from repro.sim import barrett as B
from repro.sim.barrett import BarrettHandDrive, FingerMotors
from repro.sim.episode import Episode, Observation, StepResult, View, run_episode
from repro.sim.robot import JointSet, Robot
from repro.sim.scene import Part, Scene, pose_json
from repro.sim.world import World, WorldConfig, pb_to_pose, pose_to_pb

__all__ = [
    "EXPERIMENTS_EXP3", "PRESSURE_IMAGES", "BarrettHandDrive", "Exp3Config", "Exp3Controller",
    "Exp3NoTactileConfig", "FingerMotors", "FingerTorqueSensor", "GraspAudit", "build",
    "check_config", "declare_columns", "plan_contact_motor_angles", "run",
]

PAPER = "pomares2011"
EXPERIMENTS_EXP3 = ("exp3", "exp3_no_tactile")
FINGERS = B.FINGERS
N_FINGERS = len(FINGERS)
DT = 1.0e-3  # physics = control step [s]; the brief's 1 kHz (FingerDrive needs every step)

#: The hand's base in the world: palm facing down (hand z = world -z, hand x = world x), the
#: mounting face 0.40 m above the world origin. ours: any height clear of the support.
T_WORLD_HAND = make_T(np.diag([1.0, -1.0, -1.0]), (0.0, 0.0, 0.40))
#: Colours (rendered frames of Fig. 11 only).
CYLINDER_RGBA = (0.85, 0.55, 0.20, 1.0)
SUPPORT_RGBA = (0.55, 0.55, 0.60, 1.0)
#: Support rail: length along the cylinder axis, width across, height [m]. ours: 10 mm wide,
#: so that the fingertips curling under the cylinder never touch it (a 30 mm rail is touched
#: by the rounded tips, measured).
SUPPORT_SIZE = (0.10, 0.010, 0.020)
#: A finger's clutch counts as broken away when its distal is this far past 1/3 of its
#: proximal [rad]. ours: 0.5 deg, far above the ~5e-5 rad to which the gear constraint holds
#: the ratio while engaged.
BREAKAWAY_DETECT_RAD = math.radians(0.5)
#: The cylinder counts as dropped once no finger and no palm touches it and its centre is
#: this far from its pose at the start of the manipulation [m]. ours: 5 mm, twice the largest
#: displacement of a held cylinder in the runs (2.35 mm).
DROP_M = 5.0e-3


# ============================================================================ config
@dataclass(frozen=True)
class Exp3Config:
    """Experiment 3 of pomares2011 (Sec. 7.3): closing, then Algorithm 1 on a planned
    trajectory. Every value without a paper reference is ours (``# ours: <why>``)."""

    experiment: str = param("exp3", choices=EXPERIMENTS_EXP3,
                            help="exp3: with Algorithm 1; exp3_no_tactile: the same "
                                 "trajectory, one step per tick, no pressure check")
    tactile_control: bool = param(True, help="Algorithm 1 on (False: the ablation)")
    duration: float = param(40.0, unit="s", range=(0.01, 300.0), help="longest run time (the "
                            "run ends hold_s after the task ends)")  # ours: ~3x the task's length
    hold_s: float = param(2.0, unit="s", range=(0.0, 60.0), help="fingers held after the stop "
                          "(line 13) or the end of the trajectory, still logged")  # ours: does the object stay after the stop?
    # --- the cylinder and its contacts
    cylinder_radius: float = param(0.040, unit="m", range=(0.02, 0.08), help="cylinder radius")  # ours: an 80 mm cylinder; its fingertip contacts then land on the distal pads' last row (x_pad 17 mm, plan)
    cylinder_length: float = param(0.120, unit="m", range=(0.05, 0.30), help="cylinder length (along the hand's x)")  # ours: longer than the 69 mm span of fingers 1-2
    cylinder_mass: float = param(0.5, unit="kg", range=(0.01, 2.0), help="cylinder mass")  # ours: a solid 80 x 120 mm cylinder of density 0.83 g/cm^3 (hard wood, polymer); within the 2 kg per finger (facts sheet)
    palm_gap: float = param(0.005, unit="m", range=(0.0, 0.05), help="gap between the palm and the cylinder at the start (the approach's end)")  # ours: the approach stops 5 mm short of the object
    friction: float = param(1.0, range=(0.05, 2.0), help="Coulomb friction coefficient of the cylinder against the hand and the support")  # ours: rubber on wood / plastic, static 1.0 (kinetic 0.9) in GraspIt's material table (src/material.cpp, from the CRC Handbook); PyBullet has one coefficient. The pads' cover material is not given
    rolling_friction: float = param(1.0e-4, unit="m", range=(0.0, 0.01), help="PyBullet rolling friction of the cylinder (resisting torque / normal force)")  # ours: 0.1 mm, a small fraction of the ~2-3 mm contact width on a soft skin
    spinning_friction: float = param(1.0e-3, unit="m", range=(0.0, 0.01), help="PyBullet spinning (torsional) friction of the cylinder")  # ours: ~(2/3) mu a for a contact patch of radius a ~ 2.5 mm
    contact_stiffness: float = param(2000.0, unit="N/m", range=(100.0, 1.0e6), help="PyBullet contact stiffness of each contact point of the cylinder")  # ours: 0.5 mm of skin compression per N and point: a ~2-3 mm elastomer skin over the pads (no PPS figure)
    contact_damping: float = param(30.0, unit="N s/m", range=(0.1, 1.0e4), help="PyBullet contact damping of each contact point")  # ours: slightly over-damped: the 0.5 kg cylinder on ~6 such points is critically damped at 2 sqrt(6 k m) / 6 = 26 N s/m each
    # --- phase 1: automatic closing
    preshape_clearance_deg: float = param(3.0, unit="deg", range=(0.0, 30.0), help="the fingers start this far (proximal angle) before the planner's contact")  # ours: the approach leaves the fingers pre-shaped, a few mm from the object (grasp synthesis, Sec. 6)
    closing_speed_deg_s: float = param(2.0, unit="deg/s", range=(0.1, 140.0), help="closing speed of the proximal joints")  # ours: slow enough that the force grows only ~0.5 N (~3 kPa) between two 30 Hz samples (the hand's own maximum: 140 deg/s)
    grasp_kpa: tuple[float, float, float] = param((10.0, 10.0, 20.0), unit="kPa", range=(0.7, 140.0), help="a closing finger stops when its maximum pressure reaches this")  # ours: the readjust thresholds: the automatic closing goes on "until the object is restrained by the fingers" (Sec. 6), i.e. until each finger presses with the pressure the task asks of it
    support_delay_s: float = param(0.3, unit="s", range=(0.0, 10.0), help="delay between the last finger's stop and the lowering of the support")  # ours: lets the last finger's contact settle (~10 ticks)
    support_drop_m: float = param(0.05, unit="m", range=(0.005, 0.5), help="how far the support rail is lowered")  # ours: far below the fingertips
    support_speed_m_s: float = param(0.05, unit="m/s", range=(0.001, 1.0), help="lowering speed of the support")  # ours: the weight comes onto the fingers in ~0.2 s
    settle_s: float = param(1.0, unit="s", range=(0.0, 10.0), help="wait after the support is down before the trajectory starts")  # ours: the cylinder settles in the fingers within ~0.5 s (measured)
    # --- phase 2: the planned trajectory
    translation_m: float = param(0.020, unit="m", range=(0.0005, 0.04), help="planned translation of the cylinder towards fingers 1-2 (hand -y), perpendicular to the fingers")  # ours: half the cylinder's radius; the direction in which finger 3's contact moves towards its pad's edge, the paper's situation at the stop (Sec. 7.3)
    n_steps: int = param(80, range=(1, 2000), help="trajectory steps after the initial grasp (step 0)")  # ours: 0.25 mm of translation per step
    readjust_threshold_kpa: tuple[float, float, float] = param(
        PAPER_READJUST_THRESHOLD_KPA, unit="kPa", range=(0.7, 140.0),
        help="readjustThres per finger (Sec. 7.3: 10, 10, 20 kPa)")
    safety_threshold_kpa: tuple[float, float, float] = param(
        PAPER_SAFETY_THRESHOLD_KPA, unit="kPa", range=(0.7, 140.0),
        help="safetyThres per finger (Sec. 7.3: 10 kPa, stated for finger 3)")  # ours: 10 kPa for fingers 1-2 too
    max_readjustments: int = param(5, range=(0, 100), help="NUM_MAX_READJUSTMENTS per finger and step")  # ours: the paper gives none; 5 ticks = 0.17 s per finger and step
    increment_counts: int = param(50, unit="counts", range=(1, 5000), help="the readjustment of line 7: motor counts added to the finger's target")  # ours: 0.077 rad of motor = 0.035 deg of the proximal, ~0.06 mm at the fingertip: ~0.25 N, ~2 kPa (3 sensitivity steps), a "small increment"
    max_torque_nm: float = param(0.8, unit="N m", range=(0.01, 5.0), help="maximum allowable torque of line 7 (largest |joint motor torque| of the finger)")  # ours: 75 % of the TorqueSwitch breakaway (1.07 N m): readjustments stop before the clutch slips and decouples the joints from the counts (an increment can still push a transient past it, measured)
    carry_readjustments: bool = param(True, help="the increments stay on top of the later trajectory steps")  # ours: Fig. 12 shows finger 2 staying above its threshold for 8 s after its readjustments, so they were kept
    tactile_period_ms: int = param(33, unit="ms", range=(1, 1000), help="tactile sampling period = Algorithm-1 tick")  # pomares2011 Sec. 7: "30 Hz (i.e., 33 ms for each execution step)"; an integer number of 1 ms physics steps
    log_every: int = param(11, range=(1, 1000), help="control steps between trace rows (a divisor of tactile_period_ms: every tick is a row)")  # ours: 91 Hz rows, 3 per tick
    snapshot_period: float = param(0.25, unit="s", range=(0.0, 60.0), help="period of the rendered snapshots for Fig. 11 (0: none)", output_only=True)  # ours: Fig. 11's frames are the nearest snapshots to chosen instants
    seed: int = param(0, range=(0, 2**31 - 1), help="seed (nothing is random in this run)")
    video: bool = param(False, help="also write an animated GIF of the run (video.gif)",
                        output_only=True)


@dataclass(frozen=True)
class Exp3NoTactileConfig(Exp3Config):
    """Ablation (the paper argues, does not show): the same closing and the same planned
    trajectory, one step per 33 ms tick, with no pressure check, no readjustment, no stop."""

    experiment: str = param("exp3_no_tactile", choices=EXPERIMENTS_EXP3,
                            help="exp3: with Algorithm 1; exp3_no_tactile: the same "
                                 "trajectory, one step per tick, no pressure check")
    tactile_control: bool = param(False, help="Algorithm 1 on (False: the ablation)")


#: Largest planned translation per trajectory step [m]: a step must be done well within one
#: 33 ms tick (the controller passes ``settled=True`` to Algorithm 1). ours: 1 mm.
MAX_STEP_M = 1.0e-3


def check_config(config: Exp3Config) -> None:
    """Reject a malformed config before anything is written."""
    validate(config)
    if (config.experiment == "exp3") != bool(config.tactile_control):
        raise ConfigError(f"pomares2011 {config.experiment} has tactile_control="
                          f"{'true' if config.experiment == 'exp3' else 'false'} (got "
                          f"{config.tactile_control}); the other value is the other experiment")
    if config.tactile_period_ms % config.log_every:
        raise ConfigError(f"log_every = {config.log_every} must divide tactile_period_ms = "
                          f"{config.tactile_period_ms} (every Algorithm-1 tick is then a trace "
                          "row)")
    check_manipulation(config)


def check_manipulation(config: Exp3Config) -> None:
    """The checks of the manipulation's fields (experiment 3 and the whole task)."""
    for f, (s, r) in enumerate(zip(config.safety_threshold_kpa, config.readjust_threshold_kpa,
                                   strict=True)):
        if s > r:
            raise ConfigError(f"safety_threshold_kpa[{f}] = {s} kPa exceeds "
                              f"readjust_threshold_kpa[{f}] = {r} kPa")
    if config.translation_m / config.n_steps > MAX_STEP_M:
        raise ConfigError(f"translation_m / n_steps = {config.translation_m / config.n_steps:.4g}"
                          f" m per step exceeds {MAX_STEP_M} m: use more steps")
    if config.cylinder_length < 2 * (B.BH8_AW + 0.5 * B.BH8_GEOMETRY.distal_box[2]) + 0.01:
        raise ConfigError(f"cylinder_length = {config.cylinder_length} m must exceed the span of "
                          "fingers 1-2 (69 mm) by 10 mm")


def cylinder_centre_height(config: Exp3Config) -> float:
    """Nominal height of the cylinder's axis above the hand's mounting face, along the hand's
    z [m]: palm surface + gap + radius."""
    return B.BH8_GEOMETRY.palm_height + config.palm_gap + config.cylinder_radius


def planned_dy(config: Exp3Config) -> np.ndarray:
    """(n_steps + 1,) planned displacement of the cylinder along the hand's y [m] per step,
    step 0 = the initial grasp; towards fingers 1-2 (negative)."""
    return -np.linspace(0.0, config.translation_m, config.n_steps + 1)


# ============================================================================ the planner
def plan_contact_motor_angles(radius: float, length: float, z_centre: float,
                              dys: Sequence[float] | np.ndarray) -> np.ndarray:
    """Our stand-in for the geometric planner of [25] (kinematics and contact maintenance,
    no forces): the motor angle [rad] at which each finger, closing with its clutch engaged
    (``q_p = m / 125``, ``q_d = m / 375``), first touches the cylinder at each planned pose.

    In a DIRECT client of its own: the BH8 URDF at the identity, a static cylinder of
    ``radius``, ``length`` [m] with its axis along the hand's x through ``(0, dy, z_centre)``
    (hand frame, [m]); per pose and finger, a bisection (40 halvings) on the motor angle of
    the signed distance between the finger's proximal and distal links and the cylinder
    (PyBullet closest points), the other fingers open.

    Returns:
        (len(dys), 3) motor angles [rad] of fingers 1, 2, 3.

    Raises:
        ConfigError: a pose the finger does not reach before its proximal's 139 deg.
    """
    out = np.zeros((len(dys), N_FINGERS))
    with World(WorldConfig(physics_dt=DT, control_dt=DT)) as world:
        c = world.client
        body = p.loadURDF(str(B.bh8_urdf_path()), useFixedBase=True,
                          flags=p.URDF_USE_IMPLICIT_CYLINDER, physicsClientId=c)
        idx = B.bh8_joint_indices(body, c)
        col = p.createCollisionShape(p.GEOM_CYLINDER, radius=radius, height=length,
                                     physicsClientId=c)
        quat = p.getQuaternionFromEuler([0.0, math.pi / 2, 0.0])
        cyl = p.createMultiBody(0.0, col, -1, [0.0, 0.0, z_centre], quat, physicsClientId=c)

        def set_motor(k: int, m: float) -> None:
            q_p, q_d = B.finger_joints_from_motor(m)
            p.resetJointState(body, idx[f"bh8_finger{k}_proximal_joint"], q_p,
                              physicsClientId=c)
            p.resetJointState(body, idx[f"bh8_finger{k}_distal_joint"], q_d, physicsClientId=c)

        def distance(k: int) -> float:
            d = 1.0
            for link in ("proximal", "distal"):
                for pt in p.getClosestPoints(body, cyl, 0.05,
                                             linkIndexA=idx[f"bh8_finger{k}_{link}"],
                                             physicsClientId=c):
                    d = min(d, pt[8])
            return d

        m_max = B.J2_RATIO * math.radians(139.0)
        for k in FINGERS:
            set_motor(k, 0.0)
        for i, dy in enumerate(dys):
            p.resetBasePositionAndOrientation(cyl, [0.0, float(dy), z_centre], quat,
                                              physicsClientId=c)
            for k in FINGERS:
                set_motor(k, m_max)
                if distance(k) > 0.0:
                    raise ConfigError(f"planner: finger {k} does not reach the cylinder at "
                                      f"dy = {dy * 1e3:.1f} mm")
                lo, hi = 0.0, m_max
                for _ in range(40):
                    mid = 0.5 * (lo + hi)
                    set_motor(k, mid)
                    lo, hi = (mid, hi) if distance(k) > 0.0 else (lo, mid)
                out[i, k - 1] = hi
                set_motor(k, 0.0)
    return out


# ============================================================================ sensors
class FingerTorques(NamedTuple):
    """The joint motor torques of the last physics step [N m] (what the Pucks' currents give).

    Attributes:
        proximal, distal: (3,) PyBullet's applied motor torque of each finger's joints
            (engaged: the distal's motor is off, the proximal carries the gear's load).
        finger: (3,) the largest |torque| of each finger (Algorithm 1, line 7).
    """

    proximal: np.ndarray
    distal: np.ndarray
    finger: np.ndarray


class FingerTorqueSensor:
    """The fingers' joint motor torques, read every control step (episode Sensor protocol)."""

    name = "finger_torque"

    def __init__(self, hand: Robot) -> None:
        self.hand = hand
        idx = B.bh8_joint_indices(hand.body, hand.client)
        self.joints = [idx[f"bh8_finger{k}_{j}_joint"] for k in FINGERS
                       for j in ("proximal", "distal")]

    def read(self, t: float, q: Mapping[str, np.ndarray]) -> FingerTorques:
        s = p.getJointStates(self.hand.body, self.joints, physicsClientId=self.hand.client)
        tau = np.array([st[3] for st in s]).reshape(3, 2)
        return FingerTorques(tau[:, 0].copy(), tau[:, 1].copy(), np.abs(tau).max(axis=1))

    def columns(self, r: FingerTorques) -> dict[str, float]:
        out: dict[str, float] = {}
        for i in range(N_FINGERS):
            out[f"tau_prox{i + 1}"] = float(r.proximal[i])
            out[f"tau_dist{i + 1}"] = float(r.distal[i])
            out[f"tau{i + 1}"] = float(r.finger[i])
        return out

    def events(self, r: FingerTorques) -> list[tuple[str, str]]:
        return []

    def failure(self, r: FingerTorques) -> str | None:
        return None


class AuditReading(NamedTuple):
    """Ground truth of one control step (audit only: the controller never reads it)."""

    columns: dict[str, float | bool]
    touching: tuple[bool, ...]
    dropped: bool
    T_palm_cylinder: np.ndarray | None = None  # the pose read [m]


class GraspAudit:
    """Ground truth of the grasp (episode Sensor protocol; audit columns only): the
    cylinder's pose in the palm frame (``bh8_palm``) and its displacement from its pose at
    the start of the manipulation, the contacts and the raw normal forces between the hand and
    the cylinder (PyBullet contact points), the hand's distances, the drop flag. It also keeps
    the scene's record of the cylinder's pose current (the runner logs it as a moving body).

    ``reference_now``: True once the manipulation has started (read from the controller's
    phase, never the other way round): the first such step's pose is the grasp pose.
    ``lost_after``: control steps without contact before a ``finger_contact_lost`` event (ours:
    one 33 ms tick; a finger retreating by one trajectory step parts from the cylinder for a
    millisecond or two until the cylinder follows, measured).
    """

    name = "grasp_audit"

    def __init__(self, scene: Scene, hand: Robot, cylinder: str, support: str | tuple[str, ...],
                 reference_now: Callable[[], bool], lost_after: int = 33,
                 dist_of: JointSet | None = None) -> None:
        self.scene, self.hand = scene, hand
        self.cyl = scene[cylinder].ids[0]
        self.cylinder = cylinder
        self.supports = (support,) if isinstance(support, str) else tuple(support)
        self.support_ids = [scene[s].ids[0] for s in self.supports]
        #: whose distances the hand_dist_* columns are (default: the whole hand body)
        self.dist_of: JointSet = hand if dist_of is None else dist_of
        self.reference_now = reference_now
        palm = self.palm = hand.pb_link_index("bh8_palm")
        self.link_owner: dict[int, str] = {}
        for k in FINGERS:
            for part in ("proximal", "distal"):
                self.link_owner[hand.pb_link_index(f"bh8_finger{k}_{part}")] = f"finger{k}"
        self.link_owner[palm] = "palm"
        self.T_ref: np.ndarray | None = None
        self._dropped = False
        self._touch = [False] * N_FINGERS  # contact as last reported by an event
        self._apart = [0] * N_FINGERS  # control steps without contact, per finger
        self.lost_after = lost_after

    def describe(self) -> dict[str, Any]:
        """The link sets behind the audit's columns (issue 17 item 12), for scene.json."""
        c, body = self.hand.client, self.hand.body

        def name(idx: int) -> str:
            if idx == -1:
                return p.getBodyInfo(body, physicsClientId=c)[0].decode()
            return p.getJointInfo(body, idx, physicsClientId=c)[12].decode()

        fingers: dict[str, list[str]] = {}
        for idx, owner in sorted(self.link_owner.items()):
            fingers.setdefault(owner, []).append(name(idx))
        links = getattr(self.dist_of, "links", None)
        return {"contact_links": {**fingers, "meaning": "F_raw<k> / contact<k>: the contacts "
                                  "of these links of finger k; F_raw_palm: the palm's; "
                                  "F_raw_other: any other link of the body"},
                "hand_dist_links": ("every link of the body" if links is None
                                    else [name(i) for i in links]),
                "hand_dist_meaning": "hand_dist_<body>: minimum PyBullet closest-points "
                                     "distance over these links",
                "support_dist": "signed closest-points distance cylinder - support bodies "
                                f"{list(self.supports)}"}

    def read(self, t: float, q: Mapping[str, np.ndarray]) -> AuditReading:
        c = self.hand.client
        pos, quat = p.getBasePositionAndOrientation(self.cyl, physicsClientId=c)
        T_world_cyl = pb_to_pose(pos, quat)  # (the Scene keeps its own copy: refresh_dynamic)
        pos, quat = p.getLinkState(self.hand.body, self.palm, computeForwardKinematics=True,
                                   physicsClientId=c)[4:6]
        T = inv_T(pb_to_pose(pos, quat)) @ T_world_cyl  # the palm moves with an arm
        cols: dict[str, float | bool] = {}
        for a, v in zip("xyz", T[:3, 3], strict=True):
            cols[f"obj_{a}"] = float(v)
        _, q_pc = pose_to_pb(T)
        for a, v in zip(("qx", "qy", "qz", "qw"), q_pc, strict=True):
            cols[f"obj_{a}"] = float(v)
        axis = T[:3, 2]  # the cylinder's axis (its frame's z) in the palm frame
        cols["obj_axis_tilt"] = float(math.acos(min(1.0, abs(float(axis[0])))))
        if self.T_ref is not None:
            d = T[:3, 3] - self.T_ref[:3, 3]
            R = self.T_ref[:3, :3].T @ T[:3, :3]
            rot = float(math.acos(max(-1.0, min(1.0, 0.5 * (np.trace(R) - 1.0)))))
        else:
            d, rot = np.full(3, np.nan), float("nan")
        for a, v in zip("xyz", d, strict=True):
            cols[f"obj_d{a}"] = float(v)
        cols["obj_disp"] = float(np.linalg.norm(d))
        cols["obj_rot"] = rot
        force = dict.fromkeys([f"finger{k}" for k in FINGERS] + ["palm", "other"], 0.0)
        for cp in p.getContactPoints(bodyA=self.cyl, bodyB=self.hand.body, physicsClientId=c):
            force[self.link_owner.get(cp[4], "other")] += float(cp[9])
        on_support = any(len(p.getContactPoints(bodyA=self.cyl, bodyB=sid,
                                                physicsClientId=c)) > 0
                         for sid in self.support_ids)
        touching = tuple(force[f"finger{k}"] > 0.0 for k in FINGERS)
        for k in FINGERS:
            cols[f"contact{k}"] = touching[k - 1]
            cols[f"F_raw{k}"] = force[f"finger{k}"]
        cols["contact_palm"] = force["palm"] > 0.0
        cols["contact_other"] = force["other"] > 0.0
        cols["contact_support"] = on_support
        cols["support_dist"] = support_distance(c, self.cyl, self.support_ids)
        cols["F_raw_palm"] = force["palm"]
        cols["F_raw_other"] = force["other"]
        cols["F_raw_total"] = float(sum(force.values()))
        dists = self.scene.distances(self.dist_of)
        for body in (self.cylinder, *self.supports):
            cols[f"hand_dist_{body}"] = dists[body]
        cols["hand_dist_min"] = min(dists[b] for b in self.supports)
        dropped = bool(self.T_ref is not None and not any(touching) and force["palm"] == 0.0
                       and not on_support and cols["obj_disp"] > DROP_M)
        cols["dropped"] = dropped
        return AuditReading(cols, touching, dropped, T)

    def columns(self, r: AuditReading) -> dict[str, float | bool]:
        return r.columns

    def after_control(self, r: AuditReading) -> dict[str, float]:
        """Called by the runner after the controller of the same step: if that controller
        has just started the manipulation, this step's pose (read before it: the state it
        started from) becomes the reference, and the row gets zero displacement and rotation
        (issue 17: the reference used to be the next step's pose, the start row NaN)."""
        if self.T_ref is None and r.T_palm_cylinder is not None and self.reference_now():
            self.T_ref = r.T_palm_cylinder.copy()
            return {"obj_dx": 0.0, "obj_dy": 0.0, "obj_dz": 0.0, "obj_disp": 0.0,
                    "obj_rot": 0.0}
        return {}

    def events(self, r: AuditReading) -> list[tuple[str, str]]:
        out = []
        for f, now in enumerate(r.touching):
            self._apart[f] = 0 if now else self._apart[f] + 1
            if now and not self._touch[f]:
                self._touch[f] = True
                out.append(("finger_contact", f"audit: finger {f + 1} touches the cylinder"))
            elif self._touch[f] and self._apart[f] == self.lost_after:
                self._touch[f] = False
                out.append(("finger_contact_lost", f"audit: finger {f + 1} has not touched the "
                            f"cylinder for {self.lost_after} control steps (PyBullet contact "
                            "points)"))
        if r.dropped and not self._dropped:
            out.append(("object_dropped", f"audit: the cylinder touches no finger, no palm and "
                        f"no support and is {float(r.columns['obj_disp']) * 1e3:.1f} mm from "
                        "its pose at the start of the manipulation"))
        self._dropped = r.dropped
        return out

    def failure(self, r: AuditReading) -> str | None:
        return None


# ============================================================================ columns
def declare_hand_joint_columns(cols: Columns) -> Columns:
    """``hand_q{i}``: the measured angle of each of the standalone hand's eight joints (its
    q columns in scene.json; the runner logs the finger motors)."""
    for i, j in enumerate(B.BH8_JOINTS, start=1):
        cols.add(f"hand_q{i}", "rad", f"measured angle of hand joint {i} ({j}; PyBullet joint "
                 "state)")
    return cols


def hand_joint_values(q_hand: np.ndarray) -> dict[str, float]:
    """The ``hand_q{i}`` values of the hand's joint angles ``q_hand`` (8,) [rad]."""
    return {f"hand_q{i}": float(v) for i, v in enumerate(q_hand, start=1)}


#: Phases of the controller (column ``phase``).
PHASES = {
    "waiting": "the whole task only: the approach is on, the finger motors hold (Table 1)",
    "preshape": "the whole task only: the fingers move to the pre-shape at preshape_speed",
    "closing": "automatic closing: fingers close until each one's pressure reaches grasp_kpa "
               "(or its clutch breaks away)",
    "support": "every finger stopped: held while the support is lowered and the cylinder "
               "settles in the fingers",
    "manipulation": "the planned trajectory, under Algorithm 1 (or open loop in the ablation)",
    "stopped": "Algorithm 1 line 13 ended the task: fingers held",
    "done": "every trajectory step executed: fingers held",
}
#: Per-finger decision of an Algorithm-1 tick (column ``alg_decision{i}``).
DECISIONS = ("", "ok", "readjust", "readjust_blocked_torque", "give_up_continue", "stop")


def declare_columns(hand_joints: bool = True, supports: tuple[str, ...] = ("support",)
                    ) -> Columns:
    """The experiment's own columns (the runner adds ``t``, ``motor_*``, the pose columns of
    the cylinder and the support; the tactile sensor its ``tac_*``); ``hand_joints``: also
    ``hand_q{i}`` (False: someone else declares them); ``supports``: the support bodies."""
    cols = Columns()
    cols.add("phase", "text", "controller phase: " + "; ".join(f"{k}: {v}"
                                                                for k, v in PHASES.items()))
    if hand_joints:
        declare_hand_joint_columns(cols)
    cols.add("counts{i}", "counts", "motor counts of finger {i}: measured motor angle "
             "motor_q{i} x 4096 / (2 pi) (pomares2011 Fig. 12a)", n=N_FINGERS)
    cols.add("cmd_counts{i}", "counts", "commanded motor target of finger {i} in counts "
             "(motor_u{i} x 4096 / (2 pi))", n=N_FINGERS)
    cols.add("p{i}", "kPa", "maximum reported pressure of finger {i} over its two pads "
             "(proximal, distal), the held 30 Hz sample: Algorithm 1's p", n=N_FINGERS)
    cols.add("Fmap_total", "N", "total normal force implied by the seven reported pressure "
             "maps, sum of tac_<pad>_Fmap (compare the audit F_raw_total)")
    cols.add("closed{i}", "bool", "finger {i} has stopped closing (phase 1)", n=N_FINGERS)
    cols.add("broken_away{i}", "bool", "finger {i}'s TorqueSwitch has broken away, from the "
             f"measured joints: q_distal - q_proximal / 3 > {math.degrees(BREAKAWAY_DETECT_RAD)}"
             " deg", n=N_FINGERS)
    cols.add("plan_step", "-", "trajectory step last commanded, 0-based (-1: none)")
    cols.add("plan_dy", "m", "planned displacement of the cylinder along the palm's y at that "
             "step (negative: towards fingers 1-2; NaN before the trajectory)")
    cols.add("tick", "bool", "an Algorithm-1 tick happened at this row (a new tactile sample "
             "during the manipulation)")
    for name, (unit, definition) in LOG_FIELDS.items():
        if name == "tactile_state":
            definition += "; off: tactile control disabled (the ablation)"
        cols.add(name, unit, definition + " (Algorithm 1, repro.control.tactile_control)",
                 n=N_FINGERS if "{i}" in name else None)
    cols.add("alg_decision{i}", "text", "decision of this tick on finger {i} (empty: finger "
             "not checked): " + ", ".join(d for d in DECISIONS if d), n=N_FINGERS)
    cols.add("alg_p{i}", "kPa", "the pressure p of finger {i} that decision used (NaN: not "
             "checked at this tick)", n=N_FINGERS)
    cols.add("alg_num_readjust{i}", "-", "numReadjust of finger {i} right after that decision "
             "(-1: not checked at this tick)", n=N_FINGERS)
    cols.add("tau_prox{i}", "N m", "applied motor torque of finger {i}'s proximal joint, last "
             "physics step (PyBullet joint state)", n=N_FINGERS)
    cols.add("tau_dist{i}", "N m", "applied motor torque of finger {i}'s distal joint (0 "
             "while engaged: its motor is off)", n=N_FINGERS)
    cols.add("tau{i}", "N m", "largest |joint torque| of finger {i}: what line 7 compares with "
             "max_torque_nm", n=N_FINGERS)
    audit = "audit (PyBullet ground truth, never read by the controller): "
    for a in "xyz":
        cols.add(f"obj_{a}", "m", audit + f"{a} of the cylinder's centre in the palm frame "
                 "bh8_palm (z out of the palm, axes of bh8_base)", audit=True)
    for a in ("qx", "qy", "qz", "qw"):
        cols.add(f"obj_{a}", "-", audit + "orientation of the cylinder frame (z = its axis) in "
                 "the palm frame, quaternion xyzw", audit=True)
    cols.add("obj_axis_tilt", "rad", audit + "angle between the cylinder's axis and the palm's "
             "x axis", audit=True)
    for a in "xyz":
        cols.add(f"obj_d{a}", "m", audit + f"displacement along the palm's {a} of the cylinder's "
                 "centre from its pose at the start of the manipulation (NaN before)", audit=True)
    cols.add("obj_disp", "m", audit + "norm of (obj_dx, obj_dy, obj_dz)", audit=True)
    cols.add("obj_rot", "rad", audit + "rotation angle of the cylinder since the start of the "
             "manipulation (in the palm frame)", audit=True)
    for k in FINGERS:
        cols.add(f"contact{k}", "bool", audit + f"finger {k}'s proximal or distal link touches "
                 "the cylinder", audit=True)
        cols.add(f"F_raw{k}", "N", audit + f"sum of the PyBullet normal forces between finger "
                 f"{k}'s proximal and distal links and the cylinder", audit=True)
    cols.add("contact_palm", "bool", audit + "the palm plate touches the cylinder", audit=True)
    cols.add("contact_other", "bool", audit + "another hand link (knuckle, base) touches the "
             "cylinder", audit=True)
    cols.add("contact_support", "bool", audit + "the support rail touches the cylinder",
             audit=True)
    cols.add("support_dist", "m", audit + "signed distance cylinder - support rail (PyBullet "
             "closest points; < 0: the soft contact's deflection under the weight; capped at "
             "0.05 m)", audit=True)
    cols.add("F_raw_palm", "N", audit + "normal force palm - cylinder", audit=True)
    cols.add("F_raw_other", "N", audit + "normal force other hand links - cylinder", audit=True)
    cols.add("F_raw_total", "N", audit + "sum of every normal force between the hand and the "
             "cylinder (compare Fmap_total, from the pressure maps)", audit=True)
    for body in ("cylinder", *supports, "min"):
        what = ("minimum over the obstacles (the supports)" if body == "min" else
                f"minimum distance between the whole hand and {body}")
        cols.add(f"hand_dist_{body}", "m", audit + what + " (PyBullet closest points; < 0 "
                 "penetration)", audit=True)
    cols.add("dropped", "bool", audit + "no finger, no palm and no support touches the "
             f"cylinder and it is more than {DROP_M * 1e3:g} mm from its pose at the start of "
             "the manipulation", audit=True)
    return cols


# ============================================================================ controller
class Exp3Controller:
    """Closing, then the planned trajectory under Algorithm 1 (or open loop); the episode
    runner's controller (``__call__``). Reads only the tactile pads, the finger torques and
    the measured joints; no simulator inside.

    Args:
        config: the experiment.
        preshape: (3,) motor angles of the pre-shape [rad] (the fingers' start).
        plan: (n_steps + 1, 3) the planner's contact motor angles [rad]; the trajectory is the
            grasp's motor targets plus ``plan - plan[0]``.
    """

    def __init__(self, config: Exp3Config, preshape: np.ndarray, plan: np.ndarray,
                 hand_body: str = "hand", hand_idx: np.ndarray | None = None,
                 start: np.ndarray | None = None, preshape_rate: float = 0.0,
                 hand_columns: bool = True) -> None:
        self.config = config
        self.plan = np.asarray(plan, dtype=float)
        self.dy = planned_dy(config)
        #: the body whose q holds the hand's joints, and their positions in it
        self.hand_body = hand_body
        self.hand_idx = (np.arange(len(B.BH8_JOINTS)) if hand_idx is None
                         else np.asarray(hand_idx))
        self.preshape = np.asarray(preshape, dtype=float).copy()
        #: the pre-shaping speed of every motor [rad/s] (phase ``preshape``)
        self.preshape_rate = float(preshape_rate)
        #: write ``hand_q{i}`` (False: the runner logs the hand's joints, a joint group)
        self.hand_columns = hand_columns
        if start is None:  # experiment 3: the fingers start pre-shaped, closing
            self.targets, self.phase = self.preshape.copy(), "closing"
        else:  # the whole task: the fingers hold ``start`` until begin()
            self.targets, self.phase = np.asarray(start, dtype=float).copy(), "waiting"
            if self.preshape_rate <= 0.0:
                raise ConfigError("a hand that starts elsewhere needs preshape_rate > 0")
        self.closed = np.zeros(N_FINGERS, dtype=bool)
        self.t_grasp: float | None = None
        self.t_manipulation: float | None = None
        self.t_end: float | None = None
        self.trajectory: np.ndarray | None = None
        self.tactile: TactileController | None = None
        self.step_i = -1  # open loop: trajectory step last sent
        self.closing_rate = B.J2_RATIO * math.radians(config.closing_speed_deg_s)  # [rad/s]
        self.tactile_cfg = TactileControlConfig(
            readjust_threshold_kpa=tuple(config.readjust_threshold_kpa),
            safety_threshold_kpa=tuple(config.safety_threshold_kpa),
            max_readjustments=config.max_readjustments,
            increment=B.counts_to_motor_angle(config.increment_counts),
            max_torque_nm=config.max_torque_nm,
            carry_readjustments=config.carry_readjustments)
        self.broken = np.zeros(N_FINGERS, dtype=bool)
        #: Every tactile sample: (t [s], {pad: reported pressures [kPa]}) (pressure_images.npz).
        self.samples: list[tuple[float, dict[str, np.ndarray]]] = []
        #: Chosen instants for the pressure images: name -> time [s].
        self.instants: dict[str, float] = {}

    def begin(self, t: float, events: list[tuple[str, str]]) -> None:
        """End of the approach (the whole task): pre-shape, then close."""
        if self.phase != "waiting":
            raise ConfigError(f"begin() in phase {self.phase!r}: the hand has already begun")
        self.phase = "preshape"
        self.instants["hand_start"] = t
        events.append(("hand_preshape", f"fingers move from {np.round(self.targets, 2).tolist()}"
                       f" to the pre-shape {np.round(self.preshape, 2).tolist()} rad of motor"))

    @property
    def manipulating(self) -> bool:
        return self.phase == "manipulation"

    @property
    def t_support(self) -> float | None:
        """When the support starts going down [s] (None: not yet)."""
        return None if self.t_grasp is None else self.t_grasp + self.config.support_delay_s

    def support_offset(self, t: float) -> float:
        """How far the support has been lowered at ``t`` [m]."""
        t0 = self.t_support
        if t0 is None or t <= t0:
            return 0.0
        return min(self.config.support_drop_m, (t - t0) * self.config.support_speed_m_s)

    @staticmethod
    def finger_pressures(r: TactileReading) -> np.ndarray:
        """Algorithm 1's p of each finger: the max over its proximal and distal pads [kPa]."""
        return np.array([max(r.pads[f"finger{k}_proximal"].p_max,
                             r.pads[f"finger{k}_distal"].p_max) for k in FINGERS])

    def _start_manipulation(self, t: float, events: list[tuple[str, str]]) -> None:
        self.phase = "manipulation"
        self.t_manipulation = t
        self.instants["manipulation_start"] = t
        self.trajectory = self.targets[None, :] + self.plan - self.plan[0]
        if self.config.tactile_control:
            self.tactile = TactileController(self.tactile_cfg, self.trajectory)
        events.append(("manipulation_start", f"{self.config.n_steps} steps, planned "
                       f"translation {self.config.translation_m * 1e3:.1f} mm towards fingers "
                       f"1-2; tactile control {'on' if self.config.tactile_control else 'off'}"))

    def _end(self, t: float, phase: str, events: list[tuple[str, str]], kind: str,
             detail: str) -> None:
        self.phase, self.t_end = phase, t
        self.instants[phase] = t
        events.append((kind, detail))

    def __call__(self, obs: Observation) -> StepResult:
        cfg, t = self.config, obs.t
        reading: TactileReading = obs.sensors["tactile"]
        torque: FingerTorques = obs.sensors["finger_torque"]
        q_hand = obs.q[self.hand_body][self.hand_idx]
        events: list[tuple[str, str]] = []
        p_f = self.finger_pressures(reading)
        if reading.new:
            self.samples.append((float(reading.t), {n: r.pressure.astype(np.float32)
                                                     for n, r in reading.pads.items()}))
        q_p = q_hand[[B.BH8_JOINTS.index(j) for j in B.BH8_PROXIMAL_JOINTS]]
        q_d = q_hand[[B.BH8_JOINTS.index(j) for j in B.BH8_DISTAL_JOINTS]]
        broken = (q_d - q_p / 3.0) > BREAKAWAY_DETECT_RAD
        for k in np.flatnonzero(broken & ~self.broken):
            events.append(("breakaway", f"finger {k + 1}: distal {math.degrees(q_d[k]):.2f} deg "
                           f"> proximal / 3 = {math.degrees(q_p[k]) / 3:.2f} deg (TorqueSwitch "
                           "broke away)"))
        self.broken = broken
        decisions: dict[int, tuple[str, float, int]] = {}
        tick = False
        if self.phase == "preshape":
            step = self.preshape_rate * DT
            self.targets = self.targets + np.clip(self.preshape - self.targets, -step, step)
            if np.array_equal(self.targets, self.preshape):
                self.phase = "closing"
                events.append(("preshape_done", "fingers pre-shaped: automatic closing"))
        elif self.phase == "closing":
            if reading.new:
                grasp = np.asarray(cfg.grasp_kpa, dtype=float)
                for f in np.flatnonzero(~self.closed & ((p_f >= grasp) | broken)):
                    self.closed[f] = True
                    events.append(("finger_closed", f"finger {f + 1} stops closing: p = "
                                   f"{p_f[f]:.1f} kPa{' (broken away)' if broken[f] else ''}"))
            self.targets = self.targets + np.where(self.closed, 0.0, self.closing_rate * DT)
            if self.closed.all():
                self.phase, self.t_grasp = "support", t
                self.instants["grasp"] = t
                events.append(("grasp_closed", f"every finger presses the cylinder (p = "
                               f"{np.round(p_f, 1).tolist()} kPa); support lowered from "
                               f"t = {t + cfg.support_delay_s:.3f} s"))
        elif self.phase == "support":
            assert self.t_support is not None
            t_go = (self.t_support + cfg.support_drop_m / cfg.support_speed_m_s + cfg.settle_s)
            if reading.new and t >= t_go:
                self._start_manipulation(t, events)
        if self.manipulating and reading.new:
            tick = True
            assert self.trajectory is not None
            if self.tactile is not None:
                # ours: settled=True: a step (<= MAX_STEP_M of translation, a few tenths of a
                # motor radian) or an increment is done by the motor well within the 33 ms tick
                # (trapezoid: 0.3 rad in 14 ms), so the reading never sees a moving command.
                res = self.tactile.step(p_f, torque.finger, settled=True)
                self.targets = res.targets
                self.step_i = self.tactile.i
                for d in res.decisions:
                    if d.f >= 0:
                        decisions[d.f] = (d.action, d.p_kpa, d.num_readjust)
                    if d.action in ("readjust", "readjust_blocked_torque"):
                        self.instants.setdefault(f"first_readjust{d.f + 1}", t)
                    if d.action == "readjust_blocked_torque":
                        events.append(("readjust_blocked_torque", f"finger {d.f + 1}: |tau| = "
                                       f"{d.torque_nm:.3f} N m > {cfg.max_torque_nm} N m at step "
                                       f"{d.i}: increment skipped (line 7)"))
                    if d.action == "give_up_continue":
                        events.append(("readjust_give_up", f"finger {d.f + 1}: p = "
                                       f"{d.p_kpa:.1f} kPa after {d.num_readjust} readjustments "
                                       f"at step {d.i}, >= safety: next finger (line 12)"))
                if res.state == "stopped":
                    d = res.decisions[-1]
                    self._end(t, "stopped", events, "tactile_stop",
                              f"line 13: finger {d.f + 1} p = {d.p_kpa:.1f} kPa < safety "
                              f"{cfg.safety_threshold_kpa[d.f]} kPa after {d.num_readjust} "
                              f"readjustments at step {d.i} of {cfg.n_steps}")
                elif res.state == "done":
                    self._end(t, "done", events, "trajectory_done", f"all {cfg.n_steps + 1} "
                              "steps executed under Algorithm 1")
            else:  # the ablation: one step per tick, no check
                if self.step_i < cfg.n_steps:
                    self.step_i += 1
                    self.targets = self.trajectory[self.step_i].copy()
                else:
                    self._end(t, "done", events, "trajectory_done", f"all {cfg.n_steps + 1} "
                              "steps executed open loop (no tactile control)")
        stop = None
        if self.t_end is not None and t >= self.t_end + cfg.hold_s:
            stop = ("task_end", f"task {self.phase} at t = {self.t_end:.3f} s, held "
                    f"{cfg.hold_s} s")
            self.instants["end"] = t
        return StepResult({"fingers": self.targets.copy()},
                          self._columns(obs, p_f, torque, decisions, tick), events, stop)

    def _columns(self, obs: Observation, p_f: np.ndarray, torque: FingerTorques,
                 decisions: Mapping[int, tuple[str, float, int]], tick: bool
                 ) -> dict[str, float | int | str | bool]:
        reading: TactileReading = obs.sensors["tactile"]
        cols: dict[str, float | int | str | bool] = {"phase": self.phase, "tick": tick}
        if self.hand_columns:
            cols.update(hand_joint_values(obs.q[self.hand_body][self.hand_idx]))
        for i in range(N_FINGERS):
            cols[f"counts{i + 1}"] = B.motor_angle_to_counts(float(obs.q["fingers"][i]))
            cols[f"cmd_counts{i + 1}"] = B.motor_angle_to_counts(float(self.targets[i]))
            cols[f"p{i + 1}"] = float(p_f[i])
            cols[f"closed{i + 1}"] = bool(self.closed[i])
            cols[f"broken_away{i + 1}"] = bool(self.broken[i])
            action, p_used, num = decisions.get(i, ("", float("nan"), -1))
            cols[f"alg_decision{i + 1}"] = action
            cols[f"alg_p{i + 1}"] = float(p_used)
            cols[f"alg_num_readjust{i + 1}"] = int(num)
        cols["Fmap_total"] = float(sum(r.force_map for r in reading.pads.values()))
        cols["plan_step"] = int(self.step_i)
        cols["plan_dy"] = float(self.dy[self.step_i]) if self.step_i >= 0 else float("nan")
        if self.tactile is not None:
            cols.update(self.tactile.log_row())
        else:
            off = not self.config.tactile_control and self.t_manipulation is not None
            cols.update(_idle_log_row("off" if off else "start"))
        return cols


def _idle_log_row(state: str) -> dict[str, Any]:
    """The Algorithm-1 columns while no TactileController runs (before the manipulation, or
    the ablation: state ``off``)."""
    row: dict[str, Any] = {"tactile_state": state, "tactile_action": "", "tactile_line": 0,
                           "tactile_step": -1, "tactile_finger": -1, "tactile_steps_sent": 0}
    for name in LOG_FIELDS:
        if "{i}" in name:
            for k in FINGERS:
                row[name.replace("{i}", str(k))] = float("nan") if "target" in name else 0
    return row


# ============================================================================ scene, run
#: What ``pressure_images.npz`` holds (also written to scene.json).
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
                 movers={"support": support_pose}, video=config.video, video_every=33,
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


def config_for(name: str) -> Exp3Config:
    """The default config of ``exp3`` or ``exp3_no_tactile``."""
    if name not in EXPERIMENTS_EXP3:
        raise ConfigError(f"unknown pomares2011 experiment 3 run {name!r}; valid: "
                          f"{', '.join(EXPERIMENTS_EXP3)}")
    return Exp3Config() if name == "exp3" else Exp3NoTactileConfig()

