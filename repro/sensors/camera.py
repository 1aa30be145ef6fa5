"""Eye-in-hand pinhole camera: model, PyBullet rendering and coloured-dot detection.

Conventions (used by every function of this module and by :mod:`repro.vision.features`):

* **Camera frame** ``{c}`` (computer-vision convention): origin at the optical centre,
  ``+z`` along the optical axis (forward, into the scene), ``+x`` to the right of the image
  and ``+y`` down the image. ``T_world_camera`` is the 4x4 homogeneous pose of ``{c}`` in
  the world frame (so ``P_world = T_world_camera @ P_camera``); lengths in metres.
* **Normalised coordinates** of a point ``(X, Y, Z)`` of ``{c}`` with ``Z > 0``:
  ``x = X / Z``, ``y = Y / Z`` (dimensionless).
* **Pixel coordinates** ``(u, v)`` [px]: ``u`` to the right (column), ``v`` down (row).
  ``(0, 0)`` is the *centre* of the top-left pixel, so pixel ``rgb[r, c]`` covers
  ``u in [c - 1/2, c + 1/2]``, ``v in [r - 1/2, r + 1/2]`` and the image spans
  ``u in [-1/2, W - 1/2]``, ``v in [-1/2, H - 1/2]``. A centred principal point is
  ``(u0, v0) = ((W - 1) / 2, (H - 1) / 2)``.

.. math::

    u = f_u \\, x + u_0, \\qquad v = f_v \\, y + v_0, \\qquad
    K = \\begin{bmatrix} f_u & 0 & u_0 \\\\ 0 & f_v & v_0 \\\\ 0 & 0 & 1 \\end{bmatrix}.

Rendering goes through ``pybullet.getCameraImage``, which takes OpenGL-style view and
projection matrices (eye frame ``x`` right, ``y`` up, ``z`` backwards; 16 floats in
column-major order; image row 0 is the top row). PyBullet's TinyRenderer samples each pixel
at its *corner* (integer viewport coordinates), not at its centre as OpenGL does, so
:meth:`Intrinsics.projection_matrix_gl` shifts the principal point accordingly (see there):
with that matrix a rendered point lands on the pixel :func:`project_points` predicts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from repro.errors import ConfigError, UnknownChoiceError

#: Camera modes of :class:`Camera`.
CAMERA_MODES = ("render", "exact")

#: Renderers :meth:`Intrinsics.projection_matrix_gl` can build a matrix for.
GL_RENDERERS = ("tiny", "opengl")

#: Where each renderer samples a pixel, as an offset from the pixel's lower-left corner in
#: OpenGL window coordinates [px]: TinyRenderer at the corner, OpenGL at the centre.
_SAMPLE_OFFSET = {"tiny": 0.0, "opengl": 0.5}

#: Six saturated colours with hues 60 deg apart (red, green, blue, yellow, magenta, cyan).
DEFAULT_DOT_COLORS: tuple[tuple[int, int, int], ...] = (
    (255, 0, 0),
    (0, 255, 0),
    (0, 0, 255),
    (255, 255, 0),
    (255, 0, 255),
    (0, 255, 255),
)

#: Thickness of a rendered dot disc [m]; its top face is at z = 0 of the target frame.
DISC_THICKNESS = 2e-4
#: Gap between the top face of a disc and the top face of the plate [m] (plate below).
PLATE_GAP = 1e-4
#: Thickness of the plate [m].
PLATE_THICKNESS = 2e-3

# OpenGL eye frame (x right, y up, z backwards) from the camera frame (x right, y down,
# z forward): a rotation of pi about x.
_GL_FROM_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def _as_pose(T: np.ndarray, name: str) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ConfigError(f"{name} must be a finite 4x4 homogeneous matrix, got shape {T.shape}")
    return T


def _as_points(P: np.ndarray, dim: int, name: str) -> np.ndarray:
    P = np.asarray(P, dtype=float)
    if P.ndim != 2 or P.shape[1] != dim:
        raise ConfigError(f"{name} must have shape (N, {dim}), got {P.shape}")
    return P


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics (no distortion) plus the clipping planes used for rendering.

    Attributes:
        width, height: image size W, H [px].
        fu, fv: focal lengths along u and v [px].
        u0, v0: principal point [px], in the pixel-centre convention of this module.
        near, far: clipping distances along the optical axis for rendering [m].
    """

    width: int
    height: int
    fu: float
    fv: float
    u0: float
    v0: float
    near: float = 0.01
    far: float = 5.0

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise ConfigError(f"image size must be positive, got {self.width}x{self.height}")
        if not (self.fu > 0 and self.fv > 0):
            raise ConfigError(f"focal lengths must be > 0, got fu={self.fu}, fv={self.fv}")
        if not (0 < self.near < self.far):
            raise ConfigError(f"need 0 < near < far, got near={self.near}, far={self.far}")

    @classmethod
    def centered(cls, width: int, height: int, fu: float, fv: float | None = None,
                 near: float = 0.01, far: float = 5.0) -> Intrinsics:
        """Intrinsics with the principal point at the image centre ((W-1)/2, (H-1)/2) [px]."""
        return cls(width, height, fu, fu if fv is None else fv,
                   (width - 1) / 2.0, (height - 1) / 2.0, near, far)

    def K(self) -> np.ndarray:
        """3x3 calibration matrix mapping homogeneous normalised coordinates to pixels."""
        return np.array([[self.fu, 0.0, self.u0], [0.0, self.fv, self.v0], [0.0, 0.0, 1.0]])

    def to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Pixel coordinates (N, 2) [px] -> normalised coordinates (N, 2) [-].

        .. math:: x = (u - u_0) / f_u, \\qquad y = (v - v_0) / f_v
        """
        uv = np.asarray(uv, dtype=float)
        return np.stack([(uv[..., 0] - self.u0) / self.fu, (uv[..., 1] - self.v0) / self.fv],
                        axis=-1)

    def to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """Normalised coordinates (N, 2) [-] -> pixel coordinates (N, 2) [px].

        .. math:: u = f_u x + u_0, \\qquad v = f_v y + v_0
        """
        xy = np.asarray(xy, dtype=float)
        return np.stack([self.fu * xy[..., 0] + self.u0, self.fv * xy[..., 1] + self.v0],
                        axis=-1)

    def in_image(self, uv: np.ndarray) -> np.ndarray:
        """(N,) bool: True where (u, v) [px] lies on the image, u in [-1/2, W-1/2] etc."""
        uv = np.asarray(uv, dtype=float)
        with np.errstate(invalid="ignore"):
            return ((uv[..., 0] >= -0.5) & (uv[..., 0] <= self.width - 0.5)
                    & (uv[..., 1] >= -0.5) & (uv[..., 1] <= self.height - 0.5))

    def projection_matrix_gl(self, renderer: str = "tiny") -> list[float]:
        """OpenGL-style projection matrix for ``getCameraImage``: 16 floats, column-major.

        Maps OpenGL eye coordinates (``x`` right, ``y`` up, ``z`` backwards, see
        :func:`view_matrix_gl`) to clip coordinates such that the renderer's sample point
        for pixel ``rgb[r, c]`` is the point that projects to ``(u, v) = (c, r)``. It honours
        an off-centre principal point and ``fu != fv``. With ``s`` the sample offset of the
        renderer (window coordinates of pixel ``(r, c)``'s sample point are
        ``(c + s, H - 1 - r + s)``, origin at the lower-left image corner):

        .. math::

            P = \\begin{bmatrix}
                2 f_u / W & 0 & 1 - 2 (u_0 + s) / W & 0 \\\\
                0 & 2 f_v / H & 2 (v_0 + 1 - s) / H - 1 & 0 \\\\
                0 & 0 & -(f + n) / (f - n) & -2 f n / (f - n) \\\\
                0 & 0 & -1 & 0
            \\end{bmatrix}

        with ``n, f`` = ``near, far``.

        Args:
            renderer: ``"tiny"`` (PyBullet's ``ER_TINY_RENDERER``, which samples pixels at
                integer viewport coordinates, i.e. at a pixel corner: ``s = 0``; verified by
                the render-vs-projection test) or ``"opengl"`` (``ER_BULLET_HARDWARE_OPENGL``,
                standard OpenGL sampling at pixel centres: ``s = 1/2``).

        Note: PyBullet's own ``computeProjectionMatrixFOV`` equals the ``"opengl"`` matrix
        with a centred principal point; used with TinyRenderer it puts the principal point
        at ``(W/2, H/2 - 1)`` instead of ``((W-1)/2, (H-1)/2)``, half a pixel off in both axes.
        """
        if renderer not in _SAMPLE_OFFSET:
            raise UnknownChoiceError("GL renderer", renderer, GL_RENDERERS)
        s = _SAMPLE_OFFSET[renderer]
        W, H, n, f = float(self.width), float(self.height), self.near, self.far
        P = np.zeros((4, 4))
        P[0, 0] = 2.0 * self.fu / W
        P[0, 2] = 1.0 - 2.0 * (self.u0 + s) / W
        P[1, 1] = 2.0 * self.fv / H
        P[1, 2] = 2.0 * (self.v0 + 1.0 - s) / H - 1.0
        P[2, 2] = -(f + n) / (f - n)
        P[2, 3] = -2.0 * f * n / (f - n)
        P[3, 2] = -1.0
        return P.flatten(order="F").tolist()


def view_matrix_gl(T_world_camera: np.ndarray) -> list[float]:
    """OpenGL view matrix for ``getCameraImage``: 16 floats, column-major.

    The view matrix maps world coordinates to the OpenGL eye frame, which is the camera
    frame ``{c}`` rotated by pi about its x axis (``y`` up, ``z`` backwards):

    .. math:: V = \\mathrm{diag}(1, -1, -1, 1) \\, T_{world,camera}^{-1}

    Args:
        T_world_camera: 4x4 pose of the camera frame (x right, y down, z forward) in the
            world frame [m].
    """
    T = _as_pose(T_world_camera, "T_world_camera")
    R, t = T[:3, :3], T[:3, 3]
    T_camera_world = np.eye(4)
    T_camera_world[:3, :3] = R.T
    T_camera_world[:3, 3] = -R.T @ t
    return (_GL_FROM_CV @ T_camera_world).flatten(order="F").tolist()


def project_points(intr: Intrinsics, T_world_camera: np.ndarray,
                   P_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact pinhole projection of world points.

    .. math::

        (X, Y, Z)^T = R^T (P_{world} - t), \\qquad
        u = f_u X / Z + u_0, \\qquad v = f_v Y / Z + v_0

    with ``R, t`` the rotation and translation of ``T_world_camera``.

    Args:
        intr: camera intrinsics.
        T_world_camera: 4x4 pose of the camera frame in the world frame [m].
        P_world: (N, 3) points in the world frame [m].

    Returns:
        ``(uv, Z)``: ``uv`` (N, 2) pixel coordinates [px] (NaN rows for points with
        ``Z <= 0``, which have no image; no test against the image bounds, see
        :meth:`Intrinsics.in_image`) and ``Z`` (N,) depths along the optical axis in the
        camera frame [m].
    """
    T = _as_pose(T_world_camera, "T_world_camera")
    P = _as_points(P_world, 3, "P_world")
    P_c = (P - T[:3, 3]) @ T[:3, :3]
    Z = P_c[:, 2].copy()
    uv = np.full((P.shape[0], 2), np.nan)
    ok = Z > 0
    uv[ok] = intr.to_pixels(P_c[ok, :2] / Z[ok, None])
    return uv, Z


