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
:data:`FAR_MARGIN`. Every shape pair is then farther than ``cap``, the query would return
no point, and the answer is ``cap`` for every group, as asked (:mod:`repro.sim.link_boxes`;
A's box is kept between steps when the caller gives A's joints, grown by a bound on how far
they can have moved any of its shapes).

The bodies beyond the cap at their last query whose boxes the owner keeps between moves
(:meth:`ClosestPoints.keep_box`: a scene's static and scripted bodies) are tested together,
with one box holding theirs. A caller that needs a distance only where it is below a bound
(the runner between trace rows: below its running minimum) passes the bounds
(``minima_of(below=)``): the body is then asked with their largest as the threshold.

Only the time changes (``make bench``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pybullet as p

from repro.sim.link_boxes import LinkBoxes, box_gap

__all__ = ["FAR_MARGIN", "HINT_MARGIN", "ClosestPoints", "group_minima"]

#: Added to the previous query's largest group minimum to get the next threshold [m].
#: ours: a speed rule, not a value rule (any margin gives the same distances): 1 cm is
#: 10 m/s of relative motion over a 1 ms step, far above any robot or human speed here, so
#: the fallback full query is rare.
HINT_MARGIN = 0.01
#: A body counts as beyond the cap without a query when the bounding boxes are farther
#: apart than the cap plus this [m]. ours: a speed rule, not a value rule (a body it does
#: not skip is asked): 5 cm is far above the closest-points algorithm's error (~1e-6 m).
FAR_MARGIN = 0.05

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
        self.boxes = LinkBoxes(client)  # the far test's boxes
        #: bodies that move only when the owner says so (:meth:`moved`): their PyBullet box,
        #: kept from the far test that asked it until they move (None: not asked since)
        self._kept_box: dict[int, tuple[list[float], list[float]] | None] = {}
        self._moves = 0  # moves of kept bodies so far (a union of kept boxes is then stale)
        #: (body A, groups) -> (moves, the bodies, the box holding their kept boxes)
        self._far_union: dict[tuple[int, tuple[Links, ...]],
                              tuple[int, tuple[int, ...], tuple[list[float], list[float]]]] = {}
        self.queries = 0  # getClosestPoints calls made (for tests and benchmarks)
        self.skipped = 0  # pairs proved beyond the cap by their boxes (no query)

    def keep_box(self, body: int) -> None:
        """``body`` moves only through its owner, who calls :meth:`moved` after each move
        (a scene's static and scripted bodies, not a dynamic one): the far test asks its box
        once per pose instead of once per query. Only a body of one link (its base) is
        kept; any other is asked as before."""
        if self.boxes.one_link(body):
            self._kept_box.setdefault(body, None)

    def moved(self, body: int) -> None:
        """``body`` (see :meth:`keep_box`) was moved: its box is asked again."""
        if body in self._kept_box:
            self._kept_box[body] = None
            self._moves += 1

    def _box_of(self, bodies: Sequence[int]) -> tuple[list[float], list[float]]:
        """The smallest box holding the PyBullet boxes of the kept ``bodies`` (each asked
        once per pose, :meth:`keep_box`)."""
        kept, client = self._kept_box, self.client
        lo, hi = [math.inf] * 3, [-math.inf] * 3
        for b in bodies:
            box = kept.get(b)
            if box is None:
                box = kept[b] = p.getAABB(b, -1, physicsClientId=client)
            if not all(map(math.isfinite, (*box[0], *box[1]))):  # (never a proof from it)
                return [-math.inf] * 3, [math.inf] * 3
            lo = [min(x, y) for x, y in zip(lo, box[0], strict=True)]
            hi = [max(x, y) for x, y in zip(hi, box[1], strict=True)]
        return lo, hi

    def minima(self, body_a: int, body_b: int, groups: tuple[Links, ...], cap: float
               ) -> list[float]:
        """For each group of ``body_a``'s links, its minimum distance to ``body_b`` [m] (< 0:
        penetration), or ``cap`` when farther (exactly PyBullet's answer at threshold
        ``cap``)."""
        return self.minima_of(body_a, (body_b,), groups, cap)[0]

    def minima_of(self, body_a: int, bodies_b: Sequence[int], groups: tuple[Links, ...],
                  cap: float, joints_a: tuple[Sequence[int], np.ndarray] | None = None,
                  below: Sequence[Sequence[float]] | None = None) -> list[list[float]]:
        """:meth:`minima` of ``body_a`` against each of ``bodies_b`` in turn (the runner's
        every-step form: the groups' membership and the hints found once for all).
        ``joints_a``: the PyBullet indices of every movable joint of ``body_a`` (a fixed-base
        body) and their positions now, if the caller has them: then A's box is kept between
        steps and grown by how far the joints can have moved its shapes
        (:meth:`repro.sim.link_boxes.LinkBoxes.moving_box`), instead of being asked of
        PyBullet at every step.

        ``below``: for each of ``bodies_b``, a bound per group [m]: then only the groups
        closer than their bound need their value (a caller that keeps running minima and
        logs the values on some steps only). A body whose bounds are all below ``cap`` is
        asked with a threshold of their largest (every link closer is returned, so a group
        with a point below its bound has its minimum): a group's answer is its exact value
        where that is below its bound, else ``inf`` ("not below"), and the full queries'
        hint is neither used nor changed. Any other body is answered as without ``below``
        (every value exact; ``cap`` for one proved beyond the cap)."""
        key = (body_a, groups)
        hints = self._hint.get(key)
        if hints is None:
            hints = self._hint[key] = {}
        members = self._members.get(groups)
        if members is None:
            members = self._members[groups] = _Members(groups)
        ask, client, kept = p.getClosestPoints, self.client, self._kept_box
        box_a: tuple[list[float], list[float]] | None = None
        # the kept bodies beyond the cap at their last query, proved still so together when
        # one box holding all of theirs is (a person out of reach: one test, not twelve)
        far = tuple(b for b in bodies_b if hints.get(b, -math.inf) >= cap and b in kept)
        proved: tuple[int, ...] = ()
        if len(far) > 1:
            box_a = (self.boxes.box(body_a) if joints_a is None
                     else self.boxes.moving_box(body_a, *joints_a))
            union = self._far_union.get(key)
            if union is None or union[0] != self._moves or union[1] != far:
                union = self._far_union[key] = (self._moves, far, self._box_of(far))
            if box_gap(box_a, *union[2]) > cap + FAR_MARGIN:
                proved = far
        out = []
        for ib, body_b in enumerate(bodies_b):
            threshold = hints.get(body_b, cap)
            if proved and body_b in proved:
                self.skipped += 1
                out.append([cap] * members.n)
                continue  # (the hint stays: cap + HINT_MARGIN)
            if threshold >= cap and body_b in hints and self.boxes.one_link(body_b):
                # beyond the cap at the last query: are the boxes still far apart?
                if box_a is None:
                    box_a = (self.boxes.box(body_a) if joints_a is None
                             else self.boxes.moving_box(body_a, *joints_a))
                box_b = kept.get(body_b)
                if box_b is None:
                    box_b = p.getAABB(body_b, -1, physicsClientId=client)
                    if body_b in kept:
                        kept[body_b] = box_b
                if box_gap(box_a, *box_b) > cap + FAR_MARGIN:  # no shape within the cap
                    self.skipped += 1
                    out.append([cap] * members.n)
                    continue  # (the hint stays: cap + HINT_MARGIN)
            if below is not None:
                bounds = below[ib]
                if all(b < cap for b in bounds):  # (no NaN, none needing its value in full)
                    top = max(bounds)
                    mins = _minima(ask(body_a, body_b, max(top, 0.0), physicsClientId=client),
                                   members)
                    self.queries += 1
                    out.append([m if m < b else math.inf
                                for m, b in zip(mins, bounds, strict=True)])
                    continue
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
