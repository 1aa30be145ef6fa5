"""Tests of repro.control.tactile_control (pomares2011 Sec. 6, Algorithm 1): scripted
pressure sequences for every branch of the pseudo-code (walk, readjust, stop, give up and
continue, torque-blocked readjustment, per-finger thresholds, per-step reset of
numReadjust), the config validation, and a seeded property test against a line-by-line
transcription of Algorithm 1 as a Python generator."""

from __future__ import annotations

from collections.abc import Callable, Generator

import numpy as np
import pytest

from repro.control.tactile_control import (
    ACTIONS,
    LOG_FIELDS,
    PAPER_READJUST_THRESHOLD_KPA,
    PAPER_SAFETY_THRESHOLD_KPA,
    STATES,
    TactileControlConfig,
    TactileController,
    TactileStep,
)
from repro.errors import ConfigError, NonFiniteInputError

INC = 0.01  # readjustment increment [rad] of these tests
TMAX = 2.0  # maximum allowable torque [N m] of these tests
#: A 4-step trajectory of 3 finger motors [rad], every entry different.
TRAJ = np.array([[0.50, 0.60, 0.70],
                 [0.52, 0.63, 0.74],
                 [0.54, 0.66, 0.78],
                 [0.56, 0.69, 0.82]])
HIGH = 30.0  # kPa, above every paper threshold
ZERO_TAU = np.zeros(3)


def _cfg(**kw: object) -> TactileControlConfig:
    base: dict[str, object] = {"max_readjustments": 3, "increment": INC, "max_torque_nm": TMAX}
    base.update(kw)
    return TactileControlConfig(**base)  # type: ignore[arg-type]


Plant = Callable[[TactileController], tuple[np.ndarray, np.ndarray]]


def _run(ctrl: TactileController, plant: Plant, max_ticks: int = 200) -> list[TactileStep]:
    """Tick ``ctrl`` with ``plant(ctrl) -> (pressure, torque)`` until it finishes."""
    out = []
    for _ in range(max_ticks):
        out.append(ctrl.step(*plant(ctrl)))
        if ctrl.finished:
            return out
    raise AssertionError(f"not finished after {max_ticks} ticks: {ctrl.log_row()}")


def _actions(ticks: list[TactileStep]) -> list[tuple[str, int, int]]:
    return [(d.action, d.i, d.f) for t in ticks for d in t.decisions]


def _contact_plant(base: dict[int, float], gain: float = 400.0, tau: np.ndarray = ZERO_TAU
                   ) -> Plant:
    """Fingers blocked by the object: the pressure of finger f rises by ``gain`` [kPa/rad]
    with its target above the trajectory's (``base[f]`` kPa at the trajectory's angle);
    unlisted fingers read HIGH."""
    def plant(ctrl: TactileController) -> tuple[np.ndarray, np.ndarray]:
        i = max(ctrl.i, 0)
        p = np.full(3, HIGH)
        for f, b in base.items():
            p[f] = b + gain * (ctrl.targets[f] - TRAJ[i, f])
        return p, tau
    return plant


# ----------------------------------------------------------------------------- (a)
def test_all_above_thresholds_walks_the_trajectory_one_step_per_tick() -> None:
    ctrl = TactileController(_cfg(), TRAJ)
    ticks = _run(ctrl, lambda c: (np.full(3, HIGH), ZERO_TAU))
    assert len(ticks) == len(TRAJ) + 1  # one move per tick, then "done"
    for k, t in enumerate(ticks[:-1]):
        assert t.action == "move" and t.decisions[-1].i == k
        np.testing.assert_array_equal(t.targets, TRAJ[k])
        checks = [d.action for d in t.decisions[:-1]]
        assert checks == ([] if k == 0 else ["ok", "ok", "ok"])  # line 2 before any reading
    assert ticks[-1].state == "done" and [d.action for d in ticks[-1].decisions] == [
        "ok", "ok", "ok", "done"]
    assert ctrl.steps_sent == len(TRAJ) and ctrl.n_readjust.sum() == 0
    # After the end: commands held, nothing decided.
    later = ctrl.step(np.zeros(3), ZERO_TAU)
    assert later.decisions == () and later.state == "done"
    np.testing.assert_array_equal(later.targets, TRAJ[-1])


