"""Ground-truth distances from PyBullet's closest points, one query per pair of bodies and step.

:meth:`repro.sim.scene.Scene.distance_table` asks, for a robot's body A and another body B, the
minimum distance from each of several *groups* of A's links (the joint groups of one chain:
the PA-10, the mini-robot, the hand...) to B, capped at ``cap``. PyBullet's
``getClosestPoints(A, B, threshold)`` runs the closest-points algorithm on every pair of
collision shapes of A and B (no bounding-box test first), which stops early on a pair
farther apart than ``threshold``, and returns a point for every pair closer than it.
Measured on pomares2011's PA-10 (23 links with collision shapes) against one limb of the
operator: ~8 us with nothing within the threshold, ~1 us more per point returned (~50 us at
a 1 m threshold, 39 points).

:class:`ClosestPoints` asks with a smaller threshold ``T`` first: the largest of the groups'
minima at the previous query of the same pair, plus :data:`HINT_MARGIN`. The answer is the
same as the full query's, to the bit:

* a link's closest distance does not depend on the threshold it is asked with (measured:
  1038 per-link minima of the pomares2011 scene at random poses and thresholds 0.05-0.5 m
  equal those of the 1 m query; ``tests/test_closest.py`` checks it on every call it makes);
* every link closer than ``T`` is returned, so a group with a returned point no farther
  than ``T`` has its exact minimum;
* a group with no such point is farther than ``T``: then the pair is asked again with the
  full ``cap`` (the first query of a pair, a group that moved away faster than the margin,
  a group beyond ``cap``).

A pair whose last answer was ``cap`` for every group (a body beyond the cap: the operator
before he walks in) is not asked when bounding boxes prove it still is: PyBullet's own
boxes of A's links (``getAABB`` after a forward kinematics: the transforms of the shapes
the query uses, grown by the shapes' margins) and of B, farther apart than ``cap`` +
:data:`FAR_MARGIN`. Every
shape pair is then farther than ``cap``, the query would return no point, and the answer
is ``cap`` for every group, as asked.

Only the time changes (``make bench``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pybullet as p

__all__ = ["BOX_SLACK", "FAR_MARGIN", "HINT_MARGIN", "ClosestPoints", "group_minima"]

#: Added to the previous query's largest group minimum to get the next threshold [m].
#: ours: a speed rule, not a value rule (any margin gives the same distances): 1 cm is
#: 10 m/s of relative motion over a 1 ms step, far above any robot or human speed here, so
#: the fallback full query is rare.
HINT_MARGIN = 0.01
#: A body counts as beyond the cap without a query when the bounding boxes are farther
#: apart than the cap plus this [m]. ours: a speed rule, not a value rule (a body it does
#: not skip is asked): 5 cm is far above the closest-points algorithm's error (~1e-6 m).
FAR_MARGIN = 0.05
#: How far a kept box of a robot may be grown by its joints' motion before it is made again
#: [m]. ours: a speed rule, not a value rule (a grown box only proves less): 5 cm keeps
#: the far test nearly as tight as a fresh box (pomares2011 exp2 makes it again about every
#: 120 steps: 144 times in 16727).
BOX_SLACK = 0.05

#: The links of a group: a set of PyBullet link indices, or None for every link of the body.
Links = frozenset[int] | None


def group_minima(points: Sequence[tuple], groups: Sequence[Links]) -> list[float]:
    """Minimum ``contactDistance`` over the points of each group's links [m] (``inf`` where
    a group has none), from the tuples of ``pybullet.getClosestPoints`` (link of A at index
    3, distance at index 8)."""
    return _minima(points, _Members(groups))


class _Members:
    """Which groups each link of A belongs to (the groups of one query, found once)."""

    def __init__(self, groups: Sequence[Links]) -> None:
        self.n = len(groups)
        #: groups holding every link
        self.every = tuple(j for j, links in enumerate(groups) if links is None)
        self.of: dict[int, tuple[int, ...]] = {}
        for link in {link for links in groups if links is not None for link in links}:
            self.of[link] = tuple(j for j, links in enumerate(groups)
                                  if links is None or link in links)


def _minima(points: Sequence[tuple], members: _Members) -> list[float]:
    """:func:`group_minima` with the membership found."""
    out = [math.inf] * members.n
    of, every = members.of, members.every
    for pt in points:
        d = pt[8]
        for j in of.get(pt[3], every):
            if d < out[j]:
                out[j] = d
    return out


class ClosestPoints:
    """Per-group minimum distances between two PyBullet bodies, asked with a threshold hinted
    by the previous query of the same pair and groups (see the module docstring).

    Args:
        client: the PyBullet client holding both bodies.
    """

    def __init__(self, client: int) -> None:
        self.client = client
        #: (body A, groups) -> body B -> threshold of the next query [m]
        self._hint: dict[tuple[int, tuple[Links, ...]], dict[int, float]] = {}
        self._members: dict[tuple[Links, ...], _Members] = {}
        self._shaped: dict[int, list[int]] = {}  # body -> its links with collision shapes
        #: body -> (joints, box lower, box upper, q_ref, revolute mask, r) of moving_box
        self._moving: dict[int, tuple[tuple[int, ...], list[float], list[float], np.ndarray,
                                      np.ndarray, float]] = {}
        self._kinds: dict[int, dict[int, bool] | None] = {}
        self._single: dict[int, bool] = {}
        self.queries = 0  # getClosestPoints calls made (for tests and benchmarks)
        self.skipped = 0  # pairs proved beyond the cap by their boxes (no query)

    def minima(self, body_a: int, body_b: int, groups: tuple[Links, ...], cap: float
               ) -> list[float]:
        """For each group of ``body_a``'s links, its minimum distance to ``body_b`` [m] (< 0:
        penetration), or ``cap`` when farther (exactly PyBullet's answer at threshold
        ``cap``)."""
        return self.minima_of(body_a, (body_b,), groups, cap)[0]

    def minima_of(self, body_a: int, bodies_b: Sequence[int], groups: tuple[Links, ...],
                  cap: float, joints_a: tuple[Sequence[int], np.ndarray] | None = None
                  ) -> list[list[float]]:
        """:meth:`minima` of ``body_a`` against each of ``bodies_b`` in turn (the runner's
        every-step form: the groups' membership and the hints found once for all).
        ``joints_a``: the PyBullet indices of every movable joint of ``body_a`` (a fixed-base
        body) and their positions now, if the caller has them: then A's box is kept between
        steps and grown by how far the joints can have moved its shapes
        (:meth:`moving_box`), instead of being asked of PyBullet at every step."""
        key = (body_a, groups)
        hints = self._hint.get(key)
        if hints is None:
            hints = self._hint[key] = {}
        members = self._members.get(groups)
        if members is None:
            members = self._members[groups] = _Members(groups)
        ask, client = p.getClosestPoints, self.client
        box_a: tuple[float, ...] | None = None
        far2 = (cap + FAR_MARGIN) ** 2  # a squared gap beyond this: no shape within the cap
        out = []
        for body_b in bodies_b:
            threshold = hints.get(body_b, cap)
            if threshold >= cap and body_b in hints and self._one_link(body_b):
                # beyond the cap at the last query: are the boxes still far apart?
                if box_a is None:
                    lo_a, hi_a = (self.box(body_a) if joints_a is None
                                  else self.moving_box(body_a, *joints_a))
                    box_a = (*lo_a, *hi_a)
                (x0, y0, z0), (x1, y1, z1) = p.getAABB(body_b, -1, physicsClientId=client)
                gx = max(x0 - box_a[3], box_a[0] - x1, 0.0)
                gy = max(y0 - box_a[4], box_a[1] - y1, 0.0)
                gz = max(z0 - box_a[5], box_a[2] - z1, 0.0)
                if gx * gx + gy * gy + gz * gz > far2:  # (_box_gap > cap + FAR_MARGIN)
                    self.skipped += 1
                    out.append([cap] * members.n)
                    continue  # (the hint stays: cap + HINT_MARGIN)
            mins = _minima(ask(body_a, body_b, threshold, physicsClientId=client), members)
            self.queries += 1
            if threshold < cap:
                for m in mins:
                    if m > threshold:  # a group beyond the hint: ask everything
                        mins = _minima(ask(body_a, body_b, cap, physicsClientId=client),
                                       members)
                        self.queries += 1
                        break
            mins = [m if m < cap else cap for m in mins]
            hints[body_b] = max(mins, default=cap) + HINT_MARGIN
            out.append(mins)
        return out

    def _one_link(self, body: int) -> bool:
        """``body`` has a single link with a collision shape, its base (found once)."""
        got = self._single.get(body)
        if got is None:
            got = self._single[body] = self._links(body) == [-1]
        return got

    def _links(self, body: int) -> list[int]:
        """The links of ``body`` with a collision shape (-1: the base), found once."""
        got = self._shaped.get(body)
        if got is None:
            n = p.getNumJoints(body, physicsClientId=self.client)
            got = self._shaped[body] = [
                link for link in range(-1, n)
                if p.getCollisionShapeData(body, link, physicsClientId=self.client)]
        return got

    def moving_box(self, body: int, joints: Sequence[int], q: np.ndarray
                   ) -> tuple[list[float], list[float]]:
        """A box [m] holding every collision shape of the fixed-base ``body`` whose movable
        joints (PyBullet indices ``joints``: all of them) are at ``q`` now: the :meth:`box`
        made at some earlier ``q_ref``, grown by a bound ``D`` on how far any of its points
        can have moved since, and made again when ``D`` would exceed :data:`BOX_SLACK`.

        The bound: move the joints to ``q`` one at a time. Turning a revolute joint by
        ``d`` moves a point by at most ``|d|`` times its distance to the joint's axis, which
        is at most ``r + 2 D`` (``r``: the diagonal of a box holding the shapes and every
        joint origin at ``q_ref``; both the point and the axis have moved by <= ``D``); a
        prismatic joint moves it by ``|d|``. Summed: ``D (1 - 2 S) <= S r + P`` with ``S``,
        ``P`` the sums of ``|q - q_ref|`` over revolute and prismatic joints. Any other
        joint kind, or joints that are not all of the body's, and the box is made every
        time. ``q`` must be the joints' positions now (the runner passes the joint states
        it reads at every step: :class:`repro.sim.robot.Robot`'s, renewed by every physics
        step and reset)."""
        q = np.asarray(q, dtype=float)
        got = self._moving.get(body)
        if got is not None and got[0] == tuple(joints):
            _, lo, hi, q_ref, revolute, r = got
            d = np.abs(q - q_ref)
            S, P = float(d[revolute].sum()), float(d[~revolute].sum())
            if 2.0 * S < 0.5 and math.isfinite(S + P):
                D = (S * r + P) / (1.0 - 2.0 * S)
                if D <= BOX_SLACK:
                    return [v - D for v in lo], [v + D for v in hi]
        kinds = self._joint_kinds(body)
        lo, hi = self.box(body)
        if (kinds is None or sorted(joints) != sorted(kinds) or q.shape != (len(joints),)
                or not all(map(math.isfinite, lo + hi))):
            return lo, hi  # (no bound: made every time)
        n = p.getNumJoints(body, physicsClientId=self.client)
        origins = [st[4] for st in p.getLinkStates(body, list(range(n)),
                                                   physicsClientId=self.client)]
        base = p.getBasePositionAndOrientation(body, physicsClientId=self.client)[0]
        pts = [*origins, base, lo, hi]
        r = math.dist([min(c) for c in zip(*pts, strict=True)],
                      [max(c) for c in zip(*pts, strict=True)])
        revolute = np.array([kinds[j] for j in joints])
        self._moving[body] = (tuple(joints), lo, hi, q.copy(), revolute, r)
        return lo, hi

    def _joint_kinds(self, body: int) -> dict[int, bool] | None:
        """Movable joint index -> revolute (True) or prismatic (False); None when the body
        has another kind (spherical, planar). Found once."""
        if body not in self._kinds:
            kinds: dict[int, bool] | None = {}
            for j in range(p.getNumJoints(body, physicsClientId=self.client)):
                kind = p.getJointInfo(body, j, physicsClientId=self.client)[2]
                if kind == p.JOINT_FIXED:
                    continue
                if kind not in (p.JOINT_REVOLUTE, p.JOINT_PRISMATIC) or kinds is None:
                    kinds = None
                    continue
                kinds[j] = kind == p.JOINT_REVOLUTE
            self._kinds[body] = kinds
        return self._kinds[body]

    def box(self, body: int) -> tuple[list[float], list[float]]:
        """The smallest axis-aligned box [m] holding PyBullet's boxes (``getAABB``) of every
        link of ``body`` with a collision shape, now: (lower corner, upper corner)."""
        links = self._links(body)
        if links and links[-1] >= 0:
            # PyBullet's link boxes use the link transforms of its last forward kinematics,
            # which a physics step makes before it moves the links (its collision shapes are
            # moved after): one forward kinematics from the current joints first, the same
            # arithmetic as the shapes' transforms. (It changes no state a step reads: the
            # next step makes its own before it uses them.)
            p.getLinkState(body, links[-1], computeForwardKinematics=True,
                           physicsClientId=self.client)
        if not links:
            return [math.inf] * 3, [-math.inf] * 3
        aabb, client = p.getAABB, self.client
        boxes = [aabb(body, link, physicsClientId=client) for link in links]
        lo = [min(c) for c in zip(*(b[0] for b in boxes), strict=True)]
        hi = [max(c) for c in zip(*(b[1] for b in boxes), strict=True)]
        if not all(map(math.isfinite, lo + hi)):  # (never a proof from a broken box)
            return [-math.inf] * 3, [math.inf] * 3
        return lo, hi


def _box_gap(box: tuple[Sequence[float], Sequence[float]], lo: Sequence[float],
             hi: Sequence[float]) -> float:
    """Euclidean distance [m] between the box ``(lower, upper)`` and the box ``lo``-``hi``
    (0 when they overlap): no point of one is closer to a point of the other."""
    s = 0.0
    for i in range(3):
        g = max(lo[i] - box[1][i], box[0][i] - hi[i], 0.0)
        s += g * g
    return math.sqrt(s)
