"""How often each claim and clause holds over a sweep's variants (issue 19, item 4):
``<results>/sweeps/<exp>/rates.csv`` from ``variants.csv`` and the variants' verdicts.

One row per claim (``clause`` empty: the claim reproduced) and per clause (the clause held):
variants judged, how many held, the rate, its Wilson 95 % interval, and the canonical run's
verdict from results/claims.csv and results/claim_clauses.csv. Failed runs are not judged
variants; they are counted apart, and so are the refused ones (``refused``: the experiment
rejected the variant's scene before running, e.g. a board through the robot's start pose).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import pandas as pd

from repro.errors import ReproError

__all__ = ["AGREEMENT_COLUMNS", "RATES_COLUMNS", "wilson_interval", "write_agreement",
           "write_rates"]

RATES_COLUMNS = ("experiment", "claim", "clause", "variants", "held", "rate", "wilson_low",
                 "wilson_high", "failed_runs", "canonical", "refused", "scope")
#: ``scope`` of a row: a rate over the variants, or a clause (a claim, a joint row holding
#: one) that fits only the paper's own scene, judged on the canonical run alone: its rate is
#: not reported (issue 37; :attr:`repro.runs.causes.Diagnosis.scene_specific`)
SCOPE_VARIANTS, SCOPE_CANONICAL = "variants", "canonical only"
#: run_status of a variant its experiment refuses before running (ConfigError: e.g. a board
#: through the robot's start pose); such a variant is no scene of the paper's, not a failure
REFUSED = "refused"
#: run statuses that are not judged variants (a crash, a refusal)
NOT_JUDGED = ("failed", REFUSED)
Z95 = 1.959963984540054  # the two-sided 95 % normal quantile


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a binomial rate ``k / n`` (NaN, NaN for n = 0)."""
    if n <= 0:
        return math.nan, math.nan
    if not 0 <= k <= n:
        raise ReproError(f"wilson_interval: k = {k} outside [0, {n}]")
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    lo, hi = max(0.0, centre - half), min(1.0, centre + half)
    return (0.0 if k == 0 else lo), (1.0 if k == n else hi)  # exact ends, no round-off


def _clause_names(sweep_dir: Path) -> dict[tuple[str, int], str]:
    """(claim, k) -> clause name, from the variants' verdicts."""
    names: dict[tuple[str, int], str] = {}
    for path in sorted((sweep_dir / "variants").glob("*/verdicts.json")):
        verdicts = json.loads(path.read_text(encoding="utf-8")).get("verdicts", {})
        for cid, v in verdicts.items():
            for k, c in enumerate(v.get("clauses", []), start=1):
                names.setdefault((cid, k), c["name"])
    return names


def _canonical(results_dir: Path, paper: str) -> tuple[dict[str, str], dict[tuple[str, str], str]]:
    claims: dict[str, str] = {}
    clauses: dict[tuple[str, str], str] = {}
    path = results_dir / "claims.csv"
    if path.is_file():
        df = pd.read_csv(path, dtype=str, keep_default_na=False)
        claims = {r.claim: r.status for r in df[df["paper"] == paper].itertuples()}
    path = results_dir / "claim_clauses.csv"
    if path.is_file():
        df = pd.read_csv(path, dtype=str, keep_default_na=False)
        clauses = {(r.claim, r.clause): ("holds" if r.holds == "True" else "fails")
                   for r in df[df["paper"] == paper].itertuples()}
    return claims, clauses


