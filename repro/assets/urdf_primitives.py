"""Primitive links for the URDFs we generate (CRS-A465, PA-10 + mini-robot): boxes and
cylinders of uniform density per link, their mass properties, and deterministic XML.

Only boxes and cylinders: PyBullet and pinocchio both parse them (no meshes, no capsules).
Numbers are written with 12 significant digits and no "-0", so a generator reproduces its
committed URDF byte for byte (each asset's test checks it).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from repro.sim.robot import JointLimits

__all__ = ["Body", "Joint", "Shape", "add_joint", "add_link", "fmt", "fmt_vec", "geometry",
           "mass_properties", "principal_axes", "rpy_of", "urdf_text", "write_urdf"]


@dataclass(frozen=True)
class Shape:
    """A primitive of a link, axis-aligned with the link frame.

    Attributes:
        kind: "box" or "cylinder".
        size: box full sizes (x, y, z) [m]; cylinder (radius, length) [m].
        xyz: centre in the link frame [m].
        axis: cylinder axis, "z" or "y" of the link frame (boxes: "z").
    """

    kind: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: str = "z"

    def volume(self) -> float:
        """[m^3]"""
        if self.kind == "box":
            return float(np.prod(self.size))
        r, length = self.size
        return float(np.pi * r**2 * length)

    def inertia(self, mass: float) -> np.ndarray:
        """3x3 inertia [kg m^2] of a solid body of ``mass`` [kg], about its centre, link axes."""
        if self.kind == "box":
            x, y, z = self.size
            return mass / 12.0 * np.diag([y**2 + z**2, x**2 + z**2, x**2 + y**2])
        r, length = self.size
        radial = mass * (3.0 * r**2 + length**2) / 12.0
        axial = mass * r**2 / 2.0
        return np.diag([radial, axial, radial] if self.axis == "y" else [radial, radial, axial])


@dataclass(frozen=True)
class Joint:
    """A joint: parent -> child at ``xyz`` [m] / ``rpy`` [rad] (URDF convention).

    ``axis`` None: a fixed joint; ``index``: the joint's position in the robot's limits
    (-1: take it from elsewhere, or a fixed joint)."""

    name: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] | None = None
    index: int = -1


@dataclass(frozen=True)
class Body:
    """A link: a mass [kg] spread uniformly over its shapes, and a colour (RGBA)."""

    name: str
    mass: float
    shapes: tuple[Shape, ...]
    rgba: tuple[float, float, float, float]


def fmt(v: float) -> str:
    v = round(float(v), 12) + 0.0  # + 0.0: no "-0"
    return f"{v:.12g}"


def fmt_vec(vs: tuple[float, ...] | np.ndarray) -> str:
    return " ".join(fmt(v) for v in vs)


def rpy_of(R: tuple[tuple[float, ...], ...] | np.ndarray) -> tuple[float, float, float]:
    """URDF rpy [rad] of a rotation matrix (entries within 1e-12 of 0 snapped to 0)."""
    M = np.array(R, dtype=float)
    M[np.abs(M) < 1e-12] = 0.0
    r, p, y = Rotation.from_matrix(M).as_euler("xyz")
    return float(r), float(p), float(y)


def mass_properties(body: Body) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass [m] and inertia about it [kg m^2], link axes."""
    vols = np.array([s.volume() for s in body.shapes])
    masses = body.mass * vols / vols.sum()
    centres = np.array([s.xyz for s in body.shapes])
    com = masses @ centres / body.mass
    inertia = np.zeros((3, 3))
    for s, m, c in zip(body.shapes, masses, centres, strict=True):
        d = c - com
        inertia += s.inertia(m) + m * (d @ d * np.eye(3) - np.outer(d, d))
    return com, inertia


