"""The external view of a replay, framed from the run's own bodies (issue 20).

:func:`auto_view` looks at the bounding box of the robots' links and the bodies near them
over the run, over the robot's shoulder (no paper prescribes a view); :func:`frame_rows`
picks the trace row each video frame shows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import pybullet as p

from repro.replay.world import ReplayWorld

REACH_M = 1.5  # ours: bodies farther than this from every robot link are not framed
EXTERNAL_FOV_DEG = 50.0


@dataclass(frozen=True)
class ExternalView:
    """A look-at camera for the external view: eye and target [m], vertical FOV [deg]."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    fov_deg: float = EXTERNAL_FOV_DEG

    def matrices(self, width: int, height: int) -> tuple[list[float], list[float]]:
        view = p.computeViewMatrix(list(self.eye), list(self.target), [0.0, 0.0, 1.0])
        dist = float(np.linalg.norm(np.subtract(self.eye, self.target)))
        proj = p.computeProjectionMatrixFOV(self.fov_deg, width / height, 0.02,
                                            max(5.0, 4.0 * dist))
        return list(view), list(proj)


def auto_view(world: ReplayWorld, trace: pd.DataFrame, n_rows: int = 7, turn_deg: float = 215.0,
              pitch_deg: float = 40.0) -> ExternalView:
    """Frame the robots' links and the bodies within :data:`REACH_M` of them over the run.

    The eye looks at the centre of their bounding box, from ``turn_deg`` about the vertical
    away from the direction robots -> bodies (215 deg: behind the robot, over its shoulder)
    and ``pitch_deg`` above the horizontal, at the distance where the box's half-diagonal
    fills 0.95 of the half field of view (ours: chosen on a contact sheet of every paper's
    runs, the one where neither the robot nor its obstacles hide the other)."""
    links, bodies = [], []
    for k in np.linspace(0, len(trace) - 1, min(n_rows, len(trace))).round().astype(int):
        world.set_row(trace.iloc[int(k)])
        links.append(world.link_positions())
        bodies.append(world.body_positions())
    robot, other = np.vstack(links), np.vstack(bodies)
    if len(other) and len(robot):
        near = np.min(np.linalg.norm(other[:, None] - robot[None], axis=2), axis=1) < REACH_M
        other = other[near]
    pts = np.vstack([robot, other]) if len(robot) else other
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    target = (lo + hi) / 2.0
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.15)
    base = robot.mean(axis=0) if len(robot) else target
    work = other.mean(axis=0) if len(other) else target + [1.0, 0.0, 0.0]
    d = (work - base)[:2]
    d = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-3 else np.array([1.0, 0.0])
    yaw = np.radians(turn_deg)
    d = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]) @ d
    pitch = np.radians(pitch_deg)
    dist = 0.95 * radius / np.tan(np.radians(EXTERNAL_FOV_DEG) / 2.0)
    eye = target + dist * np.array([np.cos(pitch) * d[0], np.cos(pitch) * d[1], np.sin(pitch)])
    return ExternalView((float(eye[0]), float(eye[1]), float(eye[2])),
                        (float(target[0]), float(target[1]), float(target[2])))


def frame_rows(t: np.ndarray, fps: float, speed: float) -> list[int]:
    """The trace row shown in each video frame: the last row at or before the frame's time."""
    times = np.arange(t[0], t[-1] + 1e-9, speed / fps)
    rows = np.searchsorted(t, times + 1e-9, side="right") - 1
    return [int(r) for r in np.clip(rows, 0, len(t) - 1)]
