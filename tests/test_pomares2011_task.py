"""The whole task of pomares2011 Table 1 (experiments/pomares2011/task.py): its layout (IK
solutions, views, clearances, desired features), a short run through the phase switch, and
the configs it refuses."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from experiments.pomares2011 import scene as sc
from experiments.pomares2011 import task as T
from repro.control.rvc import rvc_features
from repro.errors import ConfigError
from repro.geometry import inv_T
from repro.runs.trace import load_run
from repro.sensors.camera import project_points
from repro.sim import barrett as B
from repro.sim.pa10 import ALL_JOINTS, ALL_LIMITS, HAND_JOINTS
from repro.sim.robot import Robot, solve_ik
from repro.sim.scene import Part, Scene
from repro.sim.world import WorldConfig

L = T.TASK_LAYOUT
CONFIGS = {"goal": L.q_goal, "start": L.q_start}


@pytest.fixture(scope="module")
def scene_robot():  # type: ignore[no-untyped-def]
    cfg = T.TaskConfig()
    scene = Scene(WorldConfig(physics_dt=1e-3, control_dt=1e-3), render=False)
    robot = sc.build_scene(scene, L.q_goal)[0]
    scene.add_dynamic("cylinder", Part("cylinder", (cfg.cylinder_radius, cfg.cylinder_length)),
                      cfg.cylinder_mass, T.cylinder_pose(cfg), T.TASK_CYLINDER_RGBA, {})
    scene.add_box("support", T.support_size(cfg), T.support_pose(cfg), (0.5, 0.5, 0.5, 1.0))
    yield scene, robot


@pytest.mark.parametrize("which", ["goal", "start"])
def test_pa10_configuration_is_the_ik_solution(scene_robot: tuple[Scene, Robot],
                                               which: str) -> None:
    _, robot = scene_robot
    q = CONFIGS[which]
    target = T.flange_goal() if which == "goal" else T.flange_start()
    np.testing.assert_allclose(robot.frame_pose("pa10_flange", q), target, atol=1e-6)
    seed = sc.Q_GOAL if which == "goal" else L.q_goal
    np.testing.assert_allclose(solve_ik(robot, "pa10_flange", target, seed)[:6], q[:6],
                               atol=1e-6)
    np.testing.assert_array_equal(q[9:], sc.Q_HAND)  # the hand half open, as in exp1
    margin = 5.0 * sc.DEG
    assert np.all(q[:9] > np.asarray(ALL_LIMITS.q_min[:9]) + margin)
    assert np.all(q[:9] < np.asarray(ALL_LIMITS.q_max[:9]) - margin)


def test_goal_grasps_the_cylinder_and_start_is_above_it() -> None:
    """At the goal the palm is palm_gap over the cylinder, the hand axis through its axis,
    as in experiment 3's hand frame; the start is 0.25 m straight above, turned 5 deg."""
    cfg = T.TaskConfig()
    F = sc.kinematic_frames(L.q_goal)
    T_flange_cyl = inv_T(F["pa10_flange"]) @ T.cylinder_pose(cfg)
    # (the stored joints have 1e-6 deg: 1e-7 m)
    np.testing.assert_allclose(T_flange_cyl[:3, 3], [0.0, 0.0, 0.079 + 0.005 + 0.040],
                               atol=1e-7)
    np.testing.assert_allclose(abs(T_flange_cyl[0, 2]), 1.0, atol=1e-9)  # axis = hand x
    S = sc.kinematic_frames(L.q_start)["pa10_flange"]
    np.testing.assert_allclose(S[:3, 3] - F["pa10_flange"][:3, 3], [0.0, 0.0, 0.25], atol=1e-7)
    turn = np.degrees(np.arccos(np.clip((np.trace(F["pa10_flange"][:3, :3].T @ S[:3, :3]) - 1)
                                        / 2, -1, 1)))
    assert turn == pytest.approx(5.0, abs=1e-6)


@pytest.mark.parametrize("which", ["goal", "start"])
def test_camera_sees_every_dot_unoccluded(scene_robot: tuple[Scene, Robot], which: str) -> None:
    """All four dots project >= 50 px inside the image, 0.1-0.5 m away, and nothing (robot,
    hand, cylinder, support) lies between the optical centre and any of them."""
    scene, robot = scene_robot
    q = CONFIGS[which]
    robot.reset(q)
    T_wc = robot.frame_pose("mini_camera_optical", q)
    P = sc.DOTS.points_world(sc.OBJECT.T_world)
    uv, Z = project_points(sc.INTRINSICS, T_wc, P)
    assert np.all((uv[:, 0] > 50) & (uv[:, 0] < sc.IMAGE_W - 50)), uv
    assert np.all((uv[:, 1] > 50) & (uv[:, 1] < sc.IMAGE_H - 50)), uv
    assert np.all((Z > 0.1) & (Z < 0.5)), Z
    for point in P:
        hit = p.rayTest(T_wc[:3, 3].tolist(), point.tolist(),
                        physicsClientId=scene.physics.client)[0]
        assert hit[0] == -1 or hit[0] == scene["dots"].ids[0], (which, point, hit)
    if which == "start":  # the approach has something to do: ~100 px from s*
        err = np.sqrt(np.mean(np.sum((uv - L.s_star) ** 2, axis=1)))
        assert 60.0 < err < 150.0, err


