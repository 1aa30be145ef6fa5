"""Compare a run's trace with a reference trace within measured tolerances.

A reference is compared column by column under rules *measured* beforehand: the reference
is rerun under the perturbations another machine produces (other BLAS kernel families, the
initial state moved by 1e-12), and each column's largest deviation from the reference over
those reruns sets its tolerance, ``margin`` times the measured deviation
(:func:`measure_tolerances`; ``tests/measure_tolerances.py`` does it for the committed
references). The rules, per column:

* **pointwise** on the column's *stable stretch*, the rows ``[0, stable)`` where every
  perturbed rerun stays within ``CHAOTIC_FRACTION`` of the column's own excursion once the
  margin is applied: ``|got - ref| <= atol + ROUNDING_RTOL |ref|`` row by row;
* **windowed** on the rest, the *chaotic stretch*, where a bit-level perturbation moves the
  trajectory as much as the motion itself (stick-slip of a held finger, a contact manifold
  that picks other points): the stretch is cut into at most ``N_WINDOWS`` equal windows and
  each window's mean and RMS (for a text column, the share of each value) must stay within
  ``margin`` times their own measured deviation;
* non-float columns that no perturbation changed are compared **exactly**.

If the perturbed reruns differ in length (a stop condition met at another step), the rows
that every rerun has are compared and the length must stay within ``margin`` times the
measured spread.

The tolerance file is plain JSON (:data:`TOLERANCE_FORMAT`) so that the numbers a test
uses can be read, and regenerated, without this code.
"""

from __future__ import annotations

import math
import platform
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["CHAOTIC_FRACTION", "DEFAULT_MARGIN", "N_WINDOWS", "ROUNDING_RTOL",
           "TOLERANCE_FORMAT", "Violation", "compare_to_reference", "machine_description",
           "measure_tolerances", "merge_tolerances", "summary"]

TOLERANCE_FORMAT = 1
#: Tolerance = margin x the largest deviation measured over the perturbations. ours: the
#: kernel families measured here span a factor ~5 between one another (exp1 ``pa10_qd4``:
#: 1.6e-6 to 8.8e-6 after 0.5 s), so one order of magnitude covers a machine we could not
#: run by twice the spread we saw.
DEFAULT_MARGIN = 10.0
#: A reference CSV holds 10 significant digits: each value is within 5e-10 of its own
#: magnitude; twice that, so that a rounding of the reference never fails a test.
ROUNDING_RTOL = 1e-9
#: A column whose tolerance would exceed this share of its own excursion in the reference
#: (max - min) at some row is compared by windowed statistics from that row on. ours: a
#: pointwise band wider than a tenth of the motion no longer tells one trajectory from
#: another.
CHAOTIC_FRACTION = 0.1
#: The chaotic stretch of a column is cut into this many equal windows (fewer if shorter).
#: ours: enough to see a drift within the stretch, each window long enough (>= 20 rows in
#: the short runs) that its mean averages the chatter.
N_WINDOWS = 5


@dataclass(frozen=True)
class Violation:
    """One comparison that failed: column, what was compared, by how much."""

    column: str
    what: str  # "row 73", "rows 40-60 mean", "length", "values"
    got: float | str
    ref: float | str
    tol: float

    @property
    def ratio(self) -> float:
        """Deviation over tolerance (inf for a mismatch of text or NaN)."""
        try:
            dev = abs(float(self.got) - float(self.ref))  # type: ignore[arg-type]
        except (TypeError, ValueError):
            return math.inf
        if math.isnan(dev):
            return math.inf
        return dev / self.tol if self.tol > 0 else math.inf

    def __str__(self) -> str:
        return (f"{self.column} {self.what}: got {self.got!r}, reference {self.ref!r}, "
                f"tolerance {self.tol:.3g} (x{self.ratio:.3g})")


# --------------------------------------------------------------------------- helpers
def _is_float(s: pd.Series) -> bool:
    return s.dtype.kind == "f"


def _as_float(s: pd.Series) -> np.ndarray:
    if s.dtype.kind == "b":
        return s.to_numpy(float)
    return pd.to_numeric(s, errors="coerce").to_numpy(float)


