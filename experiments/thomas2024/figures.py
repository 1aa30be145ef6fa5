"""thomas2024 figures, drawn only from the trace files under results/thomas2024/.

fig07, fig08, fig09 follow the paper's layout (Figs. 7-9): (a) e_4p components
[px], (b) joint velocities [rad/s], (c) CBFs of ring 1 [m], (d) CBFs of ring 2 [m],
all against time [s]. The ablations and the parallel-planes check are figures
the paper argues in words but does not show.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from repro.plots.style import PALETTE, apply_style, save_figure  # noqa: E402
from repro.runs.trace import RunFiles  # noqa: E402
from repro.runs.validate import load_run_if_present  # noqa: E402

PAPER = "thomas2024"
from experiments.thomas2024.columns import N_SENSORS  # noqa: E402

CBF_YLIM = (-0.03, 0.25)  # [m]: shows virtual contact; far readings (up to 0.96 m) are clipped


def _cbf_panel(ax: plt.Axes, df: pd.DataFrame, ring: int, title: str) -> None:
    t = df["t"].to_numpy()
    cols = [f"r{ring}_cbf{i}" for i in range(1, N_SENSORS + 1)]
    mins = df[cols].min()
    near = [c for c in cols if mins[c] < 0.05]
    for c in cols:
        if c not in near:
            ax.plot(t, df[c], color="0.8", lw=0.5)
    for k, c in enumerate(near):
        ax.plot(t, df[c], color=PALETTE[k % len(PALETTE)], lw=0.9,
                label=f"s{c.split('cbf')[1]}")
    ax.axhline(0.0, color="k", lw=0.6, ls="--")
    ax.set_ylim(*CBF_YLIM)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(r"$e_\delta$ (m)")
    ax.set_title(title)
    if near:
        ax.legend(ncol=3, fontsize=6, loc="upper right")


def four_panel(run: RunFiles, title: str) -> plt.Figure:
    """The paper's 4-panel layout for one run."""
    df = run.trace
    t = df["t"].to_numpy()
    fig, axes = plt.subplots(2, 2, figsize=(7.0, 4.8))
    ax = axes[0, 0]
    for i in range(4):
        ax.plot(t, df[f"e{i + 1}_u"], color=PALETTE[i], lw=0.9, label=f"$u_{i + 1}$")
        ax.plot(t, df[f"e{i + 1}_v"], color=PALETTE[i], lw=0.9, ls="--", label=f"$v_{i + 1}$")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(r"$e_{4p}$ (px)")
    ax.set_title("(a) visual task")
    ax.legend(ncol=4, fontsize=6)
    ax = axes[0, 1]
    for i in range(7):
        ax.plot(t, df[f"u{i + 1}"], color=PALETTE[i], lw=0.9, label=rf"$\dot q_{i + 1}$")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("joint velocity (rad/s)")
    ax.set_title("(b) control input")
    ax.legend(ncol=4, fontsize=6)
    _cbf_panel(axes[1, 0], df, 1, "(c) CBFs, ring 1")
    _cbf_panel(axes[1, 1], df, 2, "(d) CBFs, ring 2")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig


def ablation_no_proximity(with_cbf: RunFiles, without: RunFiles) -> plt.Figure:
    """Case 1 with and without the CBF constraints: true distance and visual error."""
    fig, axes = plt.subplots(1, 2, figsize=(7.0, 2.6))
    for run, label, color in ((with_cbf, "CBF-QP (eq. 10)", PALETTE[0]),
                              (without, "no proximity constraints", PALETTE[1])):
        df = run.trace
        axes[0].plot(df["t"], df["dist_min"], color=color, label=label)
        axes[1].plot(df["t"], df["e_norm"] * run.scene["cameras"]["camera"]["intrinsics"]["fu"],
                     color=color, label=label)
    axes[0].axhline(0.0, color="k", lw=0.6, ls="--")
    axes[0].set_ylabel("true min. distance robot-obstacles (m)")
    axes[1].set_ylabel(r"$\|e_{4p}\|$ (px, $\approx f_u\|e\|$)")
    for ax in axes:
        ax.set_xlabel("time (s)")
        ax.legend(fontsize=6)
    axes[0].set_title("(a) ground-truth clearance")
    axes[1].set_title("(b) visual error")
    fig.suptitle("Case 1 ablation: proximity constraints off (Sec. V-A)", fontsize=9)
    fig.tight_layout()
    return fig


