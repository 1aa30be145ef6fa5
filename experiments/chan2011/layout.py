"""chan2011 experiment layout from a config (issue 19), and the checks of a layout.

The experiment's scene rests on values Sec. V leaves open (the conrod's exact placement,
Table III's hand-measured obstacles, the overhead start, the dots' coordinates). They are
config fields (``conrod_*``, ``<obstacle>_d*``, ``start_*``, ``points_*``, swept in the
experiment setting only); :func:`setting_for` derives from them, by the rules documented at
``scene.SETTINGS``, every pose the run uses:

- the conrod's rest height (:func:`conrod_rest_z`: the lowest centroid z on a 0.1 mm grid at
  which the part penetrates no obstacle; 0.1789 m for the defaults),
- its dots (:func:`conrod_points`), the obstacles (:func:`obstacles`),
- the goal's standoff (:func:`goal_standoff`: the closest, 1 cm grid, with every point 40 px
  inside the image; 0.38 m),
- the start (:func:`overhead_start`: the overhead view's IK solution on the goal's branch,
  the goal solution nearest the home pose; scene.EXPERIMENT_Q0_DEG for the defaults).

A layout the paper's scene could not be (a part resting on nothing or inside an obstacle, a
dot off its face, a start with a point out of view, in collision, or off the goal's IK
branch) raises :class:`~repro.errors.ConfigError`: run.check_config refuses it, and a sweep
records it as a refused variant. Every check is geometric (no run).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pybullet as p

from experiments.chan2011 import scene as sc
from experiments.chan2011.config import EXPERIMENT, OBSTACLE_NAMES, Chan2011Config
from repro.errors import ConfigError, ReproError
from repro.geometry import Ry, Rz, inv_T, trans
from repro.planning.dcc import Box, CollisionModel
from repro.sensors.camera import project_points
from repro.sim.crs_a465 import CRS_JOINTS, CRS_LIMITS, T_FLANGE_CAMERA, crs_urdf_path
from repro.sim.robot import Robot, solve_ik
from repro.sim.scene import Part, Scene
from repro.sim.world import World, WorldConfig

DEG = sc.DEG
Q_MIN, Q_MAX = np.asarray(CRS_LIMITS.q_min), np.asarray(CRS_LIMITS.q_max)
#: the config fields of the experiment's layout (those swept only in the experiment setting)
LAYOUT_FIELDS = tuple(f.name for f in dataclasses.fields(Chan2011Config)
                      if f.metadata.get("sweep") is not None and f.metadata["sweep"].when
                      == EXPERIMENT)
REST_Z_GRID = 1e-4  # ours: the rest height's grid [m] (0.1 mm)
#: ours: the rest height is searched within Sec. V-A3's measured 0.170 m +- 2 cm (a hand
#: measurement); a part resting lower or higher is not the paper's scene
REST_Z_WINDOW = 0.02
VIEW_MARGIN_PX = 40.0  # ours: the start's and goal's points this far inside the image [px]
STANDOFF_GRID = (0.20, 0.80, 0.01)  # ours: the goal standoffs tried (from, to, step) [m]
#: the real camera (the mount error included): the views are what it sees
T_FLANGE_TRUE_CAMERA = T_FLANGE_CAMERA @ sc.T_MOUNT_ERROR


# ------------------------------------------------------------ kinematics helpers
def same_branch(q_a: np.ndarray, q_b: np.ndarray) -> bool:
    """Whether two CRS-A465 configurations lie on one inverse-kinematics branch: the elbow
    (q3) and the wrist (q5) bent the same way and no joint more than 180 deg apart (the
    shoulder flip q1 + 180 deg, q2 -> -q2 reaches the same point from the other side)."""
    return bool(np.sign(q_a[2]) == np.sign(q_b[2]) and np.sign(q_a[4]) == np.sign(q_b[4])
                and np.all(np.abs(q_a - q_b) < np.pi))


def goal_configuration(robot: Robot, setting: sc.Setting) -> np.ndarray:
    """An IK solution for the goal flange pose (deterministic): seeded at the start when
    ``setting.goal_from_start`` (and then on the start's branch), else the first of seeded
    random starts. Raises ReproError when there is none (ConfigError: off the branch)."""
    T_goal = sc.goal_flange_pose(setting)
    if setting.goal_from_start:
        q0 = np.deg2rad(setting.q0_deg)
        q = solve_ik(robot, "flange", T_goal, q0, 300)
        if not same_branch(q, q0):
            raise ConfigError(f"the goal's IK solution {np.rad2deg(q).round(1).tolist()} deg "
                              f"is on another branch than the start {list(setting.q0_deg)}")
        return q
    rng = np.random.default_rng(0)
    for _ in range(200):
        try:
            return solve_ik(robot, "flange", T_goal, rng.uniform(0.9 * Q_MIN, 0.9 * Q_MAX), 300)
        except ReproError:
            continue
    raise ReproError(f"no IK solution for the goal flange pose {T_goal[:3, 3]}")


def goal_nearest_home(robot: Robot, T_goal: np.ndarray, n_seeds: int = 60) -> np.ndarray:
    """The goal's IK branch (scene.SETTINGS): of the IK solutions from ``n_seeds`` seeded
    random starts (95 % of the joint ranges), the one nearest the home pose q = 0 (L1)."""
    rng = np.random.default_rng(0)
    sols: list[np.ndarray] = []
    for _ in range(n_seeds):
        try:
            q = solve_ik(robot, "flange", T_goal, rng.uniform(0.95 * Q_MIN, 0.95 * Q_MAX), 300)
        except ReproError:
            continue
        if not any(np.max(np.abs(q - o)) < 1e-3 for o in sols):
            sols.append(q)
    if not sols:
        raise ConfigError(f"the goal flange pose at {T_goal[:3, 3].round(3).tolist()} m is "
                          "out of the CRS-A465's reach")
    return min(sols, key=lambda q: float(np.abs(q).sum()))


def points_outside(T_base_flange: np.ndarray, points_world: np.ndarray,
                   margin: float = VIEW_MARGIN_PX) -> list[int]:
    """1-based indices of the points the real camera at flange pose ``T_base_flange`` does
    not see ``margin`` [px] inside its image (exact projection; behind it counts)."""
    uv, Z = project_points(sc.TRUE_INTRINSICS, T_base_flange @ T_FLANGE_TRUE_CAMERA,
                             points_world)
    ok = (Z > 0) & (uv[:, 0] > margin) & (uv[:, 0] < sc.IMAGE_W - margin) & (
        uv[:, 1] > margin) & (uv[:, 1] < sc.IMAGE_H - margin)
    return (np.flatnonzero(~ok) + 1).tolist()


def conrod_parts() -> list[Part]:
    """The conrod's primitives (sc.CONROD_PARTS: cylinders (radius, height), boxes (full
    size), centred at the given point of the object frame)."""
    return [Part(shape, tuple(size), trans(*centre)) for shape, size, centre in sc.CONROD_PARTS]


# ------------------------------------------------------------ the layout's pieces
def obstacles(values: dict[str, float]) -> tuple[Box, ...]:
    """Tables II-III's four boxes, each centroid moved by ``<name>_dx``, ``<name>_dy`` [m]
    and turned by ``<name>_dyaw_deg`` [deg] about the vertical (z kept)."""
    out = []
    for name in OBSTACLE_NAMES:
        x, y, z, yaw = sc.TABLE_III[name]
        out.append(Box(name, sc.TABLE_II[name], sc.table_pose(
            x + values[f"{name}_dx"], y + values[f"{name}_dy"], z,
            yaw + values[f"{name}_dyaw_deg"])))
    return tuple(out)


def conrod_pose(x: float, y: float, z: float, yaw_deg: float, tilt_deg: float) -> np.ndarray:
    """The conrod's model-frame pose with its centroid at (x, y, z) [m], tilted ``tilt_deg``
    about the base's y axis after turning ``yaw_deg`` about the vertical (chan2011 Sec. V-A3)."""
    return sc.at_centroid(trans(x, y, z) @ Ry(tilt_deg * DEG) @ Rz(yaw_deg * DEG))


