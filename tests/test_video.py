"""Issue 20: ``repro video`` replays a run from its own files into an MP4.

The replayed frames are checked against the trace they come from: the eye-in-hand view,
rendered at the logged camera pose, shows each dot where the run logged its true
projection; the external view shows the robot where the logged camera pose (on the robot)
projects. Each check has a negative control (another row's numbers) that it must fail.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import imageio.v2 as imageio
import numpy as np
import pybullet as p
import pytest

from repro.cli import main
from repro.replay import video
from repro.replay.video import Replayer, frame_rows, write_video

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"
#: Centroid of a dot's pixels in the half-size camera panel vs its logged true projection,
#: in the run's pixels: measured 0.47-1.07 px on thomas2024 case 1 (7 rows, 4 dots); a
#: panel pixel is 2 image pixels, so 2 px.
DOT_TOL_PX = 2.0
#: Nearest robot pixel of the external view to the logged camera position's projection:
#: measured 0.1-1.0 px (chan2011 experiment, pomares2011 exp2, thomas2024 case 3, 7 rows
#: each); the camera sits on the wrist's surface.
ROBOT_TOL_PX = 3.0


def _hue_centroid(img: np.ndarray, rgb: list[int]) -> tuple[float, float]:
    """(u, v) centroid [panel px] of the saturated pixels with ``rgb``'s hue (+-20 deg)."""
    hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV).astype(int)
    want = int(cv2.cvtColor(np.uint8([[rgb]]), cv2.COLOR_RGB2HSV)[0, 0, 0])
    dh = np.abs(hsv[:, :, 0] - want)
    mask = (np.minimum(dh, 180 - dh) < 10) & (hsv[:, :, 1] > 120) & (hsv[:, :, 2] > 60)
    vv, uu = np.nonzero(mask)
    assert len(uu) >= 4, f"no pixel of colour {rgb}"
    return float(uu.mean()), float(vv.mean())


