"""REPORT.md's "Why claims fail over scenes" (issue 37): per sweep of a paper, each clause
under the rate bar with the share of its failing variants per named cause, one example
variant per cause (and its video, when made), and the counterfactual's rate beside a cause
that one removes. Read from ``results/sweeps/<exp>/cause_shares.csv`` only."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import pandas as pd

from repro.runs.causes import CLASSES, RATE_BAR, UNKNOWN

__all__ = ["causes_section", "example_video"]

CLASS_MEANING = {
    "method": "the paper's design cannot do it here",
    "ours-defect": "our implementation is wrong",
    "ours-range": "the sweep's range reaches scenes the paper rules out",
    "check": "the clause cannot be judged on a varied scene (judged on the canonical run only)",
    UNKNOWN: "not classified",
}


def example_video(figures_dir: Path, paper: str, experiment: str, cause: str) -> Path:
    """Where the video of a cause's example variant goes:
    ``<figures>/<paper>/videos/causes/<experiment>__<cause>.mp4``."""
    return Path(figures_dir) / paper / "videos" / "causes" / f"{experiment}__{cause}.mp4"


def _num(value: object, fmt: str = "{:.2f}") -> str:
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return "-"
    return "-" if math.isnan(x) else fmt.format(x)


def causes_section(results_dir: Path, figures_dir: Path, paper: str,
                   link: Callable[[Path], str],
                   table: Callable[[Sequence[str], Iterable[Sequence[object]]], str]
                   ) -> list[str]:
    """The section's Markdown lines for ``paper`` (``link``: a path -> its relative link;
    ``table``: headers and rows -> a Markdown table)."""
    out = ["### Why claims fail over scenes", ""]
    found = False
    for shares_path in sorted((Path(results_dir) / "sweeps").glob("*/cause_shares.csv")):
        meta_path = shares_path.parent / "variants.columns.json"
        if not meta_path.is_file():
            continue
        exp_id = str(json.loads(meta_path.read_text(encoding="utf-8")).get("experiment", ""))
        if not exp_id.startswith(f"{paper}."):
            continue
        df = pd.read_csv(shares_path, dtype={"claim": str}, keep_default_na=False)
        if df.empty:
            continue
        found = True
        exp = exp_id.split(".", 1)[1]
        rows = []
        for r in df.to_dict("records"):
            video = example_video(figures_dir, paper, exp, str(r["cause"]))
            example = f"#{r['example_variant']} ({r['example_hash']})"
            if video.is_file():
                example += f" [mp4]({link(video)})"
            cf = ("-" if not r["counterfactual"] else
                  f"{r['counterfactual']}: {_num(r['cf_rate'])} "
                  f"({r['cf_held']}/{r['cf_variants']})")
            rate = "-" if r["scope"] != "variants" else _num(r["rate"])
            rows.append((r["claim"], r["clause"], rate, r["failing"],
                         f"**{r['class']}** {r['cause']}",
                         f"{r['n']} ({_num(r['share'], '{:.0%}')})",
                         f"{example}: {r['example_evidence']}", cf))
        unknown = int(df.loc[df["class"] == UNKNOWN, "n"].astype(int).sum())
        failing = int(df.drop_duplicates(["claim", "clause"])["failing"].astype(int).sum())
        out += [f"**{exp_id}** ({link(shares_path)}, one row per variant in "
                f"{link(shares_path.with_name('causes.csv'))}): every clause whose rate is "
                f"under {RATE_BAR:g} or that fits only the paper's scene; {failing - unknown} "
                f"of {failing} failing variant-clauses classified.", "",
                table(("claim", "clause", "rate", "failing", "class, cause",
                                "variants (share)", "example: evidence",
                                "counterfactual: rate (held/rerun)"), rows), ""]
    if not found:
        return out + ["_No cause tables yet (results/sweeps/<exp>/cause_shares.csv)._", ""]
    legend = "; ".join(f"**{c}**: {CLASS_MEANING[c]}" for c in (*CLASSES, UNKNOWN))
    return out + [f"Classes: {legend}. A counterfactual reruns the variants of one cause with "
                  "only that cause removed; its rate is the clause's over those reruns.", ""]
