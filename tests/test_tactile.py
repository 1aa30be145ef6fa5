"""Tests of repro.sensors.tactile (tactile pads simulated from PyBullet contact forces).

Scene: a static box "finger" (URDF written here) whose top face carries a pad frame (a
fixed, collision-less frame link, as in our Barrett URDF), and blocks or spheres resting on
it or pressed onto it at 1 kHz. Known answers: at rest the pad carries the block's weight
m g; a uniform block loads the cells under it; the reported map is clipped to 0-140 kPa
and quantised to 0.7 kPa (pomares2011 Sec. 7.3).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from repro.errors import ConfigError, UnknownChoiceError
from repro.geometry import make_T, rot_x, rot_z
from repro.runs.columns import Columns
from repro.sensors.tactile import (
    BH8_DISTAL,
    BH8_PAD_NAMES,
    BH8_PALM,
    BH8_PROXIMAL,
    PRESSURE_MAX_KPA,
    PRESSURE_STEP_KPA,
    MountedPad,
    PadLayout,
    TactilePad,
    TactileSensor,
    bh8_pads,
    mount_pads,
    pad_contacts,
    pressure_from_contacts,
    pressure_image,
    quantise_kpa,
    read_pad,
    tactel_row,
)

G = 9.81
DT = 1.0e-3  # physics step [s] (1 kHz)
FINGER_HALF = (0.05, 0.04, 0.01)  # the finger box [m]: its top face is larger than a palm pad

FINGER_URDF = """<?xml version="1.0"?>
<robot name="finger">
  <link name="finger">
    <inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>
    </inertial>
    <collision><geometry><box size="{sx} {sy} {sz}"/></geometry></collision>
  </link>
  <joint name="finger_pad_joint" type="fixed">
    <parent link="finger"/><child link="finger_pad"/>
    <origin xyz="0 0 {top}" rpy="0 0 0"/>
  </joint>
  <link name="finger_pad"/>
</robot>
"""


@pytest.fixture
def client() -> Iterator[int]:
    c = p.connect(p.DIRECT)
    p.setTimeStep(DT, physicsClientId=c)
    p.setGravity(0.0, 0.0, -G, physicsClientId=c)
    p.setPhysicsEngineParameter(numSolverIterations=50, deterministicOverlappingPairs=1,
                                physicsClientId=c)
    yield c
    p.disconnect(c)


def _finger(client: int, tmp_path: Path, half: tuple[float, float, float] = FINGER_HALF) -> int:
    """The static finger: box of half extents ``half`` [m] centred at the origin; link
    ``finger_pad`` sits on its top face (z = half[2]), +z up."""
    f = tmp_path / f"finger_{half[2]:.4f}.urdf"
    f.write_text(FINGER_URDF.format(sx=2 * half[0], sy=2 * half[1], sz=2 * half[2],
                                    top=half[2]))
    return p.loadURDF(str(f), useFixedBase=True, physicsClientId=client)


def _block(client: int, half: tuple[float, float, float], mass: float, x: float, y: float,
           z_support: float = FINGER_HALF[2]) -> int:
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    return p.createMultiBody(mass, col, -1, [x, y, z_support + half[2] + 1e-4],
                             physicsClientId=client)


def _sphere(client: int, radius: float, mass: float, x: float, y: float,
            z_support: float = FINGER_HALF[2]) -> int:
    col = p.createCollisionShape(p.GEOM_SPHERE, radius=radius, physicsClientId=client)
    b = p.createMultiBody(mass, col, -1, [x, y, z_support + radius + 1e-4],
                          physicsClientId=client)
    p.changeDynamics(b, -1, rollingFriction=1e-3, physicsClientId=client)
    return b


def _settle(client: int, n: int = 300) -> None:
    for _ in range(n):
        p.stepSimulation(physicsClientId=client)


def _palm(client: int, body: int, layout: PadLayout = BH8_PALM,
          T_frame_pad: np.ndarray | None = None) -> MountedPad:
    """The pad ``palm`` on the finger's ``finger_pad`` frame link."""
    T = np.eye(4) if T_frame_pad is None else T_frame_pad
    return mount_pads(client, body, [TactilePad("palm", "finger_pad", layout, T)])[0]


