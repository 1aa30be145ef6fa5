"""The CRS-A465 (Thermo/CRS Robotics, 6 DoF) of chan2011, as our own primitive-shape URDF.

The URDF ``repro/assets/crs_a465/crs_a465.urdf`` is written by
``repro/assets/crs_a465/make_urdf.py`` from the numbers below (published figures) and the
shapes and masses in that script (ours); ``repro/assets/crs_a465/README.md`` gives the
source of every number.

Conventions:

* **Zero configuration** ``q = 0``: the CRS "ready" pose, the arm straight up; every
  link frame then has the orientation of the base frame.
* **Base frame** ``crs_link0``: origin on the mounting surface, on the joint-1 axis;
  ``+z`` up.
* **Joint axes** (in the base frame at ``q = 0``): z, -y, -y, z, -y, z. Joint 1 is the
  vertical waist; 2 and 3 are shoulder and elbow pitch, 4 the forearm roll, 5 the wrist
  pitch and 6 the flange roll. Positive q2, q3, q5 tilt the arm towards ``-x``.
* **Flange frame** ``flange`` (= ``crs_link6``, the frame of the last DH row, the paper's
  end-effector frame ``F_e``): at the tool flange, ``+z`` out of the flange.
* **Camera frame** ``camera_optical`` = the paper's ``F_c`` (x right, y down, z along the
  optical axis), at ``T_flange_camera = eT_c`` (chan2011 Sec. V-A).

Standard DH table (``T_{i-1,i} = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``,
``theta_i = q_i + offset_i``), which reproduces the URDF's ``T_base_flange`` exactly:

====  ===========  =======  =======  ========
 i    offset_i     d_i [m]  a_i [m]  alpha_i
====  ===========  =======  =======  ========
 1       0          0.330    0        +90 deg
 2     +90 deg      0        0.305     0
 3     -90 deg      0        0        -90 deg
 4       0          0.330    0        +90 deg
 5       0          0        0        -90 deg
 6       0          0.076    0         0
====  ===========  =======  =======  ========
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from repro.errors import ConfigError
from repro.sim.robot import JointLimits

CRS_JOINTS = tuple(f"crs_joint{i}" for i in range(1, 7))
#: Links of the arm in chain order, from the fixed base crs_link0 to the flange link.
CRS_LINKS = tuple(f"crs_link{i}" for i in range(0, 7))

# Published CRS-A465 figures (public datasheet values; see the asset README).
#: Joint position limits, symmetric +- [deg].
Q_LIMIT_DEG = (175.0, 90.0, 110.0, 180.0, 105.0, 180.0)
#: Maximum joint speeds [deg/s].
QD_MAX_DEG_S = (180.0, 180.0, 180.0, 171.0, 173.0, 171.0)
#: Link lengths [m]: base to shoulder, shoulder to elbow, elbow to wrist, wrist to flange.
LINK_LENGTHS = (0.330, 0.305, 0.330, 0.076)
#: Joint axes in the base frame at q = 0 (and in each joint's own frame).
JOINT_AXES = ((0, 0, 1), (0, -1, 0), (0, -1, 0), (0, 0, 1), (0, -1, 0), (0, 0, 1))
# ours: torque limits [N m]; CRS does not publish joint torques. Tens of N m for the arm
# joints (about 2x / 3x the static gravity load at joints 2 / 3 of the outstretched arm with
# gripper and camera, room for a ~2 kg payload), a few N m for the wrist.
TAU_MAX = (60.0, 80.0, 40.0, 8.0, 8.0, 4.0)

CRS_LIMITS = JointLimits(
    q_min=tuple(-float(np.deg2rad(v)) for v in Q_LIMIT_DEG),
    q_max=tuple(float(np.deg2rad(v)) for v in Q_LIMIT_DEG),
    qd_max=tuple(float(np.deg2rad(v)) for v in QD_MAX_DEG_S),
    tau_max=TAU_MAX,
)

#: Standard DH rows (theta offset [rad], d [m], a [m], alpha [rad]); see the module docstring.
CRS_DH = (
    (0.0, LINK_LENGTHS[0], 0.0, np.pi / 2),
    (np.pi / 2, 0.0, LINK_LENGTHS[1], 0.0),
    (-np.pi / 2, 0.0, 0.0, -np.pi / 2),
    (0.0, LINK_LENGTHS[2], 0.0, np.pi / 2),
    (0.0, 0.0, 0.0, -np.pi / 2),
    (0.0, LINK_LENGTHS[3], 0.0, 0.0),
)


def _rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    return T


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    T = np.eye(4)
    T[0:2, 0:2] = [[c, -s], [s, c]]
    return T


def _trans(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


# chan2011 Sec. V-A: eT_c = Rz(90 deg) Rx(-12.5 deg) Txyz(0, -0.085, 0.070) [m], measured
# by hand "roughly assuming the location of the optical center". Read as the pose of the
# camera (optical) frame in the flange frame, the product taken left to right (the
# translation is along the axes of the already rotated frame).
T_FLANGE_CAMERA = _rot_z(np.deg2rad(90.0)) @ _rot_x(np.deg2rad(-12.5)) @ _trans(0.0, -0.085, 0.070)


def crs_urdf_path() -> Path:
    """The packaged CRS-A465 URDF (``repro/assets/crs_a465/crs_a465.urdf``)."""
    return Path(__file__).resolve().parent.parent / "assets" / "crs_a465" / "crs_a465.urdf"


def velocity_limits(fraction: float) -> np.ndarray:
    """``fraction`` of the maximum joint speeds [rad/s] (chan2011 Sec. V-A uses 0.05).

    For a :class:`Robot` that clips its commands to them:
    ``dataclasses.replace(CRS_LIMITS, qd_max=tuple(velocity_limits(0.05)))``.
    """
    if not 0.0 < fraction <= 1.0:
        raise ConfigError(f"velocity fraction must be in (0, 1], got {fraction!r}")
    return fraction * np.asarray(CRS_LIMITS.qd_max)


def dh_flange_pose(q: np.ndarray) -> np.ndarray:
    """``T_base_flange`` (4x4) at joint positions ``q`` [rad], from :data:`CRS_DH`."""
    q = np.asarray(q, dtype=float)
    if q.shape != (6,):
        raise ConfigError(f"q must have 6 entries, got shape {q.shape}")
    T = np.eye(4)
    for qi, (offset, d, a, alpha) in zip(q, CRS_DH, strict=True):
        T = T @ _rot_z(qi + offset) @ _trans(0.0, 0.0, d) @ _trans(a, 0.0, 0.0) @ _rot_x(alpha)
    return T
