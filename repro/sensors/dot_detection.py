"""Coloured-dot detection in a rendered image (OpenCV): HSV hue masks, connected blobs gated
by area and ellipse fill, and the scene colour check that keeps every other body out of a
dot's mask."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import cv2
import numpy as np

from repro.errors import ConfigError
from repro.sensors.camera_window import DotBlobs


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