def conrod_rest_z(x: float, y: float, yaw_deg: float, tilt_deg: float,
                  boxes: tuple[Box, ...]) -> float:
    """The conrod's rest height: the lowest centroid z [m] on a 0.1 mm grid at which the part
    penetrates no obstacle (PyBullet closest points, the same test as tests/test_chan2011.py),
    by bisection over Sec. V-A3's 0.170 m +- REST_Z_WINDOW. 0.1789 m for the defaults.

    Raises ConfigError if the part penetrates nothing even at the window's bottom (it rests
    on nothing there) or still penetrates an obstacle at its top."""
    z_meas = sc.CONROD_MEASURED[2]
    lo, hi = (int(round((z_meas - REST_Z_WINDOW) / REST_Z_GRID)),
              int(round((z_meas + REST_Z_WINDOW) / REST_Z_GRID)))
    with Scene(WorldConfig(physics_dt=1e-3, control_dt=0.1)) as s:
        for b in boxes:
            s.add_box(b.name, b.size, b.T_world, sc.OBSTACLE_RGBA)
        s.add_compound("conrod", conrod_parts(), conrod_pose(x, y, 1.0, yaw_deg, tilt_deg),
                       sc.CONROD_RGBA, obstacle=False, moving=True)
        ids = [(i, j) for i in s["conrod"].ids for b in boxes for j in s[b.name].ids]

        def penetrates(k: int) -> bool:
            s.move("conrod", conrod_pose(x, y, k * REST_Z_GRID, yaw_deg, tilt_deg))
            return any(pt[8] < 0.0 for i, j in ids for pt in p.getClosestPoints(
                i, j, 0.05, physicsClientId=s.physics.client))

        if not penetrates(lo):
            raise ConfigError(f"the conrod at ({x:.3f}, {y:.3f}) m, yaw {yaw_deg:g} deg, tilt "
                              f"{tilt_deg:g} deg rests on nothing {REST_Z_WINDOW * 100:g} cm "
                              f"under Sec. V-A3's z = {z_meas} m (its centroid z {lo / 1e4} m)")
        if penetrates(hi):
            raise ConfigError(f"the conrod at ({x:.3f}, {y:.3f}) m, yaw {yaw_deg:g} deg, tilt "
                              f"{tilt_deg:g} deg penetrates an obstacle even {REST_Z_WINDOW * 100:g}"
                              f" cm above Sec. V-A3's z = {z_meas} m")
        while hi - lo > 1:  # invariant: lo penetrates, hi is free
            mid = (lo + hi) // 2
            lo, hi = (lo, mid) if not penetrates(mid) else (mid, hi)
    return hi / 1e4  # k / 1e4: the decimal grid value itself (0.1789, not 0.17890000000000003)


