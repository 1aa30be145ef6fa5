"""The simulated world: one PyBullet DIRECT client per run.

A fresh client per run, a fixed physics step and an integer number of physics
steps per control step are what make runs deterministic (same config, same
trace). Clients cannot be pickled across processes, so each run (or worker
process) creates its own :class:`World`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import TracebackType

import numpy as np
import pybullet as p

from repro.errors import ConfigError


@dataclass(frozen=True)
class WorldConfig:
    """Time base and gravity of a world.

    Attributes:
        physics_dt: physics step [s].
        control_dt: control period [s]; must be an integer multiple of physics_dt.
        gravity: gravity vector in the world frame [m/s^2].
        solver_iterations: PyBullet constraint-solver iterations per physics step.
    """

    physics_dt: float = 1.0 / 240.0
    control_dt: float = 1.0 / 30.0
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    solver_iterations: int = 50

    @property
    def steps_per_control(self) -> int:
        """Integer physics/control ratio (raises if the periods do not divide)."""
        ratio = self.control_dt / self.physics_dt
        n = int(round(ratio))
        if n < 1 or abs(ratio - n) > 1e-9 * max(1.0, ratio):
            raise ConfigError(
                f"control_dt={self.control_dt} s is not an integer multiple of "
                f"physics_dt={self.physics_dt} s (ratio {ratio:.6g})"
            )
        return n


class World:
    """A PyBullet DIRECT client with a fixed time base.

    Use as a context manager so the client is always disconnected.
    """

    def __init__(self, config: WorldConfig | None = None) -> None:
        self.config = config or WorldConfig()
        self.steps_per_control = self.config.steps_per_control
        self.client = p.connect(p.DIRECT)
        p.resetSimulation(physicsClientId=self.client)
        p.setTimeStep(self.config.physics_dt, physicsClientId=self.client)
        p.setGravity(*self.config.gravity, physicsClientId=self.client)
        p.setPhysicsEngineParameter(
            numSolverIterations=self.config.solver_iterations,
            deterministicOverlappingPairs=1,
            physicsClientId=self.client,
        )
        self.physics_steps = 0

    @property
    def t(self) -> float:
        """Simulated time since creation [s]."""
        return self.physics_steps * self.config.physics_dt

    def step_physics(self) -> None:
        """Advance one physics step."""
        p.stepSimulation(physicsClientId=self.client)
        self.physics_steps += 1

    def step_control(self) -> None:
        """Advance one control period (``steps_per_control`` physics steps)."""
        for _ in range(self.steps_per_control):
            self.step_physics()

    def add_box(
        self,
        half_extents: tuple[float, float, float],
        T_world_box: np.ndarray,
        rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0),
        collision: bool = True,
    ) -> int:
        """Add a static box [m] at pose ``T_world_box``; returns its body id."""
        col = (
            p.createCollisionShape(p.GEOM_BOX, halfExtents=half_extents,
                                   physicsClientId=self.client)
            if collision
            else -1
        )
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half_extents, rgbaColor=rgba,
                                  physicsClientId=self.client)
        pos, quat = pose_to_pb(T_world_box)
        return p.createMultiBody(0.0, col, vis, pos, quat, physicsClientId=self.client)

    def close(self) -> None:
        """Disconnect the client (idempotent)."""
        if self.client >= 0:
            try:
                p.disconnect(physicsClientId=self.client)
            except p.error:
                pass
            self.client = -1

    def __enter__(self) -> World:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def pose_to_pb(T: np.ndarray) -> tuple[list[float], list[float]]:
    """4x4 homogeneous transform -> (position [m], quaternion xyzw) for PyBullet.

    The rotation part must be a rotation matrix. The quaternion is the one scipy's
    ``Rotation.from_matrix(R).as_quat()`` gives (the same branch on the largest of the
    diagonal and the trace, then normalised), computed here directly: this runs for every
    moving body and camera at every control step."""
    (r00, r01, r02, x), (r10, r11, r12, y), (r20, r21, r22, z) = np.asarray(
        T, dtype=float)[:3].tolist()  # Python floats: the same IEEE arithmetic, less overhead
    tr = r00 + r11 + r22
    diag = (r00, r11, r22, tr)
    choice = diag.index(max(diag))  # the first largest, as np.argmax
    if choice == 3:
        q = [r21 - r12, r02 - r20, r10 - r01, 1.0 + tr]
    else:
        R = ((r00, r01, r02), (r10, r11, r12), (r20, r21, r22))
        i = choice
        j, k = (i + 1) % 3, (i + 2) % 3
        q = [0.0, 0.0, 0.0, R[k][j] - R[j][k]]
        q[i] = 1.0 - tr + 2.0 * R[i][i]
        q[j] = R[j][i] + R[i][j]
        q[k] = R[k][i] + R[i][k]
    qa = np.array(q)
    # numpy's dot, as before (its summation order is BLAS's); then the same correctly
    # rounded square root and divisions as numpy's, in Python floats
    n2 = float(qa @ qa)
    if not n2 > 0.0:  # (not a rotation: numpy's 0/0 or NaN, as before)
        qa /= np.sqrt(n2)
        return [x, y, z], qa.tolist()
    n = math.sqrt(n2)
    return [x, y, z], [q[0] / n, q[1] / n, q[2] / n, q[3] / n]


def pb_to_pose(pos: tuple[float, ...], quat: tuple[float, ...]) -> np.ndarray:
    """(position [m], quaternion xyzw) from PyBullet -> 4x4 homogeneous transform."""
    T = np.eye(4)
    T[:3, :3] = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
    T[:3, 3] = pos
    return T