# ----------------------------------------------------------------------------- (b)
@pytest.mark.parametrize("carry", [False, True])
def test_two_readjustments_raise_one_finger_then_continue(carry: bool) -> None:
    # Finger 2 (f = 1) at step 0: 5 kPa, +4 kPa per increment -> 5, 9, 13 kPa.
    plant0 = _contact_plant({1: 5.0})
    ctrl = TactileController(_cfg(carry_readjustments=carry), TRAJ)

    def plant(c: TactileController) -> tuple[np.ndarray, np.ndarray]:
        return plant0(c) if c.i <= 0 else (np.full(3, HIGH), ZERO_TAU)

    ticks = _run(ctrl, plant)
    acts = _actions(ticks)
    readjusts = [a for a in acts if a[0] == "readjust"]
    assert readjusts == [("readjust", 0, 1), ("readjust", 0, 1)]
    assert acts[:6] == [("move", 0, -1), ("ok", 0, 0), ("readjust", 0, 1),
                        ("readjust", 0, 1), ("ok", 0, 1), ("ok", 0, 2)]
    assert acts[6] == ("move", 1, -1)
    np.testing.assert_allclose(ticks[2].targets, TRAJ[0] + [0.0, 2 * INC, 0.0])
    np.testing.assert_array_equal(ticks[2].targets[[0, 2]], TRAJ[0, [0, 2]])
    assert [d.num_readjust for d in ticks[1].decisions + ticks[2].decisions] == [0, 1, 2]
    # Next step: line 2 literal (the trajectory's angles) or the increments carried.
    np.testing.assert_allclose(ticks[3].targets, TRAJ[1] + (
        [0.0, 2 * INC, 0.0] if carry else 0.0))
    assert ticks[-1].state == "done"
    assert ctrl.n_readjust.tolist() == [0, 2, 0]
    row = ctrl.log_row()
    assert row["tactile_n_readjust2"] == 2 and row["tactile_n_readjust1"] == 0
    assert row["tactile_state"] == "done" and row["tactile_steps_sent"] == len(TRAJ)


# ----------------------------------------------------------------------------- (c)
def test_below_safety_after_max_readjustments_stops_and_holds() -> None:
    ctrl = TactileController(_cfg(max_readjustments=3), TRAJ)
    ticks = _run(ctrl, lambda c: (np.array([3.0, HIGH, HIGH]), ZERO_TAU))
    assert [t.action for t in ticks] == ["move", "readjust", "readjust", "readjust", "stop"]
    stop = ticks[-1].decisions[-1]
    assert (stop.line, stop.i, stop.f, stop.num_readjust, stop.p_kpa) == (13, 0, 0, 3, 3.0)
    held = TRAJ[0] + [3 * INC, 0.0, 0.0]
    np.testing.assert_allclose(ticks[-1].targets, held)
    for _ in range(5):  # high pressures now: still nothing sent (line 13 returned)
        t = ctrl.step(np.full(3, HIGH), ZERO_TAU)
        assert t.decisions == () and t.state == "stopped"
        np.testing.assert_allclose(t.targets, held)
    assert ctrl.steps_sent == 1 and ctrl.i == 0
    assert ctrl.log_row()["tactile_state"] == "stopped"


def test_stop_at_a_later_step_sends_no_further_steps() -> None:
    ctrl = TactileController(_cfg(max_readjustments=2), TRAJ)

    def plant(c: TactileController) -> tuple[np.ndarray, np.ndarray]:
        return np.array([HIGH, HIGH, 4.0 if c.i == 2 else HIGH]), ZERO_TAU

    ticks = _run(ctrl, plant)
    moves = [a for a in _actions(ticks) if a[0] == "move"]
    assert moves == [("move", 0, -1), ("move", 1, -1), ("move", 2, -1)]
    assert ticks[-1].decisions[-1][:4] == (13, "stop", 2, 2)
    np.testing.assert_allclose(ticks[-1].targets, TRAJ[2] + [0, 0, 2 * INC])


