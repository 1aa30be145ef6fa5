"""thomas2024 scene layouts from a config, and the check of a layout's start.

The ``case1_*``, ``case2_*`` and ``case3_*`` config fields (swept, issue 19) shape the
boards and the hand; :func:`start_view` builds the start of a run in a scene of its own
(nothing written) so that :func:`experiments.thomas2024.run.check_config` can refuse a
layout the paper's robot could not start in.
"""

from __future__ import annotations

import dataclasses
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from experiments.thomas2024 import scene as sc
from experiments.thomas2024.config import Thomas2024Config
from repro.sensors.camera import Camera, project_points
from repro.sim.panda import PANDA_JOINTS, PANDA_LIMITS
from repro.sim.scene import Scene
from repro.sim.world import WorldConfig

BOARD_RGBA = (0.8, 0.7, 0.55, 1.0)  # ours: light wood


def case1_layout(config: Thomas2024Config) -> sc.Case1Layout:
    """Case 1's board layout from the config's ``case1_*`` fields."""
    return sc.Case1Layout(**{f: getattr(config, f"case1_{f}")
                             for f in sc.Case1Layout.__dataclass_fields__})


def case2_layout(config: Thomas2024Config) -> sc.Case2Layout:
    """Case 2's board layout from the config's ``case2_*`` fields."""
    return sc.Case2Layout(**{f: getattr(config, f"case2_{f}")
                             for f in sc.Case2Layout.__dataclass_fields__})


def case3_hand(config: Thomas2024Config, hand: sc.HandPath) -> sc.HandPath:
    """Case 3's hand path with the config's ``case3_*`` fields: the nearest gap, every
    approach's duration scaled, every direction turned (start times kept)."""
    turn = np.deg2rad(config.case3_aim_offset_deg)
    return dataclasses.replace(hand, near_gap=config.case3_near_gap, approaches=tuple(
        (ring, t0, duration * config.case3_duration_scale, azimuth + turn)
        for ring, t0, duration, azimuth in hand.approaches))


def planes(config: Thomas2024Config, T_ring2_goal: np.ndarray) -> tuple[sc.Plane, ...]:
    """The boards of ``config.case`` (none in case 3)."""
    return {"parallel": lambda: sc.parallel_planes(T_ring2_goal, config.thresholds[1]),
            "case1": lambda: sc.case1_planes(T_ring2_goal, case1_layout(config)),
            "case2": lambda: sc.case2_planes(T_ring2_goal, config.thresholds[1],
                                             case2_layout(config))
            }.get(config.case, lambda: sc.SCENES[config.case].planes)()


@dataclass(frozen=True)
class StartView:
    """The robot at ``q0_deg`` among the boards, before the first step.

    Attributes:
        distances: closest distance [m] of the robot to each board (PyBullet closest points).
        found: (4,) bool, the rendered camera's detection of each target dot (1-based index
            = position + 1) in the start frame, whatever the config's camera mode.
        in_image: (4,) bool, the dot's centre is in front of the camera and projects inside
            the image (exact geometry).
    """

    distances: dict[str, float]
    found: np.ndarray
    in_image: np.ndarray

    @property
    def hidden(self) -> np.ndarray:
        """(4,) bool: in the image but not found (a body hides the dot)."""
        return self.in_image & ~self.found


def start_view(config: Thomas2024Config) -> StartView | None:
    """The start of ``config``'s run, in a PyBullet scene of its own (nothing written).
    None for the parallel-planes run, whose start is solved from its goal."""
    if config.case == "parallel":
        return None
    case = sc.SCENES[config.case]
    scene = Scene(WorldConfig(physics_dt=1.0 / config.physics_rate,
                              control_dt=1.0 / config.control_rate), render=True)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            robot = scene.add_urdf("panda", sc.write_urdf(Path(tmp) / "panda.urdf"),
                                   PANDA_JOINTS, PANDA_LIMITS)
        q_goal = np.deg2rad(case.q_goal_deg)
        T_ring2_goal = robot.frame_pose("ring2", q_goal)
        for pl in planes(config, T_ring2_goal):
            scene.add_box(pl.name, (*pl.size, pl.thickness), pl.T_world, BOARD_RGBA)
        T_target = sc.target_pose(robot.frame_pose("camera_optical", q_goal), case.target_depth)
        scene.add_dot_target("target", case.target, T_target)
        q0 = np.deg2rad(config.q0_deg)
        robot.reset(q0)
        T_cam = robot.frame_pose("camera_optical", q0)
        _, found, Z = Camera(sc.INTRINSICS, mode="render").measure(
            scene.render_client, T_cam, case.target, T_target)
        uv, _ = project_points(sc.INTRINSICS, T_cam, case.target.points_world(T_target))
        return StartView(scene.distances(robot), np.asarray(found, dtype=bool),
                         (Z > 0) & sc.INTRINSICS.in_image(uv))
    finally:
        scene.close()
