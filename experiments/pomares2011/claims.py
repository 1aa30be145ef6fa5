"""pomares2011 claims 1-4 (shared/papers/README.md), each computed from trace files.

Every clause of a claim's text is a named check; the measured text gives the numbers next
to the paper's statement. Thresholds the paper does not give are ours and named here.
The traces hold one row every ``log_every`` control steps (10 ms); distance minima over
*every* step come from the manifest's ``summary.min_over_all_steps``.
"""

from __future__ import annotations

import numpy as np

from experiments.pomares2011.exp3_claims import CLAIM_5, CLAIM_5B
from experiments.pomares2011.task_claims import CLAIM_TABLE1
from repro.runs.claims import Claim, ClaimResult, Clause
from repro.runs.trace import RunFiles

PAPER = "pomares2011"

#: "s = s*": the RMS distance of the four detected points to s* is under this [px]. ours:
#: the paper marks the instant (label "1" of Fig. 6) without a threshold; 2 px is ~8x the
#: detection error of the rendered camera (audit max 0.26 px).
REACHED_PX = 2.0
#: "stays there": after reaching s*, the RMS error never exceeds this while the PA-10 moves
#: [px]. ours: the reached threshold plus 1 px of margin for the held 200 fps frames.
STAY_PX = 3.0
#: "RVC features reach s_u*": final RMS error under this [px]. ours: as REACHED_PX.
REACHED_U_PX = 2.0
#: "the base is still": every PA-10 joint's measured speed under this [rad/s]. ours: 3e-4 of
#: the RVC's peak joint speed (0.3 rad/s).
BASE_STILL_RAD_S = 1e-4
#: "V non-increasing": no rise of V_true (exact projections) between two trace rows larger
#: than this fraction of V at the start of the still window. ours: the law runs at 1 kHz on
#: features held for 5 ms between 200 fps frames, so the continuous-time (15) holds only up
#: to the discretisation; 1e-3 V leaves that room and catches any real rise.
V_RISE_REL = 1e-3
#: The still window must last at least this long to judge claim 2 [s]. ours: 100 trace rows.
MIN_WINDOW_S = 1.0
#: "e_v -> 0": the VVS reprojection residual at the end under this [px] and the position
#: error under POSE_TOL_M. ours: ~the detection error; 2 mm at 0.2-0.4 m depth.
VVS_RESIDUAL_PX = 0.5
POSE_TOL_M = 2e-3
#: A cold start "ends at the warm start's pose" within this [m] (reported for the larger
#: offsets). ours: 1 mm, ~5x the warm start's own distance to the truth.
SAME_POSE_M = 1e-3
#: "f1y stays at 272 px" while the human is within dmin: |f2y - 272| under this [px] (the
#: held coordinate is f2y, scene.PRIMARY_TASK_ROW). ours:
#: as REACHED_PX.
F1Y_TOL_PX = 2.0
#: "e2 moves the mini-robot away": the minimum true distance to the human is at least this
#: much larger than without the secondary task [m]. ours: 1 cm, far above the distance
#: noise (0 with the default exact tracker).
AWAY_M = 0.01


#: The paper's words each claim tests (issue 18).
QUOTES = {
    "1": ('Sec. 7.1: "the label \'1\' indicates the moment when the mini-robot reaches the '
          'desired features, (s = s*), but the experiment continues until the robotic '
          'manipulator achieves the corresponding desired features, s_u* ... During this last '
          'phase of the experiment, the mini-robot compensates the robotic manipulator motion '
          'in order to maintain s = s* ... It is possible to observe that the desired features '
          'are achieved."'),
    "2": ('Sec. 3.2: "K_v is a symmetric positive-defined matrix, consequently dV/dt is a '
          'globally negative semi-definited function. Therefore, the point [q^T qdot^T]^T = '
          '[q_0^T 0]^T is a stable equilibrium."'),
    "3": ('Sec. 5.1: "Once the error is cancelled, the value of (M_O^MC)_i will be equal the '
          'extrinsic parameters of the camera located at the end of the mini-robot."'),
    "4": ('Sec. 7.2: "When the human enters within the workspace, the cost function (17) '
          'increases and the secondary task is employed to avoid the collision ... the goal of '
          'the mini-robot is to observe the y-coordinate of f_1p at position 272, i.e., f*_1py '
          '= 272 px. Only one DOF is required to perform the image-based task e_1 of the '
          'mini-robot direct hybrid controller. This DOF compensates the motion of the robotic '
          'manipulator. The other motion components will be used to carry out the secondary '
          'task. ... When the human operator enters in the workspace, the primary task '
          'compensates the decrease in depth of the robotic manipulator and the secondary task '
          'causes a small variation in the image features in order to avoid the collision '
          '(f*_1py = 272 px). Once the human goes out of the robot workspace (dist > dmin), '
          'only the primary task is employed, which considers the desired features indicated '
          'in the Experiment 1."'),
}


