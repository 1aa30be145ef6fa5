"""Pinhole intrinsics and the exact projection (the conventions of
:mod:`repro.sensors.camera`: camera frame x right, y down, z forward; pixel (0, 0) the
centre of the top-left pixel), and the OpenGL matrices PyBullet renders with."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache, cached_property
from typing import Any, NamedTuple

import numpy as np

from repro.errors import ConfigError, UnknownChoiceError

#: Renderers :meth:`Intrinsics.projection_matrix_gl` can build a matrix for.
GL_RENDERERS = ("tiny", "opengl")

#: Where each renderer samples a pixel, as an offset from the pixel's lower-left corner in
#: OpenGL window coordinates [px]: TinyRenderer at the corner, OpenGL at the centre.
_SAMPLE_OFFSET = {"tiny": 0.0, "opengl": 0.5}

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


class PixelWindow(NamedTuple):
    """A rectangle of image pixels: columns ``[x0, x1)``, rows ``[y0, y1)`` (full-image
    indices, so pixel ``rgb[r, c]`` of the window is ``(u, v) = (x0 + c, y0 + r)`` [px])."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def width(self) -> int:
        return self.x1 - self.x0

    @property
    def height(self) -> int:
        return self.y1 - self.y0

    @property
    def area(self) -> int:
        """Number of pixels."""
        return self.width * self.height

    def union(self, other: PixelWindow) -> PixelWindow:
        """The smallest window holding both."""
        return PixelWindow(min(self.x0, other.x0), min(self.y0, other.y0),
                           max(self.x1, other.x1), max(self.y1, other.y1))


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


