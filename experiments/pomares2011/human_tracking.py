"""pomares2011 Sec. 4: the human's tracked skeleton and its distance to the mini-robot, the
distance of the secondary task (17), with its gradient and its noise-free audit twin."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from experiments.pomares2011 import scene as sc
from repro.control.hybrid_vs import distance_gradient_from_joints
from repro.planning.capsules import Capsule, capsule_closest_points, min_distance
from repro.sim.human import HumanMotion
from repro.sim.pa10 import ALL_JOINTS, MINI_CAPSULES, MINI_JOINTS
from repro.sim.robot import Robot
from repro.vision.features import skew

#: The tracked human-robot distance this far from the distance with the true skeleton is
#: an event [m]. ours: 2 cm, ~4 std of the largest tracking noise we try.
TRACKING_EVENT_M = 0.02
#: Positions of the mini-robot's joints in ALL_JOINTS (q of the whole chain).
_MINI_IDX = np.array([ALL_JOINTS.index(j) for j in MINI_JOINTS])


class HumanDistance(NamedTuple):
    """The controller's human-robot distance (pomares2011 Sec. 4) at one step."""

    dist: float  # [m] min over the tracked human capsules x the mini-robot capsules
    grad: np.ndarray  # (6,) d(dist)/dr, camera twist (repro.control.hybrid_vs)
    pair: str  # "<mini capsule>|<human capsule>" of the closest pair
    dist_true: float  # [m] audit: the same with the true (noise-free) skeleton


def human_distance(chain: Robot, q: np.ndarray, tracked: list[tuple[str, Capsule]],
                   truth: list[tuple[str, Capsule]]) -> HumanDistance:
    """``dist`` of eq. (17) between the mini-robot's capsules at ``q`` and the tracked
    human capsules (``tracked is truth``: no tracking noise; python-fcl,
    :func:`repro.planning.capsules.min_distance`), and its gradient w.r.t. the camera pose
    from the closest pair's witness points: the exact joint gradient of the closest point
    on its own link, mapped to the camera-twist space
    (:func:`repro.control.hybrid_vs.distance_gradient_from_joints`)."""
    mini = sc.mini_capsules(chain, q)
    d, i, j = min_distance([c for _, c in mini], [c for _, c in tracked], method="fcl")
    _, x_r, x_h = capsule_closest_points(mini[i][1], tracked[j][1])
    n = x_r - x_h
    if np.linalg.norm(n) < 1e-9:  # touching segments: push along the robot capsule's normal
        n = mini[i][1].centre - tracked[j][1].centre
    n = n / np.linalg.norm(n)
    link = MINI_CAPSULES[i][0]
    idx = _MINI_IDX
    J_link = chain.frame_jacobian(link, q, "local_world_aligned")[:, idx]  # world axes
    o_link = chain.frame_pose(link, q)[:3, 3]
    J_p = J_link[:3] - skew(x_r - o_link) @ J_link[3:]  # velocity of the point x_r
    R = chain.frame_pose("mini_camera_optical", q)[:3, :3]
    J_g = chain.frame_jacobian("mini_camera_optical", q)[:, idx]
    grad = distance_gradient_from_joints(J_g, R.T @ J_p, R.T @ n)
    d_true = d if tracked is truth else min_distance([c_ for _, c_ in mini],
                                                     [c_ for _, c_ in truth])[0]
    return HumanDistance(float(d), grad, f"{mini[i][0]}|{tracked[j][0]}", float(d_true))



class Bones:
    """The human's capsules at time t, computed once per time for the bones' movers and the
    controller's tracker (the same call at the same t would otherwise be made 13 times)."""

    def __init__(self, human: HumanMotion) -> None:
        self.human = human
        self.t = float("nan")
        self.list: list[tuple[str, Capsule]] = []
        self.caps: dict[str, Capsule] = {}
        self.poses: dict[str, tuple[Capsule, np.ndarray]] = {}  # its capsule, its pose

    def capsules(self, t: float) -> list[tuple[str, Capsule]]:
        """:meth:`repro.sim.human.HumanMotion.capsules` at ``t`` [s], cached."""
        if t != self.t:
            self.t, self.list = t, self.human.capsules(t)
            self.caps = dict(self.list)
        return self.list

    def pose(self, name: str) -> Callable[[float], np.ndarray]:
        def pose(t: float) -> np.ndarray:
            self.capsules(t)
            cap = self.caps[name]
            seen = self.poses.get(name)
            if seen is None or seen[0] is not cap:  # a capsule of a new body state
                T = np.asarray(cap.T_world())  # (a copy of its own)
                T.setflags(write=False)  # so Scene.move knows it unchanged by identity
                seen = self.poses[name] = (cap, T)
            return seen[1]
        return pose

