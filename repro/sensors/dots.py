"""The coloured-dot targets the cameras measure: flat mesh discs on an optional plate, their
PyBullet bodies, and render-exact cylinders (see :mod:`repro.sensors.camera`'s docstring on
TinyRenderer's shapes)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from repro.errors import ConfigError
from repro.sensors.dot_detection import (
    _ELLIPSE_FILL_RANGE,
    _HUE_MARGIN,
    _HUE_TOLERANCE,
    _MAX_AREA_FACTOR,
    _MIN_SATURATION,
    _MIN_VALUE,
    _SATURATION_MARGIN,
    _check_colors,
    _hsv,
    _hue_distance,
)
from repro.sensors.intrinsics import _as_points, _as_pose

#: Six saturated colours with hues 60 deg apart (red, green, blue, yellow, magenta, cyan).
DEFAULT_DOT_COLORS: tuple[tuple[int, int, int], ...] = (
    (255, 0, 0),
    (0, 255, 0),
    (0, 0, 255),
    (255, 255, 0),
    (255, 0, 255),
    (0, 255, 255),
)

#: Sides of the regular polygon drawn for a dot disc (its vertices lie on the circle of
#: radius ``dot_radius``; the polygon's area is 0.16 % below the circle's).
DOT_SEGMENTS = 64
#: Sides of the prism drawn by :func:`cylinder_visual_shape`.
CYLINDER_SEGMENTS = 64
#: Gap between a dot (a flat disc in the target plane z = 0) and the top face of the plate
#: below it [m] (no z-fighting).
PLATE_GAP = 1e-4
#: Thickness of the plate [m].
PLATE_THICKNESS = 2e-3


@dataclass(frozen=True, eq=False)
class DotTarget:
    """Coloured dots (flat discs) on an optional white plate, or on a part built by the caller.

    Attributes:
        points_target: (N, 3) dot centres in the target frame [m]. With a plate the target is
            planar, z = 0; without one the dots need not be coplanar.
        colors: one RGB colour (0-255) per dot, saturated and of distinct hues; the colour
            identifies the dot, which gives the image-to-model correspondence.
        dot_radius: radius of every dot [m].
        plate_size: side lengths of the plate along x and y of the target frame [m]; None for
            no plate (each disc then faces +z of the target frame at its own height, e.g. on
            the faces of a part built by the caller, which must stay below the discs).
        hue_tolerance: half-width of the hue window of detection, OpenCV units (2 deg
            each); dot hues must be more than two tolerances apart. 10 allows 6 colours,
            8 allows 10 (36 deg apart).

    **Drawing** (:func:`spawn_dot_target`, :meth:`describe`): each dot is a flat regular
    ``DOT_SEGMENTS``-gon of circumradius ``dot_radius`` (a ``p.GEOM_MESH`` triangle fan, zero
    thickness, visible from +z only) lying in the plane through its point parallel to the
    target's xy plane, centred on the point: the model point *is* the centre of the visible
    disc. The plate (a ``p.GEOM_BOX``) has its top face ``PLATE_GAP`` below the dots.

    **What** :func:`detect_dots` **measures, and its bias.** The blob centroid is the centre
    of the disc's image ellipse, :func:`disc_image_centroids`, not the projection of the
    disc centre (:func:`project_points`): under perspective a tilted disc's near half images
    larger. This offset grows like ``f (r / Z)^2``: ~0.7 px for r = 12 mm at Z = 0.25 m,
    30 deg tilt, f = 600 px; <= 0.3 px for the 4 mm chan2011 dots at 0.22-0.36 m, f = 1060 px.
    The blob matches :func:`disc_image_centroids` within rasterisation noise as long as
    nothing hides part of the disc: <= 0.16 px around the chan2011 goals (dots seen 17-56 deg
    off their normal; bounded in tests/test_camera.py), up to ~0.6 px for thin ellipses
    (65-80 deg off), and a disc seen within ~5 deg of edge-on is lost (too thin a blob).

    Earlier the dots were ``p.GEOM_CYLINDER`` discs (0.2 mm thick, centred 0.1 mm below the
    point), which TinyRenderer draws 1 mm fat in every direction (see the module docstring):
    a 10 mm x 2.2 mm button whose top face was 1.0 mm above the model point. On the chan2011
    conrod's bosses (``p.GEOM_CYLINDER`` too, their faces drawn 1 mm too high) only that top
    face showed, so the blob sat ``f * 1 mm * sin(theta) / Z`` off (theta: view angle off the
    dot normal): 2.0 px predicted, 1.5-2.2 px measured for the seven boss dots at the end of
    the committed simulation run (Z = 0.21-0.24 m, theta ~ 26 deg; median 2.2-2.7 px over
    the run), 2-3.5 px (up to 6.6 px) in the experiment run at 0.25-0.36 m and larger theta;
    0.2 px for the three dots on the (exact) box beam, where the whole button showed.
    Tilted-disc perspective (<= 0.3 px), tessellation (64 sides), the 0.3 mm stand-off and
    the hue mask (flat discs shade uniformly) contribute < 0.3 px together. Flat mesh discs
    on render-exact parts (:func:`cylinder_visual_shape`) remove the bias.
    """

    points_target: np.ndarray
    colors: tuple[tuple[int, int, int], ...]
    dot_radius: float = 0.012
    plate_size: tuple[float, float] | None = (0.20, 0.20)
    hue_tolerance: int = _HUE_TOLERANCE

    def __post_init__(self) -> None:
        pts = _as_points(self.points_target, 3, "points_target").copy()
        if not np.all(np.isfinite(pts)):
            raise ConfigError("points_target must be finite")
        if self.plate_size is not None and np.any(np.abs(pts[:, 2]) > 1e-9):
            raise ConfigError("points_target must have z = 0 on a plate target "
                              "(plate_size=None allows non-coplanar dots)")
        pts.setflags(write=False)
        colors = tuple(tuple(int(c) for c in color) for color in self.colors)
        if len(colors) != pts.shape[0]:
            raise ConfigError(f"need one colour per dot: {pts.shape[0]} dots, "
                              f"{len(colors)} colours")
        if self.dot_radius <= 0 or (self.plate_size is not None and min(self.plate_size) <= 0):
            raise ConfigError(f"dot_radius and plate_size must be > 0, got {self.dot_radius}, "
                              f"{self.plate_size}")
        object.__setattr__(self, "points_target", pts)
        object.__setattr__(self, "colors", colors)
        _check_colors(colors, self.hue_tolerance)

    @property
    def n_points(self) -> int:
        """Number of dots N."""
        return int(self.points_target.shape[0])

    @classmethod
    def square(cls, half_side: float = 0.05, dot_radius: float = 0.012,
               plate_size: tuple[float, float] = (0.20, 0.20)) -> DotTarget:
        """Four dots at (+-half_side, +-half_side, 0) [m], red/green/blue/yellow.

        Order: (-a, -a), (+a, -a), (+a, +a), (-a, +a) in the target frame.
        """
        a = half_side
        pts = np.array([[-a, -a, 0.0], [a, -a, 0.0], [a, a, 0.0], [-a, a, 0.0]])
        return cls(pts, DEFAULT_DOT_COLORS[:4], dot_radius, plate_size)

    def points_world(self, T_world_target: np.ndarray) -> np.ndarray:
        """(N, 3) dot centres in the world frame [m] for the target pose ``T_world_target``."""
        T = _as_pose(T_world_target, "T_world_target")
        return self.points_target @ T[:3, :3].T + T[:3, 3]

    def describe(self) -> dict[str, Any]:
        """Everything needed to redraw and re-detect the dots with plain PyBullet/OpenCV
        (JSON-able; lengths in metres, poses in the target frame, whose world pose the
        caller records)."""
        vertices, indices = _disc_mesh(self.dot_radius)
        plate = None
        if self.plate_size is not None:
            plate = {
                "shape": "box",
                "size": [*self.plate_size, PLATE_THICKNESS],
                "centre_target": [0.0, 0.0, -PLATE_GAP - PLATE_THICKNESS / 2.0],
                "top_face_z": -PLATE_GAP,
                "gap_below_dots": PLATE_GAP,
                "rgba": [1.0, 1.0, 1.0, 1.0],
                "pybullet": "p.createVisualShape(p.GEOM_BOX, halfExtents=size / 2) at "
                            "T_world_target @ trans(centre_target)",
            }
        return {
            "points_target": self.points_target.tolist(),
            "point_definition": "centre of dot i's disc, in the target frame [m]",
            "colors_rgb255": [list(c) for c in self.colors],
            "dot": {
                "shape": "disc",
                "radius": self.dot_radius,
                "thickness": 0.0,
                "n_sides": DOT_SEGMENTS,
                "polygon": "regular polygon, vertex k at radius * (cos(2 pi k / n_sides), "
                           "sin(2 pi k / n_sides), 0) in the dot frame",
                "dot_frame": "T_world_target @ trans(points_target[i]): the disc lies in the "
                             "dot frame's xy plane, centred on its origin, facing +z of the "
                             "target frame (visible from z > 0 only)",
                "top_face_offset": 0.0,
                "top_face": "the visible face contains the model point and is centred on it "
                            "(offset along +z of the target frame [m])",
                "pybullet": "p.createVisualShape(p.GEOM_MESH, vertices=mesh.vertices, "
                            "indices=mesh.indices, rgbaColor=colors_rgb255[i] / 255 + [1]) "
                            "placed at the dot frame (not p.GEOM_CYLINDER, which TinyRenderer "
                            "draws 1 mm fat)",
                "mesh": {"vertices": vertices, "indices": indices},
            },
            "plate": plate,
            "detection": {
                "colour_space": "OpenCV HSV of the RGB image (H in [0, 180), S, V in [0, 255])",
                "hue_tolerance": self.hue_tolerance,
                "min_saturation": _MIN_SATURATION,
                "min_value": _MIN_VALUE,
                "blob": "per dot: the largest 8-connected component of its mask with an "
                        "ellipse fill area / (4 pi sqrt(det Sigma)) in "
                        f"{list(_ELLIPSE_FILL_RANGE)} and an area no larger than "
                        f"{_MAX_AREA_FACTOR} x pi (f r / Z + 1)^2 px",
                "measured_point": "blob centroid (first-order moments) = centre of the disc's "
                                  "image ellipse (perspective bias vs the projected centre)",
            },
            "pixel_convention": "(u, v) [px]: u right (column), v down (row); (0, 0) is the "
                                "centre of the top-left pixel, so pixel rgb[r, c] is at "
                                "(u, v) = (c, r) and the image spans u in [-1/2, W - 1/2], "
                                "v in [-1/2, H - 1/2]",
        }


def _disc_mesh(radius: float, n: int = DOT_SEGMENTS) -> tuple[list[list[float]], list[int]]:
    """Flat regular n-gon of circumradius ``radius`` [m] in the xy plane, centred on the
    origin, as a triangle fan wound counter-clockwise seen from +z (visible from +z only)."""
    a = 2.0 * np.pi * np.arange(n) / n
    vertices = [[0.0, 0.0, 0.0]] + [[radius * float(np.cos(t)), radius * float(np.sin(t)), 0.0]
                                    for t in a]
    indices = [i for k in range(n) for i in (0, 1 + k, 1 + (k + 1) % n)]
    return vertices, indices


def cylinder_visual_shape(client_id: int, radius: float, length: float,
                          rgba: Sequence[float], n_segments: int = CYLINDER_SEGMENTS) -> int:
    """Visual shape of a cylinder that TinyRenderer draws at its true size.

    ``p.GEOM_CYLINDER`` visuals are drawn as a convex hull inflated by a 1 mm margin (see
    the module docstring); this is a closed regular ``n_segments``-gon prism mesh
    (``p.GEOM_MESH``) with its vertices on the circle of ``radius``, flat caps and smooth
    side normals. Axis along z of the shape frame, centred on its origin (as
    ``p.GEOM_CYLINDER``). Use it for bodies a camera sees, e.g. parts carrying dots.

    Args:
        client_id: PyBullet physics client id.
        radius: radius [m]; length: length along z [m].
        rgba: colour, 4 floats in [0, 1].
        n_segments: number of sides of the prism.

    Returns:
        The visual shape id (for ``p.createMultiBody(baseVisualShapeIndex=...)``).
    """
    if not (radius > 0 and length > 0) or n_segments < 3:
        raise ConfigError(f"need radius, length > 0 and n_segments >= 3, got {radius}, "
                          f"{length}, {n_segments}")
    a = 2.0 * np.pi * np.arange(n_segments) / n_segments
    ring = np.c_[radius * np.cos(a), radius * np.sin(a)]
    h = length / 2.0
    vertices: list[list[float]] = []
    normals: list[list[float]] = []
    indices: list[int] = []
    for z, sign in ((h, 1.0), (-h, -1.0)):  # caps: centre + ring, flat normals
        base = len(vertices)
        vertices += [[0.0, 0.0, z]] + [[x, y, z] for x, y in ring]
        normals += [[0.0, 0.0, sign]] * (n_segments + 1)
        for k in range(n_segments):
            a0, a1 = base + 1 + k, base + 1 + (k + 1) % n_segments
            indices += [base, a0, a1] if sign > 0 else [base, a1, a0]
    base = len(vertices)  # side: top and bottom rings, radial normals
    for x, y in ring:
        vertices += [[x, y, h], [x, y, -h]]
        normals += [[x / radius, y / radius, 0.0]] * 2
    for k in range(n_segments):
        t0, b0 = base + 2 * k, base + 2 * k + 1
        t1, b1 = base + 2 * ((k + 1) % n_segments), base + 2 * ((k + 1) % n_segments) + 1
        indices += [t0, b0, b1, t0, b1, t1]
    return int(p.createVisualShape(p.GEOM_MESH, vertices=vertices, indices=indices,
                                   normals=normals, rgbaColor=list(rgba),
                                   physicsClientId=client_id))


def _dot_target_poses(target: DotTarget, T_world_target: np.ndarray
                      ) -> list[tuple[list[float], list[float]]]:
    """World (position, xyzw quaternion) of the plate and of each disc body."""
    T = _as_pose(T_world_target, "T_world_target")
    quat = _quat_xyzw(T[:3, :3])
    centres = ([np.array([0.0, 0.0, -PLATE_GAP - PLATE_THICKNESS / 2.0])]
               if target.plate_size is not None else [])
    centres += list(target.points_target)
    return [((T[:3, :3] @ c + T[:3, 3]).tolist(), quat) for c in centres]


def _quat_xyzw(R: np.ndarray) -> list[float]:
    """xyzw unit quaternion of a rotation matrix (PyBullet's order)."""
    return Rotation.from_matrix(R).as_quat().tolist()


def spawn_dot_target(client_id: int, target: DotTarget, T_world_target: np.ndarray) -> list[int]:
    """Create the target's visual bodies in a PyBullet client (as :meth:`DotTarget.describe`).

    A white box plate (``plate_size`` x ``PLATE_THICKNESS``) whose top face lies
    ``PLATE_GAP`` below the target plane, and per dot a flat disc mesh (see
    :class:`DotTarget`) centred on the dot, in the plane through it parallel to the target's
    xy plane, facing +z. Visual shapes only: no collision shape, mass 0.

    Args:
        client_id: PyBullet physics client id.
        target: the target model.
        T_world_target: 4x4 pose of the target frame in the world frame [m].

    Returns:
        Body ids: ``[plate, dot_0, ..., dot_{N-1}]`` (no plate id when ``plate_size`` is None).
    """
    shapes = []
    if target.plate_size is not None:
        sx, sy = target.plate_size
        shapes.append(p.createVisualShape(
            p.GEOM_BOX, halfExtents=[sx / 2.0, sy / 2.0, PLATE_THICKNESS / 2.0],
            rgbaColor=[1.0, 1.0, 1.0, 1.0], physicsClientId=client_id))
    vertices, indices = _disc_mesh(target.dot_radius)
    for color in target.colors:
        shapes.append(p.createVisualShape(
            p.GEOM_MESH, vertices=vertices, indices=indices,
            rgbaColor=[c / 255.0 for c in color] + [1.0], physicsClientId=client_id))
    ids = []
    for shape, (pos, quat) in zip(shapes, _dot_target_poses(target, T_world_target),
                                  strict=True):
        ids.append(p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=-1,
                                     baseVisualShapeIndex=shape, basePosition=pos,
                                     baseOrientation=quat, physicsClientId=client_id))
    return ids


