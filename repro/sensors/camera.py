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

    u = f_u \\, x + s \\, y + u_0, \\qquad v = f_v \\, y + v_0, \\qquad
    K = \\begin{bmatrix} f_u & s & u_0 \\\\ 0 & f_v & v_0 \\\\ 0 & 0 & 1 \\end{bmatrix}

with ``s`` = ``Intrinsics.skew`` [px] (0 for rectangular pixels; see
:meth:`Intrinsics.from_pixel_pitch` for the pixel-pitch form of chan2011 eq. (1)).

Rendering goes through ``pybullet.getCameraImage``, which takes OpenGL-style view and
projection matrices (eye frame ``x`` right, ``y`` up, ``z`` backwards; 16 floats in
column-major order; image row 0 is the top row). PyBullet's TinyRenderer samples each pixel
at its *corner* (integer viewport coordinates), not at its centre as OpenGL does, so
:meth:`Intrinsics.projection_matrix_gl` shifts the principal point accordingly (see there):
with that matrix a rendered point lands on the pixel :func:`project_points` predicts.

**Render-exact shapes.** TinyRenderer draws ``p.GEOM_CYLINDER`` visuals as a convex hull
inflated by Bullet's collision margin (1 mm in every direction, whatever the size: a
40 x 10 mm cylinder renders 42 x 12 mm, an 8 mm x 0.2 mm disc as a 10 mm x 2.2 mm button);
boxes and ``p.GEOM_MESH`` shapes render exactly. The dots are therefore flat triangle-fan
meshes, and :func:`cylinder_visual_shape` gives an exact cylinder for the bodies they sit on.

**Windowed rendering** (opt-in, :attr:`Camera.window`): after a full frame, render only a
window around each dot's last detection, through :meth:`Intrinsics.crop` (the same rays as
the full image's pixels there), with full-frame fallbacks; :mod:`repro.sensors.camera_window`.

**Detection is by colour**, so no other body in view may pass a dot's colour mask:
:func:`check_scene_colors` rejects such a scene when it is built, and :func:`detect_dots`
only accepts blobs shaped like the image of a disc (area and ellipse fill).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache, cached_property
from typing import Any, NamedTuple

import cv2
import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from repro.errors import ConfigError, UnknownChoiceError
from repro.sensors.camera_window import (
    DotBlobs,
    FrameReport,
    PixelWindow,
    WindowPlan,
    WindowPolicy,
    WindowTracker,
)

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


class ImageBounds(NamedTuple):
    """A rectangle of the image plane [px]: ``u in [u_min, u_max]``, ``v in [v_min, v_max]``
    (e.g. the field of view a controller must keep the points in, chan2011 eqs. (6)-(7))."""

    u_min: float
    u_max: float
    v_min: float
    v_max: float


class _Affine(NamedTuple):
    """The no-skew pixel -> normalised map of :meth:`Intrinsics.to_normalized`."""

    offset: np.ndarray  # (u0, v0) [px], as np.array gives them (read-only)
    scale: np.ndarray  # (fu, fv) [px] (read-only)
    #: u0, v0, fu, fv [px] when offset and scale are float64 arrays (None: integers)
    constants: tuple[float, float, float, float] | None


