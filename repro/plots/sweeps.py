"""Sensitivity figures of the variant sweeps (issue 19, item 4), drawn from their files.

For every ``results/sweeps/<exp>/variants.csv``: per claim, one panel per (clause,
parameter): the clause's signed margin against the parameter's value, a held clause filled,
a failed one hollow, the bound at margin 0. Written to
``figures/<paper>/sweep_<exp>_claim<id>.png``.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from repro.plots.style import apply_style, save_figure  # noqa: E402
from repro.runs.sweep_rates import NOT_JUDGED  # noqa: E402

__all__ = ["sweep_figures"]


def _clause_names(sweep_dir: Path) -> dict[tuple[str, int], str]:
    from repro.runs.sweep_rates import _clause_names as names

    return names(sweep_dir)


def _clip_infinite(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(values with +-inf moved 10 % of the finite span beyond the finite extremes, the mask
    of the infinite ones): a margin of inf (a clause met by a drop) is drawn, not lost."""
    inf = np.isinf(y)
    fin = y[np.isfinite(y)]
    lo, hi = (float(fin.min()), float(fin.max())) if fin.size else (-1.0, 1.0)
    pad = 0.1 * (hi - lo) if hi > lo else 1.0
    out = y.copy()
    out[inf & (y > 0)] = hi + pad
    out[inf & (y < 0)] = lo - pad
    return out, inf


def sweep_figures(results_dir: Path, figures_dir: Path) -> list[Path]:
    """Draw every sweep's sensitivity figures; return the files written."""
    apply_style()
    written: list[Path] = []
    for csv in sorted((Path(results_dir) / "sweeps").glob("*/variants.csv")):
        meta = json.loads((csv.parent / "variants.columns.json").read_text(encoding="utf-8"))
        paper, exp = str(meta["experiment"]).split(".", 1)
        df = pd.read_csv(csv)
        df = df[~df["run_status"].isin(NOT_JUDGED)]
        params = [c for c in df.columns if c.startswith("p.")]
        names = _clause_names(csv.parent)
        claims = sorted({c.split(".", 1)[0][len("claim"):] for c in df.columns
                         if c.startswith("claim") and c.endswith(".status")})
        for cid in claims:
            ks = [k for k in range(1, 100) if f"claim{cid}.c{k}.margin" in df.columns]
            if not ks or not params:
                continue
            fig, axes = plt.subplots(len(ks), len(params), squeeze=False,
                                     figsize=(2.6 * len(params), 1.6 * len(ks) + 0.6))
            for r, k in enumerate(ks):
                margin = pd.to_numeric(df[f"claim{cid}.c{k}.margin"], errors="coerce")
                held = df[f"claim{cid}.c{k}.holds"].astype(str).str.lower().eq("true")
                y, infinite = _clip_infinite(margin.to_numpy(float))
                for c, p in enumerate(params):
                    ax = axes[r][c]
                    x = pd.to_numeric(df[p], errors="coerce").to_numpy(float)
                    for sel, marker in ((~infinite, "o"), (infinite, "^")):
                        h, f = sel & held.to_numpy(), sel & ~held.to_numpy()
                        ax.scatter(x[h], y[h], s=8 if marker == "o" else 14, marker=marker,
                                   color="C0")
                        ax.scatter(x[f], y[f], s=8 if marker == "o" else 14, marker=marker,
                                   facecolors="none", edgecolors="C3")
                    ax.axhline(0.0, color="0.5", lw=0.6, ls=":")
                    if r == len(ks) - 1:
                        ax.set_xlabel(p[2:], fontsize=7)
                    if c == 0:
                        ax.set_ylabel(f"c{k} margin", fontsize=7)
                    ax.tick_params(labelsize=6)
                axes[r][0].set_title(names.get((cid, k), f"clause {k}")[:70], fontsize=6,
                                     loc="left")
            fig.subplots_adjust(hspace=0.75)  # each row's clause title clear of the ticks above
            n = len(df)
            fig.suptitle(f"{paper} {exp}: claim {cid} over {n} judged variants (filled: the "
                         "clause holds; hollow: it fails)\ntriangles: an infinite margin (e.g. "
                         "a drop) drawn at the edge; a variant without the clause's figure is "
                         "not drawn", fontsize=8,
                         y=1.0 + 0.3 / fig.get_size_inches()[1])  # above the clause titles
            written += save_figure(fig, Path(figures_dir), paper, f"sweep_{exp}_claim{cid}")
            plt.close(fig)
        written += _cause_figure(csv.parent, Path(figures_dir), paper, exp)
    return written


#: one colour per cause class (issue 37), unknown in grey
CLASS_COLOURS = {"method": "C0", "ours-defect": "C3", "ours-range": "C1", "check": "C2",
                 "unknown": "0.6"}


def _cause_figure(sweep_dir: Path, figures_dir: Path, paper: str, exp: str) -> list[Path]:
    """Issue 37: per clause under the rate bar (cause_shares.csv), its failing variants as
    one bar split by named cause, coloured by class; ``figures/<paper>/sweep_<exp>_causes``."""
    path = sweep_dir / "cause_shares.csv"
    if not path.is_file():
        return []
    df = pd.read_csv(path, dtype={"claim": str}, keep_default_na=False)
    if df.empty:
        return []
    keys = list(dict.fromkeys(zip(df["claim"], df["clause"], strict=True)))
    fig, ax = plt.subplots(figsize=(9.0, 0.45 * len(keys) + 1.4))
    for y, (cid, clause) in enumerate(keys):
        mine = df[(df["claim"] == cid) & (df["clause"] == clause)]
        left = 0
        for r in mine.to_dict("records"):
            n = int(r["n"])
            ax.barh(y, n, left=left, color=CLASS_COLOURS.get(str(r["class"]), "0.3"),
                    edgecolor="white", lw=0.5)
            cf = (f" cf {float(r['cf_rate']):.2f}" if str(r["cf_rate"]) not in ("", "nan")
                  else "")
            ax.text(left + n / 2, y, f"{r['cause']}{cf}", ha="center", va="center", fontsize=5,
                    color="white" if str(r["class"]) != "unknown" else "black")
            left += n
        rate = mine["rate"].iloc[0]
        scope = mine["scope"].iloc[0]
        tag = "canonical only" if scope != "variants" else f"rate {float(rate):.2f}"
        ax.text(left, y, f"  {tag}", va="center", fontsize=6)
    ax.set_yticks(range(len(keys)), [f"claim {c}: {n[:60]}" for c, n in keys], fontsize=6)
    ax.invert_yaxis()
    ax.set_xlabel("failing variants", fontsize=7)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in CLASS_COLOURS.values()]
    ax.legend(handles, list(CLASS_COLOURS), fontsize=6, loc="lower right", frameon=False)
    ax.set_title(f"{paper} {exp}: why each clause fails over the sweep's variants (cf: the "
                 "counterfactual's rate, the cause removed)", fontsize=8, loc="left")
    out = save_figure(fig, figures_dir, paper, f"sweep_{exp}_causes")
    plt.close(fig)
    return out
