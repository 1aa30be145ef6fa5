"""Which unknown decides a claim (issue 19, item 4): ``<results>/sweeps/<exp>/sensitivity.csv``
from ``variants.csv``.

For every claim (reproduced or not) and clause (holds or not) whose verdict differs across
the variants, and every swept parameter:

- the best single split (a decision stump): the threshold on the parameter that best
  predicts the verdict, the side on which it holds, its accuracy against the majority
  verdict's accuracy (``gain``), and a permutation p-value of that gain (the verdicts
  shuffled :data:`N_PERMUTATIONS` times, seeded: how often a split on a parameter that
  decides nothing does as well; a best split over many thresholds always gains a little);
- Spearman's rank correlation of the clause's signed margin with the parameter (for a
  claim, of its verdict), which a split misses when the verdict flips more than once.

Parameters are ranked per claim / clause by gain, then by |rho|. A verdict the same in every
variant gets rows too (``holds_when`` "every variant holds" / "fails", no split): ranked by
|rho|, they say which parameter moves its margin towards the bound.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from repro.runs.sweep_rates import NOT_JUDGED

__all__ = ["N_PERMUTATIONS", "SENSITIVITY_COLUMNS", "best_split", "write_sensitivity"]

SENSITIVITY_COLUMNS = ("experiment", "claim", "clause", "parameter", "rank", "split_at",
                       "holds_when", "split_accuracy", "majority_accuracy", "gain",
                       "permutation_p", "spearman", "variants")
N_PERMUTATIONS = 200
SEED = 0  # ours: fixed, so that the table is a function of variants.csv


def best_split(x: np.ndarray, y: np.ndarray) -> tuple[float, str, float]:
    """The threshold on ``x`` that best predicts the booleans ``y`` by one cut:
    ``(split_at, holds_when, accuracy)``; ``holds_when`` is ``"< split_at"`` or
    ``">= split_at"`` (the side where y is mostly True), "none" if no cut beats the majority.
    The cut lies halfway between two consecutive distinct values of x."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=bool)
    n = len(x)
    majority = max(y.sum(), n - y.sum()) / n if n else math.nan
    if n < 2:
        return math.nan, "none", majority
    order = np.argsort(x, kind="stable")
    xs, ys = x[order], y[order]
    left_true = np.cumsum(ys)[:-1]  # cut after position i: left = xs[: i + 1]
    left_n = np.arange(1, n)
    right_true = ys.sum() - left_true
    right_n = n - left_n
    valid = xs[1:] > xs[:-1]
    if not valid.any():
        return math.nan, "none", majority
    # either orientation: True left / False right, or False left / True right
    acc_lo = (left_true + (right_n - right_true)) / n
    acc_hi = ((left_n - left_true) + right_true) / n
    acc = np.where(valid, np.maximum(acc_lo, acc_hi), -1.0)
    i = int(np.argmax(acc))
    if acc[i] <= majority:
        return math.nan, "none", majority
    cut = 0.5 * (xs[i] + xs[i + 1])
    return float(cut), ("< " if acc_lo[i] >= acc_hi[i] else ">= ") + f"{cut:.4g}", float(acc[i])


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    from scipy.stats import spearmanr

    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3 or np.ptp(x[ok]) == 0 or np.ptp(y[ok]) == 0:
        return math.nan
    return float(spearmanr(x[ok], y[ok]).statistic)


def _rows(experiment: str, claim: str, clause: str, params: pd.DataFrame, y: pd.Series,
          score: pd.Series, rng: np.random.Generator) -> list[tuple[object, ...]]:
    ok = y.notna()
    yv = y[ok].astype(bool).to_numpy()
    n = len(yv)
    if n and (yv.all() or not yv.any()):  # one verdict everywhere: how the margin moves
        same = "holds" if yv.all() else "fails"
        rows = []
        for p in params.columns:
            x = pd.to_numeric(params.loc[ok, p], errors="coerce").to_numpy(dtype=float)
            rho = _spearman(x, pd.to_numeric(score[ok], errors="coerce").to_numpy(dtype=float))
            rows.append([experiment, claim, clause, p[2:], 0, math.nan,
                         f"every variant {same}", 1.0, 1.0, 0.0, math.nan, rho, n])
        rows.sort(key=lambda r: -(abs(float(r[11])) if np.isfinite(r[11]) else 0))
        for k, r in enumerate(rows, start=1):
            r[4] = k
        return [tuple(r) for r in rows]
    if not n:
        return []
    majority = max(yv.sum(), n - yv.sum()) / n
    perms = [rng.permutation(yv) for _ in range(N_PERMUTATIONS)]
    out = []
    for p in params.columns:
        x = pd.to_numeric(params.loc[ok, p], errors="coerce").to_numpy(dtype=float)
        cut, side, acc = best_split(x, yv)
        gain = acc - majority
        null = np.array([best_split(x, yp)[2] - majority for yp in perms])
        pval = float((1 + (null >= gain - 1e-12).sum()) / (1 + N_PERMUTATIONS))
        rho = _spearman(x, pd.to_numeric(score[ok], errors="coerce").to_numpy(dtype=float))
        out.append([experiment, claim, clause, p[2:], 0, cut, side, acc, majority, gain, pval,
                    rho, n])
    out.sort(key=lambda r: (-float(r[9]), -(abs(float(r[11])) if np.isfinite(r[11]) else 0)))
    for k, r in enumerate(out, start=1):
        r[4] = k
    return [tuple(r) for r in out]


def write_sensitivity(sweep_dir: Path, experiment: str) -> Path:
    """Write ``sweep_dir / sensitivity.csv`` from ``sweep_dir / variants.csv``."""
    from repro.runs.sweep_rates import _clause_names

    sweep_dir = Path(sweep_dir)
    df = pd.read_csv(sweep_dir / "variants.csv")
    df = df[~df["run_status"].isin(NOT_JUDGED)].reset_index(drop=True)
    params = df[[c for c in df.columns if c.startswith("p.")]]
    names = _clause_names(sweep_dir)
    rng = np.random.default_rng(SEED)
    rows: list[tuple[object, ...]] = []
    claims = sorted({c.split(".", 1)[0][len("claim"):] for c in df.columns
                     if c.startswith("claim") and c.endswith(".status")})
    for cid in claims:
        status = df[f"claim{cid}.status"]
        judged = status.notna() & (status.astype(str) != "not_run")
        y = (status == "reproduced").where(judged)
        rows += _rows(experiment, cid, "", params, y, y.astype(float), rng)
        k = 1
        while f"claim{cid}.c{k}.holds" in df.columns:
            h = df[f"claim{cid}.c{k}.holds"]
            y = h.astype(str).str.lower().map({"true": True, "false": False})
            rows += _rows(experiment, cid, names.get((cid, k), f"clause {k}"), params, y,
                          df[f"claim{cid}.c{k}.margin"], rng)
            k += 1
    out = sweep_dir / "sensitivity.csv"
    pd.DataFrame(rows, columns=list(SENSITIVITY_COLUMNS)).to_csv(out, index=False,
                                                                 float_format="%.6g")
    return out
