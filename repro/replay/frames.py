"""Frames of a replay: the external view, each camera's view with its features, a caption.

See :mod:`repro.replay.video` for what a frame shows; nothing of the experiment's code is
used, only the run folder's files.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd

from repro.errors import ConfigError
from repro.replay.view import auto_view
from repro.replay.world import ReplayWorld, camera_view_matrix, matrix, pose_of

FPS = 20  # ours: smooth enough for arm motion, half the frames of 40 fps
SIZE = (960, 480)  # ours: a 640 x 480 external view beside a 320-px column
RUN_FILES = ("scene.json", "trace.csv", "manifest.json")
GREEN, RED, WHITE, GREY = (0, 200, 0), (230, 0, 0), (235, 235, 235), (150, 150, 150)
BACKGROUND = (206, 214, 224)


def check_run_dir(run_dir: Path) -> pd.DataFrame:
    """The run's trace; a clear error (nothing written) if ``run_dir`` is not a replayable run."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ConfigError(f"{run_dir} is not a folder; give a run folder (results/<paper>/<exp>)")
    missing = [f for f in RUN_FILES if not (run_dir / f).is_file()]
    if missing:
        raise ConfigError(f"{run_dir} is not a run folder: it has no {', '.join(missing)} "
                          "(a run writes trace.csv, columns.json, events.csv, manifest.json and "
                          "scene.json)")
    trace = pd.read_csv(run_dir / "trace.csv")
    if "t" not in trace.columns or len(trace) == 0:
        raise ConfigError(f"{run_dir}: trace.csv has no time column 't' (or no row): nothing to "
                          "replay over time (e.g. an audit of random configurations)")
    return trace


def check_options(fps: float = FPS, size: tuple[int, int] = SIZE,
                  speed: float | None = None) -> None:
    """A clear error for a frame rate, size or speed no video can have."""
    if not (np.isfinite(fps) and 1 <= fps <= 60):
        raise ConfigError(f"--fps must be in [1, 60], got {fps}")
    w, h = size
    if w % 16 or h % 16 or w < 320 or h < 240 or w > 3840 or h > 2160:
        raise ConfigError(f"--size must be 320x240 to 3840x2160 with both sides multiples of "
                          f"16 (H.264 macro blocks), got {w}x{h}")
    if speed is not None and not (np.isfinite(speed) and speed > 0):
        raise ConfigError(f"--speed must be a positive number, got {speed}")


def _features(row: pd.Series, prefix: str) -> list[tuple[float, float, float, float, bool]]:
    """(u_true, v_true, u, v, found) of each feature ``<prefix><i>`` in the row [px]."""
    out, i = [], 1
    while f"{prefix}{i}_u_true" in row.index:
        found = bool(row.get(f"{prefix}{i}_found", True)) and np.isfinite(row.get(
            f"{prefix}{i}_u", np.nan))
        out.append((float(row[f"{prefix}{i}_u_true"]), float(row[f"{prefix}{i}_v_true"]),
                    float(row.get(f"{prefix}{i}_u", np.nan)),
                    float(row.get(f"{prefix}{i}_v", np.nan)), found))
        i += 1
    return out


