"""The Scene: every body of a run, added once by name, in the physics world and the render mirror.

A run has two PyBullet DIRECT clients:

* the **physics** client, where the robots move, contacts happen, rays are cast and the
  ground-truth distances are measured;
* the **render mirror** (optional), a second client that holds only what the eye-in-hand
  cameras may see (bodies added with ``render=True``: obstacles, targets, a moving hand...;
  robots are left out because their meshes cost ~20 ms a frame in TinyRenderer and are
  behind their own camera). Cameras render from it.

Every body is added once, through this class, to both clients; :meth:`Scene.move` keeps
them in step. :meth:`Scene.describe` gives the ``scene.json`` from which a run can be
rebuilt with plain ``pybullet``, ``numpy`` and ``json`` (see :data:`CONVENTIONS`), and
:meth:`Scene.distances` the ground-truth distance from a robot to every other body, a
compound body counting as the minimum over all its parts.

Size convention (one for every primitive): a box's ``size`` is its **full** extents along
its x, y, z axes [m]; cylinders and capsules have a ``radius`` [m] and a ``length`` [m]
along their z axis (for a capsule, the length of the cylindrical part between the two
sphere centres); a sphere has a ``radius``. Poses are the body frame in the world frame:
position [m] and quaternion (x, y, z, w).
"""

from __future__ import annotations

import math
import shutil
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
import pybullet_data

from repro.errors import ConfigError, UnknownChoiceError
from repro.geometry import inv_T
from repro.sensors.camera import (
    DotTarget,
    cylinder_visual_shape,
    move_dot_target,
    spawn_dot_target,
)
from repro.sim.closest import ClosestPoints
from repro.sim.robot import URDF_LOAD_FLAGS, JointGroup, JointLimits, JointSet, Robot
from repro.sim.world import World, WorldConfig, pb_to_pose, pose_to_pb

__all__ = ["CONVENTIONS", "DISTANCE_CAP", "Part", "Scene", "SceneBody", "pose_json"]

SCENE_FORMAT = "repro.scene/2"

#: Ground-truth distances are measured up to this range [m]; farther bodies read it.
DISTANCE_CAP = 1.0
#: The pybullet.changeDynamics keywords a dynamic body may set (Scene.add_dynamic).
DYNAMICS_KEYS = frozenset({"lateralFriction", "spinningFriction", "rollingFriction",
                           "restitution", "contactStiffness", "contactDamping",
                           "linearDamping", "angularDamping"})

CONVENTIONS = {
    "units": "metres, radians, seconds, kilograms; pixels where named px",
    "pose": "{position: [x, y, z] m, quaternion_xyzw: [x, y, z, w]}: the body frame "
            "(for a URDF, its root-link frame) in the world frame",
    "urdf": "load with p.loadURDF(urdf (path relative to this folder), basePosition, "
            "baseOrientation, useFixedBase, flags=load_flags.value). base_pose is the URDF "
            "root-link frame, which is what loadURDF places; resetBasePositionAndOrientation "
            "would place the root link's inertial frame instead. Mesh paths inside the URDF "
            "are relative to the URDF file.",
    "box": "size = FULL extents along the box's x, y, z axes (p.GEOM_BOX takes half of them)",
    "cylinder": "radius; length along the body's z axis (collision: p.GEOM_CYLINDER height=)",
    "capsule": "radius; length of the cylindrical part (between the sphere centres) along z",
    "sphere": "radius",
    "compound": "a body made of parts; each part is a primitive with its own pose "
                "T_body_part in the body frame; the body's distance is the minimum over parts",
    "rgba": "colour, 4 floats in [0, 1]",
    "joint_positions": "joint angles over time are the trace columns listed in q_columns",
    "moving_bodies": "a body with pose_columns moves: its pose at each row of trace.csv is "
                     "in those columns (x, y, z [m], qx, qy, qz, qw)",
    "render_mirror": "camera images are rendered from a second client that holds only the "
                     "bodies with in_render = true (robots are not in it)",
}


def pose_json(T: np.ndarray) -> dict[str, list[float]]:
    """A 4x4 pose as ``{"position": [...], "quaternion_xyzw": [...]}`` (scene.json form)."""
    pos, quat = pose_to_pb(np.asarray(T, dtype=float))
    return {"position": pos, "quaternion_xyzw": quat}


