"""Interrupted runs, for real (issue 7): a ``repro run`` subprocess is stopped by SIGINT,
SIGTERM or SIGKILL once its trace has rows; the run must end ``interrupted`` with one line
on stderr, or, after SIGKILL, be read and marked as interrupted by ``repro results``. A run
is made in its folder's staging folder (``<parent>/.partial/<name>``, issue 40): that is
where a stopped run's partial files are, and nothing is left under the folder's name."""

from __future__ import annotations

import dataclasses
import json
import os
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


def _partial(out: Path) -> Path:
    """Where a run of ``out`` is made (repro.runs.staging.staging_dir)."""
    return out.parent / ".partial" / out.name


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
    _wait_for_rows(proc, _partial(out))
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=15)

    assert proc.returncode == code, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if not line.startswith(FOREIGN)]
    assert len(lines) == 1, err
    match = re.fullmatch(rf"repro: interrupted \({sig.name}\) after (\d+) rows; "
                         rf"partial trace in {re.escape(str(_partial(out)))}; nothing in "
                         rf"{re.escape(str(out))}", lines[0])
    assert match, lines[0]
    n_rows = int(match.group(1))

    assert not out.exists()  # a new folder: no partial run under its name
    run = load_run(_partial(out))  # every file is there and readable
    assert run.manifest["status"] == "interrupted"
    assert run.manifest["reason"] == f"KeyboardInterrupt: {sig.name}"
    assert run.manifest["experiment"] == "case1"
    assert n_rows > 0 and run.manifest["n_rows"] == n_rows == len(run.trace)


def test_sigkill_leaves_a_running_manifest_that_repro_results_marks_interrupted(
    tmp_path, monkeypatch, capsys
):
    results = tmp_path / "results"
    target = results / "thomas2024" / "case1__x"
    out = _partial(target)
    proc = _start(target, results)
    _wait_for_rows(proc, out)
    proc.kill()
    proc.wait(timeout=10)  # reaped: its pid is gone
    assert proc.returncode == -signal.SIGKILL
    assert not target.exists()

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
    assert f"interrupted  {out}  (partial run: process gone: pid {proc.pid}" in printed
    assert f"{n_rows} rows in trace.csv (rerun it); {n_rows} rows; {target} has no run" \
        in printed
    assert "1 partial" in printed

    fixed = json.loads((out / "manifest.json").read_text())
    assert (fixed["status"], fixed["n_rows"]) == ("interrupted", n_rows)
    assert fixed["reason"].startswith("process gone")
    assert (out / "trace.csv").read_bytes().count(b"\n") - 1 == n_rows  # trace untouched


# --------------------------------------------------------------------------- issue 16: signals


def _start_exp(exp: str, out: Path, results: Path) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "repro", "--results", str(results), "run", exp,
           "--set", "camera_mode=exact", "--out", str(out)]
    return subprocess.Popen(cmd, cwd=Path(__file__).parents[1], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("delay_s, second", [(0.0, False), (0.35, True), (0.8, False)],
                         ids=["first-rows", "twice-50ms", "later"])
def test_chan2011_nmpc_run_stops_between_steps_on_sigint(tmp_path, delay_s, second):
    """CasADi (the NMPC's SQP, its kinematics functions) runs in most of a chan2011 step. A
    KeyboardInterrupt raised inside it was swallowed (the run went on) or became a
    SystemError / NotImplementedError (a crash); now every signal is held through the step
    (repro.runs.signals.StepGuard) and a second one, 50 ms later, is ignored."""
    out = _partial(tmp_path / "run")
    proc = _start_exp("chan2011.simulation", tmp_path / "run", tmp_path / "results")
    _wait_for_rows(proc, out, timeout_s=60.0)
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    if second:
        time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if not ln.startswith(FOREIGN)
             and not ln.startswith("running chan2011")]
    assert len(lines) == 1 and lines[0].startswith("repro: interrupted (SIGINT)"), err
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "interrupted"
    assert manifest["reason"] == "KeyboardInterrupt: SIGINT"
    assert manifest["n_rows"] == count_trace_rows(out) > 0


def test_repro_results_stops_on_sigterm(tmp_path):
    """`repro results` with stale runs (one after another, and in two workers): SIGTERM
    ends it with 143, the run it was making closed as interrupted, no other started."""
    for jobs in ("1", "2"):
        results = tmp_path / f"results{jobs}"
        cmd = [sys.executable, "-m", "repro", "--results", str(results), "results",
               "--paper", "chan2011", "-j", jobs]
        proc = subprocess.Popen(cmd, cwd=Path(__file__).parents[1], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while not any(count_trace_rows(d) for d in (results / "chan2011" / ".partial").glob("*")):
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 143, err
        assert "Traceback" not in err
        statuses = [json.loads((d / "manifest.json").read_text())["status"]
                    for d in (results / "chan2011" / ".partial").glob("*")
                    if (d / "manifest.json").is_file()]
        assert statuses and set(statuses) == {"interrupted"}, statuses
        assert not list((results / "chan2011").glob("*/manifest.json"))  # none swapped in


def test_a_signal_is_held_through_a_deferred_block_and_a_step():
    from repro.runs.signals import StepGuard, deferred, stop_on_signals

    fired: list[int] = []
    with pytest.raises(KeyboardInterrupt, match="SIGINT"), stop_on_signals(fired):
        with deferred():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.01)
            reached = True  # not raised inside the block
        raise AssertionError("not reached")  # pragma: no cover
    assert reached and fired == [signal.SIGINT]
    signal.signal(signal.SIGINT, signal.default_int_handler)  # ignored after a real stop
    signal.signal(signal.SIGTERM, signal.SIG_DFL)

    fired = []
    guard = StepGuard()
    steps = []
    with pytest.raises(KeyboardInterrupt), stop_on_signals(fired):
        for k in range(5):
            guard.step()
            steps.append(k)
            if k == 2:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.01)
                steps.append("end of 2")
    assert steps == [0, 1, 2, "end of 2"]
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def test_a_manifest_tmp_left_by_a_kill_is_recovered(tmp_path):
    from repro.runs.trace import recover_manifest_tmp

    run = tmp_path / "run"
    run.mkdir()
    (run / "manifest.json.tmp").write_text('{"status": "running", "n_rows": 0}')
    assert recover_manifest_tmp(run)
    assert json.loads((run / "manifest.json").read_text())["status"] == "running"
    (run / "manifest.json.tmp").write_text('{"status": "runn')  # cut: left alone
    assert not recover_manifest_tmp(run)


def test_a_signal_during_the_closing_write_leaves_a_whole_manifest(tmp_path, monkeypatch):
    """The closing manifest write is held against signals: the signal is raised once the
    manifest says completed with every row, never between the temporary file and its
    rename."""
    from repro.runs import trace
    from repro.runs.signals import stop_on_signals

    rec = trace.TraceRecorder(tmp_path / "run", experiment="x", paper="p", config={"a": 1},
                              seed=0)
    for k in range(3):
        rec.record({"t": 0.1 * k, "step": k})
    real = trace.environment

    def signalled() -> dict:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.01)
        return real()

    monkeypatch.setattr(trace, "environment", signalled)
    with pytest.raises(KeyboardInterrupt), stop_on_signals([]):
        rec.close()
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    manifest = json.loads((tmp_path / "run" / "manifest.json").read_text())
    assert (manifest["status"], manifest["n_rows"]) == ("completed", 3)
    assert not (tmp_path / "run" / "manifest.json.tmp").exists()
