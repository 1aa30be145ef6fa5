"""Exact distances between PyBullet bodies' collision geometry (coal), to audit the audit.

The runner's ground-truth distances (``*_dist_*`` columns, :meth:`repro.sim.scene.Scene.
distances_of`) are PyBullet's closest points. Bullet's convex shapes carry collision margins
and its GJK stops at a tolerance, so its distances are not exact: two 0.2 m cubes 0.1732 m
apart corner to corner read 0.1747 m. Here each collision shape PyBullet holds
(``p.getCollisionShapeData``: type, size, frame in the link's inertial frame) becomes a
`coal <https://github.com/coal-library/coal>`_ shape, posed from PyBullet's own link states,
and each pair's distance is coal's GJK (EPA when they overlap: negative, minus the
penetration depth), exact to ~1e-9 m on these primitives. ``tests/test_exact_distance.py``
measures how far the audit's PyBullet distances are from these: at most 1.5 mm on every
robot of the suite (:data:`BULLET_AUDIT_TOL`), in both directions.

Geometry: boxes, spheres, cylinders and capsules as PyBullet holds them; a mesh as the convex
hull of its vertices (scaled), which is what PyBullet simulates for a moving link. Planes
and concave static meshes are refused (no scene uses them).

Speed: a pair of bodies is reduced to the pairs of shapes whose bounding spheres could be
closer than the best distance found so far, nearest first; only those shapes are posed. It
is not faster than PyBullet's query on the suite's scenes (a large table's bounding sphere
prunes nothing), which is why the runner keeps PyBullet's and this module checks it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import coal
import numpy as np
import pybullet as p

from repro.errors import ConfigError

__all__ = ["BULLET_AUDIT_TOL", "BodyShapes", "ExactDistances", "Shape", "body_shapes"]

#: Largest |PyBullet closest-points distance - exact distance| [m] measured on random poses
#: of the CRS-A465, the Panda, the BH8 and the PA-10 + mini-robot against boxes and a capsule
#: (1.46 mm; tests/test_exact_distance.py): the uncertainty of every ``*_dist_*`` column.
BULLET_AUDIT_TOL = 1.5e-3


@dataclass(frozen=True)
class Shape:
    """One collision shape of a PyBullet body.

    Attributes:
        link: PyBullet link index (-1: the base).
        geometry: coal shape in its own frame.
        R_local, p_local: its frame in the link's inertial frame (rotation, position [m]).
        centre: centre of its bounding sphere in its own frame [m].
        radius: radius of that sphere [m].
    """

    link: int
    geometry: coal.ShapeBase
    R_local: np.ndarray
    p_local: np.ndarray
    centre: np.ndarray
    radius: float


@dataclass
class BodyShapes:
    """Every collision shape of one PyBullet body, by link (links without one absent)."""

    body: int
    shapes: list[Shape]
    n_links: int  # p.getNumJoints: the links whose state is read
    frame: np.ndarray  # (n,) per shape: its link's row in the link-frame arrays (link + 1)
    offset: np.ndarray  # (n, 3) per shape: its bounding-sphere centre in the link frame [m]
    radius: np.ndarray  # (n,) bounding-sphere radii [m]


def _mesh_hull(filename: str, scale: np.ndarray) -> tuple[coal.ConvexBase, np.ndarray]:
    path = Path(filename)
    if not path.is_file():
        raise ConfigError(f"collision mesh {filename!r} not found")
    if path.suffix.lower() != ".obj":
        raise ConfigError(f"collision mesh {filename!r}: only .obj meshes are read")
    vs = [line.split()[1:4] for line in path.read_text().splitlines() if line.startswith("v ")]
    pts = np.asarray(vs, dtype=float) * scale
    if len(pts) < 4:
        raise ConfigError(f"collision mesh {filename!r} has fewer than 4 vertices")
    vec = coal.StdVec_Vec3s()
    for v in pts:
        vec.append(v)
    return coal.Convex.convexHull(vec, False, ""), pts


def _shape(link: int, data: tuple) -> Shape:
    """A :class:`Shape` from one ``p.getCollisionShapeData`` entry."""
    geom, dims, fname, pos, quat = data[2], data[3], data[4], data[5], data[6]
    R = np.array(p.getMatrixFromQuaternion(quat), dtype=float).reshape(3, 3)
    centre = np.zeros(3)
    if geom == p.GEOM_BOX:  # dims: full extents
        g = coal.Box(*dims)
        radius = 0.5 * math.sqrt(sum(d * d for d in dims))
    elif geom == p.GEOM_SPHERE:  # dims[0]: radius
        g, radius = coal.Sphere(dims[0]), dims[0]
    elif geom == p.GEOM_CYLINDER:  # dims: length, radius; axis z
        g = coal.Cylinder(dims[1], dims[0])
        radius = math.hypot(dims[1], 0.5 * dims[0])
    elif geom == p.GEOM_CAPSULE:  # dims: length between the cap centres, radius
        g, radius = coal.Capsule(dims[1], dims[0]), dims[1] + 0.5 * dims[0]
    elif geom == p.GEOM_MESH:
        g, pts = _mesh_hull(fname.decode() if isinstance(fname, bytes) else fname,
                            np.asarray(dims, dtype=float))
        centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        radius = float(np.linalg.norm(pts - centre, axis=1).max())
    else:
        raise ConfigError(f"collision shape type {geom} of link {link} is not supported by "
                          "the exact distance audit (boxes, spheres, cylinders, capsules, "
                          "convex meshes)")
    return Shape(link, g, R, np.asarray(pos, dtype=float), centre, float(radius))


def body_shapes(client: int, body: int) -> BodyShapes:
    """Every collision shape PyBullet holds for ``body``."""
    n = p.getNumJoints(body, physicsClientId=client)
    shapes = [_shape(link, d) for link in range(-1, n)
              for d in p.getCollisionShapeData(body, link, physicsClientId=client)]
    frame = np.array([s.link + 1 for s in shapes], dtype=int)
    offset = np.array([s.R_local @ s.centre + s.p_local for s in shapes]).reshape(-1, 3)
    radius = np.array([s.radius for s in shapes], dtype=float)
    return BodyShapes(body, shapes, n, frame, offset, radius)


class ExactDistances:
    """Per-link exact distances between bodies of one PyBullet client.

    Poses are read from PyBullet once per :meth:`begin` (call it once the bodies are where
    they should be, e.g. once per control step); bodies' shapes are read once."""

    def __init__(self, client: int) -> None:
        self.client = client
        self._shapes: dict[int, BodyShapes] = {}
        self._frames: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # body -> (R, p) per link
        self._tf: dict[tuple[int, int], coal.Transform3s] = {}
        self._spheres: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()

    def shapes(self, body: int) -> BodyShapes:
        got = self._shapes.get(body)
        if got is None:
            got = self._shapes[body] = body_shapes(self.client, body)
        return got

    def begin(self) -> None:
        """Forget the poses read so far (the bodies have moved)."""
        self._frames.clear()
        self._tf.clear()
        self._spheres.clear()

    def _link_frames(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        """(R[k], p[k]) of the inertial frame of link k-1 (k = 0: the base) in the world."""
        got = self._frames.get(body)
        if got is not None:
            return got
        bs = self.shapes(body)
        pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=self.client)
        poss, quats = [pos], [quat]
        if bs.n_links:
            for st in p.getLinkStates(body, list(range(bs.n_links)), computeForwardKinematics=1,
                                      physicsClientId=self.client):
                poss.append(st[0])
                quats.append(st[1])
        q = np.asarray(quats, dtype=float)  # xyzw
        x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        R = np.empty((len(q), 3, 3))
        R[:, 0, 0] = 1 - 2 * (y * y + z * z)
        R[:, 0, 1] = 2 * (x * y - z * w)
        R[:, 0, 2] = 2 * (x * z + y * w)
        R[:, 1, 0] = 2 * (x * y + z * w)
        R[:, 1, 1] = 1 - 2 * (x * x + z * z)
        R[:, 1, 2] = 2 * (y * z - x * w)
        R[:, 2, 0] = 2 * (x * z - y * w)
        R[:, 2, 1] = 2 * (y * z + x * w)
        R[:, 2, 2] = 1 - 2 * (x * x + y * y)
        got = self._frames[body] = (R, np.asarray(poss, dtype=float))
        return got

    def _centres(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        """World centres (n, 3) and radii (n,) of the bounding spheres of ``body``'s shapes."""
        got = self._spheres.get(body)
        if got is None:
            bs = self.shapes(body)
            R, t = self._link_frames(body)
            k = bs.frame
            got = self._spheres[body] = (np.einsum("nij,nj->ni", R[k], bs.offset) + t[k],
                                         bs.radius)
        return got

    def _transform(self, body: int, i: int) -> coal.Transform3s:
        key = (body, i)
        tf = self._tf.get(key)
        if tf is None:
            s = self.shapes(body).shapes[i]
            R, t = self._link_frames(body)
            k = s.link + 1
            tf = self._tf[key] = coal.Transform3s(R[k] @ s.R_local, R[k] @ s.p_local + t[k])
        return tf

    def pair(self, body_a: int, i: int, body_b: int, j: int) -> float:
        """Signed distance [m] between shape ``i`` of ``body_a`` and shape ``j`` of
        ``body_b`` at the poses read since :meth:`begin`."""
        sa, sb = self.shapes(body_a).shapes[i], self.shapes(body_b).shapes[j]
        self._res.clear()
        return float(coal.distance(sa.geometry, self._transform(body_a, i), sb.geometry,
                                   self._transform(body_b, j), self._req, self._res))

    def link_distances(self, body_a: int, body_b: int, max_distance: float
                       ) -> dict[int, float]:
        """{link of ``body_a``: its smallest signed distance [m] to any shape of ``body_b``}
        for the links closer than ``max_distance`` (the others are absent)."""
        A, B = self.shapes(body_a), self.shapes(body_b)
        if not A.shapes or not B.shapes:
            return {}
        ca, ra = self._centres(body_a)
        cb, rb = self._centres(body_b)
        diff = ca[:, None, :] - cb[None, :, :]
        lower = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff)) - ra[:, None] - rb[None, :]
        out: dict[int, float] = {}
        for i, s in enumerate(A.shapes):  # shapes of a link are consecutive
            row = lower[i]
            best = out.get(s.link, max_distance)
            for j in np.argsort(row, kind="stable"):
                if row[j] >= best:
                    break
                d = self.pair(body_a, i, body_b, int(j))
                if d < best:
                    best = d
            if best < max_distance:
                out[s.link] = best
        return out