def conrod_points(spread: float, jitter: float, seed: int) -> np.ndarray:
    """The ten dots in the conrod's frame [m]: scene.CONROD_POINTS with each dot's distance
    from its face's centre (the part's axis, sc.CONROD_POINT_PARTS) times ``spread``, then
    moved on its face by ``jitter`` [m] times sqrt(u) in direction a (u, a uniform, drawn from
    ``numpy.random.SeedSequence(seed)``: uniform over a disc). (1, 0, any): CONROD_POINTS."""
    if spread == 1.0 and jitter == 0.0:
        return sc.CONROD_POINTS
    centres = np.array([sc.CONROD_PARTS[k][2] for k in sc.CONROD_POINT_PARTS], float)
    P = sc.CONROD_POINTS.copy()
    P[:, :2] = centres[:, :2] + spread * (P[:, :2] - centres[:, :2])
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    r = jitter * np.sqrt(rng.uniform(size=len(P)))
    a = rng.uniform(0.0, 2 * np.pi, size=len(P))
    P[:, 0] += r * np.cos(a)
    P[:, 1] += r * np.sin(a)
    return P


def points_off_faces(P: np.ndarray, radius: float) -> list[str]:
    """Why dots of radius ``radius`` [m] at ``P`` (conrod frame) are not wholly on their
    faces (cylinder tops; the beam's top outside the bosses) or overlap: [] if they are."""
    bad = []
    for i, (pt, k) in enumerate(zip(P, sc.CONROD_POINT_PARTS, strict=True)):
        shape, size, c = sc.CONROD_PARTS[k]
        d = pt[:2] - np.asarray(c[:2])
        if shape == "cylinder":
            ok = float(np.hypot(*d)) + radius <= size[0]
        else:
            ok = abs(d[0]) + radius <= size[0] / 2 and abs(d[1]) + radius <= size[1] / 2 and all(
                np.hypot(*(pt[:2] - np.asarray(cc[:2]))) >= sz[0] + radius
                for sh, sz, cc in sc.CONROD_PARTS if sh == "cylinder")
        if not ok:
            bad.append(f"dot p{i + 1} at {(pt[:2] * 1e3).round(1).tolist()} mm leaves its face")
    for i in range(len(P)):
        for j in range(i + 1, len(P)):
            if np.linalg.norm(P[i, :2] - P[j, :2]) < 2 * radius:
                bad.append(f"dots p{i + 1} and p{j + 1} overlap")
    return bad


