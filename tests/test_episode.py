"""The shared Scene and episode runner: drives that saturate like real ones, torque control,
ground-truth distances of compound bodies, the camera audit, the NaN guard, declared
columns and self-contained run folders."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from repro.errors import ConfigError, ReproError
from repro.geometry import trans
from repro.runs.columns import Columns
from repro.runs.trace import load_run
from repro.sensors.camera import Camera, DotTarget, Intrinsics
from repro.sim.crs_a465 import CRS_JOINTS, CRS_LIMITS, crs_urdf_path
from repro.sim.drives import PositionReferenceDrive, TorqueDrive, VelocityDrive
from repro.sim.episode import CameraRig, Episode, Observation, StepResult, run_episode
from repro.sim.scene import Part, Scene
from repro.sim.world import WorldConfig

Q0 = np.array([0.3, 0.5, 0.8, 0.2, -0.4, 0.1])
GREY = (0.5, 0.5, 0.5, 1.0)


def _scene(tmp: Path, physics_dt: float = 1e-3, control_dt: float = 1e-3,
           render: bool = False) -> Scene:
    return Scene(WorldConfig(physics_dt=physics_dt, control_dt=control_dt), render=render,
                 run_dir=tmp)


def _run(ep: Episode, tmp: Path):  # type: ignore[no-untyped-def]
    run_episode(ep, tmp, experiment="test", paper="test", config={"k": 1}, seed=0)
    return load_run(tmp)


def _q(df, prefix: str = "") -> np.ndarray:  # type: ignore[no-untyped-def]
    return df[[f"{prefix}q{i}" for i in range(1, 7)]].to_numpy(float)


# ----------------------------------------------------------------------------- drives
@pytest.mark.parametrize("compensate", [True, False])
def test_gravity_compensation_holds_the_robot_still(tmp_path: Path, compensate: bool) -> None:
    scene = _scene(tmp_path)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)

    def ctrl(obs: Observation) -> StepResult:
        q = obs.q["crs"]
        return StepResult({"crs": robot.gravity_torques(q) if compensate else np.zeros(6)})

    run = _run(Episode(scene, {"crs": TorqueDrive(robot)}, ctrl, Columns(), 1.0), tmp_path)
    drift = np.abs(_q(run.trace) - Q0).max()
    if compensate:
        assert drift < 1e-6, drift
    else:  # without it the arm falls: the test can tell
        assert drift > 0.05, drift


def test_torque_drive_clips_to_tau_max(tmp_path: Path) -> None:
    scene = _scene(tmp_path)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    drive = TorqueDrive(robot)
    big = 10 * np.asarray(CRS_LIMITS.tau_max)
    np.testing.assert_allclose(drive.command(big, 1e-3), CRS_LIMITS.tau_max)
    np.testing.assert_allclose(drive.command(-big, 1e-3), -np.asarray(CRS_LIMITS.tau_max))
    scene.close()


def test_velocity_drive_saturates_whatever_the_controller_asks(tmp_path: Path) -> None:
    scene = _scene(tmp_path, 1 / 240, 1 / 30)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    qd_max = np.asarray(CRS_LIMITS.qd_max)
    ask = 10 * qd_max * np.array([1, -1, 1, -1, 1, -1])
    run = _run(Episode(scene, {"crs": VelocityDrive(robot)},
                       lambda obs: StepResult({"crs": ask}), Columns(), 0.5), tmp_path)
    df = run.trace
    qd = df[[f"qd{i}" for i in range(1, 7)]].to_numpy(float)
    assert np.all(np.abs(qd) <= qd_max * (1 + 1e-6))
    fd = np.diff(_q(df), axis=0) / (1 / 30)
    assert np.all(np.abs(fd) <= qd_max * 1.001 + 1e-9), np.abs(fd / qd_max).max()
    assert (df["n_sat"] == 6).all()
    np.testing.assert_allclose(df["u1"], ask[0])  # the trace logs the command as asked


@pytest.mark.parametrize("inner", ["kinematic", "pd"])
def test_position_reference_drive_respects_speed_limits(tmp_path: Path, inner: str) -> None:
    scene = _scene(tmp_path, 1e-3, 0.01)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    qd_max = np.asarray(CRS_LIMITS.qd_max)
    ask = 3 * qd_max
    run = _run(Episode(scene, {"crs": PositionReferenceDrive(robot, inner, 0.5)},
                       lambda obs: StepResult({"crs": ask}), Columns(), 0.3), tmp_path)
    q = _q(run.trace)
    fd = np.abs(np.diff(q, axis=0)) / 0.01
    assert np.all(fd <= qd_max * 1.02), (fd / qd_max).max()
    assert fd[5:].max() > 0.5 * qd_max.min()  # it moves


def test_kinematic_drive_tracks_a_feasible_reference(tmp_path: Path) -> None:
    scene = _scene(tmp_path, 1e-3, 0.01)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    v = 0.2 * np.asarray(CRS_LIMITS.qd_max)
    run = _run(Episode(scene, {"crs": PositionReferenceDrive(robot, "kinematic")},
                       lambda obs: StepResult({"crs": v}), Columns(), 0.5), tmp_path)
    df = run.trace
    expected = Q0 + np.outer(df["t"].to_numpy(), v)
    assert np.abs(_q(df) - expected).max() < 2e-3


def test_nan_command_never_reaches_the_drive(tmp_path: Path) -> None:
    scene = _scene(tmp_path, 1 / 240, 1 / 30)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)

    def ctrl(obs: Observation) -> StepResult:
        bad = obs.step >= 3
        return StepResult({"crs": np.full(6, np.nan) if bad else np.full(6, 0.1)})

    run = _run(Episode(scene, {"crs": VelocityDrive(robot)}, ctrl, Columns(), 1.0), tmp_path)
    assert run.manifest["status"] == "failed"
    assert "non-finite command" in run.manifest["reason"]
    assert (run.events["kind"] == "nan_command").sum() == 1
    assert len(run.trace) == 4
    assert np.isfinite(_q(run.trace)).all()


# ----------------------------------------------------------------------------- scene
def test_compound_distance_is_the_minimum_over_its_parts(tmp_path: Path) -> None:
    scene = _scene(tmp_path)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(np.zeros(6))
    far, near = trans(0.6, 0.0, 0.3), trans(0.0, 0.45, 0.3)
    parts = [Part("box", (0.05, 0.05, 0.05), far), Part("sphere", (0.03,), near)]
    scene.add_compound("thing", parts, np.eye(4), GREY)
    scene.add_box("far_alone", (0.05, 0.05, 0.05), far @ trans(0, 0, 2.0) @ trans(0, 0, -2.0),
                  GREY, render=False)
    scene.add_capsule("near_alone", 0.03, 1e-3, trans(0.0, -0.45, 0.3), GREY)
    d = scene.distances(robot)
    # The compound is as close as its nearest part (the sphere, mirrored by near_alone across
    # the robot's plane of symmetry at q = 0), not as its first part (the far box).
    assert d["thing"] < d["far_alone"] - 0.05
    assert d["thing"] == pytest.approx(d["near_alone"], abs=2e-3)
    scene.close()


def test_move_keeps_physics_and_mirror_in_step(tmp_path: Path) -> None:
    """The physics client moves at once; the render mirror before anything renders from it
    (``render_client``), lazily."""
    scene = _scene(tmp_path, render=True)
    scene.add_box("hand", (0.1, 0.1, 0.1), trans(1, 0, 0), GREY, moving=True)
    scene.move("hand", trans(0.5, 0.5, 0.5))
    scene.move("hand", trans(0.2, 0.3, 0.4))
    body = scene["hand"]
    assert scene.mirror is not None
    pos, _ = p.getBasePositionAndOrientation(body.ids[0], physicsClientId=scene.physics.client)
    np.testing.assert_allclose(pos, (0.2, 0.3, 0.4), atol=1e-12)
    pos, _ = p.getBasePositionAndOrientation(body.render_ids[0],
                                             physicsClientId=scene.mirror.client)
    np.testing.assert_allclose(pos, (1, 0, 0), atol=1e-12)  # not yet: nothing rendered
    client = scene.render_client
    pos, _ = p.getBasePositionAndOrientation(body.render_ids[0], physicsClientId=client)
    np.testing.assert_allclose(pos, (0.2, 0.3, 0.4), atol=1e-12)
    with pytest.raises(ConfigError, match="moving"):
        scene.add_box("wall", (1, 1, 1), np.eye(4), GREY)
        scene.move("wall", np.eye(4))
    with pytest.raises(ConfigError, match="already"):
        scene.add_box("hand", (1, 1, 1), np.eye(4), GREY)
    scene.close()


def test_run_folder_is_self_contained(tmp_path: Path) -> None:
    scene = _scene(tmp_path)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    scene.add_box("box", (0.2, 0.1, 0.05), trans(0.4, 0.1, 0.2), GREY)
    _run(Episode(scene, {"crs": VelocityDrive(robot)},
                 lambda obs: StepResult({"crs": np.zeros(6)}), Columns(), 0.01), tmp_path)
    text = (tmp_path / "scene.json").read_text()
    assert str(Path.home()) not in text and "site-packages" not in text
    scene_json = json.loads(text)
    urdf = next(b for b in scene_json["bodies"] if b["kind"] == "urdf")
    urdf_text = (tmp_path / urdf["urdf"]).read_text()
    for fn in re.findall(r'filename="([^"]+)"', urdf_text):
        assert not Path(fn).is_absolute()
        assert (tmp_path / fn).is_file(), fn
    box = next(b for b in scene_json["bodies"] if b["name"] == "box")
    assert box["size"] == [0.2, 0.1, 0.05]  # full extents, as the conventions say
    declared = {c["name"] for c in json.loads((tmp_path / "columns.json").read_text())["columns"]}
    assert declared == set(load_run(tmp_path).trace.columns)


def test_undeclared_trace_column_is_refused(tmp_path: Path) -> None:
    scene = _scene(tmp_path)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    ep = Episode(scene, {"crs": VelocityDrive(robot)},
                 lambda obs: StepResult({"crs": np.zeros(6)}, {"mystery": 1.0}), Columns(), 0.01)
    with pytest.raises(ReproError, match="mystery"):
        run_episode(ep, tmp_path, experiment="t", paper="t", config={"k": 1}, seed=0)


# ----------------------------------------------------------------------------- camera audit
def _camera_scene(tmp: Path, occluder: bool) -> tuple[Scene, CameraRig]:
    scene = _scene(tmp, 1 / 240, 1 / 30, render=True)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(np.zeros(6))
    T_wc = robot.frame_pose("flange", np.zeros(6))
    target = DotTarget.square(0.04, 0.006, (0.12, 0.12))
    from repro.geometry import Rx

    scene.add_dot_target("target", target, T_wc @ trans(0, 0, 0.4) @ Rx(np.pi))
    if occluder:  # a small plate hides the first dot only
        P0 = target.points_world(T_wc @ trans(0, 0, 0.4) @ Rx(np.pi))[0]
        c = T_wc[:3, 3] + 0.5 * (P0 - T_wc[:3, 3])
        scene.add_box("plate", (0.02, 0.02, 0.002), trans(*c) @ np.eye(4), GREY, render=False)
    intr = Intrinsics.centered(320, 240, 300.0)
    rig = CameraRig("camera", "s", Camera(intr, mode="exact"), robot, "flange", np.eye(4),
                    "target")
    return scene, rig


def test_audit_flags_a_detection_far_from_its_projection(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    scene, rig = _camera_scene(tmp_path, occluder=False)
    original = Camera.measure

    def biased(self, *a, **k):  # type: ignore[no-untyped-def]
        uv, found, Z = original(self, *a, **k)
        uv = uv.copy()
        uv[1] += 5.0  # point 2 is 7 px off
        return uv, found, Z

    monkeypatch.setattr(Camera, "measure", biased)
    run = _run(Episode(scene, {"crs": VelocityDrive(rig.robot)},
                       lambda obs: StepResult({"crs": np.zeros(6)}), Columns(), 0.2,
                       cameras=[rig]), tmp_path)
    audit = run.manifest["summary"]["audit"]["camera"]
    assert audit["controller_used_wrong_feature"] and audit["points_mismatched"] == [2]
    assert (run.events["kind"] == "feature_mismatch").sum() == 1
    assert run.trace["s2_err_px"].min() > 7.0 and run.trace["s1_err_px"].max() < 1e-9
    assert run.trace["s1_visible"].all()


def test_audit_flags_a_hidden_point_reported_found(tmp_path: Path) -> None:
    scene, rig = _camera_scene(tmp_path, occluder=True)
    run = _run(Episode(scene, {"crs": VelocityDrive(rig.robot)},
                       lambda obs: StepResult({"crs": np.zeros(6)}), Columns(), 0.1,
                       cameras=[rig]), tmp_path)
    df = run.trace
    assert not df["s1_visible"].any() and df[["s2_visible", "s3_visible", "s4_visible"]].all().all()
    # the exact camera mode does not know about occlusion: the audit does
    assert run.manifest["summary"]["audit"]["camera"]["points_hidden_found"] == [1]
    assert (run.events["kind"] == "hidden_found").sum() == 1


def test_video_and_snapshots_are_written_for_any_episode(tmp_path: Path) -> None:
    scene = _scene(tmp_path, 1 / 240, 1 / 30, render=True)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    scene.add_box("box", (0.1, 0.1, 0.1), trans(0.4, 0.0, 0.2), GREY)
    _run(Episode(scene, {"crs": VelocityDrive(robot)},
                 lambda obs: StepResult({"crs": np.full(6, 0.2)}), Columns(), 0.3, video=True,
                 snapshot_period=0.1), tmp_path)
    import imageio.v2 as imageio

    # issue 20: the MP4 is replayed from the run's files after it ends; a 0.3 s run plays
    # in slow motion over MIN_VIDEO_S at FPS
    from repro.replay.video import FPS, MIN_VIDEO_S

    with imageio.get_reader(tmp_path / "video.mp4") as reader:
        n = reader.count_frames()
        frames = [reader.get_data(0), reader.get_data(n - 1)]
    assert abs(n - MIN_VIDEO_S * FPS) <= 1
    assert len(list((tmp_path / "frames").glob("scene_*.png"))) == 4
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).max() > 50  # it moved


def test_a_missed_point_gets_its_ground_truth_cause(tmp_path: Path) -> None:
    scene, rig = _camera_scene(tmp_path, occluder=False)
    rig.camera = Camera(Intrinsics(320, 240, 300.0, 300.0, -20.0, 119.5), mode="exact")
    run = _run(Episode(scene, {"crs": VelocityDrive(rig.robot)},
                       lambda obs: StepResult({"crs": np.zeros(6)}), Columns(), 0.1,
                       cameras=[rig]), tmp_path)
    missed = run.events[run.events["kind"] == "feature_missed"]
    # the principal point far left: the left column of dots projects outside the image
    lost = [c for c in ("s1", "s2", "s3", "s4") if not run.trace[f"{c}_found"].any()]
    assert lost and len(missed) == len(lost)
    assert missed["detail"].str.contains("outside the image").all()


def test_two_robots_get_their_own_column_prefixes_and_distances(tmp_path: Path) -> None:
    scene = _scene(tmp_path, 1 / 240, 1 / 30)
    a = scene.add_urdf("arm_a", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS, column_prefix="a_")
    b = scene.add_urdf("arm_b", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS,
                       T_world_base=trans(0.9, 0.0, 0.0), column_prefix="b_")
    scene.add_box("box", (0.1, 0.1, 0.1), trans(0.45, 0.0, 0.05), GREY)
    a.reset(Q0)
    b.reset(-Q0)
    drives = {"arm_a": VelocityDrive(a), "arm_b": TorqueDrive(b)}

    def ctrl(obs: Observation) -> StepResult:
        return StepResult({"arm_a": np.full(6, 0.1), "arm_b": b.gravity_torques(obs.q["arm_b"])})

    run = _run(Episode(scene, drives, ctrl, Columns(), 0.2), tmp_path)
    df = run.trace
    for pre in ("a_", "b_"):
        assert {f"{pre}q1", f"{pre}qd6", f"{pre}u3", f"{pre}n_sat", f"{pre}dist_box",
                f"{pre}dist_min"} <= set(df.columns)
    assert "a_dist_arm_b" in df and "b_dist_arm_a" in df  # robots see each other...
    np.testing.assert_allclose(df["a_dist_arm_b"], df["b_dist_arm_a"], atol=1e-6)
    assert (df["a_dist_min"] == df["a_dist_box"]).all()  # ...but are not obstacles
    assert np.abs(_q(df, "b_") + Q0).max() < 1e-6  # b holds still under gravity compensation
    assert np.abs(_q(df, "a_")[-1] - Q0).max() > 0.015  # a moves (0.1 rad/s for 0.2 s)
    bodies = {b["name"]: b for b in json.loads((tmp_path / "scene.json").read_text())["bodies"]}
    assert bodies["arm_b"]["q_columns"][0] == "b_q1"
    assert bodies["arm_b"]["base_pose"]["position"] == [0.9, 0.0, 0.0]


def test_joint_groups_of_one_urdf_have_their_own_drives_columns_and_distances(
        tmp_path: Path) -> None:
    """pomares2011's layout: one URDF (PA-10 + mini-robot), the PA-10 under a velocity drive,
    the mini-robot under torque (gravity compensation), a camera every 5 control steps."""
    from repro.geometry import Rx
    from repro.sim.pa10 import (
        ALL_JOINTS,
        ALL_LIMITS,
        HAND_JOINTS,
        MINI_JOINTS,
        PA10_JOINTS,
        pa10_urdf_path,
    )
    from repro.sim.robot import JointGroup

    scene = _scene(tmp_path, 1e-3, 1e-3, render=True)
    chain = scene.add_urdf("pa10", pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS)
    q0 = np.r_[0.0, 0.3, 0.9, 0.0, 0.6, 0.0, 0.0, -0.3, 0.4, np.zeros(8)]  # + the hand
    chain.reset(q0)
    arm = scene.add_joint_group("pa10", "arm", PA10_JOINTS, "pa10_", owns_base=True)
    mini = scene.add_joint_group("pa10", "mini", MINI_JOINTS, "mini_")
    hand = scene.add_joint_group("pa10", "hand", HAND_JOINTS, "bh8_")  # no drive: observed
    assert isinstance(mini, JointGroup)
    assert set(arm.links).isdisjoint(mini.links) and -1 in arm.links and mini.links
    T_cam = chain.frame_pose("mini_camera_optical", q0)
    scene.add_dot_target("target", DotTarget.square(0.03, 0.005, (0.1, 0.1)),
                         T_cam @ trans(0, 0, 0.3) @ Rx(np.pi))
    # a box 15 cm to the side of the mini-robot's camera: nearer the mini-robot than the arm
    scene.add_box("box", (0.05, 0.05, 0.05), trans(*(T_cam[:3, 3] + 0.15 * T_cam[:3, 0])),
                  GREY, render=False)
    rig = CameraRig("camera", "s", Camera(Intrinsics.centered(320, 240, 300.0), mode="exact"),
                    chain, "mini_camera_optical", np.eye(4), "target", period=5)
    v = np.array([0.05, 0, 0, 0, 0, 0])

    def ctrl(obs: Observation) -> StepResult:
        assert obs.q["pa10"].shape == (17,) and obs.q["mini"].shape == (3,)
        # gravity compensation + a stiff joint PD: the mini-robot holds its pose while the
        # arm it sits on turns (a free joint would keep its absolute orientation instead)
        qm, qdm = obs.q["mini"], obs.qd["mini"]
        return StepResult({"arm": v, "mini": mini.gravity_torques() + 5.0 * (q0[6:9] - qm)
                           - 0.05 * qdm})

    run = _run(Episode(scene, {"arm": VelocityDrive(arm), "mini": TorqueDrive(mini)}, ctrl,
                       Columns(), 0.3, cameras=[rig]), tmp_path)
    df = run.trace
    assert {"pa10_q6", "mini_q3", "pa10_dist_box", "mini_dist_box", "mini_u3"} <= set(df.columns)
    assert "pa10_q7" not in df and "mini_q4" not in df
    assert df["mini_dist_box"].iloc[0] < df["pa10_dist_box"].iloc[0] - 0.01  # per group
    np.testing.assert_allclose(df["pa10_q1"].iloc[-1] - q0[0], 0.05 * 0.3, atol=2e-3)
    assert np.abs(df[["mini_q1", "mini_q2", "mini_q3"]].to_numpy() - q0[6:9]).max() < 0.02
    new = df["camera_new_frame"].to_numpy(bool)
    assert new[::5].all() and not new[1::5].any()
    held = df["s1_u"].to_numpy()
    assert np.all(held[1:5] == held[0]) and held[5] != held[0]  # held between frames
    body = json.loads((tmp_path / "scene.json").read_text())["bodies"][0]
    assert body["q_columns"] == ([f"pa10_q{i}" for i in range(1, 7)]
                                 + ["mini_q1", "mini_q2", "mini_q3"]
                                 + [f"bh8_q{i}" for i in range(1, 9)])
    assert [g["name"] for g in body["groups"]] == ["arm", "mini", "hand"]
    # the group without a drive: its joints and its distances logged by the runner, and no
    # command columns
    assert {"bh8_q8", "bh8_qd8", "bh8_dist_box", "bh8_dist_min"} <= set(df.columns)
    assert "bh8_u1" not in df and "bh8_n_sat" not in df
    assert df["bh8_q2"].iloc[0] == pytest.approx(q0[10], abs=1e-12)
    np.testing.assert_allclose(df[[f"bh8_q{i}" for i in range(1, 9)]].iloc[0], q0[9:],
                               atol=1e-12)
    assert len(hand.links) > 0 and np.isfinite(df["bh8_qd8"]).all()
    assert df["bh8_dist_box"].iloc[0] != df["mini_dist_box"].iloc[0]  # over its own links
    assert set(body["groups"][1]["links"]) == set(mini.links)


# ----------------------------------------------------------------------------- thinned rows
def _thinned(tmp: Path, log_every: int, duration: float = 0.1,  # type: ignore[no-untyped-def]
             extra_rows: tuple[int, ...] = ()):
    """A CRS-A465 held by gravity compensation, a box moving through a dip in its
    distance at t = 0.0425 s (between two 10 ms rows); the controller asks for a row at the
    steps ``extra_rows``."""
    scene = _scene(tmp)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    scene.add_box("box", (0.05, 0.05, 0.05), trans(1.0, 0, 0.3), GREY, moving=True)

    def box(t: float) -> np.ndarray:
        return trans(0.5 + 40.0 * (t - 0.0425) ** 2, 0.0, 0.3)

    def ctrl(obs: Observation) -> StepResult:
        return StepResult({"crs": robot.gravity_torques(obs.q["crs"])},
                          log_row=obs.step in extra_rows)

    ep = Episode(scene, {"crs": TorqueDrive(robot)}, ctrl, Columns(), duration,
                 movers={"box": box}, log_every=log_every)
    return _run(ep, tmp)


def test_controller_asks_for_rows_between_log_every_rows(tmp_path: Path) -> None:
    """StepResult.log_row: the steps the controller marks are rows too (a 30 Hz tick in a
    100 Hz log), and they are the full trace's rows at those steps."""
    full = _thinned(tmp_path / "full", 1)
    thin = _thinned(tmp_path / "thin", 10, extra_rows=(33, 66, 70))
    steps = sorted({*range(0, 101, 10), 33, 66})
    np.testing.assert_array_equal(thin.trace["step"], steps)
    merged = full.trace.set_index("step").loc[steps]
    np.testing.assert_array_equal(merged["q1"].to_numpy(), thin.trace["q1"].to_numpy())


