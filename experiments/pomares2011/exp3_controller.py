"""pomares2011 experiment 3: the controller (closing, support, manipulation under
Algorithm 1, stop)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from experiments.pomares2011.exp3_audit import FingerTorques, hand_joint_values
from experiments.pomares2011.exp3_config import (
    BREAKAWAY_DETECT_RAD,
    DT,
    FINGERS,
    N_FINGERS,
    Exp3Config,
    planned_dy,
)
from repro.control.tactile_control import (
    LOG_FIELDS,
    TactileControlConfig,
    TactileController,
)
from repro.errors import ConfigError
from repro.sensors.tactile import (
    TactileReading,
)
from repro.sim import barrett as B
from repro.sim.episode import Observation, StepResult

# ============================================================================ controller


class Exp3Controller:
    """Closing, then the planned trajectory under Algorithm 1 (or open loop); the episode
    runner's controller (``__call__``). Reads only the tactile pads, the finger torques and
    the measured joints; no simulator inside.

    Args:
        config: the experiment.
        preshape: (3,) motor angles of the pre-shape [rad] (the fingers' start).
        plan: (n_steps + 1, 3) the planner's contact motor angles [rad]; the trajectory is the
            grasp's motor targets plus ``plan - plan[0]``.
    """

    def __init__(self, config: Exp3Config, preshape: np.ndarray, plan: np.ndarray,
                 hand_body: str = "hand", hand_idx: np.ndarray | None = None,
                 start: np.ndarray | None = None, preshape_rate: float = 0.0,
                 hand_columns: bool = True) -> None:
        self.config = config
        self.plan = np.asarray(plan, dtype=float)
        self.dy = planned_dy(config)
        #: the body whose q holds the hand's joints, and their positions in it
        self.hand_body = hand_body
        self.hand_idx = (np.arange(len(B.BH8_JOINTS)) if hand_idx is None
                         else np.asarray(hand_idx))
        self.preshape = np.asarray(preshape, dtype=float).copy()
        #: the pre-shaping speed of every motor [rad/s] (phase ``preshape``)
        self.preshape_rate = float(preshape_rate)
        #: write ``hand_q{i}`` (False: the runner logs the hand's joints, a joint group)
        self.hand_columns = hand_columns
        if start is None:  # experiment 3: the fingers start pre-shaped, closing
            self.targets, self.phase = self.preshape.copy(), "closing"
        else:  # the whole task: the fingers hold ``start`` until begin()
            self.targets, self.phase = np.asarray(start, dtype=float).copy(), "waiting"
            if self.preshape_rate <= 0.0:
                raise ConfigError("a hand that starts elsewhere needs preshape_rate > 0")
        self.closed = np.zeros(N_FINGERS, dtype=bool)
        self.t_grasp: float | None = None
        self.t_manipulation: float | None = None
        self.t_end: float | None = None
        self.trajectory: np.ndarray | None = None
        self.tactile: TactileController | None = None
        self.step_i = -1  # open loop: trajectory step last sent
        self.closing_rate = B.J2_RATIO * math.radians(config.closing_speed_deg_s)  # [rad/s]
        self.tactile_cfg = TactileControlConfig(
            readjust_threshold_kpa=tuple(config.readjust_threshold_kpa),
            safety_threshold_kpa=tuple(config.safety_threshold_kpa),
            max_readjustments=config.max_readjustments,
            increment=B.counts_to_motor_angle(config.increment_counts),
            max_torque_nm=config.max_torque_nm,
            carry_readjustments=config.carry_readjustments)
        self.broken = np.zeros(N_FINGERS, dtype=bool)
        #: Every tactile sample: (t [s], {pad: reported pressures [kPa]}) (pressure_images.npz).
        self.samples: list[tuple[float, dict[str, np.ndarray]]] = []
        #: Chosen instants for the pressure images: name -> time [s].
        self.instants: dict[str, float] = {}

    def begin(self, t: float, events: list[tuple[str, str]]) -> None:
        """End of the approach (the whole task): pre-shape, then close."""
        if self.phase != "waiting":
            raise ConfigError(f"begin() in phase {self.phase!r}: the hand has already begun")
        self.phase = "preshape"
        self.instants["hand_start"] = t
        events.append(("hand_preshape", f"fingers move from {np.round(self.targets, 2).tolist()}"
                       f" to the pre-shape {np.round(self.preshape, 2).tolist()} rad of motor"))

    @property
    def manipulating(self) -> bool:
        return self.phase == "manipulation"

    @property
    def t_support(self) -> float | None:
        """When the support starts going down [s] (None: not yet)."""
        return None if self.t_grasp is None else self.t_grasp + self.config.support_delay_s

    def support_offset(self, t: float) -> float:
        """How far the support has been lowered at ``t`` [m]."""
        t0 = self.t_support
        if t0 is None or t <= t0:
            return 0.0
        return min(self.config.support_drop_m, (t - t0) * self.config.support_speed_m_s)

    @staticmethod
    def finger_pressures(r: TactileReading) -> np.ndarray:
        """Algorithm 1's p of each finger: the max over its proximal and distal pads [kPa]."""
        return np.array([max(r.pads[f"finger{k}_proximal"].p_max,
                             r.pads[f"finger{k}_distal"].p_max) for k in FINGERS])

    def _start_manipulation(self, t: float, events: list[tuple[str, str]]) -> None:
        self.phase = "manipulation"
        self.t_manipulation = t
        self.instants["manipulation_start"] = t
        self.trajectory = self.targets[None, :] + self.plan - self.plan[0]
        if self.config.tactile_control:
            self.tactile = TactileController(self.tactile_cfg, self.trajectory)
        events.append(("manipulation_start", f"{self.config.n_steps} steps, planned "
                       f"translation {self.config.translation_m * 1e3:.1f} mm towards fingers "
                       f"1-2; tactile control {'on' if self.config.tactile_control else 'off'}"))

    def _end(self, t: float, phase: str, events: list[tuple[str, str]], kind: str,
             detail: str) -> None:
        self.phase, self.t_end = phase, t
        self.instants[phase] = t
        events.append((kind, detail))

    def __call__(self, obs: Observation) -> StepResult:
        cfg, t = self.config, obs.t
        reading: TactileReading = obs.sensors["tactile"]
        torque: FingerTorques = obs.sensors["finger_torque"]
        q_hand = obs.q[self.hand_body][self.hand_idx]
        events: list[tuple[str, str]] = []
        p_f = self.finger_pressures(reading)
        if reading.new:
            self.samples.append((float(reading.t), {n: r.pressure.astype(np.float32)
                                                     for n, r in reading.pads.items()}))
        q_p = q_hand[[B.BH8_JOINTS.index(j) for j in B.BH8_PROXIMAL_JOINTS]]
        q_d = q_hand[[B.BH8_JOINTS.index(j) for j in B.BH8_DISTAL_JOINTS]]
        broken = (q_d - q_p / 3.0) > BREAKAWAY_DETECT_RAD
        for k in np.flatnonzero(broken & ~self.broken):
            events.append(("breakaway", f"finger {k + 1}: distal {math.degrees(q_d[k]):.2f} deg "
                           f"> proximal / 3 = {math.degrees(q_p[k]) / 3:.2f} deg (TorqueSwitch "
                           "broke away)"))
        self.broken = broken
        decisions: dict[int, tuple[str, float, int]] = {}
        tick = False
        if self.phase == "preshape":
            step = self.preshape_rate * DT
            self.targets = self.targets + np.clip(self.preshape - self.targets, -step, step)
            if np.array_equal(self.targets, self.preshape):
                self.phase = "closing"
                events.append(("preshape_done", "fingers pre-shaped: automatic closing"))
        elif self.phase == "closing":
            if reading.new:
                grasp = np.asarray(cfg.grasp_kpa, dtype=float)
                for f in np.flatnonzero(~self.closed & ((p_f >= grasp) | broken)):
                    self.closed[f] = True
                    events.append(("finger_closed", f"finger {f + 1} stops closing: p = "
                                   f"{p_f[f]:.1f} kPa{' (broken away)' if broken[f] else ''}"))
            self.targets = self.targets + np.where(self.closed, 0.0, self.closing_rate * DT)
            if self.closed.all():
                self.phase, self.t_grasp = "support", t
                self.instants["grasp"] = t
                events.append(("grasp_closed", f"every finger presses the cylinder (p = "
                               f"{np.round(p_f, 1).tolist()} kPa); support lowered from "
                               f"t = {t + cfg.support_delay_s:.3f} s"))
        elif self.phase == "support":
            assert self.t_support is not None
            t_go = (self.t_support + cfg.support_drop_m / cfg.support_speed_m_s + cfg.settle_s)
            if reading.new and t >= t_go:
                self._start_manipulation(t, events)
        if self.manipulating and reading.new:
            tick = True
            assert self.trajectory is not None
            if self.tactile is not None:
                # ours: settled=True: a step (<= MAX_STEP_M of translation, a few tenths of a
                # motor radian) or an increment is done by the motor well within the 33 ms tick
                # (trapezoid: 0.3 rad in 14 ms), so the reading never sees a moving command.
                res = self.tactile.step(p_f, torque.finger, settled=True)
                self.targets = res.targets
                self.step_i = self.tactile.i
                for d in res.decisions:
                    if d.f >= 0:
                        decisions[d.f] = (d.action, d.p_kpa, d.num_readjust)
                    if d.action in ("readjust", "readjust_blocked_torque"):
                        self.instants.setdefault(f"first_readjust{d.f + 1}", t)
                    if d.action == "readjust_blocked_torque":
                        events.append(("readjust_blocked_torque", f"finger {d.f + 1}: |tau| = "
                                       f"{d.torque_nm:.3f} N m > {cfg.max_torque_nm} N m at step "
                                       f"{d.i}: increment skipped (line 7)"))
                    if d.action == "give_up_continue":
                        events.append(("readjust_give_up", f"finger {d.f + 1}: p = "
                                       f"{d.p_kpa:.1f} kPa after {d.num_readjust} readjustments "
                                       f"at step {d.i}, >= safety: next finger (line 12)"))
                if res.state == "stopped":
                    d = res.decisions[-1]
                    self._end(t, "stopped", events, "tactile_stop",
                              f"line 13: finger {d.f + 1} p = {d.p_kpa:.1f} kPa < safety "
                              f"{cfg.safety_threshold_kpa[d.f]} kPa after {d.num_readjust} "
                              f"readjustments at step {d.i} of {cfg.n_steps}")
                elif res.state == "done":
                    self._end(t, "done", events, "trajectory_done", f"all {cfg.n_steps + 1} "
                              "steps executed under Algorithm 1")
            else:  # the ablation: one step per tick, no check
                if self.step_i < cfg.n_steps:
                    self.step_i += 1
                    self.targets = self.trajectory[self.step_i].copy()
                else:
                    self._end(t, "done", events, "trajectory_done", f"all {cfg.n_steps + 1} "
                              "steps executed open loop (no tactile control)")
        stop = None
        if self.t_end is not None and t >= self.t_end + cfg.hold_s:
            stop = ("task_end", f"task {self.phase} at t = {self.t_end:.3f} s, held "
                    f"{cfg.hold_s} s")
            self.instants["end"] = t
        return StepResult({"fingers": self.targets.copy()},
                          self._columns(obs, p_f, torque, decisions, tick), events, stop)

    def _columns(self, obs: Observation, p_f: np.ndarray, torque: FingerTorques,
                 decisions: Mapping[int, tuple[str, float, int]], tick: bool
                 ) -> dict[str, float | int | str | bool]:
        reading: TactileReading = obs.sensors["tactile"]
        cols: dict[str, float | int | str | bool] = {"phase": self.phase, "tick": tick}
        if self.hand_columns:
            cols.update(hand_joint_values(obs.q[self.hand_body][self.hand_idx]))
        for i in range(N_FINGERS):
            cols[f"counts{i + 1}"] = B.motor_angle_to_counts(float(obs.q["fingers"][i]))
            cols[f"cmd_counts{i + 1}"] = B.motor_angle_to_counts(float(self.targets[i]))
            cols[f"p{i + 1}"] = float(p_f[i])
            cols[f"closed{i + 1}"] = bool(self.closed[i])
            cols[f"broken_away{i + 1}"] = bool(self.broken[i])
            action, p_used, num = decisions.get(i, ("", float("nan"), -1))
            cols[f"alg_decision{i + 1}"] = action
            cols[f"alg_p{i + 1}"] = float(p_used)
            cols[f"alg_num_readjust{i + 1}"] = int(num)
        cols["Fmap_total"] = float(sum(r.force_map for r in reading.pads.values()))
        cols["plan_step"] = int(self.step_i)
        cols["plan_dy"] = float(self.dy[self.step_i]) if self.step_i >= 0 else float("nan")
        if self.tactile is not None:
            cols.update(self.tactile.log_row())
        else:
            off = not self.config.tactile_control and self.t_manipulation is not None
            cols.update(_idle_log_row("off" if off else "start"))
        return cols


def _idle_log_row(state: str) -> dict[str, Any]:
    """The Algorithm-1 columns while no TactileController runs (before the manipulation, or
    the ablation: state ``off``)."""
    row: dict[str, Any] = {"tactile_state": state, "tactile_action": "", "tactile_line": 0,
                           "tactile_step": -1, "tactile_finger": -1, "tactile_steps_sent": 0}
    for name in LOG_FIELDS:
        if "{i}" in name:
            for k in FINGERS:
                row[name.replace("{i}", str(k))] = float("nan") if "target" in name else 0
    return row


# ============================================================================ scene, run
#: What ``pressure_images.npz`` holds (also written to scene.json).
