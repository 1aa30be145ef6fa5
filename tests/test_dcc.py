"""Tests of repro.planning.dcc (chan2011 Sec. IV: dynamic collision checking, eq. (20)).

A small 4-revolute-joint arm of our own (vertical column, two horizontal links, a wrist
roll, a box gripper and a sphere camera on fixed joints) among three box obstacles:
* d(q) against PyBullet's closest points on the same URDF;
* r_j against sampled axis distances (never exceeded, not absurdly loose) and a hand
  derivation;
* certify_segment / check_segment / free_box invariants, above all conservativeness:
  no segment certified free by (20) contains a configuration in collision.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from repro.errors import ConfigError, ReproError, UnknownChoiceError
from repro.planning.dcc import (
    Box,
    CollisionModel,
    certify_segment,
    check_segment,
    free_box,
    swept_bound,
)

JOINTS = ("j1", "j2", "j3", "j4")
Q_MIN = np.array([-3.0, -1.6, -2.5, -3.0])
Q_MAX = -Q_MIN


def _T(xyz: tuple[float, float, float], yaw: float = 0.0, roll: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = pin.rpy.rpyToMatrix(roll, 0.0, yaw)
    T[:3, 3] = xyz
    return T


OBSTACLES = (
    Box("pillar", (0.15, 0.15, 1.0), _T((0.7, 0.0, 0.5))),
    Box("beam", (0.6, 0.1, 0.1), _T((0.0, -0.6, 0.8), yaw=0.5, roll=0.2)),
    Box("block", (0.3, 0.3, 0.3), _T((-0.5, 0.4, 0.3), yaw=0.2)),
)

# ---------------------------------------------------------------------------- test arm


def _link(name: str, collision: str = "") -> str:
    inertial = ('<inertial><mass value="1"/><origin xyz="0 0 0"/><inertia ixx="0.01" '
                'iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>')
    return f'<link name="{name}">{inertial}{collision}</link>'


def _col(geom: str, xyz: str = "0 0 0", rpy: str = "0 0 0") -> str:
    return (f'<collision><origin xyz="{xyz}" rpy="{rpy}"/><geometry>{geom}</geometry>'
            '</collision>')


def _joint(name: str, kind: str, parent: str, child: str, xyz: str, axis: str = "0 0 1",
           lim: float = 3.0) -> str:
    extra = "" if kind == "fixed" else (
        f'<axis xyz="{axis}"/><limit lower="{-lim}" upper="{lim}" effort="10" velocity="1"/>')
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}" rpy="0 0 0"/>{extra}</joint>')


def write_arm(path: Path, j4_kind: str = "revolute", gripper_geom: str | None = None) -> Path:
    """Our 4R test arm: base box, column cylinder (j1, z), link2 box (j2, y), link3 cylinder
    along x (j3, y), link4 box (j4, x) with a rolled box gripper and a sphere camera on
    fixed joints, and a geometry-less tool0."""
    gripper_geom = gripper_geom or '<box size="0.08 0.12 0.04"/>'
    links = [
        _link("base_link", _col('<box size="0.3 0.3 0.1"/>', "0 0 0.05")),
        _link("link1", _col('<cylinder radius="0.06" length="0.4"/>', "0 0 0.15")),
        _link("link2", _col('<box size="0.5 0.08 0.08"/>', "0.25 0 0")),
        _link("link3", _col('<cylinder radius="0.04" length="0.4"/>', "0.2 0 0",
                            f"0 {math.pi / 2} 0")),
        _link("link4", _col('<box size="0.06 0.1 0.06"/>', "0.03 0 0")),
        _link("gripper", _col(gripper_geom, "0.04 0 0", "0.3 0 0")),
        _link("camera", _col('<sphere radius="0.03"/>')),
        _link("tool0"),
    ]
    joints = [
        _joint("j1", "revolute", "base_link", "link1", "0 0 0.1", "0 0 1", 3.0),
        _joint("j2", "revolute", "link1", "link2", "0 0 0.35", "0 1 0", 1.6),
        _joint("j3", "revolute", "link2", "link3", "0.5 0 0", "0 1 0", 2.5),
        _joint("j4", j4_kind, "link3", "link4", "0.4 0 0", "1 0 0", 3.0),
        _joint("gripper_joint", "fixed", "link4", "gripper", "0.06 0 0"),
        _joint("camera_joint", "fixed", "link4", "camera", "0.02 0 0.07"),
        _joint("tool_joint", "fixed", "gripper", "tool0", "0.08 0 0"),
    ]
    path.write_text('<?xml version="1.0"?>\n<robot name="dcc_arm">'
                    + "".join(links + joints) + "</robot>\n")
    return path


@pytest.fixture(scope="module")
def urdf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_arm(tmp_path_factory.mktemp("dcc") / "arm.urdf")


@pytest.fixture(scope="module")
def model(urdf: Path) -> CollisionModel:
    return CollisionModel(urdf, JOINTS, OBSTACLES)


def _random_q(rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    return rng.uniform(Q_MIN, Q_MAX, size=None if n is None else (n, len(JOINTS)))


# ----------------------------------------------------------------- PyBullet reference


class PyBulletReference:
    """The URDF and the obstacles in a DIRECT client.

    PyBullet gives URDF shapes a 1 mm collision margin (getDynamicsInfo(...)[-1]) that
    rounds box edges, and changeDynamics(collisionMargin=0) only reaches the base. So the
    exact reference uses margin-free proxies: PyBullet's own parse of the URDF
    (getCollisionShapeData) posed by PyBullet's own forward kinematics (getLinkState).
    The URDF body itself is compared within that margin.
    """

    MARGIN = 1e-3  # PyBullet's URDF collision margin [m]

    def __init__(self, urdf: Path) -> None:
        self.cid = p.connect(p.DIRECT)
        self.robot = p.loadURDF(str(urdf), useFixedBase=True,
                                flags=p.URDF_USE_IMPLICIT_CYLINDER, physicsClientId=self.cid)
        self.obstacles = []
        for box in OBSTACLES:
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[s / 2 for s in box.size],
                                           physicsClientId=self.cid)
            quat = pin.Quaternion(box.T_world[:3, :3]).coeffs().tolist()
            body = p.createMultiBody(0.0, shape, -1, box.T_world[:3, 3].tolist(), quat,
                                     physicsClientId=self.cid)
            p.changeDynamics(body, -1, collisionMargin=0.0, physicsClientId=self.cid)
            self.obstacles.append(body)
        self.n_joints = p.getNumJoints(self.robot, physicsClientId=self.cid)
        self.joint_index = {p.getJointInfo(self.robot, k, physicsClientId=self.cid)[1].decode(): k
                            for k in range(self.n_joints)}
        self.proxies: list[tuple[int, tuple[float, ...], tuple[float, ...], int]] = []
        for link in range(-1, self.n_joints):
            for sd in p.getCollisionShapeData(self.robot, link, physicsClientId=self.cid):
                kind, dims = sd[2], sd[3]
                if kind == p.GEOM_BOX:
                    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[d / 2 for d in dims],
                                                   physicsClientId=self.cid)
                elif kind == p.GEOM_CYLINDER:
                    shape = p.createCollisionShape(p.GEOM_CYLINDER, radius=dims[1],
                                                   height=dims[0], physicsClientId=self.cid)
                else:
                    assert kind == p.GEOM_SPHERE
                    shape = p.createCollisionShape(p.GEOM_SPHERE, radius=dims[0],
                                                   physicsClientId=self.cid)
                body = p.createMultiBody(0.0, shape, -1, physicsClientId=self.cid)
                p.changeDynamics(body, -1, collisionMargin=0.0, physicsClientId=self.cid)
                self.proxies.append((link, sd[5], sd[6], body))

    def set_q(self, q: np.ndarray) -> None:
        for name, qj in zip(JOINTS, q, strict=True):
            p.resetJointState(self.robot, self.joint_index[name], float(qj),
                              physicsClientId=self.cid)
        for link, pos, orn, body in self.proxies:
            if link == -1:
                lp, lo = p.getBasePositionAndOrientation(self.robot, physicsClientId=self.cid)
            else:
                st = p.getLinkState(self.robot, link, computeForwardKinematics=True,
                                    physicsClientId=self.cid)
                lp, lo = st[0], st[1]  # inertial frame: the frame of getCollisionShapeData
            wp, wo = p.multiplyTransforms(lp, lo, pos, orn)
            p.resetBasePositionAndOrientation(body, wp, wo, physicsClientId=self.cid)

    def _closest(self, bodies: list[int]) -> float:
        return min(pt[8] for a in bodies for b in self.obstacles
                   for pt in p.getClosestPoints(a, b, 10.0, physicsClientId=self.cid))

    def distance(self) -> float:
        """Exact min distance [m] (margin-free proxies)."""
        return self._closest([body for *_, body in self.proxies])

    def distance_urdf_body(self) -> float:
        """Min distance [m] of the loaded URDF body itself (1 mm rounded box edges)."""
        return self._closest([self.robot])

    def close(self) -> None:
        p.disconnect(self.cid)


@pytest.fixture(scope="module")
def pb(urdf: Path):  # type: ignore[no-untyped-def]
    ref = PyBulletReference(urdf)
    yield ref
    ref.close()


# ------------------------------------------------------------------------- distance


def test_parsing_and_skipped_links(model: CollisionModel) -> None:
    links = sorted(prim.link for prim in model.primitives)
    # tool0 has no <collision>: skipped; fixed links (gripper, camera) are kept.
    assert links == sorted(["base_link", "link1", "link2", "link3", "link4", "gripper",
                            "camera"])
    assert {prim.kind for prim in model.primitives} == {"box", "cylinder", "sphere"}


def test_distance_matches_pybullet(model: CollisionModel, pb: PyBulletReference) -> None:
    rng = np.random.default_rng(1)
    n_free = n_coll = 0
    while n_free < 20 or n_coll < 5:
        q = _random_q(rng)
        d = model.distance(q)
        pb.set_q(q)
        d_pb = pb.distance()
        if d > 0.0 and n_free < 20:
            n_free += 1
            assert d == pytest.approx(d_pb, abs=1e-4), q
            # The URDF body itself: its shapes carry a 1 mm margin that rounds box edges,
            # pushing the closest points at most (sqrt(3) - 1) * margin farther away.
            d_body = pb.distance_urdf_body()
            assert -1e-6 <= d_body - d <= (math.sqrt(3) - 1) * pb.MARGIN + 1e-6
        elif d <= 0.0 and n_coll < 5:
            n_coll += 1
            assert d_pb <= 0.0 and pb.distance_urdf_body() <= 0.0, q
            assert model.in_collision(q)


#: Measured 2026-12-02 (the 10 configurations below, 6 OpenBLAS kernel families, the base
#: moved by +-1e-12 and 1e-9 m): separation distances (fcl's GJK) move by <= 1.05e-8 m; the
#: one penetration depth (EPA, -3.9 cm) by 2e-17 m under the default kernels and 1.0e-5 m
#: under Sandybridge, Nehalem and Prescott (EPA stops on another face). Tolerances 10x.
GJK_TOL = 1e-7
EPA_TOL = 1e-4


def test_distance_transform_of_base(urdf: Path) -> None:
    """Moving the base and the obstacles together leaves every distance unchanged, to the
    measured solver tolerances (GJK_TOL, EPA_TOL)."""
    T = _T((0.3, -0.2, 0.5), yaw=0.7, roll=0.4)
    moved = CollisionModel(urdf, JOINTS, [Box(b.name, b.size, T @ b.T_world) for b in OBSTACLES],
                           T_world_base=T)
    ref = CollisionModel(urdf, JOINTS, OBSTACLES)
    rng = np.random.default_rng(2)
    for q in _random_q(rng, 10):
        d = ref.distance(q)
        assert moved.distance(q) == pytest.approx(d, abs=GJK_TOL if d > 0 else EPA_TOL)


def test_link_distances_min_is_distance(model: CollisionModel) -> None:
    rng = np.random.default_rng(3)
    for q in _random_q(rng, 20):
        ld = model.link_distances(q)
        assert len(ld) == 7 * len(OBSTACLES)
        assert min(ld.values()) == pytest.approx(model.distance(q), abs=1e-9)


def test_skip_links_and_margin(urdf: Path, model: CollisionModel) -> None:
    skipped = CollisionModel(urdf, JOINTS, OBSTACLES, skip_links=("gripper",), margin=0.01)
    assert "gripper" not in {prim.link for prim in skipped.primitives}
    rng = np.random.default_rng(4)
    for q in _random_q(rng, 20):
        ld = {k: v for k, v in model.link_distances(q).items() if not k.startswith("gripper/")}
        assert skipped.distance(q) == pytest.approx(min(ld.values()) - 0.01, abs=1e-9)
    with pytest.raises(UnknownChoiceError):
        CollisionModel(urdf, JOINTS, OBSTACLES, skip_links=("nope",))


def test_unsupported_urdf_raises(tmp_path: Path) -> None:
    prismatic = write_arm(tmp_path / "prismatic.urdf", j4_kind="prismatic")
    with pytest.raises(ConfigError, match="revolute"):
        CollisionModel(prismatic, JOINTS, OBSTACLES)
    mesh = write_arm(tmp_path / "mesh.urdf", gripper_geom='<mesh filename="g.stl"/>')
    with pytest.raises(UnknownChoiceError, match="mesh"):
        CollisionModel(mesh, JOINTS, OBSTACLES)
    # A mesh on a skipped link is fine: it is never read.
    CollisionModel(mesh, JOINTS, OBSTACLES, skip_links=("gripper",))
    urdf = write_arm(tmp_path / "ok.urdf")
    with pytest.raises(ConfigError, match="j4"):
        CollisionModel(urdf, JOINTS[:3], OBSTACLES)


# ---------------------------------------------------------------------------- radii


def test_radii_hand_derivation(model: CollisionModel) -> None:
    r = model.radii()
    # j4 (roll about x): the camera sphere, centre 0.07 m off the axis, radius 0.03.
    assert r[3] == pytest.approx(0.10, abs=1e-12)
    # j3: link3 offset 0.4 along x + ball about o_4 through the far gripper corner.
    corner = math.hypot(0.06 + 0.08, math.hypot(0.06, 0.02))
    assert r[2] == pytest.approx(0.4 + corner, abs=1e-12)
    # j2: 0.5 more; j1: the column axis passes through o_2, so the same.
    assert r[1] == pytest.approx(0.9 + corner, abs=1e-12)
    assert r[0] == pytest.approx(r[1], abs=1e-12)


def test_radii_bound_sampled_axis_distances(model: CollisionModel) -> None:
    r = model.radii()
    rng = np.random.default_rng(5)
    sampled = np.zeros(len(JOINTS))
    for q in _random_q(rng, 2000):
        for j in range(len(JOINTS)):
            sampled[j] = max(sampled[j], model.axis_distance_at(q, j))
    assert np.all(sampled <= r + 1e-12), (sampled, r)
    assert np.all(r <= 2.0 * sampled), (sampled, r)  # a bound, but not an absurd one
    print(f"\nr_j = {np.round(r, 4)}, sampled max = {np.round(sampled, 4)}")


# ---------------------------------------------------------------------- eq. (20)

Q_UP = np.array([0.0, -1.5, 0.0, 0.0])  # arm pointing up, far from every obstacle
Q_SWEEP_I = np.array([-0.8, 0.0, 0.0, 0.0])  # arm horizontal; j1 sweeps it through the pillar
Q_SWEEP_F = np.array([0.8, 0.0, 0.0, 0.0])


def test_certify_segment(model: CollisionModel) -> None:
    assert model.distance(Q_UP) > 0.2
    assert certify_segment(model, Q_UP, Q_UP + 1e-3)
    assert model.distance(Q_SWEEP_I) > 0.0 and model.distance(Q_SWEEP_F) > 0.0
    assert model.distance(0.5 * (Q_SWEEP_I + Q_SWEEP_F)) <= 0.0
    assert not certify_segment(model, Q_SWEEP_I, Q_SWEEP_F)
    # An endpoint in collision is never certified, whatever the other clearance.
    assert not certify_segment(model, np.zeros(4), np.zeros(4), d_i=-0.01, d_f=10.0)
    # (20) itself: strict inequality on the given distances.
    s = swept_bound(model.radii(), Q_UP, Q_UP + 1e-2)
    assert certify_segment(model, Q_UP, Q_UP + 1e-2, d_i=s / 2 + 1e-9, d_f=s / 2)
    assert not certify_segment(model, Q_UP, Q_UP + 1e-2, d_i=s / 2, d_f=s / 2)


def test_check_segment_finds_midpoint_collision(model: CollisionModel) -> None:
    res = check_segment(model, Q_SWEEP_I, Q_SWEEP_F)
    assert res.collision and not res.free
    assert res.n_checks == 3  # both ends, then the midpoint is already in collision
    assert res.depth == 1


def test_check_segment_free_segments_cover(model: CollisionModel) -> None:
    q_f = Q_UP + np.array([0.6, 0.3, -0.4, 1.0])
    res = check_segment(model, Q_UP, q_f)
    assert res.free and not res.collision
    assert np.allclose(res.segments[0][0], Q_UP) and np.allclose(res.segments[-1][1], q_f)
    for (_, b), (a, _) in zip(res.segments[:-1], res.segments[1:], strict=True):
        assert np.array_equal(a, b)  # contiguous, in order
    for a, b in res.segments:
        assert certify_segment(model, a, b)
    # max_depth = 0 on a segment (20) cannot certify at once: undetermined.
    und = check_segment(model, Q_UP, q_f, max_depth=0)
    if not certify_segment(model, Q_UP, q_f):
        assert not und.free and not und.collision and und.n_checks == 2


def _dense_collides(model: CollisionModel, q_i: np.ndarray, q_f: np.ndarray,
                    step: float = 3e-3, n_min: int = 200) -> bool:
    """True if fcl.collide finds a collision at configurations spaced so that no robot
    point moves more than ``step`` [m] between two (sum_j r_j |dq_j| <= step), at least
    ``n_min`` + 1 of them."""
    n = max(n_min, math.ceil(swept_bound(model.radii(), q_i, q_f) / step))
    return any(model.in_collision(q_i + t * (q_f - q_i)) for t in np.linspace(0.0, 1.0, n + 1))


def _random_segments(rng: np.random.Generator, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Half long (anywhere within the limits), half local (steps up to 0.6 rad)."""
    out = []
    for k in range(n):
        q_i = _random_q(rng)
        q_f = _random_q(rng) if k % 2 else np.clip(q_i + rng.uniform(-0.6, 0.6, 4), Q_MIN, Q_MAX)
        out.append((q_i, q_f))
    return out


