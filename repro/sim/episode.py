"""One episode loop for every paper: scene -> sensors -> controller -> drives -> trace files.

A paper supplies plain pieces in an :class:`Episode`: the :class:`~repro.sim.scene.Scene`,
one :class:`~repro.sim.drives.Drive` per robot (the actuation mode), its eye-in-hand
cameras (:class:`CameraRig`), its other sensors (:class:`Sensor`), scripted motions of
moving bodies, and the controller: a function ``step(obs) -> StepResult`` with the paper's
equations and nothing else. The runner owns everything else, identically for every paper:

* the trace recorder and the run files (``trace.csv``, ``columns.json``, ``events.csv``,
  ``manifest.json``, ``scene.json``, optional ``video.mp4`` and ``frames/``);
* per robot (column prefix ``p``): measured joint positions ``pq{i}`` and velocities
  ``pqd{i}``, the command ``pu{i}`` as the controller gave it, and how many joints the
  drive saturated (``pn_sat``);
* per camera: the detected points, and beside them the audit (never read by the
  controller): the exact projection of each model point through the true camera pose,
  whether it is visible (in front, inside the image, no body between the camera and the
  point), and the detection error; a detection farther than the tolerance from its
  projection, or a hidden point reported found, is an event and is counted in the manifest;
* ground-truth distances from every robot to every other body (``dist_*``), collision
  events, the poses of moving bodies;
* the NaN guard: a non-finite command never reaches a drive (the drive's safe command is
  sent, an event is logged and the run ends with status ``failed``);
* the stop test, the summary and the end status.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import pybullet as p

from repro.control.kernels import finite
from repro.errors import ConfigError
from repro.runs.columns import COLUMNS_FILE, Columns
from repro.runs.signals import StepGuard
from repro.runs.trace import TraceRecorder
from repro.sensors.camera import (
    DETECTABLE_MINOR_AXIS_PX,
    Camera,
    disc_minor_axes_px,
    project_points,
    render_rgb,
)
from repro.sim.drives import Drive
from repro.sim.robot import JointSet, Robot
from repro.sim.scene import DISTANCE_CAP, Scene, pose_columns, pose_json
from repro.sim.world import pose_to_pb

__all__ = ["CameraRig", "Episode", "Features", "Observation", "Sensor", "StepResult",
           "View", "run_episode"]

Scalar = float | int | str | bool

#: Wall time of the loop, split (manifest summary "timing") [s]: moving bodies and state
#: reads (scene), cameras and other sensors with their audit (sensors), the controller,
#: the drives' commands and the row's joint columns (drives), ground-truth distances and
#: poses (audit), the trace (logging), the drives' substeps and stepSimulation (physics).
TIMING_SPLIT = ("scene_s", "sensors_s", "controller_s", "drives_s", "audit_s", "logging_s",
                "physics_s")

#: Visibility rays end this far above the dot, along the dot's normal (+z of the target
#: frame) [m]: PyBullet's ray test meets a face up to ~1 mm off, and the dots stand only
#: 0.1-0.3 mm proud of their support; a ray that reaches the lifted point unblocked sees
#: the dot.
VISIBILITY_LIFT = 2.0e-3
#: ... and a hit less than this short of the ray's end does not count [m].
VISIBILITY_MARGIN = 0.5e-3
#: Rays start this far in front of the optical centre [m] (clear of the camera's own body).
RAY_START = 5.0e-3


@dataclass
class Features:
    """What a camera gives the controller: detected points [px] (NaN where not found)."""

    uv: np.ndarray  # (N, 2) [px]
    found: np.ndarray  # (N,) bool
    Z_exact: np.ndarray  # (N,) depth of each model point [m], for the camera's "exact" mode


@dataclass
class CameraRig:
    """An eye-in-hand camera measuring the dots of a scene body.

    Attributes:
        name: sensor name (in scene.json).
        prefix: feature column prefix (``"s"`` gives ``s1_u``, ``s1_v``...).
        camera: intrinsics and mode (render + detection, or exact projection).
        robot: the robot carrying it.
        frame: the robot link the camera is fixed to (a URDF link name, also a pinocchio
            frame).
        T_frame_camera: true pose of the camera frame (x right, y down, z forward) in it.
        target: name of the scene's ``dot_target`` body.
        tol_px: a detection farther than this from the exact projection is an event [px].
        period: control steps between two frames (a 200 fps camera under a 1 kHz torque
            loop: 5); in between, the controller gets the last frame's points (held) and the
            trace repeats that frame's columns, with ``<name>_new_frame`` False.
    """

    name: str
    prefix: str
    camera: Camera
    robot: Robot
    frame: str
    T_frame_camera: np.ndarray
    target: str
    tol_px: float = 2.0
    period: int = 1
    #: log ``<prefix><i>_view_deg``, each dot's viewing angle (a flat dot seen edge-on images
    #: as a sliver and is lost; chan2011 issue 17). Off by default: the other papers' plate
    #: targets would change their committed traces' columns
    log_view_angle: bool = False

    def pose(self, q: np.ndarray) -> np.ndarray:
        """T_world_camera (4x4) at joint positions ``q`` of the carrying robot."""
        return self.robot.frame_pose(self.frame, q) @ self.T_frame_camera


class Sensor(Protocol):
    """A paper's other sensor (a proximity ring...): read once per control step."""

    name: str

    def read(self, t: float, q: Mapping[str, np.ndarray]) -> Any:
        """The measurement at time ``t`` with the robots at ``q`` (by robot name)."""
        ...

    def columns(self, reading: Any) -> Mapping[str, Scalar]:
        """Trace columns of a measurement (declared by the paper)."""
        ...

    def events(self, reading: Any) -> list[tuple[str, str]]:
        """Events of a measurement (a sensor fault...)."""
        ...

    # Optional: ``after_control(reading) -> Mapping[str, Scalar]``, called after the
    # controller of the same step, overwrites some of the reading's columns (an audit that
    # logs relative to what the controller decided this step: pomares2011's GraspAudit).

    def failure(self, reading: Any) -> str | None:
        """Why the sensor can no longer be trusted (the run then stops safely), or None."""
        ...


