"""pomares2011 experiment 3: the planned finger trajectory (ours, standing in for the
geometric planner of [25]): the motor angles at which each finger first touches the cylinder."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pybullet as p

from experiments.pomares2011.exp3_config import DT, FINGERS, N_FINGERS
from repro.errors import ConfigError
from repro.sim import barrett as B
from repro.sim.world import World, WorldConfig

# ============================================================================ the planner


def plan_contact_motor_angles(radius: float, length: float, z_centre: float,
                              dys: Sequence[float] | np.ndarray) -> np.ndarray:
    """Our stand-in for the geometric planner of [25] (kinematics and contact maintenance,
    no forces): the motor angle [rad] at which each finger, closing with its clutch engaged
    (``q_p = m / 125``, ``q_d = m / 375``), first touches the cylinder at each planned pose.

    In a DIRECT client of its own: the BH8 URDF at the identity, a static cylinder of
    ``radius``, ``length`` [m] with its axis along the hand's x through ``(0, dy, z_centre)``
    (hand frame, [m]); per pose and finger, a bisection (40 halvings) on the motor angle of
    the signed distance between the finger's proximal and distal links and the cylinder
    (PyBullet closest points), the other fingers open.

    Returns:
        (len(dys), 3) motor angles [rad] of fingers 1, 2, 3.

    Raises:
        ConfigError: a pose the finger does not reach before its proximal's 139 deg.
    """
    out = np.zeros((len(dys), N_FINGERS))
    with World(WorldConfig(physics_dt=DT, control_dt=DT)) as world:
        c = world.client
        body = p.loadURDF(str(B.bh8_urdf_path()), useFixedBase=True,
                          flags=p.URDF_USE_IMPLICIT_CYLINDER, physicsClientId=c)
        idx = B.bh8_joint_indices(body, c)
        col = p.createCollisionShape(p.GEOM_CYLINDER, radius=radius, height=length,
                                     physicsClientId=c)
        quat = p.getQuaternionFromEuler([0.0, math.pi / 2, 0.0])
        cyl = p.createMultiBody(0.0, col, -1, [0.0, 0.0, z_centre], quat, physicsClientId=c)

        def set_motor(k: int, m: float) -> None:
            q_p, q_d = B.finger_joints_from_motor(m)
            p.resetJointState(body, idx[f"bh8_finger{k}_proximal_joint"], q_p,
                              physicsClientId=c)
            p.resetJointState(body, idx[f"bh8_finger{k}_distal_joint"], q_d, physicsClientId=c)

        def distance(k: int) -> float:
            d = 1.0
            for link in ("proximal", "distal"):
                for pt in p.getClosestPoints(body, cyl, 0.05,
                                             linkIndexA=idx[f"bh8_finger{k}_{link}"],
                                             physicsClientId=c):
                    d = min(d, pt[8])
            return d

        m_max = B.J2_RATIO * math.radians(139.0)
        for k in FINGERS:
            set_motor(k, 0.0)
        for i, dy in enumerate(dys):
            p.resetBasePositionAndOrientation(cyl, [0.0, float(dy), z_centre], quat,
                                              physicsClientId=c)
            for k in FINGERS:
                set_motor(k, m_max)
                if distance(k) > 0.0:
                    raise ConfigError(f"planner: finger {k} does not reach the cylinder at "
                                      f"dy = {dy * 1e3:.1f} mm")
                lo, hi = 0.0, m_max
                for _ in range(40):
                    mid = 0.5 * (lo + hi)
                    set_motor(k, mid)
                    lo, hi = (mid, hi) if distance(k) > 0.0 else (lo, mid)
                out[i, k - 1] = hi
                set_motor(k, 0.0)
    return out
