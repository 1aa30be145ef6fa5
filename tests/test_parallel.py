"""``repro results -j N``: stale experiments in worker processes of their own, each run
closed exactly as in the serial path, its manifest saying how many runs shared the machine;
a worker killed outright leaves a run marked interrupted while the others go on; SIGTERM to
``repro results`` closes every live run as interrupted and starts no other."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from runfiles import complete_run_files
from test_cli import FakeCfg, NoVideoCfg

from repro import cli
from repro.runs import registry
from repro.runs.registry import Experiment, Paper
from repro.runs.trace import CONCURRENT_RUNS_ENV, TraceRecorder, count_trace_rows


def _run(paper: str, kill: bool = False):  # type: ignore[no-untyped-def]
    def run(config: Any, out_dir: Path) -> Path:
        rec = TraceRecorder(out_dir, experiment=out_dir.name, paper=paper, config=config,
                            seed=0)
        rec.record({"t": 0.0, "pid": os.getpid(),
                    "concurrent": int(os.environ.get(CONCURRENT_RUNS_ENV, "1"))})
        rec.flush()
        if kill:
            os.kill(os.getpid(), signal.SIGKILL)
        done = rec.close()
        complete_run_files(out_dir)
        return done
    return run


@pytest.fixture
def papers(monkeypatch: pytest.MonkeyPatch) -> dict[str, Paper]:
    def exp(paper: str, name: str, cfg: type, kill: bool = False) -> Experiment:
        return Experiment(name=name, paper=paper, description=name, config_cls=cfg,
                          run=_run(paper, kill))
    papers = {"fake": Paper("fake", (exp("fake", "case1", FakeCfg),
                                     exp("fake", "case2", NoVideoCfg))),
              "other": Paper("other", (exp("other", "case1", FakeCfg),))}
    monkeypatch.setattr(registry, "load_papers", lambda: papers)
    return papers


def _manifest(d: Path) -> dict[str, Any]:
    return json.loads((d / "manifest.json").read_text())


def test_each_stale_experiment_runs_in_a_worker_and_says_so(papers, tmp_path, capsys) -> None:
    assert cli.main(["--results", str(tmp_path), "results", "-j", "2"]) == 0
    out = capsys.readouterr().out
    dirs = [tmp_path / "fake" / "case1", tmp_path / "fake" / "case2", tmp_path / "other" / "case1"]
    for d in dirs:
        m = _manifest(d)
        assert m["status"] == "completed" and m["concurrent_runs"] == 2
        assert m["pid"] != os.getpid()  # a worker of its own
        assert f"ran    {d.parent.name}.{d.name}" in out
    assert "3 ran, 0 fresh" in out
    assert cli.main(["--results", str(tmp_path), "results", "-j", "2"]) == 0
    assert "0 ran, 3 fresh" in capsys.readouterr().out
    # serially, in this process: one run at a time
    assert cli.main(["--results", str(tmp_path), "results", "--force", "-j", "1"]) == 0
    assert _manifest(dirs[0])["concurrent_runs"] == 1 and _manifest(dirs[0])["pid"] == os.getpid()


def test_a_worker_killed_outright_is_marked_interrupted_and_the_rest_run(
        papers, monkeypatch, tmp_path, capsys) -> None:
    fake = papers["fake"]
    killed = Experiment(name="case2", paper="fake", description="", config_cls=NoVideoCfg,
                        run=_run("fake", kill=True))
    monkeypatch.setitem(papers, "fake", Paper("fake", (fake.experiments[0], killed)))
    assert cli.main(["--results", str(tmp_path), "results", "-j", "2"]) == 1
    captured = capsys.readouterr()
    partial = tmp_path / "fake" / ".partial" / "case2"  # the run stays aside, marked
    m = _manifest(partial)
    assert m["status"] == "interrupted" and "process gone" in m["reason"]
    assert not (tmp_path / "fake" / "case2").exists()  # nothing under the run's own name
    assert f"lost   fake.case2  (worker died (exit -9); marked interrupted) -> {partial}" \
        in captured.err
    assert _manifest(tmp_path / "fake" / "case1")["status"] == "completed"
    assert _manifest(tmp_path / "other" / "case1")["status"] == "completed"
    assert "2 ran" in captured.out


@pytest.mark.parametrize("jobs", ["0", "-1", "two"])
def test_a_bad_job_count_is_refused(papers, tmp_path, capsys, jobs: str) -> None:
    assert cli.main(["--results", str(tmp_path), "results", "-j", jobs]) == 2
    assert "-j/--jobs" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_sigterm_closes_every_live_run_as_interrupted(tmp_path: Path) -> None:
    """Real runs (thomas2024, rendered camera): two start, SIGTERM reaches `repro results`,
    both close as interrupted with their rows, no third starts, exit code 143."""
    results = tmp_path / "results"
    proc = subprocess.Popen([sys.executable, "-m", "repro", "--results", str(results),
                             "results", "--paper", "thomas2024", "-j", "2"],
                            cwd=Path(__file__).parents[1], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    runs: list[Path] = []
    partial = results / "thomas2024" / ".partial"  # where the runs are made
    while len(runs) < 2:
        runs = [d for d in partial.glob("*") if count_trace_rows(d) > 0] \
            if partial.is_dir() else []
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"two runs did not start: {proc.communicate()}")
        time.sleep(0.1)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    started = sorted(partial.glob("*/manifest.json"))
    assert len(started) == 2, started
    assert not list((results / "thomas2024").glob("*/manifest.json"))  # none swapped in
    for m in started:
        man = json.loads(m.read_text())
        assert man["status"] == "interrupted" and man["n_rows"] > 0 and man["concurrent_runs"] == 2
    assert err.count("closed as interrupted") == 2