def _covered(layout: PadLayout, x: float, y: float, half: float) -> np.ndarray:
    """Tactels whose whole cell lies under a square block of half side ``half`` at (x, y)."""
    c, h = layout.centres(), 0.5 * layout.sizes()
    return np.all(np.abs(c - [x, y]) + h <= half + 1e-9, axis=1)


# ------------------------------------------------------------------- (1) force balance
@pytest.mark.parametrize("block_first", [False, True])
def test_map_carries_the_contact_force_and_the_weight_at_rest(client: int, tmp_path: Path,
                                                              block_first: bool) -> None:
    """sum(pressure * area) of the unquantised map = sum of the contact normal forces
    (exactly, by construction) = m g at rest; twice the mass doubles every tactel. The
    body order (which one PyBullet calls A) does not matter."""
    half, x, y = 0.015, -0.005, -0.005
    if block_first:
        blk = _block(client, (half, half, 0.005), 0.2, x, y)
        finger = _finger(client, tmp_path)
    else:
        finger = _finger(client, tmp_path)
        blk = _block(client, (half, half, 0.005), 0.2, x, y)
    mp = _palm(client, finger)
    assert mp.frame_link == 0 and mp.contact_link == -1  # frame link -> its parent's contacts
    _settle(client)
    r = read_pad(client, mp)
    areas = BH8_PALM.areas()
    F_map_true = float(r.pressure_true @ areas) * 1e3
    assert r.n_contacts == 4  # PyBullet's manifold: the block's 4 corners
    assert F_map_true == pytest.approx(r.force_contacts, rel=1e-9)
    assert r.force_contacts == pytest.approx(0.2 * G, rel=0.01)
    assert r.force_pad == pytest.approx(F_map_true)
    # the reported map is within half a quantisation step per tactel of the true one
    assert abs(r.force_map - F_map_true) <= 0.5 * PRESSURE_STEP_KPA * areas.sum() * 1e3
    # a heavier block: every tactel scales with the weight
    p.changeDynamics(blk, -1, mass=0.6, physicsClientId=client)
    _settle(client)
    r3 = read_pad(client, mp)
    assert r3.force_contacts == pytest.approx(0.6 * G, rel=0.01)
    lit = r.pressure_true > 0.05
    np.testing.assert_allclose(r3.pressure_true[lit] / r.pressure_true[lit], 3.0, rtol=0.02)


@pytest.mark.parametrize("layout", [BH8_PALM, BH8_PROXIMAL, BH8_DISTAL],
                         ids=["palm", "proximal", "distal"])
