"""Windowed rendering for :class:`repro.sensors.camera.Camera`: after a full frame, render
only a small window around each dot's last detection.

**Why.** A TinyRenderer frame costs in proportion to the pixels its triangles cover: on the
pomares2011 exp1 camera (640 x 480 px, the table and the part fill the frame) ~0.4 us per
pixel plus ~0.4 ms per ``getCameraImage`` call, 70-90 ms a full frame; four ~60 x 60 px
windows, 5.4 ms with their detection (median over the committed exp1 run at 200 fps, AMD
EPYC).

**Same rays, same pixels.** The window ``[x0, x1) x [y0, y1)`` is rendered as an image of
its own size through the camera's intrinsics with the principal point moved to
``(u0 - x0, v0 - y0)`` (:meth:`repro.sensors.camera.Intrinsics.crop`; the TinyRenderer
pixel-corner correction of :meth:`~repro.sensors.camera.Intrinsics.projection_matrix_gl`
then applies unchanged): window pixel ``[r, c]`` samples the ray of full-image pixel
``[y0 + r, x0 + c]``, and the whole scene is drawn (no body hidden), so the detector meets
the real background. TinyRenderer rasterises in 32-bit floats at the window's own pixel
scale, so a pixel whose sample point lies within float rounding (a few 1e-5 px) of a triangle
edge can fall on the other side. Measured on the committed runs: 1 dot window in 80
(thomas2024 case1) to 250 (pomares2011 exp1) differs from the full image, in one such edge
pixel; through :class:`~repro.sensors.camera.Camera` 8 of the 5001 exp1 frames at 200 fps
and 2 of the 595 case1 frames differ from the full frame's detection, by <= 0.062 px (one
pixel more or less at a blob's edge), with the same found flags; the rest is bit-identical.

**Where the windows go** (:class:`WindowTracker`). Dot ``i``'s window is centred on the
pixel nearest its last *detected* centroid (never on a projection of the true geometry:
the tracker only ever sees detections), with half-sizes (per axis) the farthest pixel of
its last blob from that pixel plus ``margin_px + edge_px``, clipped to the image. Windows
whose union costs less to render than the windows apart (one call ~ ``call_cost_px``
pixels) are merged.

**When a full frame is rendered instead** (:data:`FULL_FRAME_REASONS`): on the first
frame; when a dot was not found in the last frame; every ``full_every`` frames; and, after
rendering the windows, when a dot was not found in its window or a pixel of its colour mask
lies within ``edge_px`` of an inner border of its window (a border that is not the
image's): the frame is then rendered again in full, so that what :meth:`Camera.measure
<repro.sensors.camera.Camera.measure>` returns is always one full-frame-equivalent
detection.

**What equals the full frame.** When no pixel of a dot's colour mask touches its window's
inner borders, every 8-connected component of that colour in the window is whole (a
component reaching outside would have a pixel on the border), so the blobs, their areas,
the area gate (``max_blob_areas``) and the ellipse-fill gate are those of the full frame,
and when the window holds every mask pixel of that colour (the scene's bodies cannot pass
a dot's mask, :func:`~repro.sensors.camera.check_scene_colors`) the labelled sub-image is the
same and the centroid is the same to the bit. The window cannot see a larger blob of the
dot's colour outside it, which the full frame would take; ``full_every`` bounds how long
such a difference could last.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from repro.errors import ConfigError
from repro.sensors.intrinsics import Intrinsics, PixelWindow

__all__ = ["FULL_FRAME_REASONS", "RASTER_PX", "DotBlobs", "FrameReport", "PixelWindow",
           "WindowPlan", "WindowPolicy", "WindowTracker", "image_motion_bound_px"]

#: Why a frame was rendered in full: no frame before (``"first"``), a dot not found in the
#: last frame (``"lost"``), the ``full_every`` period (``"period"``), a dot not found in
#: its window (``"missed"``) or too close to an inner border of it (``"edge"``); the last
#: two re-render the frame after its windows.
FULL_FRAME_REASONS = ("first", "lost", "period", "missed", "edge")

#: Extra pixels added to a motion bound for rasterisation: a blob's outermost pixel centre
#: lies within one pixel of the continuous image of the disc, so when the disc moves by m
#: px, its new pixels lie within m + 1 px of the old blob's bounding box.
RASTER_PX = 1


def image_motion_bound_px(intr: Intrinsics, frame_dt: float, omega_max: float,
                          v_max: float, z_min: float) -> float:
    """Largest image motion of a point between two frames for bounded camera speeds [px].

    A point at normalised image position ``x = (x, y)`` and depth ``Z`` moves, under the
    camera twist ``(v, omega)``, with ``dx/dt = L_v v / Z + L_omega omega`` (the interaction
    matrix of a point), where the operator norms are ``||L_v|| = sqrt(1 + r^2)`` and
    ``||L_omega|| = 1 + r^2`` with ``r^2 = x^2 + y^2`` (tight; checked in
    tests/test_camera_window.py). With ``r^2`` its largest value on the image (a corner)
    and the pixel map's norm ``||[[fu, s], [0, fv]]||``:

    .. math::

        \\Delta_{px} \\le \\Delta t \\, \\|K_{2\\times2}\\| \\left( (1 + r_{max}^2)
            \\, \\omega_{max} + \\sqrt{1 + r_{max}^2} \\, v_{max} / Z_{min} \\right)

    Args:
        intr: camera intrinsics.
        frame_dt: time between two frames [s].
        omega_max: largest angular speed of the camera [rad/s].
        v_max: largest linear speed of the optical centre [m/s].
        z_min: smallest depth of a dot in the camera frame [m].
    """
    if not (frame_dt > 0 and omega_max >= 0 and v_max >= 0 and z_min > 0):
        raise ConfigError(f"need frame_dt > 0, omega_max >= 0, v_max >= 0, z_min > 0; got "
                          f"{frame_dt}, {omega_max}, {v_max}, {z_min}")
    corners = np.array([[u, v] for u in (-0.5, intr.width - 0.5)
                        for v in (-0.5, intr.height - 0.5)])
    r2 = float(np.max(np.sum(intr.to_normalized(corners) ** 2, axis=1)))
    k2 = float(np.linalg.norm(np.array([[intr.fu, intr.skew], [0.0, intr.fv]]), 2))
    return frame_dt * k2 * ((1.0 + r2) * omega_max + math.sqrt(1.0 + r2) * v_max / z_min)


@dataclass(frozen=True)
class WindowPolicy:
    """How :class:`repro.sensors.camera.Camera` renders windows instead of full frames.

    Attributes:
        margin_px: room for a dot's motion between two frames [px]: the window reaches this
            far beyond the dot's last blob (before the ``edge_px`` band); a larger motion
            only costs a full frame (``"edge"`` or ``"missed"``), never a wrong result. See
            :meth:`for_camera_speed`.
        full_every: a full frame at least every this many frames (1: always full).
        edge_px: width of the band along a window's inner borders that no pixel of the
            dot's colour mask may reach [px] (>= 1: one clear pixel is what makes every
            component in the window whole).
        call_cost_px: the cost of one ``getCameraImage`` call counted in window pixels, to
            merge windows (ours: measured ~0.4 ms per call and ~0.4 us per pixel on the
            pomares2011 scene, ~0.1 us on thomas2024's).
    """

    margin_px: int
    full_every: int = 50  # ours: 0.25 s at 200 fps; see the module docstring, "What equals"
    edge_px: int = 1  # ours: the least that keeps the components whole
    call_cost_px: int = 1000  # ours: see above

    def __post_init__(self) -> None:
        for name, low in (("margin_px", 0), ("full_every", 1), ("edge_px", 1),
                          ("call_cost_px", 0)):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or value < low:
                raise ConfigError(f"WindowPolicy.{name} must be an integer >= {low}, got "
                                  f"{value!r}")

    @classmethod
    def for_camera_speed(cls, intr: Intrinsics, frame_dt: float, omega_max: float,
                         v_max: float, z_min: float, full_every: int = 50,
                         edge_px: int = 1) -> WindowPolicy:
        """The policy whose margin is :func:`image_motion_bound_px` rounded up plus
        :data:`RASTER_PX` (arguments as there; units [s], [rad/s], [m/s], [m])."""
        bound = image_motion_bound_px(intr, frame_dt, omega_max, v_max, z_min)
        return cls(int(math.ceil(bound)) + RASTER_PX, full_every, edge_px)


class WindowPlan(NamedTuple):
    """One window to render and the dots (indices) to detect in it."""

    window: PixelWindow
    dots: tuple[int, ...]


class DotBlobs(NamedTuple):
    """Detections of one frame, in full-image pixel coordinates.

    Attributes:
        uv: (N, 2) blob centroids [px], NaN rows for dots not found.
        found: (N,) bool.
        blob_box: (N, 4) int ``(x0, y0, x1, y1)`` bounding box of each found blob's pixels
            (exclusive ends), -1 where not found.
        mask_box: (N, 4) int bounding box of every pixel of the dot's colour mask in the
            rendered image, zeros where the mask is empty.
    """

    uv: np.ndarray
    found: np.ndarray
    blob_box: np.ndarray
    mask_box: np.ndarray


class FrameReport(NamedTuple):
    """What :meth:`repro.sensors.camera.Camera.measure` rendered for its last frame.

    Attributes:
        kind: ``"full"`` or ``"windows"`` (the result comes from windows only).
        reason: why the frame is full (one of :data:`FULL_FRAME_REASONS`), None for windows.
        windows: the windows rendered (also those of a frame re-rendered in full).
        rendered_px: pixels rendered in all, windows and full frame [px].
    """

    kind: str
    reason: str | None
    windows: tuple[PixelWindow, ...]
    rendered_px: int


class WindowTracker:
    """The window state of one camera: its last detections and frames since a full frame.

    Built only from what the camera detected (:meth:`update`); nothing of the true geometry
    enters it.

    Args:
        policy: margins, period, border band.
        width, height: image size [px].
    """

    def __init__(self, policy: WindowPolicy, width: int, height: int) -> None:
        self.policy = policy
        self.width = int(width)
        self.height = int(height)
        self.last: DotBlobs | None = None
        self.frames_since_full = 0
        self.key: object = None

    def reset(self, key: object = None) -> None:
        """Forget the last detections (the next frame is full); ``key`` names what they
        were of (:meth:`bind`)."""
        self.last = None
        self.frames_since_full = 0
        self.key = key

    def bind(self, key: object) -> None:
        """Reset when the camera measures something else (another client or target)."""
        if key != self.key:
            self.reset(key)

    def plan(self) -> tuple[tuple[WindowPlan, ...], None] | tuple[None, str]:
        """The windows of the next frame, or ``(None, reason)`` when it must be full."""
        last = self.last
        if last is None:
            return None, "first"
        if not last.found.all():
            return None, "lost"
        if self.frames_since_full + 1 >= self.policy.full_every:
            return None, "period"
        grow = self.policy.margin_px + self.policy.edge_px
        plans = []
        for i, ((u, v), (bx0, by0, bx1, by1)) in enumerate(zip(last.uv, last.blob_box,
                                                               strict=True)):
            cu, cv = math.floor(u + 0.5), math.floor(v + 0.5)
            hu = max(cu - int(bx0), int(bx1) - 1 - cu) + grow
            hv = max(cv - int(by0), int(by1) - 1 - cv) + grow
            plans.append(WindowPlan(self._clip(cu - hu, cv - hv, cu + hu + 1, cv + hv + 1),
                                    (i,)))
        return self._merge(plans), None

    def _clip(self, x0: int, y0: int, x1: int, y1: int) -> PixelWindow:
        return PixelWindow(max(x0, 0), max(y0, 0), min(x1, self.width), min(y1, self.height))

    def _cost(self, w: PixelWindow) -> int:
        return self.policy.call_cost_px + w.area

    def _merge(self, plans: list[WindowPlan]) -> tuple[WindowPlan, ...]:
        """Merge the pair of windows that saves most render cost, until none saves any."""
        plans = list(plans)
        while len(plans) > 1:
            best, pair = 0, (0, 0)
            for a in range(len(plans)):
                for b in range(a):
                    wa, wb = plans[a].window, plans[b].window
                    saving = self._cost(wa) + self._cost(wb) - self._cost(wa.union(wb))
                    if saving > best:
                        best, pair = saving, (a, b)
            if best <= 0:
                break
            a, b = pair
            merged = WindowPlan(plans[a].window.union(plans[b].window),
                                tuple(sorted(plans[a].dots + plans[b].dots)))
            plans = [p for k, p in enumerate(plans) if k not in pair] + [merged]
        return tuple(sorted(plans, key=lambda p: p.dots))

    def check(self, plans: tuple[WindowPlan, ...], blobs: DotBlobs) -> str | None:
        """Why the windowed frame must be re-rendered in full (``"missed"``, ``"edge"``),
        or None when it stands."""
        if not blobs.found.all():
            return "missed"
        e = self.policy.edge_px
        for w, dots in plans:
            for i in dots:
                mx0, my0, mx1, my1 = (int(c) for c in blobs.mask_box[i])
                if ((w.x0 > 0 and mx0 - w.x0 < e) or (w.y0 > 0 and my0 - w.y0 < e)
                        or (w.x1 < self.width and w.x1 - mx1 < e)
                        or (w.y1 < self.height and w.y1 - my1 < e)):
                    return "edge"
        return None

    def update(self, blobs: DotBlobs, full: bool) -> None:
        """Keep this frame's detections for the next frame's windows."""
        self.last = blobs
        self.frames_since_full = 0 if full else self.frames_since_full + 1
