"""A run's scene rebuilt for rendering from the run's own files (issue 20).

Only ``scene.json`` (format ``repro.scene/2``), ``trace.csv`` and the URDFs (and meshes) the
run folder ships are read -- what an outsider has -- never the experiment's code. The world
follows ``scene.json``'s ``conventions``: URDFs by ``p.loadURDF`` at their ``base_pose`` with
their ``load_flags``; primitives at ``pose`` (box ``size`` = full extents; compound bodies
part by part at ``T_body_part``); dot targets as one disc mesh per dot at
``T_world_target @ trans(points_target[i])`` with the ``plate`` beneath; a row of the
trace sets the joints from ``q_columns`` and the moving bodies from ``pose_columns``.

Two worlds make a frame, as the run's own camera did (``conventions.render_mirror``): the
*external* world holds every body; the *camera* world only the bodies with
``in_render = true`` (the robots are not in the camera's images).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pybullet as p

from repro.errors import ConfigError

Pose = tuple[list[float], list[float]]  # (position [m], quaternion xyzw)
IDENTITY: Pose = ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
#: OpenGL view matrix of a camera from T_world_camera (x right, y down, z forward):
#: diag(1, -1, -1, 1) inv(T_world_camera) (scene.json ``cameras.<name>.renderer``).
_GL_FLIP = np.diag([1.0, -1.0, -1.0, 1.0])


def pose_of(d: dict[str, Any]) -> Pose:
    """A scene.json pose ``{position, quaternion_xyzw}``."""
    return [float(v) for v in d["position"]], [float(v) for v in d["quaternion_xyzw"]]


def compose(a: Pose, b: Pose) -> Pose:
    """a * b (b expressed in a's frame)."""
    pos, quat = p.multiplyTransforms(a[0], a[1], b[0], b[1])
    return list(pos), list(quat)


def matrix(pose: Pose) -> np.ndarray:
    """4x4 homogeneous transform of a pose."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(p.getMatrixFromQuaternion(pose[1]), float).reshape(3, 3)
    T[:3, 3] = pose[0]
    return T


def camera_view_matrix(T_world_camera: np.ndarray) -> list[float]:
    """PyBullet (column-major) view matrix of an optical frame (x right, y down, z fwd)."""
    return list((_GL_FLIP @ np.linalg.inv(T_world_camera)).T.reshape(-1))


def _parts(body: dict[str, Any]) -> list[dict[str, Any]]:
    """A primitive body as one part at the body frame; a compound body's parts."""
    if body["kind"] == "compound":
        return list(body["parts"])
    part: dict[str, Any] = {k: body[k] for k in ("size", "radius", "length") if k in body}
    return [{"shape": body["kind"], "T_body_part": {"position": IDENTITY[0],
                                                    "quaternion_xyzw": IDENTITY[1]}, **part}]


def _visual(client: int, part: dict[str, Any], rgba: list[float]) -> int:
    """Visual shape of a primitive part per scene.json's size convention."""
    shape = part["shape"]
    if shape == "box":
        return p.createVisualShape(p.GEOM_BOX, halfExtents=[s / 2.0 for s in part["size"]],
                                   rgbaColor=rgba, physicsClientId=client)
    if shape in ("cylinder", "capsule"):
        kind = p.GEOM_CYLINDER if shape == "cylinder" else p.GEOM_CAPSULE
        return p.createVisualShape(kind, radius=part["radius"], length=part["length"],
                                   rgbaColor=rgba, physicsClientId=client)
    if shape == "sphere":
        return p.createVisualShape(p.GEOM_SPHERE, radius=part["radius"], rgbaColor=rgba,
                                   physicsClientId=client)
    raise ConfigError(f"scene.json: unknown primitive shape {shape!r}")


class ReplayWorld:
    """The bodies of one run in a fresh DIRECT client, posed row by row from its trace.

    Args:
        run_dir: the run folder (scene.json and the URDFs it names).
        camera_only: hold only the bodies with ``in_render = true`` (the camera world).
    """

    def __init__(self, run_dir: Path, *, camera_only: bool = False) -> None:
        self.dir = Path(run_dir)
        self.scene: dict[str, Any] = json.loads((self.dir / "scene.json").read_text())
        self.bodies = {b["name"]: b for b in self.scene["bodies"]
                       if b.get("in_render", True) or not camera_only}
        self.ids: dict[str, list[tuple[int, Pose]]] = {}  # body -> (id, T_body_part)
        self.links: dict[str, dict[str, int]] = {}  # robot -> link name -> link index
        self.joints: dict[str, list[int]] = {}  # robot -> joint index of each q column
        self.client = p.connect(p.DIRECT)
        try:
            for b in self.bodies.values():
                self._add(b)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        if p.isConnected(self.client):
            p.disconnect(self.client)

    def __enter__(self) -> ReplayWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ build
    def _add(self, b: dict[str, Any]) -> None:
        c, name = self.client, b["name"]
        if b["kind"] == "urdf":
            pos, quat = pose_of(b["base_pose"])
            bid = p.loadURDF(str(self.dir / b["urdf"]), pos, quat,
                             useFixedBase=bool(b["use_fixed_base"]),
                             flags=int(b["load_flags"]["value"]), physicsClientId=c)
            links = {p.getBodyInfo(bid, physicsClientId=c)[0].decode(): -1}
            joints = {}
            for j in range(p.getNumJoints(bid, physicsClientId=c)):
                info = p.getJointInfo(bid, j, physicsClientId=c)
                links[info[12].decode()] = j
                joints[info[1].decode()] = j
            self.ids[name] = [(bid, IDENTITY)]
            self.links[name] = links
            self.joints[name] = [joints[j] for j in b["joints"]]
        elif b["kind"] == "dot_target":
            self.ids[name] = self._dots(b)
        elif b["kind"] in ("box", "cylinder", "capsule", "sphere", "compound"):
            rgba = [float(v) for v in b.get("rgba") or (0.6, 0.6, 0.6, 1.0)]
            self.ids[name] = [(p.createMultiBody(0.0, -1, _visual(c, part, rgba),
                                                 physicsClientId=c), pose_of(part["T_body_part"]))
                              for part in _parts(b)]
        else:
            raise ConfigError(f"scene.json: body {name!r} has an unknown kind {b['kind']!r}")
        self._place(name, pose_of(b["base_pose"] if b["kind"] == "urdf" else b["pose"]))

    def _dots(self, b: dict[str, Any]) -> list[tuple[int, Pose]]:
        """One disc mesh per dot (and the plate beneath, if any), in the target frame."""
        c, dot = self.client, b["dot"]
        out = []
        lift = [0.0, 0.0, float(dot.get("top_face_offset", 0.0))]
        for point, rgb in zip(b["points_target"], b["colors_rgb255"], strict=True):
            vis = p.createVisualShape(p.GEOM_MESH, vertices=dot["mesh"]["vertices"],
                                      indices=dot["mesh"]["indices"],
                                      rgbaColor=[v / 255.0 for v in rgb] + [1.0],
                                      physicsClientId=c)
            out.append((p.createMultiBody(0.0, -1, vis, physicsClientId=c),
                        (list(np.add(point, lift)), IDENTITY[1])))
        plate = b.get("plate")
        if plate:
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=[s / 2.0 for s in plate["size"]],
                                      rgbaColor=list(plate.get("rgba", (1, 1, 1, 1))),
                                      physicsClientId=c)
            out.append((p.createMultiBody(0.0, -1, vis, physicsClientId=c),
                        (list(plate["centre_target"]), IDENTITY[1])))
        return out

    def _place(self, name: str, T: Pose) -> None:
        if self.bodies[name]["kind"] == "urdf":
            return  # placed by loadURDF; a reset would place the inertial frame
        for bid, T_body_part in self.ids[name]:
            pos, quat = compose(T, T_body_part)
            p.resetBasePositionAndOrientation(bid, pos, quat, physicsClientId=self.client)

    # ------------------------------------------------------------------ state
    def set_row(self, row: pd.Series) -> None:
        """Joints from the ``q_columns``, moving bodies from their ``pose_columns``."""
        for name, b in self.bodies.items():
            if b["kind"] == "urdf":
                bid = self.ids[name][0][0]
                for j, col in zip(self.joints[name], b.get("q_columns") or [], strict=False):
                    p.resetJointState(bid, j, float(row[col]), physicsClientId=self.client)
            elif b.get("pose_columns"):
                v = [float(row[col]) for col in b["pose_columns"]]
                if np.all(np.isfinite(v)):
                    self._place(name, (v[:3], v[3:]))

    def frame_pose(self, robot: str, frame: str) -> Pose:
        """T_world_frame of a URDF link (its link frame) or of a mount of that name."""
        links = self.links[robot]
        if frame in links:
            if links[frame] == -1:
                return pose_of(self.bodies[robot]["base_pose"])
            st = p.getLinkState(self.ids[robot][0][0], links[frame],
                                computeForwardKinematics=True, physicsClientId=self.client)
            return list(st[4]), list(st[5])
        mount = self.scene.get("mounts", {}).get(frame)
        if mount is None or mount["robot"] != robot:
            raise ConfigError(f"scene.json: frame {frame!r} of {robot!r} is neither a link "
                              "nor a mount")
        return compose(self.frame_pose(robot, mount["parent_link"]),
                       pose_of(mount["T_parent_frame"]))

    def link_positions(self) -> np.ndarray:
        """(n, 3) world positions [m] of every robot link frame (for framing a view)."""
        pts = []
        for name, links in self.links.items():
            pts += [self.frame_pose(name, link)[0] for link in links]
        return np.asarray(pts, float).reshape(-1, 3)

    def body_positions(self) -> np.ndarray:
        """(n, 3) world positions [m] of every non-robot body part (as placed now)."""
        pts = [p.getBasePositionAndOrientation(bid, physicsClientId=self.client)[0]
               for name, ids in self.ids.items() if self.bodies[name]["kind"] != "urdf"
               for bid, _ in ids]
        return np.asarray(pts, float).reshape(-1, 3)

    # ------------------------------------------------------------------ render
    def render(self, view: list[float], projection: list[float], width: int, height: int,
               *, segmentation: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """(RGB image (height, width, 3) uint8, segmentation mask or None): TinyRenderer,
        no shadow, the default light (as the runs' cameras)."""
        flags = 0 if segmentation else p.ER_NO_SEGMENTATION_MASK
        img = p.getCameraImage(width, height, view, projection, shadow=0, flags=flags,
                               renderer=p.ER_TINY_RENDERER, physicsClientId=self.client)
        rgb = np.reshape(np.asarray(img[2], np.uint8), (height, width, 4))[:, :, :3]
        seg = np.reshape(np.asarray(img[4], np.int64), (height, width)) if segmentation else None
        return np.ascontiguousarray(rgb), seg