@dataclass
class Observation:
    """Everything the controller may use at one control step."""

    t: float
    step: int
    q: dict[str, np.ndarray]  # measured joint positions by robot name [rad]
    qd: dict[str, np.ndarray]  # measured joint velocities [rad/s]
    features: dict[str, Features]  # by camera name
    sensors: dict[str, Any]  # by sensor name


@dataclass
class StepResult:
    """What the controller returns: one command per robot (by name), extra trace columns,
    events, a stop request ``(event kind, reason)`` applied after this row, and whether the
    command is a fallback (u = 0 after a failed solve or a lost feature) rather than the
    controller's own: a run in which every step fell back ends ``failed``. ``log_row``: write
    this step's row even between two ``log_every`` rows (a controller with a tick of its own,
    e.g. a 30 Hz tactile loop inside a 100 Hz log, keeps every tick in the trace)."""

    command: dict[str, np.ndarray]
    columns: dict[str, Scalar] = field(default_factory=dict)
    events: list[tuple[str, str]] = field(default_factory=list)
    stop: tuple[str, str] | None = None
    fallback: bool = False
    log_row: bool = False
    #: more columns, computed only for a row that is written (audits and diagnostics a
    #: controller logs but does not act on: at 1 kHz with a row every 10 steps, 9 of 10 would
    #: be thrown away). Called at most once, in the same step, before the controller's next
    #: call; it must not change the controller's state. Its columns follow ``columns``.
    lazy_columns: Callable[[], Mapping[str, Scalar]] | None = None

    def trace_columns(self) -> dict[str, Scalar]:
        """``columns``, then ``lazy_columns()`` (for the row of this step)."""
        if self.lazy_columns is None:
            return dict(self.columns)
        return {**self.columns, **self.lazy_columns()}


@dataclass(frozen=True)
class View:
    """A third-person view for videos and snapshots (PyBullet yaw/pitch camera)."""

    target: tuple[float, float, float] = (0.3, 0.0, 0.4)
    distance: float = 1.6
    yaw: float = 50.0
    pitch: float = -25.0
    width: int = 320
    height: int = 240
    fov: float = 55.0

    def render(self, client: int) -> np.ndarray:
        view = p.computeViewMatrixFromYawPitchRoll(list(self.target), self.distance, self.yaw,
                                                   self.pitch, 0, 2)
        proj = p.computeProjectionMatrixFOV(self.fov, self.width / self.height, 0.05, 5.0)
        img = p.getCameraImage(self.width, self.height, view, proj,
                               renderer=p.ER_TINY_RENDERER, physicsClientId=client)
        return np.reshape(np.asarray(img[2], dtype=np.uint8),
                          (self.height, self.width, 4))[:, :, :3]


@dataclass
class Episode:
    """The pieces a paper supplies (see the module docstring)."""

    scene: Scene
    drives: dict[str, Drive]  # by robot name
    controller: Callable[[Observation], StepResult]
    columns: Columns  # the paper's own columns (controller and sensor columns)
    duration: float  # [s]
    cameras: list[CameraRig] = field(default_factory=list)
    sensors: Sequence[Sensor] = field(default_factory=list)
    movers: dict[str, Callable[[float], np.ndarray]] = field(default_factory=dict)
    #: after the run, replay it from its files into video.mp4 (:mod:`repro.replay.video`,
    #: the same code as ``repro video RUN_DIR``; not written for an interrupted run)
    video: bool = False
    view: View = field(default_factory=View)
    snapshot_period: float = 0.0  # [s]; 0: no frames/ snapshots
    #: Control steps between two trace rows (1: every step). The loop, the sensors, the
    #: audit, the ground truth and the events run at every step whatever this is; only the
    #: rows written to trace.csv are thinned (a 1 kHz torque loop logged at 100 Hz), and the
    #: first and the last step are always written. The manifest's summary keeps the extremes
    #: of every ground-truth distance over *all* steps (``min_over_all_steps``).
    log_every: int = 1

    @property
    def dt(self) -> float:
        return self.scene.physics.config.control_dt

    def __post_init__(self) -> None:
        if not (isinstance(self.log_every, int) and self.log_every >= 1):
            raise ConfigError(f"Episode.log_every must be an integer >= 1, got "
                              f"{self.log_every!r}")
        for cam in self.cameras:
            if self.log_every > 1 and self.log_every % cam.period:
                raise ConfigError(f"Episode.log_every = {self.log_every} must be a multiple of "
                                  f"camera {cam.name!r}'s period {cam.period}: every trace row "
                                  "is then a fresh frame")


# ----------------------------------------------------------------------------- columns
def undriven_groups(ep: Episode) -> dict[str, JointSet]:
    """The scene's joint groups that no drive of ``ep`` commands, by name: the runner logs
    their joints (``<prefix>q{i}``, ``qd{i}``) and their ground-truth distances."""
    driven = {id(d.robot) for d in ep.drives.values()}
    return {name: g for name, g in ep.scene.joint_groups.items() if id(g) not in driven}


def _distance_columns(cols: Columns, ep: Episode, name: str, r: JointSet, pre: str) -> None:
    for body in ep.scene.bodies.values():
        if body.collision and body.robot is not getattr(r, "robot", r):
            cols.add(f"{pre}dist_{body.name}", "m", f"ground truth: minimum distance "
                     f"between the collision geometry of {name} and {body.name} (PyBullet "
                     f"closest points, minimum over its parts; < 0 penetration; capped at "
                     f"{DISTANCE_CAP} m)", audit=True)
    cols.add(f"{pre}dist_min", "m", f"ground truth: minimum of {pre}dist_* over the "
             "obstacles (bodies with obstacle = true in scene.json)", audit=True)