@cache
def _normalize_points() -> Any:
    """:func:`repro.vision.point_kernels.normalize_points`, imported on first use (numba)."""
    from repro.vision.point_kernels import normalize_points

    return normalize_points


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics (no distortion) plus the clipping planes used for rendering.

    Attributes:
        width, height: image size W, H [px].
        fu, fv: focal lengths along u and v [px].
        u0, v0: principal point [px], in the pixel-centre convention of this module.
        near, far: clipping distances along the optical axis for rendering [m].
        skew: skew coefficient s of ``u = fu x + s y + u0`` [px] (0: rectangular pixels).
    """

    width: int
    height: int
    fu: float
    fv: float
    u0: float
    v0: float
    near: float = 0.01
    far: float = 5.0
    skew: float = 0.0

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise ConfigError(f"image size must be positive, got {self.width}x{self.height}")
        if not (self.fu > 0 and self.fv > 0):
            raise ConfigError(f"focal lengths must be > 0, got fu={self.fu}, fv={self.fv}")
        if not (0 < self.near < self.far):
            raise ConfigError(f"need 0 < near < far, got near={self.near}, far={self.far}")
        if not math.isfinite(self.skew):
            raise ConfigError(f"skew must be finite, got {self.skew}")

    @classmethod
    def centered(cls, width: int, height: int, fu: float, fv: float | None = None,
                 near: float = 0.01, far: float = 5.0) -> Intrinsics:
        """Intrinsics with the principal point at the image centre ((W-1)/2, (H-1)/2) [px]."""
        return cls(width, height, fu, fu if fv is None else fv,
                   (width - 1) / 2.0, (height - 1) / 2.0, near, far)

    @classmethod
    def from_pixel_pitch(cls, f: float, ku: float, kv: float, u0: float, v0: float,
                         width: int, height: int, beta: float = math.pi / 2,
                         near: float = 0.01, far: float = 5.0) -> Intrinsics:
        """Intrinsics from a focal length and pixel densities (chan2011 eq. (1)).

        .. math::

            C = \\begin{bmatrix} f k_u & f k_u \\cot\\beta & u_0 \\\\
                                0 & f k_v / \\sin\\beta & v_0 \\\\ 0 & 0 & 1 \\end{bmatrix}
            = K, \\quad f_u = f k_u, \\; f_v = f k_v / \\sin\\beta, \\;
            s = f k_u \\cot\\beta

        Args:
            f: focal length [m].
            ku, kv: pixels per unit length along x and y of the sensor [px/m].
            u0, v0: principal point [px].
            width, height: image size [px].
            beta: angle between the sensor axes [rad], in (0, pi); pi/2 (no skew) gives
                ``skew = 0`` exactly.
            near, far: clipping distances for rendering [m].
        """
        if not (f > 0 and ku > 0 and kv > 0):
            raise ConfigError(f"need f, ku, kv > 0, got f={f}, ku={ku}, kv={kv}")
        if not 0.0 < beta < math.pi:
            raise ConfigError(f"skew angle beta must be in (0, pi) rad, got {beta}")
        fu = f * ku
        # cot(pi/2) is 6e-17 in floating point; make the no-skew case exact.
        no_skew = beta == math.pi / 2
        skew = 0.0 if no_skew else fu / math.tan(beta)
        fv = f * kv if no_skew else f * kv / math.sin(beta)
        return cls(width, height, fu, fv, float(u0), float(v0), near, far, skew)

    def crop(self, window: PixelWindow) -> Intrinsics:
        """Intrinsics of the sub-image ``window`` (columns ``[x0, x1)``, rows ``[y0, y1)``
        [px]): same focal lengths, skew and clipping, principal point
        ``(u0 - x0, v0 - y0)`` [px]. Rendered with :func:`render_rgb`, its pixel
        ``[r, c]`` samples the ray of this camera's pixel ``[y0 + r, x0 + c]``
        (:mod:`repro.sensors.camera_window` says how exactly)."""
        return Intrinsics(window.width, window.height, self.fu, self.fv,
                          self.u0 - window.x0, self.v0 - window.y0, self.near, self.far,
                          self.skew)

    def image_bounds(self) -> ImageBounds:
        """The whole image, ``u in [-1/2, W - 1/2]``, ``v in [-1/2, H - 1/2]`` [px]."""
        return ImageBounds(-0.5, self.width - 0.5, -0.5, self.height - 0.5)

    def K(self) -> np.ndarray:
        """3x3 calibration matrix mapping homogeneous normalised coordinates to pixels."""
        return np.array([[self.fu, self.skew, self.u0], [0.0, self.fv, self.v0],
                         [0.0, 0.0, 1.0]])

    def to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Pixel coordinates (N, 2) [px] -> normalised coordinates (N, 2) [-].

        .. math:: y = (v - v_0) / f_v, \\qquad x = (u - u_0 - s y) / f_u
        """
        uv = np.asarray(uv, dtype=float)
        affine = self._normalizing_affine
        if (affine is not None and affine.constants is not None and uv.ndim == 2
                and uv.shape[1] == 2):
            # (N, 2) finite pixels: one compiled loop of the broadcast's operations below
            x = np.empty(uv.shape)
            if _normalize_points()(uv, *affine.constants, x):
                return x
        if (affine is not None and uv.shape[-1:] == (2,)
                and np.count_nonzero(np.isfinite(uv)) == uv.size):
            # no skew, finite pixels: one broadcast, the same bits as the formula below (its
            # "- s y" subtracts a zero, and u - u0 is never -0 when u0 != 0)
            return (uv - affine.offset) / affine.scale
        y = (uv[..., 1] - self.v0) / self.fv
        return np.stack([(uv[..., 0] - self.u0 - self.skew * y) / self.fu, y], axis=-1)

    @cached_property
    def _normalizing_affine(self) -> _Affine | None:
        """What :meth:`to_normalized`'s no-skew forms use, made once (the intrinsics are
        frozen); None when they do not apply (a skew, or ``u0 = 0``)."""
        if not (self.skew == 0.0 and self.u0 != 0.0):
            return None
        offset, scale = np.array((self.u0, self.v0)), np.array((self.fu, self.fv))
        offset.flags.writeable = scale.flags.writeable = False
        constants = ((float(offset[0]), float(offset[1]), float(scale[0]), float(scale[1]))
                     if offset.dtype == scale.dtype == np.float64 else None)
        return _Affine(offset, scale, constants)

    def to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """Normalised coordinates (N, 2) [-] -> pixel coordinates (N, 2) [px].

        .. math:: u = f_u x + s y + u_0, \\qquad v = f_v y + v_0
        """
        xy = np.asarray(xy, dtype=float)
        return np.stack([self.fu * xy[..., 0] + self.skew * xy[..., 1] + self.u0,
                         self.fv * xy[..., 1] + self.v0], axis=-1)

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
        an off-centre principal point, ``fu != fv`` and the skew ``s``. With ``o`` the sample
        offset of the renderer (window coordinates of pixel ``(r, c)``'s sample point are
        ``(c + o, H - 1 - r + o)``, origin at the lower-left image corner):

        .. math::

            P = \\begin{bmatrix}
                2 f_u / W & -2 s / W & 1 - 2 (u_0 + o) / W & 0 \\\\
                0 & 2 f_v / H & 2 (v_0 + 1 - o) / H - 1 & 0 \\\\
                0 & 0 & -(f + n) / (f - n) & -2 f n / (f - n) \\\\
                0 & 0 & -1 & 0
            \\end{bmatrix}

        with ``n, f`` = ``near, far`` (the eye frame's ``y`` is minus the camera frame's,
        hence the sign of the skew term).

        Args:
            renderer: ``"tiny"`` (PyBullet's ``ER_TINY_RENDERER``, which samples pixels at
                integer viewport coordinates, i.e. at a pixel corner: ``o = 0``; verified by
                the render-vs-projection test) or ``"opengl"`` (``ER_BULLET_HARDWARE_OPENGL``,
                standard OpenGL sampling at pixel centres: ``o = 1/2``).

        Note: PyBullet's own ``computeProjectionMatrixFOV`` equals the ``"opengl"`` matrix
        with a centred principal point; used with TinyRenderer it puts the principal point
        at ``(W/2, H/2 - 1)`` instead of ``((W-1)/2, (H-1)/2)``, half a pixel off in both axes.
        """
        if renderer not in _SAMPLE_OFFSET:
            raise UnknownChoiceError("GL renderer", renderer, GL_RENDERERS)
        o = _SAMPLE_OFFSET[renderer]
        W, H, n, f = float(self.width), float(self.height), self.near, self.far
        P = np.zeros((4, 4))
        P[0, 0] = 2.0 * self.fu / W
        P[0, 1] = -2.0 * self.skew / W
        P[0, 2] = 1.0 - 2.0 * (self.u0 + o) / W
        P[1, 1] = 2.0 * self.fv / H
        P[1, 2] = 2.0 * (self.v0 + 1.0 - o) / H - 1.0
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

    The image of a circle is a conic; this returns its centre, which is the centroid of the
    filled ellipse and differs from the projection of the disc centre
    (:func:`project_points`) when the disc is tilted (perspective bias). Dot ``i`` lies in
    the plane ``z = z_i`` of the target frame (its own height when the dots are not
    coplanar); with ``H_i`` that plane's homography to the image and ``C_0`` the circle of
    centre ``(c_x, c_y)``, radius ``r``:

    .. math::

        H_i = K \\, [r_1 \\; r_2 \\; z_i r_3 + t], \\qquad
        C_0 = \\begin{bmatrix} 1 & 0 & -c_x \\\\ 0 & 1 & -c_y \\\\
              -c_x & -c_y & c_x^2 + c_y^2 - r^2 \\end{bmatrix}, \\qquad
        C = H_i^{-T} C_0 H_i^{-1}, \\qquad
        (u, v)^T = -C_{1:2,1:2}^{-1} C_{1:2,3}

    with ``r_1, r_2, r_3, t`` the columns of the rotation and the translation of
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
    K = intr.K()
    r = target.dot_radius
    out = np.empty((target.n_points, 2))
    for i, (cx, cy, cz) in enumerate(target.points_target):
        H_inv = np.linalg.inv(K @ np.column_stack([T_ct[:3, 0], T_ct[:3, 1],
                                                   cz * T_ct[:3, 2] + T_ct[:3, 3]]))
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
#: Margins of :func:`check_scene_colors` over the detection thresholds (8-bit rounding of
#: dark shaded pixels moves their hue and saturation by a few units): a body colour is safe
#: when its saturation is below ``_MIN_SATURATION - _SATURATION_MARGIN`` or its hue is more
#: than ``hue_tolerance + _HUE_MARGIN`` from every dot hue.
_SATURATION_MARGIN = 10
_HUE_MARGIN = 3
#: Accepted range of a blob's ellipse fill ``area / (4 pi sqrt(det Sigma))`` (1 for a
#: filled ellipse, 0.95 for a rectangle or a half disc; rings, crescents, L shapes and
#: one-pixel diagonal lines fall below 0.8).
_ELLIPSE_FILL_RANGE = (0.6, 1.25)  # a filled ellipse: 1; small digitised slivers of a dot
# seen at a grazing angle measure 0.78-0.80 (chan2011 runs), a filled rectangle 0.955


def _hue_distance(a: int, b: int) -> int:
    """Distance of two OpenCV hues on the hue circle (period 180)."""
    d = abs(a - b) % 180
    return min(d, 180 - d)


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
            if _hue_distance(hues[i], hues[j]) <= 2 * hue_tolerance:
                raise ConfigError(f"dot colours {tuple(colors[j])} and {tuple(colors[i])} have "
                                  f"hues closer than {4 * hue_tolerance} deg")
    return hues


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


def _ellipse_fill(moments: Mapping[str, float]) -> float:
    """Area of a blob over the area of the ellipse with its second moments [-].

    Pixels are unit squares (variance 1/12 added per axis); 1 for a filled ellipse.
    """
    m00 = moments["m00"]
    s_uu = moments["mu20"] / m00 + 1.0 / 12.0
    s_vv = moments["mu02"] / m00 + 1.0 / 12.0
    s_uv = moments["mu11"] / m00
    det = s_uu * s_vv - s_uv * s_uv
    return float(m00 / (4.0 * np.pi * np.sqrt(det))) if det > 0 else 0.0


#: :func:`detect_dots` ignores smaller colour components by default [px].
_MIN_AREA_PX = 6
#: :meth:`Camera.measure` rejects blobs larger than this factor times the area of the full,
#: fronto-parallel image of the disc at its depth, pi (f r / Z + 1)^2 [px] (a tilted,
#: off-axis or close disc images at most ~1.2x that).
_MAX_AREA_FACTOR = 3.0


def detect_dots(rgb: np.ndarray, colors: Sequence[Sequence[int]],
                min_area_px: int = _MIN_AREA_PX, hue_tolerance: int = _HUE_TOLERANCE,
                max_area_px: float | Sequence[float] | np.ndarray | None = None,
                ) -> tuple[np.ndarray, np.ndarray]:
    """Find the centroid of each coloured dot in an RGB image.

    Per colour: HSV mask (hue within ``hue_tolerance`` of the colour's hue, saturation
    >= 100/255, value >= 40/255; TinyRenderer's shading scales a colour, which keeps its
    hue), 8-connected components, and among the components shaped like the image of a disc
    -- area in ``[min_area_px, max_area_px]`` and ellipse fill
    ``m_00 / (4 pi sqrt(det Sigma))`` in [0.6, 1.25] (``Sigma`` the blob's second central
    moments) -- the largest; its centroid (first-order image moments):

    .. math:: u = m_{10} / m_{00}, \\qquad v = m_{01} / m_{00}

    in the pixel-centre convention of this module (pixel ``rgb[r, c]`` is at ``(c, r)``).

    Args:
        rgb: (H, W, 3) uint8 RGB image.
        colors: N RGB colours (0-255), saturated and of distinct hues.
        min_area_px: smaller components are ignored [px].
        hue_tolerance: half-width of the hue window, OpenCV units (2 deg each).
        max_area_px: larger components are ignored [px]; a number or one per dot (None: no
            bound). :meth:`Camera.measure` bounds it by the dot's size at its depth.

    Returns:
        ``(uv, found)``: ``uv`` (N, 2) centroids [px], NaN rows for dots not found;
        ``found`` (N,) bool.

    Limitations: a dot cut by the image border or partly hidden is still found if what is
    left is elliptical (a half disc is), with the centroid of its visible part. The shape
    test is a second line of defence: another body of a dot's hue in view (e.g. a brown
    box and an orange dot) is excluded by construction with :func:`check_scene_colors`.
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ConfigError(f"rgb must be an (H, W, 3) uint8 image, got {rgb.shape} {rgb.dtype}")
    hues = _check_colors(colors, hue_tolerance)
    max_area = np.broadcast_to(np.inf if max_area_px is None else
                               np.asarray(max_area_px, dtype=float), (len(hues),))
    blobs = _detect_blobs(rgb, hues, min_area_px, hue_tolerance, max_area)
    return blobs.uv, blobs.found


