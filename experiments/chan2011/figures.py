"""chan2011 figures, drawn only from the files under results/chan2011/."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import imageio.v2 as imageio  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from experiments.chan2011.columns import scene_limits, target_points_world  # noqa: E402
from repro.plots.style import PALETTE, apply_style, save_figure  # noqa: E402
from repro.runs.trace import RunFiles, load_run  # noqa: E402
from repro.runs.validate import load_run_if_present  # noqa: E402

PAPER = "chan2011"
from experiments.chan2011.columns import N_POINTS as N  # noqa: E402

COLORS = [plt.get_cmap("tab10")(i) for i in range(N)]


def _pixels(run: RunFiles) -> tuple[np.ndarray, np.ndarray]:
    df = run.trace
    u = df[[f"p{j}_u" for j in range(1, N + 1)]].to_numpy(float)
    v = df[[f"p{j}_v" for j in range(1, N + 1)]].to_numpy(float)
    return u, v


def _image_axes(ax: plt.Axes, run: RunFiles) -> None:
    tab = run.scene["controller_model"]["table_I"]
    w = run.scene["cameras"]["camera"]["intrinsics"]["width"]
    h = run.scene["cameras"]["camera"]["intrinsics"]["height"]
    ax.add_patch(plt.Rectangle((tab["u_min"], tab["v_min"]), tab["u_max"] - tab["u_min"],
                               tab["v_max"] - tab["v_min"], fill=False, ls=":", lw=0.8))
    ax.set_xlim(-150, w + 150)
    ax.set_ylim(h + 150, -150)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")


def image_trajectory(run: RunFiles, title: str, ax: plt.Axes | None = None) -> plt.Figure:
    """Fig. 3: feature trajectories; initial 'o', desired 'x'."""
    fig = ax.figure if ax is not None else plt.figure(figsize=(4.2, 3.4))
    ax = ax or fig.add_subplot(111)
    u, v = _pixels(run)
    pd_ = np.asarray(run.scene["desired_pixels"], float)
    for j in range(N):
        ax.plot(u[:, j], v[:, j], color=COLORS[j], lw=0.8)
        ax.plot(u[0, j], v[0, j], "o", mfc="none", color=COLORS[j], ms=4)
        ax.plot(pd_[j, 0], pd_[j, 1], "x", color=COLORS[j], ms=5)
    _image_axes(ax, run)
    ax.set_title(title)
    return fig  # type: ignore[return-value]


def camera_trajectory(run: RunFiles) -> plt.Figure:
    """Fig. 4: the camera's Cartesian trajectory (base frame)."""
    df = run.trace
    fig = plt.figure(figsize=(4.2, 3.6))
    ax = fig.add_subplot(111, projection="3d")
    ax.plot(df["camera_x"], df["camera_y"], df["camera_z"], color=PALETTE[0])
    ax.scatter(df["camera_x"].iloc[0], df["camera_y"].iloc[0], df["camera_z"].iloc[0], marker="o",
               color=PALETTE[1], label="start")
    ax.scatter(df["camera_x"].iloc[-1], df["camera_y"].iloc[-1], df["camera_z"].iloc[-1], marker="x",
               color=PALETTE[2], label="end")
    P = target_points_world(run.scene)
    ax.scatter(P[:, 0], P[:, 1], P[:, 2], s=4, color="k", label="target points")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.legend(fontsize=6)
    ax.set_title("Camera trajectory (cf. paper Fig. 4)")
    return fig


def joints(run: RunFiles, velocity: bool) -> plt.Figure:
    """Fig. 5 (positions, deg) or Fig. 6 (velocities, deg/s) with the limits dotted."""
    df = run.trace
    lim = scene_limits(run.scene)
    fig, axes = plt.subplots(2, 3, figsize=(7.0, 3.6), sharex=True)
    for i, ax in enumerate(axes.ravel()):
        if velocity:
            ax.plot(df["t"], np.rad2deg(df[f"u{i + 1}"]), color=PALETTE[0], lw=0.9,
                    label="commanded")
            ax.plot(df["t"], np.rad2deg(df[f"qd{i + 1}"]), color=PALETTE[1], lw=0.6,
                    label="measured")
            m = np.rad2deg(lim["qd_max_used"][i])
            ax.axhline(m, ls=":", color="k", lw=0.8)
            ax.axhline(-m, ls=":", color="k", lw=0.8)
            ax.set_ylabel(f"qd{i + 1} (deg/s)")
        else:
            ax.plot(df["t"], np.rad2deg(df[f"q{i + 1}"]), color=PALETTE[0], lw=0.9)
            ax.axhline(np.rad2deg(lim["q_min"][i]), ls=":", color="k", lw=0.8)
            ax.axhline(np.rad2deg(lim["q_max"][i]), ls=":", color="k", lw=0.8)
            ax.set_ylabel(f"q{i + 1} (deg)")
        if i >= 3:
            ax.set_xlabel("time (s)")
    if velocity:
        axes[0, 0].legend(fontsize=6)
    fig.suptitle(("Joint velocities with limits (cf. paper Fig. 6)" if velocity
                  else "Joint positions with limits (cf. paper Fig. 5)"), fontsize=9)
    fig.tight_layout()
    return fig