def test_desired_features_are_learned_at_the_goal() -> None:
    """s* = the exact projections of the dots at the goal; P_u project to the paper's s_u*
    through the RVC at the goal with the true object pose (the learning stage's target),
    in front of it at the part's depth."""
    F = sc.kinematic_frames(L.q_goal)
    uv, _ = project_points(sc.INTRINSICS, F["mini_camera_optical"],
                           sc.DOTS.points_world(sc.OBJECT.T_world))
    np.testing.assert_allclose(L.s_star, uv, atol=1e-9)
    feats = rvc_features(sc.RVC_INTRINSICS, inv_T(F["rvc"]) @ sc.OBJECT.T_world, L.points_u)
    np.testing.assert_allclose(feats.uv, sc.S_U_STAR, atol=1e-6)
    assert np.all(feats.Z > 0.2)
    np.testing.assert_allclose(L.points_u[:, 2], sc.OBJECT.top_z, atol=1e-12)
    assert not np.allclose(L.s_star, sc.S_STAR, atol=5.0)  # not experiment 1's values


@pytest.mark.parametrize("which", ["goal", "start"])
def test_hand_clears_the_cylinder_and_everything_clears_the_table(
        scene_robot: tuple[Scene, Robot], which: str) -> None:
    """The half-open hand around (goal) or above (start) the cylinder without touching it
    (>= 5 mm), the support >= 2 cm from the robot, the table and the part >= 5 cm."""
    scene, robot = scene_robot
    robot.reset(CONFIGS[which])
    d = scene.distances(robot)
    assert d["cylinder"] > 0.005, d
    assert d["support"] > 0.02, d
    assert min(d["table"], d["object"]) > 0.05, d


def short_config(**kw: object) -> T.TaskConfig:
    """The exact camera, the arm stopping at 60 px (so the manipulation begins ~1 s in)."""
    fields: dict[str, object] = {"camera_mode": "exact", "arm_stop_px": 60.0, "duration": 2.5,
                                 "snapshot_period": 0.0, **kw}
    return dataclasses.replace(T.TaskConfig(), **fields)


def test_short_run_switches_phase_once_when_the_arm_stops(tmp_path: Path) -> None:
    """Before the RVC reaches arm_stop_px the finger motors hold the approach pose and the
    hand waits; at that very step the PA-10's commands become 0 for good and the hand begins
    (pre-shape at its speed, then closing); every Algorithm-1-rate tactile sample is a row;
    the hand's joints are logged by the runner (bh8_q, a joint group without a drive)."""
    run = load_run(T.run(short_config(), tmp_path / "task"))
    df, ev = run.trace, run.events
    reached = ev[ev["kind"] == "rvc_reached"]
    begun = ev[ev["kind"] == "task_manipulation"]
    assert len(reached) == 1 and len(begun) == 1
    t0 = float(begun["t"].iloc[0])
    assert float(reached["t"].iloc[0]) == t0 and 0.3 < t0 < 2.0
    before, after = df[df["t"] < t0], df[df["t"] >= t0]
    assert set(before["task_phase"]) == {"approach"} and set(after["task_phase"]) == {
        "manipulation"}
    assert set(before["phase"]) == {"waiting"} and "preshape" in set(after["phase"])
    motor_u = df[["motor_u1", "motor_u2", "motor_u3"]].to_numpy(float)
    np.testing.assert_array_equal(motor_u[df["t"].to_numpy() < t0], sc.HAND_APPROACH_MOTOR)
    rate = B.J2_RATIO * np.radians(T.TaskConfig().preshape_speed_deg_s)
    grow = np.diff(motor_u[:, 0]) / np.diff(df["t"].to_numpy(float))
    assert grow.max() == pytest.approx(rate, rel=1e-6)  # the pre-shape's speed, no faster
    pa10_u = after[[f"pa10_u{i}" for i in range(1, 7)]].to_numpy(float)
    assert np.all(pa10_u == 0.0)
    assert np.abs(before[[f"pa10_u{i}" for i in range(1, 7)]].to_numpy(float)).max() > 1e-3
    assert not df["tick"].astype(bool).any()  # no trajectory in 2.5 s: no Algorithm-1 tick
    assert {f"bh8_q{i}" for i in range(1, len(HAND_JOINTS) + 1)} <= set(df.columns)
    assert {"bh8_dist_cylinder", "bh8_dist_min", "hand_dist_cylinder"} <= set(df.columns)
    assert not any(c.startswith("hand_q") for c in df.columns)
    assert run.manifest["status"] == "completed"
    assert len(ALL_JOINTS) == 17


@pytest.mark.parametrize("field, value", [("human", True), ("tactile_control", False),
                                          ("cylinder_radius", 0.05), ("log_every", 7)])
def test_refuses_configs_the_task_is_not(tmp_path: Path, field: str, value: object) -> None:
    with pytest.raises(ConfigError):
        T.run(dataclasses.replace(T.TaskConfig(), **{field: value}), tmp_path / "x")
    assert not (tmp_path / "x").exists()
