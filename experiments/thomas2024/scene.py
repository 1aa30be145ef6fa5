"""thomas2024 scenes: the Panda with two proximity rings and a camera, targets, obstacles.

The paper gives the robot, the ring layout (18 sensors each, ring 1 on link 5,
ring 2 at the flange, camera on top of ring 2), the initial configuration and
the gains; it gives neither the ring radii nor the obstacle and target poses.
Those are ours (marked ``# ours:``), designed so that the situations the paper
describes arise -- which ring meets which obstacle, in which order -- and
recorded in every run's scene.json.
"""

from __future__ import annotations

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


def ring_specs(max_range: float, noise: float) -> tuple[RingSpec, RingSpec]:
    """The two rings, sensor 1 along the ring frame's x axis, numbered counter-clockwise
    about the ring axis (ours: the paper does not say how its sensors are numbered)."""
    return (
        RingSpec("ring1", RING1_RADIUS, N_SENSORS, max_range, 0.0, 0.0, noise),
        RingSpec("ring2", RING2_RADIUS, N_SENSORS, max_range, 0.0, 0.0, noise),
    )


RING_PARENTS = {"ring1": ("panda_link5", T_LINK5_RING1), "ring2": ("panda_link8", T_FLANGE_RING2)}
CAMERA_PARENT = ("panda_link8", T_FLANGE_RING2 @ T_RING2_CAMERA)


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
        Attachment("camera_optical", cam_link, T_cam @ trans(0.0, 0.0, CAMERA_BODY[2] / 2),
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
    far: float = 0.40  # ours [m]
    near_gap: float = 0.03  # ours: hand face 3 cm from the ring rim, under every threshold [m]
    hold_fraction: float = 0.2  # ours: share of an approach spent at the nearest point


@dataclass(frozen=True)
class Scene:
    """Everything a thomas2024 case needs besides the robot."""

    q_goal_deg: tuple[float, ...]
    target_depth: float
    planes: tuple[Plane, ...] = ()
    hand: HandPath | None = None
    target: DotTarget = field(default_factory=lambda: DotTarget.square(0.04, 0.008, (0.16, 0.16)))


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


# Goal configuration of cases 1-2: the camera looks forward and down at a target
# standing 45 cm in front of the robot, with the arm reaching between boards.
Q_GOAL_DEG = (0.0, 25.0, 0.0, -105.0, 0.0, 130.0, 45.0)  # ours: a reach into a congested cell

SCENES: dict[str, Scene] = {
    # Case 1 (Sec. V-A): two planes; the straight visual path crosses the right one.
    "case1": Scene(
        q_goal_deg=Q_GOAL_DEG,
        target_depth=0.25,  # ours: inside the D405's 7-50 cm working range
        planes=(
            _plane_facing("right", (0.45, -0.20, 0.45), np.pi / 2),   # ours
            _plane_facing("left", (0.45, 0.20, 0.45), -np.pi / 2),    # ours
        ),
    ),
    # Case 2 (Sec. V-B): two ~parallel planes near the start, two angled near the goal.
    "case2": Scene(
        q_goal_deg=Q_GOAL_DEG,
        target_depth=0.25,  # ours
        planes=(
            _plane_facing("start_right", (0.15, -0.25, 0.85), np.pi / 2, size=(0.4, 0.4)),  # ours
            _plane_facing("start_left", (0.15, 0.25, 0.85), -np.pi / 2, size=(0.4, 0.4)),  # ours
            _plane_facing("goal_a", (0.50, -0.12, 0.30), np.deg2rad(120), size=(0.3, 0.3)),  # ours
            _plane_facing("goal_b", (0.50, 0.12, 0.30), np.deg2rad(-120), size=(0.3, 0.3)),  # ours
        ),
    ),
    # Case 3 (Sec. V-C): no planes; starts converged; a hand approaches ring 2 four
    # times (5-18 s) then ring 1 four times (20-30 s).
    "case3": Scene(
        q_goal_deg=Q_GOAL_DEG,
        target_depth=0.25,  # ours
        hand=HandPath(approaches=(
            ("ring2", 5.0, 3.0, np.deg2rad(0)), ("ring2", 8.3, 3.0, np.deg2rad(90)),
            ("ring2", 11.6, 3.0, np.deg2rad(180)), ("ring2", 14.9, 3.0, np.deg2rad(270)),
            ("ring1", 20.0, 2.4, np.deg2rad(90)), ("ring1", 22.5, 2.4, np.deg2rad(270)),
            ("ring1", 25.0, 2.4, np.deg2rad(60)), ("ring1", 27.5, 2.4, np.deg2rad(300)),
        )),  # ours: timings inside the paper's 5-18 s and 20-30 s windows
    ),
    # Sec. VI eq. (20): ring 2 passes between two parallel planes and the goal
    # lies between them, each plane at the ring's threshold distance.
    "parallel": Scene(
        q_goal_deg=Q_GOAL_DEG,
        target_depth=0.25,  # ours
        planes=(),  # filled from the goal ring pose by parallel_planes()
    ),
}


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
        Tp[:3, 3] = c + sgn * d * x + 0.1 * R[:, 2] * 0.0
        planes.append(Plane(name, Tp, (0.3, 0.6)))
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
            y = T_r[:3, 2]  # long side along the ring axis
            T[:3, :3] = np.column_stack([np.cross(y, z), y, z])
            T[:3, 3] = T_r[:3, 3] + dist * direction
            return T
    return None


PARKED_HAND = trans(0.0, 0.0, -5.0)  # below the floor, out of every sensor's range

__all__ = ["SCENES", "Scene", "Plane", "HandPath", "write_urdf", "ring_specs", "INTRINSICS",
           "CAMERA_PARENT", "RING_PARENTS", "target_pose", "hand_pose", "parallel_planes",
           "PARKED_HAND", "inv_T"]