def test_force_balance_on_every_barrett_layout(client: int, tmp_path: Path,
                                               layout: PadLayout) -> None:
    """A 12 x 12 mm block of 0.1 kg at three places on the grid, and a sphere on the last
    cell (the distal tip cell): sum(p a) = contact force = m g; the sphere's cell peaks."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger, layout)
    n_grid = layout.rows * layout.cols
    c, h = layout.centres()[:n_grid], 0.5 * layout.sizes()[:n_grid]
    inner_lo, inner_hi = (c - h).min(axis=0) + 0.006, (c + h).max(axis=0) - 0.006
    mid = 0.5 * (inner_lo + inner_hi)
    for x, y in [mid, (inner_lo[0], inner_hi[1]), (0.5 * (mid[0] + inner_hi[0]), inner_lo[1])]:
        blk = _block(client, (0.006, 0.006, 0.004), 0.1, x, y)
        _settle(client, 250)
        r = read_pad(client, mp)
        assert r.force_contacts == pytest.approx(0.1 * G, rel=0.01), (x, y)
        assert float(r.pressure_true @ layout.areas()) * 1e3 == pytest.approx(
            r.force_contacts, rel=1e-9)
        p.removeBody(blk, physicsClientId=client)
    last = layout.centres()[-1]
    _sphere(client, 0.004, 0.1, last[0], last[1])
    _settle(client, 250)
    r = read_pad(client, mp)
    assert r.n_contacts == 1 and int(np.argmax(r.pressure_true)) == layout.n_tactels - 1
    assert float(r.pressure_true @ layout.areas()) * 1e3 == pytest.approx(0.1 * G, rel=0.01)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_point_loads_on_the_pad_keep_their_force(seed: int) -> None:
    """Pure model: random point loads on the cells are wholly on the pad; in the rim only
    part of each reaches it, less the farther out; beyond the rim nothing; a load at a cell
    centre peaks at that cell."""
    rng = np.random.default_rng(seed)
    for layout in (BH8_PALM, BH8_PROXIMAL, BH8_DISTAL):
        c, h = layout.centres(), 0.5 * layout.sizes()
        k = rng.integers(layout.n_tactels, size=5)
        xy = c[k] + rng.uniform(-1, 1, (5, 2)) * h[k]
        f = rng.uniform(0.1, 3.0, 5)
        pr = pressure_from_contacts(layout, xy, f)
        assert float(pr @ layout.areas()) * 1e3 == pytest.approx(f.sum(), rel=1e-12)
        j = int(rng.integers(layout.n_tactels))
        one = pressure_from_contacts(layout, c[j:j + 1], np.array([1.0]))
        assert int(np.argmax(one)) == j
        lo, hi = layout.bounds()  # the footprint grown by the rim
        x_edge = float((c[:, 0] + h[:, 0]).max())
        steps = np.array([0.25, 0.5, 0.75, 0.99]) * (hi[0] - x_edge)
        share = [float(pressure_from_contacts(layout, np.array([[x_edge + d, 0.0]]),
                                              np.ones(1)) @ layout.areas()) * 1e3
                 for d in steps]
        assert 0.5 > share[0] > share[1] > share[2] > share[3] > 0.0
        far = np.array([[hi[0] + 1e-4, 0.0], [lo[0] - 1e-4, 0.0], [0.0, hi[1] + 1e-4]])
        assert np.all(pressure_from_contacts(layout, far, np.ones(3)) == 0.0)


# ---------------------------------------------------------- (2) where the pressure is
def test_pressure_is_under_the_block_and_follows_it(client: int, tmp_path: Path) -> None:
    """A 30 x 30 mm block covers 3 x 3 palm cells: each of them reads more than any other
    cell, the middle one most; more than PyBullet's 4 contact points light up; the peak
    follows the block when it is moved."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger)
    half = 0.015
    blk = _block(client, (half, half, 0.005), 0.3, -0.005, -0.005)
    peaks = []
    for x, y, peak in [(-0.005, -0.005, (2, 1)), (0.015, 0.005, (4, 2))]:
        p.resetBasePositionAndOrientation(blk, [x, y, FINGER_HALF[2] + 0.0051], [0, 0, 0, 1],
                                          physicsClientId=client)
        _settle(client)
        r = read_pad(client, mp)
        under = _covered(BH8_PALM, x, y, half)
        assert under.sum() == 9
        assert r.pressure_true[under].min() > r.pressure_true[~under].max()
        img, _ = pressure_image(BH8_PALM, r.pressure_true)
        assert np.unravel_index(np.argmax(img), img.shape) == peak
        # a uniform block: the middle cell reads about m g / (block area)
        assert img[peak] == pytest.approx(0.3 * G / (2 * half) ** 2 * 1e-3, rel=0.1)
        assert int(np.count_nonzero(r.pressure)) > 4 and r.n_contacts <= 4
        peaks.append(img[peak])
    assert peaks[0] == pytest.approx(peaks[1], rel=0.1)


