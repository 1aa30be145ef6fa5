"""Capsules (swept-sphere lines) and their distances.

pomares2011 Sec. 4: the human-robot distance ``dist`` of the secondary task (17),

.. math::

    e_2 = \\alpha \\left(1 - \\frac{dist}{d_{min}}\\right) \\quad (dist < d_{min}),
    \\qquad e_2 = 0 \\text{ otherwise},                                  \\qquad (17)

is "the minimum distance value between all these pair-wise distance tests" between
Swept-Sphere Lines covering the human skeleton and the mini-robot links (Corrales et al.
2011, the paper's ref. [31]). A swept-sphere line is a capsule: the set of points within
``radius`` of a segment ``[p0, p1]``. The distance between two capsules is the distance
between their segments minus both radii,

.. math::

    d(A, B) = \\min_{s, t \\in [0, 1]} \\| p_0 + s (p_1 - p_0) - q_0 - t (q_1 - q_0) \\|
              - r_A - r_B,

negative when they overlap (then ``-d`` is the penetration depth: the Minkowski
difference of two capsules is a flat parallelogram swept by a sphere of radius
``r_A + r_B``, so the depth is exactly ``r_A + r_B`` minus the segment distance).

Two implementations of :func:`min_distance`:

* ``"analytic"`` (default): the clamped closed form for the closest points of two
  segments (Ericson, *Real-Time Collision Detection*, 2005, Sec. 5.1.9,
  ``ClosestPtSegmentSegment``), exact to rounding and giving the witness points a
  controller needs for the gradient of ``dist``. Used in the control loop (pomares2011:
  a few human capsules against a few mini-robot capsules, every step) and as the
  reference in tests.
  :func:`capsule_closest_points` gives the witness points on the surfaces.
* ``"fcl"``: python-fcl (``fcl.Capsule`` in ``fcl.CollisionObject``, ``fcl.distance``,
  whose capsule-capsule routine is signed), the library :mod:`repro.planning.dcc`
  already uses: the independent cross-check (tests: agreement to 1e-6 m) and the way to
  mix capsules with other primitives. Both take about 1 ms for 12 x 3 pairs.

Units: lengths [m]; points are 3-vectors in one common frame (the world, unless said).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass

import fcl
import numpy as np

from repro.errors import ConfigError, UnknownChoiceError

METHODS = ("analytic", "fcl")
# Squared segment length [m^2] below which a segment is treated as a point (Ericson's
# EPSILON): 1e-12 m^2 = a 1 micrometre segment.
_EPS_SQ = 1e-12


@dataclass(frozen=True, eq=False)
class Capsule:
    """A swept-sphere line: all points within ``radius`` of the segment ``[p0, p1]``.

    Attributes:
        p0, p1: segment end points (3,) [m], in the frame of the caller (world).
        radius: sphere radius [m], >= 0 (0: a bare segment).
    """

    p0: np.ndarray
    p1: np.ndarray
    radius: float

    def __post_init__(self) -> None:
        for name in ("p0", "p1"):
            v = np.array(getattr(self, name), dtype=float)  # a private copy
            if v.shape != (3,) or not all(map(math.isfinite, v.tolist())):
                raise ConfigError(f"Capsule.{name} must be 3 finite numbers [m], got {v}")
            v.setflags(write=False)
            object.__setattr__(self, name, v)
        if not (math.isfinite(self.radius) and self.radius >= 0.0):
            raise ConfigError(f"Capsule.radius must be finite and >= 0 [m], got {self.radius}")
        object.__setattr__(self, "radius", float(self.radius))

    @classmethod
    def of_owned(cls, p0: np.ndarray, p1: np.ndarray, radius: float) -> Capsule:
        """A capsule that takes ``p0`` and ``p1`` as they are: (3,) float arrays of finite
        values that the caller made for it and never writes (made read-only here), and a
        finite ``radius`` >= 0 -- the caller's guarantee, not checked (a moving person's
        twelve capsules at every step, built from checked inputs)."""
        c = object.__new__(cls)
        for name, v in (("p0", p0), ("p1", p1)):
            v.setflags(write=False)
            object.__setattr__(c, name, v)
        object.__setattr__(c, "radius", float(radius))
        return c

    @property
    def length(self) -> float:
        """Segment length ``|p1 - p0|`` [m] (the ``length`` of :meth:`Scene.add_capsule`)."""
        return float(np.linalg.norm(self.p1 - self.p0))

    @property
    def centre(self) -> np.ndarray:
        """Segment midpoint [m]."""
        return 0.5 * (self.p0 + self.p1)

    def T_world(self) -> np.ndarray:
        """4x4 pose of a z-axis capsule of length :attr:`length` centred at the midpoint,
        its z axis along ``p1 - p0`` (any rotation for a point-like capsule): the pose for
        ``Scene.add_capsule(name, radius, length, T_world, ...)`` and ``Scene.move``, and
        the frame of ``fcl.Capsule(radius, length)``. Found once per capsule (it is
        immutable: a moving person's body pose and its tracker share it); a copy."""
        T = self.__dict__.get("_T_world")
        if T is None:
            T = np.empty((4, 4))
            T[:3, :3] = rotation_z_to(self.p1 - self.p0)
            T[:3, 3] = self.centre
            T[3] = (0.0, 0.0, 0.0, 1.0)
            object.__setattr__(self, "_T_world", T)
        return T.copy()

    def transformed(self, T_a_b: np.ndarray) -> Capsule:
        """The same capsule with its end points mapped from frame b to frame a."""
        R, t = T_a_b[:3, :3], T_a_b[:3, 3]
        return Capsule(R @ self.p0 + t, R @ self.p1 + t, self.radius)

    def fcl_object(self) -> fcl.CollisionObject:
        """A python-fcl object: ``fcl.Capsule(radius, length)`` posed by :meth:`T_world`."""
        T = self.T_world()
        return fcl.CollisionObject(
            fcl.Capsule(self.radius, self.length),
            fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3])))


