"""The audit's closest-points queries with a hinted threshold (repro.sim.closest, issue 15):
the same per-group distances as one query at the full cap, bit for bit, whatever the hint
and however far a body jumps between two queries."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from repro.sim.closest import ClosestPoints, group_minima
from repro.sim.pa10 import (
    ALL_JOINTS,
    ALL_LIMITS,
    HAND_JOINTS,
    MINI_JOINTS,
    PA10_JOINTS,
    pa10_urdf_path,
)
from repro.sim.scene import DISTANCE_CAP, Scene
from repro.sim.world import WorldConfig


def _brute(scene: Scene, body_a: int, body_b: int, groups: tuple, cap: float) -> list[float]:
    """The definition: one query at the cap, the minimum over each group's links."""
    pts = p.getClosestPoints(body_a, body_b, cap, physicsClientId=scene.physics.client)
    out = []
    for links in groups:
        ds = [pt[8] for pt in pts if links is None or pt[3] in links]
        out.append(min([cap, *ds]))
    return out


@pytest.fixture()
def scene():  # type: ignore[no-untyped-def]
    s = Scene(WorldConfig(physics_dt=1e-3, control_dt=1e-3))
    try:
        yield s
    finally:
        s.close()


def _arm_hand_limb(scene: Scene, x: float) -> tuple:
    """The PA-10 chain with its arm and hand groups, and a capsule limb at ``x`` [m]: the
    robot, the groups (None: every link) and the limb's PyBullet id."""
    robot = scene.add_urdf("pa10", pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS, np.eye(4))
    groups_js = [scene.add_joint_group("pa10", "arm", PA10_JOINTS, "pa10_", owns_base=True),
                 scene.add_joint_group("pa10", "hand", HAND_JOINTS, "bh8_")]
    scene.add_capsule("limb", 0.05, 0.3, _pose(np.array([x, 0.0, 0.5])), (1, 0, 0, 1),
                      moving=True)
    return robot, (None, *(frozenset(g.links) for g in groups_js)), scene["limb"].ids[0]