def test_off_centre_push_moves_the_centre_of_pressure(client: int, tmp_path: Path) -> None:
    """A block pushed down off its centre: the map's pressure centroid follows the contact
    forces' centre of pressure (the linear patch pressure keeps the moment)."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger)
    blk = _block(client, (0.015, 0.015, 0.005), 0.2, -0.005, -0.005)
    _settle(client)
    cen, areas = BH8_PALM.centres(), BH8_PALM.areas()

    def centroids() -> tuple[np.ndarray, np.ndarray]:
        r, con = read_pad(client, mp), pad_contacts(client, mp)
        cop = con.force @ con.xyz[:, :2] / con.force.sum()
        w = r.pressure_true * areas
        return cop, w @ cen / w.sum()

    cop0, map0 = centroids()
    for _ in range(300):  # 10 N down, 10 mm off the block's centre in +x
        p.applyExternalForce(blk, -1, [0, 0, -10.0], [0.005, -0.005, 0.02], p.WORLD_FRAME,
                             physicsClientId=client)
        p.stepSimulation(physicsClientId=client)
    cop1, map1 = centroids()
    assert cop1[0] - cop0[0] > 5e-3  # the push moved the centre of pressure by > 5 mm
    assert np.linalg.norm(map0 - cop0) < 2e-3 and np.linalg.norm(map1 - cop1) < 2e-3
    assert map1[0] - map0[0] > 5e-3


# ---------------------------------------------------------- (3) range and sensitivity
def test_quantise_known_values() -> None:
    q = quantise_kpa(np.array([-3.0, 0.2, 0.36, 1.0, 1.1, 70.2, 139.9, 150.0]))
    np.testing.assert_allclose(q, [0.0, 0.0, 0.7, 0.7, 1.4, 70.0, 140.0, 140.0])


def test_saturation_and_quantisation(client: int, tmp_path: Path) -> None:
    """A 5 kg sphere on one palm cell: its true pressure is far above 140 kPa, it reads
    140 kPa and logs a saturation event; every reading is a multiple of 0.7 kPa within half
    a step of the true pressure where not clipped."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger)
    sensor = TactileSensor(client, [mp])
    c = BH8_PALM.centres()[9]
    _sphere(client, 0.01, 5.0, c[0], c[1])
    _settle(client)
    r = sensor.read(0.0)
    pr = r.pads["palm"]
    assert pr.force_contacts == pytest.approx(5.0 * G, rel=0.01)
    assert pr.pressure_true[9] > 1.5 * PRESSURE_MAX_KPA
    assert pr.pressure[9] == PRESSURE_MAX_KPA and pr.p_max == PRESSURE_MAX_KPA
    assert np.flatnonzero(pr.saturated).tolist() == [9]
    levels = pr.pressure / PRESSURE_STEP_KPA
    np.testing.assert_allclose(levels, np.round(levels), atol=1e-9)
    ok = ~pr.saturated
    assert np.all(np.abs(pr.pressure[ok] - pr.pressure_true[ok]) <= 0.5 * PRESSURE_STEP_KPA + 1e-9)
    assert np.any((pr.pressure_true > 0) & (pr.pressure == 0))  # below 0.35 kPa reads 0
    kinds = [k for k, _ in sensor.events(r)]
    # the clipped map carries less than the link feels: the coverage audit says so too
    assert kinds == ["tactile_saturated", "tactile_coverage_low"]
    assert sensor.failure(r) is None


# --------------------------------------------------------------------- (4) 30 Hz hold
def test_30_hz_sample_and_hold(client: int, tmp_path: Path) -> None:
    """Read every 1 ms for 1 s: 31 samples (t = 0, 1/30, ..., 1 s), each taken at the first
    step at or after its due time; between them the last sample is held even though the
    block has moved, and events are not repeated."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger)
    sensor = TactileSensor(client, [mp])
    blk = _block(client, (0.015, 0.015, 0.005), 0.3, -0.015, -0.005)
    _settle(client)
    sample_steps, held_differs = [], 0
    last = None
    for k in range(1001):
        t = k * DT
        if k % 10 == 5:  # slide the block along x
            x = -0.015 + 0.03 * k / 1000
            p.resetBasePositionAndOrientation(blk, [x, -0.005, FINGER_HALF[2] + 0.0051],
                                              [0, 0, 0, 1], physicsClientId=client)
        r = sensor.read(t, {})
        cols = sensor.columns(r)
        assert cols["tac_new"] == r.new
        if r.new:
            sample_steps.append(k)
            assert r.t == t
            last = r
        else:
            assert last is not None and r.t == last.t and cols["tac_t_sample"] == last.t
            np.testing.assert_array_equal(r.pads["palm"].pressure, last.pads["palm"].pressure)
            assert sensor.events(r) == []
            fresh = read_pad(client, mp)
            held_differs += not np.array_equal(fresh.pressure, r.pads["palm"].pressure)
        p.stepSimulation(physicsClientId=client)
    due = [math.ceil(n / 30 / DT - 1e-6) for n in range(31)]
    assert sample_steps == due
    assert len(sample_steps) == 31
    assert held_differs > 500  # the held map really was stale most of the time


# ----------------------------------------------- (5) off the footprint, back, side faces
def test_contacts_off_the_footprint_read_zero(client: int, tmp_path: Path) -> None:
    """Spheres on the finger's face beyond the pad's rim (the 60 x 40 mm palm pad ends at
    x = 30 mm and y = 20 mm, its rim 10 mm farther): the contacts are on the face (F = m g)
    but no tactel reads."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger)
    _sphere(client, 0.004, 0.5, 0.0405, 0.0)
    _sphere(client, 0.004, 0.5, -0.0405, 0.0305)
    _settle(client)
    r = read_pad(client, mp)
    assert r.n_contacts == 2
    assert r.force_contacts == pytest.approx(1.0 * G, rel=0.01)
    assert np.all(r.pressure_true == 0.0) and r.force_pad == 0.0 and r.force_map == 0.0