_HALF_TURN_X = np.diag([1.0, -1.0, -1.0])


def rotation_z_to(axis: np.ndarray) -> np.ndarray:
    """3x3 rotation taking the z axis onto ``axis`` (the shortest one; identity for a zero
    vector, a half turn about x for -z)."""
    axis = np.asarray(axis, dtype=float)
    n = math.sqrt(float(axis.dot(axis)))  # np.linalg.norm's own sqrt(x . x), less overhead
    if n * n <= _EPS_SQ:
        return np.eye(3)
    u = axis / n
    u0, u1, c = u.tolist()  # c: cos of the angle between z and u
    if c < -1.0 + 1e-12:
        return _HALF_TURN_X.copy()  # (a hanging limb: most of a standing person's)
    # Rodrigues with k = z x u (|k| = sin): R = I + [k]x + [k]x^2 / (1 + c)
    K = np.array([[0.0, 0.0, u0], [0.0, 0.0, u1], [-u0, -u1, 0.0]])
    return _EYE3 + K + K @ K / (1.0 + c)


_EYE3 = np.eye(3)
_EYE3.setflags(write=False)


def segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray
                     ) -> tuple[float, np.ndarray, np.ndarray]:
    """Closest points of the segments ``[p0, p1]`` and ``[q0, q1]`` (3-vectors) [m].

    Ericson, *Real-Time Collision Detection* (2005), Sec. 5.1.9: minimise
    ``|p0 + s d1 - q0 - t d2|^2`` over ``s, t`` in [0, 1] by solving for the infinite
    lines, clamping ``s``, computing ``t`` for that ``s``, and recomputing ``s`` if ``t``
    had to be clamped. Parallel segments (then any pair on the overlap is closest; this
    one starts from ``s = 0``) and zero-length segments (points) are handled explicitly.

    Returns:
        ``(d, c_a, c_b)``: the distance [m] and the closest points on the first and second
        segment.
    """
    p0 = np.asarray(p0, dtype=float)
    q0 = np.asarray(q0, dtype=float)
    d1 = np.asarray(p1, dtype=float) - p0
    d2 = np.asarray(q1, dtype=float) - q0
    r = p0 - q0
    a = float(d1 @ d1)  # squared length of segment 1
    e = float(d2 @ d2)  # squared length of segment 2
    f = float(d2 @ r)
    if a <= _EPS_SQ and e <= _EPS_SQ:  # both points
        s = t = 0.0
    elif a <= _EPS_SQ:  # first segment is a point
        s = 0.0
        t = _clamp01(f / e)
    else:
        c = float(d1 @ r)
        if e <= _EPS_SQ:  # second segment is a point
            t = 0.0
            s = _clamp01(-c / a)
        else:
            b = float(d1 @ d2)
            denom = a * e - b * b  # = |d1 x d2|^2 >= 0
            # Not parallel: closest point of line 1 to line 2, clamped. Parallel (relative
            # test, so the threshold does not depend on the lengths): pick s = 0.
            s = _clamp01((b * f - c * e) / denom) if denom > 1e-14 * a * e else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = _clamp01(-c / a)
            elif t > 1.0:
                t = 1.0
                s = _clamp01((b - c) / a)
    c_a = p0 + s * d1
    c_b = q0 + t * d2
    return float(np.linalg.norm(c_a - c_b)), c_a, c_b


