"""Write ``crs_a465.urdf`` (next to this file) deterministically.

    .venv/bin/python repro/assets/crs_a465/make_urdf.py

Kinematics, limits and the camera mount come from :mod:`repro.sim.crs_a465` (published
figures, chan2011); the shapes, masses and colours below are ours (README.md says why).
Every link's inertia is computed from its primitives, each of uniform density within the
link (solid box / cylinder formulas plus the parallel-axis theorem), so the inertial
parameters are physically consistent. Only boxes and cylinders: PyBullet and pinocchio
both parse them (no meshes, no capsules). tests/test_crs_a465.py checks that the committed
URDF equals this script's output.
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from scipy.spatial.transform import Rotation

from repro.assets.urdf_primitives import (
    Body,
    Joint,
    Shape,
    add_joint,
    add_link,
    urdf_text,
    write_urdf,
)
from repro.sim.crs_a465 import (
    CRS_JOINTS,
    CRS_LIMITS,
    JOINT_AXES,
    LINK_LENGTHS,
    T_FLANGE_CAMERA,
)

URDF_PATH = Path(__file__).resolve().with_name("crs_a465.urdf")

_D1, _A2, _D4, _D6 = LINK_LENGTHS



GREY = (0.75, 0.75, 0.78, 1.0)
DARK = (0.25, 0.25, 0.28, 1.0)
BLUE = (0.15, 0.3, 0.6, 1.0)
BLACK = (0.08, 0.08, 0.08, 1.0)

# ours: shapes sized like the real arm (base column ~0.2 m diameter, upper arm and forearm
# 0.08-0.1 m thick), masses summing to the published 31 kg of the arm (links 0-6).
# Shapes of one link do not overlap, so uniform density per link is meaningful.
BODIES = (
    Body("crs_link0", 12.5, (
        Shape("box", (0.26, 0.26, 0.02), (0.0, 0.0, 0.01)),              # foot plate
        Shape("cylinder", (0.10, 0.20), (0.0, 0.0, 0.12)),               # base column
    ), DARK),
    Body("crs_link1", 7.0, (
        Shape("cylinder", (0.095, 0.04), (0.0, 0.0, 0.24)),              # waist turntable
        Shape("cylinder", (0.07, 0.18), (0.0, 0.0, _D1), "y"),           # shoulder housing
    ), GREY),
    Body("crs_link2", 5.0, (
        Shape("box", (0.09, 0.10, _A2), (0.0, 0.0, _A2 / 2)),            # upper arm
    ), GREY),
    Body("crs_link3", 2.0, (
        Shape("cylinder", (0.06, 0.14), (0.0, 0.0, 0.0), "y"),           # elbow housing
    ), BLUE),
    Body("crs_link4", 2.5, (
        Shape("cylinder", (0.04, 0.225), (0.0, 0.0, 0.06 + 0.225 / 2)),  # forearm
    ), GREY),
    Body("crs_link5", 1.7, (
        Shape("cylinder", (0.045, 0.10), (0.0, 0.0, 0.0), "y"),          # wrist housing
        Shape("cylinder", (0.032, 0.021), (0.0, 0.0, 0.045 + 0.021 / 2)),  # wrist stub
    ), BLUE),
    Body("crs_link6", 0.3, (
        Shape("cylinder", (0.032, 0.010), (0.0, 0.0, -0.005)),           # flange disc
    ), DARK),
    # ours: a small parallel gripper; palm on the flange, fingers along flange +z,
    # 48 mm apart (open), the TCP 10 mm short of the fingertips.
    Body("gripper_palm", 0.35, (Shape("box", (0.05, 0.10, 0.03), (0.0, 0.0, 0.015)),), DARK),
    Body("gripper_finger_left", 0.05, (Shape("box", (0.02, 0.012, 0.06), (0.0, 0.0, 0.03)),),
         GREY),
    Body("gripper_finger_right", 0.05, (Shape("box", (0.02, 0.012, 0.06), (0.0, 0.0, 0.03)),),
         GREY),
    # ours: Sony XC-HR70 with its 4.8 mm lens as a 0.05 x 0.05 x 0.07 m box along the
    # optical axis, its front 5 mm ahead of the optical centre (the body frame).
    Body("camera_body", 0.15, (Shape("box", (0.05, 0.05, 0.07), (0.0, 0.0, -0.03)),), BLACK),
)

#: Frame-only links (no mass, no geometry).
FRAMES = ("flange", "gripper_tcp", "camera_optical")

_FINGER_ROOT = (0.03, 0.03)  # ours: finger root, flange (|y|, z) [m]
_TCP_Z = 0.08  # ours: TCP on the flange axis, between the fingertips [m]


def _camera_origin() -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    xyz = tuple(float(v) for v in T_FLANGE_CAMERA[:3, 3])
    rpy = tuple(float(v) for v in Rotation.from_matrix(T_FLANGE_CAMERA[:3, :3]).as_euler("xyz"))
    return xyz, rpy  # type: ignore[return-value]


def joints() -> tuple[Joint, ...]:
    """Every joint of the tree, parents first."""
    cam_xyz, cam_rpy = _camera_origin()
    # Joint origins at q = 0 (all link frames parallel to the base frame): joint 1 on the
    # mounting surface, 2 at the shoulder, 3 and 4 at the elbow, 5 at the wrist centre,
    # 6 at the flange.
    origins = ((0.0, 0.0, 0.0), (0.0, 0.0, _D1), (0.0, 0.0, _A2), (0.0, 0.0, 0.0),
               (0.0, 0.0, _D4), (0.0, 0.0, _D6))
    arm = tuple(
        Joint(CRS_JOINTS[i], f"crs_link{i}", f"crs_link{i + 1}", origins[i],
              axis=JOINT_AXES[i], index=i)
        for i in range(6)
    )
    ry, rz = _FINGER_ROOT
    return arm + (
        Joint("flange_joint", "crs_link6", "flange", (0.0, 0.0, 0.0)),
        Joint("gripper_palm_joint", "flange", "gripper_palm", (0.0, 0.0, 0.0)),
        Joint("gripper_finger_left_joint", "flange", "gripper_finger_left", (0.0, ry, rz)),
        Joint("gripper_finger_right_joint", "flange", "gripper_finger_right", (0.0, -ry, rz)),
        Joint("gripper_tcp_joint", "flange", "gripper_tcp", (0.0, 0.0, _TCP_Z)),
        # chan2011 Sec. V-A: eT_c; the paper's camera frame is the optical frame.
        Joint("camera_body_joint", "flange", "camera_body", cam_xyz, cam_rpy),
        Joint("camera_optical_joint", "camera_body", "camera_optical", (0.0, 0.0, 0.0)),
    )


def build_urdf() -> str:
    """The URDF text (deterministic)."""
    robot = ET.Element("robot", name="crs_a465")
    robot.append(ET.Comment(
        " Generated by make_urdf.py (do not edit); README.md gives the source of every number. "))
    bodies = {b.name: b for b in BODIES}
    add_link(robot, bodies["crs_link0"], "crs_link0")
    for j in joints():
        add_link(robot, bodies.get(j.child), j.child)
        add_joint(robot, j.name, j.parent, j.child, j.xyz, j.rpy, j.axis, CRS_LIMITS, j.index)
    return urdf_text(robot)


def main() -> int:
    return write_urdf(URDF_PATH, build_urdf)


if __name__ == "__main__":
    sys.exit(main())
