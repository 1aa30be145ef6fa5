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

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pybullet as p

from repro.errors import ConfigError, UnknownChoiceError
from repro.sensors.camera_window import (
    DotBlobs,
    FrameReport,
    PixelWindow,
    WindowPlan,
    WindowPolicy,
    WindowTracker,
)
from repro.sensors.dot_detection import (
    _MAX_AREA_FACTOR,
    _MIN_AREA_PX,
    _check_colors,
    _detect_blobs,
    detect_dots,
)
from repro.sensors.dots import (
    CYLINDER_SEGMENTS,
    DEFAULT_DOT_COLORS,
    DOT_SEGMENTS,
    PLATE_GAP,
    PLATE_THICKNESS,
    DotTarget,
    check_scene_colors,
    cylinder_visual_shape,
    move_dot_target,
    spawn_dot_target,
)
from repro.sensors.intrinsics import (
    GL_RENDERERS,
    ImageBounds,
    Intrinsics,
    _as_pose,
    project_points,
    view_matrix_gl,
)

__all__ = ["CAMERA_MODES", "CYLINDER_SEGMENTS", "DEFAULT_DOT_COLORS", "DETECTABLE_MINOR_AXIS_PX",
           "DOT_SEGMENTS", "GL_RENDERERS", "PLATE_GAP", "PLATE_THICKNESS", "Camera",
           "DotTarget", "ImageBounds", "Intrinsics", "check_scene_colors",
           "cylinder_visual_shape", "detect_dots", "disc_image_centroids", "disc_minor_axes_px",
           "move_dot_target", "project_points", "render_rgb", "spawn_dot_target",
           "view_matrix_gl"]

#: Camera modes of :class:`Camera`.
CAMERA_MODES = ("render", "exact")


def _disc_conics(intr: Intrinsics, T_world_camera: np.ndarray, target: DotTarget,
                 T_world_target: np.ndarray) -> np.ndarray:
    """(N, 3, 3) image conics ``C_i = H_i^{-T} C_0 H_i^{-1}`` of the target's dot discs (see
    :func:`disc_image_centroids` for ``H_i`` and ``C_0``), in pixels."""
    T_cw = np.linalg.inv(_as_pose(T_world_camera, "T_world_camera"))
    T_ct = T_cw @ _as_pose(T_world_target, "T_world_target")
    K = intr.K()
    r = target.dot_radius
    out = np.empty((target.n_points, 3, 3))
    for i, (cx, cy, cz) in enumerate(target.points_target):
        H = K @ np.column_stack([T_ct[:3, 0], T_ct[:3, 1], cz * T_ct[:3, 2] + T_ct[:3, 3]])
        try:
            H_inv = np.linalg.inv(H)
        except np.linalg.LinAlgError:  # the camera in the disc's plane: no image conic
            out[i] = np.nan
            continue
        C0 = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [-cx, -cy, cx * cx + cy * cy - r * r]])
        out[i] = H_inv.T @ C0 @ H_inv
    return out


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
    C = _disc_conics(intr, T_world_camera, target, T_world_target)
    out = np.empty((target.n_points, 2))
    for i in range(target.n_points):
        out[i] = -np.linalg.solve(C[i, :2, :2], C[i, :2, 2])
    return out


#: A flat dot is detectable only when its image ellipse's minor axis is at least this
#: [px] (:func:`disc_minor_axes_px`); narrower, it images as a sliver the detector's shape
#: gates reject (issue 38: "a dot seen edge-on must be reported as not detectable").
#: Measured with the rendered camera (tests/test_camera.py): dots of 8-24 px image radius
#: tilted towards edge-on were found down to a 1.05 px minor axis and lost below 1.0 px; a
#: 3 px one is lost at 1.15 px already (its blob falls under the 6 px area gate first).
DETECTABLE_MINOR_AXIS_PX = 1.0  # ours: the measured edge of detection (above)


def disc_minor_axes_px(intr: Intrinsics, T_world_camera: np.ndarray, target: DotTarget,
                       T_world_target: np.ndarray) -> np.ndarray:
    """(N,) minor axis [px] of each dot disc's image ellipse (its full width across the
    narrow direction; ``2 f r cos(theta) / Z`` for a small disc at depth Z seen theta off
    its normal); 0 where the image is not an ellipse (exactly edge-on, or the disc's plane
    crosses the camera's). A disc seen from behind images as an ellipse too: which side the
    camera is on is not tested here.

    From the conic ``C`` of :func:`disc_image_centroids`: with ``A = C_{1:2,1:2}``,
    ``b = C_{1:2,3}``, the ellipse is ``(x - x_0)^T A (x - x_0) = b^T A^{-1} b - C_{33}``
    and its minor axis ``2 sqrt(k / lambda_max(A))``, ``k`` the right-hand side.
    """
    C = _disc_conics(intr, T_world_camera, target, T_world_target)
    out = np.zeros(target.n_points)
    for i in range(target.n_points):
        A, b, c = C[i, :2, :2], C[i, :2, 2], C[i, 2, 2]
        lam = np.linalg.eigvalsh(A)  # ascending
        if not (np.all(np.isfinite(lam)) and lam[0] * lam[1] > 0):  # not an ellipse
            continue
        if lam[1] < 0:  # C is defined up to its sign: make A positive definite
            A, b, c, lam = -A, -b, -c, -lam[::-1]
        k = float(b @ np.linalg.solve(A, b) - c)
        if k > 0:
            out[i] = 2.0 * float(np.sqrt(k / lam[1]))
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