def runner_columns(ep: Episode) -> Columns:
    """The columns the runner writes for ``ep`` (the paper declares the rest)."""
    cols = Columns()
    cols.add("t", "s", "simulated time at the start of the control step")
    cols.add("step", "-", "control step index (0-based)")
    for name, group in undriven_groups(ep).items():  # observed only (e.g. an idle hand)
        pre = group.column_prefix
        cols.add(f"{pre}q{{i}}", "rad", f"measured position of {name} joint {{i}} (PyBullet "
                 "joint state; no drive of its own)", n=group.n)
        cols.add(f"{pre}qd{{i}}", "rad/s", f"measured velocity of {name} joint {{i}}", n=group.n)
        _distance_columns(cols, ep, name, group, pre)
    for name, drive in ep.drives.items():
        r, pre, n = drive.robot, drive.robot.column_prefix, drive.robot.n
        # a joint set may be other than joints (a hand's finger motors): its own words
        what = getattr(r, "element", "joint")
        state = getattr(r, "state_source", "PyBullet joint state")
        clip = getattr(drive, "clip_to", "tau_max" if drive.mode == "torque" else "qd_max")
        cols.add(f"{pre}q{{i}}", "rad", f"measured position of {name} {what} {{i}}", n=n)
        cols.add(f"{pre}qd{{i}}", "rad/s", f"measured velocity of {name} {what} {{i}} "
                 f"({state})", n=n)
        cols.add(f"{pre}u{{i}}", drive.unit, f"{drive.mode} command of {name} {what} {{i}} as "
                 f"the controller gave it (the drive applies it clipped to {clip})", n=n)
        cols.add(f"{pre}n_sat", "-", f"number of {name} {what}s whose command the drive "
                 f"clipped to {clip}")
        _distance_columns(cols, ep, name, r, pre)
    for cam in ep.cameras:
        n = ep.scene[cam.target].dot_target.n_points  # type: ignore[union-attr]
        s = cam.prefix
        cols.add(f"{s}{{i}}_u", "px", f"{cam.name}: detected u of point {{i}} (NaN if not "
                 "found); pixel (0,0) = centre of the top-left pixel", n=n)
        cols.add(f"{s}{{i}}_v", "px", f"{cam.name}: detected v of point {{i}} (NaN if not "
                 "found)", n=n)
        cols.add(f"{s}{{i}}_found", "bool", f"{cam.name}: point {{i}} detected", n=n)
        cols.add(f"{s}{{i}}_u_true", "px", "audit: exact projection (u) of model point {i} "
                 "through the true camera pose", n=n, audit=True)
        cols.add(f"{s}{{i}}_v_true", "px", "audit: exact projection (v) of model point {i}",
                 n=n, audit=True)
        cols.add(f"{s}{{i}}_visible", "bool", "audit: point {i} is in front of the camera, "
                 "inside the image, its dot faces the camera, is not seen edge-on (its image "
                 f">= {DETECTABLE_MINOR_AXIS_PX:g} px across) and no body lies between it and "
                 "the camera (ray test; scene.json cameras.<name>.visibility)",
                 n=n, audit=True)
        cols.add(f"{s}{{i}}_err_px", "px", "audit: distance between detection and exact "
                 "projection of point {i} (NaN if not found)", n=n, audit=True)
        if cam.log_view_angle:
            cols.add(f"{s}{{i}}_view_deg", "deg", "audit: viewing angle of dot {i}: between "
                     "its normal (the target body's z axis; every dot faces +z) and the "
                     "direction from the dot to the true camera centre (90 = edge-on; > 90: "
                     "seen from behind)", n=n, audit=True)
        cols.add(f"{cam.name}_render_s", "s", f"{cam.name}: wall time of render + detection")
        if cam.camera.window is not None:
            cols.add(f"{cam.name}_frame", "text", f"{cam.name}: what this frame rendered: "
                     "'windows' (only windows around the dots' last detections) or "
                     "'full:<reason>' (first, lost, period, missed, edge; "
                     "repro.sensors.camera_window)")
            cols.add(f"{cam.name}_rendered_px", "px", f"{cam.name}: pixels rendered for "
                     "this frame (windows and full frame)")
        if cam.period > 1:
            cols.add(f"{cam.name}_new_frame", "bool", f"{cam.name}: a new frame was taken at "
                     f"this step (every {cam.period} control steps; else the last one is held)")
        for c, unit in zip(pose_columns(cam.name), ("m",) * 3 + ("-",) * 4, strict=True):
            cols.add(c, unit, f"audit: true pose of the {cam.name} optical frame in the world "
                     "(position, quaternion xyzw)", audit=True)
    for body in ep.scene.moving_bodies():
        for c, unit in zip(pose_columns(body.name), ("m",) * 3 + ("-",) * 4, strict=True):
            cols.add(c, unit, f"pose of the moving body {body.name} in the world frame "
                     "(position, quaternion xyzw)")
    cols.add("ctrl_s", "s", "wall time of the controller step")
    return cols


def _joint_column_names(pre: str, n: int) -> tuple[list[str], list[str], list[str], str]:
    """The columns ``<pre>q{i}``, ``<pre>qd{i}``, ``<pre>u{i}`` (1-based) and ``<pre>n_sat``."""
    return ([f"{pre}q{i + 1}" for i in range(n)], [f"{pre}qd{i + 1}" for i in range(n)],
            [f"{pre}u{i + 1}" for i in range(n)], f"{pre}n_sat")


