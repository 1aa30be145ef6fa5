"""pomares2011 scene: the paper's desired features are what the cameras see at the goal.

The experiment package is not registered yet: the scene module is loaded by its path.
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import numpy as np
import pybullet as p
import pytest

from repro.control.rvc import learn_desired_features, rvc_features
from repro.errors import ConfigError
from repro.sensors.camera import Camera, disc_image_centroids, project_points
from repro.sim.pa10 import ALL_LIMITS, HAND_JOINTS
from repro.sim.robot import Robot, solve_ik
from repro.sim.scene import Scene
from repro.sim.world import WorldConfig
from repro.vision.pose import is_collinear

_PATH = Path(__file__).resolve().parent.parent / "experiments" / "pomares2011" / "scene.py"


def _load() -> ModuleType:
    name = "pomares2011_scene_under_test"
    spec = importlib.util.spec_from_file_location(name, _PATH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up while building the class
    spec.loader.exec_module(module)
    return module


S = _load()
CONFIGS = {"goal": S.Q_GOAL, "start": S.Q_START}


@pytest.fixture(scope="module")
def scene_robot() -> Iterator[tuple[Scene, Robot]]:
    with Scene(WorldConfig(), render=True) as scene:
        yield scene, S.build_scene(scene, S.Q_GOAL)[0]


def _measure(scene: Scene, robot: Robot, q: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(detected uv, found, exact projections uv, depths Z) of the dots at ``q``."""
    robot.reset(q)
    T_wc = robot.frame_pose("mini_camera_optical", q)
    uv, found, Z = Camera(S.INTRINSICS).measure(scene.render_client, T_wc, S.DOTS,
                                                S.OBJECT.T_world)
    exact, _ = project_points(S.INTRINSICS, T_wc, S.DOTS.points_world(S.OBJECT.T_world))
    return uv, found, exact, Z


def test_goal_image_is_s_star(scene_robot: tuple[Scene, Robot]) -> None:
    """At Q_GOAL the exact projections of P_p are s* (1e-6 px) and the rendered, detected
    dots are within 1 px of s* (measured: <= 0.06 px)."""
    scene, robot = scene_robot
    uv, found, exact, Z = _measure(scene, robot, S.Q_GOAL)
    np.testing.assert_allclose(exact, S.S_STAR, atol=1e-6)
    assert found.all()
    err = np.linalg.norm(uv - S.S_STAR, axis=1)
    assert err.max() < 1.0, err
    assert np.all((Z > 0.15) & (Z < 0.3))  # depths [m]


def test_rvc_goal_features_are_s_u_star(scene_robot: tuple[Scene, Robot]) -> None:
    """The RVC at the PA-10 goal, with the kinematic T_rvc_obj, projects P_u to s_u*."""
    _, robot = scene_robot
    T_rvc_obj = S.rvc_object_pose(robot.frame_pose("pa10_flange", S.Q_GOAL))
    s_u = learn_desired_features(S.RVC_INTRINSICS, T_rvc_obj, S.POINTS_U)
    np.testing.assert_allclose(s_u, S.S_U_STAR, atol=1e-6)
    # the scene module's pinocchio kinematics agree with the Robot's
    np.testing.assert_allclose(S.kinematic_frames(S.Q_GOAL)["rvc"],
                               robot.frame_pose("pa10_flange", S.Q_GOAL) @ S.T_FLANGE_RVC,
                               atol=1e-12)