# ----------------------------------------------------------------------------- (d)
def test_between_safety_and_readjust_after_max_readjustments_continues() -> None:
    # Finger 3: readjust 20 kPa, safety 10 kPa; 15 kPa whatever the readjustments.
    ctrl = TactileController(_cfg(max_readjustments=2), TRAJ[:2])
    ticks = _run(ctrl, lambda c: (np.array([HIGH, HIGH, 15.0]), ZERO_TAU))
    assert _actions(ticks) == [
        ("move", 0, -1), ("ok", 0, 0), ("ok", 0, 1), ("readjust", 0, 2),
        ("readjust", 0, 2), ("give_up_continue", 0, 2), ("move", 1, -1),
        ("ok", 1, 0), ("ok", 1, 1), ("readjust", 1, 2),
        ("readjust", 1, 2), ("give_up_continue", 1, 2), ("done", 1, -1)]
    assert ticks[-1].state == "done" and ctrl.n_give_up.tolist() == [0, 0, 2]
    give_up = [d for t in ticks for d in t.decisions if d.action == "give_up_continue"]
    assert all(d.line == 12 and d.num_readjust == 2 for d in give_up)


def test_zero_max_readjustments() -> None:
    # NUM_MAX_READJUSTMENTS = 0: line 6 never holds; line 12 decides at once.
    ctrl = TactileController(_cfg(max_readjustments=0), TRAJ)
    ticks = _run(ctrl, lambda c: (np.array([HIGH, HIGH, 15.0]), ZERO_TAU))
    assert ticks[-1].state == "done" and ctrl.n_readjust.sum() == 0
    assert ctrl.n_give_up.tolist() == [0, 0, len(TRAJ)]
    ctrl = TactileController(_cfg(max_readjustments=0), TRAJ)
    ticks = _run(ctrl, lambda c: (np.array([9.0, HIGH, HIGH]), ZERO_TAU))
    assert [t.action for t in ticks] == ["move", "stop"]


# ----------------------------------------------------------------------------- (e)
def test_torque_over_max_skips_the_readjustment_and_terminates() -> None:
    tau = np.array([TMAX + 0.5, 0.0, -(TMAX + 0.5)])  # |tau| is compared
    ctrl = TactileController(_cfg(max_readjustments=3), TRAJ)
    ticks = _run(ctrl, lambda c: (np.array([HIGH, HIGH, 15.0]), tau))
    blocked = [d for t in ticks for d in t.decisions if d.action == "readjust_blocked_torque"]
    assert len(blocked) == 3 * len(TRAJ) and {d.f for d in blocked} == {2}
    assert [d.num_readjust for d in blocked[:3]] == [1, 2, 3]  # skipped ones count (ours)
    for t in ticks:  # no increment ever executed
        np.testing.assert_array_equal(t.targets, TRAJ[t.decisions[-1].i])
    assert ticks[-1].state == "done"
    assert ctrl.n_blocked.tolist() == [0, 0, 3 * len(TRAJ)] and ctrl.n_readjust.sum() == 0
    # Below safety and blocked: stops after the max (skipped) readjustments.
    ctrl = TactileController(_cfg(max_readjustments=3), TRAJ)
    ticks = _run(ctrl, lambda c: (np.array([2.0, HIGH, HIGH]), tau))
    assert [t.action for t in ticks] == ["move"] + ["readjust_blocked_torque"] * 3 + ["stop"]
    np.testing.assert_array_equal(ticks[-1].targets, TRAJ[0])


def test_torque_at_the_max_allows_and_dropping_torque_resumes() -> None:
    # Torque over the max on the first attempt only, then exactly at the max ("do not exceed").
    ctrl = TactileController(_cfg(max_readjustments=3), TRAJ[:1])
    seq = iter([TMAX + 1.0, TMAX + 1.0, TMAX, 0.0, 0.0, 0.0])
    ticks = _run(ctrl, lambda c: (np.array([5.0, HIGH, HIGH]),
                                  np.array([next(seq), 0.0, 0.0])))
    assert [t.action for t in ticks] == ["move", "readjust_blocked_torque", "readjust",
                                         "readjust", "stop"]
    np.testing.assert_allclose(ticks[-1].targets, TRAJ[0] + [2 * INC, 0, 0])


