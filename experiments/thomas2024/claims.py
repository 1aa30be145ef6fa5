"""thomas2024 claims 1-8 (shared/papers/README.md), each computed from trace files.

Tolerances that the paper does not state are ours and named here. Sensor numbers are ours
(sensor 1 on the ring frame's x axis, counter-clockwise; see discussion.md): the paper's
numbers are quoted, ours are reported, and only what does not depend on the numbering (which
ring, which side, when, how close) is judged.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from experiments.thomas2024.columns import N_JOINTS
from experiments.thomas2024.columns import N_SENSORS as N
from repro.runs.claims import Claim, ClaimResult, Clause
from repro.runs.metrics import (
    first_time_below,
    high_frequency_fraction,
    high_frequency_rms,
    sign_changes_per_second,
)
from repro.runs.trace import RunFiles

PAPER = "thomas2024"
NEAR_CONTACT = 0.01  # ours: "close to virtual contact" = CBF e_delta <= 1 cm
CONVERGED_FRACTION = 0.02  # ours: global convergence = ||e_4p|| below 2 % of its start
KAPPA_ZERO = 1e-4  # ours: a multiplier this small counts as 0 (active ones are 1e-2..1e-1)
U_SMALL = 0.05  # ours: "u -> 0" = final max |u| under 5 % of the run's peak max |u|
OSC_DEADBAND = 0.005  # ours: velocity sign changes count only beyond 5 mrad/s
OSC_CUTOFF_HZ = 2.0  # ours: "oscillation" energy above 2 Hz (the loop runs at 30 Hz)
HAND_EXCURSION_PX = 1.0  # ours: e_4p "leaves ~0" = rises by >= 1 px (5x the detection noise)
RETURN_PX = 3.0  # ours: "returns to ~0" = ||e|| under 3 px
NEAR_CONTACT_END = 2 * NEAR_CONTACT  # ours: "near virtual contact at the end" = final CBF <= 2 cm
TIME_TOL_S = 1.0  # ours: the paper's "~2.5 s", "around 4 s", "from around 5 s" read as +-1 s
OTHER_SIDE_DEG = 90.0  # ours: ring 2's "other side" = a sensor group >= 90 deg round the ring
CBF_ZERO_TOL = 0.01  # ours: "CBFs reach ~0" = the approached ring's min CBF within +-1 cm of 0
# thomas2024 Sec. V-A (Fig. 7): ring 2 {2,3,4,5} ~2.5 s, ring 1 {16,17} ~4 s, ring 2 {12,13} ~5 s
PAPER_T_RING2_FIRST, PAPER_T_RING1, PAPER_T_RING2_OTHER = 2.5, 4.0, 5.0
# thomas2024 Sec. V-C (Fig. 9): four hand approaches of ring 2 in 5-18 s, four of ring 1 in 20-30 s
HAND_WINDOWS = {2: (5.0, 18.0), 1: (20.0, 30.0)}
#: "at the end", "at convergence": a statistic over the last second, not the one row a stop
#: selects [s]. ours (issue 18): 30 control steps, longer than the loop's slowest settled mode
END_WINDOW_S = 1.0


def _e_px(run: RunFiles) -> np.ndarray:
    cols = [f"e{i}_{a}" for i in range(1, 5) for a in "uv"]
    return np.linalg.norm(run.trace[cols].to_numpy(dtype=float), axis=1)


def _cbf(df: pd.DataFrame, ring: int) -> pd.DataFrame:
    return df[[f"r{ring}_cbf{i}" for i in range(1, N + 1)]]


def _kappa_end(df: pd.DataFrame, ring: int) -> np.ndarray:
    return df[[f"r{ring}_kappa{i}" for i in range(1, N + 1)]].iloc[-1].to_numpy(dtype=float)


def _first_contacts(df: pd.DataFrame, ring: int) -> list[tuple[float, int]]:
    t = df["t"].to_numpy()
    out = []
    for i in range(1, N + 1):
        ft = first_time_below(t, df[f"r{ring}_cbf{i}"].to_numpy(), NEAR_CONTACT)
        if np.isfinite(ft):
            out.append((ft, i))
    return sorted(out)


def _groups(contacts: list[tuple[float, int]]) -> list[tuple[float, list[int]]]:
    """Sensors in near contact grouped by adjacency on the ring (cyclic)."""
    ids = sorted({i for _, i in contacts})
    first = {i: t for t, i in contacts}
    groups: list[list[int]] = []
    for i in ids:
        if groups and (i - groups[-1][-1]) <= 2:
            groups[-1].append(i)
        else:
            groups.append([i])
    if len(groups) > 1 and (groups[0][0] + N - groups[-1][-1]) <= 2:
        groups[0] = groups.pop() + groups[0]
    return sorted((min(first[i] for i in g), g) for g in groups)


def _fmt_groups(groups: list[tuple[float, list[int]]]) -> str:
    return "; ".join(f"{{{','.join(map(str, g))}}} at {t:.2f} s" for t, g in groups) or "none"


OURS_CONV = ("ours: 'converges' (Sec. V-A) has no figure; under 2 % of the start "
             "(~ the detection noise)")


# ------------------------------------------------------------------ claim 1
def _true_cbf(run: RunFiles) -> pd.DataFrame:
    """The noise-free CBFs of both rings, ``r{k}_dtrue{i} - delta*_k`` [m] (the trace's
    audit columns and the run's thresholds); the measured ``r{k}_cbf{i}`` where a trace has
    no ground truth."""
    df = run.trace
    thresholds = (run.manifest.get("config") or {}).get("thresholds") or (0.0, 0.0)
    out = {}
    for k in (1, 2):
        for i in range(1, N + 1):
            col = f"r{k}_dtrue{i}"
            out[f"r{k}_cbf{i}"] = (df[col] - float(thresholds[k - 1]) if col in df.columns
                                   else df[f"r{k}_cbf{i}"])
    return pd.DataFrame(out)


def check_1(runs: dict[str, RunFiles]) -> ClaimResult:
    """Sec. V-A: the visual task converges; Sec. III-B: a sensor that leaves the safe set
    (noise, model error) "is brought back to safety"; no collision. Judged on the noise-free
    CBFs (the statement is about the method); the measured ones are reported (issue 18: the
    old clause "every measured CBF >= -1 cm" was stricter than the text)."""
    run = runs["case1"]
    df = run.trace
    e = _e_px(run)
    e_final, e0 = e[-1], e[np.isfinite(e)][0]
    cbf = pd.concat([_cbf(df, 1), _cbf(df, 2)], axis=1)
    worst = cbf.min().idxmin()
    cbf_min = float(cbf[worst].min())
    t_worst = float(df["t"].iloc[int(np.argmin(cbf[worst].to_numpy()))])
    true = _true_cbf(run)
    t = df["t"].to_numpy(float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    outside = true.to_numpy(float) < 0.0
    deepest = float(np.nanmin(true.to_numpy(float)))
    longest = 0.0
    for j in range(outside.shape[1]):  # longest run of consecutive rows outside, per sensor
        run_len, best = 0, 0
        for flag in outside[:, j]:
            run_len = run_len + 1 if flag else 0
            best = max(best, run_len)
        longest = max(longest, best * dt)
    still_out = [c.replace("_cbf", " sensor ") for c in true.columns if true[c].iloc[-1] < 0.0]
    dmin = float(df["dist_min"].min())
    return ClaimResult.from_clauses(
        f"||e_4p|| {e0:.0f} -> {e_final:.1f} px; noise-free CBFs: deepest excursion out of the "
        f"safe set {deepest * 100:.2f} cm, longest {longest:.2f} s, still outside at the end "
        f"{still_out or 'none'}; measured CBFs (with the 2 mm noise): min {cbf_min * 100:.2f} "
        f"cm ({worst.replace('_cbf', ' sensor ')} at {t_worst:.2f} s); clearance (min true "
        f"distance) {dmin * 100:.2f} cm",
        [Clause(f"||e_4p|| under {CONVERGED_FRACTION:.0%} of its start", e_final / e0, "<=",
                CONVERGED_FRACTION, "-", OURS_CONV),
         Clause("every excursion out of the safe set is brought back (noise-free CBFs still "
                "< 0 at the end)", len(still_out), "<=", 0, "-", "paper: 'when the system "
                "leaves the safe set ... it is brought back to safety' (Sec. III-B)",
                relative=False),
         Clause("no contact (closest true distance)", dmin, ">", 0.0, "m",
                "paper: 'ensuring that the robotic platform does not collide' (abstract)",
                relative=False)])


# ------------------------------------------------------------------ claim 2
def check_2(runs: dict[str, RunFiles]) -> ClaimResult:
    df = runs["case1_no_proximity"].trace
    dcols = [c for c in df.columns if c.startswith("dist_") and c != "dist_min"]
    dmin = float(df["dist_min"].min())
    t_hit = first_time_below(df["t"].to_numpy(), df["dist_min"].to_numpy(), 0.0)
    which = min(dcols, key=lambda c: df[c].min())[5:]
    return ClaimResult.from_clauses(
        f"min true distance {dmin * 100:.2f} cm"
        + (f"; first contact with '{which}' at {t_hit:.2f} s" if dmin <= 0 else ""),
        [Clause("contact (closest true distance)", dmin, "<=", 0.0, "m",
                "paper: 'the robot arm collides with the obstacles' (Sec. V-A)",
                relative=False)])


# ------------------------------------------------------------------ claim 3
def _angle_deg(group: list[int]) -> float:
    """Direction [deg] of a sensor group on its ring (circular mean of its sensors' axes;
    sensor i at 360 (i - 1) / N deg, scene.py)."""
    a = 2 * np.pi * (np.asarray(group, float) - 1) / N
    return float(np.rad2deg(np.arctan2(np.sin(a).mean(), np.cos(a).mean())))


def _nearest_obstacle(df: pd.DataFrame, t: float) -> str:
    """The obstacle (``dist_<name>`` column) closest to the robot at time t [s]."""
    i = min(int(np.searchsorted(df["t"].to_numpy(), t)), len(df) - 1)
    dcols = [c for c in df.columns if c.startswith("dist_") and c != "dist_min"]
    return min(dcols, key=lambda c: df[c].iloc[i])[5:] if dcols else "?"


def _timed(label: str, t: float, paper: float) -> str:
    return f"{label} at {t:.2f} s (paper ~{paper:g} s)"


def check_3(runs: dict[str, RunFiles]) -> ClaimResult:
    run = runs["case1"]
    df = run.trace
    g2 = _groups(_first_contacts(df, 2))
    g1 = _groups(_first_contacts(df, 1))
    end1 = float(_cbf(df, 1).iloc[-1].min())
    end2 = float(_cbf(df, 2).iloc[-1].min())
    e = _e_px(run)
    e0 = e[np.isfinite(e)][0] if np.isfinite(e).any() else np.nan
    t2a = g2[0][0] if g2 else np.nan
    t1 = g1[0][0] if g1 else np.nan
    # ring 2's next group on the other side of the ring (>= OTHER_SIDE_DEG from the first)
    other = [(t, g) for t, g in g2[1:] if abs((_angle_deg(g) - _angle_deg(g2[0][1]) + 180)
                                                % 360 - 180) >= OTHER_SIDE_DEG]
    t2b = other[0][0] if other else np.nan
    obstacle = _nearest_obstacle(df, t2a) if g2 else "none"
    order = bool(g2 and g1 and other) and t2a < t1 <= t2b + 1e-9
    txt_a = _timed("ring 2 first", t2a, PAPER_T_RING2_FIRST)
    txt_1 = _timed("ring 1", t1, PAPER_T_RING1)
    txt_b = _timed("ring 2 other side", t2b, PAPER_T_RING2_OTHER)
    src = "paper: Sec. V-A (Fig. 7)"
    return ClaimResult.from_clauses(
        f"near contact (CBF <= {NEAR_CONTACT * 100:g} cm) first: {txt_a}, {txt_1}, {txt_b}; "
        f"ring 2 groups {_fmt_groups(g2)} (first meets '{obstacle}'); ring 1 groups "
        f"{_fmt_groups(g1)} (our sensor numbers; the paper's are {{2,3,4,5}}, {{16,17}}, "
        f"{{12,13}}); CBF at the end: ring 1 {end1 * 100:.1f} cm, ring 2 {end2 * 100:.1f} cm; "
        f"||e_4p|| {e0:.0f} -> {e[-1]:.1f} px",
        [Clause.flag("order ring 2, ring 1, ring 2 (other side)", order, src),
         Clause.flag("ring 2 first meets the right obstacle", obstacle == "right",
               "paper: 'encounters the obstacle on the right' (Sec. V-A)"),
         Clause("ring 2 first near contact, time off the paper's ~2.5 s",
                abs(t2a - PAPER_T_RING2_FIRST), "<=", TIME_TOL_S, "s",
                "ours: the paper's 'around' read as +-1 s"),
         Clause("ring 1 near contact, time off the paper's ~4 s", abs(t1 - PAPER_T_RING1), "<=",
                TIME_TOL_S, "s", "ours: the paper's 'around' read as +-1 s"),
         Clause("ring 2 other side, time off the paper's ~5 s", abs(t2b - PAPER_T_RING2_OTHER),
                "<=", TIME_TOL_S, "s", "ours: the paper's 'around' read as +-1 s"),
         Clause("both rings near contact at the end (larger of the two final min CBFs)",
                max(end1, end2), "<=", NEAR_CONTACT_END, "m",
                "ours: 'close to virtual contact in both rings till the end' has no figure"),
         Clause(f"converges (||e_4p|| under {CONVERGED_FRACTION:.0%} of its start)",
                e[-1] / e0, "<=", CONVERGED_FRACTION, "-", OURS_CONV)])


# ------------------------------------------------------------------ claim 4
CASE2_V_SENSORS = (4, 12)  # ours: case 2's V of boards faces ring-2 sensors 4 and 12 (scene.py)


def check_4(runs: dict[str, RunFiles]) -> ClaimResult:
    run = runs["case2"]
    df = run.trace
    stopped = "stop_lagrangian" in set(run.events["kind"]) if len(run.events) else False
    k2 = _kappa_end(df, 2)
    active = [int(i) + 1 for i in np.flatnonzero(k2 > KAPPA_ZERO)]
    contact_end = [i for i in range(1, N + 1) if df[f"r2_cbf{i}"].iloc[-1] <= NEAR_CONTACT]
    g1 = _groups(_first_contacts(df, 1))
    end1 = _cbf(df, 1).iloc[-1]
    s1 = int(str(end1.idxmin()).rsplit("cbf", 1)[1])
    cbf1_end = float(end1.min())
    u_abs = df[[f"u{i}" for i in range(1, N_JOINTS + 1)]].abs().max(axis=1).to_numpy(float)
    t = df["t"].to_numpy(float)
    # issue 18: "u -> 0" over the last second before the stop, not on the stop row alone
    u_end, u_peak = float(np.nanmax(u_abs[t >= t[-1] - END_WINDOW_S])), float(np.nanmax(u_abs))
    e_end = _e_px(run)[-1]
    t_contact = min((t for t, i in _first_contacts(df, 2) if i in contact_end), default=np.nan)
    return ClaimResult.from_clauses(
        f"stopped by the Lagrangian test: {stopped} at {df['t'].iloc[-1]:.2f} s with "
        f"||grad L|| = {df['grad_L0'].iloc[-1]:.4f}; ||e_4p|| = {e_end:.1f} px (local minimum); "
        f"ring-2 sensors in virtual contact at the end {contact_end} (from {t_contact:.2f} s; "
        f"the paper: {{4,12}} from ~8 s, time not compared: our V is placed by us), "
        f"kappa > 0 on {active} ({', '.join(f'{k2[i - 1]:.3f}' for i in active)}); "
        f"ring 1 closest to contact at the end: sensor {s1} at {cbf1_end * 100:.1f} cm (our "
        f"number; the paper's is 9), ring-1 near contact first: {_fmt_groups(g1)}; "
        f"max |u| over the last {END_WINDOW_S:g} s {u_end:.4f} rad/s ({u_end / u_peak:.1%} of "
        f"its peak; {u_abs[-1]:.4f} on the last row)",
        [Clause.flag("stopped by the Lagrangian test", stopped, "paper: 'stopped when the norm of "
               "gradient of Lagrangian ... falls below ... 0.01' (Sec. V-B)"),
         Clause("local (not global) minimum (final ||e_4p||)", e_end, ">", RETURN_PX, "px",
                "ours: above the 3 px 'returns to ~0' of claim 7"),
         Clause.flag(f"ring-2 sensors {CASE2_V_SENSORS} (facing the V) in virtual contact at the end",
               set(CASE2_V_SENSORS) <= set(contact_end), "paper: 'sensors {4, 12} on ring 2 "
               "being in virtual contact' (Sec. V-B); our numbering"),
         Clause.flag(">= 2 ring-2 multipliers > 0, all on sensors in contact", len(active) >= 2
               and set(active) <= set(contact_end), "paper: strict complementarity, kappa_k > 0 "
               "(Sec. VI)"),
         Clause("a ring-1 sensor near contact at the end (its final CBF)", cbf1_end, "<=",
                NEAR_CONTACT_END, "m", "ours: 'close to the situation of virtual contact' "
                "(Sec. V-B) has no figure"),
         Clause(f"u -> 0 (max |u| over the last {END_WINDOW_S:g} s over its peak)",
                u_end / u_peak, "<=", U_SMALL, "-",
                "ours: 'control input converging to very low value' (Sec. V-B) has no "
                "figure")])


# ------------------------------------------------------------------ claim 5
def _oscillation(run: RunFiles) -> tuple[float, float]:
    """(sign changes / s, high-frequency energy fraction) of the joint velocities after
    ring 2's first near contact."""
    df = run.trace
    t = df["t"].to_numpy()
    start = min((tt for tt, _ in _first_contacts(df, 2)), default=t[0])
    sel = t >= start
    dt = float(np.median(np.diff(t)))
    sc = [sign_changes_per_second(t[sel], df[f"u{i}"].to_numpy()[sel], OSC_DEADBAND)
          for i in range(1, N_JOINTS + 1)]
    hf = [high_frequency_fraction(df[f"u{i}"].to_numpy()[sel], dt, OSC_CUTOFF_HZ)
          for i in range(1, N_JOINTS + 1)]
    return float(np.mean(sc)), float(np.mean(hf))


def _hf_amplitude(run: RunFiles, t0: float, t1: float) -> float:
    """Mean over the joints of the RMS of u above OSC_CUTOFF_HZ in [t0, t1] [rad/s]."""
    df = run.trace
    t = df["t"].to_numpy(float)
    sel = (t >= t0) & (t <= t1)
    if sel.sum() < 4:
        return float("nan")
    dt = float(np.median(np.diff(t)))
    return float(np.mean([high_frequency_rms(df[f"u{i}"].to_numpy(float)[sel], dt,
                                             OSC_CUTOFF_HZ) for i in range(1, N_JOINTS + 1)]))


def check_5(runs: dict[str, RunFiles]) -> ClaimResult:
    """Sec. VI: the coarse model (6) "would create oscillations", model (5) does not. Issue 18:
    judged on the oscillation amplitude (RMS of u above the cut-off) over a common window --
    from the later of the two runs' first ring-2 near contacts to the earlier of their ends --
    not on energy fractions over different windows; the sign-change rates are reported."""
    fine, coarse = runs["case2"], runs["case2_coarse"]
    starts = [min((tt for tt, _ in _first_contacts(r.trace, 2)), default=float("nan"))
              for r in (fine, coarse)]
    contact = bool(np.all(np.isfinite(starts)))
    t0 = max(starts) if contact else 0.0  # no contact in a run: the whole common span
    t1 = min(float(r.trace["t"].iloc[-1]) for r in (fine, coarse))
    a_f, a_c = _hf_amplitude(fine, t0, t1), _hf_amplitude(coarse, t0, t1)
    sc_f, _ = _oscillation(fine)
    sc_c, _ = _oscillation(coarse)
    d_f = float(fine.trace["dist_min"].min())
    d_c = float(coarse.trace["dist_min"].min())
    return ClaimResult.from_clauses(
        f"common window {t0:.2f}-{t1:.2f} s ("
        + ("after both runs' first ring-2 contact" if contact else "a run never meets ring 2's "
           "threshold: the whole common span") + f"): RMS of u "
        f"above {OSC_CUTOFF_HZ:g} Hz, model (6) {a_c * 1e3:.2f} mrad/s, model (5) "
        f"{a_f * 1e3:.2f} mrad/s; sign changes per s after contact: (6) {sc_c:.2f}, (5) "
        f"{sc_f:.2f}; min true distance: (6) {d_c * 100:.2f} cm, (5) {d_f * 100:.2f} cm",
        [Clause(f"(6) oscillates more than (5) (ratio of the amplitudes above "
                f"{OSC_CUTOFF_HZ:g} Hz)", a_c / a_f if a_f > 0 else (
                    float("inf") if a_f == 0 and a_c > 0 else float("nan")), ">=", 2.0,
                "-", "ours: 'would create oscillations ... This does not occur using model "
                "(5)' (Sec. VI) has no figure; twice the amplitude")])


# ------------------------------------------------------------------ claim 6
def check_6(runs: dict[str, RunFiles], name: str = "parallel") -> ClaimResult:
    run = runs[name]
    df = run.trace
    sc, hf = _oscillation(run)
    contact_end = [i for i in range(1, N + 1) if abs(df[f"r2_cbf{i}"].iloc[-1]) <= NEAR_CONTACT]
    k_end = float(_kappa_end(df, 2).max())
    e_end = _e_px(run)[-1]
    e0 = _e_px(run)[0]
    return ClaimResult.from_clauses(
        f"ring-2 sensors at the threshold at the end {contact_end}; max final kappa "
        f"{k_end:.1e}; sign changes {sc:.2f}/s, energy above {OSC_CUTOFF_HZ:g} Hz {hf:.1%}; "
        f"||e_4p|| {e0:.0f} -> {e_end:.1f} px ("
        + ("noise-free run" if name == "parallel" else "with the 2 mm ToF noise") + ")"
        + (f"; {int(df['qp_status'].eq('relaxed').sum())} of {len(df)} QPs slack-relaxed"
           if "qp_status" in df.columns else ""),
        [Clause("two sensors at the threshold (sensors within 1 cm of it at the end)",
                len(contact_end), ">=", 2, "-", "paper: 'two virtual contacts' (Sec. VI)",
                relative=False),
         Clause("kappa = 0 (largest final multiplier)", k_end, "<=", KAPPA_ZERO, "-",
                "paper: 'The Lagrangian multipliers corresponding to the active set is zero' "
                "(Sec. VI); ours: 1e-4 counts as 0", relative=False),
         Clause("no oscillation (sign changes per s)", sc, "<", 1.0, "1/s",
                "paper: 'without experiencing oscillations' (Sec. VI); ours: < 1/s"),
         Clause("visual task converges (final ||e_4p|| over its start)", e_end / e0, "<=",
                0.05, "-", "ours: the goal lies between the planes; under 5 %")])


# ------------------------------------------------------------------ claim 7
def check_6b(runs: dict[str, RunFiles]) -> ClaimResult:
    """Beyond the paper (issue 18): claim 6 with the suite's 2 mm ToF noise; the paper's
    statement is about the noise-free KKT conditions (claim 6 judges the noise-free run)."""
    return check_6(runs, "parallel_noisy")


def _hand_windows(df: pd.DataFrame) -> list[tuple[float, float]]:
    """(start, end) [s] of each hand approach, from the logged hand pose (parked below
    the floor, z = -5 m, between approaches)."""
    active = (df["hand_z"] > -4.0).to_numpy()
    t = df["t"].to_numpy()
    edges = np.flatnonzero(np.diff(active.astype(int)))
    starts = [t[i + 1] for i in edges if not active[i]]
    ends = [t[i] for i in edges if active[i]]
    if active[-1]:
        ends.append(t[-1])
    return list(zip(starts, ends, strict=False))


def check_7(runs: dict[str, RunFiles]) -> ClaimResult:
    run = runs["case3"]
    df = run.trace
    t = df["t"].to_numpy()
    e = _e_px(run)
    rises: dict[int, list[float]] = {1: [], 2: []}
    cbf_min: dict[int, list[float]] = {1: [], 2: []}
    outside = []
    for t0, t1 in _hand_windows(df):
        ring = next((r for r, (a, b) in HAND_WINDOWS.items() if a <= t0 and t1 <= b), None)
        if ring is None:
            outside.append(f"{t0:.1f}-{t1:.1f} s")
            continue
        sel = (t >= t0) & (t <= t1 + 1.0)
        rises[ring].append(float(np.nanmax(e[sel]) - e[np.searchsorted(t, t0)]))
        cbf_min[ring].append(float(_cbf(df, ring)[(t >= t0) & (t <= t1)].min().min()))
    every = rises[2] + rises[1]
    cbfs = cbf_min[2] + cbf_min[1]
    dmin = float(df["dist_min"].min())

    def fmt(values: list[float], scale: float = 1.0) -> str:
        return ", ".join(f"{v * scale:.1f}" for v in values) or "none"

    return ClaimResult.from_clauses(
        f"rise of ||e_4p|| per approach: ring 2 {fmt(rises[2])} px; ring 1 {fmt(rises[1])} "
        f"px; final ||e_4p|| {e[-1]:.1f} px; min CBF of the approached ring per approach: "
        f"ring 2 {fmt(cbf_min[2], 100)} cm, ring 1 {fmt(cbf_min[1], 100)} cm; "
        f"min true distance {dmin * 100:.1f} cm"
        + (f"; approaches outside the paper's windows: {', '.join(outside)}" if outside else ""),
        [Clause.flag("4 approaches of ring 2 in 5-18 s and 4 of ring 1 in 20-30 s",
               len(rises[2]) == 4 and len(rises[1]) == 4 and not outside,
               "paper: 'the four instances in the interval between 5 s to 18 s ... from "
               "approximately 20 s to 30 s ... four instances' (Sec. V-C)"),
         # issue 18: the text says e "becomes non-zero when the hand ... is brought close",
         # not that every approach moves it (the old clause: the smallest rise >= 1 px)
         Clause("e_4p becomes non-zero when the hand is brought close (largest rise over the "
                "approaches)", max(every) if every else float("nan"), ">=",
                HAND_EXCURSION_PX, "px", "ours: 'becomes non-zero' (Sec. V-C) read as >= 1 px, "
                "5x the detection noise"),
         Clause("returns to ~0 (final ||e_4p||)", e[-1], "<=", RETURN_PX, "px",
                "ours: 'approach again the value of zero' (Sec. V-C) read as < 3 px"),
         Clause("every approach brings the approached ring's min CBF to ~0 (largest |min CBF|)",
                max(abs(c) for c in cbfs) if cbfs else float("nan"), "<=", CBF_ZERO_TOL, "m",
                "ours: 'reach close to virtual contact' (Sec. V-C) read as within 1 cm"),
         Clause("no contact (closest true distance)", dmin, ">", 0.0, "m",
                "paper: 'works well' (Sec. V-C): no collision", relative=False)])


# ------------------------------------------------------------------ claim 8
def check_8(runs: dict[str, RunFiles]) -> ClaimResult:
    """Sec. VI: at global convergence kappa* = 0. Judged over the last second (the median of
    each row's largest multiplier; the stop row alone is where noise pushed a sensor in) and
    only with convergence (issue 18)."""
    run = runs["case1"]
    df = run.trace
    t = df["t"].to_numpy(float)
    kap = pd.concat([df[[f"r{r}_kappa{i}" for i in range(1, N + 1)]] for r in (1, 2)], axis=1)
    k_row = kap.max(axis=1).to_numpy(float)
    last = t >= t[-1] - END_WINDOW_S
    k_med = float(np.median(k_row[last]))
    zero_share = float(np.mean(k_row[last] <= KAPPA_ZERO))
    e = _e_px(run)
    e0 = e[np.isfinite(e)][0]
    near = [f"r{r}s{i}" for r in (1, 2) for i in range(1, N + 1)
            if df[f"r{r}_cbf{i}"].iloc[-1] <= NEAR_CONTACT_END]
    return ClaimResult.from_clauses(
        f"largest multiplier over the last {END_WINDOW_S:g} s: median {k_med:.1e}, 0 in "
        f"{zero_share:.0%} of the rows, {k_row[-1]:.1e} on the last row; sensors near contact "
        f"at the end {near}; ||e_4p|| {e0:.0f} -> {e[-1]:.1f} px",
        [Clause(f"converges (||e_4p|| under {CONVERGED_FRACTION:.0%} of its start)",
                e[-1] / e0, "<=", CONVERGED_FRACTION, "-", OURS_CONV),
         Clause(f"kappa* = 0 at convergence (median over the last {END_WINDOW_S:g} s of the "
                "largest multiplier)", k_med, "<=", KAPPA_ZERO, "-",
                "paper: 'weak complementarity condition, i.e., kappa_k* = 0' (Sec. VI); ours: "
                "1e-4 counts as 0", relative=False)])


#: The paper's words each claim tests (issue 18).
QUOTES = {
    "1": ('Sec. V-A: "As can be seen in Fig. 7a, visual task converges. ... the control '
          'architecture ensures to satisfy safety." Sec. III-B: "In practical implementation, '
          'when the system leaves the safe set to its complement due to modelling errors and '
          'sensor uncertainties, it is brought back to safety."'),
    "2": ('Sec. V-A: "Note that, in case safety inequalities from proximity sensors are not '
          'taken into account, the robot arm collides with the obstacles."'),
    "3": ('Sec. V-A: "First, the manipulator moves towards the target and encounters the '
          'obstacle on the right ... around 2.5 s ... around 4 s, sensors {16, 17} on ring '
          '1 come close to virtual contact ... Immediately after, sensors {12, 13} come '
          'close to virtual contact on ring 2 from around 5 s. ... the controller '
          'eventually converges to the final goal position while being close to virtual '
          'contact in both rings till the end."'),
    "4": ('Sec. V-B: "the task e_4p converges to a local minimum with control input '
          'converging to very low value ... e_delta_91 corresponding to sensor 9 on ring 1 '
          'is close to the situation of virtual contact ... from approximately 8 s ... '
          'sensors {4, 12} on ring 2 being in virtual contact. The experiment is stopped '
          'when the norm of gradient of Lagrangian ... falls below ... 0.01."'),
    "5": ('Sec. VI: "This would create oscillations in the system ... This does not occur '
          'using model (5) with a correct estimation of the surface model."'),
    "6": ('Sec. VI: "The Lagrangian multipliers corresponding to the active set is zero ... '
          'It is thus possible to be at the desired threshold distance from each of the '
          'planes without experiencing oscillations."'),
    "7": ('Sec. V-C: "the components of visual task function is close to zero at the '
          'beginning and becomes non-zero when the hand of the human operator is brought '
          'close to the robot. Towards the end of the experiment, the components approach '
          'again the value of zero. ... It can be seen in Fig. 9d the four instances in the '
          'interval between 5 s to 18 s when proximity sensors on ring 2 reach close to '
          'virtual contact. In the later phase from approximately 20 s to 30 s, the hand '
          'interacts with ring 1 as seen in Fig. 9c. There are four instances when few sensors '
          'on ring 1 reach their threshold value. The results suggest that the control '
          'architecture works well even though obstacles were assumed to be static in the '
          'modelling."'),
    "8": ('Sec. VI: "For Case 1, when global convergence is achieved ... we can substitute '
          'u* = 0 ... to obtain weak complementarity condition, i.e., kappa_k* = 0."'),
}


CLAIMS: tuple[Claim, ...] = (
    Claim(PAPER, "1", "Case 1 converges globally; every sensor that leaves the safe set is "
          "brought back to it; no collision",
          "e_4p -> 0; no noise-free CBF < 0 at the end; no contact", ("case1",), check_1,
          quote=QUOTES["1"]),
    Claim(PAPER, "2", "Case 1 without the proximity constraints collides with an obstacle",
          "collision", ("case1_no_proximity",), check_2,
          quote=QUOTES["2"]),
    Claim(PAPER, "3", "Case 1 event order: ring 2 meets the right obstacle (~2.5 s), then ring 1 "
          "(~4 s), then ring 2's other side (~5 s); converges near virtual contact on both rings "
          "(the paper's sensor numbers are quoted, not compared: ours differ)",
          f"that order, each within {TIME_TOL_S:g} s of the paper's time; both rings' CBF <= "
          f"{NEAR_CONTACT_END * 100:g} cm at the end; ||e_4p|| -> 0",
          ("case1",), check_3,
          quote=QUOTES["3"]),
    Claim(PAPER, "4", "Case 2 stops at a local minimum by the Lagrangian-gradient test; ring-2 "
          "sensors 4 and 12 in virtual contact; a ring-1 sensor near contact (the paper's sensor "
          "9; numbers differ); u -> 0; kappa > 0",
          "||grad L(0,kappa*)|| <= 0.01; ring 2 {4,12} in contact at the end; a ring-1 CBF <= "
          f"{NEAR_CONTACT_END * 100:g} cm at the end; kappa > 0",
          ("case2",), check_4,
          quote=QUOTES["4"]),
    Claim(PAPER, "5", "Case 2 with the coarse model (6) on ring 2 oscillates; model (5) with "
          "estimated normals does not (Sec. VI, eq. 24)", "(6) oscillates, (5) does not",
          ("case2", "case2_coarse"), check_5, whole_run=("case2_coarse",),
          quote=QUOTES["5"]),
    Claim(PAPER, "6", "Between two parallel planes with the goal between them: no oscillation, "
          "kappa = 0 although both constraints are active (Sec. VI, eq. 20)",
          "no oscillation; kappa = 0", ("parallel",), check_6, whole_run=("parallel",),
          quote=QUOTES["6"]),
    Claim(PAPER, "6b", "Beyond the paper: claim 6's parallel planes with the suite's 2 mm "
          "ToF noise (the paper's statement is about the exact constraints)",
          "no oscillation; kappa = 0", ("parallel_noisy",), check_6b,
          whole_run=("parallel_noisy",), quote=QUOTES["6"]),
    Claim(PAPER, "7", "Case 3: e_4p leaves ~0 at each hand approach (4 at ring 2 in 5-18 s, 4 at "
          "ring 1 in 20-30 s) and returns to ~0; CBFs reach ~0 at each approach; no collision",
          f"8 excursions, return to ~0, each approach's min CBF within {CBF_ZERO_TOL * 100:g} cm "
          "of 0, no contact", ("case3",), check_7, whole_run=("case3",),
          quote=QUOTES["7"]),
    Claim(PAPER, "8", "Global convergence (case 1): kappa* = 0 at the end (weak complementarity, "
          "eq. 25)", "kappa* = 0", ("case1",), check_8,
          quote=QUOTES["8"]),
)