def goal_standoff(setting: sc.Setting) -> float:
    """The goal's standoff (scene.SETTINGS): the closest on a 1 cm grid at which the real
    camera sees every point VIEW_MARGIN_PX inside the image. 0.38 m for the defaults."""
    start, stop, step = STANDOFF_GRID
    P = setting.target.points_world(setting.T_object_actual)
    for k in range(int(round(start / step)), int(round(stop / step)) + 1):
        standoff = k / 100
        if not points_outside(sc.goal_flange_pose(dataclasses.replace(setting, standoff=standoff)),
                              P):
            return standoff
    raise ConfigError(f"no goal standoff in {start}-{stop} m shows every point "
                      f"{VIEW_MARGIN_PX:g} px inside the image")


#: the committed start's overhead camera pose (scene.OVERHEAD_START over the default points)
_CANONICAL_OVERHEAD = sc.overhead_camera_pose(sc.CONROD.points_world(sc.T_CONROD_EXPERIMENT),
                                              *sc.OVERHEAD_START)


def overhead_start(robot: Robot, points_world: np.ndarray, height: float, yaw_deg: float,
                   q_branch: np.ndarray) -> tuple[float, ...]:
    """The start (scene.SETTINGS): the IK solution (seeded on the goal's branch ``q_branch``)
    that puts the real camera ``height`` [m] above the points' mean looking straight down,
    turned ``yaw_deg`` [deg]; in degrees rounded to 0.01 (as EXPERIMENT_Q0_DEG is printed).
    The committed pose itself gives EXPERIMENT_Q0_DEG (found by the same rule before issue 19;
    its camera 0.08 mm and 0.01 deg from the pose, the IK's 0.03 deg away), so that the
    committed runs are unchanged."""
    T = sc.overhead_camera_pose(points_world, height, yaw_deg)
    if np.array_equal(T, _CANONICAL_OVERHEAD):
        return sc.EXPERIMENT_Q0_DEG
    try:
        q = solve_ik(robot, "flange", T @ inv_T(T_FLANGE_TRUE_CAMERA), q_branch, 300)
    except ReproError as exc:
        raise ConfigError(f"the overhead start {height:.4g} m above the points, yaw "
                          f"{yaw_deg:.4g} deg, is out of reach from the goal's branch: {exc}"
                          ) from exc
    return tuple(float(v) for v in np.round(np.rad2deg(q), 2))