def test_the_camera_view_shows_each_dot_at_its_logged_true_projection() -> None:
    run = RESULTS / "thomas2024" / "case1"
    with Replayer(run) as rep:
        cam = rep.cams["camera"]
        colours = rep.world.bodies[cam["target"]]["colors_rgb255"]
        rows = [0, len(rep.trace) // 2, len(rep.trace) - 1]
        for k in rows:
            row = rep.trace.iloc[k]
            img, s = rep.camera_image("camera", row)
            for i, rgb in enumerate(colours, start=1):
                u, v = _hue_centroid(img, rgb)
                u, v = (u + 0.5) / s - 0.5, (v + 0.5) / s - 0.5  # panel -> image pixels
                err = np.hypot(u - row[f"s{i}_u_true"], v - row[f"s{i}_v_true"])
                assert err < DOT_TOL_PX, (k, i, err)
        # negative control: the last frame's dots are not where row 0 logged them
        row0, last = rep.trace.iloc[0], rep.trace.iloc[rows[-1]]
        img, s = rep.camera_image("camera", last)
        u, v = _hue_centroid(img, colours[0])
        assert np.hypot((u + 0.5) / s - 0.5 - row0["s1_u_true"],
                        (v + 0.5) / s - 0.5 - row0["s1_v_true"]) > 10 * DOT_TOL_PX


def _project(view: list[float], proj: list[float], point: np.ndarray, w: int, h: int
             ) -> np.ndarray:
    """Pixel (column, row) of a world point through column-major GL matrices."""
    V = np.asarray(view).reshape(4, 4).T
    P = np.asarray(proj).reshape(4, 4).T
    c = P @ V @ np.append(point, 1.0)
    ndc = c[:3] / c[3]
    return np.array([(ndc[0] + 1) / 2 * w, (1 - ndc[1]) / 2 * h])


def test_the_external_view_shows_the_robot_where_the_trace_puts_its_camera() -> None:
    run = RESULTS / "chan2011" / "experiment"
    with Replayer(run) as rep:
        robot = rep.world.ids[rep.cams["camera"]["robot"]][0][0]
        w, h = rep.ext_w, rep.height
        view, proj = rep.view.matrices(w, h)
        rows = [0, len(rep.trace) // 2, len(rep.trace) - 1]
        pix = {}
        for k in rows:
            row = rep.trace.iloc[k]
            rep.world.set_row(row)
            seg = np.reshape(p.getCameraImage(w, h, view, proj, renderer=p.ER_TINY_RENDERER,
                                              physicsClientId=rep.world.client)[4], (h, w))
            vv, uu = np.nonzero(seg == robot)
            pix[k] = np.c_[uu, vv]
            cam = row[["camera_x", "camera_y", "camera_z"]].to_numpy(float)
            uv = _project(view, proj, cam, w, h)
            assert 0 <= uv[0] < w and 0 <= uv[1] < h, uv
            near = np.min(np.linalg.norm(pix[k] - uv, axis=1))
            assert near <= ROBOT_TOL_PX, (k, near)
        # negative control: the robot of row 0 is not where the last row's camera projects
        cam = rep.trace.iloc[rows[-1]][["camera_x", "camera_y", "camera_z"]].to_numpy(float)
        uv = _project(view, proj, cam, w, h)
        assert np.min(np.linalg.norm(pix[0] - uv, axis=1)) > 3 * ROBOT_TOL_PX


def test_frames_take_the_last_row_at_or_before_their_time() -> None:
    t = np.arange(0.0, 1.0001, 0.1)  # 11 rows, 10 Hz
    assert frame_rows(t, fps=5, speed=1.0) == [0, 2, 4, 6, 8, 10]
    assert frame_rows(t, fps=20, speed=1.0)[:4] == [0, 0, 1, 1]  # a row held for 2 frames
    assert frame_rows(t, fps=5, speed=2.0) == [0, 4, 8]


def test_a_short_run_is_written_in_slow_motion_at_the_asked_size(tmp_path: Path) -> None:
    out = tmp_path / "v" / "ibvs.mp4"
    assert main(["video", str(RESULTS / "chan2011" / "ibvs"), "--out", str(out), "--fps", "5",
                 "--size", "640x320"]) == 0
    with imageio.get_reader(out) as reader:
        n = reader.count_frames()
        first = reader.get_data(0)
    assert abs(n - video.MIN_VIDEO_S * 5) <= 1  # a 0.13 s run lasts MIN_VIDEO_S
    assert first.shape == (320, 640, 3)
    assert not list(out.parent.glob("*.partial.mp4"))


@pytest.mark.parametrize("args, message", [
    (["results/chan2011"], "is not a run folder"),
    (["results/chan2011/dcc_audit"], "no time column"),
    (["results/chan2011/ibvs", "--size", "100x100"], "--size"),
    (["results/chan2011/ibvs", "--fps", "nan"], "--fps"),
    (["results/chan2011/ibvs", "--speed", "-1"], "--speed"),
    ([], "either RUN_DIR or --all"),
])
def test_bad_input_is_refused_before_anything_is_written(
        args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["video", *[str(ROOT / a) if a.startswith("results") else a for a in args]]
    out = tmp_path / "x.mp4"
    assert main([*argv, "--out", str(out)] if args else argv) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_killed_replay_leaves_no_video(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                         ) -> None:
    calls = {"n": 0}
    frame = Replayer.frame

    def dying(self: Replayer, k: int, speed: float = 1.0) -> np.ndarray:
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return frame(self, k, speed)

    monkeypatch.setattr(Replayer, "frame", dying)
    with pytest.raises(KeyboardInterrupt):
        write_video(RESULTS / "chan2011" / "ibvs", tmp_path / "v.mp4", fps=2)
    assert not list(tmp_path.iterdir())


def test_all_writes_one_video_per_canonical_run_with_a_time_axis(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    results = tmp_path / "results"
    for name in ("ibvs", "dcc_audit"):
        shutil.copytree(RESULTS / "chan2011" / name, results / "chan2011" / name)
    figures = tmp_path / "figures"
    assert main(["video", "--all", "--paper", "chan2011", "--fps", "2", "--results",
                 str(results), "--figures", str(figures)]) == 0
    said = capsys.readouterr().out
    assert [f.name for f in (figures / "chan2011" / "videos").iterdir()] == ["ibvs.mp4"]
    assert "chan2011.dcc_audit: no video" in said and "chan2011.experiment: no video" in said


@pytest.mark.parametrize("run", ["thomas2024/case1", "chan2011/experiment", "pomares2011/exp2"])
def test_the_camera_frame_rebuilt_from_the_joints_is_the_logged_camera_pose(run: str) -> None:
    """Without the logged pose columns the camera pose comes from the URDF joints and the
    scene's mount: the same pose (to 1e-6 m / rad; the trace logs 1e-9 m digits)."""
    with Replayer(RESULTS / run) as rep:
        name = next(iter(rep.cams))
        pose_cols = [f"{name}_{a}" for a in ("x", "y", "z", "qx", "qy", "qz", "qw")]
        for k in (len(rep.trace) - 1, 0):  # the last row first: no state left from row 0
            row = rep.trace.iloc[k]
            logged = rep.camera_pose(name, row)
            rebuilt = rep.camera_pose(name, row.drop(pose_cols))
            np.testing.assert_allclose(rebuilt, logged, atol=1e-6)
        # and it is a real comparison: the camera moved between the rows
        assert np.linalg.norm(rep.camera_pose(name, rep.trace.iloc[0])[:3, 3]
                              - rep.camera_pose(name, rep.trace.iloc[-1])[:3, 3]) > 0.05