def disc_image_centroids(intr: Intrinsics, T_world_camera: np.ndarray, target: DotTarget,
                         T_world_target: np.ndarray) -> np.ndarray:
    """Exact centroids of the images of the target's (full, unoccluded) dot discs.

    The image of a circle of the target plane is a conic; this returns its centre, which is
    the centroid of the filled ellipse and differs from the projection of the disc centre
    (:func:`project_points`) when the disc is tilted (perspective bias). With ``H`` the
    plane-to-image homography and ``C_0`` the circle of centre ``(c_x, c_y)``, radius ``r``:

    .. math::

        H = K \\, [r_1 \\; r_2 \\; t], \\qquad
        C_0 = \\begin{bmatrix} 1 & 0 & -c_x \\\\ 0 & 1 & -c_y \\\\
              -c_x & -c_y & c_x^2 + c_y^2 - r^2 \\end{bmatrix}, \\qquad
        C = H^{-T} C_0 H^{-1}, \\qquad
        (u, v)^T = -C_{1:2,1:2}^{-1} C_{1:2,3}

    with ``r_1, r_2, t`` the first two columns of the rotation and the translation of
    ``T_camera_target``. Valid when the whole disc is in front of the camera.

    Args:
        intr: camera intrinsics.
        T_world_camera: 4x4 pose of the camera frame in the world frame [m].
        target: the dot target (``dot_radius`` is the disc radius r).
        T_world_target: 4x4 pose of the target frame in the world frame [m].

    Returns:
        (N, 2) ellipse centres [px].
    """
    T_cw = np.linalg.inv(_as_pose(T_world_camera, "T_world_camera"))
    T_ct = T_cw @ _as_pose(T_world_target, "T_world_target")
    H_inv = np.linalg.inv(intr.K() @ T_ct[:3, [0, 1, 3]])
    r = target.dot_radius
    out = np.empty((target.n_points, 2))
    for i, (cx, cy, _) in enumerate(target.points_target):
        C0 = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [-cx, -cy, cx * cx + cy * cy - r * r]])
        C = H_inv.T @ C0 @ H_inv
        out[i] = -np.linalg.solve(C[:2, :2], C[:2, 2])
    return out