def _first(mask: np.ndarray) -> int | None:
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


def _arm_speed(run: RunFiles) -> np.ndarray:
    df = run.trace
    return np.max(np.abs(df[[f"pa10_qd{i}" for i in range(1, 7)]].to_numpy(float)), axis=1)


def _human_min(run: RunFiles, prefix: str) -> tuple[float, float, str]:
    """(minimum over every control step of the true distance [m] between ``prefix``'s links
    and any human bone, its time [s], the bone) from the manifest (all steps)."""
    mins = run.manifest.get("summary", {}).get("min_over_all_steps", {})
    best = (float("inf"), float("nan"), "")
    for col, v in mins.items():
        if col.startswith(f"{prefix}dist_human_") and v["min_m"] < best[0]:
            best = (float(v["min_m"]), float(v["t_s"]), col[len(f"{prefix}dist_human_"):])
    if not np.isfinite(best[0]):  # no summary (older run): the logged rows
        cols = [c for c in run.trace.columns if c.startswith(f"{prefix}dist_human_")]
        if cols:
            d = run.trace[cols].to_numpy(float)
            k, j = np.unravel_index(int(np.nanargmin(d)), d.shape)
            best = (float(d[k, j]), float(run.trace["t"].iloc[k]),
                    cols[j][len(f"{prefix}dist_human_"):])
    return best


def check_1(runs: dict[str, RunFiles]) -> ClaimResult:
    run = runs["exp1"]
    df = run.trace
    t = df["t"].to_numpy(float)
    e_s = df["e_s_px"].to_numpy(float)
    e_u = df["e_u_px"].to_numpy(float)
    moving = ~df["arm_reached"].fillna(False).astype(bool).to_numpy()
    k1 = _first(e_s < REACHED_PX)
    k_arm = _first(~moving)
    t_arm = t[k_arm] if k_arm is not None else float("nan")
    if k1 is not None:
        after = e_s[k1:][moving[k1:]]
        stay = float(np.nanmax(after)) if after.size else float("nan")
        reached = f"s = s* (RMS < {REACHED_PX:g} px) at {t[k1]:.2f} s"
    else:
        stay = float("nan")
        reached = f"s never within {REACHED_PX:g} px of s* (min {np.nanmin(e_s):.1f} px)"
    e_u_end = float(e_u[np.isfinite(e_u)][-1])
    true_cols = [f"su{i}_{a}_true" for i in range(1, 5) for a in "uv"]
    truth = ""
    if all(c in df.columns for c in true_cols):
        su = df[true_cols].dropna().to_numpy(float)[-1].reshape(4, 2)
        star = np.asarray(run.scene["s_u_star_px"], float)
        e_true = float(np.sqrt(np.mean(np.sum((su - star) ** 2, axis=1))))
        truth = f" (with the true object pose {e_true:.2f} px)"
    if "s_u_star_paper_px" in run.scene:
        paper = np.asarray(run.scene["s_u_star_paper_px"], float)
        star = np.asarray(run.scene["s_u_star_px"], float)
        d = float(np.sqrt(np.mean(np.sum((star - paper) ** 2, axis=1))))
        truth += f"; s_u* learned at the goal, {d:.2f} px RMS from the paper's values"
    measured = (f"mini-robot RMS error {e_s[np.isfinite(e_s)][0]:.0f} -> "
                f"{e_s[np.isfinite(e_s)][-1]:.2f} px; {reached}; the PA-10 stops (RVC error < "
                f"arm_stop_px) at {t_arm:.2f} s; "
                + (f"worst error after reaching s* while the PA-10 moves {stay:.2f} px; "
                   if np.isfinite(stay) else "")
                + f"RVC error {np.nanmax(e_u):.0f} -> {e_u_end:.2f} px" + truth)
    src = "paper: Sec. 7.1 (Fig. 6, label '1')"
    return ClaimResult.from_clauses(measured, [
        Clause("mini-robot features reach s* (smallest RMS error)", float(np.nanmin(e_s)), "<",
               REACHED_PX, "px", "ours: 's = s*' has no figure; ~8x the detection error"),
        Clause.flag("... while the PA-10 still moves", k1 is not None and bool(moving[k1]), src),
        Clause("... and stay there while it moves (worst error after reaching s*)",
               stay if k1 is not None else float("nan"), "<=", STAY_PX, "px",
               "ours: the reached bound plus 1 px for the held frames"),
        # issue 18: the claim is about the features the RVC extracts (Fig. 7: "the virtual
        # visual features extracted by the RVC"), i.e. those from the VVS pose estimate, which
        # the controller uses; the true-pose figure is reported beside it
        Clause("RVC features reach s_u* (final RMS of the extracted, i.e. estimated-pose, "
               "features)", e_u_end, "<", REACHED_U_PX, "px",
               "ours: as s = s*; the claim is about the RVC's extracted features (Fig. 7)")])