@pytest.fixture()
def aabb_asked(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The bodies whose box is asked of PyBullet (``getAABB``), in order."""
    asked: list[int] = []
    real = p.getAABB

    def counting(body: int, link: int = -1, **kw: int) -> tuple:
        asked.append(body)
        return real(body, link, **kw)

    monkeypatch.setattr("repro.sim.closest.p.getAABB", counting)
    return asked


def _pose(xyz: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = xyz
    return T


def test_hinted_queries_equal_one_full_query(scene: Scene) -> None:
    robot = scene.add_urdf("pa10", pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS, np.eye(4))
    groups_js = [scene.add_joint_group("pa10", "arm", PA10_JOINTS, "pa10_", owns_base=True),
                 scene.add_joint_group("pa10", "mini", MINI_JOINTS, "mini_"),
                 scene.add_joint_group("pa10", "hand", HAND_JOINTS, "bh8_")]
    scene.add_box("table", (1.2, 0.8, 0.05), _pose(np.array([0.7, 0.0, -0.05])),
                  (0.5, 0.5, 0.5, 1.0))
    scene.add_capsule("limb", 0.05, 0.3, _pose(np.array([0.9, 0.4, 0.5])), (1, 0, 0, 1),
                      moving=True)
    groups = (None, *(frozenset(g.links) for g in groups_js))
    rng = np.random.default_rng(3)
    q0 = robot.q()
    cp = ClosestPoints(scene.physics.client)
    ids = {n: scene[n].ids[0] for n in ("table", "limb")}
    fallbacks = 0
    for k in range(60):
        # small steps mostly (the hint holds); every 10th a jump (a group leaves the hint)
        jump = k % 10 == 9
        robot.reset(q0 + rng.normal(0.0, 0.8 if jump else 0.05, q0.shape))
        scene.move("limb", _pose(np.array([0.9, 0.4, 0.5]) + rng.normal(
            0.0, 0.5 if jump else 0.01, 3)))
        for bid in ids.values():
            before, skipped = cp.queries, cp.skipped
            got = cp.minima(robot.body, bid, groups, DISTANCE_CAP)
            fallbacks += cp.queries - before - 1 + (cp.skipped - skipped)  # (a skip: none)
            assert got == _brute(scene, robot.body, bid, groups, DISTANCE_CAP)  # to the bit
    assert fallbacks > 0  # the second (full) query was exercised
    assert cp.queries < 2 * 60 * len(ids)  # ... and is not asked every time
    # and the scene's per-robot distances are those minima
    d = scene.distances_of(groups_js)
    for g, dists in zip(groups_js, d, strict=True):
        for name, bid in ids.items():
            assert dists[name] == _brute(scene, robot.body, bid, (frozenset(g.links),),
                                         DISTANCE_CAP)[0]


def test_a_stale_hint_is_never_an_answer(scene: Scene) -> None:
    """A hint from a near pose, then the body far beyond it: the cap, not a stale minimum."""
    robot = scene.add_urdf("pa10", pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS, np.eye(4))
    scene.add_capsule("limb", 0.05, 0.3, _pose(np.array([0.5, 0.3, 0.4])), (1, 0, 0, 1),
                      moving=True)
    bid = scene["limb"].ids[0]
    cp = ClosestPoints(scene.physics.client)
    near = cp.minima(robot.body, bid, (None,), DISTANCE_CAP)[0]
    assert 0.0 < near < 0.5
    scene.move("limb", _pose(np.array([5.0, 5.0, 0.4])))
    assert cp.minima(robot.body, bid, (None,), DISTANCE_CAP) == [DISTANCE_CAP]
    scene.move("limb", _pose(np.array([0.5, 0.3, 0.4])))
    assert cp.minima(robot.body, bid, (None,), DISTANCE_CAP) == [near]


def test_group_minima_keeps_each_groups_own_links() -> None:
    pts = [(0, 1, 2, 5, -1, 0, 0, 0, 0.30), (0, 1, 2, 6, -1, 0, 0, 0, 0.10),
           (0, 1, 2, 5, -1, 0, 0, 0, 0.20), (0, 1, 2, 9, -1, 0, 0, 0, -0.01)]
    assert group_minima(pts, (None, frozenset({5}), frozenset({6, 7}), frozenset({8}))) == [
        -0.01, 0.20, 0.10, math.inf]


def test_bodies_beyond_the_cap_are_proved_so_by_boxes(scene: Scene) -> None:
    """A limb that wanders around the cap's sphere (in, just out, far out) and a robot that
    moves: the answers with the box test equal the full query's to the bit, bodies far
    beyond the cap are not asked, and one just beyond it is (its boxes are within
    cap + FAR_MARGIN)."""
    robot, groups, bid = _arm_hand_limb(scene, 3.0)
    cp = ClosestPoints(scene.physics.client)
    rng = np.random.default_rng(7)
    q0 = robot.q()
    for k in range(150):
        robot.reset(q0 + rng.normal(0.0, 0.3, q0.shape))
        r = [0.3, 1.4, 1.6, 2.0, 4.0][k % 5] + rng.uniform(-0.3, 0.3)
        a = rng.uniform(0.0, 2.0 * np.pi)
        scene.move("limb", _pose(np.array([r * np.cos(a), r * np.sin(a), 0.6])))
        for _ in range(2):  # the second asks with the hint of the first
            assert cp.minima(robot.body, bid, groups, DISTANCE_CAP) == _brute(
                scene, robot.body, bid, groups, DISTANCE_CAP)
    assert cp.skipped > 30 and cp.queries > 100  # both ways taken
    # the box test itself: PyBullet's link boxes hold the closest points of every link
    lo, hi = cp.boxes.box(robot.body)
    for pt in p.getClosestPoints(robot.body, bid, 10.0, physicsClientId=scene.physics.client):
        assert all(lo[i] - 1e-9 <= pt[5][i] <= hi[i] + 1e-9 for i in range(3))


def test_the_box_gap_is_the_distance_between_boxes() -> None:
    from repro.sim.link_boxes import box_gap as _box_gap

    box = ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0])
    assert _box_gap(box, [0.5, 0.5, 0.5], [2.0, 2.0, 2.0]) == 0.0  # overlapping
    assert _box_gap(box, [4.0, 0.2, 0.2], [5.0, 0.3, 0.3]) == 3.0  # along x
    assert _box_gap(box, [-4.0, -5.0, 0.2], [-3.0, -4.0, 0.3]) == 5.0  # 3-4-5 below
    assert _box_gap(box, [2.0, 3.0, 1.0], [2.5, 3.5, 1.5]) == math.hypot(1.0, 2.0)


def test_the_robot_box_holds_its_shapes_while_the_physics_moves_it(scene: Scene) -> None:
    """Stepped (not reset) at 20 rad/s: the gap between the robot's box and a body's never
    exceeds their closest distance (the box is a lower bound on the shapes the query sees)."""
    robot = scene.add_urdf("pa10", pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS, np.eye(4))
    client = scene.physics.client
    p.setGravity(0.0, 0.0, 0.0, physicsClientId=client)
    p.setJointMotorControl2(robot.body, robot.pb_joints[0], p.VELOCITY_CONTROL,
                            targetVelocity=20.0, force=1e6, physicsClientId=client)
    from repro.sim.link_boxes import box_gap as _box_gap

    cp = ClosestPoints(client)
    for k, xyz in enumerate([(0.45, 0.1, 0.5), (0.9, -0.2, 0.3), (1.5, 0.0, 0.8)] * 20):
        scene.physics.step_physics()
        if k % 3 == 0:
            scene.add_capsule(f"c{k}", 0.02, 0.1, _pose(np.array(xyz)), (1, 0, 0, 1))
        bid = scene[f"c{k - k % 3}"].ids[0]
        d = min(pt[8] for pt in p.getClosestPoints(robot.body, bid, 10.0,
                                                  physicsClientId=client))
        lo, hi = p.getAABB(bid, -1, physicsClientId=client)
        assert _box_gap(cp.boxes.box(robot.body), lo, hi) <= d + 1e-9


def test_a_kept_robot_box_grown_by_the_joint_motion_holds_the_fresh_box(scene: Scene) -> None:
    """moving_box along a random walk of the joints (small steps, some jumps, through the
    physics and through resets): it always contains the box made afresh at the same joints,
    it is made again only now and then, and the distances with it are the full query's."""
    robot = scene.add_urdf("pa10", pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS, np.eye(4))
    scene.add_capsule("limb", 0.05, 0.3, _pose(np.array([1.9, 0.0, 0.5])), (1, 0, 0, 1),
                      moving=True)
    bid = scene["limb"].ids[0]
    groups = (None,)
    cp, fresh = ClosestPoints(scene.physics.client), ClosestPoints(scene.physics.client)
    rng = np.random.default_rng(23)
    q = robot.q()
    made = 0
    for k in range(300):
        q = q + rng.normal(0.0, 0.5 if k % 50 == 49 else 3e-4, q.shape)  # ~0.3 rad/s
        robot.reset(q)
        kept = cp.boxes._moving
        before = len(kept) and kept[robot.body][3].copy()
        lo, hi = cp.boxes.moving_box(robot.body, robot.pb_joints, robot.q())
        made += not (len(kept) and np.array_equal(before, kept[robot.body][3]))
        flo, fhi = fresh.boxes.box(robot.body)
        assert all(lo[i] <= flo[i] and fhi[i] <= hi[i] for i in range(3)), k
        scene.move("limb", _pose(np.array([rng.uniform(1.0, 2.6), rng.uniform(-0.5, 0.5),
                                           0.5])))
        got = cp.minima_of(robot.body, [bid], groups, DISTANCE_CAP,
                           (robot.pb_joints, robot.q()))[0]
        assert got == _brute(scene, robot.body, bid, groups, DISTANCE_CAP), k
    assert 5 < made < 150 and cp.skipped > 20


def test_a_kept_box_follows_every_move_of_its_body(scene: Scene, aabb_asked: list[int]
                                                   ) -> None:
    """The scene's static and scripted bodies keep their PyBullet box between moves (the far
    test asks it once per pose): a limb moved in and out of the cap by ``Scene.move`` gives
    the full query's answer at every step, and its box is asked only after it moved."""
    robot = scene.add_urdf("pa10", pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS, np.eye(4))
    scene.add_capsule("limb", 0.05, 0.3, _pose(np.array([3.0, 0.0, 0.5])), (1, 0, 0, 1),
                      moving=True)
    bid = scene["limb"].ids[0]
    asked = aabb_asked
    cp = scene._closest
    for k, r in enumerate([3.0, 3.0, 3.0, 0.4, 3.0, 3.0, 1.02, 3.0]):
        scene.move("limb", _pose(np.array([r, 0.1 * k, 0.6])))
        for _ in range(3):  # still: the kept box
            got = scene.distances(robot)["limb"]
            assert got == _brute(scene, robot.body, bid, (None,), DISTANCE_CAP)[0]
    assert cp.skipped > 5
    # one box per pose at most, never one per query
    assert asked.count(bid) <= 8 < cp.skipped + cp.queries


def test_below_bounds_give_the_exact_value_only_where_it_is_below(scene: Scene) -> None:
    """``below``: each group's value is the full query's where it is below the group's
    bound and ``inf`` where it is not; a body with a bound at the cap is answered in full;
    a body asked below its bounds leaves the hints of full queries as they were."""
    robot, groups, bid = _arm_hand_limb(scene, 0.6)
    cp = ClosestPoints(scene.physics.client)
    rng = np.random.default_rng(11)
    q0 = robot.q()
    n_exact = n_inf = 0
    for _ in range(60):
        robot.reset(q0 + rng.normal(0.0, 0.3, q0.shape))
        r, a = rng.uniform(0.2, 1.2), rng.uniform(0.0, 2.0 * np.pi)
        scene.move("limb", _pose(np.array([r * np.cos(a), r * np.sin(a), 0.6])))
        truth = _brute(scene, robot.body, bid, groups, DISTANCE_CAP)
        bounds = [t + rng.choice([-0.05, -1e-9, 1e-9, 0.05]) for t in truth]
        hints = dict(cp._hint.get((robot.body, groups), {}))
        got = cp.minima_of(robot.body, [bid], groups, DISTANCE_CAP, below=[bounds])[0]
        if max(bounds) >= DISTANCE_CAP:  # asked in full: every value, its hint renewed
            assert got == truth
            continue
        assert cp._hint.get((robot.body, groups), {}) == hints
        for g, t, b in zip(got, truth, bounds, strict=True):
            if t < b:
                assert g == t
                n_exact += 1
            else:
                assert g == math.inf
                n_inf += 1
        full = cp.minima_of(robot.body, [bid], groups, DISTANCE_CAP,
                            below=[[DISTANCE_CAP] * len(groups)])[0]
        assert full == truth
    assert n_exact > 40 and n_inf > 40


def test_far_bodies_are_proved_beyond_the_cap_together(scene: Scene, aabb_asked: list[int]
                                                       ) -> None:
    """Kept bodies beyond the cap at their last query are tested together, by one box
    holding theirs: three limbs out of reach cost no query and no box per step; one moved
    within reach is asked (the union is stale after a move) and answered as the full query."""
    robot = scene.add_urdf("pa10", pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS, np.eye(4))
    names = ("l1", "l2", "l3")
    for i, n in enumerate(names):
        scene.add_capsule(n, 0.05, 0.3, _pose(np.array([3.0, 0.3 * i, 0.5])), (1, 0, 0, 1),
                          moving=True)
    ids = {n: scene[n].ids[0] for n in names}
    asked = aabb_asked
    cp = scene._closest

    def check() -> None:
        got = scene.distances(robot)
        for n in names:
            assert got[n] == _brute(scene, robot.body, ids[n], (None,), DISTANCE_CAP)[0]

    check()  # first queries: all three far
    check()  # their boxes asked, once
    asked.clear()
    q0, s0 = cp.queries, cp.skipped
    for _ in range(5):
        check()
    assert cp.queries == q0 and cp.skipped == s0 + 15
    assert not set(asked) & set(ids.values())  # (the limbs' boxes: kept)
    scene.move("l2", _pose(np.array([0.5, 0.2, 0.5])))  # within reach
    check()
    assert cp.queries > q0
    scene.move("l2", _pose(np.array([3.0, 0.3, 0.5])))
    for _ in range(3):
        check()