def move_dot_target(client_id: int, body_ids: Sequence[int], target: DotTarget,
                    T_world_target: np.ndarray) -> None:
    """Move bodies made by :func:`spawn_dot_target` so the target frame is at ``T_world_target``."""
    poses = _dot_target_poses(target, T_world_target)
    if len(body_ids) != len(poses):
        raise ConfigError(f"expected {len(poses)} body ids, got {len(body_ids)}")
    for body, (pos, quat) in zip(body_ids, poses, strict=True):
        p.resetBasePositionAndOrientation(body, pos, quat, physicsClientId=client_id)


def check_scene_colors(target: DotTarget, body_rgba: Mapping[str, Sequence[float]]) -> None:
    """Reject a scene in which a body's colour could pass a dot's detection mask.

    :func:`detect_dots` keeps the pixels whose OpenCV hue is within ``hue_tolerance`` of a
    dot's hue and whose saturation is >= 100/255. TinyRenderer shades a colour ``c`` as
    ``k c + w`` (``k`` in [0, 0.95]: ambient + diffuse; ``w`` >= 0: a grey specular term),
    which keeps its hue and never raises its saturation; so a body whose colour is
    desaturated (S < 90/255) or whose hue is more than ``hue_tolerance + 3`` units from every
    dot hue can never produce dot pixels, whatever its pose and lighting. Its value V is not
    used (a specular highlight can lift a dark body above the mask's V threshold). With
    dot hues all around the circle (e.g. ten hues 36 deg apart) this means: every other body
    in view must be desaturated (greys, beiges, ...).

    Args:
        target: the dot target (colours and hue tolerance).
        body_rgba: body name -> its colour, RGB or RGBA floats in [0, 1] (PyBullet's
            ``rgbaColor``; alpha is ignored).

    Raises:
        ConfigError: naming the first body and dot that conflict, with both colours.
    """
    hues = _check_colors(target.colors, target.hue_tolerance)
    window = target.hue_tolerance + _HUE_MARGIN
    for name, rgba in body_rgba.items():
        c = [float(x) for x in rgba]
        if len(c) not in (3, 4) or not all(0.0 <= x <= 1.0 for x in c):
            raise ConfigError(f"colour of body {name!r} must be RGB(A) floats in [0, 1], "
                              f"got {tuple(rgba)}")
        rgb8 = [int(round(255.0 * x)) for x in c[:3]]
        h, s_, v = (int(x) for x in _hsv(rgb8))
        if s_ < _MIN_SATURATION - _SATURATION_MARGIN:
            continue
        for i, hue in enumerate(hues):
            if _hue_distance(h, hue) <= window:
                raise ConfigError(
                    f"body {name!r} (rgba {tuple(c)}, OpenCV HSV ({h}, {s_}, {v})) would pass "
                    f"the detection mask of dot index {i} (RGB {target.colors[i]}, hue {hue} +- "
                    f"{target.hue_tolerance}): give the body a desaturated colour (HSV "
                    f"saturation < {(_MIN_SATURATION - _SATURATION_MARGIN) / 255:.2f}, e.g. a "
                    f"grey or a beige) or a hue more than {window} units (2 deg each) from "
                    f"every dot hue")