def frames(run_dir: Path, prefix: str, title: str) -> plt.Figure | None:
    """Figs. 12-13: the saved snapshots of a run, in a grid."""
    files = sorted((run_dir / "frames").glob(f"{prefix}_*.png"))
    if not files:
        return None
    if len(files) > 12:  # twelve frames evenly spread over the run, like the paper's
        files = [files[i] for i in np.linspace(0, len(files) - 1, 12).round().astype(int)]
    cols = 4
    rows = int(np.ceil(len(files) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(7.0, 1.45 * rows * 1.1))
    for ax in np.ravel(axes):
        ax.axis("off")
    dt = None
    for ax, f in zip(np.ravel(axes), files, strict=False):
        ax.imshow(imageio.imread(f))
        step = int(f.stem.split("_")[1])
        if dt is None:
            dt = load_run(run_dir).manifest["config"]["dt"]
        ax.set_title(f"t = {step * dt:.1f} s", fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig


def baselines(runs: dict[str, RunFiles]) -> plt.Figure:
    """IBVS, IBVS + saturator and NMPC on the simulation task: which constraint breaks."""
    fig, axes = plt.subplots(2, len(runs), figsize=(7.0, 4.6))
    for c, (name, run) in enumerate(runs.items()):
        image_trajectory(run, name, axes[0, c])
        df = run.trace
        lim = scene_limits(run.scene)
        for i in range(6):
            span = (np.asarray(lim["q_max"]) - np.asarray(lim["q_min"]))[i]
            frac = (df[f"q{i + 1}"] - lim["q_min"][i]) / span
            axes[1, c].plot(df["t"], frac, lw=0.8, label=f"q{i + 1}")
        axes[1, c].axhline(0, ls=":", color="k")
        axes[1, c].axhline(1, ls=":", color="k")
        axes[1, c].set_xlabel("time (s)")
        axes[1, c].set_ylabel("q in its range (0-1)")
        reason = run.manifest.get("reason", "")
        axes[1, c].set_title(reason[:40], fontsize=6)
    axes[1, 0].legend(fontsize=5, ncol=2)
    fig.suptitle("Baselines on the simulation task (paper Sec. III-B motivation)", fontsize=9)
    fig.tight_layout()
    return fig


def distances(run: RunFiles) -> plt.Figure:
    """Experiment: true distance to each obstacle, DCC failures, joint speed."""
    df = run.trace
    t = df["t"].to_numpy()
    fig, axes = plt.subplots(2, 1, figsize=(7.0, 4.0), sharex=True)
    for k, c in enumerate(c for c in df.columns if c.startswith("dist_") and c != "dist_min"):
        axes[0].plot(t, df[c], color=PALETTE[k % len(PALETTE)], label=c[5:])
    box = df["dcc_box"].astype(bool).to_numpy()
    for ax in axes:
        ymin, ymax = ax.get_ylim()
        ax.fill_between(t, 0, 1, where=box, transform=ax.get_xaxis_transform(),
                        color="0.85", label="DCC failed: bisection bounds")
    axes[0].set_ylabel("true distance (m)")
    axes[0].legend(fontsize=6, ncol=3)
    speed = np.linalg.norm(df[[f"qd{i}" for i in range(1, 7)]].to_numpy(float), axis=1)
    axes[1].plot(t, speed, color=PALETTE[0])
    axes[1].set_ylabel("||qd|| (rad/s)")
    axes[1].set_xlabel("time (s)")
    fig.suptitle("Experiment: clearance to the obstacles and DCC", fontsize=9)
    fig.tight_layout()
    return fig


def make_figures(results_dir: Path, figures_dir: Path) -> list[Path]:
    apply_style()
    base = Path(results_dir) / PAPER

    def load(name: str) -> RunFiles | None:
        return load_run_if_present(base, name)

    written: list[Path] = []

    def save(fig: plt.Figure | None, name: str) -> None:
        nonlocal written
        if fig is not None:
            written += save_figure(fig, figures_dir, PAPER, name)
            plt.close(fig)

    sim = load("simulation")
    if sim:
        save(image_trajectory(sim, "Image trajectory (cf. paper Fig. 3)"), "fig03")
        save(camera_trajectory(sim), "fig04")
        save(joints(sim, velocity=False), "fig05")
        save(joints(sim, velocity=True), "fig06")
    exp = load("experiment")
    if exp:
        save(frames(base / "experiment", "camera", "Camera images during the approach "
                    "(cf. paper Fig. 12)"), "fig12")
        save(frames(base / "experiment", "scene", "Robot motion (cf. paper Fig. 13)"), "fig13")
        save(distances(exp), "experiment_distances")
        save(image_trajectory(exp, "Experiment: image trajectory"), "experiment_image")
    runs = {n: r for n in ("ibvs", "ibvs_saturated", "simulation") if (r := load(n))}
    if len(runs) >= 2:
        save(baselines(runs), "baselines")
    return written