def test_block_straddling_the_edge_loads_only_the_edge(client: int, tmp_path: Path) -> None:
    """A 30 mm block centred on the pad's +x edge (x = 30 mm): the half over the cells loads
    the pad fully, the half beside it only through the blur of the rim, on the last rows."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger)
    _block(client, (0.015, 0.015, 0.005), 0.3, 0.030, 0.0)
    _settle(client)
    r = read_pad(client, mp)
    F = r.force_contacts
    assert F == pytest.approx(0.3 * G, rel=0.01)
    assert 0.5 * F < r.force_pad < 0.8 * F  # (35 - 15) / 30 = 2/3 of a uniform block
    img, _ = pressure_image(BH8_PALM, r.pressure_true)
    assert img[:3].max() < 0.05 * img[4:].max()


@pytest.mark.parametrize("thickness", [0.02, 0.002], ids=["thick", "thin"])
def test_back_face_reads_zero(client: int, tmp_path: Path, thickness: float) -> None:
    """A pad on the finger's bottom face (+z down) and a block on its top face: nothing.
    On the 20 mm finger the contact is 20 mm behind the pad face; on the 2 mm one it is
    within face_tol and only the normal (pointing the wrong way) rejects it."""
    half = (FINGER_HALF[0], FINGER_HALF[1], 0.5 * thickness)
    finger = _finger(client, tmp_path, half)
    T_frame_pad = make_T(rot_x(math.pi), (0.0, 0.0, -thickness))  # the bottom face, facing down
    mp = _palm(client, finger, T_frame_pad=T_frame_pad)
    _block(client, (0.015, 0.015, 0.005), 0.3, 0.0, 0.0, z_support=half[2])
    _settle(client)
    con = pad_contacts(client, mp)
    assert len(con.force) == 4 and con.force.sum() == pytest.approx(0.3 * G, rel=0.01)
    assert np.allclose(np.abs(con.xyz[:, 2]), thickness, atol=1e-4)
    assert np.allclose(con.cos_normal, -1.0)
    r = read_pad(client, mp)
    assert r.n_contacts == 0 and r.force_contacts == 0.0 and np.all(r.pressure_true == 0.0)


@pytest.mark.parametrize("lift", [0.002, 0.010])
def test_contact_must_be_on_the_face_plane(client: int, tmp_path: Path, lift: float) -> None:
    """A pad frame ``lift`` above the real face: contacts 2 mm below it still count
    (face_tol = 3 mm), 10 mm below they do not, though their normal is right."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger, T_frame_pad=make_T(t=(0.0, 0.0, lift)))
    _block(client, (0.015, 0.015, 0.005), 0.3, 0.0, 0.0)
    _settle(client)
    con = pad_contacts(client, mp)
    assert np.allclose(con.xyz[:, 2], -lift, atol=1e-4) and np.allclose(con.cos_normal, 1.0)
    r = read_pad(client, mp)
    F = float(r.pressure_true @ BH8_PALM.areas()) * 1e3
    assert F == pytest.approx(0.3 * G if lift < BH8_PALM.face_tol else 0.0, rel=0.01, abs=1e-12)


