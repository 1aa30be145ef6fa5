"""Write ``barrett_bh8.urdf`` (next to this file) deterministically.

    .venv/bin/python repro/assets/barrett_bh8/make_urdf.py

The Barrett BH8-282 hand alone, root link ``bh8_base`` (to be fixed on a flange). Kinematics
(Barrett's DH table), limits, masses and shape sizes come from :mod:`repro.sim.barrett`; the
placement of the shapes and the colours are below (README.md gives the source of every
number and what is ours). Every joint origin is the DH transform of its row at angle 0, so
the URDF links ``bh8_finger{k}_knuckle / _proximal / _distal / _tip`` are Barrett's frames
k1, k2, k3, kT. Inertias are computed from the primitives, each of uniform density within
its link (solid box / cylinder formulas plus the parallel-axis theorem,
:mod:`repro.assets.urdf_primitives`); the rounded fingertip is a contact shape only (its
mass is in the distal box). Only boxes and cylinders: PyBullet and pinocchio both parse them.
``<mimic>`` is not written: PyBullet ignores it, and the couplings are gear constraints
(:func:`repro.sim.barrett.add_coupling_constraints`). tests/test_barrett.py checks that the
committed URDF equals this script's output.
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from repro.assets.urdf_primitives import (
    Body,
    Joint,
    Shape,
    add_joint,
    add_link,
    fmt_vec,
    geometry,
    urdf_text,
    write_urdf,
)
from repro.sim.barrett import (
    BH8_A1,
    BH8_A2,
    BH8_A3,
    BH8_AW,
    BH8_D3,
    BH8_DW,
    BH8_GEOMETRY,
    BH8_JOINTS,
    BH8_LIMITS,
    BH8_PHI3,
)
from repro.sim.robot import JointLimits

URDF_PATH = Path(__file__).resolve().with_name("barrett_bh8.urdf")

_G = BH8_GEOMETRY
HALF_PI = float(np.pi / 2)

DARK = (0.25, 0.25, 0.28, 1.0)
GREY = (0.55, 0.55, 0.58, 1.0)
SILVER = (0.78, 0.78, 0.80, 1.0)


def _base_bodies() -> tuple[Body, ...]:
    """``bh8_base`` (wrist cylinder, spine) and ``bh8_palm`` (the palm plate under the palm
    surface, the link frame), 0.60 kg split by volume."""
    r, length = _G.wrist_cylinder
    spine, palm = _G.spine_box, _G.palm_box
    shapes_base = (
        Shape("cylinder", (r, length), (0.0, 0.0, length / 2)),
        Shape("box", spine, (0.0, 0.0, length + spine[2] / 2)),
    )
    shape_palm = Shape("box", palm, (0.0, 0.0, -palm[2] / 2))
    v_base = sum(s.volume() for s in shapes_base)
    m_palm = _G.base_mass * shape_palm.volume() / (v_base + shape_palm.volume())
    return (Body("bh8_base", _G.base_mass - m_palm, shapes_base, DARK),
            Body("bh8_palm", m_palm, (shape_palm,), DARK))


def _finger_bodies(k: int) -> tuple[Body, ...]:
    """Knuckle (arm under the palm plate, housing around the proximal axis), proximal and
    distal boxes of finger ``k``, each in its DH frame (x along, y inner normal)."""
    m_knuckle, m_prox, m_dist = _G.finger_masses
    arm, (r_h, l_h) = _G.knuckle_arm, _G.knuckle_housing
    knuckle = Body(f"bh8_finger{k}_knuckle", m_knuckle, (
        Shape("box", arm, (arm[0] / 2, 0.0, _G.knuckle_arm_top - arm[2] / 2)),
        Shape("cylinder", (r_h, l_h), (BH8_A1, 0.0, 0.0), "y"),  # around the proximal axis
    ), GREY)
    prox = _G.proximal_box
    proximal = Body(f"bh8_finger{k}_proximal", m_prox, (
        Shape("box", prox, (prox[0] / 2, 0.0, 0.0)),
    ), SILVER)
    dist = _G.distal_box
    distal = Body(f"bh8_finger{k}_distal", m_dist, (
        Shape("box", dist, (dist[0] / 2, BH8_D3, 0.0)),
    ), SILVER)
    return knuckle, proximal, distal


BODIES = _base_bodies() + tuple(b for k in (1, 2, 3) for b in _finger_bodies(k))
#: Frame-only links (no mass, no geometry).
FRAMES = ("bh8_palm_pad",) + tuple(
    f"bh8_finger{k}_{part}" for k in (1, 2, 3) for part in ("proximal_pad", "distal_pad", "tip"))


def _tip_shape() -> Shape:
    """The rounded fingertip in the distal frame: a cylinder along the flexion axis on the
    DH tip point (A3, D3), as wide as the distal."""
    return Shape("cylinder", (_G.tip_radius, _G.distal_box[2]), (BH8_A3, BH8_D3, 0.0))


def joints() -> tuple[Joint, ...]:
    """Every joint of the tree, parents first, finger by finger. Each DH row
    ``Rx(alpha) Tx(a) Rz(theta) Tz(d)`` at angle 0 is the origin ``xyz = (a, -sin(alpha) d,
    cos(alpha) d)``, ``rpy = (alpha, 0, theta_0)``."""
    pad_rpy = (-HALF_PI, 0.0, 0.0)  # pad z = phalanx y (inner normal), pad x = phalanx x
    out = [
        Joint("bh8_palm_joint", "bh8_base", "bh8_palm", (0.0, 0.0, _G.palm_height)),
        Joint("bh8_palm_pad_joint", "bh8_palm", "bh8_palm_pad", (0.0, 0.0, 0.0)),
    ]
    for k, r, j in ((1, -1, 1), (2, 1, 1), (3, 0, -1)):
        knuckle, prox, dist = (f"bh8_finger{k}_{part}" for part in ("knuckle", "proximal",
                                                                     "distal"))
        spread_xyz = (r * BH8_AW, 0.0, BH8_DW)
        spread_rpy = (0.0, 0.0, -j * HALF_PI)
        if r != 0:  # theta = r q_spread - j pi/2: axis r z
            out.append(Joint(f"bh8_finger{k}_spread", "bh8_base", knuckle, spread_xyz,
                             spread_rpy, (0.0, 0.0, float(r))))
        else:
            out.append(Joint(f"bh8_finger{k}_knuckle_joint", "bh8_base", knuckle, spread_xyz,
                             spread_rpy))
        out += [
            Joint(f"bh8_finger{k}_proximal_joint", knuckle, prox, (BH8_A1, 0.0, 0.0),
                  (HALF_PI, 0.0, 0.0), (0.0, 0.0, 1.0)),
            Joint(f"bh8_finger{k}_proximal_pad_joint", prox, f"{prox}_pad",
                  (_G.proximal_pad_x, _G.proximal_face, 0.0), pad_rpy),
            Joint(f"bh8_finger{k}_distal_joint", prox, dist, (BH8_A2, 0.0, 0.0),
                  (0.0, 0.0, BH8_PHI3), (0.0, 0.0, 1.0)),
            Joint(f"bh8_finger{k}_distal_pad_joint", dist, f"{dist}_pad",
                  (_G.distal_box[0] / 2, _G.distal_face, 0.0), pad_rpy),
            # kT: Rx(-pi/2) Tx(A3) Tz(D3): at (A3, D3, 0) (z = the distal's y).
            Joint(f"bh8_finger{k}_tip_joint", dist, f"bh8_finger{k}_tip", (BH8_A3, BH8_D3, 0.0),
                  (-HALF_PI, 0.0, 0.0)),
        ]
    return tuple(out)


def add_hand_tree(robot: ET.Element, limits: JointLimits, joint_names: tuple[str, ...]) -> None:
    """Append every link and joint of the hand below ``bh8_base`` (already in ``robot``) to
    ``robot``; the revolute joints take their limits from ``limits`` at their index in
    ``joint_names`` (the standalone hand: :data:`BH8_LIMITS`, :data:`BH8_JOINTS`; the PA-10
    chain: its own). The rounded fingertip is a second visual and collision shape of each
    distal link."""
    bodies = {b.name: b for b in BODIES}
    for jt in joints():
        add_link(robot, bodies.get(jt.child), jt.child)
        if jt.child.endswith("_distal"):
            link = robot.find(f"link[@name='{jt.child}']")
            assert link is not None
            vis = ET.SubElement(link, "visual")
            geometry(vis, _tip_shape())
            mat = ET.SubElement(vis, "material", name=f"{jt.child}_tip_color")
            ET.SubElement(mat, "color", rgba=fmt_vec(SILVER))
            geometry(ET.SubElement(link, "collision"), _tip_shape())
        add_joint(robot, jt.name, jt.parent, jt.child, jt.xyz, jt.rpy, jt.axis, limits,
                  joint_names.index(jt.name) if jt.axis is not None else -1)


def base_body() -> Body:
    """The root link ``bh8_base`` (mounting face, wrist cylinder, spine)."""
    return next(b for b in BODIES if b.name == "bh8_base")


def build_urdf() -> str:
    """The URDF text (deterministic)."""
    robot = ET.Element("robot", name="barrett_bh8")
    robot.append(ET.Comment(
        " Generated by make_urdf.py (do not edit); README.md gives the source of every number. "))
    add_link(robot, base_body(), "bh8_base")
    add_hand_tree(robot, BH8_LIMITS, BH8_JOINTS)
    return urdf_text(robot)


def main() -> int:
    return write_urdf(URDF_PATH, build_urdf)


if __name__ == "__main__":
    sys.exit(main())
