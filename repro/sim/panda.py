"""The Franka Emika Panda, from ``pybullet_data``, with our own attachments.

The URDF shipped in ``pybullet_data/franka_panda/panda.urdf`` has placeholder
inertias and joint limits wider than Franka's official ones. We keep its
kinematics and meshes, drop the gripper (in thomas2024 the proximity ring at
the flange is the end-effector), add rigidly attached bodies (rings, camera)
as fixed links, and use Franka's published limits in :data:`PANDA_LIMITS`.

The generated URDF is written to a file that both PyBullet and pinocchio load.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet_data
from scipy.spatial.transform import Rotation

from repro.sim.robot import JointLimits

PANDA_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))

# Franka Emika Panda datasheet ("Robot and interface specifications", FCI docs):
# q_min/q_max [rad], qd_max [rad/s], tau_max [N m].
PANDA_LIMITS = JointLimits(
    q_min=(-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973),
    q_max=(2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973),
    qd_max=(2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100),
    tau_max=(87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0),
)

_DROP_LINKS = {"panda_hand", "panda_leftfinger", "panda_rightfinger", "panda_grasptarget"}


@dataclass(frozen=True)
class Attachment:
    """A rigid body fixed to a robot link, added to the URDF as a fixed joint + link.

    Attributes:
        name: link name of the attachment (also a pinocchio frame).
        parent: link it is fixed to.
        T_parent_child: pose of the attachment frame in the parent link frame [m].
        shape: "cylinder" (axis = child z), "box", or "none" (a frame only).
        size: cylinder (radius, length) or box (x, y, z) full sizes [m].
        rgba: colour.
        mass: [kg].
        collision: whether it has collision geometry.
    """

    name: str
    parent: str
    T_parent_child: np.ndarray
    shape: str = "none"
    size: tuple[float, ...] = ()
    rgba: tuple[float, float, float, float] = (0.2, 0.2, 0.2, 1.0)
    mass: float = 0.05
    collision: bool = True


def _origin(T: np.ndarray) -> dict[str, str]:
    rpy = Rotation.from_matrix(T[:3, :3]).as_euler("xyz")
    return {
        "xyz": " ".join(f"{v:.9g}" for v in T[:3, 3]),
        "rpy": " ".join(f"{v:.9g}" for v in rpy),
    }


def _geometry(parent: ET.Element, a: Attachment) -> None:
    geom = ET.SubElement(parent, "geometry")
    if a.shape == "cylinder":
        ET.SubElement(geom, "cylinder", radius=f"{a.size[0]}", length=f"{a.size[1]}")
    elif a.shape == "box":
        ET.SubElement(geom, "box", size=" ".join(f"{s}" for s in a.size))


def build_panda_urdf(dest: Path, attachments: tuple[Attachment, ...] = (),
                     visual_from_collision: bool = True) -> Path:
    """Write the Panda URDF (no gripper, official limits, attachments) to ``dest``.

    Mesh paths are made absolute (into the installed ``pybullet_data``); a
    :class:`repro.sim.scene.Scene` copies the meshes next to a run's URDF and makes them
    relative. With ``visual_from_collision`` the links are drawn with their collision
    meshes (444 kB instead of 9 MB of visual meshes per run; no camera of the suite sees
    the robot, only third-person videos do).
    """
    src_dir = Path(pybullet_data.getDataPath()) / "franka_panda"
    tree = ET.parse(src_dir / "panda.urdf")
    robot = tree.getroot()
    for link in list(robot.findall("link")):
        if link.get("name") in _DROP_LINKS:
            robot.remove(link)
    for joint in list(robot.findall("joint")):
        child = joint.find("child")
        if child is not None and child.get("link") in _DROP_LINKS:
            robot.remove(joint)
    for mesh in robot.iter("mesh"):
        fn = mesh.get("filename", "")
        if visual_from_collision:
            fn = fn.replace("meshes/visual/", "meshes/collision/").replace(".dae", ".obj")
        mesh.set("filename", str(src_dir / fn.replace("package://", "")))
    for i, name in enumerate(PANDA_JOINTS):
        arm_joint = robot.find(f"joint[@name='{name}']")
        assert arm_joint is not None
        lim = arm_joint.find("limit")
        assert lim is not None
        lim.set("lower", f"{PANDA_LIMITS.q_min[i]}")
        lim.set("upper", f"{PANDA_LIMITS.q_max[i]}")
        lim.set("velocity", f"{PANDA_LIMITS.qd_max[i]}")
        lim.set("effort", f"{PANDA_LIMITS.tau_max[i]}")
    for a in attachments:
        link = ET.SubElement(robot, "link", name=a.name)
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "origin", xyz="0 0 0", rpy="0 0 0")
        ET.SubElement(inertial, "mass", value=f"{a.mass}")
        ET.SubElement(inertial, "inertia", ixx="1e-4", ixy="0", ixz="0", iyy="1e-4", iyz="0",
                      izz="1e-4")
        if a.shape != "none":
            vis = ET.SubElement(link, "visual")
            _geometry(vis, a)
            mat = ET.SubElement(vis, "material", name=f"{a.name}_color")
            ET.SubElement(mat, "color", rgba=" ".join(f"{c}" for c in a.rgba))
            if a.collision:
                col = ET.SubElement(link, "collision")
                _geometry(col, a)
        fixed = ET.SubElement(robot, "joint", name=f"{a.name}_joint", type="fixed")
        ET.SubElement(fixed, "origin", attrib=_origin(np.asarray(a.T_parent_child)))
        ET.SubElement(fixed, "parent", link=a.parent)
        ET.SubElement(fixed, "child", link=a.name)
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    ET.indent(tree)
    tree.write(dest, xml_declaration=True, encoding="utf-8")
    return dest
