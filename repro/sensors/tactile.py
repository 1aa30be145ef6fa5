"""Tactile pads: arrays of pressure cells (tactels) on robot links, simulated from contacts.

pomares2011 Sec. 7.3: a Barrett hand with seven PPS RoboTouch pads (palm, and the inner
and outer phalanx of each finger); every tactel reads 0-140 kPa with a sensitivity of
0.7 kPa, at 30 Hz. This module is generic (a pad is a grid of rectangular cells on any
PyBullet link); the Barrett layout is data (:func:`bh8_pads`).

Frames. A pad has its own frame F_pad: origin at the centre of the sensing face, +z the
outward normal of that face, x along the rows (row index i grows with x), y across
(column index j grows with y). The pad is fixed to a link frame (``TactilePad.frame``, a
URDF link: either the physical link or a collision-less fixed "frame link" such as
``bh8_finger1_distal_pad``) by ``T_frame_pad``. Tactel k (row-major, ``k = i * cols + j``,
then the extra cells) is the rectangle of centre ``centres[k]`` and size ``sizes[k]`` in
the pad's xy plane [m]; its area is ``areas[k]`` [m^2].

Pressure model (why not binning, why not probes). PyBullet keeps at most 4 contact points
per body pair (bullet3 issue 4221; facts sheet "Tactile pads"): binning raw points lights
at most 4 tactels, wherever the body touches. For a flat face on the pad the 4 points are
the corners of the contact polygon, so spreading each point with a small kernel (as
GraspIt does) paints four blobs at the corners and none under the middle of the object.
Probing each tactel for penetration (Genesis) needs a ray or distance query per tactel
and a stiffness to turn depth into pressure, and its force is not the force the solver
applied. We keep the solver's forces and rebuild the contact patch they come from:

1. contact points of the pad's link (``p.getContactPoints(bodyA=body, linkIndexA=link)``:
   PyBullet returns the queried body as A, ``positionOnA`` on the pad's link and
   ``contactNormalOnB`` pointing from the other body into A) count when they lie on the
   sensing face: ``|z_pad| <= face_tol`` and the normal within ``max_normal_angle`` of
   -z_pad (a contact on the back face or on a side face is not sensed);
2. the points of one body pair (one contact manifold) are the vertices of one patch: a
   polygon (3-4 points, e.g. a flat face), a segment (collinear points, e.g. a cylinder
   lying on the pad) or a point (a sphere, an edge);
3. the pair's total normal force F and centre of pressure c = sum f_i x_i / F are spread
   over the patch with a *linear* pressure, p(x) = max(0, a + b . (x - c)): the pressure
   under a rigid flat body on a no-tension Winkler (bed-of-springs) skin, linear where it
   touches and lifting off where it would pull. a and b follow from the equilibrium
   conditions (integral of p = F, centre of pressure = c), by an active-set iteration on
   the patch samples (a grid of spacing ``sample_step`` [m]). A centred block gives a
   uniform map, an off-centre load a tilted one;
4. each sample's force is blurred by the skin: a Gaussian of standard deviation ``spread``
   [m] integrated exactly over every cell rectangle (products of normal CDFs). A sample on
   a cell is normalised over the pad's cells, so all of its force stays on the sensor:
   sum_k p_k a_k = F for a patch on the cells. A sample off the cells but within
   ``margin`` of one (the pad's rim) gives the cells only the part of its blur that
   reaches them; farther out it contributes nothing.

The normalisation in 4. keeps the force but folds the blur that would leave the pad back
onto it, mostly onto the edge cells. Computed for the three Barrett layouts: a uniform load
the size of the grid reads within 0.90-1.07 of its true pressure on every cell; a uniform
load larger than the pad (its rim loaded too) reads 1.03-1.06 in the middle and up to 1.31
in the corner cells.

A pad then reads p_k = (force on cell k) / a_k [Pa -> kPa], clipped to 0-140 kPa and
quantised to multiples of 0.7 kPa (pomares2011 Sec. 7.3); the unclipped, unquantised map is
kept as an audit. :class:`TactileSensor` samples all pads at 30 Hz and holds the last
sample in between (the episode runner reads sensors every control step).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pybullet as p
from scipy.special import ndtr

from repro.errors import ConfigError, UnknownChoiceError

__all__ = [
    "BH8_DISTAL", "BH8_PALM", "BH8_PAD_NAMES", "BH8_PROXIMAL", "MountedPad", "PRESSURE_MAX_KPA",
    "PRESSURE_STEP_KPA", "PadLayout", "PadReading", "SAMPLE_RATE_HZ", "TactilePad",
    "TactileReading", "TactileSensor", "bh8_pads", "mount_pads", "pad_contacts",
    "pressure_from_contacts", "pressure_image", "quantise_kpa", "tactel_row",
]

#: Upper end of the tactels' range [kPa] (pomares2011 Sec. 7.3: "0-140 kPa").
PRESSURE_MAX_KPA = 140.0
#: Sensitivity = quantisation step of a reading [kPa] (pomares2011 Sec. 7.3: "0.7 kPa").
PRESSURE_STEP_KPA = 0.7
#: Sampling rate of every pad [Hz] (pomares2011 Sec. 7.3 and Sec. 7: "30 Hz (33 ms)").
SAMPLE_RATE_HZ = 30.0

_EPS_T = 1e-9  # [s] slack on the sample schedule (float time stamps k * dt)

Cell = tuple[float, float, float, float]  # (x, y, size_x, size_y) in the pad frame [m]


@dataclass(frozen=True)
class PadLayout:
    """Geometry of one pad in its own frame (see the module docstring for the frame).

    Attributes:
        rows: cells along x.
        cols: cells along y.
        cell: (size along x, size along y) of a grid cell [m]; no gaps between cells.
        origin: centre of the rows x cols grid in the pad frame (x, y) [m].
        extra_cells: cells outside the grid, each (x, y, size_x, size_y) [m] (the tip
            cell of the Barrett distal pad).
        spread: standard deviation of the skin's Gaussian blur [m]; None: half the
            smaller cell side (# ours: a point load on a cell centre gives 47 % of its force
            to that cell and 9 % to each edge neighbour -- a blur "about one pitch" wide,
            FWHM 1.18 cells; the papers give no cross-talk figure).
        margin: a contact sample off the cells but within this distance of one (in x and
            in y) loads the cells with the part of its blur that reaches them [m]; None:
            one pitch = 2 ``spread`` (# ours: beyond 2 sigma less than 2.3 % of a load
            reaches the pad, so the cut-off changes little).
        face_tol: a contact point counts when |z| in the pad frame is at most this [m]
            (# ours: 3 mm: a point on a meshed face is within ~1 mm of the pad plane,
            a finger link's back face one link thickness away; a back face nearer than
            face_tol is still rejected by its normal).
        max_normal_angle: a contact counts when its normal is within this angle of the
            pad's inward normal -z [rad] (# ours: 60 deg; side faces are at 90 deg).
        sample_step: grid spacing of the contact-patch samples [m]; None: a quarter of the
            smaller cell side (# ours: 16 samples per covered cell; the cover fraction of
            an edge cell is then right to ~1/8).
    """

    rows: int
    cols: int
    cell: tuple[float, float]
    origin: tuple[float, float] = (0.0, 0.0)
    extra_cells: tuple[Cell, ...] = ()
    spread: float | None = None
    margin: float | None = None
    face_tol: float = 3.0e-3
    max_normal_angle: float = math.radians(60.0)
    sample_step: float | None = None

    def __post_init__(self) -> None:
        bad = (self.rows < 0 or self.cols < 0 or min(self.cell) <= 0
               or self.rows * self.cols + len(self.extra_cells) == 0
               or any(len(c) != 4 or c[2] <= 0 or c[3] <= 0 for c in self.extra_cells)
               or (self.spread is not None and self.spread <= 0)
               or (self.margin is not None and self.margin < 0)
               or self.face_tol <= 0 or not 0 < self.max_normal_angle <= math.pi / 2
               or (self.sample_step is not None and self.sample_step <= 0))
        if bad:
            raise ConfigError(f"invalid pad layout: {self}")

    @property
    def n_tactels(self) -> int:
        """Number of tactels: rows * cols + len(extra_cells)."""
        return self.rows * self.cols + len(self.extra_cells)

    @property
    def pitch(self) -> float:
        """Smaller side of a grid cell [m] (or of the extra cells when there is no grid)."""
        sides = [*self.cell] if self.rows * self.cols else []
        sides += [s for c in self.extra_cells for s in c[2:]]
        return float(min(sides))

    @property
    def sigma(self) -> float:
        """The skin blur actually used [m] (``spread`` or half the pitch)."""
        return self.spread if self.spread is not None else 0.5 * self.pitch

    @property
    def rim(self) -> float:
        """The margin actually used [m] (``margin`` or one pitch)."""
        return self.margin if self.margin is not None else self.pitch

    @property
    def step(self) -> float:
        """The patch sampling step actually used [m]."""
        return self.sample_step if self.sample_step is not None else 0.25 * self.pitch

    @functools.cached_property
    def _geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(centres, sizes, areas), computed once (read-only arrays)."""
        i, j = np.meshgrid(np.arange(self.rows), np.arange(self.cols), indexing="ij")
        x = self.origin[0] + (i.ravel() - (self.rows - 1) / 2.0) * self.cell[0]
        y = self.origin[1] + (j.ravel() - (self.cols - 1) / 2.0) * self.cell[1]
        extra = np.array(self.extra_cells, dtype=float).reshape(-1, 4)
        centres = np.vstack([np.column_stack([x, y]).reshape(-1, 2), extra[:, :2]])
        sizes = np.vstack([np.tile(np.asarray(self.cell, dtype=float),
                                   (self.rows * self.cols, 1)), extra[:, 2:]])
        areas = sizes[:, 0] * sizes[:, 1]
        for a in (centres, sizes, areas):
            a.setflags(write=False)
        return centres, sizes, areas

    def centres(self) -> np.ndarray:
        """(n, 2) centres of the tactels in the pad frame [m], row-major, extras last."""
        return self._geometry[0]

    def sizes(self) -> np.ndarray:
        """(n, 2) sides (x, y) of the tactels [m]."""
        return self._geometry[1]

    def areas(self) -> np.ndarray:
        """(n,) areas of the tactels [m^2]."""
        return self._geometry[2]

    def on_pad(self, xy: np.ndarray, rim: float | None = None) -> np.ndarray:
        """(m,) True where a point (m, 2) of the pad plane [m] is within ``rim`` [m] of a
        cell, in x and in y (default: the layout's ``rim``; 0: on a cell)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        reach = 0.5 * self.sizes() + (self.rim if rim is None else rim)
        d = np.abs(xy[:, None, :] - self.centres()[None, :, :])
        return np.any(np.all(d <= reach[None] + 1e-12, axis=2), axis=1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) corners (x, y) of the footprint grown by ``rim`` [m]."""
        c, h = self.centres(), 0.5 * self.sizes() + self.rim
        return (c - h).min(axis=0), (c + h).max(axis=0)