def _rises(V: np.ndarray) -> tuple[float, int]:
    """(largest rise between consecutive rows [J], number of rising intervals)."""
    d = np.diff(V)
    return (float(np.max(d)) if d.size else 0.0), int(np.sum(d > 0))


def check_2(runs: dict[str, RunFiles]) -> ClaimResult:
    """Eq. (15) on the still-base window. Issue 18: eq. (15) is a statement about the control
    law with exact features; the run's camera is noisy (every trace row is a new frame, whose
    detection noise steps the image potential). The check reports V from the detected points
    (column V) and from the exact projections through the true camera pose (V_true, same qd,
    M, k_P), and judges on V_true."""
    run = runs["exp1"]
    df = run.trace
    t = df["t"].to_numpy(float)
    V = df["V"].to_numpy(float)
    has_true = "V_true" in df.columns
    Vt = df["V_true"].to_numpy(float) if has_true else np.full(len(df), np.nan)
    still = (_arm_speed(run) < BASE_STILL_RAD_S) & np.isfinite(V)
    moving = np.flatnonzero(~still)  # the base is still from the row after its last motion
    k0 = (int(moving[-1]) + 1 if moving.size else 0) if still[-1] else None
    if k0 is None or k0 >= len(t) - 1:
        return ClaimResult(f"the PA-10 is never still (max joint speed < {BASE_STILL_RAD_S:g} "
                           f"rad/s) in {t[-1]:.1f} s: claim 2 not testable", "not_reproduced")
    window = float(t[-1] - t[k0])
    worst, n_up = _rises(V[k0:])
    worst_t, n_up_t = _rises(Vt[k0:])
    n = len(t) - 1 - k0
    measured = (f"PA-10 still from {t[k0]:.2f} s ({window:.1f} s window): with the exact "
                f"projections (V_true, the claim's) V {Vt[k0]:.3g} -> {Vt[-1]:.3g} J, largest "
                f"rise between rows {worst_t:.3g} J ({worst_t / Vt[k0]:.2e} of V at the start), "
                f"{n_up_t} of {n} row intervals rise; from the detected points (V, every row a "
                f"new noisy frame) {V[k0]:.3g} -> {V[-1]:.3g} J, largest rise {worst:.3g} J "
                f"({worst / V[k0]:.2e}), {n_up} of {n} intervals rise; before that, with the "
                f"base moving, V_true rises in "
                f"{int(np.sum(np.diff(Vt[:k0][np.isfinite(Vt[:k0])]) > 0))} of {k0 - 1} "
                f"intervals")
    if window < MIN_WINDOW_S:  # a precondition, not a clause of the claim
        return ClaimResult(measured + f" -- not testable: the base is still for only "
                           f"{window:.2f} s (< {MIN_WINDOW_S:g} s, ours: 100 trace rows)",
                           "not_reproduced")
    return ClaimResult.from_clauses(measured, [
        Clause("V non-increasing once the base is still, with exact features (largest rise "
               "of V_true over its value at the start)",
               worst_t / Vt[k0] if has_true else float("nan"), "<=", V_RISE_REL, "-",
               "paper: eq. (15), dV/dt <= 0 (a statement about the law, exact features); "
               "ours: 1e-3 V for the 1 kHz integration and the 5 ms held frames",
               relative=False)])


