"""pomares2011 experiment 3: the finger-torque sensor and the grasp audit (the cylinder's
true pose and contacts beside what the tactile controller sees)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import numpy as np
import pybullet as p

from experiments.pomares2011.exp3_config import DROP_M, FINGERS, N_FINGERS
from experiments.pomares2011.object_rest import (
    support_distance,
)
from repro.geometry import inv_T
from repro.runs.columns import Columns
from repro.sim import barrett as B
from repro.sim.robot import JointSet, Robot
from repro.sim.scene import Scene
from repro.sim.world import pb_to_pose, pose_to_pb

# ============================================================================ sensors


class FingerTorques(NamedTuple):
    """The joint motor torques of the last physics step [N m] (what the Pucks' currents give).

    Attributes:
        proximal, distal: (3,) PyBullet's applied motor torque of each finger's joints
            (engaged: the distal's motor is off, the proximal carries the gear's load).
        finger: (3,) the largest |torque| of each finger (Algorithm 1, line 7).
    """

    proximal: np.ndarray
    distal: np.ndarray
    finger: np.ndarray


class FingerTorqueSensor:
    """The fingers' joint motor torques, read every control step (episode Sensor protocol)."""

    name = "finger_torque"

    def __init__(self, hand: Robot) -> None:
        self.hand = hand
        idx = B.bh8_joint_indices(hand.body, hand.client)
        self.joints = [idx[f"bh8_finger{k}_{j}_joint"] for k in FINGERS
                       for j in ("proximal", "distal")]

    def read(self, t: float, q: Mapping[str, np.ndarray]) -> FingerTorques:
        s = p.getJointStates(self.hand.body, self.joints, physicsClientId=self.hand.client)
        tau = np.array([st[3] for st in s]).reshape(3, 2)
        return FingerTorques(tau[:, 0].copy(), tau[:, 1].copy(), np.abs(tau).max(axis=1))

    def columns(self, r: FingerTorques) -> dict[str, float]:
        out: dict[str, float] = {}
        for i in range(N_FINGERS):
            out[f"tau_prox{i + 1}"] = float(r.proximal[i])
            out[f"tau_dist{i + 1}"] = float(r.distal[i])
            out[f"tau{i + 1}"] = float(r.finger[i])
        return out

    def events(self, r: FingerTorques) -> list[tuple[str, str]]:
        return []

    def failure(self, r: FingerTorques) -> str | None:
        return None


class AuditReading(NamedTuple):
    """Ground truth of one control step (audit only: the controller never reads it)."""

    columns: dict[str, float | bool]
    touching: tuple[bool, ...]
    dropped: bool
    T_palm_cylinder: np.ndarray | None = None  # the pose read [m]


class GraspAudit:
    """Ground truth of the grasp (episode Sensor protocol; audit columns only): the
    cylinder's pose in the palm frame (``bh8_palm``) and its displacement from its pose at
    the start of the manipulation, the contacts and the raw normal forces between the hand and
    the cylinder (PyBullet contact points), the hand's distances, the drop flag. It also keeps
    the scene's record of the cylinder's pose current (the runner logs it as a moving body).

    ``reference_now``: True once the manipulation has started (read from the controller's
    phase, never the other way round): the first such step's pose is the grasp pose.
    ``lost_after``: control steps without contact before a ``finger_contact_lost`` event (ours:
    one 33 ms tick; a finger retreating by one trajectory step parts from the cylinder for a
    millisecond or two until the cylinder follows, measured).
    """

    name = "grasp_audit"

    def __init__(self, scene: Scene, hand: Robot, cylinder: str, support: str | tuple[str, ...],
                 reference_now: Callable[[], bool], lost_after: int = 33,
                 dist_of: JointSet | None = None) -> None:
        self.scene, self.hand = scene, hand
        self.cyl = scene[cylinder].ids[0]
        self.cylinder = cylinder
        self.supports = (support,) if isinstance(support, str) else tuple(support)
        self.support_ids = [scene[s].ids[0] for s in self.supports]
        #: whose distances the hand_dist_* columns are (default: the whole hand body)
        self.dist_of: JointSet = hand if dist_of is None else dist_of
        self.reference_now = reference_now
        palm = self.palm = hand.pb_link_index("bh8_palm")
        self.link_owner: dict[int, str] = {}
        for k in FINGERS:
            for part in ("proximal", "distal"):
                self.link_owner[hand.pb_link_index(f"bh8_finger{k}_{part}")] = f"finger{k}"
        self.link_owner[palm] = "palm"
        self.T_ref: np.ndarray | None = None
        self._dropped = False
        self._touch = [False] * N_FINGERS  # contact as last reported by an event
        self._apart = [0] * N_FINGERS  # control steps without contact, per finger
        self.lost_after = lost_after

    def describe(self) -> dict[str, Any]:
        """The link sets behind the audit's columns (issue 17 item 12), for scene.json."""
        c, body = self.hand.client, self.hand.body

        def name(idx: int) -> str:
            if idx == -1:
                return p.getBodyInfo(body, physicsClientId=c)[0].decode()
            return p.getJointInfo(body, idx, physicsClientId=c)[12].decode()

        fingers: dict[str, list[str]] = {}
        for idx, owner in sorted(self.link_owner.items()):
            fingers.setdefault(owner, []).append(name(idx))
        links = getattr(self.dist_of, "links", None)
        return {"contact_links": {**fingers, "meaning": "F_raw<k> / contact<k>: the contacts "
                                  "of these links of finger k; F_raw_palm: the palm's; "
                                  "F_raw_other: any other link of the body"},
                "hand_dist_links": ("every link of the body" if links is None
                                    else [name(i) for i in links]),
                "hand_dist_meaning": "hand_dist_<body>: minimum PyBullet closest-points "
                                     "distance over these links",
                "support_dist": "signed closest-points distance cylinder - support bodies "
                                f"{list(self.supports)}"}

    def read(self, t: float, q: Mapping[str, np.ndarray]) -> AuditReading:
        c = self.hand.client
        pos, quat = p.getBasePositionAndOrientation(self.cyl, physicsClientId=c)
        T_world_cyl = pb_to_pose(pos, quat)  # (the Scene keeps its own copy: refresh_dynamic)
        pos, quat = p.getLinkState(self.hand.body, self.palm, computeForwardKinematics=True,
                                   physicsClientId=c)[4:6]
        T = inv_T(pb_to_pose(pos, quat)) @ T_world_cyl  # the palm moves with an arm
        cols: dict[str, float | bool] = {}
        for a, v in zip("xyz", T[:3, 3], strict=True):
            cols[f"obj_{a}"] = float(v)
        _, q_pc = pose_to_pb(T)
        for a, v in zip(("qx", "qy", "qz", "qw"), q_pc, strict=True):
            cols[f"obj_{a}"] = float(v)
        axis = T[:3, 2]  # the cylinder's axis (its frame's z) in the palm frame
        cols["obj_axis_tilt"] = float(math.acos(min(1.0, abs(float(axis[0])))))
        if self.T_ref is not None:
            d = T[:3, 3] - self.T_ref[:3, 3]
            R = self.T_ref[:3, :3].T @ T[:3, :3]
            rot = float(math.acos(max(-1.0, min(1.0, 0.5 * (np.trace(R) - 1.0)))))
        else:
            d, rot = np.full(3, np.nan), float("nan")
        for a, v in zip("xyz", d, strict=True):
            cols[f"obj_d{a}"] = float(v)
        cols["obj_disp"] = float(np.linalg.norm(d))
        cols["obj_rot"] = rot
        force = dict.fromkeys([f"finger{k}" for k in FINGERS] + ["palm", "other"], 0.0)
        for cp in p.getContactPoints(bodyA=self.cyl, bodyB=self.hand.body, physicsClientId=c):
            force[self.link_owner.get(cp[4], "other")] += float(cp[9])
        on_support = any(len(p.getContactPoints(bodyA=self.cyl, bodyB=sid,
                                                physicsClientId=c)) > 0
                         for sid in self.support_ids)
        touching = tuple(force[f"finger{k}"] > 0.0 for k in FINGERS)
        for k in FINGERS:
            cols[f"contact{k}"] = touching[k - 1]
            cols[f"F_raw{k}"] = force[f"finger{k}"]
        cols["contact_palm"] = force["palm"] > 0.0
        cols["contact_other"] = force["other"] > 0.0
        cols["contact_support"] = on_support
        cols["support_dist"] = support_distance(c, self.cyl, self.support_ids)
        cols["F_raw_palm"] = force["palm"]
        cols["F_raw_other"] = force["other"]
        cols["F_raw_total"] = float(sum(force.values()))
        dists = self.scene.distances(self.dist_of)
        for body in (self.cylinder, *self.supports):
            cols[f"hand_dist_{body}"] = dists[body]
        cols["hand_dist_min"] = min(dists[b] for b in self.supports)
        dropped = bool(self.T_ref is not None and not any(touching) and force["palm"] == 0.0
                       and not on_support and cols["obj_disp"] > DROP_M)
        cols["dropped"] = dropped
        return AuditReading(cols, touching, dropped, T)

    def columns(self, r: AuditReading) -> dict[str, float | bool]:
        return r.columns

    def after_control(self, r: AuditReading) -> dict[str, float]:
        """Called by the runner after the controller of the same step: if that controller
        has just started the manipulation, this step's pose (read before it: the state it
        started from) becomes the reference, and the row gets zero displacement and rotation
        (issue 17: the reference used to be the next step's pose, the start row NaN)."""
        if self.T_ref is None and r.T_palm_cylinder is not None and self.reference_now():
            self.T_ref = r.T_palm_cylinder.copy()
            return {"obj_dx": 0.0, "obj_dy": 0.0, "obj_dz": 0.0, "obj_disp": 0.0,
                    "obj_rot": 0.0}
        return {}

    def events(self, r: AuditReading) -> list[tuple[str, str]]:
        out = []
        for f, now in enumerate(r.touching):
            self._apart[f] = 0 if now else self._apart[f] + 1
            if now and not self._touch[f]:
                self._touch[f] = True
                out.append(("finger_contact", f"audit: finger {f + 1} touches the cylinder"))
            elif self._touch[f] and self._apart[f] == self.lost_after:
                self._touch[f] = False
                out.append(("finger_contact_lost", f"audit: finger {f + 1} has not touched the "
                            f"cylinder for {self.lost_after} control steps (PyBullet contact "
                            "points)"))
        if r.dropped and not self._dropped:
            out.append(("object_dropped", f"audit: the cylinder touches no finger, no palm and "
                        f"no support and is {float(r.columns['obj_disp']) * 1e3:.1f} mm from "
                        "its pose at the start of the manipulation"))
        self._dropped = r.dropped
        return out

    def failure(self, r: AuditReading) -> str | None:
        return None


# ============================================================================ columns
def declare_hand_joint_columns(cols: Columns) -> Columns:
    """``hand_q{i}``: the measured angle of each of the standalone hand's eight joints (its
    q columns in scene.json; the runner logs the finger motors)."""
    for i, j in enumerate(B.BH8_JOINTS, start=1):
        cols.add(f"hand_q{i}", "rad", f"measured angle of hand joint {i} ({j}; PyBullet joint "
                 "state)")
    return cols


def hand_joint_values(q_hand: np.ndarray) -> dict[str, float]:
    """The ``hand_q{i}`` values of the hand's joint angles ``q_hand`` (8,) [rad]."""
    return {f"hand_q{i}": float(v) for i, v in enumerate(q_hand, start=1)}


#: Phases of the controller (column ``phase``).