def _detect_blobs(rgb: np.ndarray, hues: Sequence[int], min_area_px: int, hue_tolerance: int,
                  max_area: np.ndarray, origin: tuple[int, int] = (0, 0)) -> DotBlobs:
    """:func:`detect_dots` on validated inputs, also returning each blob's and each colour
    mask's bounding box; ``origin`` (x0, y0) [px] is the full-image pixel of ``rgb[0, 0]``
    (a window), added to every coordinate returned (integers first, so that a centroid is
    the same float as in the full image)."""
    hsv = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2HSV)
    uv = np.full((len(hues), 2), np.nan)
    found = np.zeros(len(hues), dtype=bool)
    blob_box = np.full((len(hues), 4), -1, dtype=int)
    mask_box = np.zeros((len(hues), 4), dtype=int)
    ox, oy = origin
    lo_fill, hi_fill = _ELLIPSE_FILL_RANGE
    for i, hue in enumerate(hues):
        mask = _hue_mask(hsv, hue, hue_tolerance)
        # Label only the bounding box of the mask's pixels (a few hundred pixels instead of
        # the whole image); the centroid is shifted back to full-image coordinates.
        x0, y0, w, h = cv2.boundingRect(mask)
        if w == 0 or h == 0:
            continue
        mask_box[i] = (x0 + ox, y0 + oy, x0 + ox + w, y0 + oy + h)
        n, labels, stats, centroids = cv2.connectedComponentsWithStats(
            np.ascontiguousarray(mask[y0:y0 + h, x0:x0 + w]), connectivity=8)
        areas = stats[1:, cv2.CC_STAT_AREA]
        for k in 1 + np.argsort(-areas, kind="stable"):
            area = stats[k, cv2.CC_STAT_AREA]
            if area < min_area_px:
                break  # sorted by decreasing area
            if area > max_area[i]:
                continue
            cx, cy, cw, ch = stats[k, :4]
            blob = (labels[cy:cy + ch, cx:cx + cw] == k).astype(np.uint8)
            if not lo_fill <= _ellipse_fill(cv2.moments(blob, binaryImage=True)) <= hi_fill:
                continue
            uv[i] = centroids[k] + (x0 + ox, y0 + oy)
            found[i] = True
            bx, by = x0 + ox + int(cx), y0 + oy + int(cy)
            blob_box[i] = (bx, by, bx + int(cw), by + int(ch))
            break
    return DotBlobs(uv, found, blob_box, mask_box)


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
        window: ``"render"`` mode only: None renders every frame in full; a
            :class:`~repro.sensors.camera_window.WindowPolicy` renders, after a full frame,
            only windows around the dots' last detections, with the full-frame fallbacks of
            :mod:`repro.sensors.camera_window` (the camera then keeps state between frames:
            its last detections; :meth:`reset_windows` forgets them).
        last_frame: what the last ``"render"`` frame rendered (None before one, and
            always None without ``window``).
        last_projection: the exact projection :meth:`measure` made last, ``(P_world (N, 3)
            [m], uv (N, 2) [px], Z (N,) [m])`` of the target's dot centres (the audit's
            ground truth, not computed twice); None before a frame.
    """

    intrinsics: Intrinsics
    T_link_camera: np.ndarray = field(default_factory=lambda: np.eye(4))
    mode: str = "render"
    window: WindowPolicy | None = None
    last_frame: FrameReport | None = field(default=None, init=False, repr=False,
                                           compare=False)
    _tracker: WindowTracker | None = field(default=None, init=False, repr=False,
                                           compare=False)
    last_projection: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(
        default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.mode not in CAMERA_MODES:
            raise UnknownChoiceError("camera mode", self.mode, CAMERA_MODES)
        if self.window is not None and not isinstance(self.window, WindowPolicy):
            raise ConfigError(f"Camera.window must be a WindowPolicy or None, got "
                              f"{self.window!r}")
        self.T_link_camera = _as_pose(self.T_link_camera, "T_link_camera").copy()

    @property
    def window_tracker(self) -> WindowTracker | None:
        """The window state (last detections, frames since a full frame); None before the
        first windowed frame."""
        return self._tracker

    def reset_windows(self) -> None:
        """Forget the last detections: the next ``"render"`` frame is full."""
        if self._tracker is not None:
            self._tracker.reset()

    def pose(self, T_world_link: np.ndarray) -> np.ndarray:
        """T_world_camera = T_world_link @ T_link_camera (4x4) [m]."""
        return _as_pose(T_world_link, "T_world_link") @ self.T_link_camera

    def max_blob_areas(self, target: DotTarget, Z: np.ndarray) -> np.ndarray:
        """(N,) largest blob area accepted for each dot [px]: ``_MAX_AREA_FACTOR`` (3) times
        the area of the full fronto-parallel image of its disc at depth ``Z`` [m],
        ``pi (f r / Z + 1)^2`` with ``f = max(fu, fv)``; 0 for ``Z <= 0`` (behind the camera).

        ours: the depths come from the true geometry, like the ``Z`` :meth:`measure`
        returns; the bound is loose (a real system would use its depth estimate).
        """
        f = max(self.intrinsics.fu, self.intrinsics.fv)
        Z = np.asarray(Z, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            r_px = np.where(Z > 0, f * target.dot_radius / np.where(Z > 0, Z, 1.0) + 1.0, 0.0)
        return _MAX_AREA_FACTOR * np.pi * r_px**2

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
            bool -- the detection result in ``"render"`` mode (blobs larger than
            :meth:`max_blob_areas` are not taken for a dot), and in ``"exact"`` mode False
            for dots behind the camera (Z <= 0) or whose centre projects outside the image;
            ``Z`` (N,) depth of each dot centre in the camera frame from the exact
            geometry [m] (for every dot, found or not). With :attr:`window` the
            ``"render"`` result is the same detection made in windows when the policy allows
            (:mod:`repro.sensors.camera_window`; :attr:`last_frame` says what was rendered).
        """
        if self.mode not in CAMERA_MODES:
            raise UnknownChoiceError("camera mode", self.mode, CAMERA_MODES)
        P = target.points_world(T_world_target)
        uv_exact, Z = project_points(self.intrinsics, T_world_camera, P)
        self.last_projection = (P, uv_exact, Z)
        if self.mode == "exact":
            found = (Z > 0) & self.intrinsics.in_image(uv_exact)
            uv = np.where(found[:, None], uv_exact, np.nan)
            return uv, found, Z
        if self.window is not None:
            blobs = self._measure_windowed(client_id, T_world_camera, target,
                                           self.max_blob_areas(target, Z))
            return blobs.uv.copy(), blobs.found.copy(), Z  # the tracker keeps the originals
        rgb = render_rgb(client_id, self.intrinsics, T_world_camera)
        uv, found = detect_dots(rgb, target.colors, hue_tolerance=target.hue_tolerance,
                                max_area_px=self.max_blob_areas(target, Z))
        return uv, found, Z

    def _measure_windowed(self, client_id: int, T_world_camera: np.ndarray,
                          target: DotTarget, max_area: np.ndarray) -> DotBlobs:
        """One ``"render"`` frame through the window policy (:mod:`repro.sensors.camera_window`):
        the windows the tracker plans from its last detections, or a full frame (first
        frame, a dot lost, the period; or after the windows, a dot missed or at a border).
        Detection as :func:`detect_dots` with the same gates (``max_area`` [px] per dot)."""
        assert self.window is not None
        intr = self.intrinsics
        tracker = self._tracker
        if tracker is None or tracker.policy != self.window or (
                tracker.width, tracker.height) != (intr.width, intr.height):
            tracker = self._tracker = WindowTracker(self.window, intr.width, intr.height)
        tracker.bind((client_id, id(target), target.n_points))
        hues = _check_colors(target.colors, target.hue_tolerance)
        plans, reason = tracker.plan()
        tried: tuple[PixelWindow, ...] = ()
        if plans is not None:
            blobs = self._detect_in_windows(client_id, T_world_camera, hues, target,
                                            max_area, plans)
            reason = tracker.check(plans, blobs)
            tried = tuple(p.window for p in plans)
            if reason is None:
                tracker.update(blobs, full=False)
                self.last_frame = FrameReport("windows", None, tried,
                                              sum(w.area for w in tried))
                return blobs
        rgb = render_rgb(client_id, intr, T_world_camera)
        blobs = _detect_blobs(rgb, hues, _MIN_AREA_PX, target.hue_tolerance, max_area)
        tracker.update(blobs, full=True)
        self.last_frame = FrameReport("full", reason, tried,
                                      sum(w.area for w in tried) + intr.width * intr.height)
        return blobs

    def _detect_in_windows(self, client_id: int, T_world_camera: np.ndarray,
                           hues: Sequence[int], target: DotTarget, max_area: np.ndarray,
                           plans: Sequence[WindowPlan]) -> DotBlobs:
        """Render each planned window (:meth:`Intrinsics.crop`) and detect its dots there,
        in full-image pixel coordinates."""
        n = target.n_points
        out = DotBlobs(np.full((n, 2), np.nan), np.zeros(n, dtype=bool),
                       np.full((n, 4), -1, dtype=int), np.zeros((n, 4), dtype=int))
        for window, dots in plans:
            rgb = render_rgb(client_id, self.intrinsics.crop(window), T_world_camera)
            idx = list(dots)
            got = _detect_blobs(rgb, [hues[i] for i in idx], _MIN_AREA_PX, target.hue_tolerance,
                                max_area[idx], origin=(window.x0, window.y0))
            for field_out, field_got in zip(out, got, strict=True):
                field_out[idx] = field_got
        return out