def check_3(runs: dict[str, RunFiles]) -> ClaimResult:
    parts, clauses = [], []
    for name in ("exp1", "exp2"):
        df = runs[name].trace
        res = df["vvs_residual_px"].to_numpy(float)
        err = df["vvs_pos_err_m"].to_numpy(float)
        ok = np.isfinite(res) & np.isfinite(err)
        res, err = res[ok], err[ok]
        conv = df["vvs_converged"].dropna().astype(bool)
        parts.append(f"{name}: VVS residual {res[0]:.2f} -> {res[-1]:.3f} px (max "
                     f"{np.max(res):.2f}), pose error vs the true object {err[0] * 1e3:.2f} -> "
                     f"{err[-1] * 1e3:.3f} mm (max {np.max(err) * 1e3:.2f} mm), converged on "
                     f"its tolerance in {conv.mean():.1%} of the frames")
        clauses += [
            Clause(f"{name}: e_v -> 0 (final residual)", float(res[-1]), "<", VVS_RESIDUAL_PX,
                   "px", "ours: 'once the error is cancelled' has no figure; ~the detection "
                   "error"),
            Clause(f"{name}: the pose converges to the true pose (final position error)",
                   float(err[-1]), "<", POSE_TOL_M, "m", "ours: 2 mm at 0.2-0.4 m depth")]
    cold = runs.get("vvs_cold")
    if cold is None:
        clauses.append(Clause("a cold start (>= 2 cm / 10 deg off) converges (vvs_cold run)",
                              float("nan"), "<", VVS_RESIDUAL_PX, "px", "ours: issue 18"))
    else:
        df = cold.trace
        off_m, off_deg = df["offset_m"].to_numpy(float), df["offset_deg"].to_numpy(float)
        case = (off_m == off_m.min()) & (off_deg == off_deg[off_m == off_m.min()].min())
        c = df[case]
        lo_m, lo_deg = float(off_m[case][0]), float(off_deg[case][0])
        rep = []
        for (m, d), g in df.groupby(["offset_m", "offset_deg"]):
            same = g["to_warm_m"].to_numpy(float) < SAME_POSE_M
            rep.append(f"{m * 100:g} cm / {d:g} deg: {same.mean():.0%} of {len(g)} end at the "
                       f"warm start's pose (worst residual {g['residual_px'].max():.2f} px, "
                       f"position error {g['pos_err_m'].max() * 1e3:.1f} mm)")
        parts.append(f"cold starts on {df['frame'].nunique()} rendered frames along the "
                     f"approach (vvs_cold): " + "; ".join(rep))
        clauses += [
            Clause(f"cold start ({lo_m * 100:g} cm / {lo_deg:g} deg off): e_v -> 0 (worst final "
                   f"residual of {len(c)} starts)", float(c["residual_px"].max()), "<",
                   VVS_RESIDUAL_PX, "px", "ours: as the warm case; the start from issue 18 "
                   "(a part placed by hand)"),
            Clause(f"cold start ({lo_m * 100:g} cm / {lo_deg:g} deg off): the pose converges to "
                   "the true pose (worst final position error)", float(c["pos_err_m"].max()),
                   "<", POSE_TOL_M, "m", "ours: as the warm case")]
    return ClaimResult.from_clauses("; ".join(parts), clauses)