def test_rotated_pad_frame(client: int, tmp_path: Path) -> None:
    """The pad frame yawed 90 deg on the face: rows now run along world y; the block's
    cells are found in the pad frame."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger, T_frame_pad=make_T(rot_z(math.pi / 2)))
    _block(client, (0.015, 0.015, 0.005), 0.3, 0.005, 0.015)  # pad frame (0.015, -0.005)
    _settle(client)
    r = read_pad(client, mp)
    img, _ = pressure_image(BH8_PALM, r.pressure_true)
    assert np.unravel_index(np.argmax(img), img.shape) == (4, 1)
    assert float(r.pressure_true @ BH8_PALM.areas()) * 1e3 == pytest.approx(0.3 * G, rel=0.01)


# ------------------------------------------------------------ (6) the Barrett layout
def test_barrett_layout_counts_and_areas() -> None:
    """pomares2011 Sec. 7.3: 24 tactels of 100 mm^2 (palm), 22 of 36 mm^2 (outer), 24 of
    25 mm^2 (inner); GraspIt's footprints 60 x 40 and 48 x 18 mm; no two cells overlap."""
    expect = {"palm": (BH8_PALM, 24, 100.0, (60, 40), (6, 4), 0),
              "distal": (BH8_DISTAL, 22, 36.0, (48, 18), (7, 3), 1),
              "proximal": (BH8_PROXIMAL, 24, 25.0, (40, 15), (8, 3), 0)}
    for name, (lay, n, area_mm2, foot_mm, shape, n_extra) in expect.items():
        assert lay.n_tactels == n, name
        np.testing.assert_allclose(lay.areas() * 1e6, area_mm2, err_msg=name)
        c, h = lay.centres(), 0.5 * lay.sizes()
        lo, hi = (c - h).min(axis=0), (c + h).max(axis=0)
        np.testing.assert_allclose((hi - lo) * 1e3, foot_mm, err_msg=name)
        centre = (0.0075, 0.0) if name == "distal" else (0.0, 0.0)  # issue 17 item 8
        np.testing.assert_allclose(0.5 * (hi + lo), centre, atol=1e-12, err_msg=name)
        gap = np.abs(c[:, None] - c[None]) - (h[:, None] + h[None])  # < 0 in x and y: overlap
        overlap = np.all(gap < -1e-9, axis=2) & ~np.eye(n, dtype=bool)
        assert not overlap.any(), name
        img, extra = pressure_image(lay, np.arange(n, dtype=float))
        assert img.shape == shape and extra.shape == (n_extra,)
        assert img[1, 0] == shape[1]  # row-major: the next row starts after cols cells
    # the distal tip cell continues the middle column towards the fingertip (+x)
    tip = BH8_DISTAL.centres()[21]
    np.testing.assert_allclose(tip, [0.0285, 0.0])
    assert tip[0] > BH8_DISTAL.centres()[:21, 0].max()


def test_distal_pad_ends_where_the_finger_ends() -> None:
    """Issue 17 item 8: GraspIt's distal cells end at its link-3 frame, the distal link's end
    (DH a = 55 mm): ours end at our finger's end, A3 + tip radius from the distal axis (the
    pad frame sits at the distal box's face centre)."""
    from repro.sim.barrett import BH8_A3, BH8_GEOMETRY

    c, h = BH8_DISTAL.centres(), 0.5 * BH8_DISTAL.sizes()
    far_end = BH8_GEOMETRY.distal_box[0] / 2 + float((c + h)[:, 0].max())
    assert far_end == pytest.approx(BH8_A3 + BH8_GEOMETRY.tip_radius, abs=1e-12)


def test_bh8_pads_and_tactel_row() -> None:
    pads = bh8_pads()
    assert [q.name for q in pads] == list(BH8_PAD_NAMES)
    assert [q.frame for q in pads] == [f"bh8_{n}_pad" for n in BH8_PAD_NAMES]
    assert [q.layout.n_tactels for q in pads] == [24, 24, 22, 24, 22, 24, 22]
    assert all(np.array_equal(q.pose(), np.eye(4)) for q in pads)
    moved = bh8_pads(frames={"palm": "bh8_palm"},
                     offsets={"palm": make_T(t=(0.0, 0.0, 0.05))})
    assert moved[0].frame == "bh8_palm" and moved[0].pose()[2, 3] == 0.05
    with pytest.raises(UnknownChoiceError, match="palm"):
        bh8_pads(frames={"thumb": "x"})
    with pytest.raises(ConfigError):
        PadLayout(rows=0, cols=3, cell=(0.005, 0.005))
    with pytest.raises(ConfigError):
        TactilePad("x", "f", BH8_PALM, T_frame_pad=np.eye(3))


