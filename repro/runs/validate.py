"""One validating loader for run folders: nothing reads a damaged run as if it were whole.

Figures, claims, the report and ``repro results`` all read runs through
:func:`check_run`. It checks, in this order, and stops at the first rule that fails
(:class:`DamagedRun` names the folder and that rule):

1. the folder and its five files exist (trace.csv, columns.json, events.csv, manifest.json,
   scene.json);
2. manifest.json is a JSON object with a known ``status``, an integer ``n_rows`` >= 0 and a
   ``config_hash``; its status, read as :func:`repro.runs.trace.effective_manifest` reads
   it (a dead ``running`` run is ``interrupted``), is ``completed``;
3. scene.json is a JSON object with a ``format`` and a list of ``bodies``;
4. columns.json is ``{"columns": [{name, unit, definition}, ...]}`` with unique names;
5. trace.csv's header is exactly those names, in that order; its last line ends with a
   newline (not cut); every line has one field per column; the data rows number
   ``n_rows``;
6. every cell has its column's declared type: ``bool`` columns hold True/False, ``text``
   columns anything, every other unit a number (an empty cell, or nan, is a missing value);
7. ``t`` (in a time series) is finite and strictly increasing, ``step`` (when present)
   finite integers;
8. events.csv has the columns t, step, kind, detail with numeric t and integer steps
   (:func:`repro.runs.trace.load_run` checks these; its error becomes the rule).
"""

from __future__ import annotations

import csv
import io
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from repro.errors import ReproError
from repro.runs.columns import COLUMNS_FILE
from repro.runs.trace import (
    RUN_FILES,
    RUN_STATUSES,
    RunFiles,
    effective_manifest,
    load_run,
)

__all__ = ["DamagedRun", "VALID_FILES", "check_run", "load_run_if_present"]

#: The files every run folder must hold.
VALID_FILES = (*RUN_FILES, COLUMNS_FILE)


class DamagedRun(ReproError):
    """A run folder that fails a rule of :func:`check_run`."""

    def __init__(self, folder: Path, rule: str) -> None:
        self.folder = Path(folder)
        self.rule = rule
        super().__init__(f"damaged run {self.folder}: {rule}")


def _json_object(path: Path, what: str) -> dict[str, Any]:
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise DamagedRun(path.parent, f"{what} is not readable JSON ({exc})") from exc
    if not isinstance(obj, dict):
        raise DamagedRun(path.parent, f"{what} is not a JSON object")
    return obj


def _check_manifest(run_dir: Path) -> dict[str, Any]:
    m = _json_object(run_dir / "manifest.json", "manifest.json")
    status = m.get("status")
    if status not in (*RUN_STATUSES, "running"):
        raise DamagedRun(run_dir, f"manifest.json status {status!r} is not one of "
                                  f"{', '.join((*RUN_STATUSES, 'running'))}")
    n = m.get("n_rows")
    if not isinstance(n, int) or isinstance(n, bool) or n < 0:
        raise DamagedRun(run_dir, f"manifest.json n_rows {n!r} is not an integer >= 0")
    if not isinstance(m.get("config_hash"), str):
        raise DamagedRun(run_dir, "manifest.json has no config_hash")
    eff = effective_manifest(run_dir, m)
    if eff.get("status") != "completed":
        reason = eff.get("reason") or "no reason recorded"
        raise DamagedRun(run_dir, f"status {eff.get('status')!r}, not 'completed' ({reason})")
    return m


def _check_scene(run_dir: Path) -> None:
    s = _json_object(run_dir / "scene.json", "scene.json")
    if not isinstance(s.get("format"), str) or not isinstance(s.get("bodies"), list):
        raise DamagedRun(run_dir, "scene.json lacks its format or its list of bodies")


def _check_columns(run_dir: Path) -> list[tuple[str, str]]:
    c = _json_object(run_dir / COLUMNS_FILE, COLUMNS_FILE)
    cols = c.get("columns")
    ok = isinstance(cols, list) and all(
        isinstance(e, dict) and all(isinstance(e.get(k), str) and e.get(k)
                                    for k in ("name", "unit", "definition")) for e in cols)
    if not ok or not cols:
        raise DamagedRun(run_dir, f"{COLUMNS_FILE} is not a list of columns with a name, a "
                                  "unit and a definition")
    names = [e["name"] for e in cols]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise DamagedRun(run_dir, f"{COLUMNS_FILE} declares column {dup!r} twice")
    return [(e["name"], e["unit"]) for e in cols]