# ----------------------------------------------------------------------------- (f)
def test_paper_thresholds_15_kpa_readjusts_finger_3_only() -> None:
    assert PAPER_READJUST_THRESHOLD_KPA == (10.0, 10.0, 20.0)
    assert PAPER_SAFETY_THRESHOLD_KPA == (10.0, 10.0, 10.0)
    cfg = TactileControlConfig(max_readjustments=2, increment=INC)  # paper thresholds
    ctrl = TactileController(cfg, TRAJ[:2])
    ticks = _run(ctrl, lambda c: (np.full(3, 15.0), ZERO_TAU))
    readjusted = {d.f for t in ticks for d in t.decisions if d.action == "readjust"}
    assert readjusted == {2}
    assert ctrl.n_readjust.tolist() == [0, 0, 4]
    assert ticks[1].decisions[0].action == "ok" and ticks[1].decisions[1].action == "ok"
    # 9 kPa is below fingers 1-2's threshold: finger 1 readjusts first.
    ctrl = TactileController(cfg, TRAJ[:2])
    ctrl.step(np.full(3, 9.0), ZERO_TAU)
    assert ctrl.step(np.full(3, 9.0), ZERO_TAU).decisions[-1][1:4] == ("readjust", 0, 0)


def test_thresholds_are_strict() -> None:
    # Lines 6 and 12 compare with "<": exactly at a threshold is enough.
    cfg = TactileControlConfig(max_readjustments=1, increment=INC)  # paper thresholds
    ctrl = TactileController(cfg, TRAJ[:1])
    ctrl.step(np.full(3, HIGH), ZERO_TAU)
    t = ctrl.step(np.array([10.0, 10.0, 20.0]), ZERO_TAU)
    assert [d.action for d in t.decisions] == ["ok", "ok", "ok", "done"]
    # Finger 3 exactly at the safety threshold after the max readjustments: continues.
    ctrl = TactileController(cfg, TRAJ[:1])
    ctrl.step(np.full(3, HIGH), ZERO_TAU)
    assert ctrl.step(np.array([HIGH, HIGH, 10.0]), ZERO_TAU).action == "readjust"
    assert [d.action for d in ctrl.step(np.array([HIGH, HIGH, 10.0]), ZERO_TAU).decisions
            ] == ["give_up_continue", "done"]


# ----------------------------------------------------------------------------- (g)
def test_num_readjust_resets_at_every_trajectory_step() -> None:
    ctrl = TactileController(_cfg(max_readjustments=2), TRAJ[:3])
    ticks = _run(ctrl, lambda c: (np.array([HIGH, HIGH, 15.0]), ZERO_TAU))
    decisions = [d for t in ticks for d in t.decisions]
    per_step = [sum(d.action == "readjust" and d.i == i for d in decisions) for i in range(3)]
    assert per_step == [2, 2, 2]  # without the reset, steps 1-2 would give up at once
    first = [d for t in ticks for d in t.decisions if d.action == "readjust"][::2]
    assert [d.num_readjust for d in first] == [1, 1, 1]
    # log_row shows numReadjust of the current step: back to 0 after each move.
    ctrl = TactileController(_cfg(max_readjustments=2), TRAJ[:3])
    plant = (np.array([HIGH, HIGH, 15.0]), ZERO_TAU)
    rows = []
    for _ in range(8):
        ctrl.step(*plant)
        rows.append(ctrl.log_row())
    assert [r["tactile_num_readjust3"] for r in rows] == [0, 1, 2, 0, 1, 2, 0, 1]
    assert [r["tactile_step"] for r in rows] == [0, 0, 0, 1, 1, 1, 2, 2]


# ----------------------------------------------------------------------------- settled
def test_unsettled_ticks_only_wait() -> None:
    ctrl = TactileController(_cfg(max_readjustments=3), TRAJ[:1])
    ctrl.step(np.full(3, HIGH), ZERO_TAU)  # move
    assert ctrl.step(np.array([5.0, HIGH, HIGH]), ZERO_TAU).action == "readjust"
    for _ in range(3):  # the finger is still moving: the (high) reading is not used
        t = ctrl.step(np.full(3, HIGH), ZERO_TAU, settled=False)
        assert t.action == "wait" and t.decisions[0].line == 5 and t.state == "check"
    assert ctrl.num_readjust[0] == 1 and ctrl.f == 0
    assert ctrl.step(np.array([5.0, HIGH, HIGH]), ZERO_TAU).action == "readjust"
    assert ctrl.step(np.full(3, HIGH), ZERO_TAU).action == "done"
    np.testing.assert_allclose(ctrl.targets, TRAJ[0] + [2 * INC, 0, 0])


