"""Test support: the run files a fake experiment writes so that the validating loader
(:mod:`repro.runs.validate`) reads its folder as a whole run."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from repro.runs.columns import COLUMNS_FILE, Columns


def complete_run_files(out_dir: Path) -> None:
    """Add what a recorder-only run lacks: ``columns.json`` for trace.csv's header (``t`` in
    s, every other column a number) and, when empty, a minimal ``scene.json``."""
    out_dir = Path(out_dir)
    header = (out_dir / "trace.csv").read_text().split("\n", 1)[0].split(",")
    cols = Columns()
    for name in header:
        cols.add(name, "s" if name == "t" else "-", f"test column {name}")
    cols.write(out_dir / COLUMNS_FILE, header)
    scene = out_dir / "scene.json"
    if not scene.is_file() or not json.loads(scene.read_text() or "{}").get("bodies"):
        scene.write_text(json.dumps({"format": "test/1", "bodies": []}))


def write_whole_run(out_dir: Path, **manifest: Any) -> None:
    """A one-row run whose manifest holds ``manifest`` (plus ``n_rows`` = 1)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "trace.csv").write_text("t\n0.0\n")
    (out_dir / "events.csv").write_text("t,step,kind,detail\n")
    (out_dir / "manifest.json").write_text(json.dumps({"n_rows": 1, **manifest}))
    complete_run_files(out_dir)
