"""Audit of the VVS pose estimate from a cold start (pomares2011 Sec. 5.1, claim 3).

In experiments 1-2 every VVS (22)-(24) is warm-started from the previous frame's pose (the
first from a PnP pose), so the estimate never has to cancel a large error (issue 18). Here
the camera of experiment 1 renders the part at configurations along the approach (the
joint-space segment from the start to the goal), the four dots are detected as in the run,
and the VVS starts from the true object pose moved by a fixed translation and rotation in
random directions. One trace row per start.

The reference of each frame is the VVS started at the true pose (the least-squares pose of
these detections, which differs from the truth by the detection noise): a cold start that
ends elsewhere has found another stationary point.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from experiments.pomares2011 import scene as sc
from repro.config import param, validate
from repro.errors import ConfigError
from repro.geometry import inv_T
from repro.runs.columns import COLUMNS_FILE, Columns
from repro.runs.trace import TraceRecorder
from repro.sensors.camera import Camera
from repro.sim.episode import _camera_json
from repro.sim.pa10 import ALL_JOINTS
from repro.sim.scene import Scene
from repro.sim.world import WorldConfig
from repro.vision.vvs import project_normalized, se3_exp, vvs_pose


@dataclass(frozen=True)
class VVSColdConfig:
    """Cold starts of the VVS on rendered frames of experiment 1's camera."""

    # ours: issue 18 asks for a start >= 2 cm / 10 deg off (a part placed by hand, a rough
    # first guess); 5 cm / 20 deg and 10 cm / 30 deg show where the basin ends
    offsets_m: tuple[float, ...] = param((0.02, 0.05, 0.10), unit="m", range=(0.0, 0.5),
                                         help="translation of each start from the true pose")
    offsets_deg: tuple[float, ...] = param((10.0, 20.0, 30.0), unit="deg", range=(0.0, 90.0),
                                           help="rotation of each start (paired with "
                                                "offsets_m)")
    # ours: the start, the middle and the goal of the approach
    fractions: tuple[float, ...] = param((0.0, 0.5, 1.0), range=(0.0, 1.0),
                                         help="configurations q_start + f (q_goal - q_start)")
    n_starts: int = param(40, range=(1, 10000),
                          help="random directions per offset and configuration")  # ours
    camera_mode: str = param("render", choices=("render", "exact"),
                             help="rendered + detected dots, or exact projections")
    seed: int = param(0, range=(0, 2**32 - 1), help="seed of the directions (32-bit)")


def check_config(config: VVSColdConfig) -> None:
    validate(config)
    if len(config.offsets_m) != len(config.offsets_deg) or not config.offsets_m:
        raise ConfigError(f"offsets_m {config.offsets_m} and offsets_deg {config.offsets_deg} "
                          "must be non-empty and pair up")
    if not config.fractions:
        raise ConfigError("fractions must not be empty")


def perturbed(T: np.ndarray, offset_m: float, offset_deg: float,
              rng: np.random.Generator) -> np.ndarray:
    """``T`` (object in camera) moved by exactly ``offset_m`` [m] along a random direction of
    the camera frame and turned by exactly ``offset_deg`` [deg] about a random axis through
    the object's origin."""
    u = rng.normal(size=3)
    a = rng.normal(size=3)
    u, a = u / np.linalg.norm(u), a / np.linalg.norm(a)
    R = se3_exp(np.r_[0.0, 0.0, 0.0, np.radians(offset_deg) * a])[:3, :3]
    out = T.copy()
    out[:3, :3] = R @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + offset_m * u
    return out


def pose_errors(T: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """(position error [m], rotation angle [deg]) of ``T`` against ``T_ref``."""
    c = 0.5 * (np.trace(T[:3, :3].T @ T_ref[:3, :3]) - 1.0)
    return (float(np.linalg.norm(T[:3, 3] - T_ref[:3, 3])),
            float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))))


def _reprojection_px(T: np.ndarray, uv: np.ndarray) -> float:
    xy, Z = project_normalized(sc.POINTS_P, T)
    if np.any(Z <= 0):
        return float("inf")
    K = sc.INTRINSICS
    pix = np.column_stack([K.fu * xy[:, 0] + K.u0, K.fv * xy[:, 1] + K.v0])
    return float(np.sqrt(np.mean(np.sum((pix - uv) ** 2, axis=1))))


