"""Exact distances (coal) on known solutions, and how far the audit's PyBullet distances are
from them on every robot of the suite."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

import repro
from repro.sim.exact_distance import BULLET_AUDIT_TOL, ExactDistances
from repro.sim.panda import build_panda_urdf
from repro.sim.robot import URDF_LOAD_FLAGS

EXACT_TOL = 1e-7  # coal's GJK on primitives: ~1e-9 m measured; a 1e-4 relative error fails


@pytest.fixture()
def client():
    c = p.connect(p.DIRECT)
    yield c
    p.disconnect(physicsClientId=c)


def _body(c: int, geom: int, pos, quat=(0, 0, 0, 1), **kw) -> int:
    s = p.createCollisionShape(geom, physicsClientId=c, **kw)
    return p.createMultiBody(0, s, basePosition=pos, baseOrientation=quat, physicsClientId=c)


def _d(c: int, a: int, b: int, cap: float = 10.0) -> float:
    ed = ExactDistances(c)
    ed.begin()
    return ed.link_distances(a, b, cap).get(-1, cap)


def test_box_box_corner_to_corner_is_exact_where_bullet_is_not(client):
    a = _body(client, p.GEOM_BOX, [0, 0, 0], halfExtents=[0.1, 0.1, 0.1])
    b = _body(client, p.GEOM_BOX, [0.3, 0.3, 0.3], halfExtents=[0.1, 0.1, 0.1])
    assert _d(client, a, b) == pytest.approx(math.sqrt(3) * 0.1, abs=EXACT_TOL)
    bullet = min(pt[8] for pt in p.getClosestPoints(a, b, 1.0, physicsClientId=client))
    assert abs(bullet - math.sqrt(3) * 0.1) > 1e-3  # the margin this module measures


def test_primitive_pairs_against_closed_forms(client):
    box = _body(client, p.GEOM_BOX, [0, 0, 0], halfExtents=[0.1, 0.2, 0.3])
    # a sphere off a face, off an edge, rotated box
    s1 = _body(client, p.GEOM_SPHERE, [0.5, 0, 0], radius=0.05)
    assert _d(client, box, s1) == pytest.approx(0.5 - 0.1 - 0.05, abs=EXACT_TOL)
    s2 = _body(client, p.GEOM_SPHERE, [0.4, 0.6, 0], radius=0.05)
    assert _d(client, box, s2) == pytest.approx(math.hypot(0.3, 0.4) - 0.05, abs=EXACT_TOL)
    # capsule (length = between the cap centres) parallel to z beside the box's x face
    cap = _body(client, p.GEOM_CAPSULE, [0.4, 0, 0], radius=0.05, height=0.2)
    assert _d(client, box, cap) == pytest.approx(0.4 - 0.1 - 0.05, abs=EXACT_TOL)
    # capsule along z above the box: its lower cap centre 0.1 above the box's centre + 0.3
    cap2 = _body(client, p.GEOM_CAPSULE, [0, 0, 0.3 + 0.1 + 0.1], radius=0.05, height=0.2)
    assert _d(client, box, cap2) == pytest.approx(0.05, abs=EXACT_TOL)
    # cylinder (length, radius) lying along x after a 90 deg turn about y
    quat = p.getQuaternionFromEuler([0, math.pi / 2, 0])
    cyl = _body(client, p.GEOM_CYLINDER, [0, 0, 0.6], quat, radius=0.05, height=0.4)
    assert _d(client, box, cyl) == pytest.approx(0.6 - 0.3 - 0.05, abs=EXACT_TOL)


def test_overlap_is_negative_by_the_penetration_depth(client):
    a = _body(client, p.GEOM_BOX, [0, 0, 0], halfExtents=[0.1, 0.1, 0.1])
    b = _body(client, p.GEOM_BOX, [0.15, 0, 0], halfExtents=[0.1, 0.1, 0.1])
    assert _d(client, a, b) == pytest.approx(-0.05, abs=1e-6)


def test_a_mesh_is_its_convex_hull_scaled(client, tmp_path):
    """A URDF mesh (PyBullet keeps the file name of URDF meshes, not of meshes built with
    ``p.createCollisionShape``, which the audit refuses)."""
    # a unit cube's corners plus a point inside it (not on the hull), scaled by 0.1
    obj = tmp_path / "cube.obj"
    corners = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)] + [(0, 0, 0.5)]
    faces = ["f 1 2 4 3", "f 5 7 8 6", "f 1 5 6 2", "f 3 4 8 7", "f 1 3 7 5", "f 2 6 8 4"]
    obj.write_text("\n".join([f"v {x} {y} {z}" for x, y, z in corners] + faces) + "\n")
    urdf = tmp_path / "cube.urdf"
    urdf.write_text(
        '<robot name="cube"><link name="base"><inertial><mass value="0.1"/>'
        '<inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" iyz="0"/></inertial>'
        '<collision><geometry><mesh filename="cube.obj" scale="0.1 0.1 0.1"/></geometry>'
        "</collision></link></robot>")
    m = p.loadURDF(str(urdf), useFixedBase=True, physicsClientId=client)
    sph = _body(client, p.GEOM_SPHERE, [0.5, 0, 0], radius=0.1)
    assert _d(client, m, sph) == pytest.approx(0.5 - 0.1 - 0.1, abs=EXACT_TOL)


def test_links_are_posed_from_pybullet_and_only_near_links_reported(client):
    """A robot's links (collision origins offset from inertial frames) against a box: the
    per-link result follows the joints, and a far cap drops every link."""
    from repro.sim.pa10 import pa10_urdf_path

    rob = p.loadURDF(str(pa10_urdf_path()), useFixedBase=True,
                     flags=sum(URDF_LOAD_FLAGS.values()), physicsClientId=client)
    box = _body(client, p.GEOM_BOX, [0.6, 0.0, 0.2], halfExtents=[0.2, 0.2, 0.02])
    ed = ExactDistances(client)
    ed.begin()
    near = ed.link_distances(rob, box, 1.0)
    assert near and min(near.values()) < 1.0
    closest = min(near.values())
    assert closest > 0.0  # the arm stands clear of the box here
    assert ed.link_distances(rob, box, closest / 2) == {}  # nothing within half of it
    assert set(ed.link_distances(rob, box, closest * 1.001)) == {
        link for link, d in near.items() if d < closest * 1.001}
    p.resetJointState(rob, 1, 0.8, physicsClientId=client)  # shoulder pitch: the arm moves
    ed.begin()
    moved = ed.link_distances(rob, box, 1.0)
    assert moved != near


@pytest.mark.parametrize("urdf", ["crs_a465", "panda", "barrett_bh8", "pa10"])
def test_bullet_audit_distances_are_within_the_stated_tolerance(client, urdf, tmp_path):
    """The uncertainty of the runner's ``*_dist_*`` columns: PyBullet's closest points (the
    runner's 1 m query, per link) against exact distances on 60 random poses, with boxes
    and a capsule around the robot. Measured worst 1.46 mm (collision margins, both signs);
    a shape at the wrong frame or scale is off by centimetres."""
    path = _urdf(urdf, tmp_path)
    rob = p.loadURDF(str(path), useFixedBase=True, flags=sum(URDF_LOAD_FLAGS.values()),
                     physicsClientId=client)
    obstacles = [_body(client, p.GEOM_BOX, pos, halfExtents=he)
                 for pos, he in (([0.5, 0, 0.1], [0.3, 0.4, 0.02]),
                                 ([0.3, 0.3, 0.4], [0.05, 0.05, 0.2]),
                                 ([0, -0.4, 0.3], [0.1, 0.02, 0.3]))]
    obstacles.append(_body(client, p.GEOM_CAPSULE, [0.2, -0.2, 0.5], radius=0.05, height=0.3))
    joints = [j for j in range(p.getNumJoints(rob, physicsClientId=client))
              if p.getJointInfo(rob, j, physicsClientId=client)[2] != p.JOINT_FIXED]
    ed = ExactDistances(client)
    rng = np.random.default_rng(0)
    worst, n = 0.0, 0
    for _ in range(60):
        for j in joints:
            lo, hi = p.getJointInfo(rob, j, physicsClientId=client)[8:10]
            lo, hi = (lo, hi) if hi > lo else (-3.0, 3.0)
            p.resetJointState(rob, j, lo + (hi - lo) * rng.random(), physicsClientId=client)
        ed.begin()
        for ob in obstacles:
            bullet: dict[int, float] = {}
            for pt in p.getClosestPoints(rob, ob, 1.0, physicsClientId=client):
                bullet[pt[3]] = min(bullet.get(pt[3], math.inf), pt[8])
            exact = ed.link_distances(rob, ob, 1.0)
            for link in set(bullet) | set(exact):
                worst = max(worst, abs(bullet.get(link, 1.0) - exact.get(link, 1.0)))
                n += 1
    assert n > 100
    assert worst <= BULLET_AUDIT_TOL


def _urdf(name: str, tmp: Path) -> Path:
    root = Path(repro.__file__).parent / "assets"
    if name == "panda":  # its collision meshes: convex hulls in PyBullet and here
        return build_panda_urdf(tmp / "panda.urdf")
    if name == "pa10":
        from repro.sim.pa10 import pa10_urdf_path

        return pa10_urdf_path()
    return root / name / f"{name}.urdf"
