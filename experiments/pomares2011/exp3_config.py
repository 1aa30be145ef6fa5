"""pomares2011 experiment 3: its configuration, constants and config checks (split
from ``exp3.py``, whose docstring describes the experiment)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from repro.config import param, validate
from repro.control.tactile_control import (
    PAPER_READJUST_THRESHOLD_KPA,
    PAPER_SAFETY_THRESHOLD_KPA,
)
from repro.errors import ConfigError
from repro.geometry import make_T
from repro.sim import barrett as B
from repro.sweep_ranges import SweepRange

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


#: The cylinder's size, the grasp height and the trajectory length are swept in experiment 3
#: and its ablation only: the whole task's layout (IK, desired features) is solved for one.
EXP3_ONLY = (("experiment", frozenset(EXPERIMENTS_EXP3)),)


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
    cylinder_radius: float = param(0.040, unit="m", range=(0.02, 0.08), help="cylinder radius",
        sweep=SweepRange(0.030, 0.050, when=EXP3_ONLY, reason="Sec. 7.3 and Fig. 11 name 'a cylinder' held by the three fingers, no size: a hand-sized one of 60-100 mm diameter (a drink can's 66 mm to a jar's 100 mm); the planner reaches every planned pose over this range with every swept grasp height and trajectory length"))  # ours: an 80 mm cylinder; its fingertip contacts then land on the distal pads' last row (x_pad 17 mm, plan)
    cylinder_length: float = param(0.120, unit="m", range=(0.05, 0.30), help="cylinder length (along the hand's x)",
        sweep=SweepRange(0.090, 0.200, when=EXP3_ONLY, reason="no length given: from 90 mm (the span of fingers 1-2, 69 mm, plus the 10 mm the config check asks, rounded up) to a 200 mm bottle"))  # ours: longer than the 69 mm span of fingers 1-2
    cylinder_mass: float = param(0.5, unit="kg", range=(0.01, 2.0), help="cylinder mass",
        sweep=SweepRange(0.1, 1.0, dist="log-uniform", reason="an 80 x 120 mm cylinder from thin-walled plastic (~0.1 kg) to solid dense polymer (1.2 g/cm^3: 0.72 kg), rounded up; under the BH8's 2 kg per finger"))  # ours: a solid 80 x 120 mm cylinder of density 0.83 g/cm^3 (hard wood, polymer); within the 2 kg per finger (facts sheet)
    palm_gap: float = param(0.005, unit="m", range=(0.0, 0.05), help="gap between the palm and the cylinder at the start (the approach's end): the grasp height",
        sweep=SweepRange(0.0, 0.015, when=EXP3_ONLY, reason="Sec. 6: the hand ends the approach 'situated over this object'; from touching the palm to 15 mm over it (three times our 5 mm; about the fingertip's 13 mm thickness)"))  # ours: the approach stops 5 mm short of the object
    friction: float = param(1.0, range=(0.05, 2.0), help="Coulomb friction coefficient of the cylinder against the hand and the support",
        sweep=SweepRange(0.5, 1.5, reason="dry rubber (the pads' skin) on wood or plastic: static coefficients of 0.5-1.5 in engineering tables; GraspIt's rubber table gives 1.0"))  # ours: rubber on wood / plastic, static 1.0 (kinetic 0.9) in GraspIt's material table (src/material.cpp, from the CRC Handbook); PyBullet has one coefficient. The pads' cover material is not given
    rolling_friction: float = param(1.0e-4, unit="m", range=(0.0, 0.01), help="PyBullet rolling friction of the cylinder (resisting torque / normal force)")  # ours: 0.1 mm, a small fraction of the ~2-3 mm contact width on a soft skin
    spinning_friction: float = param(1.0e-3, unit="m", range=(0.0, 0.01), help="PyBullet spinning (torsional) friction of the cylinder")  # ours: ~(2/3) mu a for a contact patch of radius a ~ 2.5 mm
    contact_stiffness: float = param(2000.0, unit="N/m", range=(100.0, 1.0e6), help="PyBullet contact stiffness of each contact point of the cylinder",
        sweep=SweepRange(500.0, 20000.0, dist="log-uniform", reason="the pads' elastomer skin from soft (2 mm per N and contact point) to hard (0.05 mm per N); the default 0.5 mm per N"))  # ours: 0.5 mm of skin compression per N and point: a ~2-3 mm elastomer skin over the pads (no PPS figure)
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
    translation_m: float = param(0.020, unit="m", range=(0.0005, 0.04), help="planned translation of the cylinder towards fingers 1-2 (hand -y), perpendicular to the fingers: the trajectory length",
        sweep=SweepRange(0.010, 0.030, when=EXP3_ONLY, reason="Sec. 7.3 gives no length ('translate the cylinder in the perpendicular direction of the fingers', stopped early): a quarter to three quarters of our 40 mm radius; n_steps stays 80, so a step is 0.125-0.375 mm, under MAX_STEP_M"))  # ours: half the cylinder's radius; the direction in which finger 3's contact moves towards its pad's edge, the paper's situation at the stop (Sec. 7.3)
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
    video: bool = param(False, help="also write video.mp4, replayed from the run's files after it ends (as repro video)",
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


def config_for(name: str) -> Exp3Config:
    """The default config of ``exp3`` or ``exp3_no_tactile``."""
    if name not in EXPERIMENTS_EXP3:
        raise ConfigError(f"unknown pomares2011 experiment 3 run {name!r}; valid: "
                          f"{', '.join(EXPERIMENTS_EXP3)}")
    return Exp3Config() if name == "exp3" else Exp3NoTactileConfig()