def check_4(runs: dict[str, RunFiles]) -> ClaimResult:
    run, base = runs["exp2"], runs["exp2_no_secondary"]
    df = run.trace
    t = df["t"].to_numpy(float)
    active = df["secondary_active"].fillna(False).astype(bool).to_numpy()
    d_mini, t_mini, bone = _human_min(run, "mini_")
    # the PA-10 side: its arm and the BH8 hand it carries (joints and finger motors); issue
    # 18: the hand came 4.4 cm closer to the human than the arm and was left out
    d_arm, _, bone_arm = min((_human_min(run, pre) for pre in ("pa10_", "bh8_", "motor_")),
                             key=lambda x: x[0])
    d_base, t_base, bone_base = _human_min(base, "mini_")
    if not active.any():
        return ClaimResult(f"the human never came within dmin of the mini-robot (min true "
                           f"distance {d_mini * 100:.1f} cm): the secondary task never acted",
                           "not_reproduced")
    k_on, k_off = _first(active), int(np.flatnonzero(active)[-1])
    # issue 18: the held coordinate's change from its value when the secondary task starts
    # (the paper: "a small variation"), and its offset from 272 px, both reported
    e_y = df["e_f2y_px"].to_numpy(float)
    f1y_max = float(np.nanmax(np.abs(e_y[active])))
    held_change = float(np.nanmax(np.abs(e_y[active] - e_y[k_on])))
    e_s = df["e_s_px"].to_numpy(float)
    e_end = float(e_s[-1])  # the last row: dots lost at the end are NaN and fail
    left = k_off < len(t) - 1
    # the final error is NaN for one of two causes; say which (issue 19's review)
    final_cause = ("" if left and np.isfinite(e_end) else
                   " (the human never leaves)" if not left else
                   " (a dot is out of the image at the end)")
    cam = df[[f"camera_{a}" for a in "xyz"]].to_numpy(float)
    cam_b = base.trace[[f"camera_{a}" for a in "xyz"]].to_numpy(float)
    n = min(len(cam), len(cam_b))
    shift = float(np.max(np.linalg.norm(cam[:n] - cam_b[:n], axis=1)))
    measured = (f"secondary task active {t[k_on]:.2f}-{t[k_off]:.2f} s "
                f"({active.mean() * (t[-1] - t[0]):.1f} s); min true distance human - "
                f"mini-robot {d_mini * 100:.1f} cm ({bone}, {t_mini:.2f} s), human - PA-10 and hand "
                f"{d_arm * 100:.1f} cm ({bone_arm}), over every control step; without the "
                f"secondary task {d_base * 100:.1f} cm ({bone_base}, {t_base:.2f} s)"
                f"{' -- the human touches the mini-robot' if d_base <= 0 else ''}; camera "
                f"up to {shift * 100:.1f} cm from the baseline's path; while active the held f2y "
                f"moves up to {held_change:.2f} px from its value at the start of the task "
                f"(|f2y - 272| <= {f1y_max:.2f} px); after the human leaves, RMS error to s* "
                f"{e_end:.2f} px at {t[-1]:.1f} s{final_cause}")
    return ClaimResult.from_clauses(measured, [
        Clause("e2 moves the mini-robot away (min distance gained over the run without it)",
               d_mini - d_base, ">=", AWAY_M, "m", "ours: 1 cm, far above the distance noise"),
        Clause("dist > 0 always (both robots, every control step: the smaller minimum)",
               min(d_mini, d_arm), ">", 0.0, "m", "paper: 'to avoid the collision' (Sec. 7.2)",
               relative=False),
        Clause("the held coordinate (f2y) stays while active (largest change from its value "
               "when the secondary task starts)", held_change, "<=", F1Y_TOL_PX, "px",
               "ours: 'a small variation' (Sec. 7.2) has no figure; as s = s*"),
        Clause("after the human leaves, s -> s* (final RMS; NaN if the human never leaves "
               "or a dot is out of the image at the end)",
               e_end if left else float("nan"), "<", REACHED_PX, "px",
               "ours: as s = s*")])


CLAIMS_1_4: tuple[Claim, ...] = (
    Claim(PAPER, "1", "Exp 1: the mini-robot features reach s*, then stay there while the "
          "PA-10 moves; the RVC features reach s_u*",
          f"s = s* before the PA-10 stops (RMS < {REACHED_PX:g} px), within {STAY_PX:g} px "
          f"after; s_u* reached (< {REACHED_U_PX:g} px)", ("exp1",), check_1,
          whole_run=("exp1",),
          quote=QUOTES["1"]),
    Claim(PAPER, "2", "Exp 1: with no human, V (10) is non-increasing once the base is still "
          "(eq. 15)", f"no rise of V > {V_RISE_REL:g} V once the PA-10 is still (V from the "
          "exact projections; the detected points' V reported)",
          ("exp1",), check_2, whole_run=("exp1",),
          quote=QUOTES["2"]),
    Claim(PAPER, "3", "The VVS pose estimate converges to the true object pose (e_v -> 0)",
          f"final residual < {VVS_RESIDUAL_PX:g} px, pose error < {POSE_TOL_M * 1e3:g} mm, in "
          f"the runs (warm-started) and from cold starts 2 cm / 10 deg off",
          ("exp1", "exp2", "vvs_cold"), check_3,
          quote=QUOTES["3"]),
    Claim(PAPER, "4", "Exp 2: when the human comes within dmin, e2 moves the mini-robot away; "
          "dist > 0 always; f1y stays at 272 px; after the human leaves, s -> s*",
          f"farther than without e2 (>= {AWAY_M * 100:g} cm); min true distance > 0; "
          f"|f2y - 272| <= {F1Y_TOL_PX:g} px; final RMS < {REACHED_PX:g} px",
          ("exp2", "exp2_no_secondary"), check_4, whole_run=("exp2", "exp2_no_secondary"),
          quote=QUOTES["4"]),
)

#: Claims 1-4 (this module) and claim 5 (experiment 3, :mod:`experiments.pomares2011.exp3_claims`).
CLAIMS: tuple[Claim, ...] = (*CLAIMS_1_4, CLAIM_5, CLAIM_5B, CLAIM_TABLE1)
