"""Tests of repro.planning.capsules (pomares2011 Sec. 4: swept-sphere-line distances).

Known solutions (parallel, crossing at right angles, end to end, points = spheres,
penetration); the analytic form against python-fcl on random pairs and against an enumeration
of the KKT candidates; invariants (symmetry, swapping segment ends, witness points on the segments);
the minimum over two sets; the z-axis pose used by Scene.add_capsule.
"""

from __future__ import annotations

import numpy as np
import pytest

from repro.errors import ConfigError, UnknownChoiceError
from repro.planning.capsules import (
    METHODS,
    Capsule,
    _fcl_signed_distance,
    capsule_closest_points,
    capsule_distance,
    min_distance,
    rotation_z_to,
    segment_distance,
)

FCL_TOL = 1e-6  # [m] fcl vs analytic


def _v(*xyz: float) -> np.ndarray:
    return np.array(xyz, dtype=float)


def _random_capsule(rng: np.random.Generator, half: float = 0.5) -> Capsule:
    return Capsule(rng.uniform(-half, half, 3), rng.uniform(-half, half, 3),
                   float(rng.uniform(0.0, 0.15)))


def _on_segment(c: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> bool:
    d, _, _ = segment_distance(c, c, p0, p1)
    return d < 1e-9


def test_parallel_segments() -> None:
    p0, p1 = _v(0, 0, 0), _v(1, 0, 0)
    # overlapping projections: distance = the offset, any pair on the overlap
    d, ca, cb = segment_distance(p0, p1, _v(0.2, 0.5, 0), _v(0.8, 0.5, 0))
    assert d == pytest.approx(0.5, abs=1e-12)
    assert np.linalg.norm(ca - cb) == pytest.approx(d, abs=1e-12)
    assert 0.2 - 1e-12 <= ca[0] <= 0.8 + 1e-12
    # partly overlapping, opposite direction
    d, _, _ = segment_distance(p0, p1, _v(2.0, 0.3, 0), _v(0.5, 0.3, 0))
    assert d == pytest.approx(0.3, abs=1e-12)
    # parallel and disjoint along the axis: end to end
    d, ca, cb = segment_distance(p0, p1, _v(2, 1, 0), _v(3, 1, 0))
    assert d == pytest.approx(np.sqrt(2.0), abs=1e-12)
    np.testing.assert_allclose(ca, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(cb, [2, 1, 0], atol=1e-12)
    a, b = Capsule(p0, p1, 0.1), Capsule(_v(0.2, 0.5, 0), _v(0.8, 0.5, 0), 0.15)
    assert capsule_distance(a, b) == pytest.approx(0.25, abs=1e-12)


def test_crossing_at_right_angles() -> None:
    d, ca, cb = segment_distance(_v(-1, 0, 0), _v(1, 0, 0), _v(0.3, -1, 0.4), _v(0.3, 1, 0.4))
    assert d == pytest.approx(0.4, abs=1e-12)
    np.testing.assert_allclose(ca, [0.3, 0, 0], atol=1e-12)
    np.testing.assert_allclose(cb, [0.3, 0, 0.4], atol=1e-12)
    # the closest point of the second segment beyond the first one's end: clamped
    d, ca, cb = segment_distance(_v(-1, 0, 0), _v(1, 0, 0), _v(1.5, -1, 0.4), _v(1.5, 1, 0.4))
    assert d == pytest.approx(np.hypot(0.5, 0.4), abs=1e-12)
    np.testing.assert_allclose(ca, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(cb, [1.5, 0, 0.4], atol=1e-12)


def test_end_to_end_collinear() -> None:
    for q0, q1 in ((_v(1.5, 0, 0), _v(3, 0, 0)), (_v(3, 0, 0), _v(1.5, 0, 0))):
        d, ca, cb = segment_distance(_v(0, 0, 0), _v(1, 0, 0), q0, q1)
        assert d == pytest.approx(0.5, abs=1e-12)
        np.testing.assert_allclose(ca, [1, 0, 0], atol=1e-12)
        np.testing.assert_allclose(cb, [1.5, 0, 0], atol=1e-12)
    a = Capsule(_v(0, 0, 0), _v(1, 0, 0), 0.2)
    b = Capsule(_v(1.5, 0, 0), _v(3, 0, 0), 0.2)
    assert capsule_distance(a, b) == pytest.approx(0.1, abs=1e-12)


def test_point_like_capsules_are_spheres() -> None:
    c1, c2 = _v(0.1, -0.2, 0.3), _v(0.5, 0.1, 0.3)
    a, b = Capsule(c1, c1, 0.1), Capsule(c2, c2, 0.2)
    assert a.length == 0.0
    assert capsule_distance(a, b) == pytest.approx(0.5 - 0.3, abs=1e-12)
    # sphere against a segment, both argument orders
    seg = Capsule(_v(0, 1, 0), _v(0, -1, 0), 0.05)
    sph = Capsule(_v(0.4, 0.5, 0), _v(0.4, 0.5, 0), 0.1)
    assert capsule_distance(seg, sph) == pytest.approx(0.25, abs=1e-12)
    assert capsule_distance(sph, seg) == pytest.approx(0.25, abs=1e-12)
    for method in METHODS:
        assert min_distance([a], [b], method)[0] == pytest.approx(0.2, abs=FCL_TOL)
        assert min_distance([seg], [sph], method)[0] == pytest.approx(0.25, abs=FCL_TOL)


def test_penetration_is_negative_depth() -> None:
    # crossing segments: depth = r_a + r_b
    a = Capsule(_v(-1, 0, 0), _v(1, 0, 0), 0.1)
    b = Capsule(_v(0, -1, 0), _v(0, 1, 0), 0.05)
    assert capsule_distance(a, b) == pytest.approx(-0.15, abs=1e-12)
    # parallel, 0.1 apart, radii 0.1 each: depth 0.1
    c = Capsule(_v(-1, 0.1, 0), _v(1, 0.1, 0), 0.1)
    assert capsule_distance(a, c) == pytest.approx(-0.1, abs=1e-12)
    for method in METHODS:
        assert min_distance([a], [b], method)[0] == pytest.approx(-0.15, abs=FCL_TOL)
        assert min_distance([a], [c], method)[0] == pytest.approx(-0.1, abs=FCL_TOL)
    d, xa, xb = capsule_closest_points(a, Capsule(_v(0, 0.5, 0.0), _v(0, 0.5, 1), 0.2))
    assert d == pytest.approx(0.2, abs=1e-12)
    np.testing.assert_allclose(xa, [0, 0.1, 0], atol=1e-12)
    np.testing.assert_allclose(xb, [0, 0.3, 0], atol=1e-12)


def test_fcl_matches_analytic_on_random_pairs() -> None:
    rng = np.random.default_rng(20110)
    n_penetrating = 0
    for _ in range(500):
        a, b = _random_capsule(rng), _random_capsule(rng)
        d_an = capsule_distance(a, b)
        d_fcl, _, _ = min_distance([a], [b], method="fcl")
        assert abs(d_fcl - d_an) < FCL_TOL, (a, b, d_an, d_fcl)
        n_penetrating += d_an < 0.0
    assert 20 < n_penetrating < 480  # both regimes are exercised


def _kkt_reference(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray
                   ) -> float:
    """Segment distance by enumerating the KKT candidates of the convex quadratic
    |p0 + s d1 - q0 - t d2|^2 on [0, 1]^2: the interior stationary point (if any) and the
    minimum along each of the four edges (a 1-D clamped projection)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0

    def f(s: float, t: float) -> float:
        return float(np.linalg.norm(r + s * d1 - t * d2))

    cands = []
    A = np.array([[d1 @ d1, -d1 @ d2], [-d1 @ d2, d2 @ d2]])
    if abs(np.linalg.det(A)) > 1e-12:
        s, t = np.linalg.solve(A, [-(d1 @ r), d2 @ r])
        if 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0:
            cands.append(f(s, t))
    for s in (0.0, 1.0):
        cands.append(f(s, float(np.clip((r + s * d1) @ d2 / (d2 @ d2), 0.0, 1.0))))
    for t in (0.0, 1.0):
        cands.append(f(float(np.clip(-(r - t * d2) @ d1 / (d1 @ d1), 0.0, 1.0)), t))
    return min(cands)


def test_analytic_against_kkt_enumeration() -> None:
    rng = np.random.default_rng(3)
    for _ in range(300):
        p0, p1, q0, q1 = rng.uniform(-1, 1, (4, 3))
        d, ca, cb = segment_distance(p0, p1, q0, q1)
        assert d == pytest.approx(_kkt_reference(p0, p1, q0, q1), abs=1e-12)
        assert _on_segment(ca, p0, p1) and _on_segment(cb, q0, q1)
        assert np.linalg.norm(ca - cb) == pytest.approx(d, abs=1e-12)


def test_nearly_parallel_segments_are_robust() -> None:
    for eps in (0.0, 1e-12, 1e-9, 1e-6):
        p0, p1 = _v(0, 0, 0), _v(1, 0, 0)
        q0, q1 = _v(-0.5, 0.2, 0), _v(0.5, 0.2, eps)
        d, ca, cb = segment_distance(p0, p1, q0, q1)
        assert d == pytest.approx(0.2, abs=1e-9)
        assert _on_segment(ca, p0, p1) and _on_segment(cb, q0, q1)
        a, b = Capsule(p0, p1, 0.05), Capsule(q0, q1, 0.05)
        assert min_distance([a], [b], "fcl")[0] == pytest.approx(d - 0.1, abs=FCL_TOL)


def test_symmetric_and_invariant_to_swapping_ends() -> None:
    rng = np.random.default_rng(7)
    for _ in range(300):
        p0, p1, q0, q1 = rng.uniform(-1, 1, (4, 3))
        if rng.random() < 0.2:  # some parallel pairs
            q1 = q0 + rng.uniform(-2, 2) * (p1 - p0)
        d = segment_distance(p0, p1, q0, q1)[0]
        for args in ((q0, q1, p0, p1), (p1, p0, q0, q1), (p0, p1, q1, q0), (q1, q0, p1, p0)):
            assert segment_distance(*args)[0] == pytest.approx(d, abs=1e-12)
        a, b = Capsule(p0, p1, 0.1), Capsule(q0, q1, 0.2)
        assert capsule_distance(a, b) == pytest.approx(capsule_distance(b, a), abs=1e-12)


def test_min_distance_finds_a_pair_that_is_not_first() -> None:
    set_a = [Capsule(_v(0, 0, z), _v(1, 0, z), 0.05) for z in (0.0, 1.0, 2.0)]
    set_b = [Capsule(_v(0, 5, 0), _v(1, 5, 0), 0.05),  # 5 m from set_a[0]
             Capsule(_v(0.5, 0.3, 2.0), _v(0.5, 1.0, 2.0), 0.05),  # 0.3 m from set_a[2]
             Capsule(_v(0, 2, 0), _v(0, 3, 0), 0.05)]
    for method in METHODS:
        d, i, j = min_distance(set_a, set_b, method)
        assert (i, j) == (2, 1)
        assert d == pytest.approx(0.3 - 0.1, abs=FCL_TOL)


def test_min_distance_rejects_bad_input() -> None:
    a = Capsule(_v(0, 0, 0), _v(1, 0, 0), 0.1)
    with pytest.raises(ConfigError):
        min_distance([], [a])
    with pytest.raises(UnknownChoiceError, match="analytic, fcl"):
        min_distance([a], [a], method="gjk")
    with pytest.raises(ConfigError):
        Capsule(_v(0, 0, 0), _v(1, 0, 0), -0.1)
    with pytest.raises(ConfigError):
        Capsule(np.zeros(2), _v(1, 0, 0), 0.1)


@pytest.mark.parametrize("axis", [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0.3, -0.5, 0.2),
                                  (1e-3, 0, -1)])
def test_T_world_is_the_z_axis_capsule_pose(axis: tuple[float, float, float]) -> None:
    p0 = _v(0.2, -0.1, 0.7)
    p1 = p0 + 0.4 * np.asarray(axis) / np.linalg.norm(axis)
    c = Capsule(p0, p1, 0.05)
    T = c.T_world()
    R = T[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    half = np.array([0.0, 0.0, c.length / 2])
    np.testing.assert_allclose(R @ half + T[:3, 3], p1, atol=1e-12)
    np.testing.assert_allclose(-R @ half + T[:3, 3], p0, atol=1e-12)
    np.testing.assert_allclose(rotation_z_to(np.zeros(3)), np.eye(3))
    # transformed(): distances are invariant under a rigid motion
    rng = np.random.default_rng(1)
    other = _random_capsule(rng)
    M = np.eye(4)
    M[:3, :3] = rotation_z_to(rng.normal(size=3))
    M[:3, 3] = rng.normal(size=3)
    assert capsule_distance(c.transformed(M), other.transformed(M)) == pytest.approx(
        capsule_distance(c, other), abs=1e-12)


def _fcl_every_pair(set_a: list[Capsule], set_b: list[Capsule]) -> tuple[float, int, int]:
    """The definition: fcl on every pair, the first minimum in row-major order."""
    best = (np.inf, -1, -1)
    for i, a in enumerate(set_a):
        for j, b in enumerate(set_b):
            d = _fcl_signed_distance(a.fcl_object(), b.fcl_object())
            if d < best[0]:
                best = (d, i, j)
    return best


@pytest.mark.parametrize("spread", [0.05, 0.5, 3.0])  # overlapping, near, far apart
def test_fcl_min_distance_skips_only_pairs_that_cannot_win(spread: float) -> None:
    """min_distance(method="fcl") skips pairs by their bounding spheres: the same distance
    and the same (first) pair as fcl on every pair, to the bit, ties included."""
    rng = np.random.default_rng(11)
    for _ in range(40):
        set_a = [Capsule(*(rng.normal(0.0, spread, 3) for _ in range(2)), rng.uniform(0, 0.05))
                 for _ in range(4)]
        set_b = [Capsule(*(rng.normal(0.3, spread, 3) for _ in range(2)), rng.uniform(0, 0.1))
                 for _ in range(12)]
        set_b.append(set_b[3])  # an exact tie: the first of the two pairs wins
        assert min_distance(set_a, set_b, "fcl") == _fcl_every_pair(set_a, set_b)


def test_capsules_that_come_back_keep_their_fcl_objects(monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    """The fcl memo drops the least recently used first: a person's twelve capsules, asked
    at every call beside four robot capsules that are new at every call, are built about
    once each."""
    from repro.planning import capsules as caps

    rng = np.random.default_rng(3)
    person = [Capsule(rng.normal(size=3), rng.normal(size=3), 0.05) for _ in range(12)]
    built: list[int] = []
    real = Capsule.fcl_object
    monkeypatch.setattr(Capsule, "fcl_object", lambda c: (built.append(id(c)), real(c))[1])
    caps._FCL_MEMO.clear()
    for _ in range(40):
        robot = [Capsule(rng.normal(size=3) + 3.0, rng.normal(size=3) + 3.0, 0.05)
                 for _ in range(4)]
        d, i, j = min_distance(robot, person, method="fcl")
        assert d == min_distance(robot, person, method="analytic")[0] or abs(
            d - min_distance(robot, person, method="analytic")[0]) < 1e-12
    # (one left unused for a dozen calls, pruned, may be dropped and built again; a memo
    # emptied when full builds them again every 13 calls: ~30)
    assert sum(built.count(id(c)) for c in person) <= 15
