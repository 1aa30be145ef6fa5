"""pomares2011 figures from the traces (experiment 1: Figs. 5-7)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from experiments.pomares2011.columns import N_POINTS  # noqa: E402
from repro.plots.style import PALETTE, apply_style, save_figure  # noqa: E402
from repro.runs.trace import RunFiles, load_run_if_present  # noqa: E402

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


def torques(run: RunFiles, title: str) -> plt.Figure:
    """The mini-robot's joint torques vs time, with the instant s = s* marked ('1')."""
    df = run.trace
    t = df["t"].to_numpy(float)
    fig, ax = plt.subplots(figsize=(3.6, 2.6))
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
                                  "(cf. Fig. 7)"), "fig07")):
            written += save_figure(fig, figures_dir, PAPER, name)
            plt.close(fig)
    return written