def _columns() -> Columns:
    cols = Columns()
    cols.add("start", "-", "start index")
    cols.add("frame", "-", "configuration index (fractions[frame])")
    cols.add("fraction", "-", "the configuration q_start + fraction (q_goal - q_start)")
    cols.add("offset_m", "m", "translation of the start from the true pose (camera frame)")
    cols.add("offset_deg", "deg", "rotation of the start from the true pose")
    cols.add("init_pos_err_m", "m", "audit: position error of the start vs the true pose",
             audit=True)
    cols.add("init_rot_err_deg", "deg", "audit: rotation error of the start", audit=True)
    cols.add("init_residual_px", "px", "RMS reprojection error of the dots at the start")
    cols.add("iterations", "-", "VVS pose updates (pomares2011 (22)-(24), ViSP's stop rule)")
    cols.add("converged", "bool", "the VVS met its stopping rule within max_iter, every "
             "point in front of the camera")
    cols.add("residual_px", "px", "final RMS reprojection error (e_v in pixels)")
    cols.add("pos_err_m", "m", "audit: final position error vs the true object pose "
             "(camera frame)", audit=True)
    cols.add("rot_err_deg", "deg", "audit: final rotation error vs the true pose", audit=True)
    cols.add("to_warm_m", "m", "final position distance to the VVS started at the true pose "
             "(the least-squares pose of the same detections)")
    cols.add("warm_residual_px", "px", "final RMS reprojection error of that warm start")
    cols.add("warm_pos_err_m", "m", "audit: that warm start's position error vs the true pose "
             "(the detection noise's share)", audit=True)
    cols.add("det{i}_u", "px", "detected u of dot {i} in this frame", n=4)
    cols.add("det{i}_v", "px", "detected v of dot {i} in this frame", n=4)
    cols.add("q{i}", "rad", "joint {i} (scene.json's robot joints order) of this frame", n=17)
    return cols


def run(config: VVSColdConfig, out_dir: Path, experiment: str | None = None) -> Path:
    """Render each configuration's frame, detect the dots, run the VVS from every start."""
    check_config(config)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cols = _columns()
    render = config.camera_mode == "render"
    with TraceRecorder(out_dir, experiment=experiment or out_dir.name.split("__")[0],
                       paper="pomares2011", config=config, seed=config.seed) as rec, \
            Scene(WorldConfig(), render=render, run_dir=out_dir) as scene:
        chain, _ = sc.build_scene(scene, sc.LAYOUT.q_start)
        scene.add_mount("camera", "pa10", "mini_camera_optical", np.eye(4),
                        "the mini-robot camera (x right, y down, z forward)")
        camera = Camera(sc.INTRINSICS, mode=config.camera_mode)
        desc = scene.describe()
        robot = next(b for b in desc["bodies"] if b["kind"] == "urdf")
        robot["q_columns"] = []  # no time axis: each row's joints are its q1..q17 columns
        desc["cameras"] = {"camera": {"robot": "pa10", "frame": "mini_camera_optical",
                                      "T_frame_camera": "identity", "target": "dots",
                                      "mode": config.camera_mode, **_camera_json(camera)}}
        desc.update(columns_file=COLUMNS_FILE, points_object=sc.POINTS_P,
                    note="no time axis: one trace row per VVS start; the robot is at the "
                         "row's q1..q17 (ALL_JOINTS order), the camera renders the dots "
                         "there; points_object are the dots in the part's frame [m]")
        rec.set_scene(desc)
        rng = np.random.default_rng(config.seed)
        q0, q1 = np.asarray(sc.LAYOUT.q_start, float), np.asarray(sc.LAYOUT.q_goal, float)
        body = scene["dots"]
        assert body.dot_target is not None
        i = 0
        for f_idx, frac in enumerate(config.fractions):
            q = q0 + frac * (q1 - q0)
            chain.reset(q)
            T_wc = chain.frame_pose("mini_camera_optical", q)
            uv, found, _ = camera.measure(scene.render_client, T_wc, body.dot_target,
                                          body.T_world)
            if not found.all():
                rec.event(0.0, f_idx, "feature_lost", f"frame {f_idx} (fraction {frac}): "
                          f"dots {(np.flatnonzero(~found) + 1).tolist()} not detected; no "
                          "starts from it")
                continue
            T_true = inv_T(T_wc) @ sc.OBJECT.T_world
            warm = vvs_pose(sc.POINTS_P, uv, sc.INTRINSICS, T_true)
            for off_m, off_deg in zip(config.offsets_m, config.offsets_deg, strict=True):
                for _ in range(config.n_starts):
                    T0 = perturbed(T_true, off_m, off_deg, rng)
                    res = vvs_pose(sc.POINTS_P, uv, sc.INTRINSICS, T0)
                    e0 = pose_errors(T0, T_true)
                    e = pose_errors(res.T_cam_obj, T_true)
                    row: dict[str, float | int | bool | str] = {
                        "start": i, "frame": f_idx, "fraction": frac, "offset_m": off_m,
                        "offset_deg": off_deg, "init_pos_err_m": e0[0],
                        "init_rot_err_deg": e0[1], "init_residual_px": _reprojection_px(T0, uv),
                        "iterations": res.iterations, "converged": res.converged,
                        "residual_px": res.residual_px, "pos_err_m": e[0], "rot_err_deg": e[1],
                        "to_warm_m": float(np.linalg.norm(res.T_cam_obj[:3, 3]
                                                          - warm.T_cam_obj[:3, 3])),
                        "warm_residual_px": warm.residual_px,
                        "warm_pos_err_m": pose_errors(warm.T_cam_obj, T_true)[0]}
                    for j in range(4):
                        row[f"det{j + 1}_u"], row[f"det{j + 1}_v"] = uv[j]
                    for j in range(len(ALL_JOINTS)):
                        row[f"q{j + 1}"] = float(q[j])
                    if i == 0:
                        cols.write(out_dir / COLUMNS_FILE, row)
                    rec.record(row)
                    i += 1
        if i == 0:
            rec.close("failed", "no configuration showed the four dots")
            return out_dir
        rec.close("completed", f"{i} VVS starts on {len(config.fractions)} frames")
    return out_dir