def _pose_tuple(T: Any) -> tuple[tuple[float, ...], ...]:
    A = np.asarray(T, dtype=float)
    if A.shape != (4, 4) or not np.isfinite(A).all():
        raise ConfigError(f"T_frame_pad must be a finite 4x4 transform, got {A!r}")
    return tuple(tuple(float(v) for v in row) for row in A)


_IDENTITY = _pose_tuple(np.eye(4))


@dataclass(frozen=True)
class TactilePad:
    """A pad placed on a robot link.

    Attributes:
        name: pad name (column names: ``<prefix><name>_pmax``...).
        frame: URDF link whose frame carries the pad: the physical link, or a fixed,
            collision-less frame link on it (``bh8_palm_pad``).
        layout: the cells, in the pad frame.
        T_frame_pad: pose of the pad frame in the ``frame`` link frame (4x4; identity when
            ``frame`` already is the pad frame).
        contact_link: URDF link whose contacts load the pad; None: ``frame`` if it has a
            collision shape, else the first ancestor through fixed joints that has one.
    """

    name: str
    frame: str
    layout: PadLayout
    T_frame_pad: tuple[tuple[float, ...], ...] | np.ndarray = _IDENTITY  # stored as tuples
    contact_link: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_frame_pad", _pose_tuple(self.T_frame_pad))

    def pose(self) -> np.ndarray:
        """T_frame_pad as a 4x4 array."""
        return np.array(self.T_frame_pad)


