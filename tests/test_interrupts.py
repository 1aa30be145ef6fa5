"""Interrupted runs, for real (issue 7): a ``repro run`` subprocess is stopped by SIGINT,
SIGTERM or SIGKILL once its trace has rows; the run must end ``interrupted`` with one line
on stderr, or, after SIGKILL, be read and marked as interrupted by ``repro results``."""

from __future__ import annotations

import dataclasses
import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from repro import cli
from repro.runs import registry
from repro.runs.trace import count_trace_rows, effective_manifest, load_run

# Lines other programs print on stderr: PyBullet's import banner, and the CLI's start notice.
FOREIGN = ("pybullet build time", "running thomas2024.case1 -> ")


def _start(out: Path, results: Path) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "repro", "--results", str(results), "run", "thomas2024.case1",
           "--set", "camera_mode=exact", "--set", "duration=20", "--out", str(out)]
    return subprocess.Popen(cmd, cwd=Path(__file__).parents[1], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _wait_for_rows(proc: subprocess.Popen[str], out: Path, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while count_trace_rows(out) < 1:
        if proc.poll() is not None:
            pytest.fail(f"the run ended before any row was flushed: {proc.communicate()}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"no trace row after {timeout_s} s")
        time.sleep(0.05)


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)],
                         ids=["SIGINT", "SIGTERM"])
def test_signal_closes_the_run_as_interrupted_with_one_line(sig, code, tmp_path):
    out = tmp_path / "run"
    proc = _start(out, tmp_path / "results")
    _wait_for_rows(proc, out)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=15)

    assert proc.returncode == code, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if not line.startswith(FOREIGN)]
    assert len(lines) == 1, err
    match = re.fullmatch(rf"repro: interrupted \({sig.name}\) after (\d+) rows; "
                         rf"partial trace in {re.escape(str(out))}", lines[0])
    assert match, lines[0]
    n_rows = int(match.group(1))

    run = load_run(out)  # every file is there and readable
    assert run.manifest["status"] == "interrupted"
    assert run.manifest["reason"] == f"KeyboardInterrupt: {sig.name}"
    assert run.manifest["experiment"] == "case1"
    assert n_rows > 0 and run.manifest["n_rows"] == n_rows == len(run.trace)


def test_sigkill_leaves_a_running_manifest_that_repro_results_marks_interrupted(
    tmp_path, monkeypatch, capsys
):
    results = tmp_path / "results"
    out = results / "thomas2024" / "case1__x"
    proc = _start(out, results)
    _wait_for_rows(proc, out)
    proc.kill()
    proc.wait(timeout=10)  # reaped: its pid is gone
    assert proc.returncode == -signal.SIGKILL

    manifest = json.loads((out / "manifest.json").read_text())
    assert (manifest["status"], manifest["n_rows"]) == ("running", 0)
    assert manifest["pid"] == proc.pid
    n_rows = (out / "trace.csv").read_bytes().count(b"\n") - 1  # complete rows on disk
    assert n_rows > 0
    seen = effective_manifest(out)
    assert (seen["status"], seen["n_rows"]) == ("interrupted", n_rows)

    # `repro results` on that tree; the default runs it would make are faked (seconds, not
    # minutes): only the override folder's manifest is under test.
    def fake_run(config: Any, out_dir: Path) -> Path:
        (out_dir / "manifest.json").write_text(json.dumps(
            {"status": "completed", "config_hash": registry.compute_config_hash(config)}))
        return out_dir

    paper = registry.load_papers()["thomas2024"]
    paper = dataclasses.replace(paper, experiments=tuple(
        dataclasses.replace(exp, run=fake_run) for exp in paper.experiments))
    monkeypatch.setattr(registry, "load_papers", lambda: {"thomas2024": paper})
    assert cli.main(["--results", str(results), "results"]) == 0
    printed = capsys.readouterr().out
    assert f"interrupted  {out}  (process gone: pid {proc.pid}" in printed
    assert f"{n_rows} rows in trace.csv (rerun it)" in printed
    assert "1 marked interrupted" in printed

    fixed = json.loads((out / "manifest.json").read_text())
    assert (fixed["status"], fixed["n_rows"]) == ("interrupted", n_rows)
    assert fixed["reason"].startswith("process gone")
    assert (out / "trace.csv").read_bytes().count(b"\n") - 1 == n_rows  # trace untouched
