"""A scripted human made of capsules (swept-sphere lines), for human-robot distance tests.

pomares2011 Sec. 4: a motion-capture suit and a UWB tag give the operator's skeleton; the
skeleton is covered by Swept-Sphere Lines and ``dist`` of the secondary task (17) is the
minimum over the pair-wise distances to the mini-robot's capsules
(:func:`repro.planning.capsules.min_distance`). The paper gives neither the bone lengths,
nor the radii, nor the operator's motion; this module supplies them:

* **Skeleton** (:class:`HumanBody`): torso (hip centre to shoulder centre), head (neck
  base to the top of the head+neck segment), upper arms, forearms, hands, thighs and
  shanks, left and right, each a capsule. Lengths are fractions of the stature ``H``
  (Winter, *Biomechanics and Motor Control of Human Movement*, Table 4.1; facts sheet
  ``pomares2011_facts.md``); ``H`` is ours.
* **Radii** (:class:`HumanRadii`): :data:`TIGHT_RADII` (default, ours: a median adult's
  limb half-thicknesses) or :data:`CONSERVATIVE_RADII` (DIN 33402-2 95th percentile, as in
  TUM's SaRA safety shield). The capsules here are the simulated person's *body* (scene
  geometry, ground-truth distances, renders), so they should look like one person; the
  95th-percentile envelope is a safety margin for an unknown person plus tracking error and
  belongs to the controller's side (its own capsules, or ``dmin``), which can ask
  :meth:`HumanMotion.capsules` for the same skeleton with ``radii=CONSERVATIVE_RADII``.
* **Motion** (:class:`HumanPath`, :class:`HumanMotion`): stand at ``start``; from
  ``t_enter`` walk (facing the approach point) to a stance from which the reaching hand
  can touch ``approach``; raise the arm so that the hand tip is at ``approach`` at
  ``t_reach``; hold until ``t_hold``; lower the arm, turn on the spot, walk to ``exit``
  (default ``start``), standing there from ``t_leave`` on. Every move follows the
  minimum-jerk profile ``sigma(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5`` (zero velocity and
  acceleration at both ends), and the construction checks that no skeleton joint moves
  faster than :data:`V_MAX` = 2 m/s (facts sheet: human joint speeds up to 2 m/s).
* **Tracking noise** (:func:`add_tracking_noise`): a separate function, so the ground
  truth (scene) and the measurement (controller) never mix.

Frames: the *base* frame of :class:`HumanPath` has its xy-plane on the floor and z up;
``T_world_base`` places it in the world. The *body* frame stands on the floor between the
feet: x forward (the facing direction), y to the person's left, z up. Units: [m], [s],
[rad].
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from repro.errors import ConfigError, UnknownChoiceError
from repro.planning.capsules import Capsule

if TYPE_CHECKING:
    from repro.sim.scene import Scene

V_MAX = 2.0  # [m/s] human joint speed bound (facts sheet, from SaRA's joint_v_max)
#: Arm poses whose body-frame skeleton is kept. ours: a memory bound, not a value rule (a
#: pose not kept is computed again, to the same bits): a walk or a hold keeps one pose, a
#: reach or a withdrawal makes a new one every step, so a few entries hold all reuse.
_BODY_CACHE_SIZE = 8

# Winter Table 4.1 (facts sheet): segment lengths as fractions of the stature H.
SEGMENT_FRACTIONS: dict[str, float] = {
    "upper_arm": 0.186,  # shoulder to elbow
    "forearm": 0.146,  # elbow to wrist
    "hand": 0.108,  # wrist to finger tip
    "trunk": 0.288,  # hip (greater trochanter) to shoulder
    "head_neck": 0.130,  # neck base to the top of the head segment
    "thigh": 0.245,  # hip to knee
    "shank": 0.246,  # knee to ankle
}
ARMS = ("left", "right")
PHASES = ("before", "walk_in", "reach", "hold", "withdraw", "turn", "walk_out", "after")


@dataclass(frozen=True)
class HumanRadii:
    """Capsule radii per segment [m]."""

    torso: float
    head: float
    upper_arm: float
    forearm: float
    hand: float
    thigh: float
    shank: float

    def __post_init__(self) -> None:
        for name, r in vars(self).items():
            if not (math.isfinite(r) and r > 0.0):
                raise ConfigError(f"HumanRadii.{name} must be > 0 [m], got {r}")


# ours: a median adult's half-breadths / circumference / (2 pi), rounded to 5 mm: chest
# 0.33 m broad, 0.24 m deep -> 0.15; head 0.155 x 0.195 m -> 0.10; arm girth 0.31 m ->
# 0.05; forearm 0.26 m -> 0.04; hand breadth 0.09 m -> 0.045; thigh 0.50 m -> 0.08;
# calf 0.36 m -> 0.055.
TIGHT_RADII = HumanRadii(torso=0.15, head=0.10, upper_arm=0.05, forearm=0.04, hand=0.045,
                         thigh=0.08, shank=0.055)
# DIN 33402-2 95th percentile as in SaRA (JakobThumm/sara-shield, safety_shield/config:
# capsule "thickness" = diameter 0.434, 0.434, 0.2, 0.132, 0.206 m). SaRA has no legs and
# says its arm values are DIN leg values: ours, thigh and shank reuse them.
CONSERVATIVE_RADII = HumanRadii(torso=0.217, head=0.217, upper_arm=0.10, forearm=0.066,
                                hand=0.103, thigh=0.10, shank=0.066)


@dataclass(frozen=True)
class HumanBody:
    """The skeleton's dimensions.

    Attributes:
        stature: body height H [m]; every segment length is a Winter fraction of it.
        radii: capsule radii [m] (:data:`TIGHT_RADII` or :data:`CONSERVATIVE_RADII`).
        shoulder_half_width: shoulder joint centre to the body's mid-plane [H].
        hip_half_width: hip joint centre to the mid-plane [H].
        ankle_height: ankle joint above the floor [H].
    """

    stature: float = 1.75  # ours: [m] an adult man's stature
    radii: HumanRadii = TIGHT_RADII  # ours: the body itself, not a safety envelope
    shoulder_half_width: float = 0.10  # ours: [H] shoulder joints ~0.35 m apart at 1.75 m
    hip_half_width: float = 0.05  # ours: [H] hip joints ~0.18 m apart at 1.75 m
    ankle_height: float = 0.039  # ours: [H] Winter's ankle height (not in the facts sheet)

    def __post_init__(self) -> None:
        if not (0.5 <= self.stature <= 2.5):
            raise ConfigError(f"HumanBody.stature must be in [0.5, 2.5] m, got {self.stature}")
        for name in ("shoulder_half_width", "hip_half_width", "ankle_height"):
            v = getattr(self, name)
            if not (0.0 <= v < 0.5):
                raise ConfigError(f"HumanBody.{name} must be in [0, 0.5) H, got {v}")

    def length(self, segment: str) -> float:
        """Length of a segment [m]: ``SEGMENT_FRACTIONS[segment] * stature``."""
        if segment not in SEGMENT_FRACTIONS:
            raise UnknownChoiceError("body segment", segment, SEGMENT_FRACTIONS)
        return SEGMENT_FRACTIONS[segment] * self.stature

    @property
    def hip_height(self) -> float:
        """Hip joint centre above the floor, standing [m]."""
        return (self.ankle_height + SEGMENT_FRACTIONS["shank"]
                + SEGMENT_FRACTIONS["thigh"]) * self.stature

    @property
    def shoulder_height(self) -> float:
        """Shoulder joint centre above the floor, standing [m]."""
        return self.hip_height + self.length("trunk")

    @property
    def arm_length(self) -> float:
        """Shoulder to finger tip, arm straight [m]."""
        return self.length("upper_arm") + self.length("forearm") + self.length("hand")


@dataclass(frozen=True)
class HumanPath:
    """The scripted visit: walk in, reach the approach point, hold, withdraw, walk away.

    Points are in the base frame (xy-plane = floor, z up); times are absolute [s] with
    ``t_enter < t_reach <= t_hold < t_leave``.

    Attributes:
        start: floor point (x, y) [m] where the person stands until ``t_enter``.
        approach: point (x, y, z) [m] the reaching hand's tip (end of the hand segment)
            is at during ``[t_reach, t_hold]``.
        t_enter: the person starts walking towards the approach point [s].
        t_reach: the hand tip arrives at the approach point [s].
        t_hold: end of the hold: the arm starts to withdraw [s].
        t_leave: the person stands at ``exit`` again [s].
        arm: ``"right"`` or ``"left"``: the reaching arm.
        exit: floor point (x, y) [m] walked to after the hold; ``None`` = ``start``.
        reach_duration: raising (and lowering) the arm [s].
        turn_duration: turning on the spot towards the exit [s].
        reach_extension: shoulder-to-tip distance at the approach point, as a fraction of
            the straight-arm length [-]; sets where the person stops.
    """

    start: tuple[float, float]
    approach: tuple[float, float, float]
    t_enter: float
    t_reach: float
    t_hold: float
    t_leave: float
    arm: str = "right"
    exit: tuple[float, float] | None = None
    reach_duration: float = 1.5  # ours: [s] keeps the hand tip below ~1.3 m/s
    turn_duration: float = 1.5  # ours: [s] a half turn on the spot at ~1.3 m/s hand speed
    reach_extension: float = 0.85  # ours: [-] a natural reach, elbow slightly bent

    def __post_init__(self) -> None:
        if self.arm not in ARMS:
            raise UnknownChoiceError("reaching arm", self.arm, ARMS)
        if len(self.start) != 2 or len(self.approach) != 3 or (
                self.exit is not None and len(self.exit) != 2):
            raise ConfigError("HumanPath: start and exit are (x, y), approach is (x, y, z) "
                              f"[m]; got {self.start}, {self.approach}, {self.exit}")
        if not (0.0 < self.reach_duration and 0.0 < self.turn_duration):
            raise ConfigError("HumanPath: reach_duration and turn_duration must be > 0 s, "
                              f"got {self.reach_duration}, {self.turn_duration}")
        if not (0.3 <= self.reach_extension <= 0.99):
            raise ConfigError("HumanPath.reach_extension must be in [0.3, 0.99], got "
                              f"{self.reach_extension}")
        if not (self.t_enter < self.t_reach - self.reach_duration):
            raise ConfigError(f"HumanPath: t_reach - t_enter = {self.t_reach - self.t_enter} s"
                              f" leaves no time to walk before the {self.reach_duration} s "
                              "reach")
        if self.t_hold < self.t_reach:
            raise ConfigError(f"HumanPath: t_hold = {self.t_hold} s before t_reach = "
                              f"{self.t_reach} s")
        if not (self.t_hold + self.reach_duration + self.turn_duration < self.t_leave):
            raise ConfigError(f"HumanPath: t_leave - t_hold = {self.t_leave - self.t_hold} s"
                              " leaves no time to walk after withdrawing "
                              f"({self.reach_duration} s) and turning ({self.turn_duration} s)")

    @property
    def exit_point(self) -> tuple[float, float]:
        return self.start if self.exit is None else self.exit


def min_jerk(tau: float) -> float:
    """Minimum-jerk profile ``10 tau^3 - 15 tau^4 + 6 tau^5`` on [0, 1], clamped outside
    (peak rate 1.875 at tau = 0.5)."""
    tau = min(max(tau, 0.0), 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


def _progress(t: float, t0: float, t1: float) -> float:
    return min_jerk((t - t0) / (t1 - t0))


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class _ArmPose:
    """An arm in its vertical plane of azimuth ``phi`` (body frame): upper arm at ``theta``
    from straight down towards the plane's forward direction, elbow flexed by ``beta``
    (forearm and hand in line, at ``theta + beta``) [rad]."""

    phi: float = 0.0
    theta: float = 0.0
    beta: float = 0.0


class HumanMotion:
    """A person following a :class:`HumanPath`: skeleton joints and capsules over time.

    Args:
        path: the scripted visit (base frame).
        body: skeleton dimensions and radii.
        T_world_base: 4x4 pose of the base frame in the world (xy-plane = floor).

    Raises:
        ConfigError: the approach point cannot be reached from any stance on the way in
            (too high, too low, or ``start`` too close), or some joint would move faster
            than :data:`V_MAX`.
    """

    def __init__(self, path: HumanPath, body: HumanBody | None = None,
                 T_world_base: np.ndarray | None = None) -> None:
        self.path = path
        self.body = body if body is not None else HumanBody()
        self.T_world_base = (np.eye(4) if T_world_base is None
                             else np.asarray(T_world_base, dtype=float).copy())
        if self.T_world_base.shape != (4, 4) or not np.isfinite(self.T_world_base).all():
            raise ConfigError(f"T_world_base must be a finite 4x4 pose, got "
                              f"{self.T_world_base.tolist()}")
        self._side = 1.0 if path.arm == "left" else -1.0  # +y is the person's left
        #: per radii: (state, capsules) of the last call; a still person's capsules are
        #: computed once (values identical: the same state gives the same arithmetic)
        self._capsule_cache: dict[HumanRadii, tuple[tuple[bytes, float, _ArmPose],
                                                    list[tuple[str, Capsule]]]] = {}
        #: the body-frame joints of the last arm poses (:meth:`_body_joints`)
        self._body_cache: dict[tuple[_ArmPose, float, float, float],
                               list[tuple[str, np.ndarray]]] = {}
        self._solve_stance()
        p = path
        self._t_walk_in_end = p.t_reach - p.reach_duration
        self._t_withdraw_end = p.t_hold + p.reach_duration
        self._t_turn_end = self._t_withdraw_end + p.turn_duration
        peak = self.speed_bound()
        if peak > V_MAX:
            raise ConfigError(f"a skeleton joint may reach {peak:.2f} m/s > {V_MAX} m/s (the "
                              "human speed bound): give the walks, the reach or the turn "
                              "more time")

    # ---------------------------------------------------------------- geometry
    def _solve_stance(self) -> None:
        """Where the person stops, facing the approach point, so that the shoulder-to-tip
        distance is ``reach_extension * arm_length``; and the arm angles there."""
        p, b = self.path, self.body
        start = np.asarray(p.start, dtype=float)
        a = np.asarray(p.approach, dtype=float)
        horiz = a[:2] - start
        D = float(np.linalg.norm(horiz))
        if D < 1e-6:
            raise ConfigError(f"HumanPath.start {p.start} is below the approach point")
        self.yaw_in = math.atan2(horiz[1], horiz[0])
        w = b.shoulder_half_width * b.stature
        dz = a[2] - b.shoulder_height
        reach = p.reach_extension * b.arm_length
        fwd_sq = reach**2 - w**2 - dz**2
        if fwd_sq <= 0.0:
            raise ConfigError(f"approach point height {a[2]:.3f} m is out of reach: the "
                              f"shoulder is at {b.shoulder_height:.3f} m and the reach "
                              f"{reach:.3f} m")
        fwd = math.sqrt(fwd_sq)  # horizontal shoulder-to-target distance, forward
        if D <= fwd:
            raise ConfigError(f"HumanPath.start is {D:.3f} m from the approach point "
                              f"(horizontally); it must be farther than the stance, {fwd:.3f} m")
        self.stance = start + (D - fwd) / D * horiz  # floor point (x, y), base frame
        exit_ = np.asarray(p.exit_point, dtype=float)
        out = exit_ - self.stance
        self.yaw_out = (math.atan2(out[1], out[0]) if np.linalg.norm(out) > 1e-6
                        else self.yaw_in)
        # Arm angles at the target (body frame; shoulder at (0, side*w, h_sh)).
        v = np.array([fwd, -self._side * w, dz])
        L1 = b.length("upper_arm")
        L2 = b.length("forearm") + b.length("hand")
        d = float(np.linalg.norm(v))
        gamma = math.atan2(math.hypot(v[0], v[1]), -v[2])  # target angle from straight down
        alpha = math.acos((L1 * L1 + d * d - L2 * L2) / (2.0 * L1 * d))
        elbow = math.acos((L1 * L1 + L2 * L2 - d * d) / (2.0 * L1 * L2))
        # elbow below the shoulder-target line (the natural reach)
        self.reach_pose = _ArmPose(phi=math.atan2(v[1], v[0]), theta=gamma - alpha,
                                   beta=math.pi - elbow)

    def _state(self, t: float) -> tuple[np.ndarray, float, _ArmPose, str]:
        """(floor position (x, y) in the base frame, yaw [rad], reaching-arm pose, phase)."""
        p = self.path
        start = np.asarray(p.start, dtype=float)
        exit_ = np.asarray(p.exit_point, dtype=float)
        rest = _ArmPose(phi=self.reach_pose.phi)
        R = self.reach_pose

        def arm(s: float) -> _ArmPose:
            return _ArmPose(R.phi, s * R.theta, s * R.beta)

        turn = _wrap(self.yaw_out - self.yaw_in)
        if t < p.t_enter:
            return start, self.yaw_in, rest, "before"
        if t < self._t_walk_in_end:
            s = _progress(t, p.t_enter, self._t_walk_in_end)
            return start + s * (self.stance - start), self.yaw_in, rest, "walk_in"
        if t < p.t_reach:
            s = _progress(t, self._t_walk_in_end, p.t_reach)
            return self.stance, self.yaw_in, arm(s), "reach"
        if t < p.t_hold:
            return self.stance, self.yaw_in, R, "hold"
        if t < self._t_withdraw_end:
            s = 1.0 - _progress(t, p.t_hold, self._t_withdraw_end)
            return self.stance, self.yaw_in, arm(s), "withdraw"
        if t < self._t_turn_end:
            s = _progress(t, self._t_withdraw_end, self._t_turn_end)
            return self.stance, self.yaw_in + s * turn, rest, "turn"
        yaw = self.yaw_in + turn
        if t < p.t_leave:
            s = _progress(t, self._t_turn_end, p.t_leave)
            return self.stance + s * (exit_ - self.stance), yaw, rest, "walk_out"
        return exit_, yaw, rest, "after"

    def phase(self, t: float) -> str:
        """One of :data:`PHASES` at time ``t`` [s]."""
        return self._state(t)[3]

    def joints(self, t: float) -> dict[str, np.ndarray]:
        """Skeleton joint positions (3,) [m] in the world frame at time ``t`` [s].

        Names: ``hip``, ``neck`` (shoulder centre), ``head_top``, ``shoulder_l/r``,
        ``elbow_l/r``, ``wrist_l/r``, ``fingertip_l/r``, ``hip_l/r``, ``knee_l/r``,
        ``ankle_l/r``.
        """
        pos, yaw, reach_arm, _ = self._state(t)
        return self._joints(pos, yaw, reach_arm)

    def _joints(self, pos: np.ndarray, yaw: float, reach_arm: _ArmPose
                ) -> dict[str, np.ndarray]:
        c, s = math.cos(yaw), math.sin(yaw)
        T_base_body = np.array([[c, -s, 0.0, pos[0]], [s, c, 0.0, pos[1]],
                                [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
        T = self.T_world_base @ T_base_body
        R, o = T[:3, :3], T[:3, 3]
        return {k: R @ v + o for k, v in self._body_joints(reach_arm)}

    def _body_joints(self, reach_arm: _ArmPose) -> list[tuple[str, np.ndarray]]:
        """The skeleton's joints in the body frame (they depend on the arm pose alone: kept
        for the last few poses, e.g. the whole of a walk)."""
        a = reach_arm  # its zeros' signs too: the same bits, the same arithmetic
        key = (a, math.copysign(1.0, a.phi), math.copysign(1.0, a.theta),
               math.copysign(1.0, a.beta))
        got = self._body_cache.get(key)
        if got is not None:
            return got
        b = self.body
        H = b.stature
        z = np.array([0.0, 0.0, 1.0])
        P: dict[str, np.ndarray] = {}
        P["hip"] = np.array([0.0, 0.0, b.hip_height])
        P["neck"] = np.array([0.0, 0.0, b.shoulder_height])
        P["head_top"] = P["neck"] + b.length("head_neck") * z
        L1, L2, L3 = b.length("upper_arm"), b.length("forearm"), b.length("hand")
        for side, tag in ((1.0, "l"), (-1.0, "r")):
            a = reach_arm if side == self._side else _ArmPose()
            e = np.array([math.cos(a.phi), math.sin(a.phi), 0.0])  # arm-plane forward
            u1 = math.sin(a.theta) * e - math.cos(a.theta) * z
            u2 = math.sin(a.theta + a.beta) * e - math.cos(a.theta + a.beta) * z
            P[f"shoulder_{tag}"] = P["neck"] + np.array([0.0, side * b.shoulder_half_width * H,
                                                         0.0])
            P[f"elbow_{tag}"] = P[f"shoulder_{tag}"] + L1 * u1
            P[f"wrist_{tag}"] = P[f"elbow_{tag}"] + L2 * u2
            P[f"fingertip_{tag}"] = P[f"wrist_{tag}"] + L3 * u2
            P[f"hip_{tag}"] = P["hip"] + np.array([0.0, side * b.hip_half_width * H, 0.0])
            P[f"knee_{tag}"] = P[f"hip_{tag}"] - b.length("thigh") * z
            P[f"ankle_{tag}"] = P[f"knee_{tag}"] - b.length("shank") * z
        for v in P.values():
            v.setflags(write=False)
        if len(self._body_cache) >= _BODY_CACHE_SIZE:
            self._body_cache.clear()
        got = self._body_cache[key] = list(P.items())
        return got

    def capsules(self, t: float, radii: HumanRadii | None = None
                 ) -> list[tuple[str, Capsule]]:
        """The body's capsules in the world frame at time ``t`` [s] (ground truth).

        Names: ``torso``, ``head``, then per side ``upper_arm_l``, ``forearm_l``,
        ``hand_l``, ``thigh_l``, ``shank_l`` (and ``_r``). Segment directions run from
        the proximal joint (``p0``) to the distal one (``p1``); ``head`` from the neck up.

        Args:
            radii: override of ``body.radii`` (e.g. :data:`CONSERVATIVE_RADII` for the
                controller's own bounding volumes).
        """
        r = self.body.radii if radii is None else radii
        pos, yaw, reach_arm, _ = self._state(t)
        key = (np.asarray(pos, dtype=float).tobytes(), float(yaw), reach_arm)
        cached = self._capsule_cache.get(r)
        if cached is not None and cached[0] == key:  # standing or holding: the same body
            return list(cached[1])  # (Capsule is immutable)
        if not all(map(math.isfinite, (*np.asarray(pos, dtype=float).tolist(), yaw,
                                        reach_arm.phi, reach_arm.theta, reach_arm.beta))):
            raise ConfigError(f"the person's state at t = {t} s is not finite: position "
                              f"{pos}, yaw {yaw}, arm {reach_arm}")
        # finite state, finite T_world_base and body: finite joints, fresh arrays each
        J = self._joints(pos, yaw, reach_arm)
        cap = Capsule.of_owned
        out = [("torso", cap(J["hip"], J["neck"], r.torso)),
               ("head", cap(J["neck"], J["head_top"], r.head))]
        for tag in ("l", "r"):
            out += [(f"upper_arm_{tag}", cap(J[f"shoulder_{tag}"], J[f"elbow_{tag}"],
                                             r.upper_arm)),
                    (f"forearm_{tag}", cap(J[f"elbow_{tag}"], J[f"wrist_{tag}"], r.forearm)),
                    (f"hand_{tag}", cap(J[f"wrist_{tag}"], J[f"fingertip_{tag}"], r.hand)),
                    (f"thigh_{tag}", cap(J[f"hip_{tag}"], J[f"knee_{tag}"], r.thigh)),
                    (f"shank_{tag}", cap(J[f"knee_{tag}"], J[f"ankle_{tag}"], r.shank))]
        if cached is not None and cached[0][:2] == key[:2]:
            out = _kept(cached[1], out)  # standing, one arm moving: the rest is as it was
        self._capsule_cache[r] = (key, out)
        return list(out)

    def fingertip(self, t: float) -> np.ndarray:
        """Tip of the reaching hand (end of its hand segment) in the world [m]."""
        return self.joints(t)["fingertip_" + ("l" if self._side > 0 else "r")]

    def speed_bound(self) -> float:
        """Upper bound on every joint's speed [m/s], in closed form.

        A minimum-jerk move of duration T has peak rate ``1.875 / T`` (per unit of
        progress). Walking translates the rigid body: ``1.875 D / T``, exact. Turning by
        ``dpsi`` moves a joint at horizontal radius rho at ``1.875 |dpsi| rho / T``; with
        the arms hanging, rho <= the shoulder half-width. Reaching moves the tip at
        ``|d tip / ds| * ds/dt <= (|theta| L1 + |theta + beta| (L2 + L3)) 1.875 / T``
        (triangle inequality over the two angular rates; elbow and wrist are slower).
        """
        p, b, R = self.path, self.body, self.reach_pose
        k = 1.875
        start, exit_ = np.asarray(p.start, float), np.asarray(p.exit_point, float)
        walk_in = k * float(np.linalg.norm(self.stance - start)) / (
            self._t_walk_in_end - p.t_enter)
        walk_out = k * float(np.linalg.norm(exit_ - self.stance)) / (
            p.t_leave - self._t_turn_end)
        turn = (k * abs(_wrap(self.yaw_out - self.yaw_in)) * b.shoulder_half_width * b.stature
                / p.turn_duration)
        arm = k * (abs(R.theta) * b.length("upper_arm") + abs(R.theta + R.beta) * (
            b.length("forearm") + b.length("hand"))) / p.reach_duration
        return max(walk_in, walk_out, turn, arm)

    def peak_speed(self, dt: float = 0.005) -> float:
        """Largest joint speed [m/s] over the whole visit, by finite differences of
        :meth:`joints` with step ``dt`` [s] (the profile is smooth, so a 5 ms step is
        within a fraction of a percent of the true peak)."""
        ts = np.arange(self.path.t_enter, self.path.t_leave + dt, dt)
        prev = np.array(list(self.joints(float(ts[0])).values()))
        peak = 0.0
        for t in ts[1:]:
            cur = np.array(list(self.joints(float(t)).values()))
            peak = max(peak, float(np.max(np.linalg.norm(cur - prev, axis=1))) / dt)
            prev = cur
        return peak


def _kept(old: list[tuple[str, Capsule]], new: list[tuple[str, Capsule]]
          ) -> list[tuple[str, Capsule]]:
    """``new`` with each capsule whose end points have the same bits as in ``old`` (and the
    same radius) replaced by ``old``'s object: a body part that did not move keeps its
    capsule, so its users (a mover, a tracker) see it unchanged by identity."""
    out = []
    for (name, c), (_, o) in zip(new, old, strict=True):
        same = (c.radius == o.radius and c.p0.tobytes() == o.p0.tobytes()
                and c.p1.tobytes() == o.p1.tobytes())
        out.append((name, o if same else c))
    return out


def add_tracking_noise(capsules: Sequence[tuple[str, Capsule]], std: float,
                       rng: np.random.Generator) -> list[tuple[str, Capsule]]:
    """Measured capsules: every distinct end point moved by ``N(0, std^2 I_3)`` [m].

    End points shared by two segments (a joint: the elbow ends the upper arm and starts
    the forearm) get the same draw, so the measured skeleton stays connected, as a
    tracker reports joints. Radii are unchanged. Draws come from ``rng`` in the order the
    points first appear, so a seeded Generator gives the same measurement.

    Args:
        capsules: ground truth, as from :meth:`HumanMotion.capsules`.
        std: standard deviation per axis [m] (0 gives exact copies).
        rng: the caller's seeded Generator.
    """
    if not (math.isfinite(std) and std >= 0.0):
        raise ConfigError(f"tracking noise std must be >= 0 [m], got {std}")
    keys: dict[bytes, int] = {}
    for _, c in capsules:
        for pt in (c.p0, c.p1):
            keys.setdefault(pt.tobytes(), len(keys))
    noise = rng.normal(0.0, std, size=(len(keys), 3)) if std > 0.0 else np.zeros((len(keys), 3))
    return [(name, Capsule(c.p0 + noise[keys[c.p0.tobytes()]],
                           c.p1 + noise[keys[c.p1.tobytes()]], c.radius))
            for name, c in capsules]


@dataclass
class HumanInScene:
    """The human's capsules as moving bodies of a :class:`repro.sim.scene.Scene`, named
    ``<prefix><capsule name>`` (e.g. ``human_forearm_r``)."""

    motion: HumanMotion
    prefix: str = "human_"
    rgba: tuple[float, float, float, float] = (0.85, 0.65, 0.5, 1.0)
    names: list[str] = field(default_factory=list)

    def add(self, scene: Scene, t: float = 0.0) -> None:
        """Add every capsule at its pose at time ``t`` [s] (``moving=True``)."""
        for name, c in self.motion.capsules(t):
            scene.add_capsule(self.prefix + name, c.radius, c.length, c.T_world(), self.rgba,
                              moving=True)
            self.names.append(self.prefix + name)

    def move(self, scene: Scene, t: float) -> None:
        """Move every capsule to its pose at time ``t`` [s] (the bones are rigid, so the
        lengths given to :meth:`add` still hold)."""
        for name, c in self.motion.capsules(t):
            scene.move(self.prefix + name, c.T_world())