# --------------------------------------------------------------------- the Barrett layout
#: Palm pad: 6 x 4 cells of 10 x 10 mm = 24 tactels of 100 mm^2 (pomares2011 Sec. 7.3:
#: 24 tactels, 100 mm^2; the 6 x 4 grid from GraspIt's Barrett_PP_Sensor_4_Pad.xml, facts
#: sheet). # ours: rows along the pad's x.
BH8_PALM = PadLayout(rows=6, cols=4, cell=(0.010, 0.010))
#: Outer (distal) phalanx pad: 7 rows along the link x 3 across of 6 x 6 mm, plus one tip
#: cell = 22 tactels of 36 mm^2 (pomares2011 Sec. 7.3; GraspIt layout, facts sheet: the tip
#: cell continues the middle column towards the tip). Where it sits: GraspIt's cells span
#: -48..0 mm from its link-3 frame, which its DH (a = 55 mm) puts at the distal link's end,
#: so the real pad ends where the finger ends, the tip cell on the fingertip. Ours ends at
#: our finger's end, A3 + tip radius = 56.5 mm from the distal axis, i.e. +31.5 mm from the
#: pad frame (the distal box's face centre, 25 mm from the axis): grid centre at x = +4.5 mm,
#: tip cell at +28.5 mm (issue 17 item 8: centred on the pad frame, the grid ended 7.5 mm
#: short of the finger's end, and finger 3's contact at 24-26 mm lay past it;
#: tests/test_tactile.py checks the end against repro.sim.barrett's geometry).
BH8_DISTAL = PadLayout(rows=7, cols=3, cell=(0.006, 0.006), origin=(0.0045, 0.0),
                       extra_cells=((0.0285, 0.0, 0.006, 0.006),))
#: Inner (proximal) phalanx pad: 24 tactels of 25 mm^2 (pomares2011 Sec. 7.3) as 8 rows x 3
#: of 5 x 5 mm (# ours: no public layout; 40 x 15 mm fits the proximal link's face).
BH8_PROXIMAL = PadLayout(rows=8, cols=3, cell=(0.005, 0.005))

#: The seven pads of pomares2011 Sec. 7.3, in this order.
BH8_PAD_NAMES = ("palm", "finger1_proximal", "finger1_distal", "finger2_proximal",
                 "finger2_distal", "finger3_proximal", "finger3_distal")


def bh8_pads(frames: Mapping[str, str] | None = None,
             offsets: Mapping[str, np.ndarray] | None = None) -> tuple[TactilePad, ...]:
    """The seven pads of the Barrett hand of pomares2011 Sec. 7.3.

    Args:
        frames: frame link of each pad by pad name (:data:`BH8_PAD_NAMES`); default
            ``bh8_<pad>_pad``, the fixed pad frames of our Barrett URDF (centre of the
            grasping face, +z outward, x towards the fingertip).
        offsets: T_frame_pad by pad name (4x4) where a frame is not the pad frame itself;
            default identity.
    """
    frames, offsets = dict(frames or {}), dict(offsets or {})
    for given in (frames, offsets):
        for name in given:
            if name not in BH8_PAD_NAMES:
                raise UnknownChoiceError("Barrett pad", name, BH8_PAD_NAMES)
    layouts = {"palm": BH8_PALM, "proximal": BH8_PROXIMAL, "distal": BH8_DISTAL}
    return tuple(TactilePad(name, frames.get(name, f"bh8_{name}_pad"),
                            layouts[name.rsplit("_", 1)[-1]],
                            offsets.get(name, _IDENTITY))
                 for name in BH8_PAD_NAMES)