def _clamp01(x: float) -> float:
    return 0.0 if x < 0.0 else 1.0 if x > 1.0 else x


def capsule_distance(a: Capsule, b: Capsule) -> float:
    """Signed distance between two capsules [m]: segment distance minus both radii
    (negative = penetration, minus the depth)."""
    d, _, _ = segment_distance(a.p0, a.p1, b.p0, b.p1)
    return d - a.radius - b.radius


def capsule_closest_points(a: Capsule, b: Capsule) -> tuple[float, np.ndarray, np.ndarray]:
    """``(d, x_a, x_b)``: signed distance [m] and the witness points on the two capsule
    surfaces (on the segments' common normal; when the segments touch, the segment point,
    as the direction is undefined). ``x_b - x_a`` points from a to b when ``d > 0``."""
    d_seg, c_a, c_b = segment_distance(a.p0, a.p1, b.p0, b.p1)
    if d_seg <= 0.0:
        return -a.radius - b.radius, c_a, c_b
    n = (c_b - c_a) / d_seg
    return d_seg - a.radius - b.radius, c_a + a.radius * n, c_b - b.radius * n


def _fcl_signed_distance(oa: fcl.CollisionObject, ob: fcl.CollisionObject) -> float:
    # The default request: for a capsule pair fcl (0.7, python-fcl 0.7.0.11) calls its
    # dedicated capsule-capsule routine (segment closest points minus radii), which is
    # exact to ~1e-13 m and already negative when the capsules overlap. Asking for
    # enable_signed_distance=True routes it through GJK/EPA instead: off by up to 0.5 mm
    # on separated pairs (measured on 2000 random pairs).
    return float(fcl.distance(oa, ob, fcl.DistanceRequest(), fcl.DistanceResult()))


#: python-fcl objects of the capsules seen last, by id (each entry holds its capsule, so
#: the id cannot be reused while it is here), the least recently used dropped first: a
#: capsule that comes back (a still person's body, held between tracker samples) is not
#: rebuilt, and a robot's capsules, new at every call, do not push it out. Same object,
#: same distances.
_FCL_MEMO: OrderedDict[int, tuple[Capsule, fcl.CollisionObject]] = OrderedDict()
_FCL_MEMO_SIZE = 64  # ours: a few skeletons' worth of capsules


def _fcl_object_of(c: Capsule) -> fcl.CollisionObject:
    got = _FCL_MEMO.get(id(c))
    if got is not None and got[0] is c:
        _FCL_MEMO.move_to_end(id(c))
        return got[1]
    if len(_FCL_MEMO) >= _FCL_MEMO_SIZE:
        _FCL_MEMO.popitem(last=False)
    obj = c.fcl_object()
    _FCL_MEMO[id(c)] = (c, obj)
    return obj