# ----------------------------------------------------------------------------- audit
def _visible(scene: Scene, T_wc: np.ndarray, P_world: np.ndarray, normal: np.ndarray,
             uv: np.ndarray, Z: np.ndarray, cam: Camera, minor_px: np.ndarray) -> np.ndarray:
    """(N,) True where a point is in front, inside the image, faces the camera (the camera
    more than VISIBILITY_LIFT above the dot's plane), is detectable (its disc's image
    ellipse at least DETECTABLE_MINOR_AXIS_PX across, ``minor_px``: not edge-on) and is
    unoccluded: a ray from the camera to the point lifted by VISIBILITY_LIFT along
    ``normal`` meets no body (ray test in the physics client, which holds every body)."""
    c = T_wc[:3, 3]
    P_world = P_world + VISIBILITY_LIFT * np.asarray(normal)
    d = P_world - c
    length = np.linalg.norm(d, axis=1)
    u = d / length[:, None]
    start = c + RAY_START * u
    hits = p.rayTestBatch(start.tolist(), P_world.tolist(),
                          physicsClientId=scene.physics.client)
    free = np.array([h[0] < 0 or h[2] * (L - RAY_START) >= (L - RAY_START) - VISIBILITY_MARGIN
                     for h, L in zip(hits, length, strict=True)])
    facing = (c - P_world) @ np.asarray(normal) > 0  # the camera sees the dot's front face
    return ((Z > 0) & cam.intrinsics.in_image(uv) & free & facing
            & (minor_px >= DETECTABLE_MINOR_AXIS_PX))


@dataclass
class _Audit:
    """Counts of one camera's audit over a run (written to the manifest's summary)."""

    mismatch_rows: int = 0
    hidden_found_rows: int = 0
    max_err_px: float = 0.0
    points_mismatched: set[int] = field(default_factory=set)
    points_hidden_found: set[int] = field(default_factory=set)

    def summary(self) -> dict[str, Any]:
        return {"mismatch_rows": self.mismatch_rows, "hidden_found_rows": self.hidden_found_rows,
                "max_err_px": self.max_err_px,
                "points_mismatched": sorted(self.points_mismatched),
                "points_hidden_found": sorted(self.points_hidden_found),
                "controller_used_wrong_feature": self.mismatch_rows > 0}


def _missed_cause(camera: Camera, Z: float, uv: np.ndarray, visible: bool, c: np.ndarray,
                  P: np.ndarray, normal: np.ndarray, minor_px: float = math.inf) -> str:
    """:func:`_why_missed` of a dot at depth ``Z`` [m] whose centre projects to ``uv``
    (1, 2) [px] and whose image ellipse is ``minor_px`` across [px]."""
    return _why_missed(bool(Z > 0 and camera.intrinsics.in_image(uv)[0]), visible, c, P,
                       normal, minor_px)


def _why_missed(in_view: bool, visible: bool, c: np.ndarray, P: np.ndarray,
                normal: np.ndarray, minor_px: float = math.inf) -> str:
    """Ground-truth cause of a missed detection (for the feature_missed event)."""
    if not in_view:
        return "its projection is outside the image (or behind the camera)"
    d = c - P
    angle = float(np.degrees(np.arccos(np.clip(d @ normal / np.linalg.norm(d), -1.0, 1.0))))
    if not visible and angle < 90 and minor_px < DETECTABLE_MINOR_AXIS_PX:
        return (f"seen edge-on ({angle:.1f} deg from its normal: its image is {minor_px:.2f} px "
                f"across, under the {DETECTABLE_MINOR_AXIS_PX:g} px a dot needs): not "
                "detectable")
    if not visible:
        return (f"seen from behind ({angle:.0f} deg from its normal)" if angle >= 90
                else "occluded by a body between it and the camera")
    return f"visible, seen at {angle:.0f} deg from its normal" + (
        " (grazing: a flat dot's image is a sliver)" if angle > 75 else "")


class _RunningMinima:
    """The smallest finite value of each of a fixed list of distance columns over the steps
    [m], and the time of the first step that reached it [s] (the manifest's
    ``min_over_all_steps``)."""

    def __init__(self, columns: list[str]) -> None:
        self.columns = columns
        self.best = [math.inf] * len(columns)
        self.t = [math.nan] * len(columns)

    def update(self, values: list[float], t: float) -> bool:
        """One step's values (in the columns' order); True if one of them is <= 0."""
        best, touch = self.best, False
        for i, v in enumerate(values):
            if v < best[i] and math.isfinite(v):
                best[i], self.t[i] = float(v), t
            if v <= 0.0:
                touch = True
        return touch

    def merge_into(self, best_of: dict[str, tuple[float, float]]) -> None:
        """Into ``column -> (min [m], t [s])``: the smaller, the earlier on a tie."""
        for c, d, t in zip(self.columns, self.best, self.t, strict=True):
            if d == math.inf:
                continue  # never finite
            old = best_of.get(c)
            if old is None or d < old[0] or (d == old[0] and t < old[1]):
                best_of[c] = (d, t)


@dataclass
class _DistanceColumns:
    """A robot's distance columns for one set of other bodies (:meth:`_Runner.ground_truth`)."""

    names: list[str]  # <pre>dist_<body>, in the bodies' order
    name_min: str  # <pre>dist_min
    obstacles: list[int]  # positions of the obstacles among the bodies
    minima: _RunningMinima


