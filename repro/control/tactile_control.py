r"""Tactile control of pomares2011 (Sec. 6, Algorithm 1) as a tick-driven state machine.

The algorithm executes a planned finger joint trajectory and, after every step, checks each
finger's maximum contact pressure ``p`` (the maximum over its tactile arrays) against two
thresholds: below the *readjust* threshold the finger's joint angles are incremented a
little (the finger is blocked by the object, so its position stays and its pressure rises),
at most ``NUM_MAX_READJUSTMENTS`` times; if the pressure is still below the *safety*
threshold after that many readjustments the manipulation task ends. The pseudo-code, with
the paper's line numbers (line 09 does not exist in the paper)::

    01: for i = 1..nSteps
    02:   Execute Joint Angles of step i of the trajectory for all fingers
    03:   for f = 1..nFingers
    04:     numReadjust = 0
    05:     Get Maximum contact pressure p for finger f from its tactile sensor arrays
    06:     if p < readjustThres[f] && numReadjust < NUM_MAX_READJUSTMENTS
    07:       Increment joint angles of finger f if joint torques of f do not exceed
              maximum allowable torque
    08:       numReadjust = numReadjust + 1
    10:       goto line 5
    11:     end if
    12:     if p < safetyThres[f] && numReadjust == NUM_MAX_READJUSTMENTS
    13:       return // End manipulation task
    14:     end if
    15:   end for
    16: end for

Ticks. The paper runs the algorithm at the 30 Hz of the tactile sensors (Sec. 7: "33 ms
for each execution step"), so here one call of :meth:`TactileController.step` is one tick
with the latest reading of every finger: its maximum pressure [kPa] and its joint torque
[N m]. A tick runs the pseudo-code until it has to wait for a new reading, i.e. until it
sends a command -- the trajectory step of line 2 or the readjustment of line 7 (``goto
line 5`` then reads ``p`` again) -- or the task ends (line 13, or the last step done). The
comparisons of lines 6 and 12 take no time: one reading may pass several fingers, and with
every finger above its threshold the trajectory advances one step per tick. The first tick
sends step 0 (line 2 comes before any reading). A tick whose reading is flagged not
``settled`` (the previous command still moving the finger) only waits.

Units: finger targets are in the units of the trajectory (for the Barrett hand, where one
motor drives the coupled joints of a finger, one value per finger: the motor's joint angle
[rad], proportional to the paper's "motor counts"); the increment is in the same unit.
Pressures [kPa]; torques [N m]. Indices are 0-based: the paper's finger ``k`` is ``f = k -
1``, its step ``i`` is our ``i - 1``. No simulator inside.

Readings we had to make (each marked ``# ours:`` at the code):

* A readjustment skipped because the finger's torque exceeds its maximum (line 7, "if
  joint torques of f do not exceed") still counts: line 8 is outside the condition of
  line 7 in the pseudo-code. So a blocked finger uses up its readjustments and the task
  still ends (continue or stop by line 12); it cannot loop forever. ``|tau_f| <= max``
  allows the increment ("do not exceed"); ``|tau_f| > max`` skips it.
* A skipped readjustment also ends the tick (``goto line 5`` reads ``p`` again): nothing
  was sent, but the next reading is the next sample anyway.
* Line 2 "Execute Joint Angles of step i of the trajectory" is taken literally by default:
  the next step commands ``JointTrajectory[i]`` and the increments of earlier steps are
  dropped. ``carry_readjustments=True`` keeps every finger's accumulated increments on top
  of the later trajectory steps instead (the paper does not say).
* The safety threshold is the lower one (paper: 10 <= 10, 10 <= 20 kPa); we refuse a
  safety threshold above the readjust threshold, which would let line 12 stop a finger
  whose pressure line 6 had just accepted.
* The paper gives the safety threshold as "10 kPa" for finger 3 only; we use it for every
  finger. ``NUM_MAX_READJUSTMENTS``, the increment and the maximum torques are not given.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from repro.errors import ConfigError, NonFiniteInputError

__all__ = ["ACTIONS", "LOG_FIELDS", "PAPER_READJUST_THRESHOLD_KPA",
           "PAPER_SAFETY_THRESHOLD_KPA", "STATES", "Decision", "TactileControlConfig",
           "TactileController", "TactileStep"]

# pomares2011 Sec. 7.3: "10 kPa for fingers 1-2 and 20 kPa for finger 3".
PAPER_READJUST_THRESHOLD_KPA = (10.0, 10.0, 20.0)
# pomares2011 Sec. 7.3: "below the safety threshold (10 kPa)".
# ours: the paper states it for finger 3; we use it for every finger.
PAPER_SAFETY_THRESHOLD_KPA = (10.0, 10.0, 10.0)

#: What a decision did (``Decision.action``), with the line of Algorithm 1 it comes from.
ACTIONS = {
    "move": "line 2: sent step i of the trajectory to all fingers",
    "wait": "line 5: the reading is not settled yet; nothing decided",
    "readjust": "lines 6-8: p < readjustThres[f], numReadjust < max, torque allows: "
                "target of finger f += increment",
    "readjust_blocked_torque": "lines 6-8: as readjust, but |torque| > max allowable: "
                               "increment skipped, numReadjust still counted",
    "ok": "lines 6, 12, 15: p >= readjustThres[f], on to the next finger",
    "give_up_continue": "lines 12, 15: numReadjust == max, safetyThres[f] <= p < "
                        "readjustThres[f], on to the next finger",
    "stop": "lines 12-13: p < safetyThres[f] with numReadjust == max: task ended, "
            "no further trajectory step is sent",
    "done": "line 16: every step of the trajectory executed",
}

#: State of the machine between ticks.
STATES = {
    "start": "nothing sent yet; the next tick sends step 0 (line 2)",
    "check": "waiting for a reading to check finger f at step i (line 5)",
    "stopped": "line 13 ended the task; commands held",
    "done": "all steps executed; commands held",
}

# Line of Algorithm 1 each action executes.
_LINE = {"move": 2, "wait": 5, "readjust": 7, "readjust_blocked_torque": 7, "ok": 6,
         "give_up_continue": 12, "stop": 13, "done": 16}

#: Fields of :meth:`TactileController.log_row`: name -> (unit, definition). A name with
#: ``{i}`` is one field per finger, ``{i}`` 1-based (the paper's finger number), as
#: :meth:`repro.runs.columns.Columns.add` expands it.
LOG_FIELDS: dict[str, tuple[str, str]] = {
    "tactile_state": ("text", "state of Algorithm 1: " + ", ".join(STATES)),
    "tactile_action": ("text", "last action of this tick (empty: none): "
                       + ", ".join(ACTIONS)),
    "tactile_line": ("-", "line of Algorithm 1 of the last action of this tick (0: none)"),
    "tactile_step": ("-", "trajectory step i being executed, 0-based (-1: none sent yet)"),
    "tactile_finger": ("-", "finger f being checked, 0-based (-1: none)"),
    "tactile_steps_sent": ("-", "trajectory steps sent so far (line 2)"),
    "tactile_target{i}": ("rad", "commanded target of finger {i} (units of the trajectory: "
                          "its motor joint angle)"),
    "tactile_num_readjust{i}": ("-", "numReadjust of finger {i} in the current step "
                                "(line 4 resets it)"),
    "tactile_n_readjust{i}": ("-", "readjustments of finger {i} executed so far (line 7)"),
    "tactile_n_blocked{i}": ("-", "readjustments of finger {i} skipped so far: torque over "
                             "the maximum (line 7)"),
    "tactile_n_give_up{i}": ("-", "times finger {i} passed on after max readjustments "
                             "(line 12 false)"),
}


def _per_finger(name: str, value: float | Sequence[float], n: int | None) -> tuple[float, ...]:
    """``value`` as a tuple of finite floats > 0, one per finger (a scalar is broadcast when
    ``n`` is given)."""
    values: tuple[Any, ...]
    if np.ndim(value) == 0:
        if n is None:
            raise ConfigError(f"{name} must be a sequence, one value per finger; got {value!r}")
        values = (value,) * n
    else:
        values = tuple(value)  # type: ignore[arg-type]
    if n is not None and len(values) != n:
        raise ConfigError(f"{name} must have one value per finger ({n}), got {len(values)}: "
                          f"{values!r}")
    if not values:
        raise ConfigError(f"{name} must have at least one finger, got {values!r}")
    out = []
    for k, v in enumerate(values):
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"{name}[{k}] must be a number, got {v!r}") from None
        if not (math.isfinite(x) and x > 0):
            raise ConfigError(f"{name}[{k}] must be finite and > 0, got {v!r}")
        out.append(x)
    return tuple(out)


@dataclass(frozen=True)
class TactileControlConfig:
    """Parameters of Algorithm 1 (pomares2011 Sec. 6); one entry per finger.

    Attributes:
        readjust_threshold_kpa: ``readjustThres[f]`` [kPa], > 0 (pomares2011 Sec. 7.3:
            10, 10, 20 kPa). Its length sets the number of fingers.
        safety_threshold_kpa: ``safetyThres[f]`` [kPa], 0 < safety <= readjust
            (pomares2011 Sec. 7.3: 10 kPa).
        max_readjustments: ``NUM_MAX_READJUSTMENTS``, an integer >= 0; ours.
        increment: the readjustment step of line 7, per finger or one for all, > 0, in the
            units of the trajectory (the finger's motor joint angle [rad]); ours.
        max_torque_nm: the maximum allowable torque of line 7 per finger or one for all
            [N m], > 0; compared with ``|tau_f|``; ours.
        carry_readjustments: False (the paper's line 2, literal): each new step commands
            the trajectory's angles; True: the increments accumulated so far stay on top of
            the later steps; ours.
    """

    readjust_threshold_kpa: tuple[float, ...] = PAPER_READJUST_THRESHOLD_KPA
    safety_threshold_kpa: tuple[float, ...] = PAPER_SAFETY_THRESHOLD_KPA
    max_readjustments: int = 5  # ours: a few 30 Hz ticks (0.17 s) per finger and step
    # ours: 0.01 rad (0.57 deg) of the proximal joint per readjustment, a "small increment".
    increment: float | tuple[float, ...] = 0.01
    # ours: Barrett wiki's 2 kg load per finger x g x (A2 + A3 = 0.12 m) = 2.35 N m.
    max_torque_nm: float | tuple[float, ...] = 2.35
    carry_readjustments: bool = False  # ours: the paper's line 2 read literally

    def __post_init__(self) -> None:
        readjust = _per_finger("readjust_threshold_kpa", self.readjust_threshold_kpa, None)
        n = len(readjust)
        safety = _per_finger("safety_threshold_kpa", self.safety_threshold_kpa, None)
        if len(safety) != n:
            raise ConfigError(f"safety_threshold_kpa must have one value per finger ({n}, as "
                              f"readjust_threshold_kpa), got {len(safety)}: {safety!r}")
        for f, (s, r) in enumerate(zip(safety, readjust, strict=True)):
            if s > r:
                # ours: see the module docstring (the paper: 10 <= 10, 10 <= 20 kPa).
                raise ConfigError(f"safety_threshold_kpa[{f}] = {s} kPa must not exceed "
                                  f"readjust_threshold_kpa[{f}] = {r} kPa")
        m = self.max_readjustments
        if isinstance(m, bool) or not isinstance(m, int | np.integer) or m < 0:
            raise ConfigError(f"max_readjustments must be an integer >= 0, got {m!r}")
        if not isinstance(self.carry_readjustments, bool | np.bool_):
            raise ConfigError(f"carry_readjustments must be True or False, got "
                              f"{self.carry_readjustments!r}")
        object.__setattr__(self, "readjust_threshold_kpa", readjust)
        object.__setattr__(self, "safety_threshold_kpa", safety)
        object.__setattr__(self, "max_readjustments", int(m))
        object.__setattr__(self, "increment", _per_finger("increment", self.increment, n))
        object.__setattr__(self, "max_torque_nm",
                           _per_finger("max_torque_nm", self.max_torque_nm, n))
        object.__setattr__(self, "carry_readjustments", bool(self.carry_readjustments))

    @property
    def n_fingers(self) -> int:
        """Number of fingers (length of every per-finger field)."""
        return len(self.readjust_threshold_kpa)


class Decision(NamedTuple):
    """One decision of Algorithm 1 within a tick.

    Attributes:
        line: line of Algorithm 1 it executed (:data:`ACTIONS`).
        action: one of :data:`ACTIONS`.
        i: trajectory step, 0-based.
        f: finger, 0-based (-1 for the whole hand: ``move``, ``wait``, ``done``).
        num_readjust: ``numReadjust`` of finger ``f`` after the decision (0 for ``f = -1``).
        p_kpa: the pressure of finger ``f`` it used [kPa] (NaN when none).
        torque_nm: the torque of finger ``f`` it used [N m] (NaN when none).
    """

    line: int
    action: str
    i: int
    f: int
    num_readjust: int
    p_kpa: float
    torque_nm: float


class TactileStep(NamedTuple):
    """What one tick returns.

    Attributes:
        targets: (nFingers,) finger targets to command, units of the trajectory (held as
            they were after ``stop`` or ``done``).
        decisions: the decisions of this tick, in order (empty once stopped or done).
        state: the state after the tick (:data:`STATES`).
    """

    targets: np.ndarray
    decisions: tuple[Decision, ...]
    state: str

    @property
    def action(self) -> str:
        """The last action of the tick ("" when none)."""
        return self.decisions[-1].action if self.decisions else ""


class TactileController:
    """pomares2011 Algorithm 1, one tick per tactile reading (30 Hz).

    Args:
        config: thresholds, readjustment limits and increments.
        trajectory: (nSteps, nFingers) planned finger targets ``JointTrajectory[i][f]``,
            units of the trajectory (one motor angle per finger), nSteps >= 1.
    """

    def __init__(self, config: TactileControlConfig, trajectory: np.ndarray) -> None:
        traj = np.asarray(trajectory, dtype=float)
        n = config.n_fingers
        if traj.ndim != 2 or traj.shape[0] < 1 or traj.shape[1] != n:
            raise ConfigError(f"trajectory must have shape (nSteps >= 1, nFingers = {n}), "
                              f"got {traj.shape}")
        if not np.isfinite(traj).all():
            raise ConfigError(f"trajectory must be finite; non-finite entries at "
                              f"{np.argwhere(~np.isfinite(traj)).tolist()}")
        self.config = config
        self.trajectory = traj
        self._readjust = np.array(config.readjust_threshold_kpa)
        self._safety = np.array(config.safety_threshold_kpa)
        self._increment = np.array(config.increment, dtype=float)
        self._max_torque = np.array(config.max_torque_nm, dtype=float)
        self.state = "start"
        self.i = -1  # trajectory step being executed (-1: none sent yet)
        self.f = -1  # finger being checked (-1: none)
        self.targets = traj[0].copy()  # nothing sent before the first tick
        self.num_readjust = np.zeros(n, dtype=int)  # numReadjust per finger, this step
        self.offset = np.zeros(n)  # increments added to the trajectory's targets
        self.steps_sent = 0
        self.n_readjust = np.zeros(n, dtype=int)  # readjustments executed (line 7)
        self.n_blocked = np.zeros(n, dtype=int)  # readjustments skipped: torque (line 7)
        self.n_give_up = np.zeros(n, dtype=int)  # line 12 false after max readjustments
        self._last: Decision | None = None

    @property
    def finished(self) -> bool:
        """True once the task stopped (line 13) or the trajectory is done."""
        return self.state in ("stopped", "done")

    def _reading(self, name: str, a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=float).reshape(-1)
        n = self.config.n_fingers
        if a.shape != (n,):
            raise ValueError(f"{name} must have one value per finger ({n}), got {a.shape[0]}")
        if not np.isfinite(a).all():
            raise NonFiniteInputError(f"{name} must be finite, got {a.tolist()}")
        return a

    def _decide(self, out: list[Decision], action: str, f: int = -1,
                p: float = math.nan, tau: float = math.nan) -> None:
        d = Decision(_LINE[action], action, self.i, f,
                     int(self.num_readjust[f]) if f >= 0 else 0, float(p), float(tau))
        out.append(d)
        self._last = d

    def _move(self, i: int, out: list[Decision]) -> None:
        """Lines 1-4: start step ``i``: send its angles to all fingers, check finger 0 next."""
        self.i = i
        if not self.config.carry_readjustments:
            self.offset[:] = 0.0  # line 2, literal: the trajectory's angles
        # ours (carry_readjustments): the increments so far stay on top of the trajectory.
        self.targets = self.trajectory[i] + self.offset  # line 2
        self.steps_sent += 1
        self.num_readjust[:] = 0  # line 4 (every finger of this step starts at 0)
        self.f = 0  # line 3
        self.state = "check"
        self._decide(out, "move")

    def step(self, pressure_kpa: np.ndarray, torque_nm: np.ndarray, settled: bool = True
             ) -> TactileStep:
        """One tick of Algorithm 1 with the latest tactile reading.

        Args:
            pressure_kpa: (nFingers,) maximum contact pressure of each finger over its
                tactile arrays [kPa] (line 5).
            torque_nm: (nFingers,) joint torque of each finger [N m] (the motor's, or the
                largest ``|tau|`` over the finger's joints), for line 7.
            settled: False while the previous command is still moving the fingers: the
                tick only waits (``wait``), the reading is not used.

        Returns:
            The targets to command, this tick's decisions and the new state.

        Raises:
            NonFiniteInputError: a pressure or torque is NaN or inf.
            ValueError: not one value per finger.
        """
        p = self._reading("pressure_kpa", pressure_kpa)
        tau = self._reading("torque_nm", torque_nm)
        out: list[Decision] = []
        self._last = None
        if self.state == "start":
            self._move(0, out)  # line 1-2: i = 1 (0-based 0), before any reading
        elif self.state == "check":
            if not settled:
                self._decide(out, "wait")
            else:
                self._check(p, tau, out)
        return TactileStep(self.targets.copy(), tuple(out), self.state)

    def _check(self, p: np.ndarray, tau: np.ndarray, out: list[Decision]) -> None:
        """Lines 5-16 with one reading, until the tick must wait or the task ends."""
        cfg = self.config
        n_max = cfg.max_readjustments
        while True:
            f = self.f
            pf, tf = float(p[f]), float(tau[f])  # line 5
            if pf < self._readjust[f] and self.num_readjust[f] < n_max:  # line 6
                if abs(tf) <= self._max_torque[f]:  # line 7: torque allows
                    self.targets[f] += self._increment[f]  # line 7
                    self.offset[f] += self._increment[f]
                    self.n_readjust[f] += 1
                    action = "readjust"
                else:  # line 7: torque over the maximum, increment skipped
                    self.n_blocked[f] += 1
                    action = "readjust_blocked_torque"
                # ours: line 8 counts a skipped readjustment too (it is outside line 7's
                # condition), so a finger blocked by its torque cannot loop forever.
                self.num_readjust[f] += 1  # line 8
                self._decide(out, action, f, pf, tf)
                return  # line 10: goto line 5, i.e. wait for the next reading
            # line 12, as the paper writes it; with safety <= readjust (the config checks it)
            # "line 6 false and p < safety" already implies numReadjust == max.
            if pf < self._safety[f] and self.num_readjust[f] == n_max:  # line 12
                self.state = "stopped"
                self._decide(out, "stop", f, pf, tf)  # line 13: end the manipulation task
                return
            if pf < self._readjust[f]:  # numReadjust == max, p >= safety
                self.n_give_up[f] += 1
                self._decide(out, "give_up_continue", f, pf, tf)
            else:
                self._decide(out, "ok", f, pf, tf)
            if f + 1 < cfg.n_fingers:  # line 15: next finger
                self.f = f + 1
                self.num_readjust[self.f] = 0  # line 4
                continue
            if self.i + 1 < self.trajectory.shape[0]:  # line 16: next step
                self._move(self.i + 1, out)
                return
            self.f = -1
            self.state = "done"  # line 16: all steps executed
            self._decide(out, "done")
            return

    def log_row(self) -> dict[str, Any]:
        """The state after the last tick, one scalar per field of :data:`LOG_FIELDS`."""
        row: dict[str, Any] = {
            "tactile_state": self.state,
            "tactile_action": self._last.action if self._last else "",
            "tactile_line": self._last.line if self._last else 0,
            "tactile_step": self.i,
            "tactile_finger": self.f,
            "tactile_steps_sent": self.steps_sent,
        }
        per_finger = {"tactile_target{i}": self.targets,
                      "tactile_num_readjust{i}": self.num_readjust,
                      "tactile_n_readjust{i}": self.n_readjust,
                      "tactile_n_blocked{i}": self.n_blocked,
                      "tactile_n_give_up{i}": self.n_give_up}
        for name, values in per_finger.items():
            for k, v in enumerate(values):
                row[name.replace("{i}", str(k + 1))] = v.item()
        return row