def test_log_every_thins_rows_but_not_the_loop(tmp_path: Path) -> None:
    full = _thinned(tmp_path / "full", 1)
    thin = _thinned(tmp_path / "thin", 10)
    assert len(full.trace) == 101 and len(thin.trace) == 11
    np.testing.assert_array_equal(thin.trace["step"], np.arange(0, 101, 10))
    # the same simulation: the thinned rows are rows of the full trace
    merged = full.trace.set_index("step").loc[thin.trace["step"]]
    np.testing.assert_allclose(merged["q2"].to_numpy(), thin.trace["q2"].to_numpy(), atol=0)
    # the minimum between two rows is in the summary, at its step
    low = thin.manifest["summary"]["min_over_all_steps"]["dist_box"]
    assert low["t_s"] == pytest.approx(0.042, abs=1.5e-3)
    assert low["min_m"] == pytest.approx(full.trace["dist_box"].min(), abs=1e-12)
    assert low["min_m"] < thin.trace["dist_box"].min() - 1e-4
    assert thin.manifest["summary"]["log_every"] == 10
    assert thin.scene["trace_rows"]["log_every_control_steps"] == 10


def _passing(tmp: Path, log_every: int):  # type: ignore[no-untyped-def]
    """A held CRS-A465; a box and a two-part compound sweep past it, both touching it
    between two 10-step rows, then move away."""
    scene = _scene(tmp)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    scene.add_box("box", (0.05, 0.05, 0.05), trans(1.0, 0.0, 0.05), GREY, moving=True)
    scene.add_compound("pair", [Part("box", (0.04, 0.04, 0.04), trans(0.0, -0.05, 0.0)),
                                Part("box", (0.04, 0.04, 0.04), trans(0.0, 0.05, 0.0))],
                       trans(0.0, 1.0, 0.3), GREY, moving=True)

    def ctrl(obs: Observation) -> StepResult:
        return StepResult({"crs": robot.gravity_torques(obs.q["crs"])})

    movers = {"box": lambda t: trans(0.115 + 40.0 * (t - 0.0437) ** 2, 0.0, 0.05),
              "pair": lambda t: trans(0.0, 0.05 + 50.0 * (t - 0.061) ** 2, 0.3)}
    ep = Episode(scene, {"crs": TorqueDrive(robot)}, ctrl, Columns(), 0.1, movers=movers,
                 log_every=log_every)
    return _run(ep, tmp)


