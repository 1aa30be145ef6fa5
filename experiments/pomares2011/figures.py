"""pomares2011 figures from the traces: experiment 1 (Figs. 5-7), experiment 2 (Figs. 8-10)
and the two baselines (no secondary task; indirect visual servo); experiment 3's and the whole
task's from their modules."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from experiments.pomares2011.columns import N_POINTS  # noqa: E402
from experiments.pomares2011.exp3_figures import make_exp3_figures  # noqa: E402
from experiments.pomares2011.task_figures import make_task_figures  # noqa: E402
from repro.plots.style import PALETTE, apply_style, save_figure  # noqa: E402
from repro.runs.trace import RunFiles  # noqa: E402
from repro.runs.validate import load_run_if_present  # noqa: E402

PAPER = "pomares2011"
#: s* reached: the RMS distance of the points to s* under this [px] (the mark of Fig. 6).
REACHED_PX = 2.0  # ours: the paper marks the instant without a threshold


def image_trajectory(run: RunFiles, prefix: str, star_key: str, title: str) -> plt.Figure:
    """Image trajectories of four points (start 'o', desired 'x'), 640 x 480 image."""
    df = run.trace
    star = np.asarray(run.scene[star_key], float)
    fig, ax = plt.subplots(figsize=(3.6, 2.9))
    for i in range(N_POINTS):
        u, v = df[f"{prefix}{i + 1}_u"].to_numpy(float), df[f"{prefix}{i + 1}_v"].to_numpy(float)
        ax.plot(u, v, color=PALETTE[i], lw=0.9)
        ax.plot(u[0], v[0], "o", mfc="none", color=PALETTE[i], ms=4)
        ax.plot(star[i, 0], star[i, 1], "x", color=PALETTE[i], ms=6)
    ax.set_xlim(0, 640)
    ax.set_ylim(480, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_title(title)
    return fig


def _shade_active(ax: plt.Axes, df: pd.DataFrame) -> None:
    """Shade the time spans where the secondary task (17) is active."""
    if "secondary_active" not in df.columns:
        return
    t = df["t"].to_numpy(float)
    a = df["secondary_active"].fillna(False).astype(bool).to_numpy()
    edges = np.flatnonzero(np.diff(np.r_[False, a, False].astype(int)))
    for k0, k1 in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(t[k0], t[min(k1, len(t) - 1)], color="0.85", lw=0, zorder=0)


def torques(run: RunFiles, title: str) -> plt.Figure:
    """The mini-robot's joint torques vs time, with the instant s = s* marked ('1') and the
    spans where the secondary task acts shaded."""
    df = run.trace
    t = df["t"].to_numpy(float)
    fig, ax = plt.subplots(figsize=(3.6, 2.6))
    _shade_active(ax, df)
    for i in range(3):
        ax.plot(t, df[f"mini_u{i + 1}"], color=PALETTE[i], lw=0.8, label=f"$\\tau_{i + 1}$")
    reached = np.flatnonzero(df["e_s_px"].to_numpy(float) < REACHED_PX)
    if reached.size:
        ax.axvline(t[reached[0]], color="k", ls=":", lw=0.8)
        ax.annotate("1", (t[reached[0]], ax.get_ylim()[1]), ha="center", va="bottom")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("torque (N m)")
    ax.set_title(title)
    ax.legend(fontsize=7)
    return fig


def paths_3d(run: RunFiles, title: str) -> plt.Figure:
    """3D paths of the PA-10 flange and the mini-robot camera (coloured by whether the
    secondary task is active) and of the operator's reaching hand (cf. Fig. 10)."""
    df = run.trace
    fig = plt.figure(figsize=(4.2, 3.6))
    ax = fig.add_subplot(projection="3d")
    fl = df[["flange_x", "flange_y", "flange_z"]].to_numpy(float)
    cam = df[["camera_x", "camera_y", "camera_z"]].to_numpy(float)
    act = df["secondary_active"].fillna(False).astype(bool).to_numpy()
    ax.plot(*fl.T, color=PALETTE[0], lw=1.0, label="PA-10 flange")
    ax.plot(*cam.T, color=PALETTE[1], lw=0.8, label="camera (primary task)")
    ax.scatter(*cam[act].T, color=PALETTE[3], s=2, label="camera (secondary task on)")
    hand = [c for c in ("human_hand_r_x", "human_hand_r_y", "human_hand_r_z") if c in df]
    if len(hand) == 3:
        h = df[hand].to_numpy(float)
        far = np.linalg.norm(h - cam, axis=1) >= 0.6  # only where it comes near the robot
        h[far] = np.nan
        ax.plot(*h.T, color=PALETTE[2], lw=0.6, ls="--", label="operator's hand (< 0.6 m)")
    ax.scatter(*fl[0], color=PALETTE[0], marker="o", s=10)
    ax.scatter(*cam[0], color=PALETTE[1], marker="o", s=10)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_title(title)
    ax.legend(fontsize=6, loc="upper left")
    return fig