# ----------------------------------------------------------------------------- (h)
@pytest.mark.parametrize(("kw", "message"), [
    ({"readjust_threshold_kpa": (10.0, -1.0, 20.0)}, "readjust_threshold_kpa[1]"),
    ({"readjust_threshold_kpa": (10.0, float("nan"), 20.0)}, "readjust_threshold_kpa[1]"),
    ({"readjust_threshold_kpa": (10.0, 10.0, float("inf"))}, "readjust_threshold_kpa[2]"),
    ({"readjust_threshold_kpa": ()}, "at least one finger"),
    ({"readjust_threshold_kpa": 10.0}, "one value per finger"),
    ({"safety_threshold_kpa": (10.0, 0.0, 10.0)}, "safety_threshold_kpa[1]"),
    ({"safety_threshold_kpa": (10.0, 10.0)}, "got 2"),
    ({"safety_threshold_kpa": (10.0, 10.0, 25.0)}, "must not exceed"),
    ({"max_readjustments": -1}, "-1"),
    ({"max_readjustments": 2.5}, "2.5"),
    ({"max_readjustments": True}, "True"),
    ({"increment": 0.0}, "increment[0]"),
    ({"increment": (0.01, 0.01)}, "increment must have one value per finger (3)"),
    ({"max_torque_nm": (1.0, "x", 1.0)}, "max_torque_nm[1]"),
    ({"max_torque_nm": float("nan")}, "max_torque_nm[0]"),
    ({"carry_readjustments": "yes"}, "carry_readjustments"),
])
def test_config_validation_names_the_bad_value(kw: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError) as err:
        _cfg(**kw)
    assert message in str(err.value)


def test_config_normalises_and_trajectory_and_readings_are_checked() -> None:
    cfg = _cfg(increment=(0.01, 0.02, 0.03), max_readjustments=np.int64(4))
    assert cfg.increment == (0.01, 0.02, 0.03) and cfg.max_torque_nm == (TMAX,) * 3
    assert cfg.max_readjustments == 4 and type(cfg.max_readjustments) is int
    assert _cfg(readjust_threshold_kpa=[12, 12], safety_threshold_kpa=[5, 5]).n_fingers == 2
    with pytest.raises(ConfigError, match=r"shape \(nSteps >= 1, nFingers = 3\)"):
        TactileController(cfg, TRAJ[:, :2])
    with pytest.raises(ConfigError, match="nSteps >= 1"):
        TactileController(cfg, np.zeros((0, 3)))
    with pytest.raises(ConfigError, match=r"\[\[1, 2\]\]"):
        TactileController(cfg, np.where(np.arange(12).reshape(4, 3) == 5, np.nan, TRAJ))
    ctrl = TactileController(cfg, TRAJ)
    with pytest.raises(NonFiniteInputError, match="pressure_kpa"):
        ctrl.step(np.array([1.0, np.nan, 1.0]), ZERO_TAU)
    with pytest.raises(NonFiniteInputError, match="torque_nm"):
        ctrl.step(np.ones(3), np.array([0.0, 0.0, np.inf]))
    with pytest.raises(ValueError, match="one value per finger"):
        ctrl.step(np.ones(2), ZERO_TAU)


def test_log_row_fields_are_the_declared_ones() -> None:
    ctrl = TactileController(_cfg(), TRAJ)
    expected = set()
    for name in LOG_FIELDS:
        expected |= ({name.replace("{i}", str(k)) for k in (1, 2, 3)} if "{i}" in name
                     else {name})
    row0 = ctrl.log_row()
    assert set(row0) == expected
    assert (row0["tactile_state"], row0["tactile_step"], row0["tactile_action"]) == (
        "start", -1, "")
    ctrl.step(np.full(3, HIGH), ZERO_TAU)
    ctrl.step(np.array([HIGH, 5.0, HIGH]), np.array([0.0, TMAX + 1, 0.0]))
    row = ctrl.log_row()
    assert (row["tactile_action"], row["tactile_line"], row["tactile_finger"]) == (
        "readjust_blocked_torque", 7, 1)
    assert row["tactile_n_blocked2"] == 1 and row["tactile_num_readjust2"] == 1
    assert row["tactile_target3"] == TRAJ[0, 2]
    assert all(isinstance(v, str | int | float) for v in row.values())
    assert set(STATES) >= {row["tactile_state"]} and row["tactile_action"] in ACTIONS


# ----------------------------------------------------------------------------- property
Reading = tuple[np.ndarray, np.ndarray]