# ------------------------------------------------------------ the setting of a config
def layout_values(config: Chan2011Config) -> dict[str, float]:
    """``{field: value}`` of the config's layout fields (LAYOUT_FIELDS)."""
    return {f: getattr(config, f) for f in LAYOUT_FIELDS}


def non_default_layout(config: Chan2011Config) -> list[str]:
    """The layout fields of ``config`` that differ from Chan2011Config's defaults."""
    d = Chan2011Config()
    return [f for f in LAYOUT_FIELDS if getattr(config, f) != getattr(d, f)]


def setting_for(config: Chan2011Config) -> sc.Setting:
    """The poses of ``config.setting``: the simulation's as printed (scene.SETTINGS), the
    experiment's derived from the layout fields (:func:`experiment_setting`)."""
    if config.setting != "experiment":
        return sc.SETTINGS[config.setting]
    return experiment_setting(tuple(layout_values(config).items()))


@functools.lru_cache(maxsize=32)
def experiment_setting(values: tuple[tuple[str, float], ...]) -> sc.Setting:
    """The experiment's setting for the layout ``values`` (``(field, value)`` pairs of
    LAYOUT_FIELDS), checked: raises ConfigError for a layout the paper's scene could not be."""
    v = dict(values)
    boxes = obstacles(v)
    x = sc.CONROD_MEASURED[0] + v["conrod_dx"]
    y = sc.CONROD_MEASURED[1] + v["conrod_dy"]
    P = conrod_points(v["points_spread"], v["points_jitter"], int(v["points_seed"]))
    bad = points_off_faces(P, sc.CONROD.dot_radius)
    if bad:
        raise ConfigError("the conrod's dots are not the paper's ten dots on its faces: "
                          + "; ".join(bad))
    z = conrod_rest_z(x, y, v["conrod_yaw_deg"], v["conrod_tilt_deg"], boxes)
    target = sc.CONROD if P is sc.CONROD_POINTS else dataclasses.replace(sc.CONROD,
                                                                          points_target=P)
    s = dataclasses.replace(
        sc.SETTINGS["experiment"], obstacles=boxes, target=target,
        T_object_actual=conrod_pose(x, y, z, v["conrod_yaw_deg"], v["conrod_tilt_deg"]))
    s = dataclasses.replace(s, standoff=goal_standoff(s))
    P_world = target.points_world(s.T_object_actual)
    dcc = CollisionModel(crs_urdf_path(), CRS_JOINTS, boxes)
    with World() as w:
        robot = Robot(w, crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
        q_branch = goal_nearest_home(robot, sc.goal_flange_pose(s))
        s = dataclasses.replace(s, q0_deg=overhead_start(robot, P_world, v["start_height"],
                                                         v["start_yaw_deg"], q_branch))
        q0 = np.deg2rad(s.q0_deg)
        where = f"the start {list(s.q0_deg)} deg"
        if not same_branch(q0, q_branch):
            raise ConfigError(f"{where} is on another IK branch than the goal's "
                              f"({np.rad2deg(q_branch).round(1).tolist()} deg)")
        out = points_outside(robot.frame_pose("flange", q0), P_world)
        if out:
            raise ConfigError(f"{where}: points {out} (1-based) are not {VIEW_MARGIN_PX:g} px "
                              "inside the start image")
        try:
            q_goal = goal_configuration(robot, s)
        except ConfigError:
            raise
        except ReproError as exc:
            raise ConfigError(f"the goal is not reachable from {where}: {exc}") from exc
    for name, q in (("start", q0), ("goal", q_goal)):
        d = dcc.distance(q)
        if d <= 0.0:
            raise ConfigError(f"the robot at its {name} {np.rad2deg(q).round(2).tolist()} deg "
                              f"collides with an obstacle (distance {d:.4f} m)")
    return s