def test_steps_without_a_row_keep_every_minimum_and_event(tmp_path: Path) -> None:
    """Between rows the runner asks only for distances below their running minima
    (Scene.distance_table's ``below``): the minima over all steps (values and times), the
    collision events (their steps) and the rows are those of a run that logs every step."""
    full = _passing(tmp_path / "full", 1)
    thin = _passing(tmp_path / "thin", 10)
    assert (thin.manifest["summary"]["min_over_all_steps"]
            == full.manifest["summary"]["min_over_all_steps"])
    assert thin.events.to_dict("records") == full.events.to_dict("records")
    assert set(thin.events["kind"]) == {"collision"} and len(thin.events) == 2
    assert all(k % 10 for k in thin.events["step"])  # both touch between two rows
    merged = full.trace.set_index("step").loc[thin.trace["step"]]
    for col in ("dist_box", "dist_pair", "dist_min"):
        np.testing.assert_array_equal(merged[col].to_numpy(), thin.trace[col].to_numpy())


def test_log_every_keeps_the_last_step(tmp_path: Path) -> None:
    thin = _thinned(tmp_path, 7, duration=0.05)
    assert thin.trace["step"].tolist() == [0, 7, 14, 21, 28, 35, 42, 49, 50]


def _lazy(tmp: Path, log_every: int, stop_at: int | None = None):  # type: ignore[no-untyped-def]
    """Gravity compensation; the controller gives ``a`` eagerly and ``b``, ``c`` lazily
    (functions of the step), counting the lazy calls."""
    scene = _scene(tmp)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    calls: list[int] = []
    cols = Columns()
    for name in "abc":
        cols.add(name, "-", f"column {name}")

    def ctrl(obs: Observation) -> StepResult:
        k = obs.step

        def lazy() -> dict[str, float]:
            calls.append(k)
            return {"b": 2.0 * k, "c": float(obs.q["crs"][0])}

        stop = ("test_stop", "asked") if k == stop_at else None
        return StepResult({"crs": robot.gravity_torques(obs.q["crs"])}, {"a": float(k)},
                          stop=stop, lazy_columns=lazy)

    ep = Episode(scene, {"crs": TorqueDrive(robot)}, ctrl, cols, 0.05, log_every=log_every)
    return _run(ep, tmp), calls


