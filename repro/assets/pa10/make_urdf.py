"""Write ``pa10_mini.urdf`` (next to this file) deterministically.

    .venv/bin/python repro/assets/pa10/make_urdf.py

Kinematics, limits and masses come from :mod:`repro.sim.pa10` (ARTE's DH table and
limits, the manufacturer's 7-DoF link masses and the mini-robot sizes); the link shapes and
colours below are ours (README.md says why). The Barrett BH8-282 on the flange is the
standalone hand's tree (``repro/assets/barrett_bh8/make_urdf.py``, the suite's one hand
model), its root ``bh8_base`` fixed on ``pa10_flange``. Every link's
inertia is computed from its primitives, each of uniform density within the link (solid
box / cylinder formulas plus the parallel-axis theorem); a link whose tensor is not
diagonal in its own axes gets its inertial frame on the principal axes (PyBullet reads only
the diagonal). Only boxes and cylinders: PyBullet and pinocchio both parse them.
tests/test_pa10.py checks that the committed URDF equals this script's output.
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from repro.assets.barrett_bh8 import make_urdf as bh8
from repro.assets.urdf_primitives import (
    Body,
    Shape,
    add_joint,
    add_link,
    rpy_of,
    urdf_text,
    write_urdf,
)
from repro.sim.pa10 import (
    ALL_JOINTS,
    ALL_LIMITS,
    MINI_GEOMETRY,
    MINI_MASSES,
    PA10_FOREARM_ROLL_OFFSET,
    PA10_LINK_MASSES,
    pa10_dh_frames,
)

URDF_PATH = Path(__file__).resolve().with_name("pa10_mini.urdf")


@dataclass(frozen=True)
class Joint:
    """A joint: parent -> child at ``xyz`` [m] with rotation ``R`` (3x3, parent axes)."""

    name: str
    parent: str
    child: str
    xyz: tuple[float, ...]
    R: tuple[tuple[float, ...], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    axis: tuple[float, ...] | None = None  # None: fixed joint


WHITE = (0.85, 0.85, 0.82, 1.0)
BLUE = (0.15, 0.3, 0.6, 1.0)
DARK = (0.25, 0.25, 0.28, 1.0)
ORANGE = (0.9, 0.5, 0.1, 1.0)
BLACK = (0.08, 0.08, 0.08, 1.0)

_M = PA10_LINK_MASSES
_G = MINI_GEOMETRY

# ours: PA-10 shapes sized like the real arm, guided by the collision primitives of
# Choreonoid's PA10.body (base column r 0.115, arm tubes r 0.05-0.06, wrist r 0.035-0.045).
# Link frames: at the joint origins (README), parallel to the base frame at q = 0.
# Shapes of one link do not overlap, so uniform density per link is meaningful.
PA10_BODIES = (
    Body("pa10_link0", _M[0], (
        Shape("cylinder", (0.115, 0.20), (0.0, 0.0, 0.10)),                 # base column
    ), WHITE),
    Body("pa10_link1", _M[1], (
        Shape("cylinder", (0.115, 0.02), (0.0, 0.0, 0.21)),                 # turntable
        Shape("cylinder", (0.09, 0.035), (0.0, 0.0, 0.2375)),               # pedestal
        Shape("cylinder", (0.06, 0.23), (0.0, 0.0, 0.315), "y"),            # shoulder
    ), WHITE),
    Body("pa10_link2", _M[2], (
        Shape("cylinder", (0.06, 0.33), (0.0, 0.0, 0.225)),                 # upper arm
    ), WHITE),
    Body("pa10_link3", _M[3], (
        Shape("cylinder", (0.06, 0.12), (0.0, 0.0, 0.0), "y"),              # elbow
        Shape("cylinder", (0.05, 0.19), (0.0, 0.0, 0.155)),                 # lower forearm
    ), BLUE),
    Body("pa10_link4", _M[4], (
        Shape("cylinder", (0.06, 0.07), (0.0, 0.0, 0.035)),                 # roll housing
        Shape("box", (0.07, 0.03, 0.21), (0.0, 0.065, 0.175)),              # wrist yoke +y
        Shape("box", (0.07, 0.03, 0.21), (0.0, -0.065, 0.175)),             # wrist yoke -y
    ), WHITE),
    Body("pa10_link5", _M[5], (
        Shape("cylinder", (0.045, 0.10), (0.0, 0.0, 0.0), "y"),             # wrist housing
        Shape("cylinder", (0.035, 0.03), (0.0, 0.0, 0.06)),                 # wrist stub
    ), BLUE),
    Body("pa10_link6", _M[6], (
        Shape("cylinder", (0.04, 0.005), (0.0, 0.0, -0.0025)),              # flange disc
    ), DARK),
)


def _mini_bodies() -> tuple[Body, ...]:
    """The RRR mini-robot (ours): clamp ring, arm + post + joint-2 servo, tube + joint-3
    servo, camera bracket, camera body (its frame at the optical centre)."""
    R, h2, l2, l3 = _G.radius, _G.joint2_height, _G.link2, _G.link3
    m = MINI_MASSES
    return (
        Body("mini_base", m["mini_base"], (
            Shape("cylinder", (0.065, 0.03), (0.0, 0.0, -0.015)),            # clamp ring
        ), ORANGE),
        Body("mini_link1", m["mini_link1"], (
            Shape("box", (R + 0.015 - 0.07, 0.03, 0.03),
                  ((0.07 + R + 0.015) / 2, 0.0, -0.015)),                    # radial arm
            Shape("box", (0.03, 0.03, h2 - 0.02), (R, 0.0, (h2 - 0.02) / 2)),  # post
            Shape("cylinder", (0.02, 0.04), (R, 0.0, h2), "y"),             # joint-2 servo
        ), ORANGE),
        Body("mini_link2", m["mini_link2"], (
            Shape("box", (0.02, 0.02, l2 - 0.038), (0.0, 0.0, 0.02 + (l2 - 0.038) / 2)),
            Shape("cylinder", (0.018, 0.036), (0.0, 0.0, l2), "y"),         # joint-3 servo
        ), ORANGE),
        Body("mini_link3", m["mini_link3"], (
            Shape("box", (0.03, 0.03, 0.012), (0.0, 0.0, 0.024)),           # bracket
        ), ORANGE),
        # ours: GigE camera with lens as a 0.04 x 0.04 x 0.04 m box along the optical
        # axis, its front at the optical centre (the camera frame), its back on the bracket.
        Body("mini_camera", m["mini_camera"], (
            Shape("box", (0.04, 0.04, l3 - 0.03), (0.0, 0.0, -(l3 - 0.03) / 2)),
        ), BLACK),
    )


BODIES = PA10_BODIES + _mini_bodies()
#: Frame-only links (no mass, no geometry) of the arm and the mini-robot (the hand's:
#: ``bh8.FRAMES``).
FRAMES = ("pa10_flange", "mini_camera_optical")
#: The fixed joint that mounts the hand's root ``bh8_base`` on the flange (identity).
HAND_MOUNT_JOINT = "bh8_mount_joint"

def _tup(a: np.ndarray) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in np.asarray(a))


def _pa10_joints() -> tuple[Joint, ...]:
    """PA-10 joints from the DH frames at q = 0: joint i on the DH axis z_{i-1}, at the
    origin of DH frame i-1, except joint 4 (forearm roll, PA10_FOREARM_ROLL_OFFSET up the
    forearm) and joint 6 (at the flange, d6 out). All link frames parallel to the base."""
    T0 = pa10_dh_frames(np.zeros(6))
    shift = (0.0, 0.0, 0.0, PA10_FOREARM_ROLL_OFFSET, 0.0, T0[6][2, 3] - T0[5][2, 3])
    origins = [T0[i][:3, 3] + shift[i] * T0[i][:3, 2] for i in range(6)]
    joints = []
    prev = np.zeros(3)
    for i in range(6):
        joints.append(Joint(ALL_JOINTS[i], f"pa10_link{i}", f"pa10_link{i + 1}",
                            tuple(origins[i] - prev), axis=tuple(T0[i][:3, 2])))
        prev = origins[i]
    # DH frame 6 = the flange: at joint 6's origin, rotated as T_06(0).
    joints.append(Joint("pa10_flange_joint", "pa10_link6", "pa10_flange",
                        tuple(T0[6][:3, 3] - prev), _tup(T0[6][:3, :3])))
    return tuple(joints)


def _mini_joints() -> tuple[Joint, ...]:
    # Camera frame in mini_link3: Rz(-90 deg): optical x = -y, optical y = +x (radially
    # outward at q = 0), optical z = +z (forward).
    R_cam = ((0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    return (
        Joint("mini_base_joint", "pa10_flange", "mini_base", (0.0, 0.0, 0.0)),
        Joint("mini_joint1", "mini_base", "mini_link1", (0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0)),
        Joint("mini_joint2", "mini_link1", "mini_link2", (_G.radius, 0.0, _G.joint2_height),
              axis=(0.0, -1.0, 0.0)),
        Joint("mini_joint3", "mini_link2", "mini_link3", (0.0, 0.0, _G.link2),
              axis=(0.0, -1.0, 0.0)),
        Joint("mini_camera_joint", "mini_link3", "mini_camera", (0.0, 0.0, _G.link3), R_cam),
        Joint("mini_camera_optical_joint", "mini_camera", "mini_camera_optical",
              (0.0, 0.0, 0.0)),
    )


def joints() -> tuple[Joint, ...]:
    """Every joint of the arm and the mini-robot, parents first (the hand's: ``bh8.joints``,
    below :data:`HAND_MOUNT_JOINT`)."""
    return _pa10_joints() + _mini_joints()


def build_urdf() -> str:
    """The URDF text (deterministic)."""
    robot = ET.Element("robot", name="pa10_mini")
    robot.append(ET.Comment(
        " Generated by make_urdf.py (do not edit); README.md gives the source of every number. "))
    bodies = {b.name: b for b in BODIES}
    add_link(robot, bodies["pa10_link0"], "pa10_link0")
    for j in joints():
        add_link(robot, bodies.get(j.child), j.child)
        add_joint(robot, j.name, j.parent, j.child, j.xyz, rpy_of(j.R), j.axis, ALL_LIMITS,
                  ALL_JOINTS.index(j.name) if j.axis is not None else -1)
    # The Barrett BH8-282 (repro/assets/barrett_bh8, the suite's one hand model), its root on
    # the flange: bh8_base = pa10_flange.
    add_joint(robot, HAND_MOUNT_JOINT, "pa10_flange", "bh8_base", (0.0, 0.0, 0.0),
              (0.0, 0.0, 0.0), None)
    add_link(robot, bh8.base_body(), "bh8_base")
    bh8.add_hand_tree(robot, ALL_LIMITS, ALL_JOINTS)
    return urdf_text(robot)


def main() -> int:
    return write_urdf(URDF_PATH, build_urdf)


if __name__ == "__main__":
    sys.exit(main())