# ----------------------------------------------------------------------------- the loop
class _Runner:
    def __init__(self, ep: Episode, rec: TraceRecorder, out_dir: Path) -> None:
        self.ep, self.rec, self.out_dir = ep, rec, out_dir
        self.guard = StepGuard()  # signals are raised between steps (repro.runs.signals)
        self._sensor_dist_cols: dict[str, list[str]] = {}  # sensor -> its *dist_* columns
        self.cols = runner_columns(ep).extend(ep.columns)
        self.robots = {name: d.robot for name, d in ep.drives.items()}
        #: joint groups no drive commands: observed and logged only
        self.observed = undriven_groups(ep)
        # the whole chains (cameras need every joint of the robot carrying them)
        self.chains = {getattr(r, "robot", r).name: getattr(r, "robot", r)
                       for r in self.robots.values()}
        self.audit = {c.name: _Audit() for c in ep.cameras}
        self._flags: dict[str, bool] = {}
        self.collided: set[tuple[str, str]] = set()
        self.held: dict[str, tuple[Features, dict[str, Scalar]]] = {}
        #: every joint set whose ground-truth distances are logged, observed ones first
        self._groups = list({**self.observed, **self.robots}.items())
        self._group_sets = [g for _, g in self._groups]
        #: the joint columns of each drive and observed group, named once
        self._joint_cols = {name: _joint_column_names(d.robot.column_prefix, d.robot.n)
                            for name, d in ep.drives.items()}
        self._observed_cols = {name: _joint_column_names(g.column_prefix, g.n)
                               for name, g in self.observed.items()}
        self.dist_min: dict[str, tuple[float, float]] = {}  # column -> (min [m], at t [s])
        #: per (column prefix, bodies): the distance columns, which bodies are obstacles and
        #: their running minima
        self._dist_cols: dict[tuple[str, tuple[str, ...]], _DistanceColumns] = {}
        #: (number of scene bodies, each joint set's running minima) of the last step: the
        #: bounds of the next step's distances when it writes no row (ground_truth)
        self._gt_minima: tuple[int, list[list[float]]] | None = None

    def onset(self, key: str, now: bool, t: float, k: int, kind: str,
              detail: str | Callable[[], str],
              end_detail: str | Callable[[], str] | None = None) -> None:
        """Log an event when a condition starts (and optionally when it ends). A text may be
        given as a function: it is formatted only when its event is logged."""
        was = self._flags.get(key, False)
        if now and not was:
            self.rec.event(t, k, kind, detail if isinstance(detail, str) else detail())
        elif was and not now and end_detail is not None:
            self.rec.event(t, k, kind + "_end",
                           end_detail if isinstance(end_detail, str) else end_detail())
        self._flags[key] = now

    def measure(self, cam: CameraRig, q: np.ndarray, t: float, k: int
                ) -> tuple[Features, dict[str, Scalar], bool]:
        """Take a frame every ``cam.period`` steps; hold the last one in between. Returns the
        features, the frame's trace columns (held ones between frames) and whether the frame
        is new (``<name>_new_frame``)."""
        held = self.held.get(cam.name)
        if held is not None and k % cam.period:
            return held[0], held[1], False
        cols: dict[str, Scalar] = {}
        feats = self._measure(cam, q, t, k, cols)
        if cam.period > 1:
            cols[f"{cam.name}_new_frame"] = True
        self.held[cam.name] = (feats, cols)
        return feats, cols, True

    def _measure(self, cam: CameraRig, q: np.ndarray, t: float, k: int,
                 row: dict[str, Scalar]) -> Features:
        scene = self.ep.scene
        body = scene[cam.target]
        target = body.dot_target
        assert target is not None
        T_wc = cam.pose(q)
        tic = time.perf_counter()
        uv, found, Z = cam.camera.measure(scene.render_client, T_wc, target, body.T_world)
        row[f"{cam.name}_render_s"] = time.perf_counter() - tic
        if cam.camera.window is not None:
            rep = cam.camera.last_frame
            if rep is None:  # the exact mode renders nothing
                row[f"{cam.name}_frame"], row[f"{cam.name}_rendered_px"] = "none", 0
            else:
                row[f"{cam.name}_frame"] = (rep.kind if rep.reason is None
                                            else f"{rep.kind}:{rep.reason}")
                row[f"{cam.name}_rendered_px"] = rep.rendered_px
        pos, quat = pose_to_pb(T_wc)
        for c, v in zip(pose_columns(cam.name), pos + quat, strict=True):
            row[c] = v
        # the exact projection of the dot centres: the one the camera made of the same
        # poses (when it keeps it), else made here
        proj = getattr(cam.camera, "last_projection", None)
        if proj is not None:
            P, uv_true = proj[0], proj[1]
        else:
            P = target.points_world(body.T_world)
            uv_true, _ = project_points(cam.camera.intrinsics, T_wc, P)
        minor = disc_minor_axes_px(cam.camera.intrinsics, T_wc, target, body.T_world)
        visible = _visible(scene, T_wc, P, body.T_world[:3, 2], uv_true, Z, cam.camera, minor)
        err = np.where(found, np.linalg.norm(uv - uv_true, axis=1), np.nan)
        if cam.log_view_angle:
            to_cam = T_wc[:3, 3] - P
            cos = (to_cam @ body.T_world[:3, 2]) / np.linalg.norm(to_cam, axis=1)
            view_deg = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        a = self.audit[cam.name]
        with np.errstate(invalid="ignore"):
            bad = found & ~(err <= cam.tol_px)
        hidden = found & ~visible
        a.mismatch_rows += int(bad.any())
        a.hidden_found_rows += int(hidden.any())
        if found.any():
            a.max_err_px = max(a.max_err_px, float(np.nanmax(err)))
        for i in range(target.n_points):
            j, s = i + 1, f"{cam.prefix}{i + 1}"
            row[f"{s}_u"], row[f"{s}_v"] = float(uv[i, 0]), float(uv[i, 1])
            row[f"{s}_found"] = bool(found[i])
            row[f"{s}_u_true"], row[f"{s}_v_true"] = float(uv_true[i, 0]), float(uv_true[i, 1])
            row[f"{s}_visible"] = bool(visible[i])
            row[f"{s}_err_px"] = float(err[i])
            if cam.log_view_angle:
                row[f"{s}_view_deg"] = float(view_deg[i])
            if bad[i]:
                a.points_mismatched.add(j)
            if hidden[i]:
                a.points_hidden_found.add(j)
            # the texts are formatted only when an event is logged (onset)
            self._dot_events(cam, s, j, t, k, bool(bad[i]), not found[i], bool(hidden[i]),
                             float(err[i]), functools.partial(
                                 _missed_cause, cam.camera, Z[i], uv_true[i:i + 1],
                                 bool(visible[i]), T_wc[:3, 3], P[i], body.T_world[:3, 2],
                                 float(minor[i])))
        return Features(uv, found, Z)

    def _dot_events(self, cam: CameraRig, s: str, j: int, t: float, k: int, bad: bool,
                    missed: bool, hidden: bool, err_px: float, cause: Callable[[], str]
                    ) -> None:
        """The audit events of dot ``j`` (1-based, columns ``s``) of a frame: a detection
        off its projection, a dot missed (with its ground-truth ``cause``), one found that
        is not visible, each when it starts and when it ends."""
        name, tol = cam.name, cam.tol_px
        self.onset(f"{s}_mismatch", bad, t, k, "feature_mismatch",
                   lambda: f"{name} point {j} detected {err_px:.1f} px from the projection "
                   f"of its model point (tolerance {tol} px)",
                   lambda: f"{name} point {j} back within {tol} px")
        self.onset(f"{s}_missed", missed, t, k, "feature_missed",
                   lambda: f"audit: {name} point {j} not detected; ground truth: {cause()}",
                   lambda: f"{name} point {j} detected again")
        self.onset(f"{s}_hidden", hidden, t, k, "hidden_found",
                   lambda: f"{name} point {j} reported found but its model point is not "
                   "visible (occluded or outside the image)",
                   lambda: f"{name} point {j} visible again or no longer found")

    def ground_truth(self, t: float, k: int, row: dict[str, Scalar] | None) -> None:
        """Distances at every step (collision events, the minima over all steps); their
        columns and the moving bodies' poses only into a row that is written (``row`` not
        None)."""
        scene = self.ep.scene
        # a step that writes no row needs a distance only where it is below its running
        # minimum (a new minimum, a first touch): asked so (the values of the rows and
        # every minimum and event are the same; Scene.distance_table)
        kept = self._gt_minima
        below = (kept[1] if row is None and kept is not None and kept[0] == len(scene.bodies)
                 else None)
        minima = []
        for (name, robot), (bodies, dists) in zip(
                self._groups, scene.distance_table(self._group_sets, below=below),
                strict=True):
            cols = self._distance_columns(robot.column_prefix, bodies)
            minima.append(cols.minima.best)
            d_min = min([dists[i] for i in cols.obstacles], default=math.nan)
            if cols.minima.update([*dists, d_min], t):  # a body touched
                for body, di in zip(bodies, dists, strict=True):
                    if di <= 0.0 and (name, body) not in self.collided:
                        self.collided.add((name, body))
                        # an obstacle touched is a collision; a body the robot touches on
                        # purpose (obstacle = false: a grasped object) is a contact
                        hit = scene[body].obstacle
                        self.rec.summary[f"{'collided' if hit else 'touched'}_{body}"] = True
                        self.rec.event(t, k, "collision" if hit else "contact",
                                       f"{name} touches {body} (distance {di:.4f} m)")
            if row is not None:
                row.update(zip(cols.names, dists, strict=True))
                row[cols.name_min] = d_min
        self._gt_minima = (len(scene.bodies), minima)
        if row is None:
            return
        for moving in scene.moving_bodies():
            pos, quat = pose_to_pb(moving.T_world)
            for c, v in zip(pose_columns(moving.name), pos + quat, strict=True):
                row[c] = v

    def _distance_columns(self, pre: str, bodies: tuple[str, ...]) -> _DistanceColumns:
        """The distance columns of a robot (``<pre>dist_<body>``, ``<pre>dist_min``), which
        bodies are obstacles (a body with no robot, marked obstacle) and their running
        minima, made once per robot and set of bodies."""
        key = (pre, bodies)
        got = self._dist_cols.get(key)
        if got is None:
            scene = self.ep.scene
            names = [f"{pre}dist_{body}" for body in bodies]
            obstacles = [i for i, b in enumerate(bodies)
                         if scene[b].robot is None and scene[b].obstacle]
            got = self._dist_cols[key] = _DistanceColumns(
                names, f"{pre}dist_min", obstacles, _RunningMinima([*names, f"{pre}dist_min"]))
        return got

    @staticmethod
    def _keep_min(best_of: dict[str, tuple[float, float]], col: str, d: float, t: float
                  ) -> None:
        """Keep the smallest finite distance of ``col`` and its time."""
        best = best_of.get(col)
        if math.isfinite(d) and (best is None or d < best[0]):
            best_of[col] = (float(d), t)

    def _row(self, t: float, k: int,
             frames: list[tuple[CameraRig, Features, dict[str, Scalar], bool]],
             sensor_parts: list[Mapping[str, Scalar]], t_ctrl: float,
             amend_parts: list[Mapping[str, Scalar]], res: StepResult,
             commanded: list[tuple[str, np.ndarray, np.ndarray]],
             q: Mapping[str, np.ndarray], qd: Mapping[str, np.ndarray]) -> dict[str, Scalar]:
        """The trace row of a step that is written, in column order (the distances and the
        moving bodies' poses follow, from :meth:`ground_truth`)."""
        row: dict[str, Scalar] = {"t": t, "step": k}
        for cam, _, cols, fresh in frames:
            row.update(cols)
            if cam.period > 1:
                row[f"{cam.name}_new_frame"] = fresh
        for part in sensor_parts:
            row.update(part)
        row["ctrl_s"] = t_ctrl
        for part in amend_parts:
            row.update(part)
        row.update(res.trace_columns())
        for name, u, applied in commanded:
            names_q, names_qd, names_u, name_sat = self._joint_cols[name]
            for i, (cq, cqd, cu) in enumerate(zip(names_q, names_qd, names_u, strict=True)):
                row[cq] = float(q[name][i])
                row[cqd] = float(qd[name][i])
                row[cu] = float(u[i])
            row[name_sat] = int(np.sum(np.abs(applied - u) > 1e-12))
        for name, group in self.observed.items():
            names_q, names_qd, _, _ = self._observed_cols[name]
            for cq, cqd, qi, qdi in zip(names_q, names_qd, group.q(), group.qd(), strict=True):
                row[cq], row[cqd] = float(qi), float(qdi)
        return row

    def snapshot(self, k: int) -> None:
        import imageio.v2 as imageio

        frames = self.out_dir / "frames"
        frames.mkdir(exist_ok=True)
        scene = self.ep.scene
        for cam in self.ep.cameras:
            if scene.mirror is not None:
                rgb = render_rgb(scene.render_client, cam.camera.intrinsics,
                                 cam.pose(cam.robot.q()))
                imageio.imwrite(frames / f"camera_{k:05d}.png", rgb)
        imageio.imwrite(frames / f"scene_{k:05d}.png", self.ep.view.render(scene.physics.client))

    def run(self) -> tuple[str, str]:
        ep, rec = self.ep, self.rec
        world = ep.scene.physics
        dt, h = ep.dt, world.config.physics_dt
        n_steps = int(round(ep.duration / dt))
        snap_every = max(1, int(round(ep.snapshot_period / dt))) if ep.snapshot_period else 0
        status, reason = "completed", "duration reached"
        n_commanded = 0
        progress = _Progress(n_steps + 1, dt)
        clock = time.perf_counter
        split = dict.fromkeys(TIMING_SPLIT, 0.0)  # [s] summed over the steps
        t_start = clock()
        k = 0
        for k in range(n_steps + 1):
            self.guard.step()  # a SIGINT / SIGTERM stops the run here, between steps
            progress.update(k)
            tic0 = clock()
            t = k * dt
            for name, T_of_t in ep.movers.items():
                ep.scene.move(name, T_of_t(t))
            ep.scene.refresh_dynamic()  # free bodies: where the physics put them
            q = {name: r.q() for name, r in self.robots.items()}
            qd = {name: r.qd() for name, r in self.robots.items()}
            for name, chain in self.chains.items():
                q.setdefault(name, chain.q())
                qd.setdefault(name, chain.qd())
            tic1 = clock()
            split["scene_s"] += tic1 - tic0
            # the row's parts, in column order; a row is assembled only when it is written
            frames = [(c, *self.measure(c, q[c.robot.name], t, k)) for c in ep.cameras]
            feats = {c.name: f for c, f, _, _ in frames}
            readings = {s.name: s.read(t, q) for s in ep.sensors}
            split["sensors_s"] += clock() - tic1
            failed_sensor = None
            sensor_parts = []
            for s in ep.sensors:
                sensor_cols = s.columns(readings[s.name])
                sensor_parts.append(sensor_cols)
                # a sensor's ground-truth distances (pomares2011 hand_dist_*) join the
                # per-step minima; which columns they are is found once per sensor
                dist_cols = self._sensor_dist_cols.get(s.name)
                if dist_cols is None:
                    dist_cols = self._sensor_dist_cols[s.name] = [
                        c for c in sensor_cols if "dist_" in c]
                for col in dist_cols:
                    self._keep_min(self.dist_min, col, float(sensor_cols[col]), t)
                for kind, detail in s.events(readings[s.name]):
                    rec.event(t, k, kind, detail)
                failed_sensor = failed_sensor or s.failure(readings[s.name])
            tic = time.perf_counter()
            res = ep.controller(Observation(t, k, q, qd, feats, readings))
            t_ctrl = time.perf_counter() - tic
            split["controller_s"] += t_ctrl
            tic2 = clock()
            amend_parts = []  # columns a sensor can only give once the controller ran
            for s in ep.sensors:
                amend = getattr(s, "after_control", None)
                if amend is not None:
                    amend_parts.append(amend(readings[s.name]))
            for kind, detail in res.events:
                rec.event(t, k, kind, detail)
            stop = res.stop
            n_commanded += not res.fallback
            if failed_sensor is not None:  # stop safely: the drives' safe commands
                status, reason = "failed", f"sensor failure at t = {t:.3f} s: {failed_sensor}"
                stop = ("sensor_failed", reason + "; safe command sent, run stopped")
                rec.event(t, k, *stop)
            commanded = []  # (drive, command as given, as applied)
            for name, drive in ep.drives.items():
                u = np.asarray(res.command[name] if name in res.command
                               else drive.safe_command(), dtype=float)
                if failed_sensor is not None:
                    u = drive.safe_command()
                if u.shape != (drive.robot.n,) or not finite(u):
                    rec.event(t, k, "nan_command", f"{name}: controller command {u.tolist()} "
                              "is not a finite vector of the right size; safe command sent, "
                              "run stopped")
                    u = drive.safe_command()
                    status, reason = "failed", f"non-finite command for {name} at t = {t:.3f} s"
                    stop = ("nan_command", reason)
                commanded.append((name, u, drive.command(u, dt)))
            log = k % ep.log_every == 0 or k == n_steps or stop is not None or res.log_row
            row: dict[str, Scalar] | None = None
            if log:
                row = self._row(t, k, frames, sensor_parts, t_ctrl, amend_parts, res,
                                commanded, q, qd)
            tic3 = clock()
            split["drives_s"] += tic3 - tic2
            self.ground_truth(t, k, row)
            tic4 = clock()
            split["audit_s"] += tic4 - tic3
            if row is not None:
                if k == 0:
                    self.cols.check(row)
                    self.cols.write(self.out_dir / COLUMNS_FILE, row)
                rec.record(row)
            split["logging_s"] += clock() - tic4
            if snap_every and k % snap_every == 0:
                self.snapshot(k)
            if stop is not None:
                if status == "completed":
                    reason = stop[1]
                    rec.event(t, k, stop[0], stop[1])
                break
            tic5 = clock()
            for i in range(1, world.steps_per_control + 1):
                for drive in ep.drives.values():
                    drive.substep(i, h)
                world.step_physics()
            split["physics_s"] += clock() - tic5
        self.guard.close()  # one held through the last step
        progress.close()
        wall = clock() - t_start
        rec.summary["timing"] = {
            **{key: round(v, 6) for key, v in split.items()}, "loop_wall_s": round(wall, 6),
            "real_time_factor": round(k * dt / wall, 4) if wall > 0 else None}
        if status == "completed" and n_commanded == 0:
            status, reason = "failed", (f"the controller never produced a command: all {k + 1} "
                                        "steps fell back (e.g. every QP failed, no features)")
            rec.event(k * dt, k, "never_commanded", reason)
        rec.summary["commanded_steps"] = n_commanded
        rec.summary.update({"n_steps": k + 1, "sim_time_s": k * dt,
                            "mean_control_s": split["controller_s"] / (k + 1),
                            "stop_reason": reason})
        rec.summary["audit"] = {name: a.summary() for name, a in self.audit.items()}
        rec.summary["log_every"] = ep.log_every
        for cols in self._dist_cols.values():
            cols.minima.merge_into(self.dist_min)
        rec.summary["min_over_all_steps"] = {
            c: {"min_m": d, "t_s": tt} for c, (d, tt) in sorted(self.dist_min.items())}
        return status, reason