# ------------------------------------------------- the Sensor protocol and its columns
def test_columns_declared_and_tactel_export(client: int, tmp_path: Path) -> None:
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger)
    sensor = TactileSensor(client, [mp], tactel_columns=True)
    _block(client, (0.015, 0.015, 0.005), 0.3, -0.005, -0.005)
    _settle(client)
    r = sensor.read(0.0)
    cols = Columns()
    sensor.declare(cols)
    row = sensor.columns(r)
    assert set(row) == {c.name for c in cols}
    assert row["tac_palm_pmax"] == r.pads["palm"].p_max > 0
    assert row["tac_palm_F"] == pytest.approx(0.3 * G, rel=0.01)
    # the reported map's force: off by at most half a step on every tactel
    half_step_N = 0.5 * PRESSURE_STEP_KPA * BH8_PALM.areas().sum() * 1e3
    assert abs(row["tac_palm_Fmap"] - 0.3 * G) <= half_step_N
    tr = tactel_row(r)
    assert len(tr) == 24
    np.testing.assert_array_equal([tr[f"tac_palm_{k}"] for k in range(1, 25)],
                                  r.pads["palm"].pressure)
    d = sensor.describe()
    assert d["pads"][0]["contact_link_index"] == -1 and len(
        d["pads"][0]["tactel_areas_m2"]) == 24
    with pytest.raises(UnknownChoiceError, match="finger_pad"):
        mount_pads(client, finger, [TactilePad("x", "no_such_link", BH8_PALM)])


def test_non_finite_contacts_are_events_then_a_failure(client: int, tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """PyBullet giving a NaN force: the point is dropped, an event is logged; three samples
    in a row and the pad has failed."""
    finger = _finger(client, tmp_path)
    mp = _palm(client, finger)
    sensor = TactileSensor(client, [mp])
    nan_contact = (0, finger, 99, -1, -1, (0.0, 0.0, FINGER_HALF[2]), (0.0, 0.0, 0.01),
                   (0.0, 0.0, -1.0), 0.0, float("nan"), 0.0, (1, 0, 0), 0.0, (0, 1, 0))
    monkeypatch.setattr(p, "getContactPoints", lambda *a, **k: (nan_contact,))
    for n in range(3):
        r = sensor.sample(n / 30)
        assert r.pads["palm"].invalid and np.all(r.pads["palm"].pressure == 0)
        assert [k for k, _ in sensor.events(r)] == ["sensor_nan"]
        assert (sensor.failure(r) is None) == (n < 2)
    monkeypatch.undo()
    assert sensor.failure(sensor.sample(0.1)) is None


# ------------------------------------------------------- issue 17 item 8: coverage audit
def test_coverage_is_one_on_the_cells_and_low_off_them(client: int, tmp_path: Path) -> None:
    """A block resting on the palm's cells: the map carries the link's force (coverage ~1,
    no event). The same block resting on the finger's face beyond the cells: the link
    feels it, the map does not (coverage ~0, a tactile_coverage_low event, then its end when
    the block is lifted off)."""
    finger = _finger(client, tmp_path, (0.08, 0.04, 0.01))
    mp = _palm(client, finger)
    sensor = TactileSensor(client, [mp])
    blk = _block(client, (0.01, 0.01, 0.005), 0.2, 0.0, 0.0, z_support=0.01)
    _settle(client)
    r = sensor.sample(0.0)
    pr = r.pads["palm"]
    assert pr.force_link == pytest.approx(0.2 * G, rel=0.01)
    assert pr.coverage == pytest.approx(1.0, abs=0.05)
    assert [k for k, _ in sensor.events(r)] == []
    # the block moved to the face beyond the 60 mm palm grid (x = 0.065 m)
    p.resetBasePositionAndOrientation(blk, [0.065, 0.0, 0.0151], [0, 0, 0, 1],
                                      physicsClientId=client)
    _settle(client)
    r = sensor.sample(0.1)
    pr = r.pads["palm"]
    assert pr.force_link == pytest.approx(0.2 * G, rel=0.01) and pr.coverage < 0.1
    assert [k for k, _ in sensor.events(r)] == ["tactile_coverage_low"]
    assert sensor.events(sensor.sample(0.2)) == []  # an onset, not every sample
    p.removeBody(blk, physicsClientId=client)
    p.stepSimulation(physicsClientId=client)
    r = sensor.sample(0.3)
    assert np.isnan(r.pads["palm"].coverage)  # nothing to judge
    assert [k for k, _ in sensor.events(r)] == ["tactile_coverage_low_end"]
    cols = sensor.columns(r)
    assert {"tac_palm_Flink", "tac_palm_coverage"} <= set(cols)
