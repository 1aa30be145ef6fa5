"""The pomares2011 robot chain as one URDF: Mitsubishi PA-10 (6 DoF), the Barrett BH8-282
hand of :mod:`repro.sim.barrett` on its flange and the authors' RRR mini-robot carrying the
camera.

The URDF ``repro/assets/pa10/pa10_mini.urdf`` is written by
``repro/assets/pa10/make_urdf.py`` from the numbers below and the link shapes in that
script; ``repro/assets/pa10/README.md`` gives the source of every number (public figures
from the facts sheet, or ``# ours`` with the reason).

One :class:`repro.sim.robot.Robot` holds all 17 joints, :data:`ALL_JOINTS` (the PA-10's
six, the mini-robot's three, the hand's eight); a controller commands a subset of them (the
PA-10 by RVC, the mini-robot by the direct hybrid controller, the hand's three finger motors
by the tactile control, pomares2011 Table 1).

Conventions:

* **Zero configuration** ``q = 0``: the PA-10 straight up (ARTE's zero, with the +90 deg
  DH offsets of joints 2 and 3), the mini-robot straight along the flange axis, its camera
  looking forward (along the flange ``+z``).
* **Base frame** ``pa10_link0``: on the mounting surface, on the joint-1 axis, ``+z`` up.
  Every PA-10 link frame is parallel to it at ``q = 0``.
* **Joint axes** at ``q = 0`` (base frame): z, -y, -y, z, -y, z, the DH ``z_{i-1}``
  axes; a positive q2, q3 or q5 tilts the distal part towards ``-x``.
* **Flange** ``pa10_flange`` = DH frame 6 of the table below (its ``x`` is the base's
  ``-x`` at ``q = 0``); ``+z`` out of the flange.
* **Hand** ``bh8_base`` (= ``pa10_flange``) and ``bh8_palm`` (palm surface, normal
  ``+z`` = approach direction, 79 mm out); its other frames in :mod:`repro.sim.barrett`.
* **Mini-robot** ``mini_base`` (= ``pa10_flange``): ``mini_joint1`` turns the mini-robot
  about the flange ``z`` axis, around the hand ("q1 rotates it around the task",
  pomares2011 Sec. 7); ``mini_joint2`` and ``mini_joint3`` are parallel pitch joints
  (axis tangential) that point the camera; positive q2, q3 tilt it towards the hand axis.
* **Camera** ``mini_camera_optical``: x right, y down, z forward (the looking direction,
  the convention of :mod:`repro.sensors.camera`). At ``q = 0`` its ``z`` is the flange
  ``+z``, its ``y`` points radially away from the hand axis and it sits
  :data:`MINI_GEOMETRY` ``.radius`` = 0.13 m off that axis, 0.24 m out from the flange.

Standard DH table of the PA-10 (``4rtur1t0/ARTE:robots/MITSUBISHI/PA-10/parameters.m``),
``T_{i-1,i} = Rz(q_i + offset_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``:

====  ===========  =======  =======  ========
 i    offset_i     d_i [m]  a_i [m]  alpha_i
====  ===========  =======  =======  ========
 1       0          0.315    0        +90 deg
 2     +90 deg      0        0.45      0
 3     +90 deg      0        0        +90 deg
 4       0          0.50     0        -90 deg
 5       0          0        0        +90 deg
 6       0          0.08     0         0
====  ===========  =======  =======  ========
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from repro.errors import ConfigError
from repro.sim.barrett import BH8_GEOMETRY, BH8_JOINTS, BH8_LIMITS
from repro.sim.robot import JointLimits

PA10_JOINTS = tuple(f"pa10_joint{i}" for i in range(1, 7))
MINI_JOINTS = ("mini_joint1", "mini_joint2", "mini_joint3")
#: Every non-fixed joint of the URDF, in the order of :data:`ALL_LIMITS`: the PA-10's six,
#: the mini-robot's three, then the hand's eight (:data:`repro.sim.barrett.BH8_JOINTS`).
ALL_JOINTS = PA10_JOINTS + MINI_JOINTS + BH8_JOINTS
#: Links of the PA-10 in chain order, from the fixed base pa10_link0 to the flange link.
PA10_LINKS = tuple(f"pa10_link{i}" for i in range(0, 7))
MINI_LINKS = ("mini_link1", "mini_link2", "mini_link3")

# ---------------------------------------------------------------------------- PA-10
#: Standard DH rows (theta offset [rad], d [m], a [m], alpha [rad]), ARTE parameters.m.
PA10_DH = (
    (0.0, 0.315, 0.0, np.pi / 2),
    (np.pi / 2, 0.0, 0.45, 0.0),
    (np.pi / 2, 0.0, 0.0, np.pi / 2),
    (0.0, 0.50, 0.0, -np.pi / 2),
    (0.0, 0.0, 0.0, np.pi / 2),
    (0.0, 0.08, 0.0, 0.0),
)
# ARTE parameters.m (the 6-DoF PA-10, the same file as the DH table; README says why not
# Choreonoid's 7-DoF set).
#: Joint position limits, symmetric +- [deg].
PA10_Q_LIMIT_DEG = (177.0, 91.0, 137.0, 255.0, 165.0, 360.0)
#: Maximum joint speeds [deg/s].
PA10_QD_MAX_DEG_S = (200.0, 200.0, 260.0, 360.0, 360.0, 450.0)
# ours: torque limits [N m]; no public joint-torque figures were found. Joints 2 and 3
# carry the stretched arm with hand and mini-robot (112 / 36 N m, tests/test_pa10.py) plus
# the PA-10's 10 kg rated payload at the palm (+109 / +65 N m): 250 / 120 N m leave
# >= 10 % on top of that. Joint 1 gets the shoulder's figure (inertial loads only); the
# wrist joints 4-6 carry the hand, the mini-robot and a payload 0.1-0.2 m off their axes.
PA10_TAU_MAX = (250.0, 250.0, 120.0, 40.0, 40.0, 20.0)
#: Link masses [kg], pa10_link0..pa10_link6. Manufacturer's 7-DoF PA-10 data
#: (MBDyn tests/invdyn/pa10, Choreonoid PA10.body): base 3.04 and link 1 9.78 as given;
#: the 6-DoF upper arm (shoulder pitch to elbow pitch) lumps the two 7-DoF links either
#: side of the upper-arm roll S3 that the 6-DoF arm lacks (8.41 + 3.51 = 11.92); then
#: elbow 4.31, forearm 3.45, wrist 1.46, flange 0.24 as given.
PA10_LINK_MASSES = (3.04, 9.78, 11.92, 4.31, 3.45, 1.46, 0.24)  # 11.92 = 8.41 + 3.51
#: Where joint 4 (forearm roll) sits on its axis, from the elbow [m] (the 7-DoF arm's E2,
#: Choreonoid PA10.body); joint 4's origin is not fixed by the DH table.
PA10_FOREARM_ROLL_OFFSET = 0.25

# ---------------------------------------------------------------------------- hand
#: The hand on the flange: the Barrett BH8-282 of :mod:`repro.sim.barrett` (its root
#: ``bh8_base`` = ``pa10_flange``), joints :data:`repro.sim.barrett.BH8_JOINTS`.
HAND_JOINTS = BH8_JOINTS
#: Palm surface out from the flange along its z [m] (the hand's ``bh8_palm`` frame).
PALM_HEIGHT = BH8_GEOMETRY.palm_height


# ---------------------------------------------------------------------------- mini-robot


@dataclass(frozen=True)
class MiniGeometry:
    """Kinematics of the RRR mini-robot (all ours: the paper gives none), in ``mini_base``
    (= ``pa10_flange``) at ``q = 0`` [m].

    Attributes:
        radius: distance of the joint-2 and joint-3 axes and of the camera from the hand
            axis (outside the fingers' reach of ~0.09 m).
        joint2_height: joint 2 out from the flange plane.
        link2: joint 2 to joint 3, along the flange z at q = 0.
        link3: joint 3 to the camera's optical centre, along the optical axis.
    """

    radius: float = 0.13
    joint2_height: float = 0.08
    link2: float = 0.10
    link3: float = 0.07

    @property
    def camera_height(self) -> float:
        """Optical centre out from the flange plane at q = 0 [m]."""
        return self.joint2_height + self.link2 + self.link3


#: The mini-robot's kinematic sizes.
MINI_GEOMETRY = MiniGeometry()
#: Link masses [kg]: mini_base (clamp ring on the flange), mini_link1 (arm, post, joint-2
#: servo), mini_link2 (tube, joint-3 servo), mini_link3 (camera bracket), mini_camera.
#: ours: light aluminium parts and small servos; the camera a compact GigE body with lens.
MINI_MASSES = {"mini_base": 0.15, "mini_link1": 0.30, "mini_link2": 0.12,
               "mini_link3": 0.03, "mini_camera": 0.10}
# ours: q1 +-180 deg ("any point around the manipulation task", Sec. 7, with a cable
# stop); q2 +-90 deg; q3 +-120 deg, so that the camera can lean back (q2 < 0) and still
# look at an object 0.2 m in front of the palm from ~0.15 m away (tests/test_pa10.py).
MINI_Q_LIMIT_DEG = (180.0, 90.0, 120.0)
# ours: small-servo speeds (20 rpm for the turn around the task, 30 rpm for the pointing).
MINI_QD_MAX_DEG_S = (120.0, 180.0, 180.0)
# ours: 3-5x the largest static gravity load over all poses with the PA-10 stretched out
# (0.95 / 0.28 / 0.06 N m, tests/test_pa10.py), small-servo class, room for accelerations.
MINI_TAU_MAX = (3.0, 1.0, 0.3)


#: The mini-robot's links covered by capsules (swept-sphere lines) for the human-distance
#: of pomares2011 Sec. 4 (eq. 17): ``(link, p0, p1, radius)``, end points in the link frame
#: [m]. ours: the paper covers the links with SSLs but gives no sizes; each capsule holds
#: every box and servo cylinder of its link in ``make_urdf.py`` (tests/test_pa10.py
#: checks that the capsule distance never exceeds PyBullet's distance to the real
#: geometry): the radial arm and the post of link 1 (30 x 30 mm boxes, half diagonal
#: 21 mm, the joint-2 servo r 20 mm x 40 mm), the tube and joint-3 servo of link 2
#: (r 18 mm x 36 mm: corner 25.5 mm), the bracket and the 40 mm camera body (half
#: diagonal of its face 28.3 mm, 30 mm behind the optical centre) on link 3.
MINI_CAPSULES: tuple[tuple[str, tuple[float, float, float], tuple[float, float, float],
                           float], ...] = (
    ("mini_link1", (0.055, 0.0, -0.015), (0.13, 0.0, -0.015), 0.022),
    ("mini_link1", (0.13, 0.0, -0.015), (0.13, 0.0, 0.08), 0.029),
    ("mini_link2", (0.0, 0.0, 0.0), (0.0, 0.0, 0.10), 0.026),
    ("mini_link3", (0.0, 0.0, 0.018), (0.0, 0.0, 0.07), 0.029),
)


def _limits(q_deg: tuple[float, ...], qd_deg: tuple[float, ...],
            tau: tuple[float, ...]) -> JointLimits:
    return JointLimits(
        q_min=tuple(-float(np.deg2rad(v)) for v in q_deg),
        q_max=tuple(float(np.deg2rad(v)) for v in q_deg),
        qd_max=tuple(float(np.deg2rad(v)) for v in qd_deg),
        tau_max=tuple(float(v) for v in tau),
    )


PA10_LIMITS = _limits(PA10_Q_LIMIT_DEG, PA10_QD_MAX_DEG_S, PA10_TAU_MAX)
MINI_LIMITS = _limits(MINI_Q_LIMIT_DEG, MINI_QD_MAX_DEG_S, MINI_TAU_MAX)
_ARM_MINI_LIMITS = _limits(PA10_Q_LIMIT_DEG + MINI_Q_LIMIT_DEG,
                           PA10_QD_MAX_DEG_S + MINI_QD_MAX_DEG_S, PA10_TAU_MAX + MINI_TAU_MAX)
#: Limits of the 17 joints, in the order of :data:`ALL_JOINTS` (the hand's:
#: :data:`repro.sim.barrett.BH8_LIMITS`).
ALL_LIMITS = JointLimits(*(getattr(_ARM_MINI_LIMITS, f) + getattr(BH8_LIMITS, f)
                           for f in ("q_min", "q_max", "qd_max", "tau_max")))


def pa10_urdf_path() -> Path:
    """The packaged URDF (``repro/assets/pa10/pa10_mini.urdf``)."""
    return Path(__file__).resolve().parent.parent / "assets" / "pa10" / "pa10_mini.urdf"


def _dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """``Rz(theta) Tz(d) Tx(a) Rx(alpha)`` (4x4)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct],
                     [st, ct * ca, -ct * sa, a * st],
                     [0.0, sa, ca, d],
                     [0.0, 0.0, 0.0, 1.0]])


def pa10_dh_frames(q: np.ndarray) -> np.ndarray:
    """DH frames ``T_0i`` (7 x 4 x 4, i = 0..6) at PA-10 joint positions ``q`` [rad].

    Joint ``i`` turns about the ``z`` axis of frame ``i - 1``.
    """
    q = np.asarray(q, dtype=float)
    if q.shape != (6,):
        raise ConfigError(f"q must have 6 entries (the PA-10 joints), got shape {q.shape}")
    frames = [np.eye(4)]
    for qi, (offset, d, a, alpha) in zip(q, PA10_DH, strict=True):
        frames.append(frames[-1] @ _dh(qi + offset, d, a, alpha))
    return np.array(frames)


def pa10_dh_fk(q: np.ndarray) -> np.ndarray:
    """``T_base_flange`` (4x4) at PA-10 joint positions ``q`` [rad], from :data:`PA10_DH`
    (equals the URDF's ``pa10_flange`` in ``pa10_link0``)."""
    return pa10_dh_frames(q)[-1]