def ablation_coarse(fine: RunFiles, coarse: RunFiles) -> plt.Figure:
    """Case 2 with model (5) vs (6) on ring 2: joint velocities and ring-2 CBFs."""
    fig, axes = plt.subplots(2, 2, figsize=(7.0, 4.8), sharex="col")
    for col, (run, label) in enumerate(((fine, "model (5), estimated normals"),
                                        (coarse, "model (6), coarse"))):
        df = run.trace
        for i in range(7):
            axes[0, col].plot(df["t"], df[f"u{i + 1}"], color=PALETTE[i], lw=0.8,
                              label=rf"$\dot q_{i + 1}$")
        axes[0, col].set_title(f"ring 2: {label}")
        axes[0, col].set_ylabel("joint velocity (rad/s)")
        _cbf_panel(axes[1, col], df, 2, "CBFs, ring 2")
    axes[0, 0].legend(ncol=4, fontsize=6)
    fig.suptitle("Case 2 ablation: interaction model of ring 2 (Sec. VI, eq. 24)", fontsize=9)
    fig.tight_layout()
    return fig


def parallel(run: RunFiles, noisy: RunFiles | None) -> plt.Figure:
    """Sec. VI eq. (20): goal between two parallel planes at the threshold."""
    fig, axes = plt.subplots(1, 3, figsize=(7.0, 2.4))
    runs = [(run, "noise-free", "-")] + ([(noisy, "2 mm noise", ":")] if noisy else [])
    for r, label, ls in runs:
        df = r.trace
        for i in (1, 10):
            axes[0].plot(df["t"], df[f"r2_cbf{i}"], ls=ls, label=f"s{i} {label}")
            axes[1].plot(df["t"], df[f"r2_kappa{i}"], ls=ls, label=f"s{i} {label}")
        axes[2].plot(df["t"], df["grad_L0"], ls=ls, label=label)
    axes[0].set_ylim(-0.02, 0.15)
    axes[0].set_ylabel(r"$e_\delta$ ring 2 (m)")
    axes[1].set_ylabel(r"$\kappa$")
    axes[1].set_yscale("symlog", linthresh=1e-3)
    axes[2].set_ylabel(r"$\|\nabla_u L(0,\kappa^*)\|$")
    axes[2].set_yscale("log")
    for ax in axes:
        ax.set_xlabel("time (s)")
        ax.legend(fontsize=5)
    fig.suptitle("Two parallel planes at the threshold, goal between them (Sec. VI, eq. 20)",
                 fontsize=9)
    fig.tight_layout()
    return fig


def make_figures(results_dir: Path, figures_dir: Path) -> list[Path]:
    """Draw every thomas2024 figure whose runs exist; returns the written files."""
    apply_style()
    base = Path(results_dir) / PAPER

    def load(name: str) -> RunFiles | None:
        return load_run_if_present(base, name)

    written: list[Path] = []
    for name, fig_name, title in (
        ("case1", "fig07", "Case 1: global convergence (cf. paper Fig. 7)"),
        ("case2", "fig08", "Case 2: local convergence, model (5) on ring 2 (cf. paper Fig. 8)"),
        ("case3", "fig09", "Case 3: dynamic obstacle (cf. paper Fig. 9)"),
        ("case1_no_proximity", "fig07_no_proximity", "Case 1 without proximity constraints"),
        ("case2_coarse", "fig08_coarse_model", "Case 2 with the coarse model (6) on ring 2"),
    ):
        run = load(name)
        if run is not None:
            fig = four_panel(run, title)
            written += save_figure(fig, figures_dir, PAPER, fig_name)
            plt.close(fig)
    c1, c1n = load("case1"), load("case1_no_proximity")
    if c1 and c1n:
        fig = ablation_no_proximity(c1, c1n)
        written += save_figure(fig, figures_dir, PAPER, "ablation_no_proximity")
        plt.close(fig)
    c2, c2c = load("case2"), load("case2_coarse")
    if c2 and c2c:
        fig = ablation_coarse(c2, c2c)
        written += save_figure(fig, figures_dir, PAPER, "ablation_coarse_model")
        plt.close(fig)
    par = load("parallel")
    if par:
        fig = parallel(par, load("parallel_noisy"))
        written += save_figure(fig, figures_dir, PAPER, "parallel_planes")
        plt.close(fig)
    return written


__all__ = ["make_figures", "four_panel", "np"]
