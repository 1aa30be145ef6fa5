"""One figure style for the whole suite, and deterministic figure files.

Figures are regenerated from the traces and committed, so :func:`save_figure` strips the
timestamps and version strings matplotlib puts in PNG/PDF metadata: regenerating an unchanged
figure gives byte-identical files (for a given matplotlib version).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import matplotlib as mpl
from matplotlib.figure import Figure

from repro.errors import ConfigError

__all__ = ["PALETTE", "PNG_DPI", "STYLE", "apply_style", "save_figure"]

PNG_DPI = 150

PALETTE = (
    "#0072B2",  # blue
    "#D55E00",  # vermillion
    "#009E73",  # bluish green
    "#E69F00",  # orange
    "#CC79A7",  # reddish purple
    "#56B4E9",  # sky blue
    "#F0E442",  # yellow
    "#000000",  # black
)
"""Okabe-Ito colour-blind-safe colours, in cycle order."""

STYLE: dict[str, Any] = {
    "figure.figsize": (3.5, 2.6),  # in; one column of a two-column paper
    "figure.dpi": 100,
    "savefig.dpi": PNG_DPI,
    "savefig.bbox": "tight",
    "savefig.pad_inches": 0.02,
    "font.family": "sans-serif",
    "font.sans-serif": ["DejaVu Sans"],  # ships with matplotlib: same glyphs on every machine
    "font.size": 8,
    "axes.titlesize": 8,
    "axes.labelsize": 8,
    "xtick.labelsize": 7,
    "ytick.labelsize": 7,
    "legend.fontsize": 7,
    "legend.frameon": False,
    "axes.grid": True,
    "grid.linewidth": 0.4,
    "grid.alpha": 0.4,
    "axes.linewidth": 0.6,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.prop_cycle": mpl.cycler(color=list(PALETTE)),  # type: ignore[attr-defined]
    "lines.linewidth": 1.2,
    "lines.markersize": 3,
    "xtick.major.width": 0.6,
    "ytick.major.width": 0.6,
    "pdf.fonttype": 42,  # TrueType: text stays editable/searchable in the PDF
    "ps.fonttype": 42,
    "svg.hashsalt": "repro",
}
"""rcParams set by apply_style (the backend is left alone: saving works under Agg)."""

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


def apply_style() -> None:
    """Set the suite's rcParams (small fonts, grid, colour-blind-safe cycle).

    Does not select a backend and never opens a window, so it is safe under Agg / headless.
    """
    mpl.rcParams.update(STYLE)  # type: ignore[arg-type]


def save_figure(fig: Figure, figures_dir: Path, paper: str, name: str) -> list[Path]:
    """Write ``<figures_dir>/<paper>/<name>.png`` (150 dpi) and ``.pdf``; return both paths.

    The metadata carrying dates and software versions is removed so unchanged figures do not
    churn in git. The figure is not closed.

    Raises:
        ConfigError: if paper or name is not a plain file name ([A-Za-z0-9_.-], no slash).
    """
    for label, value in (("paper", paper), ("figure name", name)):
        if not isinstance(value, str) or not _NAME.match(value) or value.endswith((".png", ".pdf")):
            raise ConfigError(
                f"{label} must be a plain name of letters, digits, '_', '.', '-' "
                f"(no extension), got {value!r}"
            )
    out_dir = Path(figures_dir) / paper
    out_dir.mkdir(parents=True, exist_ok=True)
    png = out_dir / f"{name}.png"
    pdf = out_dir / f"{name}.pdf"
    fig.savefig(png, format="png", dpi=PNG_DPI, metadata={"Software": None})
    fig.savefig(
        pdf,
        format="pdf",
        metadata={"CreationDate": None, "ModDate": None, "Producer": None, "Creator": None},
    )
    return [png, pdf]