@dataclass(frozen=True)
class Part:
    """One primitive of a compound body (or the single shape of a primitive body).

    Attributes:
        shape: ``"box"``, ``"cylinder"``, ``"capsule"`` or ``"sphere"``.
        size: box: full extents (x, y, z) [m]; cylinder / capsule: (radius, length) [m];
            sphere: (radius,) [m].
        T_body_part: pose of the part in the body frame (4x4) [m].
    """

    shape: str
    size: tuple[float, ...]
    T_body_part: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        n = {"box": 3, "cylinder": 2, "capsule": 2, "sphere": 1}
        if self.shape not in n:
            raise UnknownChoiceError("primitive shape", self.shape, n)
        if len(self.size) != n[self.shape] or not all(np.isfinite(self.size)) or min(
                self.size) <= 0:
            raise ConfigError(f"{self.shape} size must be {n[self.shape]} positive numbers, "
                              f"got {self.size}")

    def describe(self) -> dict[str, Any]:
        d: dict[str, Any] = {"shape": self.shape, "T_body_part": pose_json(self.T_body_part)}
        if self.shape == "box":
            d["size"] = list(self.size)
        elif self.shape == "sphere":
            d["radius"] = self.size[0]
        else:
            d["radius"], d["length"] = self.size
        return d


def _create_shape(client: int, part: Part, rgba: Sequence[float], collision: bool
                  ) -> tuple[int, int]:
    """(collision shape id or -1, visual shape id) of a primitive part."""
    s = part.size
    col = -1
    if part.shape == "box":
        half = [v / 2 for v in s]
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=list(rgba),
                                  physicsClientId=client)
        if collision:
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    elif part.shape == "cylinder":
        # TinyRenderer draws p.GEOM_CYLINDER 1 mm too big all round: an exact mesh instead.
        vis = cylinder_visual_shape(client, s[0], s[1], rgba)
        if collision:
            col = p.createCollisionShape(p.GEOM_CYLINDER, radius=s[0], height=s[1],
                                         physicsClientId=client)
    elif part.shape == "capsule":
        vis = p.createVisualShape(p.GEOM_CAPSULE, radius=s[0], length=s[1],
                                  rgbaColor=list(rgba), physicsClientId=client)
        if collision:
            col = p.createCollisionShape(p.GEOM_CAPSULE, radius=s[0], height=s[1],
                                         physicsClientId=client)
    else:
        vis = p.createVisualShape(p.GEOM_SPHERE, radius=s[0], rgbaColor=list(rgba),
                                  physicsClientId=client)
        if collision:
            col = p.createCollisionShape(p.GEOM_SPHERE, radius=s[0], physicsClientId=client)
    return col, vis


def _frozen(T: np.ndarray) -> bool:
    """``T`` is a float64 array that owns its data and is read-only: no one can write it
    (a mover's pose, e.g. pomares2011's ``Bones``), so it is kept as it is, not copied,
    and the same object given again is the same pose."""
    return (type(T) is np.ndarray and T.dtype == np.float64 and T.base is None
            and not T.flags.writeable)


def _place(client: int, ids: Sequence[int], body: SceneBody, T_world: np.ndarray) -> None:
    """Put the PyBullet bodies ``ids`` of ``body`` (its parts, or its dots) in ``client`` at
    the body pose ``T_world``."""
    if body.dot_target is not None:
        move_dot_target(client, list(ids), body.dot_target, T_world)
        return
    for bid, part in zip(ids, body.parts, strict=True):
        pos, quat = pose_to_pb(T_world @ part.T_body_part)
        p.resetBasePositionAndOrientation(bid, pos, quat, physicsClientId=client)


@dataclass
class SceneBody:
    """A named body of the scene and its PyBullet ids in both clients."""

    name: str
    kind: str  # urdf | box | cylinder | capsule | sphere | compound | dot_target
    T_world: np.ndarray
    rgba: tuple[float, ...] | None
    collision: bool
    in_render: bool
    ids: list[int]  # physics-client body ids (one per part)
    render_ids: list[int]
    parts: tuple[Part, ...] = ()
    moving: bool = False
    robot: Robot | None = None
    info: dict[str, Any] = field(default_factory=dict)
    dot_target: DotTarget | None = None
    obstacle: bool = True  # counts in dist_min (False: a body the robot approaches on purpose)
    #: a simulated (free) body: its mass [kg] and PyBullet dynamics (changeDynamics keywords);
    #: None for static and scripted bodies. Its pose is read back every step
    #: (:meth:`Scene.refresh_dynamic`).
    dynamics: dict[str, float] | None = None