def test_check_segment_is_conservative(model: CollisionModel) -> None:
    """The important one: a segment certified free by DCC has no configuration in collision
    (dense fcl.collide check every <= 3 mm of motion of any robot point, >= 200 samples)."""
    rng = np.random.default_rng(6)
    n_free = n_coll = n_undet = 0
    n_checks = []
    for q_i, q_f in _random_segments(rng, 500):
        res = check_segment(model, q_i, q_f)
        n_checks.append(res.n_checks)
        assert not (res.free and res.collision)
        if res.free:
            n_free += 1
            assert not _dense_collides(model, q_i, q_f), (q_i, q_f)
        elif res.collision:
            n_coll += 1
        else:
            n_undet += 1
    print(f"\nDCC on 500 segments: certified free {n_free}, collision {n_coll}, "
          f"undetermined {n_undet}; distance queries median {np.median(n_checks):.0f}, "
          f"max {max(n_checks)}")
    assert n_free >= 100 and n_coll >= 100  # both outcomes well exercised


def test_conservativeness_check_has_teeth(urdf: Path) -> None:
    """With r_j scaled down 10x (an invalid bound) the same dense check finds certified
    segments that collide: the conservativeness test above can fail."""
    broken = CollisionModel(urdf, JOINTS, OBSTACLES)
    broken._r = broken.radii() * 0.1
    rng = np.random.default_rng(6)
    for q_i, q_f in _random_segments(rng, 500):
        if check_segment(broken, q_i, q_f).free and _dense_collides(broken, q_i, q_f):
            return
    pytest.fail("underestimated radii went unnoticed")