def test_lazy_columns_are_computed_for_written_rows_only(tmp_path: Path) -> None:
    """StepResult.lazy_columns: called once per written row (a stop row too), never for a
    step without one; the trace equals the one with every row, column for column."""
    full, calls_full = _lazy(tmp_path / "full", 1)
    thin, calls_thin = _lazy(tmp_path / "thin", 10)
    assert calls_full == list(range(51))
    assert calls_thin == [0, 10, 20, 30, 40, 50] == thin.trace["step"].tolist()
    merged = full.trace.set_index("step").loc[thin.trace["step"]].reset_index()
    assert list(thin.trace.columns) == list(full.trace.columns)
    assert list(thin.trace.columns).index("c") == list(thin.trace.columns).index("a") + 2
    for c in ("a", "b", "c", "q1", "u1"):
        np.testing.assert_array_equal(merged[c].to_numpy(), thin.trace[c].to_numpy())
    np.testing.assert_array_equal(thin.trace["b"], 2.0 * thin.trace["step"])
    stopped, calls_stop = _lazy(tmp_path / "stop", 10, stop_at=23)
    assert calls_stop == [0, 10, 20, 23] == stopped.trace["step"].tolist()


@pytest.mark.parametrize("bad", [0, -1, 2.5])
def test_log_every_is_validated(tmp_path: Path, bad: object) -> None:
    scene = _scene(tmp_path)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    with pytest.raises(ConfigError, match="log_every"):
        Episode(scene, {"crs": TorqueDrive(robot)}, lambda o: StepResult({}), Columns(), 1.0,
                log_every=bad)  # type: ignore[arg-type]
    scene.close()