def distance_baseline(run: RunFiles, base: RunFiles, dmin: float) -> plt.Figure:
    """Ground-truth minimum distance between the mini-robot and the operator with and
    without the secondary task, and the controller's capsule distance."""
    fig, ax = plt.subplots(figsize=(3.8, 2.6))
    for r, label, color in ((run, "with e2 (exp2)", PALETTE[0]),
                            (base, "without e2 (baseline)", PALETTE[3])):
        df = r.trace
        cols = [c for c in df.columns if c.startswith("mini_dist_human_")]
        ax.plot(df["t"], df[cols].min(axis=1), color=color, lw=0.9, label=f"{label}: true")
        ax.plot(df["t"], df["dist_m"], color=color, lw=0.6, ls=":",
                label=f"{label}: capsules (controller)")
    _shade_active(ax, run.trace)
    ax.axhline(dmin, color="k", lw=0.6, ls="--")
    ax.annotate("$d_{min}$", (run.trace["t"].iloc[0], dmin), va="bottom", fontsize=7)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_ylim(-0.02, 0.6)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("mini-robot - human (m)")
    ax.set_title("Secondary task on and off (beyond the paper)")
    ax.legend(fontsize=6)
    return fig


def indirect_baseline(direct: RunFiles, indirect: RunFiles) -> plt.Figure:
    """Direct (torque-level) vs indirect (kinematic IBVS + joint PD) servo of the
    mini-robot on experiment 1: image error, torques and one image trajectory."""
    fig, axes = plt.subplots(1, 3, figsize=(9.0, 2.7))
    for r, label, ls in ((direct, "direct", "-"), (indirect, "indirect", "--")):
        df = r.trace
        axes[0].semilogy(df["t"], df["e_s_px"], ls=ls, color="k", lw=0.8, label=label)
        for i in range(3):
            axes[1].plot(df["t"], df[f"mini_u{i + 1}"], ls=ls, color=PALETTE[i], lw=0.7,
                         label=f"$\\tau_{i + 1}$ {label}")
        axes[2].plot(df["s1_u"], df["s1_v"], ls=ls, color=PALETTE[0], lw=0.8, label=label)
        for i in range(1, N_POINTS):
            axes[2].plot(df[f"s{i + 1}_u"], df[f"s{i + 1}_v"], ls=ls, color=PALETTE[i], lw=0.8)
    star = np.asarray(direct.scene["s_star_px"], float)
    axes[2].plot(star[:, 0], star[:, 1], "kx", ms=5)
    tau = np.concatenate([r.trace[[f"mini_u{i}" for i in (1, 2, 3)]].to_numpy(float).ravel()
                          for r in (direct, indirect)])
    lo, hi = np.nanpercentile(tau, [0.5, 99.5])
    pad = 0.1 * (hi - lo)
    axes[1].set_ylim(lo - pad, hi + pad)
    peak = float(np.nanmax(np.abs(tau)))
    if peak > max(abs(lo), abs(hi)) + pad:
        axes[1].set_title(f"start-up peaks up to {peak:.2f} N m clipped", fontsize=7)
    axes[0].set_xlabel("time (s)")
    axes[0].set_ylabel("RMS error to s* (px)")
    axes[0].legend(fontsize=7)
    axes[1].set_xlabel("time (s)")
    axes[1].set_ylabel("torque (N m)")
    axes[1].legend(fontsize=5, ncol=2)
    axes[2].set_xlim(0, 640)
    axes[2].set_ylim(480, 0)
    axes[2].set_aspect("equal")
    axes[2].set_xlabel("u (px)")
    axes[2].set_ylabel("v (px)")
    axes[2].legend(fontsize=7)
    fig.suptitle("Mini-robot: direct vs indirect visual servo (beyond the paper)", fontsize=9)
    return fig


