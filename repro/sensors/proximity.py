"""Proximity rings: time-of-flight range finders arranged radially on a ring.

thomas2024 Sec. II: ring j carries m_j sensors whose axes are radial and pass
through the ring centre S_j, at radius r_j. Sensor i measures delta_ij, the
distance along its axis n_S_ij from its own position S_j + r_j n_S_ij to the
first obstacle, or the maximum range (1 m) when nothing is detected.

Each sensor is a PyBullet ray cast. Frames: the ring frame F_Sj has its origin
at S_j and its z axis along the ring axis; sensor i (1-based, as in the paper)
points along n_S_i = (cos theta_i, sin theta_i, 0) with
theta_i = theta_0 + 2 pi (i - 1) / m_j.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p

from repro.errors import ConfigError

#: Collision-filter group of the robot's links: rays ignore it, so a ring does
#: not see its own robot (# ours: the paper's rings see only obstacles). PyBullet
#: puts dynamic bodies in group 1 and static ones in group 2 by default.
ROBOT_GROUP = 4
RAY_MASK = 0xFFFF ^ ROBOT_GROUP


@dataclass(frozen=True)
class RingSpec:
    """Geometry and sensor model of one proximity ring.

    Attributes:
        name: ring name (also the URDF frame name of S_j).
        radius: r_j, distance from S_j to each sensor [m].
        n_sensors: m_j.
        max_range: reading when nothing is detected [m] (thomas2024 Sec. V: 1 m).
        min_range: shortest distance the sensor reports [m] (closer returns this).
        theta0: angle of sensor 1 about the ring z axis from the ring x axis [rad].
        noise_std: standard deviation of additive Gaussian noise on detections [m].
    """

    name: str
    radius: float
    n_sensors: int = 18
    max_range: float = 1.0
    min_range: float = 0.0
    theta0: float = 0.0
    noise_std: float = 0.0

    def __post_init__(self) -> None:
        if self.radius <= 0 or self.n_sensors < 1 or self.max_range <= self.min_range:
            raise ConfigError(f"invalid ring {self.name}: radius={self.radius}, "
                              f"n_sensors={self.n_sensors}, range=({self.min_range}, "
                              f"{self.max_range})")

    def directions(self) -> np.ndarray:
        """Sensor axes n_S_i in the ring frame, (m, 3) unit vectors."""
        theta = self.theta0 + 2.0 * np.pi * np.arange(self.n_sensors) / self.n_sensors
        return np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], axis=1)

    def origins(self) -> np.ndarray:
        """Sensor positions r_j n_S_i in the ring frame, (m, 3) [m]."""
        return self.radius * self.directions()


@dataclass(frozen=True)
class RingReading:
    """One scan of a ring.

    Attributes:
        delta: distances (m,) [m]; ``max_range`` where nothing is detected.
        detected: (m,) True where an obstacle is within range.
        hit_body: (m,) PyBullet body id of the hit (-1 when none); ground truth, for
            logging only -- the controller does not use it.
        invalid: (m,) True where the raw reading was not finite and was replaced.
    """

    delta: np.ndarray
    detected: np.ndarray
    hit_body: np.ndarray
    invalid: np.ndarray


class ProximityRing:
    """Ray-cast model of a ring of range finders.

    Args:
        spec: ring geometry and sensor model.
        rng: random generator for the measurement noise (seeded by the run).
    """

    def __init__(self, spec: RingSpec, rng: np.random.Generator | None = None) -> None:
        self.spec = spec
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self._dirs = spec.directions()
        self._origins = spec.origins()
        self._last_valid = np.full(spec.n_sensors, spec.max_range)

    def cast(self, client: int, T_world_ring: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw ray casts: (distance (m,) [m] or max_range, hit body ids (m,))."""
        R, t = T_world_ring[:3, :3], T_world_ring[:3, 3]
        start = self._origins @ R.T + t
        end = start + self.spec.max_range * (self._dirs @ R.T)
        hits = p.rayTestBatch(
            start.tolist(), end.tolist(), collisionFilterMask=RAY_MASK,
            physicsClientId=client,
        )
        frac = np.array([h[2] if h[0] >= 0 else 1.0 for h in hits])
        body = np.array([h[0] for h in hits], dtype=int)
        return frac * self.spec.max_range, body

    def read(self, client: int, T_world_ring: np.ndarray) -> RingReading:
        """Scan the ring at pose ``T_world_ring``: noisy, clipped, NaN-safe readings.

        A non-finite raw value (a sensor fault) is replaced by the sensor's last
        valid reading and flagged in ``invalid`` so the caller logs an event.
        """
        dist, body = self.cast(client, T_world_ring)
        return self.sanitize(dist, body)

    def sanitize(self, dist: np.ndarray, body: np.ndarray) -> RingReading:
        """Apply noise, range limits and the fault policy to raw distances [m]."""
        s = self.spec
        detected = np.isfinite(dist) & (dist < s.max_range)
        noisy = dist.astype(float).copy()
        if s.noise_std > 0:
            noise = self.rng.normal(0.0, s.noise_std, size=dist.shape)
            noisy[detected] += noise[detected]
        invalid = ~np.isfinite(noisy)
        noisy[invalid] = self._last_valid[invalid]
        noisy = np.clip(noisy, s.min_range, s.max_range)
        noisy[~detected & ~invalid] = s.max_range
        self._last_valid = noisy.copy()
        return RingReading(delta=noisy, detected=detected & ~invalid, hit_body=body,
                           invalid=invalid)


def exclude_from_rays(client: int, body: int) -> None:
    """Put every link of ``body`` in ROBOT_GROUP so proximity rays ignore it.

    Collisions between the robot and obstacles are unaffected (the masks stay
    all-ones).
    """
    for link in range(-1, p.getNumJoints(body, physicsClientId=client)):
        p.setCollisionFilterGroupMask(body, link, ROBOT_GROUP, -1, physicsClientId=client)
