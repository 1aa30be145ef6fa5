"""The whole task (Table 1) from its trace: the phases of the three robots over time."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from experiments.pomares2011.exp3_figures import (  # noqa: E402
    FINGERS,
    _readjust_times,
    snapshot_montage,
)
from repro.plots.style import PALETTE, apply_style, save_figure  # noqa: E402
from repro.runs.trace import RunFiles  # noqa: E402
from repro.runs.validate import load_run_if_present  # noqa: E402

PAPER = "pomares2011"
#: Shading of the hand's phases (the approach stays white).
HAND_SHADE = {"preshape": "#e8eef8", "closing": "0.93", "support": "0.86",
              "manipulation": "#fff6e0", "stopped": "#f6dcdc", "done": "#dcefdc"}
PA10_QD = tuple(f"pa10_qd{i}" for i in range(1, 7))


def _spans(t: np.ndarray, labels: np.ndarray) -> list[tuple[str, float, float]]:
    """(label, t0, t1) of each run of equal labels."""
    edges = np.flatnonzero(np.r_[True, labels[1:] != labels[:-1]])
    out = []
    for i, k0 in enumerate(edges):
        k1 = edges[i + 1] if i + 1 < len(edges) else len(t) - 1
        out.append((str(labels[k0]), float(t[k0]), float(t[k1])))
    return out


def _shade(ax: plt.Axes, df: pd.DataFrame, t_manip: float | None) -> None:
    t = df["t"].to_numpy(float)
    for label, t0, t1 in _spans(t, df["phase"].fillna("").astype(str).to_numpy()):
        colour = HAND_SHADE.get(label)
        if colour:
            ax.axvspan(t0, t1, color=colour, lw=0, zorder=0)
    if t_manip is not None:
        ax.axvline(t_manip, color="k", lw=0.8, ls="--")


def phases(run: RunFiles) -> plt.Figure:
    """(a) the RVC and camera errors, (b) the PA-10's largest joint speed, (c) the mini-robot's
    torques, (d) the motor counts per finger and (e) the maximum pressure per finger with the
    thresholds, over time; the hand's phases shaded, the end of the approach dashed."""
    df = run.trace
    t = df["t"].to_numpy(float)
    ev = run.events
    hit = ev[ev["kind"] == "task_manipulation"]
    t_manip = float(hit["t"].iloc[0]) if len(hit) else None
    cfg = run.manifest["config"]
    fig, axes = plt.subplots(5, 1, figsize=(6.4, 8.2), sharex=True)
    ax = axes[0]
    ax.semilogy(t, df["e_u_px"].to_numpy(float), color=PALETTE[0], lw=0.9,
                label="RVC error (s_u - s_u*)")
    ax.semilogy(t, df["e_s_px"].to_numpy(float), color=PALETTE[1], lw=0.9,
                label="camera error (s - s*)")
    ax.axhline(float(cfg["arm_stop_px"]), color="0.4", lw=0.6, ls=":")
    ax.set_ylabel("RMS error (px)")
    ax.legend(fontsize=6, loc="upper right")
    ax = axes[1]
    qd = np.abs(df[list(PA10_QD)].to_numpy(float)).max(axis=1)
    ax.semilogy(t, np.maximum(qd, 1e-9), color=PALETTE[2], lw=0.9)
    ax.set_ylabel("PA-10 max |qd|\n(rad/s)")
    ax = axes[2]
    for i in range(3):
        ax.plot(t, df[f"mini_u{i + 1}"].to_numpy(float), color=PALETTE[i], lw=0.8,
                label=f"tau{i + 1}")
    ax.set_ylabel("mini-robot\ntorque (N m)")
    ax.legend(fontsize=6, ncol=3, loc="upper right")
    ax = axes[3]
    for k in FINGERS:
        ax.plot(t, df[f"counts{k}"].to_numpy(float), color=PALETTE[k - 1], lw=0.9,
                label=f"finger {k}")
    ax.set_ylabel("motor counts")
    ax.legend(fontsize=6, ncol=3, loc="upper left")
    ax = axes[4]
    thr = cfg["readjust_threshold_kpa"]
    for k in FINGERS:
        ax.plot(t, df[f"p{k}"].to_numpy(float), color=PALETTE[k - 1], lw=0.8,
                label=f"finger {k}")
        ax.axhline(float(thr[k - 1]), color=PALETTE[k - 1], lw=0.6, ls=":")
        r = _readjust_times(df, k)
        if len(r):
            ax.plot(r, np.full(len(r), -2.0 - k), "|", color=PALETTE[k - 1], ms=4)
    ax.set_ylabel("max pressure (kPa)")
    ax.set_xlabel("t (s)")
    ax.legend(fontsize=6, ncol=3, loc="upper left")
    for a in axes:
        _shade(a, df, t_manip)
    axes[0].set_title("Whole task (Table 1): approach (white), then manipulation (dashed line: "
                      "s_u* reached)\nhand: pre-shape (blue), closing, support away, "
                      "trajectory (yellow), stopped (red)", fontsize=8)
    fig.tight_layout()
    return fig


def frames(run: RunFiles, run_dir: Path) -> plt.Figure | None:
    """Eight rendered snapshots of the whole task, the nearest to: the start, a third and two
    thirds of the approach, the arm's stop, the fingers' first contact, the support lowered,
    the middle of the trajectory and the end of the hand's task."""
    df = run.trace
    t = df["t"].to_numpy(float)
    first: dict[str, float] = {}
    for k, ph in enumerate(df["phase"].fillna("").astype(str).to_numpy()):
        first.setdefault(ph, float(t[k]))
    t_m = first.get("preshape", float(t[-1]))
    t_s, t_traj = first.get("support", t_m), first.get("manipulation", t_m)
    t_end = first.get("stopped", first.get("done", float(t[-1])))
    wanted = [(0.0, "start"), (t_m / 3, "approach"), (2 * t_m / 3, "approach"),
              (t_m, "s_u* reached"), (t_s, "grasp closed"), (t_traj, "support lowered"),
              (0.5 * (t_traj + t_end), "trajectory"), (t_end, "end of the hand's task")]
    period = float(run.manifest["config"].get("snapshot_period", 0.0))
    return snapshot_montage(run, run_dir, wanted, "Whole task (Table 1): approach, then "
                            f"manipulation (snapshots every {period:g} s)", figsize=(7.0, 3.6))


def make_task_figures(results_dir: Path, figures_dir: Path) -> list[Path]:
    """The whole-task figures, if its run exists under ``results_dir / pomares2011``."""
    apply_style()
    run_dir = Path(results_dir) / PAPER / "task"
    run = load_run_if_present(Path(results_dir) / PAPER, "task")
    if run is None:
        return []
    out: list[Path] = []
    for fig, name in ((phases(run), "task_phases"), (frames(run, run_dir), "task_frames")):
        if fig is None:
            continue
        out += save_figure(fig, figures_dir, PAPER, name)
        plt.close(fig)
    return out
