"""Joint drives: how a command reaches a simulated robot, saturated as a real drive would.

Three actuation modes, one class each. A drive takes the controller's command once per
control period (:meth:`Drive.command`, which returns the command as the drive applies it,
saturated) and acts before every physics step of the period (:meth:`Drive.substep`).
Whatever the controller asks, a joint never moves faster than ``qd_max`` (the drive clips
the command and the simulation clamps the joint speed, see :class:`repro.sim.robot.Robot`)
and never gets more than ``tau_max``.

* :class:`VelocityDrive` -- joint velocity at the control rate (thomas2024): PyBullet's
  velocity motor with force limit ``tau_max``, target clipped to ``+-qd_max``.
* :class:`PositionReferenceDrive` -- a velocity command turned into a quintic position
  reference tracked at the physics rate (chan2011 Sec. V-A5): ``"pd"`` with PyBullet's
  joint PD (force <= ``tau_max``), or ``"kinematic"``, an ideal drive that follows the
  reference exactly up to the joint speed limit (the paper's Sec. III simulation).
* :class:`TorqueDrive` -- joint torque at the physics rate (pomares2011), clipped to
  ``+-tau_max``; PyBullet's default velocity motors are switched off first.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import pybullet as p

from repro.control.interpolation import quintic, quintic_lists
from repro.errors import UnknownChoiceError
from repro.sim.robot import JointSet

__all__ = ["ACTUATION_MODES", "Drive", "PositionReferenceDrive", "TorqueDrive", "VelocityDrive"]

ACTUATION_MODES = ("velocity", "position_reference", "torque")

#: Force limit of the ideal ("kinematic") drive [N m]: large enough to follow any reference.
IDEAL_DRIVE_FORCE = 1.0e5


class Drive(Protocol):
    """What the episode runner needs of a drive."""

    robot: JointSet
    mode: str
    unit: str  # unit of the command [rad/s or N m]

    def command(self, u: np.ndarray, dt: float) -> np.ndarray:
        """Take the command of a control period of ``dt`` [s]; return it as applied."""
        ...

    def substep(self, i: int, h: float) -> None:
        """Act before physics step ``i`` (1-based) of the period, ``h`` = physics step [s]."""
        ...

    def safe_command(self) -> np.ndarray:
        """The command that stops the robot safely (sent when the controller's is unusable)."""
        ...


class VelocityDrive:
    """Joint velocity commands [rad/s], held for the control period."""

    mode = "velocity"
    unit = "rad/s"

    def __init__(self, robot: JointSet) -> None:
        self.robot = robot
        self.qd_max = np.asarray(robot.limits.qd_max, dtype=float)
        robot.velocity_mode()

    def command(self, u: np.ndarray, dt: float) -> np.ndarray:
        applied = np.clip(np.asarray(u, dtype=float), -self.qd_max, self.qd_max)
        self.robot.set_velocity_command(applied)
        return applied

    def substep(self, i: int, h: float) -> None:
        return None

    def safe_command(self) -> np.ndarray:
        return np.zeros(self.robot.n)


def clip_nonzero(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``np.clip(x, lo, hi)`` for bounds with no zero (NaN propagates as in np.clip), without
    np.clip's wrapper: the same values (the two differ only on a zero bound, where np.clip
    gives +0.0 and np.maximum keeps -0.0)."""
    return np.minimum(np.maximum(x, lo), hi)


class PositionReferenceDrive:
    """A velocity command ``qd`` [rad/s] becomes the quintic reference from
    ``(q_ref, v_ref)`` to ``(q_ref + dt qd, qd)`` over the period, tracked at every physics
    step (chan2011 Sec. V-A5). ``qd`` is clipped to ``qd_max`` and the target to the joint
    range first.

    Args:
        robot: the robot.
        inner: ``"pd"`` (PyBullet joint PD, force <= tau_max, ``position_gain``) or
            ``"kinematic"`` (ideal velocity source: target velocity ``v_ref + (q_ref - q)/h``
            clipped to ``qd_max``, force :data:`IDEAL_DRIVE_FORCE`).
    """

    mode = "position_reference"
    unit = "rad/s"
    INNER = ("pd", "kinematic")

    def __init__(self, robot: JointSet, inner: str = "pd", position_gain: float = 0.2) -> None:
        if inner not in self.INNER:
            raise UnknownChoiceError("inner loop", inner, self.INNER)
        self.robot, self.inner, self.gain = robot, inner, position_gain
        self.qd_max = np.asarray(robot.limits.qd_max, dtype=float)
        #: no velocity bound is zero: the clips to +-qd_max may skip np.clip's wrapper
        #: (clip_nonzero, or min/max of Python floats), with the same values
        self._fast_clip = bool(np.all(self.qd_max > 0.0))
        self._qd_bounds = list(zip((-self.qd_max).tolist(), self.qd_max.tolist(), strict=True))
        self.q_min = np.asarray(robot.limits.q_min, dtype=float)
        self.q_max = np.asarray(robot.limits.q_max, dtype=float)
        self.q_ref = robot.q()
        self.v_ref = np.zeros(robot.n)
        self._from = (self.q_ref, self.v_ref)
        self._dt = 0.0

    def command(self, u: np.ndarray, dt: float) -> np.ndarray:
        qd = self._clip_qd(np.asarray(u, dtype=float))
        target = np.clip(self.q_ref + dt * qd, self.q_min, self.q_max)
        self._from = (self.q_ref, self.v_ref)
        self.q_ref, self.v_ref, self._dt = target, qd, dt
        return qd

    def _clip_qd(self, qd: np.ndarray) -> np.ndarray:
        """``qd`` clipped to +-qd_max [rad/s] (np.clip's values)."""
        if self._fast_clip:
            return clip_nonzero(qd, -self.qd_max, self.qd_max)
        return np.clip(qd, -self.qd_max, self.qd_max)

    def substep(self, i: int, h: float) -> None:
        q0, v0 = self._from
        if self.inner == "pd" and self._fast_clip:
            got = quintic_lists(q0, v0, self.q_ref, self.v_ref, self._dt, i * h)
            if got is not None:  # in Python floats: the same values as below
                qr_l, vr_l = got
                vr_l = [min(max(v, lo), hi)  # np.clip's, no bound being zero
                        for v, (lo, hi) in zip(vr_l, self._qd_bounds, strict=True)]
                self.robot.set_position_command(qr_l, vr_l, position_gain=self.gain)
                return
        qr, vr = quintic(q0, v0, self.q_ref, self.v_ref, self._dt, i * h)
        vr = self._clip_qd(vr)
        if self.inner == "pd":
            self.robot.set_position_command(qr, vr, position_gain=self.gain)
            return
        v = np.clip((qr - self.robot.q()) / h, -self.qd_max, self.qd_max)
        p.setJointMotorControlArray(
            self.robot.body, self.robot.pb_joints, p.VELOCITY_CONTROL,
            targetVelocities=v.tolist(), forces=[IDEAL_DRIVE_FORCE] * self.robot.n,
            physicsClientId=self.robot.client)

    def safe_command(self) -> np.ndarray:
        return np.zeros(self.robot.n)


class TorqueDrive:
    """Joint torque commands [N m], clipped to ``+-tau_max`` and re-applied before every
    physics step (a PyBullet torque lasts one step). Use with control rate = physics rate
    for a torque controller."""

    mode = "torque"
    unit = "N m"

    def __init__(self, robot: JointSet) -> None:
        self.robot = robot
        self.tau_max = np.asarray(robot.limits.tau_max, dtype=float)
        self._tau = np.zeros(robot.n)
        self._forces: list[float] | None = None
        robot.torque_mode()

    def command(self, u: np.ndarray, dt: float) -> np.ndarray:
        self._tau = np.clip(np.asarray(u, dtype=float), -self.tau_max, self.tau_max)
        self._forces = None
        return self._tau

    def substep(self, i: int, h: float) -> None:
        # the command is within +-tau_max already (set_torque_command's clip would return
        # it as it is): the same forces, listed once per command
        if self._forces is None:
            self._forces = self._tau.tolist()
        p.setJointMotorControlArray(self.robot.body, self.robot.pb_joints, p.TORQUE_CONTROL,
                                    forces=self._forces, physicsClientId=self.robot.client)

    def safe_command(self) -> np.ndarray:
        # Hold against gravity (a drive's brake would do the same).
        return np.clip(self.robot.gravity_torques(self.robot.q()), -self.tau_max, self.tau_max)