def _deviation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| with NaN == NaN (0) and NaN vs a number (inf)."""
    with np.errstate(invalid="ignore"):
        d = np.abs(a - b)
    na, nb = np.isnan(a), np.isnan(b)
    d[na & nb] = 0.0
    d[na ^ nb] = np.inf
    return d


def _scale(ref: np.ndarray) -> float:
    """The column's own excursion (max - min), or its magnitude if it is constant."""
    fin = ref[np.isfinite(ref)]
    if fin.size == 0:
        return 0.0
    ptp = float(fin.max() - fin.min())
    return ptp if ptp > 0 else float(np.abs(fin).max())


def _windows(start: int, stop: int) -> list[tuple[int, int]]:
    n = stop - start
    if n <= 0:
        return []
    k = min(N_WINDOWS, n)
    edges = np.linspace(start, stop, k + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


def _float_stats(x: np.ndarray) -> dict[str, float]:
    fin = x[np.isfinite(x)]
    if fin.size == 0:
        return {"mean": math.nan, "rms": math.nan, "n_nan": float(x.size)}
    return {"mean": float(fin.mean()), "rms": float(np.sqrt(np.mean(fin ** 2))),
            "n_nan": float(x.size - fin.size)}


def _text_stats(x: np.ndarray, values: list[str]) -> dict[str, float]:
    return {f"share[{v}]": float(np.mean(x == v)) for v in values}


def _text(s: pd.Series) -> np.ndarray:
    return s.astype(object).where(s.notna(), "").astype(str).to_numpy()


def _stat_dev(a: float, b: float) -> float:
    if math.isnan(a) and math.isnan(b):
        return 0.0
    if math.isnan(a) or math.isnan(b):
        return math.inf
    return abs(a - b)


def machine_description() -> dict[str, Any]:
    """Where a tolerance was measured (CPU, Python, numpy, date)."""
    from repro.runs.trace import cpu_name

    return {"cpu": cpu_name(), "machine": platform.machine(), "python": platform.python_version(),
            "numpy": np.__version__, "date": datetime.now(UTC).strftime("%Y-%m-%d")}


# --------------------------------------------------------------------------- measuring
def _measure_float(ref: np.ndarray, runs: Mapping[str, np.ndarray], n: int,
                   margin: float) -> dict[str, Any]:
    devs = {k: _deviation(v[:n], ref[:n]) for k, v in runs.items()}
    d = np.max(np.vstack(list(devs.values())), axis=0) if devs else np.zeros(n)
    scale = _scale(ref[:n])
    bad = np.nonzero(margin * d > CHAOTIC_FRACTION * scale)[0]
    stable = int(bad[0]) if bad.size else n
    rule: dict[str, Any] = {"kind": "float", "scale": scale, "stable": stable}
    if stable > 0:
        k = int(np.argmax(d[:stable]))
        by = max(devs, key=lambda p: devs[p][k]) if devs else ""
        rule.update(measured=float(d[k]), measured_row=k, by=by, atol=margin * float(d[k]))
    windows = []
    for a, b in _windows(stable, n):
        st_ref = _float_stats(ref[a:b])
        meas = {s: max((_stat_dev(_float_stats(v[a:b])[s], st_ref[s]) for v in runs.values()),
                       default=0.0) for s in st_ref}
        windows.append({"rows": [a, b], "measured": meas,
                        "atol": {s: margin * m for s, m in meas.items()}})
    if windows:
        rule["windows"] = windows
    return rule


def _measure_text(ref: np.ndarray, runs: Mapping[str, np.ndarray], n: int,
                  margin: float) -> dict[str, Any]:
    same = np.ones(n, bool)
    for v in runs.values():
        same &= v[:n] == ref[:n]
    stable = int(np.argmin(same)) if not same.all() else n
    rule: dict[str, Any] = {"kind": "text", "stable": stable}
    values = sorted(set(ref[:n]).union(*(set(v[:n]) for v in runs.values())))
    windows = []
    for a, b in _windows(stable, n):
        st_ref = _text_stats(ref[a:b], values)
        meas = {s: max(abs(_text_stats(v[a:b], values)[s] - st_ref[s]) for v in runs.values())
                for s in st_ref}
        windows.append({"rows": [a, b], "measured": meas,
                        "atol": {s: margin * m for s, m in meas.items()}})
    if windows:
        rule["windows"] = windows
    return rule


def measure_tolerances(ref: pd.DataFrame, runs: Mapping[str, pd.DataFrame], *,
                       margin: float = DEFAULT_MARGIN,
                       machine: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The comparison rules of ``ref`` from its reruns under perturbations.

    Args:
        ref: the reference trace (as read back from its CSV).
        runs: perturbation name -> the rerun's trace (same columns).
        margin: tolerance / measured deviation [-].
        machine: where it was measured (:func:`machine_description`).
    """
    for name, df in runs.items():
        if list(df.columns) != list(ref.columns):
            raise ValueError(f"rerun {name!r} has other columns than the reference")
    lengths = {k: len(v) for k, v in runs.items()}
    n = min([len(ref), *lengths.values()])
    dlen = max((abs(v - len(ref)) for v in lengths.values()), default=0)
    columns: dict[str, Any] = {}
    for c in ref.columns:
        s = ref[c]
        if _is_float(s) or any(_is_float(v[c]) for v in runs.values()):
            columns[c] = _measure_float(_as_float(s),
                                        {k: _as_float(v[c]) for k, v in runs.items()}, n,
                                        margin)
            continue
        txt = _text(s)
        others = {k: _text(v[c]) for k, v in runs.items()}
        if all(not _compare_exact(c, v[c], s, n) for v in runs.values()):
            columns[c] = {"kind": "exact"}
        elif s.dtype.kind in "biu":
            columns[c] = _measure_float(_as_float(s),
                                        {k: _as_float(v[c]) for k, v in runs.items()}, n,
                                        margin)
        else:
            columns[c] = _measure_text(txt, others, n, margin)
    return {
        "format": TOLERANCE_FORMAT,
        "how": ("tolerance = margin x the largest deviation from the reference over the "
                "perturbed reruns (repro.runs.compare)"),
        "margin": margin, "chaotic_fraction": CHAOTIC_FRACTION, "rounding_rtol": ROUNDING_RTOL,
        "measured_on": dict(machine or {}), "perturbations": sorted(runs),
        "rows": len(ref), "rows_compared": n, "rows_measured": lengths,
        "length_atol": margin * dlen,
        "columns": columns,
    }


def _merge_float(a: Mapping[str, Any], b: Mapping[str, Any], margin: float) -> dict[str, Any]:
    base, other = (a, b) if int(a["stable"]) <= int(b["stable"]) else (b, a)
    out: dict[str, Any] = {k: v for k, v in base.items() if k != "windows"}
    stable = int(base["stable"])
    if stable > 0:
        m = max(float(base["measured"]), float(other["measured"]))
        if float(other["measured"]) > float(base["measured"]):
            out.update(measured_row=other["measured_row"], by=other["by"])
        out.update(measured=m, atol=margin * m)
    o_stable = int(other["stable"])
    o_point = float(other.get("measured", 0.0)) if o_stable > 0 else 0.0
    windows = []
    for w in base.get("windows", []):
        lo, hi = w["rows"]
        meas = dict(w["measured"])
        for ow in other.get("windows", []):  # the other machine's overlapping windows
            if ow["rows"][0] < hi and ow["rows"][1] > lo:
                for st in meas:
                    meas[st] = max(meas[st], float(ow["measured"].get(st, 0.0)))
        if lo < o_stable:  # the other compared some of these rows pointwise: a window's
            for st in ("mean", "rms"):  # mean and RMS move at most by that deviation
                if st in meas:
                    meas[st] = max(meas[st], o_point)
        windows.append({"rows": [lo, hi], "measured": meas,
                        "atol": {st: margin * v for st, v in meas.items()}})
    if windows:
        out["windows"] = windows
    return out


def _merge_text(a: Mapping[str, Any], b: Mapping[str, Any], margin: float) -> dict[str, Any]:
    base, other = (a, b) if int(a["stable"]) <= int(b["stable"]) else (b, a)
    out: dict[str, Any] = {k: v for k, v in base.items() if k != "windows"}
    windows = []
    for w in base.get("windows", []):
        lo, hi = w["rows"]
        meas = dict(w["measured"])
        for ow in other.get("windows", []):  # (rows the other held equal moved by 0)
            if ow["rows"][0] < hi and ow["rows"][1] > lo:
                for st in set(meas) | set(ow["measured"]):
                    meas[st] = max(meas.get(st, 0.0), float(ow["measured"].get(st, 0.0)))
        windows.append({"rows": [lo, hi], "measured": meas,
                        "atol": {st: margin * v for st, v in meas.items()}})
    if windows:
        out["windows"] = windows
    return out


def merge_tolerances(a: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, Any]:
    """The tolerance file of one reference measured on two machines (``a`` and ``b``, each
    from :func:`measure_tolerances`): per column the looser rule. A column exact on one
    machine takes the other's rule; a float or text column's stable stretch is the shorter
    of the two, its pointwise deviation the larger, and each window's statistics the larger
    of its own and those of the other machine's overlapping windows (or, where the other
    compared those rows pointwise, its pointwise deviation, which bounds a window's mean and
    RMS change). Every tolerance stays ``margin`` x its measured deviation.

    Raises:
        ValueError: the two files describe other references (columns, rows or margin).
    """
    if (list(a["columns"]) != list(b["columns"]) or a["rows"] != b["rows"]
            or a["margin"] != b["margin"]):
        raise ValueError("the two tolerance files describe other references (columns, rows "
                         "or margin differ): remeasure one")
    margin = float(a["margin"])
    columns: dict[str, Any] = {}
    for c, ra in a["columns"].items():
        rb = b["columns"][c]
        if ra["kind"] == "exact" or rb["kind"] == "exact":
            columns[c] = dict(rb if ra["kind"] == "exact" else ra)
        elif ra["kind"] != rb["kind"]:
            raise ValueError(f"column {c!r} is {ra['kind']} in one file, {rb['kind']} in the "
                             "other")
        else:
            columns[c] = (_merge_float if ra["kind"] == "float" else _merge_text)(ra, rb,
                                                                                  margin)
    machines = [*(a["measured_on"] if isinstance(a["measured_on"], list)
                  else [a["measured_on"]]),
                *(b["measured_on"] if isinstance(b["measured_on"], list)
                  else [b["measured_on"]])]
    return {**a, "measured_on": machines,
            "perturbations": sorted(set(a["perturbations"]) | set(b["perturbations"])),
            "rows_compared": min(int(a["rows_compared"]), int(b["rows_compared"])),
            "rows_measured": {**b["rows_measured"], **a["rows_measured"]},
            "length_atol": max(float(a["length_atol"]), float(b["length_atol"])),
            "columns": columns}


# --------------------------------------------------------------------------- comparing
def _compare_float(c: str, got: np.ndarray, ref: np.ndarray, rule: Mapping[str, Any],
                   n: int) -> list[Violation]:
    out: list[Violation] = []
    stable = min(int(rule["stable"]), n)
    if stable > 0:
        dev = _deviation(got[:stable], ref[:stable])
        tol = float(rule["atol"]) + ROUNDING_RTOL * np.nan_to_num(np.abs(ref[:stable]))
        bad = np.nonzero(~(dev <= tol))[0]
        if bad.size:
            k = int(bad[np.argmax(dev[bad] / np.maximum(tol[bad], 1e-300))])
            out.append(Violation(c, f"row {k}", float(got[k]), float(ref[k]), float(tol[k])))
    for w in rule.get("windows", []):
        a, b = w["rows"]
        if a >= n:
            continue
        b = min(b, n)
        sg, sr = _float_stats(got[a:b]), _float_stats(ref[a:b])
        for s, atol in w["atol"].items():
            tol = float(atol) + ROUNDING_RTOL * (abs(sr[s]) if math.isfinite(sr[s]) else 0.0)
            if not _stat_dev(sg[s], sr[s]) <= tol:
                out.append(Violation(c, f"rows {a}-{b} {s}", sg[s], sr[s], tol))
    return out


def _compare_text(c: str, got: np.ndarray, ref: np.ndarray, rule: Mapping[str, Any],
                  n: int) -> list[Violation]:
    out: list[Violation] = []
    stable = min(int(rule["stable"]), n)
    diff = np.nonzero(got[:stable] != ref[:stable])[0]
    if diff.size:
        k = int(diff[0])
        out.append(Violation(c, f"row {k}", str(got[k]), str(ref[k]), 0.0))
    for w in rule.get("windows", []):
        a, b = w["rows"]
        if a >= n:
            continue
        b = min(b, n)
        values = [s[len("share["):-1] for s in w["atol"]]
        sg, sr = _text_stats(got[a:b], values), _text_stats(ref[a:b], values)
        unknown = sorted(set(got[a:b]) - set(values))
        if unknown:
            out.append(Violation(c, f"rows {a}-{b} values", ", ".join(unknown), "", 0.0))
        for s, atol in w["atol"].items():
            if not abs(sg[s] - sr[s]) <= float(atol):
                out.append(Violation(c, f"rows {a}-{b} {s}", sg[s], sr[s], float(atol)))
    return out


def _numeric(s: pd.Series) -> bool:
    return s.dtype.kind in "biuf"


def _compare_exact(c: str, got: pd.Series, ref: pd.Series, n: int) -> list[Violation]:
    """Equal values row by row: as numbers when both columns are numeric (a reference
    column of zeros reads back as integers, a live run's as floats), else as text."""
    if _numeric(got) and _numeric(ref):
        g, r = _as_float(got)[:n], _as_float(ref)[:n]
        diff = np.nonzero(_deviation(g, r) != 0.0)[0]
        if diff.size:
            k = int(diff[0])
            return [Violation(c, f"row {k}", float(g[k]), float(r[k]), 0.0)]
        return []
    gt, rt = _text(got)[:n], _text(ref)[:n]
    diff = np.nonzero(gt != rt)[0]
    if diff.size:
        k = int(diff[0])
        return [Violation(c, f"row {k}", str(gt[k]), str(rt[k]), 0.0)]
    return []


def compare_to_reference(got: pd.DataFrame, ref: pd.DataFrame,
                         tolerances: Mapping[str, Any]) -> list[Violation]:
    """Every comparison of ``got`` with ``ref`` that fails its measured tolerance.

    Raises:
        ValueError: the tolerance file does not describe this reference (other columns
            or row count): remeasure it.
    """
    rules = tolerances["columns"]
    if list(rules) != list(ref.columns) or tolerances["rows"] != len(ref):
        raise ValueError("the tolerance file was measured on another reference "
                         "(columns or rows differ); rerun tests/measure_tolerances.py")
    out: list[Violation] = []
    if list(got.columns) != list(ref.columns):
        missing = [c for c in ref.columns if c not in got.columns]
        extra = [c for c in got.columns if c not in ref.columns]
        return [Violation("<columns>", "names", f"extra {extra}", f"missing {missing}", 0.0)]
    if not abs(len(got) - len(ref)) <= float(tolerances["length_atol"]):
        out.append(Violation("<rows>", "length", float(len(got)), float(len(ref)),
                             float(tolerances["length_atol"])))
    n = min(len(got), int(tolerances["rows_compared"]))
    for c, rule in rules.items():
        kind = rule["kind"]
        if kind == "exact":
            out += _compare_exact(c, got[c], ref[c], n)
        elif kind == "float":
            out += _compare_float(c, _as_float(got[c]), _as_float(ref[c]), rule, n)
        else:
            out += _compare_text(c, _text(got[c]), _text(ref[c]), rule, n)
    return sorted(out, key=lambda v: -v.ratio)


def summary(name: str, tol: Mapping[str, Any]) -> str:
    """One paragraph: how many columns are compared how, the tightest and loosest."""
    cols = tol["columns"]
    kinds = {"exact": 0, "pointwise": 0, "partly chaotic": 0, "chaotic": 0}
    for r in cols.values():
        if r["kind"] == "exact":
            kinds["exact"] += 1
        elif r["stable"] >= tol["rows_compared"]:
            kinds["pointwise"] += 1
        elif r["stable"] > 0:
            kinds["partly chaotic"] += 1
        else:
            kinds["chaotic"] += 1
    chaotic = [c for c, r in cols.items() if r["kind"] != "exact"
               and r["stable"] < tol["rows_compared"]]
    lengths = sorted(set(tol["rows_measured"].values()) | {tol["rows"]})
    return (f"{name}: {tol['rows']} rows (reruns {lengths}), "
            + ", ".join(f"{v} {k}" for k, v in kinds.items())
            + (f"; chaotic from a row on: {', '.join(chaotic[:12])}"
               + (" ..." if len(chaotic) > 12 else "") if chaotic else ""))
