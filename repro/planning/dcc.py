"""Dynamic collision checking (DCC) of joint-space segments among box obstacles.

chan2011 Sec. IV-A, after Schwarzer, Saha & Latombe (2005): a straight joint-space
segment ``q(t) = q_i + (q_f - q_i) t``, ``0 <= t <= 1``, is collision-free if no point
of the robot travels farther than the clearance at its two ends,

.. math::

    \\ell(q(t)) < d(q_i) + d(q_f)                                   \\qquad (13)

where ``d(q)`` is the minimum robot-obstacle distance [m] and ``l`` the longest path of
any robot point. For revolute joints (chan2011 eqs. (17)-(19))

.. math::

    \\ell(q(t)) \\le \\sum_j r_j |\\Delta q_j|                        \\qquad (19)

with ``r_j`` the greatest distance between the axis ``z_j`` and any point of links
``j..N``, over all configurations of joints ``j+1..N``. Hence the test

.. math::

    \\sum_j r_j |q_{f,j} - q_{i,j}| < d(q_i) + d(q_f)               \\qquad (20)

which :func:`certify_segment` evaluates once and :func:`check_segment` applies by
recursive bisection. :func:`free_box` turns (20) into a collision-free box around one
configuration (chan2011 Sec. IV-B, Figs. 8-9).

Geometry: the collision primitives (box, cylinder, sphere) of a URDF, read with
``xml.etree``, posed by pinocchio forward kinematics of the same URDF, and queried with
python-fcl. Obstacles are static boxes. Self-collision is not considered.

Units: lengths [m], angles [rad]; every pose is a 4x4 homogeneous matrix ``T_a_b``
(frame ``b`` expressed in frame ``a``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import fcl
import numpy as np
import pinocchio as pin

from repro.errors import ConfigError, ReproError, UnknownChoiceError

GEOMETRY_TYPES = ("box", "cylinder", "sphere")
# Samples per cylinder end circle when the max distance to an axis is taken over a
# circle: r_j adds the Lipschitz slack pi * radius / _CIRCLE_SAMPLES (a guaranteed bound);
# axis_distance_at() uses the samples as they are (an estimate from below).
_CIRCLE_SAMPLES = 720


# --------------------------------------------------------------------------------------
# Obstacles and URDF primitives
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Box:
    """A static box obstacle.

    Attributes:
        name: label used in :meth:`CollisionModel.link_distances`.
        size: full edge lengths (x, y, z) [m] in the box frame.
        T_world: 4x4 pose of the box centre in the world [m].
    """

    name: str
    size: tuple[float, float, float]
    T_world: np.ndarray

    def __post_init__(self) -> None:
        if len(self.size) != 3 or min(self.size) <= 0.0:
            raise ConfigError(f"Box {self.name!r}: size {self.size} must be 3 lengths > 0 [m]")
        if np.shape(self.T_world) != (4, 4):
            raise ConfigError(f"Box {self.name!r}: T_world has shape {np.shape(self.T_world)}, "
                              "expected (4, 4)")


@dataclass(frozen=True)
class Primitive:
    """One ``<collision>`` element of a URDF link.

    Attributes:
        link: URDF link name.
        kind: ``"box"``, ``"cylinder"`` or ``"sphere"``.
        params: box: full lengths (x, y, z); cylinder: (radius, length) with its axis
            along the geometry z, centred; sphere: (radius,) [m].
        T_link_geom: pose of the geometry frame in the link frame.
    """

    link: str
    kind: str
    params: tuple[float, ...]
    T_link_geom: np.ndarray

    def fcl_geometry(self) -> fcl.CollisionGeometry:
        if self.kind == "box":
            return fcl.Box(*self.params)
        if self.kind == "cylinder":
            return fcl.Cylinder(*self.params)
        return fcl.Sphere(*self.params)


@dataclass(frozen=True)
class UrdfJoint:
    """A URDF ``<joint>``: type, parent/child links, placement ``T_parent_joint``, unit axis."""

    name: str
    kind: str
    parent: str
    child: str
    T_parent_joint: np.ndarray
    axis: np.ndarray


def _origin(elem: ET.Element | None) -> np.ndarray:
    """4x4 transform of a URDF ``<origin xyz rpy>`` (rpy: fixed-axis roll, pitch, yaw)."""
    T = np.eye(4)
    if elem is None:
        return T
    xyz = [float(v) for v in elem.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in elem.get("rpy", "0 0 0").split()]
    T[:3, :3] = pin.rpy.rpyToMatrix(*rpy)
    T[:3, 3] = xyz
    return T


def parse_urdf(urdf_path: Path, skip_links: Sequence[str] = ()
               ) -> tuple[dict[str, list[Primitive]], dict[str, UrdfJoint]]:
    """Collision primitives per link and the joints of a URDF.

    Links without ``<collision>`` and links in ``skip_links`` get an empty list. A mesh
    (or any geometry but box, cylinder, sphere) on another link raises
    :class:`UnknownChoiceError`: ignoring it silently would make the collision check unsafe.
    """
    root = ET.parse(urdf_path).getroot()
    links: dict[str, list[Primitive]] = {}
    for link in root.findall("link"):
        name = link.get("name", "")
        prims: list[Primitive] = []
        for col in [] if name in skip_links else link.findall("collision"):
            geom = col.find("geometry")
            shape = None if geom is None or len(geom) == 0 else geom[0]
            if shape is None:
                raise ConfigError(f"{urdf_path}: link {name!r} has a <collision> without geometry")
            if shape.tag not in GEOMETRY_TYPES:
                raise UnknownChoiceError(f"collision geometry of link {name!r}", shape.tag,
                                         GEOMETRY_TYPES)
            if shape.tag == "box":
                params = tuple(float(v) for v in shape.get("size", "").split())
            elif shape.tag == "cylinder":
                params = (float(shape.get("radius", "nan")), float(shape.get("length", "nan")))
            else:
                params = (float(shape.get("radius", "nan")),)
            if not all(np.isfinite(params)) or min(params) <= 0.0:
                raise ConfigError(f"{urdf_path}: link {name!r} has a {shape.tag} with "
                                  f"parameters {params}")
            prims.append(Primitive(name, shape.tag, params, _origin(col.find("origin"))))
        links[name] = prims
    joints: dict[str, UrdfJoint] = {}
    for joint in root.findall("joint"):
        name = joint.get("name", "")
        axis_elem = joint.find("axis")
        axis = np.array([float(v) for v in (axis_elem.get("xyz", "1 0 0") if axis_elem is not None
                                            else "1 0 0").split()])
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None:
            raise ConfigError(f"{urdf_path}: joint {name!r} lacks <parent> or <child>")
        joints[name] = UrdfJoint(name, joint.get("type", ""), parent.get("link", ""),
                                 child.get("link", ""), _origin(joint.find("origin")),
                                 axis / np.linalg.norm(axis))
    return links, joints


# --------------------------------------------------------------------------------------
# Geometric bounds of one primitive
# --------------------------------------------------------------------------------------

_UNIT_CUBE = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])


def _circle_points(T: np.ndarray, radius: float, length: float, n: int) -> np.ndarray:
    """Points (2n x 3) on the two end circles of a cylinder posed by ``T``."""
    th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    ring = np.stack([radius * np.cos(th), radius * np.sin(th), np.zeros(n)], axis=1)
    local = np.vstack([ring + [0, 0, length / 2], ring - [0, 0, length / 2]])
    return local @ T[:3, :3].T + T[:3, 3]


def ball_radius(prim: Primitive, T: np.ndarray) -> float:
    """Exact max distance [m] from the origin to the primitive posed by ``T``.

    A distance to a point is convex, so its max over a convex body is at an extreme
    point: box vertices, cylinder end circles (closed form), sphere (centre + radius).
    """
    t = T[:3, 3]
    if prim.kind == "box":
        v = (_UNIT_CUBE * prim.params) @ T[:3, :3].T + t
        return float(np.max(np.linalg.norm(v, axis=1)))
    if prim.kind == "cylinder":
        rad, length = prim.params
        a = T[:3, :3].T @ t  # origin offset in the geometry frame
        sq = t @ t + rad**2 + length**2 / 4 + 2 * rad * math.hypot(a[0], a[1]) \
            + abs(a[2]) * length
        return math.sqrt(sq)
    return float(np.linalg.norm(t)) + prim.params[0]


def axis_radius(prim: Primitive, T: np.ndarray, axis: np.ndarray, bound: bool) -> float:
    """Max distance [m] from the line through the origin along unit ``axis`` to the primitive.

    Box and sphere: exact. Cylinder: max over ``_CIRCLE_SAMPLES`` points per end circle;
    with ``bound`` plus ``pi * radius / _CIRCLE_SAMPLES`` (every circle point lies within
    that arc of a sample and a distance to a line is 1-Lipschitz), a guaranteed upper bound.
    """

    def perp(x: np.ndarray) -> np.ndarray:
        return x - np.outer(x @ axis, axis)

    if prim.kind == "box":
        v = (_UNIT_CUBE * prim.params) @ T[:3, :3].T + T[:3, 3]
        return float(np.max(np.linalg.norm(perp(v), axis=1)))
    if prim.kind == "cylinder":
        rad, length = prim.params
        pts = _circle_points(T, rad, length, _CIRCLE_SAMPLES)
        slack = math.pi * rad / _CIRCLE_SAMPLES if bound else 0.0
        return float(np.max(np.linalg.norm(perp(pts), axis=1))) + slack
    c = T[:3, 3]
    return float(np.linalg.norm(c - (c @ axis) * axis)) + prim.params[0]


# --------------------------------------------------------------------------------------
# The collision model
# --------------------------------------------------------------------------------------


def _fcl_transform(T: np.ndarray) -> fcl.Transform:
    return fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def static_links(urdf_path: Path) -> tuple[str, ...]:
    """The links of a fixed-base URDF that no joint moves: the root link and every link
    attached to it through fixed joints only (chan2011: the CRS-A465's base).

    Their distance to the obstacles is the same at every configuration, so in ``d(q)`` it
    is only a cap: the CRS base's 0.192 m made eq. (20) fail at that distance at every
    configuration, far from any obstacle (issue 17). Leave them out with ``skip_links``;
    the ground-truth audit still measures them."""
    root_el = ET.parse(urdf_path).getroot()
    links = [lk.get("name", "") for lk in root_el.findall("link")]
    joints = [(j.get("type", ""), j.find("parent"), j.find("child"))
              for j in root_el.findall("joint")]
    children = {c.get("link", "") for _, _, c in joints if c is not None}
    roots = [lk for lk in links if lk not in children]
    if len(roots) != 1:
        raise ConfigError(f"{urdf_path}: expected one root link, found {roots}")
    static = [roots[0]]
    grew = True
    while grew:
        grew = False
        for kind, parent, child in joints:
            if (kind == "fixed" and parent is not None and child is not None
                    and parent.get("link") in static and child.get("link") not in static):
                static.append(child.get("link", ""))
                grew = True
    return tuple(static)


class CollisionModel:
    """python-fcl geometry of a robot, read from the collision primitives (box, cylinder,
    sphere) of its URDF, posed by pinocchio forward kinematics of the same URDF.

    Args:
        urdf_path: the robot URDF (the one PyBullet and :class:`repro.sim.robot.Robot` load).
        joint_names: the actuated joints in control order; every non-fixed URDF joint,
            each revolute (``r_j`` of chan2011 eq. (18) is for revolute joints).
        obstacles: static boxes.
        T_world_base: pose of the URDF root link in the world (default identity).
        skip_links: links whose geometry is ignored, both in ``d(q)`` and in ``r_j``
            (e.g. a base that rests on a table obstacle). Their motion does not matter
            because they are never checked against the obstacles. chan2011 skips
            :func:`static_links`, the links no joint moves: their fixed distance would cap
            ``d(q)``.
        margin: safety padding [m] subtracted from every distance (0: the bare geometry).

    Links attached by fixed joints (camera, gripper) move with the link of the last
    movable joint before them and count in that joint's ``r_j``.
    """

    def __init__(
        self,
        urdf_path: Path,
        joint_names: tuple[str, ...],
        obstacles: Sequence[Box],
        T_world_base: np.ndarray | None = None,
        skip_links: Sequence[str] = (),
        margin: float = 0.0,
    ) -> None:
        self.urdf_path = Path(urdf_path)
        self.joint_names = tuple(joint_names)
        self.obstacles = tuple(obstacles)
        self.T_world_base = np.eye(4) if T_world_base is None else np.asarray(T_world_base, float)
        self.margin = float(margin)
        self.n = len(self.joint_names)
        links, joints = parse_urdf(self.urdf_path, skip_links)
        self._joints = joints
        for link in skip_links:
            if link not in links:
                raise UnknownChoiceError("link", link, links)
        for name in self.joint_names:
            if name not in joints:
                raise UnknownChoiceError("joint", name, joints)
        for jt in joints.values():
            if jt.kind == "fixed":
                continue
            if jt.kind != "revolute":
                raise ConfigError(f"joint {jt.name!r} is {jt.kind!r}; DCC radii r_j "
                                  "(chan2011 eq. (18)) are implemented for revolute joints only")
            if jt.name not in self.joint_names:
                raise ConfigError(f"movable joint {jt.name!r} is not in joint_names "
                                  f"{self.joint_names}")
        self.primitives: tuple[Primitive, ...] = tuple(
            prim for prims in links.values() for prim in prims)
        # Children of each link (URDF tree).
        self._child_joints: dict[str, list[UrdfJoint]] = {name: [] for name in links}
        for jt in joints.values():
            self._child_joints[jt.parent].append(jt)

        # pinocchio: each primitive gets its own frame (placement T_link_geom), so that one
        # framesForwardKinematics call poses them all in C++; control order -> q index.
        self.model = pin.buildModelFromUrdf(str(self.urdf_path))
        self._frame = []
        for k, prim in enumerate(self.primitives):
            body = self.model.frames[self.model.getFrameId(prim.link, pin.FrameType.BODY)]
            self._frame.append(self.model.addFrame(pin.Frame(
                f"dcc_geom_{k}_{prim.link}", body.parentJoint,
                body.placement * pin.SE3(prim.T_link_geom), pin.FrameType.OP_FRAME)))
        self.data = self.model.createData()
        self._M_world_base = (None if np.allclose(self.T_world_base, np.eye(4))
                              else pin.SE3(self.T_world_base))
        if self.model.nq != self.n:
            raise ConfigError(f"pinocchio model has nq={self.model.nq}, joint_names has {self.n}")
        self._q_idx = np.array([self.model.joints[self.model.getJointId(n)].idx_q
                                for n in self.joint_names])
        self._pin_joint = [self.model.getJointId(n) for n in self.joint_names]

        # fcl objects: robot primitives (moved by setTransform) and static obstacles.
        self._robot_objs = [fcl.CollisionObject(prim.fcl_geometry(), fcl.Transform())
                            for prim in self.primitives]
        self._obst_objs = [fcl.CollisionObject(fcl.Box(*b.size), _fcl_transform(b.T_world))
                           for b in self.obstacles]
        self._robot_mgr = fcl.DynamicAABBTreeCollisionManager()
        self._robot_mgr.registerObjects(self._robot_objs)
        self._robot_mgr.setup()
        self._obst_mgr = fcl.DynamicAABBTreeCollisionManager()
        self._obst_mgr.registerObjects(self._obst_objs)
        self._obst_mgr.setup()
        self._posed_q: np.ndarray | None = None
        self._last_d: tuple[np.ndarray, float] | None = None
        self.n_queries = 0  # distance() evaluations that were not served from the cache
        self._r = self._compute_radii()

    # ------------------------------------------------------------------ posing
    def _pin_q(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n,):
            raise ConfigError(f"q has shape {q.shape}, expected ({self.n},)")
        qp = np.zeros(self.model.nq)
        qp[self._q_idx] = q
        return qp

    def _pose(self, q: np.ndarray) -> None:
        """Forward kinematics and fcl transforms of every robot primitive at ``q``."""
        q = np.asarray(q, dtype=float)
        if self._posed_q is not None and np.array_equal(q, self._posed_q):
            return
        pin.framesForwardKinematics(self.model, self.data, self._pin_q(q))
        base = self._M_world_base
        for obj, fid in zip(self._robot_objs, self._frame, strict=True):
            M = self.data.oMf[fid] if base is None else base * self.data.oMf[fid]
            obj.setTransform(fcl.Transform(M.rotation, M.translation))
        self._robot_mgr.update()
        self._posed_q = q.copy()

    def primitive_poses(self, q: np.ndarray) -> list[np.ndarray]:
        """T_world_geom of every primitive in :attr:`primitives` at ``q``."""
        pin.framesForwardKinematics(self.model, self.data, self._pin_q(q))
        self._posed_q = None  # data changed under the fcl objects' feet: re-pose next time
        return [self.T_world_base @ self.data.oMf[fid].homogeneous for fid in self._frame]

    # --------------------------------------------------------------- distances
    def _penetration(self) -> float:
        """Largest penetration depth [m] of the posed robot into any obstacle (0 if none)."""
        depth = 0.0
        for a in self._robot_objs:
            for b in self._obst_objs:
                res = fcl.CollisionResult()
                if fcl.collide(a, b, fcl.CollisionRequest(enable_contact=True), res):
                    depth = max([depth] + [c.penetration_depth for c in res.contacts])
        return depth

    def distance(self, q: np.ndarray) -> float:
        """d(q): min distance [m] between the robot and the obstacles, minus ``margin``.

        When the geometry overlaps (fcl.distance returns -1 then), the value is minus the
        largest penetration depth fcl.collide reports, so ``d(q) <= 0`` iff in collision
        (for ``margin = 0``). ``inf`` when there are no obstacles.
        """
        q = np.asarray(q, dtype=float)
        if self._last_d is not None and np.array_equal(q, self._last_d[0]):
            return self._last_d[1]
        self.n_queries += 1
        if not self._obst_objs or not self._robot_objs:
            d = math.inf
        else:
            self._pose(q)
            data = fcl.DistanceData()
            self._robot_mgr.distance(self._obst_mgr, data, fcl.defaultDistanceCallback)
            d = float(data.result.min_distance)
            if d <= 0.0:
                d = -self._penetration()
        d -= self.margin
        self._last_d = (q.copy(), d)
        return d

    def in_collision(self, q: np.ndarray) -> bool:
        """True when the bare geometry overlaps an obstacle at ``q`` (fcl.collide; no margin)."""
        if not self._obst_objs or not self._robot_objs:
            return False
        self._pose(q)
        data = fcl.CollisionData()
        self._robot_mgr.collide(self._obst_mgr, data, fcl.defaultCollisionCallback)
        return bool(data.result.is_collision)

    def link_distances(self, q: np.ndarray) -> dict[str, float]:
        """Min distance [m] (minus ``margin``) per ``"link/obstacle"`` pair, for logging.

        A pair in collision gets minus its penetration depth (<= 0).
        """
        self._pose(q)
        out: dict[str, float] = {}
        for prim, a in zip(self.primitives, self._robot_objs, strict=True):
            for box, b in zip(self.obstacles, self._obst_objs, strict=True):
                d = fcl.distance(a, b, fcl.DistanceRequest(), fcl.DistanceResult())
                if d <= 0.0:
                    res = fcl.CollisionResult()
                    fcl.collide(a, b, fcl.CollisionRequest(enable_contact=True), res)
                    d = -max([0.0] + [c.penetration_depth for c in res.contacts])
                key = f"{prim.link}/{box.name}"
                out[key] = min(out.get(key, math.inf), float(d) - self.margin)
        return out

    # ------------------------------------------------------------------- radii
    def _rigid_group(self, link: str) -> list[tuple[str, np.ndarray]]:
        """(link, T_link0_link) of ``link`` and every link fixed to it (fixed joints)."""
        out = [(link, np.eye(4))]
        stack = [(link, np.eye(4))]
        while stack:
            parent, T = stack.pop()
            for jt in self._child_joints[parent]:
                if jt.kind == "fixed":
                    item = (jt.child, T @ jt.T_parent_joint)
                    out.append(item)
                    stack.append(item)
        return out

    def _movable_children(self, link: str) -> list[tuple[UrdfJoint, np.ndarray]]:
        """Movable joints below the rigid group of ``link``, with T_link_joint."""
        return [(jt, T @ jt.T_parent_joint) for name, T in self._rigid_group(link)
                for jt in self._child_joints[name] if jt.kind != "fixed"]

    def _group_prims(self, link: str) -> list[tuple[Primitive, np.ndarray]]:
        """Primitives of the rigid group of ``link``, with T_link_geom (relative to ``link``)."""
        by_link: dict[str, list[Primitive]] = {}
        for prim in self.primitives:
            by_link.setdefault(prim.link, []).append(prim)
        return [(prim, T @ prim.T_link_geom) for name, T in self._rigid_group(link)
                for prim in by_link.get(name, [])]

    def _ball(self, joint: UrdfJoint, memo: dict[str, float]) -> float:
        """R_m: radius of a ball about the origin of joint m holding links m..N for every q.

        R_m = max(max over the rigid group of m of the exact distance to its origin,
                  max over the next movable joints m' of |t_{m m'}| + R_{m'}),
        the triangle inequality over the chain of fixed joint-placement translations.
        """
        if joint.name not in memo:
            rad = [ball_radius(prim, T) for prim, T in self._group_prims(joint.child)]
            rad += [float(np.linalg.norm(T[:3, 3])) + self._ball(child, memo)
                    for child, T in self._movable_children(joint.child)]
            memo[joint.name] = max(rad, default=0.0)
        return memo[joint.name]

    def _compute_radii(self) -> np.ndarray:
        """r_j of chan2011 eq. (18), a guaranteed upper bound from the URDF geometry.

        In the frame of joint j (its origin on the axis z_j, rotating with it):
        * the rigid group of link j (link j and links fixed to it) is at a fixed place,
          so its max distance to z_j is computed exactly (``axis_radius``);
        * a point P below the next movable joint m satisfies
          ``P - o_j = t_jm + (P - o_m)`` with ``t_jm`` fixed in frame j, hence
          ``dist(P, z_j) = |perp_j(t_jm + (P - o_m))| <= |perp_j(t_jm)| + R_m``
          with ``R_m`` from :meth:`_ball`. Bounding by ``|t_jm| + R_m`` (the distance
          to o_j, a point of the axis) would also be valid but looser.
        """
        memo: dict[str, float] = {}
        r = np.zeros(self.n)
        for k, name in enumerate(self.joint_names):
            jt = self._joints[name]
            a = jt.axis
            vals = [axis_radius(prim, T, a, bound=True) for prim, T in self._group_prims(jt.child)]
            for child, T in self._movable_children(jt.child):
                t = T[:3, 3]
                vals.append(float(np.linalg.norm(t - (t @ a) * a)) + self._ball(child, memo))
            r[k] = max(vals, default=0.0)
        return r

    def radii(self) -> np.ndarray:
        """r_j [m], one per joint in control order (chan2011 eqs. (18)-(19))."""
        return self._r.copy()

    def subtree_links(self, j: int) -> list[str]:
        """Links moved by joint ``j`` (control order index): links j..N of chan2011."""
        out, stack = [], [self._joints[self.joint_names[j]].child]
        while stack:
            link = stack.pop()
            out.append(link)
            stack.extend(jt.child for jt in self._child_joints[link])
        return out

    def axis_distance_at(self, q: np.ndarray, j: int) -> float:
        """Max distance [m] between axis z_j and the geometry of links j..N at ``q``.

        Exact for boxes and spheres; cylinders use ``_CIRCLE_SAMPLES`` points per end
        circle (an estimate from below). By definition ``r_j`` bounds this for every q.
        """
        pin.framesForwardKinematics(self.model, self.data, self._pin_q(q))
        self._posed_q = None
        oMj_inv = self.data.oMi[self._pin_joint[j]].inverse().homogeneous
        links = set(self.subtree_links(j))
        axis = self._joints[self.joint_names[j]].axis
        vals = [axis_radius(prim, oMj_inv @ self.data.oMf[fid].homogeneous, axis, bound=False)
                for prim, fid in zip(self.primitives, self._frame, strict=True)
                if prim.link in links]
        return max(vals, default=0.0)


# --------------------------------------------------------------------------------------
# DCC
# --------------------------------------------------------------------------------------


def swept_bound(r: np.ndarray, q_i: np.ndarray, q_f: np.ndarray) -> float:
    """sum_j r_j |q_f,j - q_i,j| [m]: bound on the path of any robot point (chan2011 eq. (19))."""
    return float(np.sum(r * np.abs(np.asarray(q_f, float) - np.asarray(q_i, float))))


def certify_segment(model: CollisionModel, q_i: np.ndarray, q_f: np.ndarray,
                    d_i: float | None = None, d_f: float | None = None) -> bool:
    """True when chan2011 eq. (20) certifies the straight segment q_i -> q_f collision-free:
    ``sum_j r_j |q_f,j - q_i,j| < d(q_i) + d(q_f)``.

    ``d_i``, ``d_f`` [m]: distances already known (computed when None). An endpoint with
    ``d <= 0`` (in collision) is never certified.
    """
    d_i = model.distance(q_i) if d_i is None else d_i
    d_f = model.distance(q_f) if d_f is None else d_f
    if d_i <= 0.0 or d_f <= 0.0:
        return False
    return swept_bound(model.radii(), q_i, q_f) < d_i + d_f


@dataclass(frozen=True)
class DCCResult:
    """Outcome of :func:`check_segment`.

    Attributes:
        free: every sub-segment is certified by (20): the whole segment is collision-free.
        collision: a sampled configuration is in collision (d <= 0).
        n_checks: distance queries used.
        depth: bisection depth reached (0: the whole segment was tested once).
        segments: the certified sub-segments (q_a, q_b), in order along the segment.
    ``free == collision == False``: undetermined (max_depth reached).
    """

    free: bool
    collision: bool
    n_checks: int
    depth: int
    segments: tuple[tuple[np.ndarray, np.ndarray], ...]


def check_segment(model: CollisionModel, q_i: np.ndarray, q_f: np.ndarray,
                  max_depth: int = 12, d_i: float | None = None,
                  d_f: float | None = None) -> DCCResult:
    """Dynamic collision checking of ``q(t) = q_i + (q_f - q_i) t`` by recursive bisection
    (chan2011 Sec. IV-A, after Schwarzer et al.).

    (20) is tested on [q_i, q_f]; a failing sub-segment is split at its midpoint, whose
    distance is computed once and shared by both halves. Breadth-first, so every
    configuration on the 2^-k grid is sampled before any segment of depth k+1 is tested.
    Stops when every sub-segment passes (``free``), a sampled configuration has
    ``d <= 0`` (``collision``), or a sub-segment of depth ``max_depth`` fails (neither:
    undetermined). ``d_i``, ``d_f`` [m]: endpoint distances already known.
    """
    r = model.radii()
    q_i = np.asarray(q_i, dtype=float)
    q_f = np.asarray(q_f, dtype=float)
    n_checks = 0

    def dist(q: np.ndarray) -> float:
        nonlocal n_checks
        n_checks += 1
        return model.distance(q)

    d_i = dist(q_i) if d_i is None else d_i
    d_f = dist(q_f) if d_f is None else d_f
    if d_i <= 0.0 or d_f <= 0.0:
        return DCCResult(False, True, n_checks, 0, ())
    # (t_a, t_b, q_a, q_b, d_a, d_b, depth)
    queue = deque([(0.0, 1.0, q_i, q_f, d_i, d_f, 0)])
    certified: list[tuple[float, np.ndarray, np.ndarray]] = []
    depth = 0

    def done(free: bool, collision: bool) -> DCCResult:
        segs = tuple((qa, qb) for _, qa, qb in sorted(certified, key=lambda s: s[0]))
        return DCCResult(free, collision, n_checks, depth, segs)

    while queue:
        ta, tb, qa, qb, da, db, k = queue.popleft()
        depth = max(depth, k)
        if swept_bound(r, qa, qb) < da + db:  # chan2011 eq. (20)
            certified.append((ta, qa, qb))
            continue
        if k >= max_depth:
            return done(False, False)
        tm = 0.5 * (ta + tb)
        qm = 0.5 * (qa + qb)
        dm = dist(qm)
        if dm <= 0.0:
            depth = k + 1
            return done(False, True)
        queue.append((ta, tm, qa, qm, da, dm, k + 1))
        queue.append((tm, tb, qm, qb, dm, db, k + 1))
    return done(True, False)


def free_box(model: CollisionModel, q: np.ndarray, d: float | None = None,
             q_min: np.ndarray | None = None,
             q_max: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A collision-free box (lower, upper) [rad] around ``q`` from chan2011 eq. (20).

    Every q' with ``sum_j r_j |q'_j - q_j| < d(q)`` is reached from q by a segment that
    (13) certifies with d(q') >= 0, so the open weighted-L1 ball of radius d(q) is free.
    chan2011 calls the region a 'hyperrectangle' without giving its shape; ours is the
    box with half-widths ``h_j = d(q) / (N r_j)``, the largest one with equal shares
    ``r_j h_j`` inside that ball (its corners lie on the ball's boundary, so the open box
    is free). Clipped to [q_min, q_max]; a joint with r_j = 0 is bounded only by them.

    Raises ReproError when q is in collision (d <= 0): there is no free box.
    """
    q = np.asarray(q, dtype=float)
    d = model.distance(q) if d is None else d
    if d <= 0.0:
        raise ReproError(f"free_box: q = {q} is in collision (d = {d:.4g} m)")
    r = model.radii()
    with np.errstate(divide="ignore"):
        h = np.where(r > 0.0, d / (len(q) * r), np.inf)
    lower, upper = q - h, q + h
    if q_min is not None:
        lower = np.maximum(lower, np.asarray(q_min, dtype=float))
    if q_max is not None:
        upper = np.minimum(upper, np.asarray(q_max, dtype=float))
    return lower, upper
