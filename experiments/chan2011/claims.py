"""chan2011 claims 1-7 (shared/papers/README.md), each computed from trace files.

Claims about the whole motion ("never exceeded", "the whole time", "collision-free") name
their runs in ``whole_run``: a run that stopped before its duration (the experiment, when a
dot is lost) cannot reproduce them (repro.runs.claims).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from experiments.chan2011.columns import N_POINTS as N
from experiments.chan2011.columns import scene_limits, target_points_world
from repro.runs.claims import Claim, ClaimResult, Clause
from repro.runs.trace import RunFiles

PAPER = "chan2011"

CONVERGED_FRACTION = 0.05  # ours: "converges" = RMS pixel error under 5 % of its start
# chan2011 Sec. III-B gives no size for its "significant translation towards the target
# object, as well as in-plane and out-of-plane rotations" (Figs. 3-4 only); "large" is ours:
MIN_APPROACH_M = 0.20  # ours: the camera ends >= 20 cm closer to the target (10x the pose error)
MIN_IN_PLANE_DEG = 90.0  # ours: >= 90 deg about the optical axis (where classical IBVS retreats)
MIN_OUT_OF_PLANE_DEG = 30.0  # ours: optical axis turned >= 30 deg (3x the pose-estimate error)
RIDE_FRACTION = 0.95  # ours: "rides just under its limit" = measured |qd| >= 95 % of the limit
RIDE_MIN_JOINTS = 2  # ours: "velocities ride" = at least two joints ...
RIDE_MIN_S = 0.5  # ours: ... each for at least 0.5 s in total (more than a start-up transient)
LIMIT_TOL = 1e-6  # [rad, rad/s] numerical tolerance on limits
#: Measured (not commanded) joint speeds may exceed their limit by this fraction of it. ours
#: (issue 18): the NMPC constrains the *command* (Sec. II-C-1); the measured speed adds the
#: inner loop's tracking error (a 1 kHz PD following the quintic reference, as the robot's
#: own servo does), which no constraint on the command removes. 0.1 % of the limit: a tenth
#: of what Fig. 6, the paper's evidence for the claim, can show (its speeds and dotted limit
#: lines are drawn ~1 % of the axis apart at best).
MEASURED_SPEED_TOL = 1e-3
SLOW_RATIO = 0.8  # ours: "slows near obstacles" = mean speed with DCC bounds < 80 % of without
RATE_HZ = 10.0  # chan2011 Sec. V-A5: 10 Hz


OURS_TOL = "ours: 1e-6 numerical tolerance on a limit"


def _pixels(run: RunFiles) -> np.ndarray:
    df = run.trace
    cols = [f"p{j}_{a}" for j in range(1, N + 1) for a in "uv"]
    return df[cols].to_numpy(float).reshape(len(df), N, 2)


def _limits(run: RunFiles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lim = scene_limits(run.scene)
    return (np.asarray(lim["q_min"], float), np.asarray(lim["q_max"], float),
            np.asarray(lim["qd_max_used"], float))


def _table_i(scene: dict) -> dict:
    """Table I's image bounds as the run's scene.json records them (controller_model)."""
    model = scene["controller_model"]
    return model["table_I"] if "table_I" in model else model["intrinsics_table_I"]


def _missing(run: RunFiles) -> list[tuple[int, float, str]]:
    """(point j, first time [s], ground truth) of every point missing (NaN) in some row,
    whether or not an event says so."""
    df = run.trace
    p = _pixels(run)
    t = df["t"].to_numpy(float)
    tab = _table_i(run.scene)
    out = []
    for j in range(1, N + 1):
        bad = ~np.all(np.isfinite(p[:, j - 1, :]), axis=1)
        if not bad.any():
            continue
        k = int(np.argmax(bad))
        truth = ""
        if f"p{j}_u_true" in df.columns:
            u, v = float(df[f"p{j}_u_true"].iloc[k]), float(df[f"p{j}_v_true"].iloc[k])
            inside = tab["u_min"] <= u <= tab["u_max"] and tab["v_min"] <= v <= tab["v_max"]
            truth = (" (its true projection is inside the image: occluded or not detected)"
                     if inside else " (its true projection is outside the image)")
        out.append((j, float(t[k]), truth))
    return out


def _fov(run: RunFiles) -> tuple[bool, float, str]:
    """(every point found and inside Table I's bounds at every step, worst margin of the
    found points [px], text naming the missing points)."""
    tab = _table_i(run.scene)
    p = _pixels(run)
    margins = np.stack([p[..., 0] - tab["u_min"], tab["u_max"] - p[..., 0],
                        p[..., 1] - tab["v_min"], tab["v_max"] - p[..., 1]])
    missing = _missing(run)
    reported = bool(run.trace["status"].eq("no_features").any())
    worst = float(np.nanmin(margins)) if np.isfinite(margins).any() else float("nan")
    text = "; ".join(f"point {j} missing from {t:.2f} s{truth}" for j, t, truth in missing)
    if reported and not missing:
        text = "the controller reported a point lost"
    return not (missing or reported) and worst >= 0, worst, text


def _motion(run: RunFiles) -> tuple[float, float, float, float, float]:
    """Camera motion from the first to the last row: (displacement [m], distance to the
    target's point centroid at the start and at the end [m], rotation about the start optical
    axis [deg], angle between the start and end optical axes [deg]) -- a swing-twist split of
    the relative rotation R0^T R1 = R_swing R_twist, twist about z (the optical axis)."""
    df = run.trace
    pos = df[[f"camera_{a}" for a in "xyz"]].to_numpy(float)
    quat = df[[f"camera_q{a}" for a in "xyzw"]].to_numpy(float)
    target = target_points_world(run.scene).mean(axis=0)
    r0, r1 = Rotation.from_quat(quat[0]), Rotation.from_quat(quat[-1])
    qx, qy, qz, qw = (r0.inv() * r1).as_quat()
    twist = np.rad2deg(2 * np.arctan2(qz, qw))
    twist = (twist + 180.0) % 360.0 - 180.0
    z0, z1 = r0.as_matrix()[:, 2], r1.as_matrix()[:, 2]
    swing = np.rad2deg(np.arccos(np.clip(z0 @ z1, -1.0, 1.0)))
    return (float(np.linalg.norm(pos[-1] - pos[0])), float(np.linalg.norm(target - pos[0])),
            float(np.linalg.norm(target - pos[-1])), float(twist), float(swing))


def check_1(runs: dict[str, RunFiles]) -> ClaimResult:
    run = runs["simulation"]
    df = run.trace
    e = df["e_rms_px"].to_numpy(float)
    moved, d0, d1, twist, swing = _motion(run)
    stop_px = float((run.manifest.get("config") or {}).get("stop_px", 0.5))
    t95 = df["t"].to_numpy()[np.argmax(e <= CONVERGED_FRACTION * e[0])] if np.any(
        e <= CONVERGED_FRACTION * e[0]) else float("nan")
    return ClaimResult.from_clauses(
        f"RMS pixel error {e[0]:.0f} -> {e[-1]:.1f} px at {df['t'].iloc[-1]:.1f} s (under "
        f"{CONVERGED_FRACTION:.0%} at {t95:.2f} s); camera moved {moved * 100:.0f} cm, from "
        f"{d0 * 100:.0f} to {d1 * 100:.0f} cm from the target, rotated {abs(twist):.0f} deg about its optical "
        f"axis and {swing:.0f} deg out of plane; with the estimated object pose 2-3 cm and "
        "10 deg off (Sec. III-A) and Table I's uncalibrated camera, with ideal point features "
        "as in the paper's simulation" + _rendered(runs),
        [Clause("the camera reaches the desired position (final RMS pixel error; the run "
                f"stops once under {stop_px:g} px for 0.2 s)", e[-1], "<", stop_px, "px",
                "ours: the run's own convergence test, stop_px (a 1024 x 768 image); issue "
                "18: was 'under 5 % of its start' on a 20 s run"),
         # the stop test ends the run just under its bound by design: its margin is small
         # and the clause is marginal, which the table must say (issue 38)
         Clause("significant translation towards the target", d0 - d1, ">=", MIN_APPROACH_M,
                "m", "ours: 'significant' (Sec. III-B) has no figure; 10x the pose error"),
         Clause("in-plane rotation", abs(twist), ">=", MIN_IN_PLANE_DEG, "deg",
                "ours: where classical IBVS retreats (Chaumette 1998)"),
         Clause("out-of-plane rotation", swing, ">=", MIN_OUT_OF_PLANE_DEG, "deg",
                "ours: 3x the pose-estimate error")])


def _rendered(runs: dict[str, RunFiles]) -> str:
    """What the same task gives with the rendered camera (informative, not judged)."""
    run = runs.get("simulation_render")
    if run is None:
        return ""
    df = run.trace
    e = df["e_rms_px"].to_numpy(float)
    last = float(e[np.isfinite(e)][-1]) if np.isfinite(e).any() else float("nan")
    return (f"; beyond the paper, with the rendered camera and dot detection "
            f"(simulation_render): {run.manifest['summary'].get('stop_reason')} at "
            f"{df['t'].iloc[-1]:.2f} s, RMS error {last:.0f} px{_missed(run)}")


def _missed(run: RunFiles) -> str:
    ev = run.events
    if len(ev) and (ev["kind"] == "feature_missed").any():
        row = ev[ev["kind"] == "feature_missed"].iloc[0]
        return f" ({row['detail']})"
    return ""


def check_2(runs: dict[str, RunFiles]) -> ClaimResult:
    parts, clauses = [], []
    for name in [n for n in ("simulation", "experiment") if n in runs]:  # per_run
        run = runs[name]
        df = run.trace
        q_min, q_max, qd_max = _limits(run)
        q = df[[f"q{i}" for i in range(1, 7)]].to_numpy(float)
        qd = df[[f"qd{i}" for i in range(1, 7)]].to_numpy(float)
        u = df[[f"u{i}" for i in range(1, 7)]].to_numpy(float)
        dt = float(np.median(np.diff(df["t"].to_numpy(float)))) if len(df) > 1 else 0.0
        ride_s = np.sum(np.abs(qd) / qd_max >= RIDE_FRACTION, axis=0) * dt  # per joint [s]
        riders = [int(i) + 1 for i in np.flatnonzero(ride_s >= RIDE_MIN_S)]
        margin = float(np.min(np.minimum(q - q_min, q_max - q)))
        parts.append(
            f"{name}: closest approach to a position limit {np.rad2deg(margin):.1f} deg, "
            f"max measured |qd|/limit {np.max(np.abs(qd) / qd_max):.3f} (commanded "
            f"{np.max(np.abs(u) / qd_max):.3f}); time at >= {RIDE_FRACTION:.0%} of the limit per "
            f"joint {', '.join(f'{x:.2f}' for x in ride_s)} s")
        clauses += [
            Clause(f"{name}: position limits respected (closest approach)", margin, ">=",
                   -LIMIT_TOL, "rad", OURS_TOL, relative=False),
            Clause(f"{name}: commanded velocities within their limits (largest excess)",
                   float(np.max(np.abs(u) - qd_max)), "<=", LIMIT_TOL, "rad/s", OURS_TOL,
                   relative=False),
            Clause(f"{name}: measured velocities within their limits (largest excess over "
                   f"the limit, as a fraction of it)", float(np.max(np.abs(qd) / qd_max - 1.0)),
                   "<=", MEASURED_SPEED_TOL, "-", "ours: 0.1 % of the limit for the inner "
                   "loop's tracking error (the NMPC constrains the command, Sec. II-C-1)",
                   relative=False),
            Clause(f"{name}: velocities ride just under their limits (joints at >= "
                   f"{RIDE_FRACTION:.0%} for >= {RIDE_MIN_S:g} s: {riders})", len(riders),
                   ">=", RIDE_MIN_JOINTS, "-", "ours: 'keeping the joint velocities just "
                   "below their limits' (Sec. III-B) has no figure; two joints, 0.5 s each",
                   relative=False)]
    return ClaimResult.from_clauses("; ".join(parts), clauses)


def check_3(runs: dict[str, RunFiles]) -> ClaimResult:
    parts, clauses = [], []
    for name in [n for n in ("simulation", "experiment") if n in runs]:  # per_run
        ok, worst, missing = _fov(runs[name])
        parts.append(f"{name}: worst margin of the found points to the image border "
                     f"{worst:.1f} px" + (f"; {missing}" if missing else ""))
        lost = len(_missing(runs[name])) + int(runs[name].trace["status"].eq(
            "no_features").any() and not _missing(runs[name]))
        clauses += [
            Clause(f"{name}: every point found at every step (points ever lost)", lost, "<=",
                   0, "-", "paper: 'satisfy the camera field-of-view constraints' (Fig. 12)",
                   relative=False),
            Clause(f"{name}: inside Table I's bounds (worst margin of the found points)",
                   worst, ">=", 0.0, "px", "paper: Table I, u in [1, 1023], v in [1, 767]",
                   relative=False)]
    return ClaimResult.from_clauses("; ".join(parts), clauses)


def _broken(run: RunFiles) -> list[str]:
    q_min, q_max, qd_max = _limits(run)
    df = run.trace
    q = df[[f"q{i}" for i in range(1, 7)]].to_numpy(float)
    u = df[[f"u{i}" for i in range(1, 7)]].to_numpy(float)
    broken = []
    fov_ok, worst, missing = _fov(run)
    if not fov_ok:
        broken.append(f"field of view ({missing or 'a point outside the image'}; worst "
                      f"margin of the found points {worst:.0f} px)")
    if np.any(q < q_min - LIMIT_TOL) or np.any(q > q_max + LIMIT_TOL):
        broken.append("joint position limits")
    excess = np.max(np.abs(u) / qd_max)
    if excess > 1 + LIMIT_TOL:
        broken.append(f"joint velocity limits (commands x{excess:.2f} the limit)")
    return broken


def check_4(runs: dict[str, RunFiles]) -> ClaimResult:
    b1, b2 = _broken(runs["ibvs"]), _broken(runs["ibvs_saturated"])
    e = runs["ibvs_saturated"].trace["e_rms_px"].to_numpy(float)
    e_last = float(e[np.isfinite(e)][-1]) if np.isfinite(e).any() else float("nan")
    src = ("paper: 'cannot be achieved with a saturator, as this will likely bring the target "
           "object outside of the camera's field of view' (Sec. III-B)")
    return ClaimResult.from_clauses(
        f"IBVS breaks: {', '.join(b1) or 'nothing'}; IBVS + saturator breaks: "
        f"{', '.join(b2) or 'nothing'} (its last RMS error {e_last:.1f} px)",
        [Clause("IBVS breaks a constraint (constraints broken)", len(b1), ">=", 1, "-", src,
                relative=False),
         Clause("IBVS with a saturator breaks a constraint (constraints broken)", len(b2),
                ">=", 1, "-", src, relative=False)])


def check_5(runs: dict[str, RunFiles]) -> ClaimResult:
    run = runs["experiment"]
    df = run.trace
    dmin = float(df["dist_min"].min())
    box = df["dcc_box"].astype(bool).to_numpy()
    fails = int(np.sum(run.events["kind"] == "dcc_fail")) if len(run.events) else 0
    speed = np.linalg.norm(df[[f"qd{i}" for i in range(1, 7)]].to_numpy(float), axis=1)
    moving = speed > 1e-3
    # issue 18: compare at equal phase of the motion -- each stretch under the bisection
    # bounds against as many free steps just before it (after it for a stretch at the start),
    # not against every free step of the run
    v_box_list, v_near_list = [], []
    k = 0
    while k < len(box):
        if not box[k]:
            k += 1
            continue
        j = k
        while j < len(box) and box[j]:
            j += 1
        n = j - k
        before = np.flatnonzero(~box[:k])[-n:]
        near = before if before.size else np.flatnonzero(~box[j:])[:n] + j
        v_box_list.append(speed[k:j])
        v_near_list.append(speed[near])
        k = j
    v_box = float(np.mean(np.concatenate(v_box_list))) if v_box_list else float("nan")
    v_free = (float(np.mean(np.concatenate(v_near_list))) if v_near_list
              and np.concatenate(v_near_list).size else float("nan"))
    del moving
    d_fail = float(np.nanmean(df["d_fcl"].to_numpy(float)[box])) if box.any() else float("nan")
    d_ok = float(np.nanmean(df["d_fcl"].to_numpy(float)[~box]))
    return ClaimResult.from_clauses(
        f"min true distance to the obstacles {dmin * 100:.1f} cm; DCC failed in "
        f"{int(box.sum())} of {len(df)} steps ({fails} episodes), at a mean distance "
        f"{d_fail * 100:.1f} cm vs {d_ok * 100:.1f} cm elsewhere; mean joint speed with the "
        f"bisection bounds {v_box:.3f} rad/s vs {v_free:.3f} rad/s over as many free steps "
        f"next to each stretch",
        [Clause("collision-free (closest true distance)", dmin, ">", 0.0, "m",
                "paper: 'satisfies ... workspace collision constraints' (Fig. 13)",
                relative=False),
         Clause("DCC fails near the obstacles (steps under the bisection bounds)",
                int(box.sum()), ">=", 1, "-", "paper: 'In frames 8 to 12, collision-free "
                "motion can no longer be guaranteed by the DCC algorithm' (Sec. V-B)",
                relative=False),
         Clause("DCC fails closer to the obstacles than it passes (mean d(q) failing minus "
                "passing)", d_fail - d_ok, "<", 0.0, "m", "paper: 'when the robot gripper is "
                "in proximity to the workspace obstacles' (Sec. V-B)", relative=False),
         Clause("motion slower under the bounds (mean joint speed ratio to the free steps next "
                "to each stretch)",
                v_box / v_free if v_free > 0 else float("nan"), "<",
                SLOW_RATIO, "-", "ours: 'more conservative' (Sec. V-B) has no figure; 80 %")])


def check_6(runs: dict[str, RunFiles]) -> ClaimResult:
    df = runs["dcc_audit"].trace
    cert = df["bisection_free"].astype(bool).to_numpy()
    dense = df["dense_min_distance"].to_numpy(float)
    bad = int(np.sum(cert & (dense <= 0)))
    closest = float(np.nanmin(dense[cert])) if cert.any() else float("nan")
    return ClaimResult.from_clauses(
        f"{len(df)} random segments: {int(cert.sum())} certified free "
        f"({int(df['direct_certified'].astype(bool).sum())} by eq. (20) directly, the rest "
        f"after bisection), {int(df['bisection_collision'].astype(bool).sum())} found colliding;"
        f" dense fcl checks of the certified ones: min distance "
        f"{closest * 1000:.1f} mm, {bad} in collision",
        [Clause("no certified segment collides (certified segments in collision)", bad, "<=",
                0, "-", "paper: eq. (20) from the upper bound (19) (Sec. IV-A): conservative",
                relative=False),
         Clause("some segments certified", int(cert.sum()), ">=", 1, "-",
                "ours: a test that certifies nothing proves nothing", relative=False)])


def check_7(runs: dict[str, RunFiles]) -> ClaimResult:
    """The whole controller step (NMPC with its retries, DCC and the bisection: ``ctrl_s``),
    not only the last NMPC solve (issue 18), against the paper's 10 Hz, read as a sustained
    rate (the 95th percentile of the step; the slowest step and solve_s reported)."""
    parts, clauses = [], []
    for name in [n for n in ("simulation", "experiment") if n in runs]:  # per_run
        df = runs[name].trace
        col = "ctrl_s" if "ctrl_s" in df.columns else "solve_s"
        c_all = df[col].to_numpy(float)
        c = c_all[np.isfinite(c_all)]
        s_all = df["solve_s"].to_numpy(float)
        s = s_all[np.isfinite(s_all)]
        cfg = runs[name].manifest["config"]
        if not len(c):
            parts.append(f"{name}: no controller times recorded")
            clauses.append(Clause(f"{name}: controller times recorded", 0, ">=", 1, "-",
                                  "ours: nothing to judge", relative=False))
            continue
        parts.append(f"{name} (Np = {cfg['Np']}): whole controller step ({col}) over {len(c)} "
                     f"steps: median {np.median(c) * 1e3:.2f} ms, p95 "
                     f"{np.percentile(c, 95) * 1e3:.2f} ms, max {c.max() * 1e3:.1f} ms"
                     + (f"; NMPC solves alone: median {np.median(s) * 1e3:.2f} ms, max "
                        f"{s.max() * 1e3:.1f} ms" if len(s) else ""))
        clauses.append(Clause(f"{name}: the controller sustains {RATE_HZ:g} Hz (95th "
                              "percentile of the whole step)",
                              float(np.percentile(c, 95)), "<", 1.0 / RATE_HZ, "s",
                              "paper: 'The maximum control rate that is achieved ... is "
                              "10Hz' (Sec. V-A5), a sustained rate; ours: the 95th "
                              "percentile (the slowest step is reported)"))
    return ClaimResult.from_clauses("; ".join(parts), clauses)


#: The paper's words each claim tests (issue 18).
QUOTES = {
    "1": ('Sec. III-B: "The motion requires significant translation towards the target '
          'object, as well as in-plane and out-of-plane rotations. The control law '
          'successfully generates motions that bring the camera to the desired position."'),
    "2": ('Sec. III-B: "The robot responds to its joint limits (e.g., joint 5) by '
          'predicting several steps ahead and replanning control inputs to avoid constraint '
          "violation. ... The aggressive controller maximizes the robot's output "
          'capabilities by keeping the joint velocities just below their limits."'),
    "3": ('Fig. 12 (Sec. V-B): "The resulting image feature trajectories satisfy the camera '
          'field-of-view constraints."'),
    "4": ('Sec. III-B: "Note that the simultaneous avoidance of these unilateral '
          'constraints cannot be achieved with a saturator, as this will likely bring the '
          "target object outside of the camera's field of view and cause instability in the "
          'control loop."'),
    "5": ('Sec. V-B: "Robot motions become more conservative when the robot gripper is in '
          'proximity to the workspace obstacles next to the conrod. In frames 8 to 12, '
          'collision-free motion can no longer be guaranteed by the DCC algorithm ... the '
          'MPC controller replaces its joint limits with the dynamically updated '
          'collision-free bounds provided by the DCC bisection algorithm." Fig. 13: "The '
          'resulting robot trajectory satisfies joint position, joint velocity, and '
          'workspace collision constraints."'),
    "6": ('Sec. IV-B, eq. (20): "sum_j r_j |dq_j| < d(q_i) + d(q_f)", built on the upper '
          "bound (19) of every hull point's path: a segment it certifies is collision-free."),
    "7": ('Sec. V-A5: "The maximum control rate that is achieved, with SQP optimization '
          'running on one thread and feature tracking running on another, is 10Hz."'),
}


CLAIMS: tuple[Claim, ...] = (
    Claim(PAPER, "1", "Simulation: a large motion (translation towards the target, in- and "
          "out-of-plane rotation) converges despite the pose-estimate error",
          f"converges; >= {MIN_APPROACH_M * 100:g} cm closer, >= {MIN_IN_PLANE_DEG:g} deg in "
          f"plane, >= {MIN_OUT_OF_PLANE_DEG:g} deg out of plane",
          ("simulation", "simulation_render"), check_1, whole_run=("simulation",),
          quote=QUOTES["1"], done_events=("converged",), per_run=("simulation",)),
    Claim(PAPER, "2", "Joint position and velocity limits are never exceeded; velocities ride "
          "just under their limits",
          f"within limits (commanded and measured); >= {RIDE_MIN_JOINTS} joints at >= "
          f"{RIDE_FRACTION:.0%} of their limit for >= {RIDE_MIN_S:g} s",
          ("simulation", "experiment"), check_2, whole_run=("simulation", "experiment"),
          quote=QUOTES["2"], done_events=("converged",), per_run=("simulation", "experiment")),
    Claim(PAPER, "3", "All feature points stay inside the image the whole time",
          "every point found, u in [1, 1023], v in [1, 767]", ("simulation", "experiment"),
          check_3, whole_run=("simulation", "experiment"),
          quote=QUOTES["3"], done_events=("converged",), per_run=("simulation", "experiment")),
    Claim(PAPER, "4", "Plain IBVS, or IBVS with a velocity saturator, on the same task breaks a "
          "constraint (field of view, joint limit)", "each baseline breaks a constraint",
          ("ibvs", "ibvs_saturated"), check_4,
          quote=QUOTES["4"]),
    Claim(PAPER, "5", "Experiment: collision-free among the four obstacles; DCC fails near the "
          "obstacles and the bisection bounds take over; motion slows near the obstacles",
          "no contact; DCC failures near the obstacles; slower there", ("experiment",),
          check_5, whole_run=("experiment",),
          quote=QUOTES["5"]),
    Claim(PAPER, "6", "DCC never certifies a segment that collides (conservative)",
          "0 certified segments in collision", ("dcc_audit",), check_6,
          quote=QUOTES["6"]),
    Claim(PAPER, "7", "The controller runs at >= 10 Hz",
          "the whole controller step (NMPC, DCC, bisection) < 100 ms",
          ("simulation", "experiment"), check_7,
          quote=QUOTES["7"], per_run=("simulation", "experiment")),
)