def principal_axes(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(moments [kg m^2], rotation R_link_inertial) with ``inertia = R diag(moments) R^T``.

    Identity when the tensor is already diagonal; otherwise the eigenvectors, each signed so
    that its largest component is positive, the last flipped if needed to make R proper.
    """
    off = inertia - np.diag(np.diag(inertia))
    if np.abs(off).max() <= 1e-12 * np.abs(inertia).max():
        return np.diag(inertia).copy(), np.eye(3)
    moments, R = np.linalg.eigh(inertia)
    for k in range(3):
        if R[np.argmax(np.abs(R[:, k])), k] < 0:
            R[:, k] *= -1.0
    if np.linalg.det(R) < 0:
        R[:, 2] *= -1.0
    return moments, R


def geometry(parent: ET.Element, s: Shape) -> None:
    rpy = (np.pi / 2, 0.0, 0.0) if s.axis == "y" else (0.0, 0.0, 0.0)
    ET.SubElement(parent, "origin", xyz=fmt_vec(s.xyz), rpy=fmt_vec(rpy))
    geom = ET.SubElement(parent, "geometry")
    if s.kind == "box":
        ET.SubElement(geom, "box", size=fmt_vec(s.size))
    else:
        ET.SubElement(geom, "cylinder", radius=fmt(s.size[0]), length=fmt(s.size[1]))


def add_link(robot: ET.Element, body: Body | None, name: str) -> None:
    link = ET.SubElement(robot, "link", name=name)
    inertial = ET.SubElement(link, "inertial")
    if body is None:  # a frame: no mass
        ET.SubElement(inertial, "origin", xyz="0 0 0", rpy="0 0 0")
        ET.SubElement(inertial, "mass", value="0")
        ET.SubElement(inertial, "inertia", ixx="0", ixy="0", ixz="0", iyy="0", iyz="0",
                      izz="0")
        return
    com, inertia = mass_properties(body)
    moments, R = principal_axes(inertia)
    ET.SubElement(inertial, "origin", xyz=fmt_vec(com), rpy=fmt_vec(rpy_of(R)))
    ET.SubElement(inertial, "mass", value=fmt(body.mass))
    ET.SubElement(inertial, "inertia", ixx=fmt(moments[0]), ixy="0", ixz="0",
                  iyy=fmt(moments[1]), iyz="0", izz=fmt(moments[2]))
    for k, s in enumerate(body.shapes):
        vis = ET.SubElement(link, "visual")
        geometry(vis, s)
        mat = ET.SubElement(vis, "material", name=f"{body.name}_color{k}")
        ET.SubElement(mat, "color", rgba=fmt_vec(body.rgba))
    for s in body.shapes:
        geometry(ET.SubElement(link, "collision"), s)


def add_joint(robot: ET.Element, name: str, parent: str, child: str,
              xyz: tuple[float, ...] | np.ndarray, rpy: tuple[float, ...] | np.ndarray,
              axis: tuple[float, ...] | None, limits: JointLimits | None = None,
              index: int = -1) -> None:
    """A fixed joint (``axis`` None) or a revolute one with ``limits`` of joint ``index``."""
    joint = ET.SubElement(robot, "joint", name=name,
                          type="fixed" if axis is None else "revolute")
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    ET.SubElement(joint, "origin", xyz=fmt_vec(xyz), rpy=fmt_vec(rpy))
    if axis is not None:
        assert limits is not None and index >= 0
        ET.SubElement(joint, "axis", xyz=fmt_vec(axis))
        ET.SubElement(joint, "limit", lower=fmt(limits.q_min[index]),
                      upper=fmt(limits.q_max[index]), velocity=fmt(limits.qd_max[index]),
                      effort=fmt(limits.tau_max[index]))


def urdf_text(robot: ET.Element) -> str:
    """The deterministic text of a URDF tree (indented, XML declaration, final newline)."""
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def write_urdf(path: Path, build: Callable[[], str]) -> int:
    """A generator script's ``main``: write ``build()`` to ``path``; exit status 0."""
    path.write_text(build())
    print(f"wrote {path}")
    return 0