class _Progress:
    """A progress bar on a terminal (simulated time, real-time factor); silent otherwise."""

    def __init__(self, total: int, dt: float) -> None:
        import sys

        self.bar: Any = None
        self.dt = dt
        self.t0 = time.perf_counter()
        if sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="step", leave=False, file=sys.stderr,
                            mininterval=0.5)

    def update(self, k: int) -> None:
        if self.bar is None or k % 10:
            return
        wall = time.perf_counter() - self.t0
        self.bar.set_postfix_str(f"t = {k * self.dt:.2f} s, x{k * self.dt / max(wall, 1e-9):.2f}"
                                 " real time", refresh=False)
        self.bar.n = k
        self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run_episode(ep: Episode, out_dir: Path, *, paper: str, config: Any,
                experiment: str | None = None, seed: int | None = None,
                scene_extra: Mapping[str, Any] | None = None) -> Path:
    """Run ``ep`` and write the run files into ``out_dir``; the scene is closed at the end.

    ``experiment`` defaults to the folder's name without its ``__<hash>`` suffix, ``seed``
    to ``config.seed``. A crash or an interrupt still closes the run (status ``crashed`` /
    ``interrupted``) with the rows recorded so far.
    """
    import shutil

    out_dir = Path(out_dir)
    experiment = experiment or out_dir.name.split("__")[0]
    seed = int(config.seed) if seed is None else seed
    shutil.rmtree(out_dir / "frames", ignore_errors=True)  # no stale snapshots
    (out_dir / "video.mp4").unlink(missing_ok=True)
    if ep.duration <= 0:
        raise ConfigError(f"episode duration must be > 0 s, got {ep.duration}")
    try:
        with TraceRecorder(out_dir, experiment=experiment, paper=paper, config=config,
                           seed=seed) as rec:
            desc = ep.scene.describe()
            desc["cameras"] = {c.name: {
                "robot": c.robot.name, "frame": c.frame,
                "frame_is": "a URDF link of the robot: camera pose = link frame pose @ "
                            "T_frame_camera",
                "T_frame_camera": pose_json(c.T_frame_camera),
                "target": c.target, "feature_prefix": c.prefix, "mode": c.camera.mode,
                "audit_tolerance_px": c.tol_px, "period_control_steps": c.period,
                **_camera_json(c.camera)} for c in ep.cameras}
            desc["actuation"] = {name: {"mode": d.mode, "command_unit": d.unit}
                                 for name, d in ep.drives.items()}
            desc["columns_file"] = COLUMNS_FILE
            desc["trace_rows"] = {
                "log_every_control_steps": ep.log_every, "control_dt_s": ep.dt,
                "meaning": "trace.csv holds one row every log_every control steps (and the "
                           "last one); the loop, sensors, audit and events ran at every step"}
            desc.update(scene_extra or {})
            rec.set_scene(desc)
            runner = _Runner(ep, rec, out_dir)
            try:
                status, reason = runner.run()
            except BaseException:
                runner.guard.close(raise_pending=False)  # this exception closes the run
                raise
            rec.close(status, reason)
    finally:
        ep.scene.close()
    if ep.video and status != "interrupted":
        from repro.replay.video import write_video

        write_video(out_dir)  # from the files just closed, as an outsider would
    return out_dir


