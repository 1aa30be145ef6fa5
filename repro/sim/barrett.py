"""The Barrett BH8-282 hand of pomares2011 (Sec. 6, 7.3): joint names and limits, Barrett's
finger kinematics, the one-motor fingers (motor angle <-> joint angles <-> encoder counts),
the TorqueSwitch breakaway, and the PyBullet pieces that make the URDF move like the hand.

The URDF ``repro/assets/barrett_bh8/barrett_bh8.urdf`` is written by
``repro/assets/barrett_bh8/make_urdf.py`` from the numbers below; the asset's README gives the
source of every number (the facts sheet, ``shared/papers/pomares2011_facts.md``, or
``# ours`` with the reason) and the pad frames of the tactile sensors.

Frames (all URDF links; the pads and tips are massless frames):

* ``bh8_base`` (root): on the mounting face, on the hand axis, ``+z`` the approach direction
  (Barrett's wrist frame W); fingers 1 and 2 on the ``-y`` side, finger 3 on ``+y``.
* ``bh8_palm``: the palm surface centre, ``+z`` its outward normal (the palm plate is this
  link's body, so a contact on the palm is reported on this link).
* ``bh8_finger{k}_knuckle`` = Barrett DH frame k1: on finger k's spread axis, at the height
  of the proximal axis, ``x`` outwards along the knuckle (fingers 1, 2: the child of the
  spread joint; finger 3: fixed on the base).
* ``bh8_finger{k}_proximal`` = DH frame k2 (inner phalanx), ``bh8_finger{k}_distal`` = DH frame
  k3 (outer phalanx): origin on the joint axis, ``x`` along the phalanx towards the tip,
  ``y`` the inner (grasping) normal, ``z`` the flexion axis (a positive angle closes).
* ``bh8_finger{k}_tip`` = DH frame kT: the centre of the rounded fingertip, ``z`` = inner
  normal.
* ``bh8_palm_pad``, ``bh8_finger{k}_proximal_pad``, ``bh8_finger{k}_distal_pad``: the centre of
  each tactile pad's face, ``+z`` its outward normal, ``x`` along the phalanx towards the tip
  (palm: the hand's ``x``).

Barrett's finger kinematics (Craig's modified DH, ``T_{i-1,i} = Rx(alpha_{i-1}) Tx(a_{i-1})
Rz(theta_i) Tz(d_i)``; Barrett wiki Hand/280 kinematics, facts sheet), finger ``k`` with
``r = (-1, 1, 0)``, ``j = (1, 1, -1)`` for fingers 1, 2, 3:

====  ===========  ===========  =====  =============================
 i    a_{i-1}      alpha_{i-1}  d_i    theta_i
====  ===========  ===========  =====  =============================
 k1   r Aw          0           Dw     r theta_spread - j pi/2
 k2   A1           +pi/2        0      theta_proximal
 k3   A2            0           0      theta_distal + Phi3
 kT   A3           -pi/2        D3     0
====  ===========  ===========  =====  =============================

Motor and joints of one finger (libbarrett ``hand.h``: J2_RATIO 125, J3_RATIO 375; Barrett
wiki: motor : proximal 125 : 1, motor : distal 93.75 : 1). The distal's gear is fixed on the
motor shaft, so its angle from the palm, ``q_proximal + q_distal``, is always
``motor / 93.75``; the proximal's gear is held by the TorqueSwitch clutch, so before
breakaway ``q_proximal = motor / 125`` and the distal joint (relative) is
``motor / 93.75 - motor / 125 = motor / 375``, 1/3 of the proximal. After breakaway the
proximal stays where it was and the distal closes alone, at ``motor / 93.75``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pybullet as p

from repro.errors import ConfigError
from repro.sim.robot import JointLimits, JointSet, Robot, joint_states_stamp

__all__ = [
    "BH8_DISTAL_JOINTS", "BH8_DISTAL_LINKS", "BH8_GEOMETRY", "BH8_JOINTS", "BH8_KNUCKLE_LINKS",
    "BH8_LIMITS", "BH8_PAD_FRAMES", "BH8_PROXIMAL_JOINTS", "BH8_PROXIMAL_LINKS",
    "BH8_SPREAD_JOINTS", "BH8_TIP_FRAMES", "BREAKAWAY_TORQUE", "BarrettHandDrive",
    "COUNTS_PER_MOTOR_REV",
    "DISTAL_RATIO", "FINGERS", "GEAR_MAX_FORCE", "J2_RATIO", "J3_RATIO", "MOTOR_ANGLE_MAX",
    "MOTOR_ACCELERATION_MAX", "MOTOR_SPEED_MAX", "SPREAD_RATIO", "BH8Geometry", "FingerDrive",
    "FingerMotors", "FingerTargets", "HandCouplings", "TorqueSwitch", "add_coupling_constraints",
    "bh8_dh_frames", "bh8_joint_indices", "bh8_urdf_path", "counts_to_motor_angle",
    "finger_counts", "finger_joints_from_counts", "finger_joints_from_motor",
    "finger_motor_angle", "hand_joints_from_motors", "motor_angle_to_counts",
    "set_gear_engaged", "set_spread", "spread_counts", "spread_from_counts",
]

FINGERS = (1, 2, 3)

# ------------------------------------------------------------------------- names
#: Spread joints (fingers 1 and 2 only; finger 2 follows finger 1 through a gear constraint).
BH8_SPREAD_JOINTS = ("bh8_finger1_spread", "bh8_finger2_spread")
BH8_PROXIMAL_JOINTS = tuple(f"bh8_finger{k}_proximal_joint" for k in FINGERS)
BH8_DISTAL_JOINTS = tuple(f"bh8_finger{k}_distal_joint" for k in FINGERS)
#: Every non-fixed joint of the URDF, in URDF (and control) order: finger by finger,
#: spread, proximal, distal.
BH8_JOINTS = (
    "bh8_finger1_spread", "bh8_finger1_proximal_joint", "bh8_finger1_distal_joint",
    "bh8_finger2_spread", "bh8_finger2_proximal_joint", "bh8_finger2_distal_joint",
    "bh8_finger3_proximal_joint", "bh8_finger3_distal_joint",
)
BH8_KNUCKLE_LINKS = tuple(f"bh8_finger{k}_knuckle" for k in FINGERS)
#: Inner phalanges (the tactile pads of the inner links sit on them).
BH8_PROXIMAL_LINKS = tuple(f"bh8_finger{k}_proximal" for k in FINGERS)
#: Outer phalanges.
BH8_DISTAL_LINKS = tuple(f"bh8_finger{k}_distal" for k in FINGERS)
#: DH tip frames kT (centre of the rounded fingertip).
BH8_TIP_FRAMES = tuple(f"bh8_finger{k}_tip" for k in FINGERS)
#: Pad frames: palm, then the proximal and the distal pad of each finger.
BH8_PAD_FRAMES = ("bh8_palm_pad",) + tuple(
    f"bh8_finger{k}_{part}_pad" for k in FINGERS for part in ("proximal", "distal"))

# ------------------------------------------------------------------------- kinematics
# pomares2011_facts: Barrett DH, Aw 25 mm, A1 50 mm (knuckle), A2 70 mm (proximal),
# A3 50 mm (distal), D3 9.5 mm.
BH8_AW = 0.025
BH8_A1 = 0.050
BH8_A2 = 0.070
BH8_A3 = 0.050
BH8_D3 = 0.0095
# Phi3 = 42 deg, the fixed flexion of the distal at q_distal = 0 (Barrett wiki table, as in
# aalto-intelligent-robotics/pytorch_barrett_hand_forward_kinematics_layer, the file the
# facts sheet cites; that code multiplies it by 0 because its meshes carry the bend);
# Phi2 = 0.
BH8_PHI3 = float(np.deg2rad(42.0))
# ours: Dw, the proximal axes above the mounting face, 76 mm: the aalto layer's Dw (for the
# BH8-280, whose base is taller than the 282's; no 282 figure was found). jhu-lcsr's
# primitive BH8-280 has 75.4 mm, with the palm-plate top 3.0 mm above the axes.
BH8_DW = 0.076
# r, j of Barrett's table for fingers 1, 2, 3.
_R = (-1, 1, 0)
_J = (1, 1, -1)

# ------------------------------------------------------------------------- drive
# pomares2011_facts (libbarrett hand.cpp / hand.h): motor : proximal 125 : 1 and, with
# J3_RATIO 375, the distal joint (relative to the proximal) turns at motor / 375 before
# breakaway, i.e. 1/3 of the proximal; the distal's angle from the palm is motor / 93.75.
J2_RATIO = 125.0
J3_RATIO = 375.0
#: Motor : distal angle from the palm (q_proximal + q_distal), 1 / (1/125 + 1/375) = 93.75.
DISTAL_RATIO = 1.0 / (1.0 / J2_RATIO + 1.0 / J3_RATIO)
# BarrettTechnology/libbarrett:include/barrett/products/hand.h, SPREAD_RATIO (motor : spread).
SPREAD_RATIO = 17.5
# ours: encoder counts per motor revolution, 4096: the value a public BH8-282 driver uses
# (corlab/rsb-bh8-hardware-integration:src/rsb-bh8-interface.hpp, "cts = 4096", read from
# the Puck's CTS property); not in the facts sheet. Only the scale of the counts (the
# paper's Fig. 12a) depends on it.
COUNTS_PER_MOTOR_REV = 4096

# ------------------------------------------------------------------------- limits
# pomares2011_facts: spread 0-180 deg, proximal 0-140 deg, distal 0-48 deg (relative).
_Q_MAX_DEG = {"spread": 180.0, "proximal": 140.0, "distal": 48.0}
# ours: motor speed, 125 * 140 deg/s: a finger closes fully in 1 s (the facts: finger
# speeds unknown); the proximal then turns at 140 deg/s, the distal at up to
# 125/93.75 * 140 = 186.7 deg/s (alone, after breakaway). The spread: 180 deg/s (ours, the
# same 1 s for its full range).
MOTOR_SPEED_MAX = float(np.deg2rad(125.0 * 140.0))  # [rad/s]
# ours: motor acceleration, full speed in 50 ms (a trapezoidal profile, as the Pucks' own
# trapezoidal moves): a velocity step would load the proximal with ~1.1 N m of inertia in one
# 1 ms step, more than the breakaway torque (measured); with 50 ms it is ~0.02 N m.
MOTOR_ACCELERATION_MAX = MOTOR_SPEED_MAX / 0.05  # [rad/s^2]
_QD_MAX = {"spread": float(np.deg2rad(180.0)), "proximal": MOTOR_SPEED_MAX / J2_RATIO,
           "distal": MOTOR_SPEED_MAX / DISTAL_RATIO}
# pomares2011_facts: max load per finger 2 kg. ours: each joint's torque limit is that
# load's weight at the fingertip's largest distance from the joint axis (q_distal = 0):
# proximal |(A2 + A3 cos Phi3 - D3 sin Phi3, A3 sin Phi3 + D3 cos Phi3)| = 0.1086 m,
# distal |(A3, D3)| = 0.0509 m, spread (horizontal reach, proximal flat)
# A1 + A2 + A3 cos Phi3 - D3 sin Phi3 = 0.1508 m.
TIP_LOAD_MASS = 2.0  # [kg]
GRAVITY = 9.81  # [m/s^2]
_c3, _s3 = np.cos(BH8_PHI3), np.sin(BH8_PHI3)
_LEVER = {
    "spread": BH8_A1 + BH8_A2 + BH8_A3 * _c3 - BH8_D3 * _s3,
    "proximal": float(np.hypot(BH8_A2 + BH8_A3 * _c3 - BH8_D3 * _s3,
                               BH8_A3 * _s3 + BH8_D3 * _c3)),
    "distal": float(np.hypot(BH8_A3, BH8_D3)),
}
_TAU_MAX = {kind: TIP_LOAD_MASS * GRAVITY * lever for kind, lever in _LEVER.items()}
# ours: TorqueSwitch breakaway torque [N m] on the proximal joint: half the proximal torque
# limit (1.07 N m, 2 kg at the tip), so a contact on the inner link breaks away well before
# the motor saturates, while the finger's own weight on the motor (0.04 N m at most) and
# free closing at full speed (0.063 N m) stay below a tenth of it (tests/test_barrett.py;
# Barrett: the
# threshold is set when the finger opens against its stop; value unknown, facts sheet).
BREAKAWAY_TORQUE = 0.5 * _TAU_MAX["proximal"]


def _kind(joint: str) -> str:
    return "spread" if joint.endswith("_spread") else joint.split("_")[2]


#: Largest motor angle [rad]: the proximal at 140 deg (broken away there) and the distal at
#: 48 deg, ``93.75 * (140 + 48) deg``.
MOTOR_ANGLE_MAX = DISTAL_RATIO * float(np.deg2rad(_Q_MAX_DEG["proximal"] + _Q_MAX_DEG["distal"]))

#: Limits of :data:`BH8_JOINTS` (positions [rad], speeds [rad/s], torques [N m]).
BH8_LIMITS = JointLimits(
    q_min=tuple(0.0 for _ in BH8_JOINTS),
    q_max=tuple(float(np.deg2rad(_Q_MAX_DEG[_kind(j)])) for j in BH8_JOINTS),
    qd_max=tuple(_QD_MAX[_kind(j)] for j in BH8_JOINTS),
    tau_max=tuple(float(_TAU_MAX[_kind(j)]) for j in BH8_JOINTS),
)


# ------------------------------------------------------------------------- geometry
# jhu-lcsr/barrett_model:models/hand.urdf.xacro CAD link masses [kg]: knuckle (its
# prox_link), proximal (med_link), distal (dist_link).
_JHU_FINGER = (0.14109, 0.062139, 0.041377)
_JHU_SPLIT = (_JHU_FINGER[0] / sum(_JHU_FINGER), _JHU_FINGER[1] / sum(_JHU_FINGER),
              _JHU_FINGER[2] / sum(_JHU_FINGER))


@dataclass(frozen=True)
class BH8Geometry:
    """Primitive shapes and masses of the hand (read by ``make_urdf.py``); sizes are full
    sizes [m], positions in the frame of the link named, masses [kg].

    Attributes:
        base_mass: base + palm (motors, electronics) (pomares2011_facts: Hand/280
            MassByJoint 0.60 kg), split between ``bh8_base`` and ``bh8_palm`` by volume.
        finger_mass: one finger (pomares2011_facts: Hand/282 MassProperties 0.179 kg),
            knuckle + proximal + distal.
        finger_mass_split: fractions of ``finger_mass`` for knuckle, proximal, distal.
            ours: the proportions of jhu-lcsr/barrett_model's CAD link masses (knuckle
            0.141, proximal 0.062, distal 0.041 kg), which sum to more than Barrett's 0.179.
        wrist_cylinder: (radius, length) of the round base on the mounting face
            (jhu-lcsr's primitives, facts sheet).
        spine_box: box on the wrist cylinder carrying the knuckles, up to the palm plate
            (ours: 24 x 108 mm as jhu-lcsr's spine, its height filling up to the plate).
        palm_box: the palm plate (pomares2011_facts: 76 x 46 x 12 mm); its top is the palm.
        palm_height: palm surface above the mounting face (ours: 3 mm above the proximal
            axes, as in jhu-lcsr's model, so a flat proximal's inner face is flush with it).
        knuckle_arm: box of the knuckle (x from the spread axis, y across, z height),
            under the palm plate (ours).
        knuckle_arm_top: its top below the proximal axis (ours: the palm plate's bottom).
        knuckle_housing: (radius, length) of the cylinder around the proximal axis (ours,
            jhu-lcsr's knuckle cylinder r 15 mm, slimmed so that it clears the palm plate
            at every spread).
        proximal_box: inner phalanx (length along x from the proximal axis, thickness
            along y centred on the axis, width along the flexion axis z)
            (pomares2011_facts: 70 x 19 x 6 mm; ours: read as length, width, thickness,
            which puts a flat finger's inner face 3 mm above its axis, flush with the palm).
        distal_box: outer phalanx (length, thickness, width); it spans y from
            ``D3 - thickness / 2`` to ``D3 + thickness / 2`` (ours: its centre line through
            the DH tip point, D3 inside the distal axis).
        tip_radius: the rounded tip, a cylinder along the flexion axis centred on the DH tip
            point (pomares2011_facts: r 6.5 mm, distal ~55 mm); a contact shape only, its
            mass counted in the distal box (ours).
        proximal_pad_x: the proximal pad's centre along the inner face (ours: 1 mm short of
            the face centre, so that the 40 mm pad ends where the distal's inner face is at
            full flexion, 54 mm).
    """

    base_mass: float = 0.60
    finger_mass: float = 0.179
    finger_mass_split: tuple[float, float, float] = _JHU_SPLIT
    wrist_cylinder: tuple[float, float] = (0.045, 0.042)
    spine_box: tuple[float, float, float] = (0.024, 0.108, 0.025)
    palm_box: tuple[float, float, float] = (0.076, 0.046, 0.012)
    palm_height: float = BH8_DW + 0.003
    knuckle_arm: tuple[float, float, float] = (0.038, 0.024, 0.012)
    knuckle_arm_top: float = -0.009
    knuckle_housing: tuple[float, float] = (0.012, 0.024)
    proximal_box: tuple[float, float, float] = (0.070, 0.006, 0.019)
    distal_box: tuple[float, float, float] = (0.050, 0.013, 0.019)
    tip_radius: float = 0.0065
    proximal_pad_x: float = 0.034

    @property
    def finger_masses(self) -> tuple[float, float, float]:
        """Knuckle, proximal, distal mass [kg] of one finger."""
        k, pr, _ = (self.finger_mass * f for f in self.finger_mass_split)
        return k, pr, self.finger_mass - k - pr

    @property
    def proximal_face(self) -> float:
        """The proximal's inner face, ``y`` in its frame [m]."""
        return self.proximal_box[1] / 2

    @property
    def distal_face(self) -> float:
        """The distal's inner face, ``y`` in its frame [m]."""
        return BH8_D3 + self.distal_box[1] / 2


#: The hand's shapes and masses.
BH8_GEOMETRY = BH8Geometry()


def bh8_urdf_path() -> Path:
    """The packaged URDF (``repro/assets/barrett_bh8/barrett_bh8.urdf``)."""
    return (Path(__file__).resolve().parent.parent / "assets" / "barrett_bh8"
            / "barrett_bh8.urdf")


def _craig(a: float, alpha: float, d: float, theta: float) -> np.ndarray:
    """``Rx(alpha) Tx(a) Rz(theta) Tz(d)`` (4x4), Craig's modified DH."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st, 0.0, a],
                     [st * ca, ct * ca, -sa, -sa * d],
                     [st * sa, ct * sa, ca, ca * d],
                     [0.0, 0.0, 0.0, 1.0]])


def bh8_dh_frames(finger: int, q_spread: float, q_proximal: float,
                  q_distal: float) -> np.ndarray:
    """Barrett's DH frames ``T_base_k1, T_base_k2, T_base_k3, T_base_kT`` (4 x 4 x 4) of
    ``finger`` (1, 2, 3) at spread, proximal and distal angles [rad] (finger 3 ignores the
    spread), from the table in the module docstring."""
    if finger not in FINGERS:
        raise ConfigError(f"finger must be one of {FINGERS}, got {finger!r}")
    r, j = _R[finger - 1], _J[finger - 1]
    rows = ((r * BH8_AW, 0.0, BH8_DW, r * q_spread - j * np.pi / 2),
            (BH8_A1, np.pi / 2, 0.0, q_proximal),
            (BH8_A2, 0.0, 0.0, q_distal + BH8_PHI3),
            (BH8_A3, -np.pi / 2, BH8_D3, 0.0))
    frames = []
    T = np.eye(4)
    for row in rows:
        T = T @ _craig(*row)
        frames.append(T)
    return np.array(frames)


# ------------------------------------------------------------------------- motor <-> joints
def finger_joints_from_motor(motor_angle: float,
                             q_breakaway: float | None = None) -> tuple[float, float]:
    """(q_proximal, q_distal) [rad] of a finger at ``motor_angle`` [rad].

    Engaged (``q_breakaway`` None, or the motor not past the breakaway point
    ``J2_RATIO * q_breakaway``): ``motor / 125`` and ``motor / 375``. Broken away at the
    proximal angle ``q_breakaway``: the proximal stays there and the distal closes alone,
    ``q_distal = motor / 93.75 - q_breakaway``.
    """
    m = float(motor_angle)
    if q_breakaway is None or m <= J2_RATIO * q_breakaway:
        return m / J2_RATIO, m / J3_RATIO
    return float(q_breakaway), m / DISTAL_RATIO - float(q_breakaway)


def hand_joints_from_motors(motors: tuple[float, float, float] | np.ndarray,
                            spread: float = 0.0) -> np.ndarray:
    """(8,) joint angles of the hand, :data:`BH8_JOINTS` order [rad], with the three finger
    motors at ``motors`` [rad] and the clutches engaged (:func:`finger_joints_from_motor`),
    both spread joints at ``spread`` [rad]."""
    q = np.zeros(len(BH8_JOINTS))
    for k, m in zip(FINGERS, motors, strict=True):
        q[BH8_JOINTS.index(f"bh8_finger{k}_proximal_joint")], q[BH8_JOINTS.index(
            f"bh8_finger{k}_distal_joint")] = finger_joints_from_motor(float(m))
    for j in BH8_SPREAD_JOINTS:
        q[BH8_JOINTS.index(j)] = spread
    return q


def finger_motor_angle(q_proximal: float, q_distal: float) -> float:
    """Motor angle [rad] of a finger at joint angles [rad]: ``93.75 (q_p + q_d)`` (the distal
    gear is fixed on the motor shaft; valid before and after breakaway)."""
    return DISTAL_RATIO * (float(q_proximal) + float(q_distal))


def motor_angle_to_counts(motor_angle: float) -> int:
    """Encoder counts [-] of a motor angle [rad] (:data:`COUNTS_PER_MOTOR_REV` per turn)."""
    return int(round(float(motor_angle) * COUNTS_PER_MOTOR_REV / (2.0 * np.pi)))


def counts_to_motor_angle(counts: int) -> float:
    """Motor angle [rad] of encoder ``counts`` [-]."""
    return float(counts) * 2.0 * np.pi / COUNTS_PER_MOTOR_REV


def finger_counts(q_proximal: float, q_distal: float) -> int:
    """Motor counts of a finger at joint angles [rad] (what pomares2011 Fig. 12a plots)."""
    return motor_angle_to_counts(finger_motor_angle(q_proximal, q_distal))


def finger_joints_from_counts(counts: int,
                              q_breakaway: float | None = None) -> tuple[float, float]:
    """(q_proximal, q_distal) [rad] at motor ``counts`` (see :func:`finger_joints_from_motor`)."""
    return finger_joints_from_motor(counts_to_motor_angle(counts), q_breakaway)


def spread_counts(q_spread: float) -> int:
    """Spread-motor counts at spread angle [rad] (:data:`SPREAD_RATIO` : 1)."""
    return motor_angle_to_counts(SPREAD_RATIO * float(q_spread))


def spread_from_counts(counts: int) -> float:
    """Spread angle [rad] at spread-motor ``counts``."""
    return counts_to_motor_angle(counts) / SPREAD_RATIO


# ------------------------------------------------------------------------- PyBullet
# ours: force limit of the gear constraints [N m], 10x the largest joint torque limit: the
# gear trains are rigid, so the couplings never slip within the drives' torque limits.
GEAR_MAX_FORCE = 10.0 * max(_TAU_MAX.values())
# ours: position-error correction of the gear constraints (PyBullet's erp): without it the
# coupling holds only velocities and the distal creeps ~0.01 deg/s under gravity (measured
# at 1 kHz); with 0.2 the ratio holds to 1e-5.
GEAR_ERP = 0.2
# ours: PyBullet's (dimensionless) position gain of the finger and spread motors; with
# velocity gain 1 and the reference's speed fed forward, a full-speed closing at 1 kHz lags
# its reference by 0.14 deg, one step at 140 deg/s (measured).
POSITION_GAIN = 0.3


class HandCouplings(NamedTuple):
    """Gear-constraint ids of one hand body.

    Attributes:
        spread: finger 2's spread follows finger 1's (ratio 1).
        distal: per finger 1, 2, 3: the distal joint follows the proximal at 1/3 (engaged
            TorqueSwitch).
    """

    spread: int
    distal: tuple[int, int, int]


def bh8_joint_indices(body: int, client: int) -> dict[str, int]:
    """PyBullet joint index of every joint of the hand body, and of every link (a link has
    the index of its parent joint; the base ``bh8_base`` is -1), by name."""
    out = {p.getBodyInfo(body, physicsClientId=client)[0].decode(): -1}
    for j in range(p.getNumJoints(body, physicsClientId=client)):
        info = p.getJointInfo(body, j, physicsClientId=client)
        out[info[1].decode()] = j
        out[info[12].decode()] = j
    return out


def _gear(body: int, client: int, leader: int, follower: int, ratio: float) -> int:
    """A JOINT_GEAR constraint ``q_leader + ratio * q_follower = 0`` between two joints of one
    body (PyBullet's convention: ``ratio = -3`` gives ``q_follower = q_leader / 3``)."""
    c = p.createConstraint(body, leader, body, follower, p.JOINT_GEAR, [0.0, 0.0, 1.0],
                           [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=client)
    p.changeConstraint(c, gearRatio=ratio, maxForce=GEAR_MAX_FORCE, erp=GEAR_ERP,
                       relativePositionTarget=0.0, physicsClientId=client)
    return c


def add_coupling_constraints(body: int, client: int) -> HandCouplings:
    """Add the hand's mechanical couplings to a loaded BH8 body as JOINT_GEAR constraints
    (PyBullet ignores URDF ``<mimic>``), and free the followers' default velocity motors so
    that only the constraints move them:

    * ``q_finger2_spread = q_finger1_spread`` (one spread motor, symmetric);
    * ``q_distal = q_proximal * J2_RATIO / J3_RATIO = q_proximal / 3`` per finger (one motor
      per finger, TorqueSwitch engaged).

    Drive the spread of finger 1 and the proximal joints; :class:`FingerDrive` releases a
    finger's distal gear at breakaway (:func:`set_gear_engaged`).
    """
    idx = bh8_joint_indices(body, client)
    spread = _gear(body, client, idx["bh8_finger1_spread"], idx["bh8_finger2_spread"], -1.0)
    distal = tuple(_gear(body, client, idx[f"bh8_finger{k}_proximal_joint"],
                         idx[f"bh8_finger{k}_distal_joint"], -J3_RATIO / J2_RATIO)
                   for k in FINGERS)
    for name in ("bh8_finger2_spread", *BH8_DISTAL_JOINTS):
        p.setJointMotorControl2(body, idx[name], p.VELOCITY_CONTROL, targetVelocity=0.0,
                                force=0.0, physicsClientId=client)
    return HandCouplings(spread, (distal[0], distal[1], distal[2]))


def set_gear_engaged(constraint: int, client: int, engaged: bool) -> None:
    """Engage (force limit :data:`GEAR_MAX_FORCE`) or release (force limit 0) a gear
    constraint; the ratio and the position target are kept."""
    p.changeConstraint(constraint, maxForce=GEAR_MAX_FORCE if engaged else 0.0,
                       physicsClientId=client)


def set_spread(body: int, client: int, q_spread: float, qd_spread: float = 0.0) -> None:
    """Position-control the spread motor (finger 1's spread joint; finger 2's follows through
    its gear constraint) towards ``q_spread`` [rad], clipped to 0-180 deg, at speed
    ``qd_spread`` [rad/s] fed forward; torque limited to the spread's ``tau_max``."""
    k = BH8_JOINTS.index("bh8_finger1_spread")
    q = float(np.clip(q_spread, BH8_LIMITS.q_min[k], BH8_LIMITS.q_max[k]))
    p.setJointMotorControl2(body, bh8_joint_indices(body, client)["bh8_finger1_spread"],
                            p.POSITION_CONTROL, targetPosition=q,
                            targetVelocity=float(qd_spread), positionGain=POSITION_GAIN,
                            velocityGain=1.0, force=BH8_LIMITS.tau_max[k],
                            physicsClientId=client)


class FingerTargets(NamedTuple):
    """What the TorqueSwitch makes of a motor angle.

    Attributes:
        q_proximal: proximal joint target [rad].
        q_distal: distal joint target [rad] (relative to the proximal).
        engaged: the clutch holds: the distal follows the proximal through the gear
            constraint (only the proximal is driven); False after breakaway: the proximal is
            held and the distal driven alone.
    """

    q_proximal: float
    q_distal: float
    engaged: bool


class TorqueSwitch:
    """Barrett's TorqueSwitch of one finger, as a two-state machine (no simulator).

    Engaged, the motor drives both joints (``q_p = m / 125``, ``q_d = m / 375``). When the
    proximal joint's torque exceeds ``threshold`` while the motor closes, the clutch breaks
    away: the proximal stays where it is, ``q_breakaway``, and the distal closes alone
    (``q_d = m / 93.75 - q_breakaway``). Reopening re-engages it once the motor is back at
    the breakaway point (``m <= 125 q_breakaway``: the clutch's threaded gear screws back onto
    its springs, Barrett wiki; the two laws agree there, so the targets are continuous).

    Args:
        threshold: breakaway torque on the proximal joint [N m] (> 0).
    """

    def __init__(self, threshold: float = BREAKAWAY_TORQUE) -> None:
        if not threshold > 0.0:
            raise ConfigError(f"threshold must be > 0 N m, got {threshold!r}")
        self.threshold = float(threshold)
        self.q_breakaway: float | None = None
        """Proximal angle where the clutch broke away [rad]; None while engaged."""

    @property
    def engaged(self) -> bool:
        return self.q_breakaway is None

    def reset(self) -> None:
        """Engage the clutch (e.g. after the finger was reset open)."""
        self.q_breakaway = None

    def update(self, motor_angle: float, tau_proximal: float,
               q_proximal: float) -> FingerTargets:
        """Joint targets for ``motor_angle`` [rad], given the measured proximal joint torque
        ``tau_proximal`` [N m] (positive closes) and angle ``q_proximal`` [rad]."""
        m = float(motor_angle)
        if self.q_breakaway is not None and m <= J2_RATIO * self.q_breakaway:
            self.q_breakaway = None  # reopened to the breakaway point: engaged again
        if (self.q_breakaway is None and tau_proximal > self.threshold
                and m / J2_RATIO > q_proximal):  # closing against a load
            self.q_breakaway = float(q_proximal)
        q_p, q_d = finger_joints_from_motor(m, self.q_breakaway)
        return FingerTargets(q_p, q_d, self.q_breakaway is None)


class FingerDrive:
    """The motor of one finger on a loaded BH8 body (with :func:`add_coupling_constraints`):
    a motor-angle command, speed- and acceleration-limited, through the
    :class:`TorqueSwitch` to PyBullet position control of the joints, torque-limited to
    ``tau_max``. Call :meth:`step` before every physics step.

    Engaged: the proximal is driven to ``m / 125`` and the distal follows through the gear
    constraint (its own motor off). Broken away: the gear constraint is released, the
    proximal held at the breakaway angle (position control, force ``tau_max``: the
    self-locking worm gear; ours: with the breakaway torque as force limit the distal's
    reaction on an object pushes the proximal open by ~6 deg, and a zero-velocity lock
    creeps and loses the contact, both measured) and the distal driven to
    ``m / 93.75 - q_breakaway``. The held proximal presses on what stopped it with up to
    ``tau_max`` (the angle measured at breakaway lies ~0.1 deg inside the contact), not with
    the breakaway torque the real drive would keep. The proximal torque the switch reads is
    PyBullet's applied motor torque of the last step (it carries the distal's load through
    the gear).

    Args:
        body, client: the hand body and its PyBullet client.
        finger: 1, 2 or 3.
        couplings: the hand's gear constraints.
        switch: the finger's TorqueSwitch (default: :data:`BREAKAWAY_TORQUE`).
    """

    def __init__(self, body: int, client: int, finger: int, couplings: HandCouplings,
                 switch: TorqueSwitch | None = None) -> None:
        if finger not in FINGERS:
            raise ConfigError(f"finger must be one of {FINGERS}, got {finger!r}")
        self.body, self.client, self.finger = body, client, finger
        self.gear = couplings.distal[finger - 1]
        self.switch = switch or TorqueSwitch()
        idx = bh8_joint_indices(body, client)
        self.j_proximal = idx[f"bh8_finger{finger}_proximal_joint"]
        self.j_distal = idx[f"bh8_finger{finger}_distal_joint"]
        k_p = BH8_JOINTS.index(f"bh8_finger{finger}_proximal_joint")
        self.tau_max_proximal = BH8_LIMITS.tau_max[k_p]
        self.tau_max_distal = BH8_LIMITS.tau_max[k_p + 1]
        self.q_max_distal = BH8_LIMITS.q_max[k_p + 1]
        q_p, q_d = self.joint_positions()
        self.motor_angle = finger_motor_angle(q_p, q_d)
        """The motor angle commanded last [rad] (after the speed and acceleration limits)."""
        self.motor_speed = 0.0
        """Its rate [rad/s]."""
        self._engaged = True
        self.targets = FingerTargets(q_p, q_d, True)
        #: the joint commands sent last (engaged, q_proximal, motor speed, q_distal): a
        #: PyBullet motor keeps its settings between steps, so the same ones are not resent
        self._sent: tuple[bool, float, float, float] | None = None

    def joint_positions(self) -> tuple[float, float]:
        """(q_proximal, q_distal) [rad] as simulated."""
        s = p.getJointStates(self.body, [self.j_proximal, self.j_distal],
                             physicsClientId=self.client)
        return float(s[0][0]), float(s[1][0])

    def proximal_torque(self) -> float:
        """The proximal motor's torque of the last physics step [N m] (positive closes)."""
        return float(p.getJointState(self.body, self.j_proximal,
                                     physicsClientId=self.client)[3])

    def counts(self) -> int:
        """Motor counts of the simulated joints (:func:`finger_counts`)."""
        return finger_counts(*self.joint_positions())

    def step(self, motor_target: float, h: float,
             proximal_state: Sequence[Any] | None = None) -> FingerTargets:
        """Move the motor towards ``motor_target`` [rad] (clipped to the finger's range; a
        trapezoidal profile, :data:`MOTOR_SPEED_MAX`, :data:`MOTOR_ACCELERATION_MAX`), update
        the TorqueSwitch from the last step's proximal torque and send the joint commands
        for the next physics step of ``h`` [s]. ``proximal_state``: the proximal joint's
        ``pybullet.getJointState`` of this physics step, if the caller read it already (one
        call for the whole hand); None: read here. Returns the joint targets."""
        q_b = self.switch.q_breakaway
        top = MOTOR_ANGLE_MAX if q_b is None else DISTAL_RATIO * (q_b + self.q_max_distal)
        # scalar min/max and math.sqrt: the same IEEE results as np.clip / np.sqrt, without
        # numpy's per-call overhead (three fingers at 1 kHz)
        err = min(max(float(motor_target), 0.0), top) - self.motor_angle
        # Trapezoidal profile: speed <= MOTOR_SPEED_MAX, |acceleration| <= MOTOR_ACCELERATION_MAX,
        # braking in time to stop on the target.
        a_h = MOTOR_ACCELERATION_MAX * h
        sign = (err > 0.0) - (err < 0.0)
        v_want = sign * min(MOTOR_SPEED_MAX, abs(err) / h,
                            math.sqrt(2.0 * MOTOR_ACCELERATION_MAX * abs(err)))
        md = min(max(v_want, self.motor_speed - a_h), self.motor_speed + a_h)
        if abs(md * h) > abs(err) and md * err >= 0.0:
            md = err / h
        self.motor_speed = md
        m_new = self.motor_angle + md * h
        self.motor_angle = m_new
        if proximal_state is None:
            proximal_state = p.getJointState(self.body, self.j_proximal,
                                             physicsClientId=self.client)
        q_p, tau_p = float(proximal_state[0]), float(proximal_state[3])
        t = self.switch.update(m_new, tau_p, q_p)
        self.targets = t
        if t.engaged != self._engaged:
            set_gear_engaged(self.gear, self.client, t.engaged)
            self._engaged = t.engaged
        sent = (t.engaged, t.q_proximal, md, t.q_distal)
        if self._sent is not None and _same_floats(sent, self._sent):
            return t  # the motors hold these settings already
        self._sent = sent
        if t.engaged:
            p.setJointMotorControl2(self.body, self.j_proximal, p.POSITION_CONTROL,
                                    targetPosition=t.q_proximal,
                                    targetVelocity=md / J2_RATIO,
                                    positionGain=POSITION_GAIN, velocityGain=1.0,
                                    force=self.tau_max_proximal, physicsClientId=self.client)
            p.setJointMotorControl2(self.body, self.j_distal, p.VELOCITY_CONTROL,
                                    targetVelocity=0.0, force=0.0,
                                    physicsClientId=self.client)
        else:
            p.setJointMotorControl2(self.body, self.j_proximal, p.POSITION_CONTROL,
                                    targetPosition=t.q_proximal, targetVelocity=0.0,
                                    positionGain=POSITION_GAIN, velocityGain=1.0,
                                    force=self.tau_max_proximal, physicsClientId=self.client)
            p.setJointMotorControl2(self.body, self.j_distal, p.POSITION_CONTROL,
                                    targetPosition=t.q_distal,
                                    targetVelocity=md / DISTAL_RATIO,
                                    positionGain=POSITION_GAIN, velocityGain=1.0,
                                    force=self.tau_max_distal, physicsClientId=self.client)
        return t


def _same_floats(a: tuple[Any, ...], b: tuple[Any, ...]) -> bool:
    """Equal element by element, a zero's sign included (the same bits for finite floats)."""
    for x, y in zip(a, b, strict=True):
        if x != y or (x == 0.0 and math.copysign(1.0, x) != math.copysign(1.0, y)):
            return False
    return True


# ------------------------------------------------------------------------- the drive
class FingerMotors(JointSet):
    """The three finger motors of a loaded BH8 body as a joint set (the runner logs them as
    ``<prefix>q{i}``, ``qd{i}``, ``u{i}``): position = the motor angle [rad] of finger i,
    ``93.75 (q_proximal + q_distal)`` of the simulated joints (the distal gear sits on the
    motor shaft: valid before and after breakaway), velocity its rate [rad/s].

    ``robot`` is the body that carries the hand: the standalone hand, or the PA-10 chain of
    :mod:`repro.sim.pa10` (the joints are found by name). The runner then also observes its
    joints, and measures the ground-truth distances over ``links``: the proximal and distal
    links.
    """

    #: what the runner's columns call one element of this set
    element = "finger motor"
    state_source = "93.75 (q_proximal + q_distal) of the PyBullet joint states"

    def __init__(self, hand: Robot, name: str = "fingers", column_prefix: str = "motor_") -> None:
        self.robot = hand
        self.world, self.body, self.client = hand.world, hand.body, hand.client
        self.name, self.column_prefix = name, column_prefix
        idx = bh8_joint_indices(hand.body, hand.client)
        self._pairs = [(idx[f"bh8_finger{k}_proximal_joint"], idx[f"bh8_finger{k}_distal_joint"])
                       for k in FINGERS]
        self.pb_joints = [a for a, _ in self._pairs]
        self.n = len(FINGERS)
        k_p = BH8_JOINTS.index("bh8_finger1_proximal_joint")
        self.limits = JointLimits(q_min=(0.0,) * 3, q_max=(MOTOR_ANGLE_MAX,) * 3,
                                  qd_max=(MOTOR_SPEED_MAX,) * 3,
                                  tau_max=(BH8_LIMITS.tau_max[k_p],) * 3)
        names = {f"bh8_finger{k}_{part}" for k in FINGERS for part in ("proximal", "distal")}
        self.links = sorted(idx[n] for n in names)
        self._joints = [j for pair in self._pairs for j in pair]
        self._states_key: tuple[int, int] | None = None
        self._now = (np.zeros(3), np.zeros(3))

    def _states(self) -> tuple[np.ndarray, np.ndarray]:
        """(motor angles, their rates), read once per physics step (as a Robot's joint
        states: a step, a reset or :func:`repro.sim.robot.joint_states_changed` renews them)."""
        key = joint_states_stamp(self.world)
        if key != self._states_key:
            s = p.getJointStates(self.body, self._joints, physicsClientId=self.client)
            self._now = (
                np.array([DISTAL_RATIO * (s[2 * i][0] + s[2 * i + 1][0]) for i in range(3)]),
                np.array([DISTAL_RATIO * (s[2 * i][1] + s[2 * i + 1][1]) for i in range(3)]))
            self._states_key = key
        return self._now

    def q(self) -> np.ndarray:
        return self._states()[0].copy()

    def qd(self) -> np.ndarray:
        return self._states()[1].copy()

    def gravity_torques(self, q: np.ndarray) -> np.ndarray:
        return np.zeros(self.n)


class BarrettHandDrive:
    """The hand's three finger motors (the Drive protocol of :mod:`repro.sim.drives`).

    Command: one motor angle target per finger [rad of the motor; counts = rad x 4096 /
    (2 pi)], clipped to 0 .. :data:`repro.sim.barrett.MOTOR_ANGLE_MAX` (the applied command;
    the runner's ``motor_n_sat`` counts the clipped fingers). Before every physics step each
    finger's :class:`repro.sim.barrett.FingerDrive` moves its motor towards the target
    (trapezoidal profile, 305 rad/s, full speed in 50 ms), updates its TorqueSwitch and sends
    the joint commands. The spread motor is held at ``spread`` [rad] by PyBullet's position
    motor (set once: a position motor persists between steps). The safe command holds the
    last targets (the Barrett's hold).
    """

    mode = "motor_position"
    unit = "rad"
    clip_to = "its motor's range 0 .. MOTOR_ANGLE_MAX (repro.sim.barrett)"

    def __init__(self, motors: FingerMotors, couplings: HandCouplings,
                 spread: float = 0.0) -> None:
        self.robot: JointSet = motors
        self.fingers = [FingerDrive(motors.body, motors.client, k, couplings) for k in FINGERS]
        self._proximal = [f.j_proximal for f in self.fingers]
        self.spread = float(spread)
        set_spread(motors.body, motors.client, self.spread)
        self.target = np.array([f.motor_angle for f in self.fingers])

    def command(self, u: np.ndarray, dt: float) -> np.ndarray:
        self.target = np.clip(np.asarray(u, dtype=float), 0.0, MOTOR_ANGLE_MAX)
        return self.target.copy()

    def substep(self, i: int, h: float) -> None:
        # the three proximal joints' states in one call (the motor commands sent in between
        # change no state until the physics steps)
        states = p.getJointStates(self.robot.body, self._proximal,
                                  physicsClientId=self.robot.client)
        for finger, m, st in zip(self.fingers, self.target, states, strict=True):
            finger.step(float(m), h, st)

    def safe_command(self) -> np.ndarray:
        return self.target.copy()

    def describe(self) -> dict[str, Any]:
        return {"kind": "barrett_bh8_finger_motors", "command": "motor angle target per finger "
                "[rad]; counts = rad * 4096 / (2 pi)", "spread_rad": self.spread,
                "motor": "repro.sim.barrett.FingerDrive: trapezoidal motor profile "
                f"({MOTOR_SPEED_MAX:.1f} rad/s, {MOTOR_ACCELERATION_MAX:.0f} rad/s^2), "
                f"TorqueSwitch breakaway at {BREAKAWAY_TORQUE:.3f} N m on the proximal, "
                "PyBullet position control of the joints (gain "
                f"{POSITION_GAIN}), JOINT_GEAR constraints distal = proximal / 3 (engaged) "
                "and spread 2 = spread 1",
                "measured_motor_angle": "motor_q{i} = 93.75 (q_proximal + q_distal)",
                "counts_per_motor_rev": COUNTS_PER_MOTOR_REV,
                "motor_angle_range_rad": [0.0, MOTOR_ANGLE_MAX],
                "motor_angle_range_meaning": "every motor target is clipped to this range: "
                "DISTAL_RATIO x (the proximal + distal joint limits), the fingers fully closed"}