# ------------------------------------------------------------------------- free box


def test_free_box(model: CollisionModel) -> None:
    rng = np.random.default_rng(7)
    q = _random_q(rng)
    while model.distance(q) < 0.05:
        q = _random_q(rng)
    lower, upper = free_box(model, q, q_min=Q_MIN, q_max=Q_MAX)
    assert np.all(lower < q) and np.all(q < upper)
    assert np.all(lower >= Q_MIN) and np.all(upper <= Q_MAX)
    # Unclipped corners lie on the weighted-L1 boundary sum_j r_j h_j = d(q).
    lo_u, hi_u = free_box(model, q)
    assert swept_bound(model.radii(), q, hi_u) == pytest.approx(model.distance(q), rel=1e-12)
    samples = rng.uniform(lower, upper, size=(1000, len(JOINTS)))
    assert all(model.distance(s) > 0.0 for s in samples)
    # Clipping at a limit.
    q_edge = Q_UP.copy()
    q_edge[3] = Q_MAX[3] - 1e-3
    lo_e, hi_e = free_box(model, q_edge, q_min=Q_MIN, q_max=Q_MAX)
    assert hi_e[3] == Q_MAX[3] and lo_e[3] < q_edge[3]


def test_free_box_in_collision_raises(model: CollisionModel) -> None:
    with pytest.raises(ReproError, match="collision"):
        free_box(model, 0.5 * (Q_SWEEP_I + Q_SWEEP_F))