def write_rates(sweep_dir: Path, results_dir: Path, paper: str, experiment: str,
                joint: Sequence[Sequence[str]] = (),
                specific: Mapping[tuple[str, str], str] | None = None) -> Path:
    """Write ``sweep_dir / rates.csv`` from ``sweep_dir / variants.csv``; return its path.

    ``joint``: sets of claims the paper makes together; each set whose claims were all
    judged gets a row ``claim = "1+2+3"``: the variants in which every one is reproduced.
    ``specific``: ``{(claim, clause): why}`` of the clauses that fit only the paper's own
    scene: their rows (and their claim's, and a joint row holding it) keep their counts but
    no rate (``scope`` "canonical only")."""
    sweep_dir, results_dir = Path(sweep_dir), Path(results_dir)
    df = pd.read_csv(sweep_dir / "variants.csv")
    judged = df[~df["run_status"].isin(NOT_JUDGED)]
    failed = int((df["run_status"] == "failed").sum())
    refused = int((df["run_status"] == "refused").sum())
    names = _clause_names(sweep_dir)
    canon_claims, canon_clauses = _canonical(results_dir, paper)
    rows = []
    claim_ids = sorted({c.split(".", 1)[0][len("claim"):] for c in df.columns
                        if c.startswith("claim") and c.endswith(".status")})
    for cid in claim_ids:
        st = judged[f"claim{cid}.status"].dropna().astype(str)
        k = int((st == "reproduced").sum())
        lo, hi = wilson_interval(k, len(st))
        rows.append((experiment, cid, "", len(st), k, k / len(st) if len(st) else math.nan,
                     lo, hi, failed, canon_claims.get(cid, ""), refused))
        j = 1
        while f"claim{cid}.c{j}.holds" in df.columns:
            col = judged[f"claim{cid}.c{j}.holds"].dropna()
            held = col.astype(str).str.lower().eq("true")
            k, n = int(held.sum()), int(len(col))
            lo, hi = wilson_interval(k, n)
            name = names.get((cid, j), f"clause {j}")
            rows.append((experiment, cid, name, n, k, k / n if n else math.nan, lo, hi, failed,
                         canon_clauses.get((cid, name), ""), refused))
            j += 1
    for group in joint:
        cols = [f"claim{c}.status" for c in group]
        if not group or any(c not in df.columns for c in cols):
            continue
        st = judged[cols].astype(str)
        ok = st.notna().all(axis=1) & ~st.isin(["nan", ""]).any(axis=1)
        both = st[ok].eq("reproduced").all(axis=1)
        k, n = int(both.sum()), int(ok.sum())
        lo, hi = wilson_interval(k, n)
        canon = [canon_claims.get(c, "") for c in group]
        rows.append((experiment, "+".join(group), "(jointly: every claim reproduced)", n, k,
                     k / n if n else math.nan, lo, hi, failed,
                     "reproduced" if all(c == "reproduced" for c in canon)
                     else ("" if not all(canon) else "not jointly"), refused))
    specific = dict(specific or {})
    bare = {cid for cid, _ in specific}
    scoped = []
    for r in rows:
        cid, clause = r[1], r[2]
        local = ((cid, clause) in specific or (not clause and cid in bare)
                 or ("+" in cid and bool(set(cid.split("+")) & bare)))
        if local:  # counts kept, no rate: the clause fits only the paper's scene
            r = (*r[:5], math.nan, math.nan, math.nan, *r[8:])
        scoped.append((*r, SCOPE_CANONICAL if local else SCOPE_VARIANTS))
    out = sweep_dir / "rates.csv"
    pd.DataFrame(scoped, columns=list(RATES_COLUMNS)).to_csv(out, index=False,
                                                             float_format="%.6g")
    return out


AGREEMENT_COLUMNS = ("experiment", "claim", "clause", "twins", "agree", "rate", "wilson_low",
                     "wilson_high", "exact_held", "render_held")


def write_agreement(exact_dir: Path, render_dir: Path, experiment: str) -> Path:
    """``exact_dir / render_agreement.csv``: per claim and clause, over the variants run with
    both cameras (twins: the same parameter values, matched on every ``p.`` column), how
    many verdicts the rendered camera and the exact projection agree on."""
    ex = pd.read_csv(Path(exact_dir) / "variants.csv")
    re_ = pd.read_csv(Path(render_dir) / "variants.csv")
    params = sorted(c for c in ex.columns if c.startswith("p.") and c in re_.columns)
    ex, re_ = (d[~d["run_status"].isin(NOT_JUDGED)] for d in (ex, re_))
    key = ex[params].round(12).astype(str).agg("|".join, axis=1)
    rkey = re_[params].round(12).astype(str).agg("|".join, axis=1)
    twins = ex.assign(_k=key).merge(re_.assign(_k=rkey), on="_k", suffixes=("", "@render"))
    names = _clause_names(Path(exact_dir))
    rows = []
    for col in [c for c in ex.columns if c.startswith("claim") and
                (c.endswith(".status") or c.endswith(".holds"))]:
        if f"{col}@render" not in twins.columns:
            continue
        a = twins[col].astype(str).str.lower()
        b = twins[f"{col}@render"].astype(str).str.lower()
        ok = ~a.isin(["nan", ""]) & ~b.isin(["nan", ""])
        k, n = int((a[ok] == b[ok]).sum()), int(ok.sum())
        lo, hi = wilson_interval(k, n)
        cid = col.split(".", 1)[0][len("claim"):]
        if col.endswith(".status"):
            clause, good = "", ("reproduced",)
        else:
            j = int(col.split(".")[1][1:])
            clause, good = names.get((cid, j), f"clause {j}"), ("true",)
        rows.append((experiment, cid, clause, n, k, k / n if n else math.nan, lo, hi,
                     int(a[ok].isin(good).sum()), int(b[ok].isin(good).sum())))
    out = Path(exact_dir) / "render_agreement.csv"
    pd.DataFrame(rows, columns=list(AGREEMENT_COLUMNS)).to_csv(out, index=False,
                                                               float_format="%.6g")
    return out
