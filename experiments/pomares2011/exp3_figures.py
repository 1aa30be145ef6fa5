"""pomares2011 experiment 3 figures from the run folders (never the simulator): Fig. 11
(rendered frames of the closing and the manipulation), Fig. 12 (a: motor counts, b: maximum
pressure per finger with the thresholds), the object's pose over time, the pressure images at
chosen instants, and the ablation without tactile control."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import imageio.v2 as imageio  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from repro.plots.style import PALETTE, apply_style, save_figure  # noqa: E402
from repro.runs.trace import RunFiles  # noqa: E402
from repro.runs.validate import load_run_if_present  # noqa: E402

PAPER = "pomares2011"
FINGERS = (1, 2, 3)
PADS = ("palm", "finger1_proximal", "finger1_distal", "finger2_proximal", "finger2_distal",
        "finger3_proximal", "finger3_distal")
PHASE_SHADE = {"closing": "0.93", "support": "0.86", "stopped": "#f6dcdc", "done": "#dcefdc"}


def _t(df: pd.DataFrame) -> np.ndarray:
    return df["t"].to_numpy(float)


def _phase_times(df: pd.DataFrame) -> dict[str, float]:
    """First time of each phase [s]."""
    phase = df["phase"].fillna("").astype(str).to_numpy()
    t = _t(df)
    out: dict[str, float] = {}
    for k, ph in enumerate(phase):
        out.setdefault(ph, float(t[k]))
    return out


def _shade(ax: plt.Axes, df: pd.DataFrame) -> None:
    """Shade the closing, support and end phases (the manipulation stays white)."""
    phase = df["phase"].fillna("").astype(str).to_numpy()
    t = _t(df)
    edges = np.flatnonzero(np.r_[True, phase[1:] != phase[:-1]])
    for i, k0 in enumerate(edges):
        k1 = edges[i + 1] if i + 1 < len(edges) else len(t) - 1
        colour = PHASE_SHADE.get(phase[k0])
        if colour:
            ax.axvspan(t[k0], t[k1], color=colour, lw=0, zorder=0)


def _readjust_times(df: pd.DataFrame, k: int) -> np.ndarray:
    dec = df[f"alg_decision{k}"].fillna("").astype(str).to_numpy()
    return _t(df)[np.isin(dec, ("readjust", "readjust_blocked_torque"))]


def _end_marker(ax: plt.Axes, run: RunFiles) -> None:
    ev = run.events
    for kind, ls, label in (("tactile_stop", "-", "stop (line 13)"),
                            ("trajectory_done", "-.", "trajectory done")):
        hit = ev[ev["kind"] == kind]
        if len(hit):
            ax.axvline(float(hit["t"].iloc[0]), color="k", ls=ls, lw=0.8, label=label)


def snapshot_montage(run: RunFiles, run_dir: Path, wanted: list[tuple[float, str]], title: str,
                     figsize: tuple[float, float] = (7.0, 3.1), crop: float = 0.0
                     ) -> plt.Figure | None:
    """Eight rendered snapshots of ``run_dir/frames`` in a 2 x 4 grid: for each ``(t [s],
    label)`` of ``wanted`` the snapshot nearest to ``t``, its left and right ``crop`` fraction
    cut off. None without snapshots."""
    files = sorted((run_dir / "frames").glob("scene_*.png"))
    if not files:
        return None
    dt = float(run.scene["world"]["control_dt"])
    steps = np.array([int(f.stem.split("_")[1]) for f in files])
    fig, axes = plt.subplots(2, 4, figsize=figsize)
    for i, (ax, (tw, label)) in enumerate(zip(np.ravel(axes), wanted, strict=True)):
        j = int(np.argmin(np.abs(steps * dt - tw)))
        img = imageio.imread(files[j])
        w = img.shape[1]
        ax.imshow(img[:, int(crop * w):int((1.0 - crop) * w)])
        ax.set_title(f"{i + 1}: t = {steps[j] * dt:.1f} s\n{label}", fontsize=6.5)
        ax.axis("off")
    fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    return fig


def fig11(run: RunFiles, run_dir: Path) -> plt.Figure | None:
    """Fig. 11: eight rendered frames, 1-4 the automatic closing and the support going away,
    5-8 the manipulation (start, 1/3, 2/3, end), the nearest snapshots to those instants."""
    df = run.trace
    ph = _phase_times(df)
    cfg = run.manifest.get("config", {})
    t_closed = ph.get("support", float(_t(df)[-1]))
    t_down = t_closed + float(cfg.get("support_delay_s", 0.0)) + float(
        cfg.get("support_drop_m", 0.0)) / float(cfg.get("support_speed_m_s", 1.0))
    t_m = ph.get("manipulation", t_down)
    t_end = ph.get("stopped", ph.get("done", float(_t(df)[-1])))
    wanted = [(0.0, "pre-shape"), (0.5 * t_closed, "closing"), (t_closed, "all fingers touch"),
              (t_down, "support lowered"), (t_m, "manipulation starts"),
              (t_m + (t_end - t_m) / 3, "manipulation"), (t_m + 2 * (t_end - t_m) / 3,
                                                          "manipulation"),
              (t_end, "stop" if "stopped" in ph else "trajectory done")]
    return snapshot_montage(run, run_dir, wanted, "Exp. 3 (cf. Fig. 11): finger 3 left, "
                            "fingers 1-2 right; the cylinder is moved towards fingers 1-2",
                            crop=0.12)


def fig12(run: RunFiles) -> plt.Figure:
    """Fig. 12: (a) motor counts per finger, (b) maximum contact pressure per finger with the
    readjustment thresholds (dashed, finger colours) and the safety threshold (dotted);
    readjustments marked on (b)."""
    df = run.trace
    t = _t(df)
    cfg = run.manifest.get("config", {})
    thr = cfg.get("readjust_threshold_kpa", (10.0, 10.0, 20.0))
    safety = cfg.get("safety_threshold_kpa", (10.0, 10.0, 10.0))
    fig, (a, b) = plt.subplots(2, 1, figsize=(4.6, 4.4), sharex=True)
    for ax in (a, b):
        _shade(ax, df)
    for k in FINGERS:
        c = PALETTE[k - 1]
        a.plot(t, df[f"counts{k}"] / 1e3, color=c, lw=0.9, label=f"finger {k}")
        b.plot(t, df[f"p{k}"], color=c, lw=0.7, label=f"finger {k}")
        b.axhline(float(thr[k - 1]), color=c, ls="--", lw=0.7)
        tr = _readjust_times(df, k)
        if tr.size:
            b.plot(tr, np.full(tr.size, -2.0 - 2.0 * k), "|", color=c, ms=4, mew=0.6)
    b.axhline(float(min(safety)), color="k", ls=":", lw=0.8, label="safety threshold")
    _end_marker(a, run)
    _end_marker(b, run)
    a.set_ylabel("motor counts (x 1000)")
    a.set_title("(a) motor counts (cf. Fig. 12a)")
    a.legend(fontsize=6, ncol=2)
    b.set_ylabel("max pressure (kPa)")
    b.set_xlabel("time (s)")
    b.set_title("(b) maximum contact pressure; dashed: readjust thresholds; ticks below 0: "
                "readjustments", fontsize=7)
    top = float(np.nanmax(df[[f"p{k}" for k in FINGERS]].to_numpy(float)))
    b.set_ylim(-9.0, max(25.0, 1.1 * top))
    b.legend(fontsize=6, ncol=2, loc="upper left")
    fig.tight_layout()
    return fig


def object_pose(run: RunFiles) -> plt.Figure:
    """The cylinder in the palm frame from the start of the manipulation: displacement
    against the plan, rotation, finger contacts, and the force audit (raw contact forces vs
    the pressure maps)."""
    df = run.trace
    t = _t(df)
    fig, axes = plt.subplots(3, 1, figsize=(4.6, 5.2), sharex=True)
    for ax in axes:
        _shade(ax, df)
    ax = axes[0]
    for a, c in zip("xyz", PALETTE, strict=False):
        ax.plot(t, df[f"obj_d{a}"] * 1e3, color=c, lw=0.9, label=f"d{a}")
    ax.plot(t, df["plan_dy"] * 1e3, color=PALETTE[1], ls="--", lw=0.8, label="planned dy")
    _end_marker(ax, run)
    ax.set_ylabel("displacement (mm)")
    ax.set_title("cylinder centre in the palm frame, from its pose at the start of the "
                 "manipulation", fontsize=7)
    ax.legend(fontsize=6, ncol=3)
    ax = axes[1]
    ax.plot(t, np.degrees(df["obj_rot"].to_numpy(float)), color=PALETTE[3], lw=0.9,
            label="rotation (deg; mostly rolling about its axis)")
    ax.plot(t, np.degrees(df["obj_axis_tilt"].to_numpy(float)), color=PALETTE[4], lw=0.9,
            label="axis tilt (deg)")
    for k in FINGERS:
        on = df[f"contact{k}"].fillna(False).astype(bool).to_numpy()
        ax.plot(t, np.where(on, -2.0 * k, np.nan), color=PALETTE[k - 1], lw=2.0,
                label=f"finger {k} touches")
    ax.set_ylabel("deg / contact")
    ax.legend(fontsize=6, ncol=2)
    ax = axes[2]
    ax.plot(t, df["F_raw_total"], color="k", lw=0.9, label="raw contact forces (audit)")
    ax.plot(t, df["Fmap_total"], color=PALETTE[4], lw=0.9, label="from the pressure maps")
    for k in FINGERS:
        ax.plot(t, df[f"F_raw{k}"], color=PALETTE[k - 1], lw=0.6, ls="--",
                label=f"raw, finger {k}")
    ax.set_ylabel("normal force (N)")
    ax.set_xlabel("time (s)")
    ax.legend(fontsize=5.5, ncol=2)
    fig.tight_layout()
    return fig


def pressure_images(run_dir: Path) -> plt.Figure | None:
    """The seven pads' reported pressure maps at the chosen instants of pressure_images.npz
    (rows along each pad's x, towards the fingertip, drawn upwards; the distal's tip cell
    above its grid)."""
    path = run_dir / "pressure_images.npz"
    if not path.exists():
        return None
    z = np.load(path)
    t = z["t_s"]
    inst = {str(n): float(v) for n, v in zip(z["instant_names"], z["instant_t_s"],
                                              strict=True)}
    firsts = sorted((tt, n) for n, tt in inst.items() if n.startswith("first_readjust"))
    order = ["grasp", "manipulation_start"] + [n for _, n in firsts[:1]] + [
        n for n in ("stopped", "done", "end") if n in inst]
    keep = [(n, inst[n]) for n in order if n in inst]
    if not keep or not len(t):
        return None
    vmax = max(1.0, max(float(z[p].max()) for p in PADS))
    fig, axes = plt.subplots(len(keep), len(PADS), figsize=(6.0, 1.05 * len(keep) + 0.6),
                             squeeze=False)
    im = None
    for r, (name, tt) in enumerate(keep):
        j = int(np.searchsorted(t, tt - 1e-9))
        j = min(j, len(t) - 1)
        for c, pad in enumerate(PADS):
            rows, cols = int(z[f"{pad}_rows"]), int(z[f"{pad}_cols"])
            pr = z[pad][j]
            img = np.full((rows + (1 if pad.endswith("distal") else 0), cols), np.nan)
            img[:rows] = pr[:rows * cols].reshape(rows, cols)
            if pad.endswith("distal"):
                img[rows, cols // 2] = pr[rows * cols]
            ax = axes[r, c]
            im = ax.imshow(img, origin="lower", vmin=0.0, vmax=vmax, cmap="viridis")
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(pad.replace("finger", "f").replace("_", "\n"), fontsize=6)
            if c == 0:
                ax.set_ylabel(f"{name}\nt = {t[j]:.2f} s", fontsize=6)
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.8, label="kPa")
    fig.suptitle("Pressure images at chosen instants (reported, 0.7 kPa steps)", fontsize=8)
    return fig


def ablation(run: RunFiles, base: RunFiles) -> plt.Figure:
    """With and without tactile control: the cylinder's deviation from the planned path and
    the finger pressures against the thresholds."""
    fig, axes = plt.subplots(2, 2, figsize=(7.0, 4.2), sharex="col")
    for c, (r, title) in enumerate(((run, "with Algorithm 1"),
                                    (base, "without tactile control"))):
        df = r.trace
        t = _t(df)
        dev = np.sqrt(df["obj_dx"].to_numpy(float) ** 2 + (df["obj_dy"].to_numpy(float)
                      - df["plan_dy"].fillna(0.0).to_numpy(float)) ** 2
                      + df["obj_dz"].to_numpy(float) ** 2)
        ax = axes[0, c]
        _shade(ax, df)
        ax.plot(t, dev * 1e3, color="k", lw=0.9, label="|deviation from plan|")
        ax.plot(t, df["obj_dz"] * 1e3, color=PALETTE[2], lw=0.8, label="dz (out of the palm)")
        ax.plot(t, (df["obj_dy"] - df["plan_dy"]) * 1e3, color=PALETTE[1], lw=0.8,
                label="dy - planned dy")
        drop = df["dropped"].fillna(False).astype(bool).to_numpy()
        if drop.any():
            ax.axvline(t[np.argmax(drop)], color="r", lw=1.0, label="dropped")
        _end_marker(ax, r)
        ax.set_title(title, fontsize=8)
        ax.set_ylabel("mm")
        ax.legend(fontsize=5.5)
        ax = axes[1, c]
        _shade(ax, df)
        thr = r.manifest.get("config", {}).get("readjust_threshold_kpa", (10.0, 10.0, 20.0))
        for k in FINGERS:
            ax.plot(t, df[f"p{k}"], color=PALETTE[k - 1], lw=0.7, label=f"finger {k}")
            ax.axhline(float(thr[k - 1]), color=PALETTE[k - 1], ls="--", lw=0.6)
        ax.set_ylabel("max pressure (kPa)")
        ax.set_xlabel("time (s)")
        ax.legend(fontsize=6)
    fig.suptitle("Ablation: the same trajectory with and without tactile control", fontsize=9)
    fig.tight_layout()
    return fig


def make_exp3_figures(results_dir: Path, figures_dir: Path) -> list[Path]:
    """Every experiment-3 figure whose runs exist under ``results_dir / pomares2011``."""
    apply_style()
    written: list[Path] = []
    base_dir = Path(results_dir) / PAPER
    run = load_run_if_present(base_dir, "exp3")
    base = load_run_if_present(base_dir, "exp3_no_tactile")
    figs: list[tuple[plt.Figure | None, str]] = []
    if run is not None:
        figs += [(fig11(run, base_dir / "exp3"), "fig11"), (fig12(run), "fig12"),
                 (object_pose(run), "exp3_object_pose"),
                 (pressure_images(base_dir / "exp3"), "exp3_pressure_images")]
    if run is not None and base is not None:
        figs.append((ablation(run, base), "exp3_ablation"))
    for fig, name in figs:
        if fig is None:
            continue
        written += save_figure(fig, figures_dir, PAPER, name)
        plt.close(fig)
    return written
