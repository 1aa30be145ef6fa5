"""Issue 40 for real: SIGINT, SIGTERM and SIGKILL during a forced remake of the committed runs
(``repro results --force -j 2`` on a copy of results/, and ``repro run`` onto a complete
run) leave every committed run folder byte-identical; the next ``repro results`` reports the
partial runs and reruns only what is missing. These tests read only files and processes (no
import of the staging code), so they run unchanged against the code before issue 40, and
fail there: its stopped runs had already overwritten chan2011's simulation and
simulation_render."""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAPERS = ("chan2011", "pomares2011", "thomas2024")
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def _tree(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _runs(results: Path) -> dict[str, dict[str, str]]:
    """Every run folder ``<results>/<paper>/<name>`` (hidden folders are not runs): its
    files and their sha256."""
    return {d.relative_to(results).as_posix(): _tree(d)
            for d in sorted(results.glob("*/*")) if (d / "manifest.json").is_file()}


def _copy(results: Path, papers: tuple[str, ...] = PAPERS) -> None:
    for paper in papers:
        shutil.copytree(ROOT / "results" / paper, results / paper)


def _rows(run_dir: Path) -> int:
    try:
        return max((run_dir / "trace.csv").read_bytes().count(b"\n") - 1, 0)
    except OSError:
        return 0


def _being_written(results: Path) -> list[Path]:
    """Folders a live run is writing, with trace rows: a ``running`` manifest, wherever the
    code under test writes it (in place, or in a staging folder)."""
    found = []
    for m in results.glob("*/**/manifest.json"):
        try:
            status = json.loads(m.read_text()).get("status")
        except (OSError, ValueError):
            continue
        if status == "running" and _rows(m.parent) > 0:
            found.append(m.parent)
    return found


def _wait_for_runs(proc: subprocess.Popen[str], results: Path, n: int) -> None:
    deadline = time.monotonic() + 120
    while len(_being_written(results)) < n:
        if proc.poll() is not None or time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail(f"{n} runs did not start: {proc.communicate()}")
        time.sleep(0.05)


def _wait_reaped(run_dirs: list[Path], timeout_s: float = 60.0) -> None:
    """Wait until the processes that wrote ``run_dirs`` are gone: killed workers are
    orphans, zombies (still "alive" to kill(pid, 0)) until init reaps them."""
    pids = [json.loads((d / "manifest.json").read_text())["pid"] for d in run_dirs]
    deadline = time.monotonic() + timeout_s
    for pid in pids:
        while time.monotonic() < deadline:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.05)


def _start(*argv: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "repro", *argv], cwd=ROOT, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # its own group: killpg reaches workers


def _stop(proc: subprocess.Popen[str], sig: signal.Signals, group: bool) -> tuple[str, str]:
    if group:  # a terminal's Ctrl-C, or kill -9 of the whole job
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    return proc.communicate(timeout=120)


@pytest.mark.parametrize(("sig", "group", "code"), [
    (signal.SIGINT, True, 130), (signal.SIGTERM, False, 143),
    (signal.SIGKILL, True, -signal.SIGKILL)], ids=["SIGINT-group", "SIGTERM", "SIGKILL-group"])
def test_a_signal_during_repro_results_force_leaves_every_committed_run_byte_identical(
        tmp_path: Path, sig: signal.Signals, group: bool, code: int) -> None:
    results = tmp_path / "results"
    _copy(results)
    before = _runs(results)
    assert len(before) == 21

    proc = _start("--results", str(results), "results", "--force", "-j", "2")
    _wait_for_runs(proc, results, 2)  # chan2011 simulation and simulation_render
    writers = _being_written(results)
    out, err = _stop(proc, sig, group)
    assert proc.returncode == code, err
    assert not re.search(r"^ran ", out, re.M), f"a run completed before the signal: {out}"
    _wait_reaped(writers)
    assert _runs(results) == before  # every committed file, byte for byte

    # the partial runs are aside, named after their folders
    partial = results / "chan2011" / ".partial"
    assert sorted(p.name for p in partial.iterdir()) == ["simulation", "simulation_render"]
    assert all(_rows(p) > 0 for p in partial.iterdir())

    # the next `repro results`: reports them, reruns only what is missing (ibvs, removed)
    shutil.rmtree(results / "chan2011" / "ibvs")
    proc = _start("--results", str(results), "results", "-j", "1")
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    why = "process gone: pid" if sig == signal.SIGKILL else f"KeyboardInterrupt: {sig.name}"
    for name in ("simulation", "simulation_render"):
        assert (f"interrupted  {partial / name}  (partial run: {why}" in out), out
        assert f"{results / 'chan2011' / name} kept as it was; removed when that run is next " \
            "made)" in out
    assert re.search(r"^ran    chan2011\.ibvs  \(no manifest", out, re.M), out
    assert "1 ran, 20 fresh, 0 skipped, 2 partial" in out
    after = _runs(results)
    assert {k: v for k, v in after.items() if k != "chan2011/ibvs"} == \
        {k: v for k, v in before.items() if k != "chan2011/ibvs"}
    assert after["chan2011/ibvs"].keys() == before["chan2011/ibvs"].keys()


def test_a_signal_during_repro_run_onto_a_complete_run_leaves_it_byte_identical(tmp_path):
    results = tmp_path / "results"
    _copy(results, ("chan2011",))
    before = _runs(results)
    proc = _start("--results", str(results), "run", "chan2011.simulation")
    _wait_for_runs(proc, results, 1)
    _, err = _stop(proc, signal.SIGTERM, group=False)
    assert proc.returncode == 143, err
    assert _runs(results) == before
    assert f"{results / 'chan2011' / 'simulation'} kept as it was" in err


def test_no_file_of_a_run_made_aside_names_where_it_was_made(tmp_path):
    """The URDF copies, scene.json, columns.json and the manifest name their neighbours by
    relative paths: a run swapped in from its staging folder names neither it nor any
    absolute path of this machine's results folder."""
    results = tmp_path / "results"
    proc = _start("--results", str(results), "run", "chan2011.ibvs")
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    run = results / "chan2011" / "ibvs"
    assert sorted(p.name for p in run.parent.iterdir()) == ["ibvs"]  # nothing left aside
    files = [p for p in run.rglob("*") if p.is_file()]
    assert {p.name for p in files} >= {"trace.csv", "manifest.json", "scene.json",
                                        "crs_a465.urdf"}
    for p in files:
        data = p.read_bytes()
        assert b".partial" not in data and str(tmp_path).encode() not in data, p