def _camera_json(cam: Camera) -> dict[str, Any]:
    i = cam.intrinsics
    return {"intrinsics": {"width": i.width, "height": i.height, "fu": i.fu, "fv": i.fv,
                           "u0": i.u0, "v0": i.v0, "near": i.near, "far": i.far},
            "convention": "camera frame x right, y down, z forward; pixel (0,0) = centre of "
                          "the top-left pixel; u = fu X/Z + u0, v = fv Y/Z + v0",
            "renderer": "pybullet.ER_TINY_RENDERER, shadow=0, default light, "
                        "flags=ER_NO_SEGMENTATION_MASK; view matrix = diag(1,-1,-1,1) "
                        "inv(T_world_camera); projection: see repro.sensors.camera."
                        "Intrinsics.projection_matrix_gl('tiny')",
            "projection_matrix_gl": i.projection_matrix_gl("tiny"),
            "visibility": ("the <prefix><i>_visible audit: a point is visible when it is in "
                           "front of the true camera (Z > 0), projects inside the image, the "
                           f"camera is more than {VISIBILITY_LIFT} m above its dot's plane on "
                           "its front side (the target body's +z: (c - P - lift n) . n > 0), "
                           "the dot is detectable (the image ellipse of its disc through the "
                           "true camera, the conic H^-T C0 H^-1 of "
                           "repro.sensors.camera.disc_image_centroids, is at least "
                           f"{DETECTABLE_MINOR_AXIS_PX:g} px across its minor axis; a dot seen "
                           "closer to edge-on images as a sliver no detector takes) and a ray "
                           f"cast from the camera centre ({RAY_START} m out along the ray) "
                           f"towards the point lifted {VISIBILITY_LIFT} m along that +z "
                           "(pybullet.rayTestBatch in the physics client, every body with a "
                           "collision shape, the robots' links included; the dots have none) "
                           f"hits nothing before {VISIBILITY_MARGIN} m short of it"),
            "windows": None if cam.window is None else {
                **dataclasses.asdict(cam.window),
                "meaning": "after a full frame, only windows around the dots' last detections "
                           "are rendered, through Intrinsics.crop (the same rays); a full "
                           "frame on the first frame, after a lost dot, every full_every "
                           "frames, and again when a dot is missed in its window or its mask "
                           "reaches within edge_px of a window's inner border "
                           "(repro.sensors.camera_window); the trace's <camera>_frame says "
                           "which"}}