# ------------------------------------------------------------------ the pressure model
def _hull(P: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise vertices) of 2D points (Andrew's monotone chain)."""
    pts = sorted(map(tuple, np.unique(P, axis=0)))

    def half(seq: Iterable[tuple[float, ...]]) -> list[tuple[float, ...]]:
        out: list[tuple[float, ...]] = []
        for q in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (q[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (q[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(q)
        return out

    lower, upper = half(pts), half(reversed(pts))
    return np.array(lower[:-1] + upper[:-1])


def _grid_in_hull(H: np.ndarray, a: np.ndarray, b: np.ndarray, step: float) -> np.ndarray:
    """Points of the grid of spacing ``step`` [m] over the box [a, b] (cell centres) that
    lie in the counter-clockwise convex polygon H."""
    gx = np.arange(a[0] + 0.5 * step, b[0], step)
    gy = np.arange(a[1] + 0.5 * step, b[1], step)
    G = np.stack(np.meshgrid(gx, gy, indexing="ij"), axis=-1).reshape(-1, 2)
    edges = np.roll(H, -1, axis=0) - H
    cross = (edges[None, :, 0] * (G[:, None, 1] - H[None, :, 1])
             - edges[None, :, 1] * (G[:, None, 0] - H[None, :, 0]))
    return G[np.all(cross >= -1e-12, axis=1)]


def _no_tension_pressure(M: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Linear pressure with lift-off on the samples M (k, d) of a patch, d = 1 or 2.

    Finds theta with p_s = max(0, theta_0 + theta_1..d . (M_s - c)) such that
    sum_s p_s (M_s - c) = 0, i.e. the centre of pressure of p is c: the pressure under a
    rigid flat body on a no-tension Winkler skin (linear where it touches, lifting off
    where the linear pressure would be negative). Active-set iteration; returns p (k,),
    sum 1 (unnormalised shape if it did not converge in 30 iterations: clipped linear).

    .. math:: \\sum_{s \\in A} p_s = 1, \\quad \\sum_{s \\in A} p_s (M_s - c) = 0,
              \\quad A = \\{s : p_s > 0\\}
    """
    X = np.column_stack([np.ones(len(M)), M - c])
    rhs = np.zeros(X.shape[1])
    rhs[0] = 1.0
    active = np.ones(len(M), dtype=bool)
    for _ in range(30):
        Xa = X[active]
        theta = np.linalg.lstsq(Xa.T @ Xa, rhs, rcond=None)[0]
        lin = X @ theta
        new = lin > 0.0
        if np.array_equal(new, active) or not new.any():
            break
        active = new
    w = np.clip(lin, 0.0, None)
    return w / w.sum() if w.sum() > 0 else np.full(len(M), 1.0 / len(M))


def _patch_samples(xy: np.ndarray, f: np.ndarray, step: float, lo: np.ndarray,
                   hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Spread one manifold's forces over its contact patch.

    The patch (hull of the points: polygon, segment or point) carries the no-tension
    linear pressure of :func:`_no_tension_pressure`: total force F = sum(f), centre of
    pressure c = f . xy / F, both kept.

    Args:
        xy: (n, 2) contact points in the pad plane [m].
        f: (n,) their normal forces [N], sum > 0.
        step: sample spacing [m].
        lo, hi: corners of the region worth sampling (the pad grown by its rim) [m].

    Returns:
        (m, 2) sample points [m] and (m,) their forces [N]: the whole patch's force
        distribution restricted to [lo, hi] (all of F when the patch lies inside).
    """
    F = float(f.sum())
    c = (f @ xy) / F
    mean = xy.mean(axis=0)
    if len(xy) > 1:
        Vt = np.linalg.svd(xy - mean, full_matrices=False)[2]
        proj = (xy - mean) @ Vt.T
        extent = np.concatenate([np.ptp(proj, axis=0), np.zeros(2)])[:2]
    else:
        Vt, proj, extent = np.eye(2), np.zeros((1, 2)), np.zeros(2)
    if extent[0] < step:  # one point (or a cluster smaller than a sample): a point load
        return c[None, :], np.array([F])
    if extent[1] < step:  # collinear: a line contact, sampled whole (at most 4000 samples)
        n = min(int(math.ceil(extent[0] / step)) + 1, 4000)
        t = np.linspace(proj[:, 0].min(), proj[:, 0].max(), n)
        w = _no_tension_pressure(t[:, None], np.array([(c - mean) @ Vt[0]]))
        return mean + t[:, None] * Vt[0][None, :], F * w
    H = _hull(xy)  # a polygon
    h_lo, h_hi = H.min(axis=0), H.max(axis=0)
    a, b = np.maximum(h_lo, lo), np.minimum(h_hi, hi)
    if np.any(b <= a):  # the patch lies off the pad
        return np.zeros((0, 2)), np.zeros(0)
    S = _grid_in_hull(H, a, b, step)
    if len(S) < 3:  # a sliver: keep the solver's points as they are
        return xy, f
    if np.all(h_lo >= lo) and np.all(h_hi <= hi):  # the whole patch is worth sampling
        return S, F * _no_tension_pressure(S, c)
    # the patch sticks out: solve on a sampling of the whole of it (<= ~4000 samples),
    # evaluate the same linear pressure on the samples near the pad
    area = 0.5 * float(np.sum(H[:, 0] * np.roll(H[:, 1], -1) - np.roll(H[:, 0], -1) * H[:, 1]))
    step_m = max(step, math.sqrt(area / 4000.0))
    Mfull = _grid_in_hull(H, h_lo, h_hi, step_m)
    if len(Mfull) < 3:
        return xy, f
    X = np.column_stack([np.ones(len(Mfull)), Mfull - c])
    wm = _no_tension_pressure(Mfull, c)  # force share of each sample of area step_m^2
    act = wm > 0
    theta = np.linalg.lstsq(X[act], wm[act] / step_m**2, rcond=None)[0]  # p(x) [1/m^2]
    p_s = np.clip(np.column_stack([np.ones(len(S)), S - c]) @ theta, 0.0, None)
    return S, F * p_s * step * step


def _cell_weights(layout: PadLayout, S: np.ndarray) -> np.ndarray:
    """(m, n) share of each sample's force on each cell: the Gaussian skin blur (std
    ``layout.sigma``) integrated over the cell rectangles. A sample on a cell is normalised
    over the pad (its row sums to 1: its force stays on the sensor); a sample beside the
    cells (in the rim) keeps the raw share that reaches them."""
    c, h, sig = layout.centres(), 0.5 * layout.sizes(), layout.sigma
    lo, hi = (c - h)[None], (c + h)[None]
    d = S[:, None, :]
    m = np.prod(ndtr((hi - d) / sig) - ndtr((lo - d) / sig), axis=2)
    tot = m.sum(axis=1, keepdims=True)
    on = layout.on_pad(S, rim=0.0)[:, None] & (tot > 1e-12)
    return np.where(on, m / np.where(tot > 1e-12, tot, 1.0), m)


def pressure_from_contacts(layout: PadLayout, xy: np.ndarray, force: np.ndarray,
                           group: Sequence[Any] | np.ndarray | None = None) -> np.ndarray:
    """Unclipped, unquantised pressure of every tactel from contact points on the face.

    Args:
        layout: the pad.
        xy: (n, 2) contact points in the pad plane [m] (already on the sensing face).
        force: (n,) normal forces [N] (>= 0).
        group: (n,) manifold key of each point (the other body and link); points of one key
            form one patch. None: every point is its own patch (a point load each).

    Returns:
        (n_tactels,) pressure [kPa]. sum(p * areas) [kPa m^2 = kN] * 1e3 is the force [N]
        on the sensor: all of ``force`` when the patches lie on the cells; a patch
        reaching into the rim adds the part of its blur that reaches the cells.
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    force = np.clip(np.asarray(force, dtype=float).reshape(-1), 0.0, None)
    keys = list(range(len(xy))) if group is None else list(group)
    lo, hi = layout.bounds()
    on_cell = np.zeros(layout.n_tactels)
    for key in dict.fromkeys(keys):
        idx = np.array([i for i, k in enumerate(keys) if k == key])
        if force[idx].sum() <= 0.0:
            continue
        S, fs = _patch_samples(xy[idx], force[idx], layout.step, lo, hi)
        keep = layout.on_pad(S) if len(S) else np.zeros(0, dtype=bool)
        if np.any(keep):
            on_cell += fs[keep] @ _cell_weights(layout, S[keep])
    return on_cell / layout.areas() * 1e-3  # [N / m^2 = Pa] -> [kPa]


def quantise_kpa(p_kpa: np.ndarray, step: float = PRESSURE_STEP_KPA,
                 p_max: float = PRESSURE_MAX_KPA) -> np.ndarray:
    """What a tactel reports [kPa]: the nearest multiple of ``step`` (the 0.7 kPa
    sensitivity, pomares2011 Sec. 7.3; # ours: rounding to the nearest level, an ideal ADC),
    clipped to [0, p_max] (0-140 kPa)."""
    return np.clip(np.round(np.asarray(p_kpa, dtype=float) / step) * step, 0.0, p_max)


# ------------------------------------------------------------------- PyBullet binding
@dataclass(frozen=True)
class MountedPad:
    """A pad on a body of a physics client: (body id, link index of its frame, layout).

    Attributes:
        pad: the pad.
        body: PyBullet body id.
        frame_link: link index of ``pad.frame`` (-1: the base).
        contact_link: link index whose contacts load the pad.
    """

    pad: TactilePad
    body: int
    frame_link: int
    contact_link: int


def _link_names(client: int, body: int) -> dict[str, int]:
    names = {p.getBodyInfo(body, physicsClientId=client)[0].decode(): -1}
    for j in range(p.getNumJoints(body, physicsClientId=client)):
        names[p.getJointInfo(body, j, physicsClientId=client)[12].decode()] = j
    return names


def mount_pads(client: int, body: int, pads: Iterable[TactilePad]) -> list[MountedPad]:
    """Resolve the link names of ``pads`` on ``body``.

    A frame link without a collision shape (a URDF pad frame on a fixed joint) is loaded by
    the contacts of its first ancestor, through fixed joints, that has one. Raises
    :class:`UnknownChoiceError` for a link name the body does not have (a URDF loaded with
    ``URDF_MERGE_FIXED_LINKS`` has no frame links).
    """
    names = _link_names(client, body)
    out = []
    for pad in pads:
        for link_name in (pad.frame, pad.contact_link):
            if link_name is not None and link_name not in names:
                raise UnknownChoiceError(f"link of pad {pad.name}", link_name, names)
        frame = names[pad.frame]
        if pad.contact_link is not None:
            contact = names[pad.contact_link]
        else:
            contact = frame
            while (contact >= 0 and not p.getCollisionShapeData(body, contact,
                                                                physicsClientId=client)
                   and p.getJointInfo(body, contact, physicsClientId=client)[2]
                   == p.JOINT_FIXED):
                contact = p.getJointInfo(body, contact, physicsClientId=client)[16]
        out.append(MountedPad(pad, body, frame, contact))
    return out


def _link_frame_pose(client: int, body: int, link: int) -> np.ndarray:
    """World pose (4x4) of a link's URDF frame (for the base: not its inertial frame)."""
    if link >= 0:
        pos, quat = p.getLinkState(body, link, computeForwardKinematics=True,
                                   physicsClientId=client)[4:6]
        return _pq(pos, quat)
    pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=client)
    lpos, lquat = p.getDynamicsInfo(body, -1, physicsClientId=client)[3:5]
    T_inertial = _pq(lpos, lquat)
    return _pq(pos, quat) @ np.linalg.inv(T_inertial)


def _pq(pos: Sequence[float], quat: Sequence[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
    T[:3, 3] = pos
    return T


@dataclass(frozen=True)
class PadContacts:
    """The raw PyBullet contact points of one pad's link, in its pad frame.

    Attributes:
        xyz: (n, 3) points on the pad's link (``positionOnA``) in the pad frame [m].
        force: (n,) normal forces [N].
        cos_normal: (n,) cosine of the angle between each normal and the pad's -z.
        group: (n,) (other body, other link) of each point.
        on_face: (n,) True where the point counts (on the sensing face, see PadLayout).
        finite: (n,) False where PyBullet gave a non-finite value.
    """

    xyz: np.ndarray
    force: np.ndarray
    cos_normal: np.ndarray
    group: list[tuple[int, int]]
    on_face: np.ndarray
    finite: np.ndarray


def pad_contacts(client: int, mp: MountedPad) -> PadContacts:
    """Contact points of ``mp``'s link with every other body, classified against its face."""
    T_world_pad = _link_frame_pose(client, mp.body, mp.frame_link) @ mp.pad.pose()
    R, t = T_world_pad[:3, :3], T_world_pad[:3, 3]
    pos, normal, force, group = [], [], [], []
    for c in p.getContactPoints(bodyA=mp.body, linkIndexA=mp.contact_link,
                                physicsClientId=client):
        if c[1] == mp.body and c[3] == mp.contact_link:  # PyBullet puts the queried body as A
            pos.append(c[5])
            normal.append(c[7])  # on B, pointing towards A (into the pad)
            group.append((c[2], c[4]))
        else:  # defensive: the same pair with the roles swapped
            pos.append(c[6])
            normal.append(tuple(-v for v in c[7]))
            group.append((c[1], c[3]))
        force.append(c[9])
    P = np.array(pos, dtype=float).reshape(-1, 3)
    N = np.array(normal, dtype=float).reshape(-1, 3)
    f = np.array(force, dtype=float)
    xyz = (P - t) @ R
    cos_n = -(N @ R[:, 2])
    finite = np.all(np.isfinite(xyz), axis=1) & np.isfinite(f) & np.isfinite(cos_n)
    lay = mp.pad.layout
    with np.errstate(invalid="ignore"):
        on_face = (finite & (np.abs(xyz[:, 2]) <= lay.face_tol)
                   & (cos_n >= math.cos(lay.max_normal_angle)))
    return PadContacts(xyz, f, cos_n, group, on_face, finite)


# ---------------------------------------------------------------------------- readings
@dataclass(frozen=True)
class PadReading:
    """One sample of one pad.

    Attributes:
        pressure: (n,) what the pad reports [kPa]: clipped to 0-140 kPa, multiples of 0.7.
        pressure_true: (n,) the model's pressure before clipping and quantisation [kPa]
            (audit).
        force_contacts: sum of the normal forces of the raw contact points on the sensing
            face, wherever they are on it [N] (audit: the solver's force).
        force_pad: sum(pressure_true * areas): the part of it on the sensor [N] (audit).
        force_map: sum(pressure * areas), the force the reported map implies [N].
        n_contacts: raw contact points on the sensing face.
        saturated: (n,) True where pressure_true > 140 kPa.
        invalid: True when PyBullet gave non-finite contact data (those points dropped).
        force_link: sum of the normal forces of every (finite) contact point on the pad's
            link, on the face or not [N] (audit: what the link really feels).
    """

    pressure: np.ndarray
    pressure_true: np.ndarray
    force_contacts: float
    force_pad: float
    force_map: float
    n_contacts: int
    saturated: np.ndarray
    invalid: bool
    force_link: float = math.nan

    @property
    def p_max(self) -> float:
        """Maximum reported pressure [kPa] (what pomares2011 Algorithm 1 compares)."""
        return float(self.pressure.max())

    @property
    def coverage(self) -> float:
        """force_map / force_link: the share of the link's contact force the reported map
        carries; NaN while the link feels under :data:`COVERAGE_MIN_FORCE_N`."""
        if not self.force_link >= COVERAGE_MIN_FORCE_N:
            return math.nan
        return self.force_map / self.force_link


@dataclass(frozen=True)
class TactileReading:
    """All pads at one sample.

    Attributes:
        t: time the sample was taken [s] (held readings keep it).
        pads: reading of each pad by pad name.
        new: True when this read took the sample, False when it holds the last one.
        failed: pads whose contact data were non-finite ``max_consecutive_faults``
            samples in a row.
    """

    t: float
    pads: Mapping[str, PadReading]
    new: bool = True
    failed: tuple[str, ...] = field(default_factory=tuple)


#: Below this contact force on a pad's link its coverage is not judged [N]. # ours: 10
#: quantisation steps of one distal tactel (10 x 0.7 kPa x 36 mm^2 = 0.25 N): under it
#: the quantised map cannot resolve a 10 % shortfall.
COVERAGE_MIN_FORCE_N = 10 * 0.7e3 * 36e-6
#: A pad whose coverage falls under this raises ``tactile_coverage_low``. # ours: issue 17
#: item 8 (the map should carry >= 90 % of what the link feels; fingers 1-2 carry 97-99 %).
COVERAGE_MIN = 0.9


def read_pad(client: int, mp: MountedPad) -> PadReading:
    """Sample one pad now (no hold): contacts -> patches -> pressure map."""
    lay = mp.pad.layout
    con = pad_contacts(client, mp)
    sel = np.flatnonzero(con.on_face)
    p_true = pressure_from_contacts(lay, con.xyz[sel, :2], con.force[sel],
                                    [con.group[i] for i in sel])
    p_rep = quantise_kpa(p_true)
    areas = lay.areas()
    return PadReading(pressure=p_rep, pressure_true=p_true,
                      force_contacts=float(con.force[sel].sum()),
                      force_pad=float(p_true @ areas * 1e3),
                      force_map=float(p_rep @ areas * 1e3), n_contacts=int(sel.size),
                      saturated=p_true > PRESSURE_MAX_KPA, invalid=bool(np.any(~con.finite)),
                      force_link=float(con.force[con.finite].sum()))


def pressure_image(layout: PadLayout, pressure: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A pad's pressures as an image for plotting.

    Returns:
        (rows, cols) array: ``image[i, j]`` is the tactel of row i (x grows with i) and
        column j (y grows with j) [same unit as ``pressure``, kPa]; and the extra cells
        (n_extra,) in their declared order (the Barrett distal tip cell).
    """
    pressure = np.asarray(pressure, dtype=float)
    if pressure.shape != (layout.n_tactels,):
        raise ConfigError(f"pressure has shape {pressure.shape}, the pad has "
                          f"{layout.n_tactels} tactels")
    n = layout.rows * layout.cols
    return pressure[:n].reshape(layout.rows, layout.cols), pressure[n:].copy()


def tactel_row(reading: TactileReading, prefix: str = "tac_") -> dict[str, float]:
    """Every reported tactel of a reading as one trace row: ``<prefix><pad>_<k>`` [kPa],
    k = 1..n in the pad's tactel order (row-major, extra cells last)."""
    return {f"{prefix}{name}_{k + 1}": float(v)
            for name, pr in reading.pads.items() for k, v in enumerate(pr.pressure)}


# ------------------------------------------------------------------------------ sensor
MODEL = (
    "contact points of the pad's link (p.getContactPoints(bodyA=body, linkIndexA=link); "
    "positionOnA, contactNormalOnB, normalForce) count when |z_pad| <= face_tol and the "
    "normal is within max_normal_angle of -z_pad; the points of one body pair span a patch "
    "(polygon hull, segment or point) sampled every sample_step, carrying the no-tension "
    "linear pressure max(0, a + b.x) that matches the pair's total normal force and centre "
    "of pressure; each sample is blurred by a Gaussian of std spread integrated over the "
    "cell rectangles, normalised over the pad for samples on a cell, raw for samples within "
    "margin of a cell; samples farther out are dropped; pressure = cell force / cell area "
    "[kPa], reported clipped to "
    f"[0, {PRESSURE_MAX_KPA}] kPa and rounded to multiples of {PRESSURE_STEP_KPA} kPa, "
    f"sampled at {SAMPLE_RATE_HZ} Hz and held in between")


class TactileSensor:
    """Tactile pads read by the episode runner (the :class:`repro.sim.episode.Sensor`
    protocol), sampled at 30 Hz (pomares2011 Sec. 7.3) and held in between.

    The readings come from the physics client's current contacts (the last physics step);
    the joint positions passed to :meth:`read` are not needed.

    Fault policy (# ours, as the proximity rings): a non-finite contact value is dropped,
    the pad is flagged ``invalid`` and an event is logged; ``max_consecutive_faults``
    invalid samples in a row and the pad has failed (:meth:`failure` stops the run safely).

    Trace columns (``p`` = prefix, ``<pad>`` = pad name): ``p new`` (a sample was taken at
    this row), ``p t_sample`` [s], ``p<pad>_pmax`` [kPa], ``p<pad>_F`` [N] (audit: raw
    contact force on the face), ``p<pad>_Fmap`` [N] (from the reported map); with
    ``tactel_columns`` also every tactel ``p<pad>_<k>`` [kPa] (:func:`tactel_row`).

    Args:
        client: physics client.
        mounts: the pads (:func:`mount_pads`).
        name: sensor name.
        prefix: column prefix.
        rate: sampling rate [Hz].
        tactel_columns: also write every tactel to the trace (# ours: off by default; the
            seven Barrett pads are 162 columns, ~50 MB of CSV per minute at 1 kHz).
        max_consecutive_faults: invalid samples in a row after which a pad has failed.
    """

    def __init__(self, client: int, mounts: Sequence[MountedPad], name: str = "tactile",
                 prefix: str = "tac_", rate: float = SAMPLE_RATE_HZ,
                 tactel_columns: bool = False, max_consecutive_faults: int = 3) -> None:
        names = [m.pad.name for m in mounts]
        if len(set(names)) != len(names) or not names:
            raise ConfigError(f"tactile sensor {name}: pad names must be unique, got {names}")
        if not (math.isfinite(rate) and rate > 0):
            raise ConfigError(f"tactile sensor {name}: rate must be > 0 Hz, got {rate}")
        self.client, self.mounts, self.name, self.prefix = client, list(mounts), name, prefix
        self.period = 1.0 / rate
        self.tactel_columns = tactel_columns
        self.max_consecutive_faults = int(max_consecutive_faults)
        self._fault_run = dict.fromkeys(names, 0)
        self._last: TactileReading | None = None
        self._low: set[str] = set()  # pads whose coverage is under COVERAGE_MIN
        self._t0 = 0.0
        self._k = 0  # samples taken; the next one is due at t0 + k * period

    def sample(self, t: float) -> TactileReading:
        """Read every pad now, whatever the schedule (does not move the schedule)."""
        pads = {m.pad.name: read_pad(self.client, m) for m in self.mounts}
        for name, pr in pads.items():
            self._fault_run[name] = self._fault_run[name] + 1 if pr.invalid else 0
        failed = tuple(n for n, r in self._fault_run.items()
                       if r >= self.max_consecutive_faults)
        return TactileReading(t=float(t), pads=pads, new=True, failed=failed)

    def read(self, t: float, q: Mapping[str, np.ndarray] | None = None) -> TactileReading:
        """The reading at time ``t`` [s]: a new sample when one is due (the first read, then
        every ``period`` from it), else the last sample with ``new=False``."""
        if self._last is None:
            self._t0, self._k = float(t), 0
        if self._last is None or t >= self._t0 + self._k * self.period - _EPS_T:
            self._last = self.sample(t)
            while self._t0 + self._k * self.period <= t + _EPS_T:
                self._k += 1
            return self._last
        return dataclasses.replace(self._last, new=False)

    def columns(self, reading: TactileReading) -> dict[str, float | bool]:
        out: dict[str, float | bool] = {f"{self.prefix}new": reading.new,
                                        f"{self.prefix}t_sample": reading.t}
        for name, pr in reading.pads.items():
            out[f"{self.prefix}{name}_pmax"] = pr.p_max
            out[f"{self.prefix}{name}_F"] = pr.force_contacts
            out[f"{self.prefix}{name}_Fmap"] = pr.force_map
            out[f"{self.prefix}{name}_Flink"] = pr.force_link
            out[f"{self.prefix}{name}_coverage"] = pr.coverage
        if self.tactel_columns:
            out.update(tactel_row(reading, self.prefix))
        return out

    def events(self, reading: TactileReading) -> list[tuple[str, str]]:
        """Saturated tactels (true pressure > 140 kPa, reported 140) and non-finite contact
        data, once per sample (a held reading repeats no event)."""
        if not reading.new:
            return []
        out = []
        for name, pr in reading.pads.items():
            if np.any(pr.saturated):
                k = (np.flatnonzero(pr.saturated) + 1).tolist()
                out.append(("tactile_saturated",
                            f"{self.name} pad {name} tactels {k} above {PRESSURE_MAX_KPA} kPa "
                            f"(max {pr.pressure_true.max():.1f} kPa): read "
                            f"{PRESSURE_MAX_KPA} kPa"))
            if pr.invalid:
                out.append(("sensor_nan", f"{self.name} pad {name}: non-finite contact data "
                            "from PyBullet, those contact points dropped"))
            cov = pr.coverage
            if math.isnan(cov):  # too little force on the link to judge
                if name in self._low:
                    self._low.discard(name)
                    out.append(("tactile_coverage_low_end", f"{self.name} pad {name}: contact "
                                f"force {pr.force_link:.2f} N, under the "
                                f"{COVERAGE_MIN_FORCE_N:.2f} N coverage is judged at"))
            elif cov < COVERAGE_MIN:
                if name not in self._low:
                    self._low.add(name)
                    out.append(("tactile_coverage_low",
                                f"audit: {self.name} pad {name} reports {pr.force_map:.2f} N "
                                f"of the {pr.force_link:.2f} N its link feels (coverage "
                                f"{cov:.2f} < {COVERAGE_MIN}): contact off the sensing cells"))
            elif name in self._low:
                self._low.discard(name)
                out.append(("tactile_coverage_low_end", f"{self.name} pad {name} coverage "
                            f"{cov:.2f} >= {COVERAGE_MIN} again"))
        return out

    def failure(self, reading: TactileReading) -> str | None:
        """Pads whose contact data were non-finite ``max_consecutive_faults`` samples in a
        row, or None."""
        if reading.failed:
            return (f"{self.name} pads {list(reading.failed)} gave non-finite contact data "
                    f"{self.max_consecutive_faults} samples in a row")
        return None

    def declare(self, cols: Any) -> None:
        """Declare this sensor's columns in a :class:`repro.runs.columns.Columns`."""
        p_ = self.prefix
        cols.add(f"{p_}new", "bool", f"{self.name}: a new {1 / self.period:g} Hz sample was "
                 "taken at this row (else the last one is held)")
        cols.add(f"{p_}t_sample", "s", f"{self.name}: time the held sample was taken")
        for m in self.mounts:
            n = m.pad.name
            cols.add(f"{p_}{n}_pmax", "kPa", f"pad {n}: maximum reported tactel pressure "
                     f"(0-{PRESSURE_MAX_KPA} kPa, {PRESSURE_STEP_KPA} kPa steps)")
            cols.add(f"{p_}{n}_F", "N", f"audit: pad {n}: sum of the PyBullet normal forces "
                     "of the contact points on its sensing face", audit=True)
            cols.add(f"{p_}{n}_Fmap", "N", f"pad {n}: sum of reported pressure * tactel "
                     "area")
            cols.add(f"{p_}{n}_Flink", "N", f"audit: pad {n}: sum of the PyBullet normal "
                     "forces of every contact point on the pad's link (on its face or not)",
                     audit=True)
            cols.add(f"{p_}{n}_coverage", "-", f"audit: pad {n}: Fmap / Flink, the share of "
                     "the link's contact force the reported map carries (NaN while Flink < "
                     f"{COVERAGE_MIN_FORCE_N:.2f} N); under {COVERAGE_MIN}: event "
                     "tactile_coverage_low", audit=True)
            if self.tactel_columns:
                cols.add(f"{p_}{n}_{{i}}", "kPa", f"pad {n}: reported pressure of tactel "
                         "{i} (row-major, rows along the pad x; extra cells last)",
                         n=m.pad.layout.n_tactels)

    def describe(self) -> dict[str, Any]:
        """The sensor model for scene.json."""
        pads = []
        for m in self.mounts:
            lay = m.pad.layout
            pads.append({
                "name": m.pad.name, "body": m.body, "frame": m.pad.frame,
                "frame_link_index": m.frame_link, "contact_link_index": m.contact_link,
                "T_frame_pad": m.pad.pose().tolist(),
                "rows": lay.rows, "cols": lay.cols, "cell_m": list(lay.cell),
                "origin_m": list(lay.origin), "extra_cells_m": [list(c) for c in lay.extra_cells],
                "tactel_centres_pad_frame_m": lay.centres().tolist(),
                "tactel_areas_m2": lay.areas().tolist(), "spread_m": lay.sigma,
                "margin_m": lay.rim, "sample_step_m": lay.step, "face_tol_m": lay.face_tol,
                "max_normal_angle_rad": lay.max_normal_angle})
        return {"kind": "tactile_pads", "rate_hz": 1.0 / self.period,
                "range_kpa": [0.0, PRESSURE_MAX_KPA], "step_kpa": PRESSURE_STEP_KPA,
                "model": MODEL, "column_prefix": self.prefix, "pads": pads}
