"""Tests of repro.sensors.proximity (ray-cast rings) and repro.control.proximity_features
(interaction matrices of thomas2024 eqs. (2), (5), (6); normal estimation, eq. (4)).

Walls are thin static boxes whose front face passes through a known point with a known
normal, so every reading has a closed form. The interaction matrices are checked against
central finite differences of the *simulated* readings.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from experiments.thomas2024.scene import attachments
from repro.control.proximity_features import (
    SOURCE_FIT,
    SOURCE_HELD,
    SOURCE_NONE,
    L_delta_beta1,
    L_delta_coarse,
    L_delta_exact,
    NormalEstimator,
    NormalEstimatorConfig,
    fit_plane_normal,
    ring_interaction_matrix,
)
from repro.errors import ConfigError, UnknownChoiceError
from repro.geometry import make_T
from repro.sensors.proximity import (
    RAY_MASK,
    ProximityRing,
    RingSpec,
    exclude_from_rays,
)
from repro.sim.panda import PANDA_JOINTS, PANDA_LIMITS, build_panda_urdf
from repro.sim.robot import Robot
from repro.sim.world import World

RADIUS = 0.07
M = 18
WALL_HALF_THICKNESS = 0.01


def _ring(noise_std: float = 0.0, seed: int = 0, min_range: float = 0.0) -> ProximityRing:
    spec = RingSpec("ring", RADIUS, M, max_range=1.0, min_range=min_range, noise_std=noise_std)
    return ProximityRing(spec, np.random.default_rng(seed))


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    return pin.exp3(rng.normal(size=3))


def _ring_pose(rng: np.random.Generator) -> np.ndarray:
    """A generic ring pose, 1 m above the world origin (away from anything else)."""
    return make_T(_random_rotation(rng), np.array([0.0, 0.0, 1.0]) + rng.uniform(-0.1, 0.1, 3))


def _add_wall(world: World, point: np.ndarray, normal: np.ndarray, half: float = 1.5) -> int:
    """A thin box whose front face contains ``point`` [m] and faces ``normal`` (world)."""
    z = normal / np.linalg.norm(normal)
    a = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z])
    return world.add_box((half, half, WALL_HALF_THICKNESS),
                         make_T(R, point - WALL_HALF_THICKNESS * z))


def _tilted_normal(n_S: np.ndarray, tilt: float, rng: np.random.Generator) -> np.ndarray:
    """Unit normal facing a sensor of axis n_S, tilted by ``tilt`` [rad] from -n_S about a
    random axis perpendicular to n_S."""
    axis = np.cross(n_S, rng.normal(size=3))
    axis /= np.linalg.norm(axis)
    return pin.exp3(tilt * axis) @ (-n_S)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b),
                                              -1.0, 1.0))))


# --------------------------------------------------------------------------------------
# Ring geometry
# --------------------------------------------------------------------------------------


def test_ring_spec_geometry() -> None:
    spec = RingSpec("r", RADIUS, M, theta0=0.1)
    d = spec.directions()
    assert d.shape == (M, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    np.testing.assert_allclose(d[:, 2], 0.0)
    np.testing.assert_allclose(d[0], [np.cos(0.1), np.sin(0.1), 0.0])
    # Counter-clockwise about z, 20 deg apart.
    np.testing.assert_allclose(np.cross(d[0], d[1]), [0, 0, np.sin(2 * np.pi / M)], atol=1e-15)
    np.testing.assert_allclose(spec.origins(), RADIUS * d)
    for bad in (dict(radius=0.0), dict(n_sensors=0), dict(max_range=0.1, min_range=0.2)):
        with pytest.raises(ConfigError):
            RingSpec("bad", **{"radius": RADIUS, **bad})  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------
# Ray casts against walls
# --------------------------------------------------------------------------------------


def test_facing_wall_reads_analytic_distance() -> None:
    rng = np.random.default_rng(10)
    ring = _ring()
    n_S = ring.spec.directions()
    for trial in range(3):
        with World() as world:
            T = _ring_pose(rng)
            R, c = T[:3, :3], T[:3, 3]
            i0 = int(rng.integers(M))
            d = 0.1 + 0.3 * trial
            wall = _add_wall(world, c + R @ ((RADIUS + d) * n_S[i0]), -R @ n_S[i0])
            rd = ring.read(world.client, T)
            assert rd.delta[i0] == pytest.approx(d, abs=1e-4)
            for k in range(M):
                cos = float(n_S[k] @ n_S[i0])
                expected = (RADIUS + d - RADIUS * cos) / cos if cos > 1e-9 else np.inf
                if expected < 1.0:
                    assert rd.delta[k] == pytest.approx(expected, abs=1e-4), k
                    assert rd.detected[k] and rd.hit_body[k] == wall
                else:  # facing away, or the wall beyond range
                    assert rd.delta[k] == 1.0, k
                    assert not rd.detected[k] and rd.hit_body[k] == -1
            assert not rd.invalid.any()
            # Sensors facing away see nothing: at least the back half of the ring.
            assert np.all(rd.delta[n_S @ n_S[i0] <= 0.0] == 1.0)


def test_nothing_in_range_reads_max_range() -> None:
    with World() as world:
        T = make_T(t=(0.0, 0.0, 1.0))
        _add_wall(world, np.array([RADIUS + 1.2, 0.0, 1.0]), np.array([-1.0, 0.0, 0.0]))
        rd = _ring().read(world.client, T)
        np.testing.assert_array_equal(rd.delta, 1.0)
        assert not rd.detected.any()


@pytest.mark.parametrize("tilt_deg", [0.0, 15.0, 30.0, 45.0, 60.0])
def test_tilted_wall_reads_d_over_cos(tilt_deg: float) -> None:
    """A wall at perpendicular distance d from the sensor, normal at theta from the
    sensor axis: the ray travels d / cos(theta)."""
    rng = np.random.default_rng(11 + int(tilt_deg))
    ring = _ring()
    n_S = ring.spec.directions()
    with World() as world:
        T = _ring_pose(rng)
        R, c = T[:3, :3], T[:3, 3]
        i0 = int(rng.integers(M))
        d, theta = 0.15, np.deg2rad(tilt_deg)
        n_T = _tilted_normal(R @ n_S[i0], theta, rng)
        assert _angle_deg(n_T, -R @ n_S[i0]) == pytest.approx(tilt_deg, abs=1e-9)
        s0 = c + RADIUS * R @ n_S[i0]  # sensor origin (world)
        _add_wall(world, s0 - d * n_T, n_T)
        rd = ring.read(world.client, T)
        assert rd.delta[i0] == pytest.approx(d / np.cos(theta), abs=1e-4)


def test_exclude_from_rays_hides_the_robot(tmp_path: Path) -> None:
    urdf = build_panda_urdf(tmp_path / "p.urdf", attachments())
    rng = np.random.default_rng(12)
    with World() as world:
        robot = Robot(world, urdf, PANDA_JOINTS, PANDA_LIMITS)
        q = np.array([0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8])
        robot.reset(q)
        starts, ends, inside = [], [], []
        for link in robot.link_names():
            centre = robot.frame_pose(link, q)[:3, 3]
            for _ in range(10):
                u = rng.normal(size=3)
                u /= np.linalg.norm(u)
                starts += [centre, centre + 0.4 * u]  # from inside the link; through it
                ends += [centre + 0.3 * u, centre - 0.4 * u]
                inside += [True, False]
        inside_arr = np.array(inside)

        def hits() -> np.ndarray:
            res = p.rayTestBatch([s.tolist() for s in starts], [e.tolist() for e in ends],
                                 collisionFilterMask=RAY_MASK, physicsClientId=world.client)
            return np.array([h[0] for h in res])

        before = hits()
        # Sanity: the rays do meet the robot, from inside and from outside.
        assert np.sum(before[inside_arr] == robot.body) > 10
        assert np.sum(before[~inside_arr] == robot.body) > 10

        exclude_from_rays(world.client, robot.body)
        after = hits()
        assert np.all(after != robot.body)
        assert np.all(after == -1)  # nothing else in the world

        # The rings mounted on the robot now see only obstacles: in free space, nothing...
        for name in ("ring1", "ring2"):
            rd = ProximityRing(RingSpec(name, 0.1 if name == "ring1" else 0.07)).read(
                world.client, robot.frame_pose(name, q))
            assert not rd.detected.any(), name
        # ... and a wall behind the robot is still seen (through the robot's links).
        T_r2 = robot.frame_pose("ring2", q)
        ring2 = ProximityRing(RingSpec("ring2", 0.07))
        n0 = T_r2[:3, :3] @ ring2.spec.directions()[0]
        wall = _add_wall(world, T_r2[:3, 3] + 0.5 * n0, -n0)
        rd = ring2.read(world.client, T_r2)
        assert rd.hit_body[0] == wall
        assert rd.delta[0] == pytest.approx(0.5 - 0.07, abs=1e-4)

        # Collisions between the robot and obstacles are unaffected.
        box = world.add_box((0.05, 0.05, 0.05), robot.frame_pose("panda_link4", q))
        p.performCollisionDetection(physicsClientId=world.client)
        assert len(p.getContactPoints(robot.body, box, physicsClientId=world.client)) > 0


# --------------------------------------------------------------------------------------
# Noise and the fault policy
# --------------------------------------------------------------------------------------


def _wall_world() -> tuple[World, np.ndarray]:
    world = World()
    _add_wall(world, np.array([RADIUS + 0.2, 0.0, 1.0]), np.array([-1.0, 0.0, 0.0]))
    return world, make_T(t=(0.0, 0.0, 1.0))


def test_noise_is_seeded_and_reproducible() -> None:
    world, T = _wall_world()
    with world:
        clean = _ring().read(world.client, T)
        runs = []
        for seed in (3, 3, 4):
            ring = _ring(noise_std=0.002, seed=seed)
            runs.append(np.array([ring.read(world.client, T).delta for _ in range(20)]))
        np.testing.assert_array_equal(runs[0], runs[1])
        assert not np.array_equal(runs[0], runs[2])
        det = clean.detected
        assert det.sum() >= 3
        # Noise only on detections; undetected sensors stay exactly at max_range.
        assert np.all(runs[0][:, ~det] == 1.0)
        assert np.all(runs[0][:, det] != clean.delta[det])
        assert np.all(np.abs(runs[0][:, det] - clean.delta[det]) < 5 * 0.002)


def test_noise_has_the_right_std() -> None:
    std = 0.005
    ring = _ring(noise_std=std, seed=5)
    truth = np.full(M, 0.3)
    truth[::3] = 1.0  # every third sensor detects nothing
    body = np.zeros(M, dtype=int)
    draws = np.array([ring.sanitize(truth, body).delta for _ in range(2000)])
    det = truth < 1.0
    err = (draws[:, det] - truth[det]).ravel()
    n = err.size  # 24000 samples: std of the sample std ~ 0.5 %
    assert abs(err.mean()) < 4 * std / np.sqrt(n)
    assert err.std() == pytest.approx(std, rel=0.03)
    assert np.all(draws[:, ~det] == 1.0)


def test_readings_are_clipped_to_the_range() -> None:
    ring = _ring(min_range=0.02)
    rd = ring.sanitize(np.array([0.005] + [0.5] * (M - 1)), np.zeros(M, dtype=int))
    assert rd.delta[0] == 0.02 and rd.detected[0]
    rd = _ring(noise_std=0.05, seed=1).sanitize(np.full(M, 0.999), np.zeros(M, dtype=int))
    assert np.all(rd.delta <= 1.0) and np.any(rd.delta == 1.0)


def test_nan_reading_keeps_last_valid_and_is_flagged() -> None:
    ring = _ring(noise_std=0.001, seed=6)
    body = np.zeros(M, dtype=int)
    first = ring.sanitize(np.linspace(0.1, 0.9, M), body)
    assert not first.invalid.any() and first.detected.all()
    raw = np.linspace(0.1, 0.9, M) + 0.01
    raw[[2, 7]] = np.nan
    raw[11] = np.inf
    second = ring.sanitize(raw, body)
    bad = np.zeros(M, dtype=bool)
    bad[[2, 7, 11]] = True
    np.testing.assert_array_equal(second.invalid, bad)
    np.testing.assert_array_equal(second.delta[bad], first.delta[bad])  # last valid value
    assert not second.detected[bad].any()
    assert second.detected[~bad].all()
    assert np.all(np.isfinite(second.delta))
    # The next valid reading replaces the held value.
    third = ring.sanitize(np.full(M, 0.5), body)
    assert not third.invalid.any()
    np.testing.assert_allclose(third.delta, 0.5, atol=0.01)
    # A sensor faulty from the start holds max_range.
    fresh = _ring().sanitize(np.r_[np.nan, np.full(M - 1, 0.4)], body)
    assert fresh.invalid[0] and fresh.delta[0] == 1.0 and not fresh.detected[0]


# --------------------------------------------------------------------------------------
# Interaction matrices vs finite differences of the simulated readings
# --------------------------------------------------------------------------------------


def _fd_readings(ring: ProximityRing, client: int, T: np.ndarray, twist: np.ndarray,
                 h: float = 1e-5) -> np.ndarray:
    """(delta(T exp(h xi)) - delta(T exp(-h xi))) / 2h, twist xi = (v, w) in the ring frame."""
    dp, _ = ring.cast(client, T @ pin.exp6(pin.Motion(h * twist)).homogeneous)
    dm, _ = ring.cast(client, T @ pin.exp6(pin.Motion(-h * twist)).homogeneous)
    return (dp - dm) / (2 * h)


def _tilted_wall_setup(world: World, rng: np.random.Generator, tilt_deg: float
                       ) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """Ring pose T, wall normal n_T in the ring frame (towards the sensors), the sensor i0
    the wall was placed in front of, and the sensors whose readings are usable."""
    ring = _ring()
    n_S = ring.spec.directions()
    T = _ring_pose(rng)
    R, c = T[:3, :3], T[:3, 3]
    i0 = int(rng.integers(M))
    n_w = _tilted_normal(R @ n_S[i0], np.deg2rad(tilt_deg), rng)
    _add_wall(world, c + R @ (RADIUS * n_S[i0]) - 0.2 * n_w, n_w)
    delta, _ = ring.cast(world.client, T)
    usable = delta < 0.8  # well inside the range and the wall
    assert usable[i0]
    return T, R.T @ n_w, i0, usable


def test_L_delta_exact_matches_simulated_finite_differences() -> None:
    rng = np.random.default_rng(20)
    ring = _ring()
    n_S = ring.spec.directions()
    for tilt_deg in (0.0, 30.0, 50.0):
        with World() as world:
            T, n_T, i0, usable = _tilted_wall_setup(world, rng, tilt_deg)
            delta, _ = ring.cast(world.client, T)
            for _ in range(5):
                twist = rng.normal(size=6)
                fd = _fd_readings(ring, world.client, T, twist)
                for k in np.flatnonzero(usable):
                    pred = L_delta_exact(n_S[k], n_T, float(delta[k]), RADIUS) @ twist
                    assert fd[k] == pytest.approx(pred, rel=1e-4, abs=1e-7), (tilt_deg, k)


def test_L_delta_beta1_differs_by_beta() -> None:
    """Eq. (5) is eq. (2) without beta = -1/(n_T . n_S): off by exactly that factor."""
    rng = np.random.default_rng(21)
    ring = _ring()
    n_S = ring.spec.directions()
    with World() as world:
        T, n_T, i0, usable = _tilted_wall_setup(world, rng, 30.0)
        delta, _ = ring.cast(world.client, T)
        for _ in range(5):
            twist = rng.normal(size=6)
            fd = _fd_readings(ring, world.client, T, twist)
            for k in np.flatnonzero(usable):
                beta = -1.0 / float(n_T @ n_S[k])
                L1 = L_delta_beta1(n_S[k], n_T, float(delta[k]), RADIUS)
                np.testing.assert_allclose(
                    beta * L1, L_delta_exact(n_S[k], n_T, float(delta[k]), RADIUS),
                    rtol=1e-12, atol=1e-15)
                assert fd[k] == pytest.approx(beta * (L1 @ twist), rel=1e-4, abs=1e-7)
        # For the 30 deg wall beta = 1/cos(30 deg) at sensor i0: eq. (5) is 13 % off there.
        assert -1.0 / float(n_T @ n_S[i0]) == pytest.approx(1 / np.cos(np.deg2rad(30)))


def test_L_delta_coarse_only_for_a_facing_wall() -> None:
    rng = np.random.default_rng(22)
    ring = _ring()
    n_S = ring.spec.directions()
    twists = rng.normal(size=(6, 6))
    # Facing wall (n_T = -n_S): eq. (6) is exact for that sensor.
    with World() as world:
        T, n_T, i0, _ = _tilted_wall_setup(world, rng, 0.0)
        np.testing.assert_allclose(n_T, -n_S[i0], atol=1e-12)
        delta, _ = ring.cast(world.client, T)
        np.testing.assert_allclose(L_delta_coarse(n_S[i0]),
                                   L_delta_exact(n_S[i0], n_T, float(delta[i0]), RADIUS),
                                   atol=1e-12)
        for twist in twists:
            fd = _fd_readings(ring, world.client, T, twist)
            assert fd[i0] == pytest.approx(L_delta_coarse(n_S[i0]) @ twist, rel=1e-4, abs=1e-7)
    # 30 deg tilted wall: eq. (6) is more than 10 % wrong.
    with World() as world:
        T, n_T, i0, _ = _tilted_wall_setup(world, rng, 30.0)
        fd = np.array([_fd_readings(ring, world.client, T, tw)[i0] for tw in twists])
        coarse = twists @ L_delta_coarse(n_S[i0])
        assert np.linalg.norm(fd - coarse) > 0.1 * np.linalg.norm(fd)


def test_ring_interaction_matrix_stacks_rows() -> None:
    rng = np.random.default_rng(23)
    n_S = RingSpec("r", RADIUS, M).directions()
    delta = rng.uniform(0.05, 0.9, M)
    normals = np.array([_tilted_normal(n, 0.4, rng) for n in n_S])
    normals[3] = np.nan  # no estimate: coarse row
    for model, fn in (("exact", L_delta_exact), ("beta1", L_delta_beta1)):
        L = ring_interaction_matrix(n_S, delta, RADIUS, model, normals)
        assert L.shape == (M, 6)
        for i in range(M):
            ref = (L_delta_coarse(n_S[i]) if i == 3
                   else fn(n_S[i], normals[i], float(delta[i]), RADIUS))
            np.testing.assert_allclose(L[i], ref, atol=1e-15)
    L = ring_interaction_matrix(n_S, delta, RADIUS, "coarse", normals)
    np.testing.assert_allclose(L, np.hstack([-n_S, np.zeros((M, 3))]))
    np.testing.assert_allclose(ring_interaction_matrix(n_S, delta, RADIUS, "exact", None), L)
    with pytest.raises(ConfigError):
        ring_interaction_matrix(n_S, delta, RADIUS, "nope", normals)


# --------------------------------------------------------------------------------------
# Plane fit (eq. (4)) and the normal estimator
# --------------------------------------------------------------------------------------


def test_fit_plane_normal_recovers_a_plane() -> None:
    rng = np.random.default_rng(30)
    for _ in range(10):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        d = rng.uniform(0.1, 1.0) * rng.choice([-1.0, 1.0])
        basis = np.linalg.svd(n[None, :])[2][1:]  # two unit vectors perpendicular to n
        pts = d * n + rng.uniform(-0.3, 0.3, (20, 2)) @ basis
        np.testing.assert_allclose(pts @ n, d, atol=1e-12)
        est = fit_plane_normal(pts)
        assert est is not None
        # Unit normal pointing from the origin towards the plane.
        np.testing.assert_allclose(est, np.sign(d) * n, atol=1e-9)


def test_fit_plane_normal_collinear_points_give_in_plane_normal() -> None:
    """One ring instant: points on a line of the ring plane z = 0 -> normal of the line
    within that plane (the pseudo-inverse branch)."""
    rng = np.random.default_rng(31)
    for _ in range(5):
        phi = rng.uniform(0, 2 * np.pi)
        n_in = np.array([np.cos(phi), np.sin(phi), 0.0])
        t = np.array([-np.sin(phi), np.cos(phi), 0.0])
        c = rng.uniform(0.1, 0.5)
        pts = c * n_in + rng.uniform(-0.2, 0.2, (3, 1)) * t
        est = fit_plane_normal(pts)
        assert est is not None
        np.testing.assert_allclose(est, n_in, atol=1e-9)


def test_fit_plane_normal_needs_two_points() -> None:
    assert fit_plane_normal(np.zeros((0, 3))) is None
    assert fit_plane_normal(np.array([[0.3, 0.1, 0.0]])) is None
    assert fit_plane_normal(np.array([[0.3, 0.1, 0.0], [0.3, -0.1, 0.0]])) is not None


def _estimator_run(steps: int, seed: int, tilt_deg: float = 35.0, still: int = 0,
                   noise_std: float = 0.0, est_out: list | None = None
                   ) -> tuple[list[np.ndarray], np.ndarray, int]:
    """Move a ring along its axis past a tilted wall, 1 cm per step, then hold it still for
    ``still`` steps; return the estimated normals after each step, the true normal n_T
    (ring frame) and the facing sensor. ``est_out`` receives (source, spread, cond) per
    step."""
    rng = np.random.default_rng(seed)
    ring = _ring(noise_std=noise_std, seed=seed)
    n_S = ring.spec.directions()
    est = NormalEstimator(n_S, RADIUS, NormalEstimatorConfig(range_noise=noise_std))
    with World() as world:
        T0, n_T, i0, _ = _tilted_wall_setup(world, rng, tilt_deg)
        assert np.all(np.isnan(est.normals()))  # nothing before the first update
        out = []
        for k in range(steps + still):
            T = T0 @ make_T(t=(0.0, 0.0, 0.01 * min(k, steps - 1)))
            rd = ring.read(world.client, T)
            assert rd.detected[i0]
            # the ground-truth normal of the ray cast (audit): the wall's, facing the sensor
            np.testing.assert_allclose(T[:3, :3].T @ rd.true_normal[i0], n_T, atol=1e-5)
            est.update(T, rd.delta, rd.detected)
            N = est.normals()
            assert N.shape == (M, 3)
            assert np.all(np.isnan(N[~rd.detected]))
            out.append(N)
            if est_out is not None:
                est_out.append((est.source.copy(), est.spread.copy(), est.cond.copy()))
    return out, n_T, i0  # pure translation along z: n_T is the same in every ring frame


def test_normal_estimator_converges_on_a_tilted_wall() -> None:
    for seed in (40, 41, 42):
        history, n_T, i0 = _estimator_run(6, seed)
        for N in history[2:]:
            assert _angle_deg(N[i0], n_T) < 2.0, seed
            np.testing.assert_allclose(np.linalg.norm(N[i0]), 1.0)


def test_normal_estimator_single_step_is_degenerate_and_not_used() -> None:
    """One scan only: the points are collinear (the ring plane cuts the wall along a line),
    eq. (4) would return the in-plane normal (wrong for a tilted wall); the fit is flagged
    degenerate (its least extent ~0) and the sensor falls back to the coarse row (NaN)."""
    for seed in (40, 41, 42):
        info: list = []
        (N,), n_T, i0 = _estimator_run(1, seed, est_out=info)
        assert np.all(np.isnan(N[i0]))
        src, spread, cond = info[0]
        assert src[i0] == SOURCE_NONE and spread[i0] < 1e-6 and cond[i0] > 1e8


def test_a_still_ring_holds_its_last_well_posed_normal() -> None:
    """Issue 17 item 6: after moving past the wall the ring stands still; its history
    collapses onto one line (the old estimator then returned the in-plane normal, 20-36 deg
    off). The estimate stays the last well-posed fit, flagged as held."""
    for seed in (40, 41, 42):
        info: list = []
        history, n_T, i0 = _estimator_run(6, seed, still=40, est_out=info)
        for N in history[2:]:
            assert _angle_deg(N[i0], n_T) < 2.0, seed
        sources = [src[i0] for src, _, _ in info]
        assert sources[-1] == SOURCE_HELD and SOURCE_FIT in sources[:6]
        assert all(sp[i0] < 1e-6 for src, sp, _ in info if src[i0] == SOURCE_HELD)


def test_with_range_noise_a_still_ring_never_uses_a_fit_on_noise() -> None:
    """With the suite's 2 mm noise a still ring's points spread by the noise only: no fit
    with a least extent under 3 sigma is used (held or coarse instead)."""
    sigma = 0.002
    for seed in (40, 41, 42):
        info: list = []
        history, n_T, i0 = _estimator_run(6, seed, still=30, noise_std=sigma, est_out=info)
        for (src, spread, _), N in zip(info, history, strict=True):
            if src[i0] == SOURCE_FIT:
                assert spread[i0] >= 3 * sigma
            if src[i0] == SOURCE_NONE:
                assert np.all(np.isnan(N[i0]))
        assert all(src[i0] != SOURCE_FIT for src, _, _ in info[-10:])  # still: no new fit


# --------------------------------------------------------------------------- issue 17: cone


def _cone_world(pole: bool = False):
    c = p.connect(p.DIRECT)
    if pole:  # a thin vertical pole 0.3 m ahead, 10 deg off sensor 1's axis (x)
        ang = np.radians(10.0)
        s = p.createCollisionShape(p.GEOM_CYLINDER, radius=0.003, height=1.0,
                                   physicsClientId=c)
        p.createMultiBody(0, s, basePosition=[RADIUS + 0.3 * np.cos(ang), 0.3 * np.sin(ang),
                                              0.0], physicsClientId=c)
    else:  # a wall facing sensor 1, 0.4 m from it
        s = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.01, 2.0, 2.0], physicsClientId=c)
        p.createMultiBody(0, s, basePosition=[RADIUS + 0.4 + 0.01, 0, 0], physicsClientId=c)
    return c


def test_the_default_ring_is_one_ray_per_sensor():
    spec = RingSpec("r", RADIUS, M)
    assert spec.fov_deg == 0.0 and spec.cone()[0].shape == (1, 3)


def test_a_cone_sees_what_the_axis_ray_misses_and_reports_its_return():
    c = _cone_world(pole=True)
    try:
        ray = ProximityRing(RingSpec("r", RADIUS, M)).read(c, np.eye(4))
        cone = ProximityRing(RingSpec("r", RADIUS, M, fov_deg=27.0, cone_rings=4,
                                      cone_azimuths=16)).read(c, np.eye(4))
    finally:
        p.disconnect(c)
    assert not ray.detected[0] and ray.delta[0] == 1.0
    assert cone.detected[0] and abs(cone.delta[0] - 0.3) < 0.02  # ~ its distance
    assert cone.hit_body[0] >= 0


def test_a_cone_on_a_facing_wall_nearest_is_the_axis_and_weighted_is_longer():
    c = _cone_world()
    try:
        reads = {ret: ProximityRing(RingSpec("r", RADIUS, M, fov_deg=27.0,
                                             cone_return=ret)).read(c, np.eye(4))
                 for ret in ("nearest", "weighted")}
        ray = ProximityRing(RingSpec("r", RADIUS, M)).read(c, np.eye(4))
    finally:
        p.disconnect(c)
    assert reads["nearest"].delta[0] == pytest.approx(ray.delta[0], abs=1e-6)
    assert ray.delta[0] == pytest.approx(0.4, abs=1e-6)
    # the off-axis rays travel 0.4 / cos(a): their weighted mean is longer, and bounded by
    # the outermost ray's 0.4 / cos(13.5 deg)
    assert 0.4 < reads["weighted"].delta[0] < 0.4 / np.cos(np.radians(13.5))


def test_a_bad_cone_is_refused():
    with pytest.raises(ConfigError):
        RingSpec("r", RADIUS, M, fov_deg=200.0)
    with pytest.raises(UnknownChoiceError):
        RingSpec("r", RADIUS, M, fov_deg=20.0, cone_return="median")