def min_distance(set_a: Sequence[Capsule], set_b: Sequence[Capsule],
                 method: str = "analytic") -> tuple[float, int, int]:
    """Minimum signed distance over every pair of ``set_a`` x ``set_b`` [m]
    (pomares2011 Sec. 4: ``dist`` of eq. (17)).

    Args:
        set_a, set_b: capsules in one common frame (non-empty).
        method: ``"analytic"`` (Ericson's closed form, see the module docstring) or
            ``"fcl"`` (python-fcl distance of ``fcl.Capsule`` objects, signed).

    Returns:
        ``(d, i, j)``: the distance and the indices of the closest pair (the first such
        pair in row-major order on ties).
    """
    if method not in METHODS:
        raise UnknownChoiceError("capsule distance method", method, METHODS)
    if len(set_a) == 0 or len(set_b) == 0:
        raise ConfigError(f"min_distance needs two non-empty sets, got {len(set_a)} and "
                          f"{len(set_b)} capsules")
    best = (math.inf, -1, -1)
    if method == "analytic":
        for i, a in enumerate(set_a):
            for j, b in enumerate(set_b):
                d = capsule_distance(a, b)
                if d < best[0]:
                    best = (d, i, j)
    else:
        # Pairs that cannot beat a known distance are skipped: a pair's distance is at
        # least its bounding spheres' gap (|c_a - c_b| minus both half-lengths and radii),
        # and fcl's is exact to ~1e-13 m, so a pair whose gap exceeds a distance already
        # found by more than PRUNE_MARGIN is farther. The first such distance is the pair
        # with the smallest gap; then every pair is visited in row-major order as before
        # (the same minimum, the same first pair on ties).
        objs_b: list[fcl.CollisionObject | None] = [None] * len(set_b)  # made when needed

        def obj_b(j: int) -> fcl.CollisionObject:
            ob = objs_b[j]
            if ob is None:
                ob = objs_b[j] = _fcl_object_of(set_b[j])
            return ob

        spheres_b = [_bounding_sphere(b) for b in set_b]
        gaps = [[math.dist(ca, cb) - ra - rb for cb, rb in spheres_b]
                for ca, ra in (_bounding_sphere(a) for a in set_a)]
        i0, j0 = min(((i, j) for i in range(len(set_a)) for j in range(len(set_b))),
                     key=lambda ij: gaps[ij[0]][ij[1]])
        d0 = _fcl_signed_distance(_fcl_object_of(set_a[i0]), obj_b(j0))
        bound = d0 + PRUNE_MARGIN
        for i, a in enumerate(set_a):
            oa = None
            for j in range(len(set_b)):
                if gaps[i][j] > bound:
                    continue  # farther than (i0, j0): not the minimum
                if (i, j) == (i0, j0):
                    d = d0
                else:
                    oa = _fcl_object_of(a) if oa is None else oa
                    d = _fcl_signed_distance(oa, obj_b(j))
                if d < best[0]:
                    best = (d, i, j)
                    bound = min(bound, d + PRUNE_MARGIN)
    return best


#: A pair is skipped when its bounding spheres are farther apart than a distance already
#: found plus this [m]. ours: 1e-9 m, 10^4 times fcl's capsule error (~1e-13 m) and far
#: above the rounding of the bound itself; any margin gives the same answer.
PRUNE_MARGIN = 1e-9


def _bounding_sphere(c: Capsule) -> tuple[tuple[float, float, float], float]:
    """Centre [m] and radius [m] of a sphere holding capsule ``c`` (Python floats)."""
    p0, p1 = c.p0.tolist(), c.p1.tolist()
    centre = (0.5 * (p0[0] + p1[0]), 0.5 * (p0[1] + p1[1]), 0.5 * (p0[2] + p1[2]))
    return centre, 0.5 * math.dist(p0, p1) + c.radius