def test_start_every_dot_found_and_away_from_goal(scene_robot: tuple[Scene, Robot]) -> None:
    """At Q_START every dot is in the image (>= 50 px from its border), found within 1 px of
    its disc image's centre, and the images of both cameras are far from the goal's."""
    scene, robot = scene_robot
    uv, found, exact, Z = _measure(scene, robot, S.Q_START)
    assert found.all()
    assert np.all(Z > 0)
    b = S.INTRINSICS.image_bounds()
    assert np.all((exact[:, 0] > b.u_min + 50) & (exact[:, 0] < b.u_max - 50))
    assert np.all((exact[:, 1] > b.v_min + 50) & (exact[:, 1] < b.v_max - 50))
    T_wc = robot.frame_pose("mini_camera_optical", S.Q_START)
    centres = disc_image_centroids(S.INTRINSICS, T_wc, S.DOTS, S.OBJECT.T_world)
    assert np.linalg.norm(uv - centres, axis=1).max() < 1.0
    assert np.linalg.norm(uv - S.S_STAR, axis=1).min() > 30.0  # [px]
    T_rvc_obj = S.rvc_object_pose(robot.frame_pose("pa10_flange", S.Q_START))
    s_u = rvc_features(S.RVC_INTRINSICS, T_rvc_obj, S.POINTS_U)  # raises if Z <= 0
    assert np.linalg.norm(s_u.uv - S.S_U_STAR, axis=1).min() > 50.0  # [px]


@pytest.mark.parametrize("which", ["goal", "start"])
def test_configurations_within_limits(which: str) -> None:
    """The arm and the mini-robot >= 5 deg inside their limits; the hand (spread 0 is its
    lower limit) at the approach pose: engaged, distal = proximal / 3, half open."""
    q = CONFIGS[which]
    assert q.shape == (17,)
    margin = 5.0 * S.DEG
    assert np.all(q[:9] > np.asarray(ALL_LIMITS.q_min[:9]) + margin)
    assert np.all(q[:9] < np.asarray(ALL_LIMITS.q_max[:9]) - margin)
    assert np.all(q[9:] >= np.asarray(ALL_LIMITS.q_min[9:]))
    assert np.all(q[9:] <= np.asarray(ALL_LIMITS.q_max[9:]))
    np.testing.assert_array_equal(q[9:], S.Q_HAND)
    for k in (1, 2, 3):
        q_p = S.Q_HAND[HAND_JOINTS.index(f"bh8_finger{k}_proximal_joint")]
        q_d = S.Q_HAND[HAND_JOINTS.index(f"bh8_finger{k}_distal_joint")]
        assert q_p == pytest.approx(np.deg2rad(60.0), abs=1e-12)
        assert q_d == pytest.approx(q_p / 3.0, abs=1e-12)


@pytest.mark.parametrize("which", ["goal", "start"])
def test_no_collision_with_table_or_object(scene_robot: tuple[Scene, Robot],
                                           which: str) -> None:
    """PyBullet closest points: the robot clears the table and the part by >= 5 cm."""
    scene, robot = scene_robot
    robot.reset(CONFIGS[which])
    d = scene.distances(robot)
    assert set(d) == {"table", "object"}
    assert min(d.values()) > 0.05, d


@pytest.mark.parametrize("which", ["goal", "start"])
def test_dots_not_occluded_by_the_robot(scene_robot: tuple[Scene, Robot], which: str) -> None:
    """The robot is not in the render mirror: check in the physics world that nothing (hand,
    mini-robot, arm) lies on the segment from the optical centre to each dot."""
    scene, robot = scene_robot
    q = CONFIGS[which]
    robot.reset(q)
    c = robot.frame_pose("mini_camera_optical", q)[:3, 3]
    for P in S.DOTS.points_world(S.OBJECT.T_world):
        hit = p.rayTest(c.tolist(), P.tolist(), physicsClientId=scene.physics.client)[0]
        assert hit[0] == -1, (which, P, hit)


@pytest.mark.parametrize("which", ["goal", "start"])
def test_pa10_configuration_is_the_ik_solution(scene_robot: tuple[Scene, Robot],
                                               which: str) -> None:
    """The stored PA-10 joints put the flange at the stated pose; solve_ik from the stated
    seed finds them again."""
    _, robot = scene_robot
    q = CONFIGS[which]
    T_target = S.T_WORLD_FLANGE_GOAL if which == "goal" else S.T_WORLD_FLANGE_START
    seed = S.IK_SEED_GOAL if which == "goal" else S.Q_GOAL
    np.testing.assert_allclose(robot.frame_pose("pa10_flange", q), T_target, atol=1e-6)
    q_ik = solve_ik(robot, "pa10_flange", T_target, seed)
    np.testing.assert_allclose(q_ik[:6], q[:6], atol=1e-6)
    np.testing.assert_array_equal(q_ik[6:], seed[6:])  # the flange does not depend on them