def _algorithm1(traj: np.ndarray, cfg: TactileControlConfig, events: list[tuple[str, int, int]]
                ) -> Generator[np.ndarray, Reading, None]:
    """pomares2011 Algorithm 1 transcribed line by line; ``yield`` sends the targets and
    waits for the next (settled) reading."""
    thr, safe = cfg.readjust_threshold_kpa, cfg.safety_threshold_kpa
    inc, tau_max = np.asarray(cfg.increment), np.asarray(cfg.max_torque_nm)  # per finger
    offset = np.zeros(cfg.n_fingers)
    for i in range(len(traj)):  # 01
        if not cfg.carry_readjustments:
            offset[:] = 0.0
        targets = traj[i] + offset  # 02
        events.append(("move", i, -1))
        p, tau = yield targets.copy()
        for f in range(cfg.n_fingers):  # 03
            num = 0  # 04
            while p[f] < thr[f] and num < cfg.max_readjustments:  # 05-06, 10: goto 5
                if abs(tau[f]) <= tau_max[f]:  # 07
                    targets[f] += inc[f]
                    offset[f] += inc[f]
                    events.append(("readjust", i, f))
                else:
                    events.append(("readjust_blocked_torque", i, f))
                num += 1  # 08
                p, tau = yield targets.copy()
            if p[f] < safe[f] and num == cfg.max_readjustments:  # 12
                events.append(("stop", i, f))
                return  # 13
            events.append(("ok" if p[f] >= thr[f] else "give_up_continue", i, f))
    events.append(("done", len(traj) - 1, -1))


@pytest.mark.parametrize("seed", range(300))
def test_random_pressures_match_algorithm_1(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_steps = int(rng.integers(1, 6))
    cfg = TactileControlConfig(max_readjustments=int(rng.integers(0, 5)),
                               increment=tuple(rng.uniform(0.005, 0.02, 3)),
                               max_torque_nm=TMAX,
                               carry_readjustments=bool(rng.integers(2)))
    traj = np.cumsum(rng.uniform(0.0, 0.05, (n_steps, 3)), axis=0)
    ctrl = TactileController(cfg, traj)
    events: list[tuple[str, int, int]] = []
    ref = _algorithm1(traj, cfg, events)
    ref_targets: np.ndarray | None = None
    ref_done = False
    bound = 1 + n_steps * (1 + 3 * cfg.max_readjustments)  # settled ticks needed at most
    n_settled = 0
    mine: list[tuple[str, int, int]] = []
    thr, safe = np.array(cfg.readjust_threshold_kpa), np.array(cfg.safety_threshold_kpa)
    for _ in range(10 * bound + 50):
        # Low, between the thresholds, or high; torques sometimes over the max.
        p = rng.choice([rng.uniform(0, 10), rng.uniform(10, 20), rng.uniform(20, 40)], 3)
        p = np.where(rng.random(3) < 0.5, rng.uniform(0, 40, 3), p)
        tau = rng.uniform(-3.0, 3.0, 3)
        settled = ctrl.state == "start" or bool(rng.random() < 0.85)
        before = ctrl.num_readjust.copy()
        t = ctrl.step(p, tau, settled)
        mine += [(d.action, d.i, d.f) for d in t.decisions if d.action != "wait"]
        if settled:
            n_settled += 1
            try:
                ref_targets = next(ref) if ref_targets is None else ref.send((p, tau))
            except StopIteration:
                ref_done = True
        else:
            assert [d.action for d in t.decisions] == ["wait"]
        assert ref_targets is not None
        np.testing.assert_allclose(t.targets, ref_targets)
        # The invariants of lines 6 and 12 on this tick's decisions.
        for d in t.decisions:
            if d.f < 0:
                continue
            assert d.p_kpa == p[d.f] and d.torque_nm == tau[d.f]
            n_before = before[d.f] if d is t.decisions[0] else 0  # line 4 for the others
            if d.action.startswith("readjust"):
                assert d.num_readjust == n_before + 1
            line6 = p[d.f] < thr[d.f] and n_before < cfg.max_readjustments
            assert d.action.startswith("readjust") == line6
            if d.action == "stop":
                assert p[d.f] < safe[d.f] and d.num_readjust == cfg.max_readjustments
            if d.action == "readjust":
                assert abs(tau[d.f]) <= TMAX
            if d.action == "readjust_blocked_torque":
                assert abs(tau[d.f]) > TMAX
        if ctrl.finished:
            break
    assert ctrl.finished and ref_done, "did not terminate"
    assert n_settled <= bound
    assert mine == events