def lyapunov(run: RunFiles) -> plt.Figure:
    """Claim 2's evidence: V (10) from the detected points and from the exact projections
    (V_true), over the run and (right) the window in which the PA-10 is still."""
    df = run.trace
    t = df["t"].to_numpy(float)
    V = df["V"].to_numpy(float)
    Vt = df["V_true"].to_numpy(float) if "V_true" in df.columns else np.full(len(t), np.nan)
    still = df["arm_reached"].fillna(False).astype(bool).to_numpy()
    fig, axes = plt.subplots(1, 2, figsize=(8.0, 3.0))
    for ax, sel in ((axes[0], np.ones(len(t), bool)), (axes[1], still)):
        if not sel.any():
            continue
        ax.plot(t[sel], V[sel], lw=0.8, label="V, detected points")
        ax.plot(t[sel], Vt[sel], lw=0.8, ls="--", label="V_true, exact projections")
        ax.set_xlabel("t (s)")
        ax.set_ylabel("V (J)")
    axes[0].set_yscale("log")
    if still.any():
        axes[0].axvspan(t[np.argmax(still)], t[-1], color="0.9", zorder=0,
                        label="PA-10 still")
    axes[0].legend(fontsize=7)
    axes[1].set_title("PA-10 still", fontsize=8)
    fig.suptitle("Exp. 1: Lyapunov function (10) (claim 2, eq. (15))", fontsize=9)
    return fig


def vvs_cold_starts(run: RunFiles) -> plt.Figure:
    """Claim 3's cold starts: final position error and residual of every start, by offset."""
    df = run.trace
    fig, axes = plt.subplots(1, 2, figsize=(7.0, 3.0))
    groups = list(df.groupby(["offset_m", "offset_deg"]))
    for j, (_, g) in enumerate(groups):
        x = j + np.linspace(-0.25, 0.25, len(g))
        axes[0].semilogy(x, np.maximum(g["pos_err_m"].to_numpy(float) * 1e3, 1e-4), ".",
                         ms=3)
        axes[1].semilogy(x, np.maximum(g["residual_px"].to_numpy(float), 1e-4), ".", ms=3)
    labels = [f"{m * 100:g} cm\n{d:g} deg" for (m, d), _ in groups]
    for ax, ylabel in zip(axes, ("final position error (mm)", "final residual (px)"),
                          strict=True):
        ax.set_xticks(range(len(groups)), labels, fontsize=7)
        ax.set_ylabel(ylabel)
        ax.set_xlabel("start offset from the true pose")
    axes[0].axhline(2.0, color="0.4", lw=0.6, ls=":")
    axes[1].axhline(0.5, color="0.4", lw=0.6, ls=":")
    fig.suptitle("VVS (22)-(24) from cold starts on rendered frames (claim 3; bounds dotted)",
                 fontsize=9)
    return fig


def make_figures(results_dir: Path, figures_dir: Path) -> list[Path]:
    apply_style()
    written: list[Path] = []
    exp1 = load_run_if_present(Path(results_dir) / PAPER, "exp1")
    if exp1 is not None:
        for fig, name in (
                (image_trajectory(exp1, "s", "s_star_px", "Mini-robot camera (cf. Fig. 5)"),
                 "fig05"),
                (torques(exp1, "Mini-robot torques (cf. Fig. 6)"), "fig06"),
                (image_trajectory(exp1, "su", "s_u_star_px", "Reference Virtual Camera "
                                  "(cf. Fig. 7)"), "fig07"),
                (lyapunov(exp1), "lyapunov")):
            written += save_figure(fig, figures_dir, PAPER, name)
            plt.close(fig)
    exp2 = load_run_if_present(Path(results_dir) / PAPER, "exp2")
    if exp2 is not None:
        for fig, name in (
                (torques(exp2, "Mini-robot torques, exp. 2 (cf. Fig. 8)"), "fig08"),
                (image_trajectory(exp2, "s", "s_star_px", "Mini-robot camera, exp. 2 "
                                  "(cf. Fig. 9)"), "fig09"),
                (paths_3d(exp2, "Exp. 2: 3D paths (cf. Fig. 10)"), "fig10")):
            written += save_figure(fig, figures_dir, PAPER, name)
            plt.close(fig)
    base = load_run_if_present(Path(results_dir) / PAPER, "exp2_no_secondary")
    if exp2 is not None and base is not None:
        fig = distance_baseline(exp2, base, float(exp2.manifest["config"]["dmin"]))
        written += save_figure(fig, figures_dir, PAPER, "baseline_no_secondary")
        plt.close(fig)
    cold = load_run_if_present(Path(results_dir) / PAPER, "vvs_cold")
    if cold is not None:
        fig = vvs_cold_starts(cold)
        written += save_figure(fig, figures_dir, PAPER, "vvs_cold")
        plt.close(fig)
    ind = load_run_if_present(Path(results_dir) / PAPER, "exp1_indirect")
    if exp1 is not None and ind is not None:
        fig = indirect_baseline(exp1, ind)
        written += save_figure(fig, figures_dir, PAPER, "baseline_indirect")
        plt.close(fig)
    return (written + make_exp3_figures(Path(results_dir), Path(figures_dir))
            + make_task_figures(Path(results_dir), Path(figures_dir)))