def render_rgb(client_id: int, intr: Intrinsics, T_world_camera: np.ndarray) -> np.ndarray:
    """Render the scene of a PyBullet client seen from ``T_world_camera``.

    Uses ``getCameraImage`` with ``ER_TINY_RENDERER`` (works in ``DIRECT`` mode), no
    shadows and no segmentation mask, with :func:`view_matrix_gl` and
    ``intr.projection_matrix_gl("tiny")``, so that pixel ``rgb[r, c]`` samples the ray of
    ``(u, v) = (c, r)``. Empty background renders white.

    Args:
        client_id: PyBullet physics client id.
        intr: camera intrinsics (image size, focal lengths, principal point, clipping).
        T_world_camera: 4x4 pose of the camera frame in the world frame [m].

    Returns:
        (H, W, 3) uint8 RGB image; row 0 is the top of the image.
    """
    _, _, rgba, _, _ = p.getCameraImage(
        intr.width,
        intr.height,
        viewMatrix=view_matrix_gl(T_world_camera),
        projectionMatrix=intr.projection_matrix_gl("tiny"),
        renderer=p.ER_TINY_RENDERER,
        shadow=0,
        flags=p.ER_NO_SEGMENTATION_MASK,
        physicsClientId=client_id,
    )
    img = np.asarray(rgba, dtype=np.uint8).reshape(intr.height, intr.width, 4)
    return np.ascontiguousarray(img[:, :, :3])