def test_goal_is_ready_to_grasp(scene_robot: tuple[Scene, Robot]) -> None:
    """At the goal the hand axis points straight down through the top-face centre, the palm
    0.24 m above it (fingertips well clear)."""
    _, robot = scene_robot
    T_wp = robot.frame_pose("bh8_palm", S.Q_GOAL)
    top = S.OBJECT.T_world @ np.array([0.0, 0.0, S.OBJECT.top_z, 1.0])
    np.testing.assert_allclose(T_wp[:3, 2], [0.0, 0.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(T_wp[:2, 3], top[:2], atol=1e-6)
    assert T_wp[2, 3] - top[2] == pytest.approx(S.GOAL_STANDOFF - 0.079, abs=1e-6)


def test_model_geometry_is_sane() -> None:
    """P_p on the dot plane and inside the top face (>= 3 cm margin), well apart for their
    size; P_u on the top face (>= 1.5 cm margin), not degenerate; dots imaged 8-20 px
    across at the goal; positive depths in both cameras."""
    half = np.array(S.OBJECT.size[:2]) / 2.0
    P_p, P_u = S.DOTS.points_target, S.POINTS_U
    np.testing.assert_allclose(P_p[:, 2], S.OBJECT.top_z + S.DOT_PROUD, atol=1e-12)
    np.testing.assert_allclose(P_u[:, 2], S.OBJECT.top_z, atol=1e-12)
    assert np.all(np.abs(P_p[:, :2]) < half - 0.03)
    assert np.all(np.abs(P_u[:, :2]) < half - 0.015)
    for P in (P_p, P_u):
        gaps = [np.linalg.norm(P[i] - P[j]) for i in range(4) for j in range(i)]
        assert min(gaps) > 8 * S.DOT_RADIUS  # [m]
        for drop in range(4):  # no three points on a line: a proper quadrilateral
            assert not is_collinear(np.delete(P[:, :2], drop, axis=0))
            tri = np.delete(P[:, :2], drop, axis=0)
            (ax, ay), (bx, by) = tri[1] - tri[0], tri[2] - tri[0]
            area = 0.5 * abs(ax * by - ay * bx)
            assert area > 5e-5  # [m^2]
    F = S.kinematic_frames(S.Q_GOAL)
    _, Z = project_points(S.INTRINSICS, F["mini_camera_optical"],
                          S.DOTS.points_world(S.OBJECT.T_world))
    diameter = 2.0 * S.INTRINSICS.fu * S.DOT_RADIUS / Z  # fronto-parallel, [px]
    assert np.all((diameter > 8.0) & (diameter < 20.0)), diameter
    assert np.all(rvc_features(S.RVC_INTRINSICS, S.rvc_object_pose(F["pa10_flange"]),
                               S.POINTS_U).Z > 0.2)


def test_intrinsics_are_the_papers() -> None:
    i = S.INTRINSICS
    assert (i.width, i.height, i.u0, i.v0, i.fu, i.fv) == (640, 480, 298.0, 225.0, 1082.3,
                                                           1073.7)
    assert S.RVC_INTRINSICS == i
    assert S.S_STAR.tolist() == [[324, 207], [377, 272], [307, 322], [257, 259]]
    assert S.S_U_STAR.tolist() == [[254, 79], [293, 226], [131, 274], [93, 116]]


def test_build_scene_checks_colours() -> None:
    """A saturated body already in the scene (a red box) is rejected by build_scene."""
    with Scene(WorldConfig(), render=False) as scene:
        scene.add_box("red_box", (0.1, 0.1, 0.1), np.eye(4), (0.9, 0.1, 0.1, 1.0))
        with pytest.raises(ConfigError, match="red_box"):
            S.build_scene(scene)