class Replayer:
    """Frames of one run (see the module docstring); :meth:`frame` is frame ``k``'s image."""

    def __init__(self, run_dir: Path, size: tuple[int, int] = SIZE) -> None:
        self.dir = Path(run_dir)
        self.trace = check_run_dir(self.dir)
        check_options(size=size)
        self.width, self.height = size
        ev = self.dir / "events.csv"
        self.events = pd.read_csv(ev) if ev.is_file() else pd.DataFrame(
            columns=["t", "kind", "detail"])
        self.manifest: dict[str, Any] = json.loads((self.dir / "manifest.json").read_text())
        self.world = ReplayWorld(self.dir)
        self.cams = self.world.scene.get("cameras", {})
        self.cam_world: ReplayWorld | None = None
        try:
            if self.cams:
                self.cam_world = ReplayWorld(self.dir, camera_only=True)
            self.view = auto_view(self.world, self.trace)
        except BaseException:
            self.close()
            raise
        self.col_w = self.width // 3
        self.ext_w = self.width - self.col_w

    def close(self) -> None:
        self.world.close()
        if self.cam_world is not None:
            self.cam_world.close()

    def __enter__(self) -> Replayer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def camera_pose(self, name: str, row: pd.Series) -> np.ndarray:
        """T_world_camera [m]: the logged pose if the trace has it, else the camera frame's."""
        cols = [f"{name}_{a}" for a in ("x", "y", "z", "qx", "qy", "qz", "qw")]
        if all(c in row.index for c in cols) and np.all(np.isfinite(row[cols].to_numpy(float))):
            v = row[cols].to_numpy(float)
            return matrix((list(v[:3]), list(v[3:])))
        cam = self.cams[name]
        self.world.set_row(row)  # the camera's frame at this row, not at the last one drawn
        frame = self.world.frame_pose(cam["robot"], cam["frame"])
        return matrix(frame) @ matrix(pose_of(cam["T_frame_camera"]))

    def external(self, row: pd.Series) -> np.ndarray:
        self.world.set_row(row)
        view, proj = self.view.matrices(self.ext_w, self.height)
        img, seg = self.world.render(view, proj, self.ext_w, self.height, segmentation=True)
        assert seg is not None
        img[seg < 0] = BACKGROUND
        return img

    def camera_image(self, name: str, row: pd.Series) -> tuple[np.ndarray, float]:
        """(the camera's view at the column's width, its scale: panel px per image px)."""
        assert self.cam_world is not None
        cam = self.cams[name]
        k = cam["intrinsics"]
        w = self.col_w
        h = int(round(w * k["height"] / k["width"]))
        self.cam_world.set_row(row)
        img, _ = self.cam_world.render(camera_view_matrix(self.camera_pose(name, row)),
                                       list(cam["projection_matrix_gl"]), w, h)
        return img, w / k["width"]

    def camera(self, name: str, row: pd.Series) -> np.ndarray:
        """The camera's view at the column's width, with true and detected features."""
        cam = self.cams[name]
        img, s = self.camera_image(name, row)  # s: pixel (u, v) of the run's image -> panel
        for ut, vt, u, v, found in _features(row, cam["feature_prefix"]):
            if np.isfinite(ut) and np.isfinite(vt):
                cv2.circle(img, (int(round(ut * s)), int(round(vt * s))), 6, GREEN, 1,
                           cv2.LINE_AA)
            if found:
                c = (int(round(u * s)), int(round(v * s)))
                cv2.drawMarker(img, c, RED, cv2.MARKER_CROSS, 9, 1, cv2.LINE_AA)
        label = f"{name} ({cam['mode']})"
        (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.38, 1)
        cv2.rectangle(img, (0, 0), (tw + 8, th + 8), (40, 40, 40), -1)  # legible on any scene
        cv2.putText(img, label, (4, th + 3), cv2.FONT_HERSHEY_SIMPLEX, 0.38, WHITE, 1,
                    cv2.LINE_AA)
        return img

    def caption(self, row: pd.Series, speed: float, height: int) -> np.ndarray:
        """Time, speed, phase, the legend and the latest events (white on dark grey)."""
        img = np.full((height, self.col_w, 3), 40, np.uint8)
        t = float(row["t"])
        lines = [(f"{self.manifest.get('paper', '')} {self.manifest.get('experiment', '')}",
                  WHITE), (f"t = {t:6.2f} s   (x{speed:.2g} speed)", WHITE)]
        if "phase" in row.index:
            lines.append((f"phase: {row['phase']}", WHITE))
        if self.cams:
            lines.append(("green ring: true, red cross: detected", GREY))
        past = self.events[self.events["t"] <= t + 1e-9].tail(6)
        for _, e in past.iloc[::-1].iterrows():
            lines.append((f"{float(e['t']):.2f} s {e['kind']}", WHITE))
            lines.append((f"  {str(e.get('detail', ''))[:46]}", GREY))
        y = 16
        for text, colour in lines:
            if y > height - 4:
                break
            cv2.putText(img, text, (6, y), cv2.FONT_HERSHEY_SIMPLEX, 0.36, colour, 1,
                        cv2.LINE_AA)
            y += 15
        return img

    def frame(self, row_index: int, speed: float = 1.0) -> np.ndarray:
        """The composed (height, width, 3) RGB frame of trace row ``row_index``."""
        row = self.trace.iloc[row_index]
        column = [self.camera(name, row) for name in self.cams]
        used = sum(c.shape[0] for c in column)
        column.append(self.caption(row, speed, max(self.height - used, 0)))
        right = np.vstack(column)[: self.height]
        if right.shape[0] < self.height:
            right = np.vstack([right, np.zeros((self.height - right.shape[0], self.col_w, 3),
                                               np.uint8)])
        return np.hstack([self.external(row), right])