def _hsv(color: Sequence[int]) -> np.ndarray:
    """OpenCV HSV (H in [0, 180), S and V in [0, 255]) of one RGB colour."""
    rgb = np.array([[list(color)]], dtype=np.uint8)
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)[0, 0].astype(int)


#: Minimum HSV saturation (0-255) of a dot colour, and of a pixel to be a dot pixel.
_MIN_SATURATION = 100
#: Minimum HSV value (0-255) of a pixel to be a dot pixel.
_MIN_VALUE = 40
#: Half-width of the hue window around a dot colour, in OpenCV hue units (2 deg each).
_HUE_TOLERANCE = 10


def _check_colors(colors: Sequence[Sequence[int]], hue_tolerance: int = _HUE_TOLERANCE
                  ) -> list[int]:
    """Validate dot colours (saturated, hues more than two tolerances apart); return their
    OpenCV hues."""
    hues = []
    for color in colors:
        if len(color) != 3 or not all(0 <= int(c) <= 255 for c in color):
            raise ConfigError(f"dot colour must be an RGB triple in 0-255, got {color!r}")
        hsv = _hsv(color)
        if hsv[1] < 2 * _MIN_SATURATION or hsv[2] < 2 * _MIN_VALUE:
            raise ConfigError(f"dot colour {tuple(color)} is not saturated/bright enough for "
                              f"hue-based detection (HSV {tuple(hsv)})")
        hues.append(int(hsv[0]))
    for i in range(len(hues)):
        for j in range(i):
            d = abs(hues[i] - hues[j])
            if min(d, 180 - d) <= 2 * hue_tolerance:
                raise ConfigError(f"dot colours {tuple(colors[j])} and {tuple(colors[i])} have "
                                  f"hues closer than {4 * hue_tolerance} deg")
    return hues