def _check_lines(run_dir: Path, names: list[str], n_rows: int) -> None:
    raw = (run_dir / "trace.csv").read_bytes()
    if not raw:
        raise DamagedRun(run_dir, "trace.csv is empty (no header)")
    if not raw.endswith(b"\n"):
        raise DamagedRun(run_dir, "trace.csv's last line is cut (no newline at its end)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DamagedRun(run_dir, f"trace.csv is not UTF-8 text ({exc})") from exc
    if '"' in text:
        lines = list(csv.reader(io.StringIO(text)))
        widths = [len(r) for r in lines]
        header = lines[0]
    else:
        rows = text.split("\n")[:-1]
        widths = [r.count(",") + 1 for r in rows]
        header = rows[0].split(",")
    if header != names:
        extra = [n for n in header if n not in names]
        missing = [n for n in names if n not in header]
        detail = (f"missing {missing[:3]}" if missing else f"undeclared {extra[:3]}"
                  if extra else "in another order")
        raise DamagedRun(run_dir, f"trace.csv's header is not columns.json's columns ({detail})")
    bad = next((i for i, w in enumerate(widths) if w != len(names)), None)
    if bad is not None:
        raise DamagedRun(run_dir, f"trace.csv line {bad + 1} has {widths[bad]} fields, "
                                  f"expected {len(names)}")
    if len(widths) - 1 != n_rows:
        raise DamagedRun(run_dir, f"trace.csv has {len(widths) - 1} data rows, the manifest "
                                  f"says n_rows = {n_rows}")


_BOOL_VALUES = {True, False, "True", "False"}


def _check_types(run_dir: Path, trace: pd.DataFrame, units: list[tuple[str, str]]) -> None:
    for name, unit in units:
        col = trace[name]
        if unit == "text":
            continue
        if unit == "bool":
            if col.dtype == bool:
                continue
            bad = col[~col.isna() & ~col.isin(_BOOL_VALUES)]
            what = "True or False"
        else:
            if pd.api.types.is_numeric_dtype(col) and col.dtype != bool:
                continue
            num = pd.to_numeric(col, errors="coerce") if col.dtype != bool else col * np.nan
            bad = col[num.isna() & ~col.isna()]
            what = f"a number ({unit})"
        if len(bad):
            row = int(bad.index[0])
            raise DamagedRun(run_dir, f"trace.csv column {name!r} row {row + 1}: "
                                      f"{bad.iloc[0]!r} is not {what}")


def _check_time(run_dir: Path, trace: pd.DataFrame) -> None:
    if "t" not in trace.columns:  # a table that is not a time series (chan2011 dcc_audit)
        return
    t = trace["t"].to_numpy(dtype=float)
    if t.size and not np.isfinite(t).all():
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        raise DamagedRun(run_dir, f"trace.csv t is not finite at row {i + 1}")
    if t.size > 1 and not (np.diff(t) > 0).all():
        i = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise DamagedRun(run_dir, f"trace.csv t is not strictly increasing at row {i + 2} "
                                  f"({t[i]!r} then {t[i + 1]!r})")
    if "step" in trace.columns:
        s = trace["step"].to_numpy(dtype=float)
        if s.size and not (np.isfinite(s).all() and (s == np.round(s)).all()):
            raise DamagedRun(run_dir, "trace.csv step holds a value that is not an integer")


def check_run(run_dir: Path) -> RunFiles:
    """Validate ``run_dir`` (the rules of this module's docstring) and return its files.

    Raises:
        DamagedRun: at the first rule that fails.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise DamagedRun(run_dir, "the folder does not exist")
    missing = [n for n in VALID_FILES if not (run_dir / n).is_file()]
    if missing:
        raise DamagedRun(run_dir, f"missing {', '.join(missing)}")
    manifest = _check_manifest(run_dir)
    _check_scene(run_dir)
    units = _check_columns(run_dir)
    _check_lines(run_dir, [n for n, _ in units], manifest["n_rows"])
    try:
        run = load_run(run_dir)
    except ReproError as exc:
        raise DamagedRun(run_dir, str(exc)) from exc
    _check_types(run_dir, run.trace, units)
    _check_time(run_dir, run.trace)
    return run


def load_run_if_present(base: Path, name: str) -> RunFiles | None:
    """The run ``base / name`` validated (:func:`check_run`) if it
    has a manifest, else None: figures draw what exists and is whole. A damaged or
    unfinished run is skipped with one line on stderr naming its folder and the rule it
    fails."""
    path = Path(base) / name
    if not (path / "manifest.json").exists():
        return None
    try:
        return check_run(path)
    except DamagedRun as exc:
        print(f"figures: skipping {exc}", file=sys.stderr)
        return None
