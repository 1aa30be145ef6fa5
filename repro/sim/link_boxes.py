"""Axis-aligned boxes [m] that hold every collision shape of a PyBullet body, now or since a
kept box was made: the audit's proof that a body is beyond the closest-points cap
(:mod:`repro.sim.closest`) without asking PyBullet.

:meth:`LinkBoxes.box` is PyBullet's own boxes (``getAABB``) of the body's links after a forward
kinematics; :meth:`LinkBoxes.moving_box` keeps one between steps and grows it by a bound on how
far the joints can have moved any shape since (see its docstring).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pybullet as p

__all__ = ["BOX_SLACK", "LinkBoxes", "box_gap"]

#: How far a kept box of a robot may be grown by its joints' motion before it is made again
#: [m]. ours: a speed rule, not a value rule (a grown box only proves less): 5 cm keeps
#: the far test nearly as tight as a fresh box (pomares2011 exp2 makes it again about every
#: 120 steps: 144 times in 16727).
BOX_SLACK = 0.05


class LinkBoxes:
    """The boxes of the bodies of one PyBullet client (what each body is made of is found
    once).

    Args:
        client: the PyBullet client.
    """

    def __init__(self, client: int) -> None:
        self.client = client
        self._shaped: dict[int, list[int]] = {}  # body -> its links with collision shapes
        #: body -> (joints, box lower, box upper, q_ref, revolute mask, r) of moving_box
        self._moving: dict[int, tuple[tuple[int, ...], list[float], list[float], np.ndarray,
                                      np.ndarray, float]] = {}
        self._kinds: dict[int, dict[int, bool] | None] = {}

    def one_link(self, body: int) -> bool:
        """``body`` has a single link with a collision shape, its base."""
        return self.links(body) == [-1]

    def links(self, body: int) -> list[int]:
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
            # ours: S < 1/4 keeps 1 - 2S >= 1/2 (the bound at most doubles S r + P); a box
            # moved that far is made again anyway (S r alone is ~BOX_SLACK at S ~ 0.03)
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
        links = self.links(body)
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


def box_gap(box: tuple[Sequence[float], Sequence[float]], lo: Sequence[float],
             hi: Sequence[float]) -> float:
    """Euclidean distance [m] between the box ``(lower, upper)`` and the box ``lo``-``hi``
    (0 when they overlap): no point of one is closer to a point of the other."""
    s = 0.0
    for i in range(3):
        g = max(lo[i] - box[1][i], box[0][i] - hi[i], 0.0)
        s += g * g
    return math.sqrt(s)