def test_touching_an_obstacle_is_a_collision_and_a_grasped_body_a_contact(
        tmp_path: Path) -> None:
    """Both boxes overlap the robot's base: the obstacle gives a ``collision`` event and
    ``collided_*``, the body with obstacle = false a ``contact`` event and ``touched_*``."""
    scene = _scene(tmp_path)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    scene.add_box("wall", (0.05, 0.05, 0.05), trans(0.0, 0.0, 0.05), GREY)
    scene.add_compound("part", [Part("box", (0.05, 0.05, 0.05))], trans(0.0, 0.0, 0.06), GREY,
                       obstacle=False)

    def ctrl(obs: Observation) -> StepResult:
        return StepResult({"crs": robot.gravity_torques(obs.q["crs"])})

    run = _run(Episode(scene, {"crs": TorqueDrive(robot)}, ctrl, Columns(), 0.01), tmp_path)
    kinds = dict(zip(run.events["detail"].str.split().str[2], run.events["kind"], strict=True))
    assert kinds == {"wall": "collision", "part": "contact"}, run.events
    assert run.manifest["summary"]["collided_wall"] is True
    assert run.manifest["summary"]["touched_part"] is True
    assert "collided_part" not in run.manifest["summary"]


def test_a_dynamic_body_falls_and_its_logged_pose_follows(tmp_path: Path) -> None:
    """Scene.add_dynamic: a free sphere dropped from 0.5 m falls under gravity (its pose
    columns follow the simulation: z = 0.5 - g t^2 / 2 before it lands), scene.json states its
    mass and dynamics, and an unknown dynamics keyword is refused."""
    scene = _scene(tmp_path)
    robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
    robot.reset(Q0)
    scene.add_dynamic("ball", Part("sphere", (0.02,)), 0.1, trans(1.0, 1.0, 0.5), GREY,
                      {"lateralFriction": 0.8, "restitution": 0.0})
    with pytest.raises(ConfigError, match="dynamics keyword"):
        scene.add_dynamic("bad", Part("sphere", (0.02,)), 0.1, trans(2.0, 1.0, 0.5), GREY,
                          {"bounciness": 1.0})
    with pytest.raises(ConfigError, match="mass"):
        scene.add_dynamic("bad", Part("sphere", (0.02,)), 0.0, trans(2.0, 1.0, 0.5), GREY)

    def ctrl(obs: Observation) -> StepResult:
        return StepResult({"crs": robot.gravity_torques(obs.q["crs"])})

    run = _run(Episode(scene, {"crs": TorqueDrive(robot)}, ctrl, Columns(), 0.2), tmp_path)
    t, z = run.trace["t"].to_numpy(), run.trace["ball_z"].to_numpy()
    np.testing.assert_allclose(z, 0.5 - 9.81 * t**2 / 2, atol=2e-3)
    ball = next(b for b in run.scene["bodies"] if b["name"] == "ball")
    assert ball["dynamic"]["mass"] == 0.1 and ball["dynamic"]["lateralFriction"] == 0.8
    assert ball["pose_columns"][2] == "ball_z"


def test_a_dot_seen_edge_on_is_reported_not_detectable() -> None:
    """Issue 38: a missed dot seen within a fraction of a degree of edge-on is named so (its
    image is under DETECTABLE_MINOR_AXIS_PX across), not 'visible, grazing'; one seen
    from behind or well in view keeps its own cause."""
    from repro.sim.episode import _why_missed

    n = np.array([0.0, 0.0, 1.0])
    P = np.zeros(3)
    grazing = np.array([0.0, -0.3, 0.3 * math.cos(math.radians(89.6))])
    got = _why_missed(True, False, grazing, P, n, minor_px=0.17)
    assert got.startswith("seen edge-on (89.6 deg") and "not detectable" in got
    assert "grazing" in _why_missed(True, True, grazing, P, n, minor_px=1.5)
    assert _why_missed(True, False, np.array([0.0, 0.0, -0.3]), P, n, 0.0).startswith(
        "seen from behind")
    assert _why_missed(True, False, np.array([0.0, 0.0, 0.3]), P, n, 24.0).startswith(
        "occluded")
