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


#: (turn, pitch) [deg] tried by :func:`auto_view`, in order of preference: the turn about
#: the vertical away from the direction robots -> bodies (180: behind the robot).
CANDIDATES = ((215.0, 40.0), (145.0, 40.0), (215.0, 60.0), (145.0, 60.0), (90.0, 35.0),
              (270.0, 35.0), (35.0, 35.0))
SCORE_SIZE = (160, 120)  # [px] the small renders that score a candidate
PREFER = 0.9  # ours: the first candidate within 10 % of the best score wins (near ties)


def _look(target: np.ndarray, d: np.ndarray, dist: float, turn_deg: float, pitch_deg: float
          ) -> ExternalView:
    yaw, pitch = np.radians(turn_deg), np.radians(pitch_deg)
    d = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]) @ d
    eye = target + dist * np.array([np.cos(pitch) * d[0], np.cos(pitch) * d[1], np.sin(pitch)])
    return ExternalView((float(eye[0]), float(eye[1]), float(eye[2])),
                        (float(target[0]), float(target[1]), float(target[2])))


def auto_view(world: ReplayWorld, trace: pd.DataFrame, n_rows: int = 7) -> ExternalView:
    """Frame the robots' links and the bodies within :data:`REACH_M` of them over the run.

    The eye looks at the centre of their bounding box from the distance where the box's
    half-diagonal fills 0.95 of the half field of view. Its direction is the first of
    :data:`CANDIDATES` that shows both the robots and those bodies within :data:`PREFER`
    of the best (ours: no paper prescribes a view): small segmentation renders at three
    rows score each candidate by the smaller of its robot pixels and its body pixels, each
    relative to the best candidate's, so that neither hides the other."""
    sample = np.linspace(0, len(trace) - 1, min(n_rows, len(trace))).round().astype(int)
    links: list[np.ndarray] = []
    bodies: dict[str, list[tuple[float, float, float]]] = {}
    robots = [n for n, b in world.bodies.items() if b["kind"] == "urdf"]
    for k in sample:
        world.set_row(trace.iloc[int(k)])
        links.append(world.link_positions())
        for name, ids in world.ids.items():
            if name not in robots and ids:
                bodies.setdefault(name, []).extend(
                    p.getBasePositionAndOrientation(bid, physicsClientId=world.client)[0]
                    for bid, _ in ids)
    robot = np.vstack(links)
    near = [n for n, pts in bodies.items() if len(robot) == 0 or np.min(np.linalg.norm(
        np.asarray(pts)[:, None] - robot[None], axis=2)) < REACH_M]
    other = np.asarray([q for n in near for q in bodies[n]], dtype=float).reshape(-1, 3)
    if len(other) and len(robot):  # a body parked far away part of the run is framed near
        other = other[np.min(np.linalg.norm(other[:, None] - robot[None], axis=2),
                             axis=1) < REACH_M]
    pts = np.vstack([robot, other])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    target = (lo + hi) / 2.0
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.15)
    base = robot.mean(axis=0) if len(robot) else target
    work = other.mean(axis=0) if len(other) else target + [1.0, 0.0, 0.0]
    d = (work - base)[:2]
    d = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-3 else np.array([1.0, 0.0])
    dist = 0.95 * radius / np.tan(np.radians(EXTERNAL_FOV_DEG) / 2.0)
    views = [_look(target, d, dist, *c) for c in CANDIDATES]
    robot_ids = {world.ids[n][0][0] for n in robots}
    work_ids = {bid for n in near for bid, _ in world.ids[n]}
    counts = np.zeros((len(views), 2))
    w, h = SCORE_SIZE
    for k in sample[[0, len(sample) // 2, -1]]:
        world.set_row(trace.iloc[int(k)])
        for i, v in enumerate(views):
            _, seg = world.render(*v.matrices(w, h), w, h, segmentation=True)
            assert seg is not None
            counts[i] += (np.isin(seg, list(robot_ids)).sum(), np.isin(seg, list(work_ids)).sum())
    best = counts.max(axis=0)
    score = np.min(counts / np.where(best > 0, best, 1.0), axis=1)
    return views[int(np.flatnonzero(score >= PREFER * score.max())[0])]


def frame_rows(t: np.ndarray, fps: float, speed: float) -> list[int]:
    """The trace row shown in each video frame: the last row at or before the frame's time."""
    times = np.arange(t[0], t[-1] + 1e-9, speed / fps)
    rows = np.searchsorted(t, times + 1e-9, side="right") - 1
    return [int(r) for r in np.clip(rows, 0, len(t) - 1)]
