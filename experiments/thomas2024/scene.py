"""thomas2024 scenes: the Panda with two proximity rings and a camera, targets, obstacles.

The paper gives the robot, the ring layout (18 sensors each, ring 1 on link 5,
ring 2 at the flange, camera on top of ring 2), the initial configuration and
the gains; it gives neither the ring radii nor the obstacle and target poses.
Those are ours (marked ``# ours:``), designed so that the situations the paper
describes arise -- which ring meets which obstacle, in which order -- and
recorded in every run's scene.json.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from repro.geometry import Rx, Ry, Rz, inv_T, make_T, trans
from repro.sensors.camera import DotTarget, Intrinsics
from repro.sensors.proximity import RingSpec
from repro.sim.panda import Attachment, build_panda_urdf

# ---------------------------------------------------------------- the robot
# Ring 1 around the forearm (link 5). Link 5's z axis is the forearm axis; the
# forearm's cross-section is centred ~4 cm off that axis (mesh bounding box).
T_LINK5_RING1 = trans(0.0, 0.035, -0.20)  # ours: mid-forearm, from the link-5 mesh extents
RING1_RADIUS = 0.10  # ours: clears the forearm (mesh radius <= 0.09 m about this centre)
# Ring 2 at the flange (link 8), its axis along the flange z axis.
T_FLANGE_RING2 = trans(0.0, 0.0, 0.02)  # ours: a 4 cm thick ring bolted on the flange
RING2_RADIUS = 0.07  # ours: a ring around the 63 mm Franka flange
RING_THICKNESS = (0.03, 0.04)  # ours: ring widths along their axes [m]
# Camera (Intel RealSense D405) on the front face of ring 2, looking along the flange z.
T_RING2_CAMERA = trans(0.0, 0.0, 0.02 + 0.012)  # ours: D405 body 23 mm deep on the ring face
CAMERA_BODY = (0.042, 0.042, 0.023)  # D405 outer dimensions [m] (Intel datasheet)
# D405-like intrinsics at 640x480, with an off-centre principal point and fu != fv.
INTRINSICS = Intrinsics(width=640, height=480, fu=431.0, fv=429.5, u0=322.3, v0=236.8)  # ours: D405-class calibration
N_SENSORS = 18  # thomas2024 Sec. V


def ring_specs(max_range: float, noise: float, fov_deg: float = 0.0
               ) -> tuple[RingSpec, RingSpec]:
    """The two rings, sensor 1 along the ring frame's x axis, numbered counter-clockwise
    about the ring axis (ours: the paper does not say how its sensors are numbered); each
    sensor one ray (``fov_deg`` = 0, Sec. II-A's thin field) or a cone of that full angle."""
    return (
        RingSpec("ring1", RING1_RADIUS, N_SENSORS, max_range, 0.0, 0.0, noise, fov_deg=fov_deg),
        RingSpec("ring2", RING2_RADIUS, N_SENSORS, max_range, 0.0, 0.0, noise, fov_deg=fov_deg),
    )


RING_PARENTS = {"ring1": ("panda_link5", T_LINK5_RING1), "ring2": ("panda_link8", T_FLANGE_RING2)}
CAMERA_PARENT = ("panda_link8", T_FLANGE_RING2 @ T_RING2_CAMERA)
#: The optical frame (x right, y down, z forward) at the D405 body's front face, in the flange.
T_FLANGE_CAMERA = CAMERA_PARENT[1] @ trans(0.0, 0.0, CAMERA_BODY[2] / 2)


def attachments() -> tuple[Attachment, ...]:
    """Rings and camera as fixed links of the Panda URDF."""
    cam_link, T_cam = CAMERA_PARENT
    return (
        Attachment("ring1", "panda_link5", T_LINK5_RING1, "cylinder",
                   (RING1_RADIUS, RING_THICKNESS[0]), (0.55, 0.55, 0.55, 1.0), 0.15),
        Attachment("ring2", "panda_link8", T_FLANGE_RING2, "cylinder",
                   (RING2_RADIUS, RING_THICKNESS[1]), (0.1, 0.1, 0.1, 1.0), 0.15),
        Attachment("camera_body", cam_link, T_cam, "box", CAMERA_BODY,
                   (0.15, 0.15, 0.2, 1.0), 0.06),
        # The optical frame (x right, y down, z forward) at the body's front face.
        Attachment("camera_optical", cam_link, T_FLANGE_CAMERA,
                   "none", (), mass=0.0, collision=False),
    )


def write_urdf(dest: Path) -> Path:
    """The Panda + rings + camera URDF that PyBullet and pinocchio both load."""
    return build_panda_urdf(dest, attachments())


# ---------------------------------------------------------------- the scenes
@dataclass(frozen=True)
class Plane:
    """A planar obstacle: a thin box. ``T_world`` is its centre; its normal is its z axis."""

    name: str
    T_world: np.ndarray
    size: tuple[float, float] = (0.6, 0.6)  # ours: 60 cm boards
    thickness: float = 0.01  # ours

    def half_extents(self) -> tuple[float, float, float]:
        return (self.size[0] / 2, self.size[1] / 2, self.thickness / 2)


@dataclass(frozen=True)
class HandPath:
    """Scripted dynamic obstacle (case 3): a hand-sized box brought to a ring and back.

    Each approach moves the hand along a straight line in the ring plane from
    ``far`` to ``near`` metres from the ring centre (smooth cosine profile), holds,
    and retreats.
    """

    size: tuple[float, float, float] = (0.09, 0.18, 0.03)  # ours: an adult palm, 9 x 18 x 3 cm
    approaches: tuple[tuple[str, float, float, float], ...] = ()  # (ring, start [s], duration [s], azimuth [rad])
    far: float = 0.30  # ours: starts out of the threshold's reach [m]
    near_gap: float = 0.03  # ours: hand face 3 cm from the ring rim, under every threshold [m]
    hold_fraction: float = 0.2  # ours: share of an approach spent at the nearest point


@dataclass(frozen=True)
class Scene:
    """Everything a thomas2024 case needs besides the robot."""

    q_goal_deg: tuple[float, ...]
    target_depth: float
    planes: tuple[Plane, ...] = ()
    hand: HandPath | None = None
    target: DotTarget = field(default_factory=lambda: DotTarget.square(0.04, 0.008, (0.11, 0.11)))  # ours: 8 cm square of 16 mm dots on an 11 cm card


def target_pose(T_world_camera_goal: np.ndarray, depth: float) -> np.ndarray:
    """Target facing the camera at the goal, centred on its optical axis, ``depth`` [m] away.

    Target frame: z towards the camera (its visible face), x along the camera's x.
    """
    return T_world_camera_goal @ trans(0.0, 0.0, depth) @ Rx(np.pi)


def _plane_facing(name: str, centre: tuple[float, float, float], normal_yaw: float,
                  normal_pitch: float = 0.0, size: tuple[float, float] = (0.6, 0.6)) -> Plane:
    """A plane at ``centre`` [m] whose normal (z) has yaw/pitch [rad] in the world."""
    T = make_T(t=centre) @ Rz(normal_yaw) @ Ry(np.pi / 2 - normal_pitch)
    return Plane(name, T, size)


# Goal configuration of every case: the camera looks forward, right and down at a
# target 30 cm ahead; from the start pose the target is in view (bottom of the image).
Q_GOAL_DEG = (-20.0, -10.0, 0.0, -135.0, 0.0, 190.0, 45.0)  # ours: a reach into a congested cell
TARGET_DEPTH = 0.30  # ours: inside the D405's 7-50 cm working range

# Planes are placed in "corridor" coordinates: s along the horizontal line from the
# start of ring 2, (0.04, 0, 0), towards its final position (yaw -21 deg), and a
# lateral offset (left > 0). The straight visual path of ring 2 follows s.
CORRIDOR_ORIGIN = (0.04, 0.0)  # ours: ring 2 at the start, projected on the floor
CORRIDOR_YAW = np.deg2rad(-21.0)  # ours: heading of ring 2's unconstrained path


def corridor_plane(name: str, s0: float, s1: float, lateral: float, z0: float, z1: float,
                   yaw_offset_deg: float = 0.0) -> Plane:
    """A vertical board spanning s in [s0, s1] and z in [z0, z1] [m] at ``lateral`` [m]
    from the corridor axis, facing it, turned by ``yaw_offset_deg`` about the vertical."""
    d = np.array([np.cos(CORRIDOR_YAW), np.sin(CORRIDOR_YAW), 0.0])
    left = np.array([-np.sin(CORRIDOR_YAW), np.cos(CORRIDOR_YAW), 0.0])
    c = np.array([*CORRIDOR_ORIGIN, 0.0]) + d * (s0 + s1) / 2 + left * lateral
    c[2] = (z0 + z1) / 2
    normal_yaw = CORRIDOR_YAW + (-np.pi / 2 if lateral > 0 else np.pi / 2)
    normal_yaw += np.deg2rad(yaw_offset_deg)
    T = make_T(t=c) @ Rz(normal_yaw) @ Ry(np.pi / 2)
    return Plane(name, T, (z1 - z0, s1 - s0))


def blocking_plane(name: str, T_world_ring: np.ndarray, sensor: int, gap: float,
                   lean_deg: float, ahead: float, size: tuple[float, float]) -> Plane:
    """A board that faces ring sensor ``sensor`` (1-based) of a ring at pose
    ``T_world_ring``, ``gap`` [m] from the sensor, leaning by ``lean_deg`` towards the
    ring's +z axis so that, with its partner, it forms a V that narrows ahead."""
    R, c = T_world_ring[:3, :3], T_world_ring[:3, 3]
    theta = 2 * np.pi * (sensor - 1) / N_SENSORS
    n_s = R @ np.array([np.cos(theta), np.sin(theta), 0.0])
    z = R[:, 2]
    lean = np.deg2rad(lean_deg)
    n_t = -(np.cos(lean) * n_s + np.sin(lean) * z)  # normal facing the ring, tilted
    p0 = c + ahead * z + (RING2_RADIUS + gap) * n_s
    y = np.cross(n_t, n_s)
    y /= np.linalg.norm(y)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([np.cross(y, n_t), y, n_t])
    T[:3, 3] = p0 - n_t * 0.005  # the board's face (not its centre) passes through p0
    return Plane(name, T, size)


SCENES: dict[str, Scene] = {
    # Case 1 (Sec. V-A): two boards forming a corridor around the goal, turned so that
    # the straight visual path of ring 2 runs into the right one (case1_planes()).
    "case1": Scene(q_goal_deg=Q_GOAL_DEG, target_depth=TARGET_DEPTH),
    # Case 2 (Sec. V-B): two ~parallel boards around ring 1 near the start, two boards
    # in a V in front of ring 2 near the goal, filled in by case2_planes().
    "case2": Scene(q_goal_deg=Q_GOAL_DEG, target_depth=TARGET_DEPTH),
    # Case 3 (Sec. V-C): no boards; starts converged; a hand approaches ring 2 four
    # times (5-18 s) then ring 1 four times (20-30 s).
    "case3": Scene(
        q_goal_deg=Q_GOAL_DEG,
        target_depth=TARGET_DEPTH,
        hand=HandPath(approaches=(
            ("ring2", 5.0, 3.0, np.deg2rad(0)), ("ring2", 8.3, 3.0, np.deg2rad(90)),
            ("ring2", 11.6, 3.0, np.deg2rad(180)), ("ring2", 14.9, 3.0, np.deg2rad(270)),
            ("ring1", 20.0, 2.4, np.deg2rad(90)), ("ring1", 22.5, 2.4, np.deg2rad(270)),
            ("ring1", 25.0, 2.4, np.deg2rad(60)), ("ring1", 27.5, 2.4, np.deg2rad(300)),
        )),  # ours: timings inside the paper's 5-18 s and 20-30 s windows
    ),
    # Sec. VI eq. (20): ring 2 passes between two parallel boards and the goal lies
    # between them, each at the ring's threshold distance (parallel_planes()).
    "parallel": Scene(q_goal_deg=Q_GOAL_DEG, target_depth=TARGET_DEPTH),
}

@dataclass(frozen=True)
class Case1Layout:
    """Case 1's two boards, in corridor coordinates about ring 2's goal (Sec. V-A, Fig. 4;
    every number is ours: the config's ``case1_*`` fields, swept in issue 19).

    The corridor axis runs through ring 2's goal, horizontally, turned by ``turn_deg`` from
    ring 2's straight path (``CORRIDOR_YAW``); s along it (> 0 past the goal), lateral to
    its left. Each board is vertical, faces the axis, spans s in [-back, front] and z in
    [BOARD_BOTTOM, top] [m], its centre plane ``lateral`` [m] from the axis.
    """

    turn_deg: float = -15.0
    right_lateral: float = 0.165
    left_lateral: float = 0.19
    right_top: float = 0.85
    left_top: float = 0.85
    right_back: float = 0.30
    left_back: float = 0.45
    front: float = 0.25


BOARD_BOTTOM = 0.30  # ours: case 1's boards stand on a 30 cm support, below ring 2's path


def case1_planes(T_world_ring2_goal: np.ndarray, layout: Case1Layout = Case1Layout()
                 ) -> tuple[Plane, ...]:
    """Case 1 boards: a corridor around ring 2's goal (``layout``); by default 16.5 / 19 cm
    to its right / left, turned by -15 deg so that the unconstrained path meets the right
    board."""
    yaw = CORRIDOR_YAW + np.deg2rad(layout.turn_deg)
    d = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    left = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    g = T_world_ring2_goal[:3, 3]
    boards = []
    # (name, s from [m], s to [m] along the corridor from the goal, lateral [m], z0, z1 [m])
    for name, s0, s1, lat, z0, z1 in (
            ("right", -layout.right_back, layout.front, -layout.right_lateral, BOARD_BOTTOM,
             layout.right_top),
            ("left", -layout.left_back, layout.front, layout.left_lateral, BOARD_BOTTOM,
             layout.left_top)):
        c = np.array([g[0], g[1], 0.0]) + d * (s0 + s1) / 2 + left * lat
        c[2] = (z0 + z1) / 2
        normal_yaw = yaw + (-np.pi / 2 if lat > 0 else np.pi / 2)
        boards.append(Plane(name, make_T(t=c) @ Rz(normal_yaw) @ Ry(np.pi / 2), (z1 - z0, s1 - s0)))
    return tuple(boards)


@dataclass(frozen=True)
class Case2Layout:
    """Case 2's four boards (Sec. V-B, Fig. 5; every number ours: the config's ``case2_*``
    fields, swept in issue 19). Two start boards in corridor coordinates (see
    :func:`corridor_plane`), ``*_lateral`` [m] to the right / left of ring 2's start, turned
    by -skew/2 / +skew/2 [deg] about the vertical (skew > 0: they diverge towards the goal);
    and a V facing ring 2's sensors 4 and 12 at its goal pose, each board leaning by
    ``v_lean_deg`` towards the ring's axis, its face at ring 2's threshold from the sensor
    ``v_ahead`` [m] along the ring's axis from the goal (< 0: before it)."""

    start_right_lateral: float = 0.22
    start_left_lateral: float = 0.16
    start_skew_deg: float = 0.0
    v_lean_deg: float = 35.0
    v_ahead: float = -0.05


def case2_planes(T_world_ring2_goal: np.ndarray, threshold: float,
                 layout: Case2Layout = Case2Layout()) -> tuple[Plane, ...]:
    """Case 2 boards: the start pair and a V in front of ring 2's goal pose that faces
    sensors 4 and 12 and (by default) stops ring 2 ~5 cm before the goal."""
    half = layout.start_skew_deg / 2
    start = (
        corridor_plane("start_right", -0.30, 0.20, -layout.start_right_lateral, 0.55, 1.05,
                       -half),  # ours: s and z extents
        corridor_plane("start_left", -0.30, 0.20, layout.start_left_lateral, 0.55, 1.05,
                       half),  # ours
    )
    return start + (
        blocking_plane("goal_a", T_world_ring2_goal, 4, threshold, layout.v_lean_deg,
                       layout.v_ahead, (0.25, 0.3)),  # ours: 25 x 30 cm
        blocking_plane("goal_b", T_world_ring2_goal, 12, threshold, layout.v_lean_deg,
                       layout.v_ahead, (0.25, 0.3)),  # ours
    )


PARALLEL_RETREAT = 0.15  # ours: start of the "parallel" run, ring 2 15 cm behind its goal [m]


def parallel_planes(T_world_ring2_goal: np.ndarray, gap: float) -> tuple[Plane, Plane]:
    """Two planes parallel to ring 2's axis, ``gap`` [m] from its rim on both sides
    at the goal (sensors 1 and 10 face them)."""
    R = T_world_ring2_goal[:3, :3]
    c = T_world_ring2_goal[:3, 3]
    x = R[:, 0]
    d = RING2_RADIUS + gap + 0.005  # planes' half thickness
    planes = []
    for name, sgn in (("plane_pos", 1.0), ("plane_neg", -1.0)):
        Tp = np.eye(4)
        z = -sgn * x  # normal towards the ring
        y = R[:, 2]   # plane extends along the ring axis
        Tp[:3, :3] = np.column_stack([np.cross(y, z), y, z])
        Tp[:3, 3] = c + sgn * d * x + 0.02 * R[:, 2]
        # ours: 30 cm across, 16 cm along the ring axis (from 6 cm behind the ring centre,
        # clear of the wrist, to 10 cm ahead of it)
        planes.append(Plane(name, Tp, (0.3, 0.16)))
    return planes[0], planes[1]


def hand_pose(hand: HandPath, t: float, ring_poses: dict[str, np.ndarray],
              ring_radius: dict[str, float]) -> np.ndarray | None:
    """World pose of the hand at time ``t`` [s] (None: parked out of the way).

    ``ring_poses`` are the rings' poses at the start (the hand follows a script,
    not the robot).
    """
    for ring, start, duration, azimuth in hand.approaches:
        if start <= t <= start + duration:
            s = (t - start) / duration
            hold = hand.hold_fraction
            ramp = (1.0 - hold) / 2.0
            if s < ramp:
                a = 0.5 - 0.5 * np.cos(np.pi * s / ramp)
            elif s < ramp + hold:
                a = 1.0
            else:
                a = 0.5 + 0.5 * np.cos(np.pi * (s - ramp - hold) / ramp)
            T_r = ring_poses[ring]
            direction = T_r[:3, :3] @ np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
            near = ring_radius[ring] + hand.near_gap + hand.size[2] / 2
            dist = hand.far + a * (near - hand.far)
            T = np.eye(4)
            z = -direction  # palm faces the ring
            y = np.cross(T_r[:3, 2], z)  # fingers tangential to the ring
            T[:3, :3] = np.column_stack([np.cross(y, z), y, z])
            T[:3, 3] = T_r[:3, 3] + dist * direction
            return T
    return None


PARKED_HAND = trans(0.0, 0.0, -5.0)  # below the floor, out of every sensor's range


def hand_motion(hand: HandPath, ring_poses: dict[str, np.ndarray]
                ) -> Callable[[float], np.ndarray]:
    """The hand's scripted pose as a function of time [s] (parked between approaches);
    ``ring_poses`` are the rings' poses at the start."""
    radii = {s.name: s.radius for s in ring_specs(1.0, 0.0)}

    def pose(t: float) -> np.ndarray:
        T = hand_pose(hand, t, ring_poses, radii)
        return PARKED_HAND if T is None else T

    return pose

__all__ = ["SCENES", "Scene", "Plane", "HandPath", "write_urdf", "ring_specs", "INTRINSICS",
           "CAMERA_PARENT", "RING_PARENTS", "target_pose", "hand_pose", "parallel_planes",
           "PARKED_HAND", "inv_T", "hand_motion", "T_FLANGE_CAMERA", "trans", "N_SENSORS"]
