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

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pybullet as p

from repro.errors import ConfigError, UnknownChoiceError

#: What a cone of rays reports (:class:`RingSpec`).
CONE_RETURNS = ("nearest", "weighted")

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
        fov_deg: full angle of each sensor's field of view [deg]; 0 (default): one ray
            along the axis, the paper's "detects along its axis". VL53L-class ToF parts
            have a 25-27 deg cone (issue 17: an option, so that the sweep can vary it).
        cone_rings, cone_azimuths: rays of a cone: the axis plus ``cone_rings`` circles
            at ``k / cone_rings`` of the half-angle, ``cone_azimuths`` rays each.
        cone_return: what a cone reports: ``"nearest"`` (the shortest return of its
            rays, how a ToF's first photons read) or ``"weighted"`` (the mean of the
            returns of the rays that hit, each weighted by the cosine of its angle to the
            axis: a lens's fall-off, ours).
    """

    name: str
    radius: float
    n_sensors: int = 18
    max_range: float = 1.0
    min_range: float = 0.0
    theta0: float = 0.0
    noise_std: float = 0.0
    fov_deg: float = 0.0
    # ours: 1 + 2 x 8 rays sample a 27 deg cone every 6.75 deg, finer than the 25-27 deg
    # parts' own zones; a thin object between rays is missed (the tests' 6 mm pole needs 4 x 16)
    cone_rings: int = 2
    cone_azimuths: int = 8
    cone_return: str = "nearest"  # ours: a ToF's first photons come from the nearest surface

    def __post_init__(self) -> None:
        if self.radius <= 0 or self.n_sensors < 1 or self.max_range <= self.min_range:
            raise ConfigError(f"invalid ring {self.name}: radius={self.radius}, "
                              f"n_sensors={self.n_sensors}, range=({self.min_range}, "
                              f"{self.max_range})")
        if not 0.0 <= self.fov_deg < 180.0 or self.cone_rings < 1 or self.cone_azimuths < 3:
            raise ConfigError(f"invalid cone of ring {self.name}: fov_deg={self.fov_deg} "
                              f"(in [0, 180)), cone_rings={self.cone_rings} (>= 1), "
                              f"cone_azimuths={self.cone_azimuths} (>= 3)")
        if self.cone_return not in CONE_RETURNS:
            raise UnknownChoiceError("cone return", self.cone_return, CONE_RETURNS)

    def cone(self) -> tuple[np.ndarray, np.ndarray]:
        """Rays of one sensor's field of view in the sensor frame (axis = x, ring axis = z):
        (k, 3) unit directions and their (k,) angles to the axis [rad]; the axis alone
        when ``fov_deg`` is 0."""
        if self.fov_deg == 0.0:
            return np.array([[1.0, 0.0, 0.0]]), np.zeros(1)
        half = np.radians(self.fov_deg) / 2.0
        dirs, angles = [[1.0, 0.0, 0.0]], [0.0]
        for k in range(1, self.cone_rings + 1):
            a = half * k / self.cone_rings
            for j in range(self.cone_azimuths):
                phi = 2.0 * np.pi * j / self.cone_azimuths
                dirs.append([np.cos(a), np.sin(a) * np.cos(phi), np.sin(a) * np.sin(phi)])
                angles.append(a)
        return np.asarray(dirs), np.asarray(angles)

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
        true_delta: (m,) noise-free ray-cast distance [m] (ground truth, for the audit
            columns only; max_range when nothing is hit); None when not known.
        failed: (m,) True where the sensor has given ``max_consecutive_faults`` or more
            non-finite readings in a row (see :class:`ProximityRing`); None: no fault policy.
        true_normal: (m, 3) unit surface normal at the noise-free hit, world frame
            (PyBullet's hit normal, facing the sensor; for a cone its nearest ray's), NaN rows
            where nothing is hit; ground truth for the audit columns only; None: not known.
    """

    delta: np.ndarray
    detected: np.ndarray
    hit_body: np.ndarray
    invalid: np.ndarray
    true_delta: np.ndarray | None = None
    failed: np.ndarray | None = None
    true_normal: np.ndarray | None = None


class ProximityRing:
    """Ray-cast model of a ring of range finders.

    Fault policy (a non-finite raw reading is a fault; flagged in ``RingReading.invalid``):

    * with ``fault_value`` set (what :class:`RingSensor` does: the ring's threshold delta*),
      a faulty sensor reads ``fault_value``: an obstacle at the threshold, so its CBF row
      forbids any motion towards it -- the conservative reading, never "nothing in range";
      after ``max_consecutive_faults`` faults in a row the sensor has *failed*
      (``RingReading.failed``) and :meth:`RingSensor.failure` stops the run safely;
    * with ``fault_value=None`` (legacy), the sensor's last valid reading is held.

    Args:
        spec: ring geometry and sensor model.
        rng: random generator for the measurement noise (seeded by the run).
        fault_value: reading of a faulty sensor [m], or None to hold the last valid one.
        max_consecutive_faults: faults in a row after which a sensor has failed.
    """

    def __init__(self, spec: RingSpec, rng: np.random.Generator | None = None,
                 fault_value: float | None = None, max_consecutive_faults: int = 3) -> None:
        self.spec = spec
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self._dirs = spec.directions()
        self._origins = spec.origins()
        # the cone's rays of every sensor in the ring frame: (m, k, 3); the sensor frame's
        # x is n_S_i, its z the ring axis, its y = z x n_S_i
        cone, self._cone_angles = spec.cone()
        z = np.array([0.0, 0.0, 1.0])
        y = np.cross(z, self._dirs)
        self._cone = (cone[None, :, 0:1] * self._dirs[:, None, :]
                      + cone[None, :, 1:2] * y[:, None, :] + cone[None, :, 2:3] * z)
        self._last_valid = np.full(spec.n_sensors, spec.max_range)
        #: world-frame hit normals of the last :meth:`cast` (NaN rows: no hit; ground truth)
        self.last_normals = np.full((spec.n_sensors, 3), np.nan)
        self.fault_value = fault_value
        self.max_consecutive_faults = int(max_consecutive_faults)
        self._fault_run = np.zeros(spec.n_sensors, dtype=int)

    def cast(self, client: int, T_world_ring: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw ray casts: (distance (m,) [m] or max_range, hit body ids (m,))."""
        R, t = T_world_ring[:3, :3], T_world_ring[:3, 3]
        start = self._origins @ R.T + t
        if self.spec.fov_deg == 0.0:  # one ray per sensor, along its axis
            end = start + self.spec.max_range * (self._dirs @ R.T)
            hits = p.rayTestBatch(
                start.tolist(), end.tolist(), collisionFilterMask=RAY_MASK,
                physicsClientId=client,
            )
            frac = np.array([h[2] if h[0] >= 0 else 1.0 for h in hits])
            body = np.array([h[0] for h in hits], dtype=int)
            self.last_normals = np.array([h[4] if h[0] >= 0 else (np.nan,) * 3 for h in hits],
                                         dtype=float).reshape(-1, 3)
            return frac * self.spec.max_range, body
        return self._cast_cone(client, R, start)

    def _cast_cone(self, client: int, R: np.ndarray, start: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Every ray of every sensor's cone; per sensor its ``cone_return`` and the body of
        its nearest hit."""
        m, k = self._cone.shape[:2]
        s = np.repeat(start, k, axis=0)
        end = s + self.spec.max_range * (self._cone.reshape(-1, 3) @ R.T)
        hits = p.rayTestBatch(s.tolist(), end.tolist(), collisionFilterMask=RAY_MASK,
                              physicsClientId=client)
        body = np.array([h[0] for h in hits], dtype=int).reshape(m, k)
        d = np.array([h[2] if h[0] >= 0 else 1.0 for h in hits]).reshape(m, k)
        d = d * self.spec.max_range
        hit: np.ndarray = np.asarray(body >= 0)
        nearest = np.where(hit, d, np.inf).argmin(axis=1)
        rows = np.arange(m)
        out_body = np.where(hit.any(axis=1), body[rows, nearest], -1)
        normals = np.array([h[4] if h[0] >= 0 else (np.nan,) * 3 for h in hits],
                           dtype=float).reshape(m, k, 3)
        any_hit: np.ndarray = np.asarray(hit.any(axis=1))
        self.last_normals = np.where(any_hit[:, None], normals[rows, nearest], np.nan)
        if self.spec.cone_return == "nearest":
            out = np.where(hit.any(axis=1), d[rows, nearest], self.spec.max_range)
        else:
            w = np.cos(self._cone_angles)[None, :] * hit
            wsum = w.sum(axis=1)
            out = np.where(wsum > 0, (w * d).sum(axis=1) / np.where(wsum > 0, wsum, 1.0),
                           self.spec.max_range)
        return out, out_body

    def read(self, client: int, T_world_ring: np.ndarray) -> RingReading:
        """Scan the ring at pose ``T_world_ring``: noisy, clipped, NaN-safe readings.

        A non-finite raw value (a sensor fault) is replaced by the sensor's last
        valid reading and flagged in ``invalid`` so the caller logs an event.
        """
        dist, body = self.cast(client, T_world_ring)
        reading = self.sanitize(dist, body)
        return dataclasses.replace(reading, true_delta=dist, true_normal=self.last_normals)

    def sanitize(self, dist: np.ndarray, body: np.ndarray) -> RingReading:
        """Apply noise, range limits and the fault policy to raw distances [m]."""
        s = self.spec
        detected = np.isfinite(dist) & (dist < s.max_range)
        noisy = dist.astype(float).copy()
        if s.noise_std > 0:
            noise = self.rng.normal(0.0, s.noise_std, size=dist.shape)
            noisy[detected] += noise[detected]
        invalid = ~np.isfinite(noisy)
        self._fault_run = np.where(invalid, self._fault_run + 1, 0)
        noisy[invalid] = (self._last_valid[invalid] if self.fault_value is None
                          else self.fault_value)
        noisy = np.clip(noisy, s.min_range, s.max_range)
        noisy[~detected & ~invalid] = s.max_range
        self._last_valid = np.where(invalid, self._last_valid, noisy)
        failed = (self._fault_run >= self.max_consecutive_faults
                  if self.fault_value is not None else None)
        return RingReading(delta=noisy, detected=detected & ~invalid, hit_body=body,
                           invalid=invalid, failed=failed)


RAY_MODEL = (
    "sensor i of a ring: ray from S_j + r_j n_i (on the ring's outer surface) along n_i, "
    "length max_range, pybullet.rayTestBatch with collisionFilterMask = 0xFFFF ^ 4: the "
    "robot's links (collision group 4) are ignored, every other body is seen; reading = "
    "hit fraction * max_range plus N(0, noise_std) noise on hits only, clipped to "
    "[min_range, max_range]; no hit -> max_range (the 'no detection' value); a non-finite "
    "reading is a fault: the sensor reads its ring's threshold delta* (an obstacle at the "
    "threshold) and the fault is an event; 3 faults in a row and the sensor has failed: "
    "the run stops safely (zero velocity, status failed)")


CONE_MODEL = (
    "sensor i of a ring: rays from S_j + r_j n_i over a cone of full angle cone.fov_deg about "
    "n_i: the axis plus cone.rings circles at k / rings of the half-angle, cone.azimuths rays "
    "each (in the sensor frame x = n_i, z = the ring axis, y = z x n_i: direction (cos a, "
    "sin a cos phi, sin a sin phi)); each ray as in the single-ray model; the reading is the "
    "nearest return "
    "(return = nearest) or the mean of the returns of the rays that hit weighted by the cosine "
    "of each ray's angle to n_i (return = weighted); noise, range limits and faults as in the "
    "single-ray model")


class RingSensor:
    """A :class:`ProximityRing` on a robot frame, read by the episode runner every step.

    Trace columns (prefix ``r{k}_``): ``d{i}`` the reading [m], ``dtrue{i}`` the noise-free
    ray distance (audit), ``cbf{i}`` = reading - threshold [m].

    Args:
        ring: the ring (spec, noise generator).
        robot: the robot carrying it (a :class:`repro.sim.robot.Robot`).
        frame: the robot frame at the ring centre S_j (z along the ring axis).
        client: physics client to cast rays in.
        prefix: column prefix, e.g. ``"r1_"``.
        threshold: delta* of the ring [m] (for the ``cbf`` columns).
        on_read: called with (T_world_ring, reading) after each scan (normal estimation).
    """

    def __init__(self, ring: ProximityRing, robot: Any, frame: str, client: int, prefix: str,
                 threshold: float, on_read: Any = None) -> None:
        self.ring, self.robot, self.frame, self.client = ring, robot, frame, client
        self.name = ring.spec.name
        self.prefix, self.threshold, self.on_read = prefix, threshold, on_read
        ring.fault_value = threshold  # a faulty sensor reads an obstacle at its threshold

    def read(self, t: float, q: Mapping[str, np.ndarray]) -> RingReading:
        T = self.robot.frame_pose(self.frame, q[self.robot.name])
        reading = self.ring.read(self.client, T)
        if self.on_read is not None:
            self.on_read(T, reading)
        return reading

    def columns(self, r: RingReading) -> dict[str, float]:
        out: dict[str, float] = {}
        true = r.true_delta if r.true_delta is not None else np.full_like(r.delta, np.nan)
        for i in range(self.ring.spec.n_sensors):
            out[f"{self.prefix}d{i + 1}"] = float(r.delta[i])
        for i in range(self.ring.spec.n_sensors):
            out[f"{self.prefix}dtrue{i + 1}"] = float(true[i])
        for i in range(self.ring.spec.n_sensors):
            out[f"{self.prefix}cbf{i + 1}"] = float(r.delta[i] - self.threshold)
        return out

    def events(self, r: RingReading) -> list[tuple[str, str]]:
        if np.any(r.invalid):
            held = (f"read as an obstacle at the threshold ({self.threshold} m)"
                    if self.ring.fault_value is not None else "held their last value")
            return [("sensor_nan", f"{self.name} sensors "
                     f"{(np.flatnonzero(r.invalid) + 1).tolist()} non-finite: {held}")]
        return []

    def failure(self, r: RingReading) -> str | None:
        """A sensor that gave ``max_consecutive_faults`` non-finite readings in a row."""
        if r.failed is not None and np.any(r.failed):
            return (f"{self.name} sensors {(np.flatnonzero(r.failed) + 1).tolist()} gave "
                    f"{self.ring.max_consecutive_faults} non-finite readings in a row")
        return None

    def declare(self, cols: Any) -> None:
        """Declare this ring's columns in a :class:`repro.runs.columns.Columns`."""
        n, s = self.ring.spec.n_sensors, self.name
        cols.add(f"{self.prefix}d{{i}}", "m", f"{s} sensor {{i}}: range reading delta "
                 f"(max_range = {self.ring.spec.max_range} m when nothing is detected)", n=n)
        cols.add(f"{self.prefix}dtrue{{i}}", "m", f"audit: {s} sensor {{i}}: noise-free ray "
                 "distance", n=n, audit=True)
        cols.add(f"{self.prefix}cbf{{i}}", "m", f"{s} sensor {{i}}: CBF e_delta = delta - "
                 f"delta* (delta* = {self.threshold} m)", n=n)

    def describe(self) -> dict[str, Any]:
        """The sensor model for scene.json."""
        s = self.ring.spec
        return {"kind": "tof_ring", "robot": self.robot.name, "frame": self.frame,
                "radius": s.radius, "n_sensors": s.n_sensors, "max_range": s.max_range,
                "min_range": s.min_range, "noise_std": s.noise_std, "theta0": s.theta0,
                "sensor_axes_ring_frame": s.directions(),
                "ray_model": RAY_MODEL if s.fov_deg == 0.0 else CONE_MODEL,
                "cone": {"fov_deg": s.fov_deg, "rings": s.cone_rings,
                         "azimuths": s.cone_azimuths, "return": s.cone_return},
                "ray_filter": {"collision_filter_mask": RAY_MASK,
                               "robot_links_collision_group": ROBOT_GROUP,
                               "robots_in_group": [self.robot.name],
                               "pybullet": "p.setCollisionFilterGroupMask(robot, link, 4, -1) "
                                           "for every link of those robots; rays use "
                                           "collisionFilterMask"},
                "column_prefix": self.prefix,
                "columns": {"reading": [f"{self.prefix}d{i + 1}" for i in range(s.n_sensors)],
                            "true_distance": [f"{self.prefix}dtrue{i + 1}"
                                              for i in range(s.n_sensors)],
                            "cbf": [f"{self.prefix}cbf{i + 1}" for i in range(s.n_sensors)]}}


def exclude_from_rays(client: int, body: int) -> None:
    """Put every link of ``body`` in ROBOT_GROUP so proximity rays ignore it.

    Collisions between the robot and obstacles are unaffected (the masks stay
    all-ones).
    """
    for link in range(-1, p.getNumJoints(body, physicsClientId=client)):
        p.setCollisionFilterGroupMask(body, link, ROBOT_GROUP, -1, physicsClientId=client)