def test_links_no_joint_moves_are_left_out_of_d_so_it_is_not_capped():
    """issue 17: the CRS-A465's fixed base sits 0.192 m from the books at every q; with it
    in the model d(q) never exceeded that, and eq. (20) failed at the cap far from any
    obstacle. static_links finds the base; without it d(q) follows the moving links."""
    from experiments.chan2011 import scene as chan_scene
    from repro.planning.dcc import static_links
    from repro.sim.crs_a465 import CRS_JOINTS, CRS_LIMITS, crs_urdf_path

    urdf = crs_urdf_path()
    assert static_links(urdf) == ("crs_link0",)
    full = CollisionModel(urdf, CRS_JOINTS, chan_scene.OBSTACLES)
    moving = CollisionModel(urdf, CRS_JOINTS, chan_scene.OBSTACLES,
                            skip_links=static_links(urdf))
    rng = np.random.default_rng(1)
    lo, hi = np.asarray(CRS_LIMITS.q_min), np.asarray(CRS_LIMITS.q_max)
    qs = rng.uniform(lo, hi, size=(200, len(lo)))
    d_full = np.array([full.distance(q) for q in qs])
    d_moving = np.array([moving.distance(q) for q in qs])
    assert d_full.max() <= 0.1925  # the base's cap
    assert d_moving.max() > 0.2
    assert (d_moving >= d_full - 1e-12).all()  # fewer links: never closer
    assert (d_moving > d_full + 1e-6).mean() > 0.5


def test_static_links_of_a_chain_with_a_fixed_root_group(tmp_path):
    from repro.planning.dcc import static_links

    urdf = tmp_path / "r.urdf"
    urdf.write_text(
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/><link name="d"/>'
        '<joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint>'
        '<joint name="bc" type="revolute"><parent link="b"/><child link="c"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        '<joint name="cd" type="fixed"><parent link="c"/><child link="d"/></joint></robot>')
    assert static_links(urdf) == ("a", "b")