@dataclass(frozen=True, eq=False)
class DotTarget:
    """Planar target: a white plate carrying coloured dots.

    Attributes:
        points_target: (N, 3) dot centres in the target frame [m]; the target is planar,
            z = 0 (the plate's visible face is at z = 0, its normal is +z of the target frame).
        colors: one RGB colour (0-255) per dot, saturated and of distinct hues; the colour
            identifies the dot, which gives the image-to-model correspondence.
        dot_radius: radius of every dot [m].
        plate_size: side lengths of the plate along x and y of the target frame [m]; None for
            no plate: the dots then need not be coplanar (each disc faces +z of the target
            frame at its own height, e.g. on the faces of a part built by the caller).
        hue_tolerance: half-width of the hue window of detection, OpenCV units (2 deg
            each); dot hues must be more than two tolerances apart. 10 allows 6 colours,
            8 allows 10 (36 deg apart).

    Note: under perspective the centroid of the image of a tilted disc (what
    :func:`detect_dots` measures) is not the image of its centre (what :func:`project_points`
    gives); the offset grows like ``f (r / Z)^2``: ~0.7 px for r = 12 mm at Z = 0.25 m,
    30 deg tilt, f = 600 px (up to ~1 px in the worst geometry), ~0.2 px for r = 6 mm.
    :func:`disc_image_centroids` computes the exact blob centre.
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


def _dot_target_poses(target: DotTarget, T_world_target: np.ndarray
                      ) -> list[tuple[list[float], list[float]]]:
    """World (position, xyzw quaternion) of the plate and of each disc body."""
    T = _as_pose(T_world_target, "T_world_target")
    quat = _quat_xyzw(T[:3, :3])
    centres = ([np.array([0.0, 0.0, -PLATE_GAP - PLATE_THICKNESS / 2.0])]
               if target.plate_size is not None else [])
    centres += [pt + np.array([0.0, 0.0, -DISC_THICKNESS / 2.0]) for pt in target.points_target]
    return [((T[:3, :3] @ c + T[:3, 3]).tolist(), quat) for c in centres]


def _quat_xyzw(R: np.ndarray) -> list[float]:
    """xyzw unit quaternion of a rotation matrix (PyBullet's order)."""
    return Rotation.from_matrix(R).as_quat().tolist()


def spawn_dot_target(client_id: int, target: DotTarget, T_world_target: np.ndarray) -> list[int]:
    """Create the target's visual bodies in a PyBullet client.

    A white box plate (``plate_size`` x ``PLATE_THICKNESS``) whose top face lies
    ``PLATE_GAP`` below the target plane, and per dot a cylinder disc of radius
    ``dot_radius`` and thickness ``DISC_THICKNESS`` whose top face, centred on the dot, lies in
    the target plane z = 0 (so the visible dot centre is exactly ``points_target``). Visual
    shapes only: no collision shape, mass 0.

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
    for color in target.colors:
        shapes.append(p.createVisualShape(
            p.GEOM_CYLINDER, radius=target.dot_radius, length=DISC_THICKNESS,
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


def _hue_mask(hsv: np.ndarray, hue: int, tolerance: int = _HUE_TOLERANCE) -> np.ndarray:
    """uint8 mask of vivid pixels whose hue is within ``tolerance`` of ``hue`` (OpenCV units)."""
    lo, hi = hue - tolerance, hue + tolerance
    ranges = [(max(lo, 0), min(hi, 179))]
    if lo < 0:  # the hue circle wraps at 180 (red)
        ranges.append((180 + lo, 179))
    if hi > 179:
        ranges.append((0, hi - 180))
    mask = None
    for a, b in ranges:
        m = cv2.inRange(hsv, np.array([a, _MIN_SATURATION, _MIN_VALUE], dtype=np.uint8),
                        np.array([b, 255, 255], dtype=np.uint8))
        mask = m if mask is None else cv2.bitwise_or(mask, m)
    assert mask is not None
    return mask


def detect_dots(rgb: np.ndarray, colors: Sequence[Sequence[int]],
                min_area_px: int = 6, hue_tolerance: int = _HUE_TOLERANCE
                ) -> tuple[np.ndarray, np.ndarray]:
    """Find the centroid of each coloured dot in an RGB image.

    Per colour: HSV mask (hue within +-20 deg of the colour's hue, saturation >= 100/255,
    value >= 40/255; TinyRenderer's shading scales a colour, which keeps its hue), 8-connected
    components, and the centroid (first-order image moments) of the largest component:

    .. math:: u = m_{10} / m_{00}, \\qquad v = m_{01} / m_{00}

    in the pixel-centre convention of this module (pixel ``rgb[r, c]`` is at ``(c, r)``).

    Args:
        rgb: (H, W, 3) uint8 RGB image.
        colors: N RGB colours (0-255), saturated and of distinct hues.
        min_area_px: a largest component smaller than this [px] counts as not found.

    Returns:
        ``(uv, found)``: ``uv`` (N, 2) centroids [px], NaN rows for dots not found;
        ``found`` (N,) bool.

    Limitations: a dot cut by the image border is still found, with the centroid of its
    visible part; any other saturated object of a similar hue in view (e.g. an orange robot
    link vs a red or yellow dot) competes for the largest component.
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ConfigError(f"rgb must be an (H, W, 3) uint8 image, got {rgb.shape} {rgb.dtype}")
    hues = _check_colors(colors, hue_tolerance)
    hsv = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2HSV)
    uv = np.full((len(hues), 2), np.nan)
    found = np.zeros(len(hues), dtype=bool)
    for i, hue in enumerate(hues):
        mask = _hue_mask(hsv, hue, hue_tolerance)
        # Label only the bounding box of the mask's pixels (a few hundred pixels instead of
        # the whole image); the centroid is shifted back to full-image coordinates.
        x0, y0, w, h = cv2.boundingRect(mask)
        if w == 0 or h == 0:
            continue
        n, _, stats, centroids = cv2.connectedComponentsWithStats(
            np.ascontiguousarray(mask[y0:y0 + h, x0:x0 + w]), connectivity=8)
        if n < 2:
            continue
        k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        if stats[k, cv2.CC_STAT_AREA] < min_area_px:
            continue
        uv[i] = centroids[k] + (x0, y0)
        found[i] = True
    return uv, found


@dataclass
class Camera:
    """Camera rigidly mounted on a link, measuring the dots of a :class:`DotTarget`.

    Attributes:
        intrinsics: pinhole intrinsics.
        T_link_camera: 4x4 pose of the camera frame (x right, y down, z forward) in the
            frame of the link it is fixed to [m].
        mode: ``"render"`` (PyBullet TinyRenderer image + :func:`detect_dots`; the target must
            already be spawned in the client at ``T_world_target``) or ``"exact"``
            (:func:`project_points` of the dot centres, no rendering).
    """

    intrinsics: Intrinsics
    T_link_camera: np.ndarray = field(default_factory=lambda: np.eye(4))
    mode: str = "render"

    def __post_init__(self) -> None:
        if self.mode not in CAMERA_MODES:
            raise UnknownChoiceError("camera mode", self.mode, CAMERA_MODES)
        self.T_link_camera = _as_pose(self.T_link_camera, "T_link_camera").copy()

    def pose(self, T_world_link: np.ndarray) -> np.ndarray:
        """T_world_camera = T_world_link @ T_link_camera (4x4) [m]."""
        return _as_pose(T_world_link, "T_world_link") @ self.T_link_camera

    def measure(self, client_id: int, T_world_camera: np.ndarray, target: DotTarget,
                T_world_target: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Measure the image points of the target's dots.

        Args:
            client_id: PyBullet physics client id (used in ``"render"`` mode only).
            T_world_camera: 4x4 pose of the camera frame in the world frame [m].
            target: the dot target.
            T_world_target: 4x4 pose of the target frame in the world frame [m].

        Returns:
            ``(uv, found, Z)``: ``uv`` (N, 2) [px], NaN rows where not found; ``found`` (N,)
            bool -- the detection result in ``"render"`` mode, and in ``"exact"`` mode False
            for dots behind the camera (Z <= 0) or whose centre projects outside the image;
            ``Z`` (N,) depth of each dot centre in the camera frame from the exact
            geometry [m] (for every dot, found or not).
        """
        if self.mode not in CAMERA_MODES:
            raise UnknownChoiceError("camera mode", self.mode, CAMERA_MODES)
        uv_exact, Z = project_points(self.intrinsics, T_world_camera,
                                     target.points_world(T_world_target))
        if self.mode == "exact":
            found = (Z > 0) & self.intrinsics.in_image(uv_exact)
            uv = np.where(found[:, None], uv_exact, np.nan)
            return uv, found, Z
        rgb = render_rgb(client_id, self.intrinsics, T_world_camera)
        uv, found = detect_dots(rgb, target.colors, hue_tolerance=target.hue_tolerance)
        return uv, found, Z