class Scene:
    """The physics world, the optional render mirror and every named body in them.

    Args:
        world_config: time base and gravity (the same for both clients).
        render: create the render mirror (cameras in ``"render"`` mode need it).
        run_dir: folder of the run; URDFs (and their meshes) are copied there so that
            ``scene.json`` refers to them by relative paths. None: nothing is copied.
    """

    def __init__(self, world_config: WorldConfig, render: bool = False,
                 run_dir: Path | None = None) -> None:
        self.physics = World(world_config)
        self.mirror: World | None = World(world_config) if render else None
        self.run_dir = Path(run_dir) if run_dir is not None else None
        self.bodies: dict[str, SceneBody] = {}
        self._others_memo: dict[tuple[int, int], tuple[tuple[str, ...], list[int],
                                                       list[tuple[int, int]] | None]] = {}
        self._closest = ClosestPoints(self.physics.client)
        #: robots of a distances_of call (kept alive: their ids are the key) -> per chain:
        #: the chain, its robots' positions in the call, their links
        self._distance_plans: dict[tuple[int, ...], tuple[list[JointSet], list[tuple[
            JointSet, list[int], tuple[frozenset[int] | None, ...]]]]] = {}
        #: every joint group by name (:meth:`add_joint_group`); the runner logs the groups no
        #: drive covers (positions, velocities, ground-truth distances)
        self.joint_groups: dict[str, JointGroup] = {}
        self.mounts: dict[str, dict[str, Any]] = {}
        self.sensors: dict[str, dict[str, Any]] = {}
        self.extra: dict[str, Any] = {}
        self._mirror_pending: dict[str, np.ndarray] = {}  # moves not yet in the mirror

    # ----------------------------------------------------------------- clients
    @property
    def render_client(self) -> int:
        """Client the cameras render from (the mirror if there is one), with every pending
        move applied (:meth:`move` updates the mirror lazily, only when something renders)."""
        if self.mirror is None:
            return self.physics.client
        self._sync_mirror()
        return self.mirror.client

    def _sync_mirror(self) -> None:
        if self.mirror is None:
            return
        for name, T_world in self._mirror_pending.items():
            body = self.bodies[name]
            _place(self.mirror.client, body.render_ids, body, T_world)
        self._mirror_pending.clear()

    def close(self) -> None:
        """Disconnect both clients (idempotent)."""
        self.physics.close()
        if self.mirror is not None:
            self.mirror.close()

    def __enter__(self) -> Scene:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ bodies
    def _check_name(self, name: str) -> None:
        if not name or not name.replace("_", "").isalnum():
            raise ConfigError(f"body name must be a non-empty identifier, got {name!r}")
        if name in self.bodies:
            raise ConfigError(f"the scene already has a body named {name!r}")

    def __getitem__(self, name: str) -> SceneBody:
        if name not in self.bodies:
            raise UnknownChoiceError("scene body", name, self.bodies)
        return self.bodies[name]

    def add_urdf(self, name: str, urdf: Path, joints: tuple[str, ...], limits: JointLimits,
                 T_world_base: np.ndarray | None = None, column_prefix: str = "",
                 render: bool = False) -> Robot:
        """Load a fixed-base robot from ``urdf`` into the physics client.

        The URDF (and every mesh it names) is copied into the run folder with relative mesh
        paths. ``column_prefix`` prefixes its trace columns (``q1`` or ``pa10_q1``).
        """
        self._check_name(name)
        src = Path(urdf)
        path = self._copy_urdf(src, name) if self.run_dir is not None else src
        robot = Robot(self.physics, path, joints, limits, T_world_base)
        robot.name = name
        robot.column_prefix = column_prefix
        render_ids = []
        if render and self.mirror is not None:
            render_ids = [Robot(self.mirror, path, joints, limits, T_world_base).body]
        n = robot.n
        self.bodies[name] = SceneBody(
            name, "urdf", robot.T_world_base, None, True, render, [robot.body], render_ids,
            robot=robot, info={
                "urdf": path.name if self.run_dir is not None else str(path),
                "use_fixed_base": True,
                "load_flags": {"names": list(URDF_LOAD_FLAGS), "value": robot.load_flags},
                "joints": list(joints),
                "column_prefix": column_prefix,
                "q_columns": [f"{column_prefix}q{i + 1}" for i in range(n)],
                "joint_limits": {"q_min": limits.q_min, "q_max": limits.q_max,
                                 "qd_max": limits.qd_max, "tau_max": limits.tau_max},
                "actuator_model": "joint velocity clamped to qd_max by the simulation "
                                  "(changeDynamics maxJointVelocity and the drive), torque "
                                  "to tau_max",
            })
        return robot

    def add_joint_group(self, body: str, name: str, joints: tuple[str, ...],
                        column_prefix: str, owns_base: bool = False) -> JointGroup:
        """A subset of a URDF body's joints driven and logged on its own (e.g. pomares2011's
        PA-10 and mini-robot in one URDF); recorded in scene.json: the body's ``q_columns``
        become the groups' columns, and each group lists its joints, links and prefix."""
        robot = self[body].robot
        if robot is None:
            raise ConfigError(f"body {body!r} is not a robot")
        group = JointGroup(robot, name, joints, column_prefix, owns_base)
        info = self[body].info
        groups = info.setdefault("groups", [])
        if any(g["name"] == name for g in groups):
            raise ConfigError(f"body {body!r} already has a joint group named {name!r}")
        groups.append({"name": name, "column_prefix": column_prefix, "joints": list(joints),
                       "q_columns": [f"{column_prefix}q{i + 1}" for i in range(len(joints))],
                       "links": group.links, "links_note": "PyBullet link indices this group "
                       "moves (-1 = base); its <prefix>dist_* columns are over these links"})
        by_joint = {j: f"{g['column_prefix']}q{g['joints'].index(j) + 1}"
                    for g in groups for j in g["joints"]}
        info["q_columns"] = [by_joint.get(j, "") for j in info["joints"]]
        self.joint_groups[name] = group
        return group

    def _copy_urdf(self, src: Path, name: str) -> Path:
        """Copy ``src`` into the run folder; copy its meshes under ``meshes/<name>/`` and
        point the URDF at them by relative paths."""
        assert self.run_dir is not None
        self.run_dir.mkdir(parents=True, exist_ok=True)
        tree = ET.parse(src)
        mesh_dir = self.run_dir / "meshes" / name
        for mesh in tree.getroot().iter("mesh"):
            fn = mesh.get("filename", "")
            mpath = Path(fn.replace("package://", ""))
            if not mpath.is_absolute():
                mpath = (src.parent / mpath).resolve()
            if not mpath.is_file():
                raise ConfigError(f"URDF {src} names a mesh that does not exist: {fn}")
            rel = _mesh_relpath(mpath)
            dest = mesh_dir / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            if not dest.exists():
                shutil.copyfile(mpath, dest)
                mtl = mpath.with_suffix(".mtl")  # an OBJ's material library, if any
                if mtl.is_file():
                    shutil.copyfile(mtl, dest.with_suffix(".mtl"))
            mesh.set("filename", (Path("meshes") / name / rel).as_posix())
        out = self.run_dir / f"{name}.urdf"
        ET.indent(tree)
        tree.write(out, xml_declaration=True, encoding="utf-8")
        return out

    def _add_parts(self, name: str, kind: str, parts: Sequence[Part], T_world: np.ndarray,
                   rgba: Sequence[float], collision: bool, render: bool, moving: bool,
                   info: dict[str, Any] | None = None, obstacle: bool = True) -> SceneBody:
        self._check_name(name)
        rgba = tuple(float(c) for c in rgba)
        if len(rgba) != 4 or not all(0.0 <= c <= 1.0 for c in rgba):
            raise ConfigError(f"rgba of {name!r} must be 4 numbers in [0, 1], got {rgba}")
        ids: list[int] = []
        render_ids: list[int] = []
        clients = [(self.physics.client, ids, collision)]
        if render and self.mirror is not None:
            clients.append((self.mirror.client, render_ids, False))
        for client, out, col in clients:
            for part in parts:
                c, v = _create_shape(client, part, rgba, col)
                pos, quat = pose_to_pb(T_world @ part.T_body_part)
                out.append(p.createMultiBody(0.0, c, v, pos, quat, physicsClientId=client))
        for bid in ids:  # mass 0: moved by move() alone (the far test keeps its box)
            self._closest.keep_box(bid)
        body = SceneBody(name, kind, np.asarray(T_world, float).copy(), rgba, collision, render,
                         ids, render_ids, tuple(parts), moving, info=info or {},
                         obstacle=obstacle)
        self.bodies[name] = body
        return body

    def add_box(self, name: str, size: Sequence[float], T_world: np.ndarray,
                rgba: Sequence[float], collision: bool = True, render: bool = True,
                moving: bool = False) -> SceneBody:
        """A box of full extents ``size`` [m] at ``T_world`` (static unless ``moving``)."""
        return self._add_parts(name, "box", [Part("box", tuple(size))], T_world, rgba,
                               collision, render, moving)

    def add_cylinder(self, name: str, radius: float, length: float, T_world: np.ndarray,
                     rgba: Sequence[float], collision: bool = True, render: bool = True,
                     moving: bool = False) -> SceneBody:
        """A cylinder (radius, length along z [m]); exact, not a hull, in PyBullet's GJK."""
        return self._add_parts(name, "cylinder", [Part("cylinder", (radius, length))], T_world,
                               rgba, collision, render, moving)

    def add_capsule(self, name: str, radius: float, length: float, T_world: np.ndarray,
                    rgba: Sequence[float], collision: bool = True, render: bool = True,
                    moving: bool = False) -> SceneBody:
        """A capsule: radius, cylindrical length between the sphere centres along z [m]."""
        return self._add_parts(name, "capsule", [Part("capsule", (radius, length))], T_world,
                               rgba, collision, render, moving)

    def add_compound(self, name: str, parts: Sequence[Part], T_world: np.ndarray,
                     rgba: Sequence[float], collision: bool = True, render: bool = True,
                     moving: bool = False, obstacle: bool = True) -> SceneBody:
        """A body made of several primitives (one PyBullet body per part, moved together);
        its ground-truth distance is the minimum over all its parts. ``obstacle=False``: a
        body the robot approaches on purpose (left out of ``dist_min``)."""
        if not parts:
            raise ConfigError(f"compound body {name!r} needs at least one part")
        return self._add_parts(name, "compound", list(parts), T_world, rgba, collision,
                               render, moving, obstacle=obstacle)

    def add_dynamic(self, name: str, part: Part, mass: float, T_world: np.ndarray,
                    rgba: Sequence[float], dynamics: Mapping[str, float] | None = None,
                    obstacle: bool = False, render: bool = False) -> SceneBody:
        """A free body the physics moves (a grasped object): one primitive ``part`` of
        ``mass`` [kg] at ``T_world``, with PyBullet's ``changeDynamics`` keywords
        ``dynamics`` (friction, contact stiffness...: state them, they decide grip and slip).
        It is a moving body (pose columns every row, read back from the simulation by
        :meth:`refresh_dynamic`); ``obstacle=False`` by default: touching it is a contact, not
        a collision.

        Raises:
            ConfigError: a non-positive or non-finite mass, or an unknown dynamics keyword.
        """
        if not (np.isfinite(mass) and mass > 0.0):
            raise ConfigError(f"mass of the dynamic body {name!r} must be > 0 kg, got {mass}")
        dyn = {k: float(v) for k, v in (dynamics or {}).items()}
        unknown = sorted(set(dyn) - DYNAMICS_KEYS)
        if unknown:
            raise UnknownChoiceError(f"dynamics keyword of {name!r}", unknown[0],
                                     tuple(sorted(DYNAMICS_KEYS)))
        self._check_name(name)
        rgba = tuple(float(c) for c in rgba)
        T_world = np.asarray(T_world, dtype=float)
        pos, quat = pose_to_pb(T_world @ part.T_body_part)
        col, vis = _create_shape(self.physics.client, part, rgba, True)
        bid = p.createMultiBody(float(mass), col, vis, pos, quat,
                                physicsClientId=self.physics.client)  # a free body
        if dyn:
            p.changeDynamics(bid, -1, physicsClientId=self.physics.client, **dyn)
        render_ids: list[int] = []
        if render and self.mirror is not None:  # the mirror only shows it: static, no shape
            _, vis_m = _create_shape(self.mirror.client, part, rgba, False)
            render_ids.append(p.createMultiBody(0.0, -1, vis_m, pos, quat,
                                                physicsClientId=self.mirror.client))
        body = SceneBody(name, part.shape, T_world.copy(), rgba, True, bool(render_ids), [bid],
                         render_ids, (part,), True, obstacle=obstacle,
                         dynamics={"mass": float(mass), **dyn})
        self.bodies[name] = body
        return body

    def refresh_dynamic(self) -> None:
        """Read the pose of every dynamic body back from the physics (the render mirror
        follows when something next renders)."""
        for body in self.bodies.values():
            if body.dynamics is None:
                continue
            pos, quat = p.getBasePositionAndOrientation(body.ids[0],
                                                        physicsClientId=self.physics.client)
            T = pb_to_pose(pos, quat) @ inv_T(body.parts[0].T_body_part)
            body.T_world = T
            if body.render_ids:
                self._mirror_pending[body.name] = T.copy()

    def add_dot_target(self, name: str, target: DotTarget, T_world: np.ndarray,
                       moving: bool = False) -> SceneBody:
        """The coloured dots a camera measures (visual only, no collision), in both clients
        (the physics client's copy is for third-person views)."""
        self._check_name(name)
        ids = spawn_dot_target(self.physics.client, target, T_world)
        render_ids = (spawn_dot_target(self.mirror.client, target, T_world)
                      if self.mirror is not None else [])
        body = SceneBody(name, "dot_target", np.asarray(T_world, float).copy(), None, False,
                         True, ids, render_ids, (), moving, dot_target=target)
        self.bodies[name] = body
        return body

    def move(self, name: str, T_world: np.ndarray) -> None:
        """Put body ``name`` at ``T_world`` (a moving hand, a human): at once in the physics
        client; in the render mirror when something next renders (:attr:`render_client`)."""
        body = self.bodies.get(name)
        if body is None:
            raise UnknownChoiceError("scene body", name, self.bodies)
        if not body.moving:
            raise ConfigError(f"body {name!r} was not added with moving=True")
        if T_world is body.T_world and _frozen(T_world):
            return  # the very pose it was put at, which nothing can have written since
        T_world = np.asarray(T_world, dtype=float)
        old = body.T_world
        if T_world.shape == old.shape == (4, 4):
            a, b = float(T_world[0, 3]), float(old[0, 3])
            moved = a != b and a == a and b == b  # two numbers: neither the same bits nor values
        else:
            moved = False
        if not moved and (T_world.tobytes() == old.tobytes() or (
                T_world.shape == old.shape and T_world.tolist() == old.tolist())):
            return  # where it is: resetting a body to its own pose changes nothing
        _place(self.physics.client, body.ids, body, T_world)
        for bid in body.ids:
            self._closest.moved(bid)  # (its box, kept by the ground truth's far test)
        T_world = T_world if _frozen(T_world) else T_world.copy()
        if body.render_ids:
            self._mirror_pending[name] = T_world
        body.T_world = T_world

    def moving_bodies(self) -> list[SceneBody]:
        """Bodies whose pose is logged every row."""
        return [b for b in self.bodies.values() if b.moving]

    def robots(self) -> list[Robot]:
        """Every robot (URDF body) in the scene, in the order added."""
        return [b.robot for b in self.bodies.values() if b.robot is not None]

    # ----------------------------------------------------------- ground truth
    def distances(self, robot: JointSet, max_distance: float = DISTANCE_CAP
                  ) -> dict[str, float]:
        """Ground-truth minimum distance [m] from ``robot`` to every other body with a
        collision shape (PyBullet closest points between collision geometries; < 0 is
        penetration; ``max_distance`` when farther). A compound body: the minimum over its
        parts. ``robot`` may be a :class:`~repro.sim.robot.JointGroup`: then only the links
        it moves count, and the rest of its own body is skipped."""
        return self.distances_of([robot], max_distance)[0]

    def distances_of(self, robots: Sequence[JointSet], max_distance: float = DISTANCE_CAP
                     ) -> list[dict[str, float]]:
        """:meth:`distances` of several robots, with one closest-points query per pair of
        PyBullet bodies: joint groups of one URDF body (the PA-10, the mini-robot and the
        hand of one chain) share each query and keep the points on their own links
        (:class:`repro.sim.closest.ClosestPoints`: the same distances, asked with a
        threshold hinted by the previous step)."""
        return [dict(zip(names, values, strict=True))
                for names, values in self.distance_table(robots, max_distance)]

    def distance_table(self, robots: Sequence[JointSet], max_distance: float = DISTANCE_CAP,
                       below: Sequence[Sequence[float]] | None = None
                       ) -> list[tuple[tuple[str, ...], list[float]]]:
        """:meth:`distances_of` as, per robot, the other bodies' names and the distances [m]
        in that order (the runner's every-step form: no dictionaries).

        ``below``: per robot, a bound [m] per other body in the order of the names this
        returns (a longer list is fine: its first entries count), e.g. the running minimum
        of each distance column: then a distance is exact where it is below its bound, and
        elsewhere a value that is not below it (``inf``, or the exact one:
        :meth:`repro.sim.closest.ClosestPoints.minima_of`); the caller must have had the
        names from an earlier call since the last body was added."""
        key = tuple(id(r) for r in robots)
        plan = self._distance_plans.get(key)
        if plan is None:
            chains: dict[int, tuple[JointSet, list[int]]] = {}  # id(chain) -> its robots
            for i, robot in enumerate(robots):
                full = getattr(robot, "robot", robot)  # a JointGroup's whole chain
                chains.setdefault(id(full), (full, []))[1].append(i)
            # each robot's own links (a joint group's); None: all of the chain's
            plan = self._distance_plans[key] = (list(robots), [
                (full, idx, tuple(None if (links := getattr(robots[i], "links", None)) is None
                                  else frozenset(links) for i in idx))
                for full, idx in chains.values()])
        out: list[tuple[tuple[str, ...], list[float]]] = [((), [])] * len(robots)
        cap = float(max_distance)
        minima_of = self._closest.minima_of
        for full, idx, groups in plan[1]:
            names, ids, spans = self._others(full)
            # the chain's joints now (its box is then kept between steps: ClosestPoints)
            joints = (full.pb_joints, full.q()) if isinstance(full, Robot) else None
            bounds = None
            if below is not None:  # [id][group]: each part of a body has the body's bound
                per_name = [[below[i][b] for i in idx] for b in range(len(names))]
                bounds = per_name if spans is None else [
                    per_name[b] for b, (start, stop) in enumerate(spans)
                    for _ in range(start, stop)]
            per_body = minima_of(full.body, ids, groups, cap, joints, bounds)  # [id][group]
            if spans is None:  # one PyBullet body per scene body
                values = [list(col) for col in zip(*per_body, strict=True)] if per_body else [
                    [] for _ in idx]
            else:  # a compound body: the minimum over its parts
                values = [[] for _ in idx]
                fill = cap if below is None else math.inf
                for start, stop in spans:
                    best = [fill] * len(idx)
                    for mins in per_body[start:stop]:
                        for j, d in enumerate(mins):
                            if d < best[j]:
                                best[j] = d
                    for vals, d in zip(values, best, strict=True):
                        vals.append(d)
            for i, vals in zip(idx, values, strict=True):
                out[i] = (names, vals)
        return out

    def _others(self, full: JointSet
                ) -> tuple[tuple[str, ...], list[int], list[tuple[int, int]] | None]:
        """Every body with a collision shape but ``full``: their names, their PyBullet ids
        in order, and each name's span of ids (None when every body is one id); kept until
        a body is added."""
        key = (id(full), len(self.bodies))
        got = self._others_memo.get(key)
        if got is None:
            others = [(b.name, b.ids) for b in self.bodies.values()
                      if b.collision and b.robot is not full]
            ids: list[int] = []
            spans: list[tuple[int, int]] = []
            for _, bids in others:
                spans.append((len(ids), len(ids) + len(bids)))
                ids.extend(bids)
            got = self._others_memo[key] = (
                tuple(name for name, _ in others), ids,
                None if all(len(bids) == 1 for _, bids in others) else spans)
        return got

    # -------------------------------------------------------- sensors, frames
    def add_mount(self, name: str, robot: str, parent_link: str, T_parent_frame: np.ndarray,
                  note: str = "") -> None:
        """Declare a named frame rigidly attached to a robot link (a camera, a ring)."""
        if robot not in self.bodies or self.bodies[robot].robot is None:
            raise UnknownChoiceError("robot", robot, [b.name for b in self.bodies.values()
                                                      if b.robot is not None])
        rob = self.bodies[robot].robot
        assert rob is not None
        rob.pb_link_index(parent_link)  # raises on an unknown link
        self.mounts[name] = {"robot": robot, "parent_link": parent_link,
                             "T_parent_frame": np.asarray(T_parent_frame, float), "note": note}

    def add_sensor(self, name: str, description: Mapping[str, Any]) -> None:
        """Record a sensor's model (mount, ray model, noise...) for scene.json."""
        if name in self.sensors:
            raise ConfigError(f"the scene already has a sensor named {name!r}")
        self.sensors[name] = dict(description)

    def check_colors(self, check: Callable[[DotTarget, Mapping[str, Sequence[float]]], None]
                     ) -> None:
        """Run a colour check of every dot target against every other body's colour."""
        colours = {b.name: b.rgba for b in self.bodies.values() if b.rgba is not None}
        for b in self.bodies.values():
            if b.dot_target is not None:
                check(b.dot_target, colours)

    # ---------------------------------------------------------------- scene.json
    def describe(self) -> dict[str, Any]:
        """The scene as plain JSON-able data (written to scene.json)."""
        cfg = self.physics.config
        bodies = []
        for b in self.bodies.values():
            d: dict[str, Any] = {"name": b.name, "kind": b.kind, "pose": pose_json(b.T_world),
                                 "collision": b.collision, "in_render": b.in_render,
                                 "obstacle": b.obstacle and b.collision and b.robot is None}
            if b.rgba is not None:
                d["rgba"] = list(b.rgba)
            if b.kind in ("box", "cylinder", "capsule", "sphere"):
                d.update({k: v for k, v in b.parts[0].describe().items()
                          if k not in ("shape", "T_body_part")})
            elif b.kind == "compound":
                d["parts"] = [pt.describe() for pt in b.parts]
            elif b.kind == "urdf":
                d["base_pose"] = d.pop("pose")
                d.update(b.info)
            elif b.dot_target is not None:
                d.update(b.dot_target.describe())
            if b.moving:
                d["pose_columns"] = pose_columns(b.name)
            if b.dynamics is not None:
                d["dynamic"] = {**b.dynamics, "meaning": "a free body simulated with this "
                                "mass [kg] and these pybullet.changeDynamics keywords; its pose "
                                "is in the trace (pose_columns)"}
            bodies.append(d)
        return {
            "format": SCENE_FORMAT,
            "conventions": CONVENTIONS,
            "world": {"gravity": list(cfg.gravity), "physics_dt": cfg.physics_dt,
                      "control_dt": cfg.control_dt,
                      "solver_iterations": cfg.solver_iterations,
                      "deterministic_overlapping_pairs": 1,
                      "pybullet_version": _pybullet_version(),
                      "distance_cap": DISTANCE_CAP},
            "bodies": bodies,
            "mounts": {k: {**v, "T_parent_frame": pose_json(v["T_parent_frame"])}
                       for k, v in self.mounts.items()},
            "sensors": self.sensors,
            **self.extra,
        }


def pose_columns(name: str) -> list[str]:
    """Trace columns of a moving body's pose."""
    return [f"{name}_{a}" for a in ("x", "y", "z", "qx", "qy", "qz", "qw")]


def _mesh_relpath(mesh: Path) -> Path:
    """Path of a mesh below its package root (pybullet_data's, or its own folder)."""
    root = Path(pybullet_data.getDataPath()).resolve()
    try:
        return mesh.resolve().relative_to(root)
    except ValueError:
        return Path(mesh.name)


def _pybullet_version() -> str:
    import importlib.metadata

    try:
        return importlib.metadata.version("pybullet")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"
