"""Runs written aside and swapped in whole (issue 40, repro/runs/staging.py): a run that
does not return leaves the run it was replacing byte for byte, its partial files in
``<parent>/.partial/<name>``; a swap a kill cut short is undone or finished; ``repro results``
lists the partial runs and reruns only what is missing or stale; a sweep's variant folder is
there only once judged. The real signals on real runs: tests/test_stopped_remake.py."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from runfiles import write_whole_run

from repro import cli
from repro.config import param
from repro.errors import ReproError
from repro.runs import registry, staging
from repro.runs.registry import Experiment, Paper
from repro.runs.staging import PARTIAL_DIR, REPLACED_DIR, recover, staged, staging_dir

ROOT = Path(__file__).resolve().parents[1]


def tree(folder: Path) -> dict[str, str]:
    """Every file under ``folder``: relative path -> sha256 of its bytes."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def old_run(target: Path) -> dict[str, str]:
    """A complete run in ``target`` (with a sub-folder); its tree."""
    write_whole_run(target, status="completed", experiment=target.name, paper="fake",
                    config_hash="old")
    (target / "meshes").mkdir()
    (target / "meshes" / "a.obj").write_text("v 0 0 0\n")
    return tree(target)


# --------------------------------------------------------------------------- the swap


def test_a_returned_run_replaces_its_folder_whole_and_leaves_nothing_aside(tmp_path):
    target = tmp_path / "paper" / "case"
    old_run(target)
    with staged(target) as stage:
        assert stage == tmp_path / "paper" / PARTIAL_DIR / "case"
        assert list(stage.iterdir()) == []  # a fresh folder, not the old run's
        assert (target / "meshes" / "a.obj").is_file()  # the old run in place meanwhile
        (stage / "manifest.json").write_text('{"status": "completed"}')
        (stage / "trace.csv").write_text("t\n0.5\n")
    assert tree(target).keys() == {"manifest.json", "trace.csv"}  # no old file survives
    assert (target / "trace.csv").read_text() == "t\n0.5\n"
    assert sorted(p.name for p in target.parent.iterdir()) == ["case"]  # no .partial left


@pytest.mark.parametrize("error", [KeyboardInterrupt("SIGTERM"), RuntimeError("crash")],
                         ids=["interrupted", "crashed"])
def test_a_run_that_raises_leaves_the_old_run_byte_identical(tmp_path, error):
    target = tmp_path / "paper" / "case"
    before = old_run(target)
    with pytest.raises(type(error)), staged(target) as stage:
        (stage / "manifest.json").write_text('{"status": "interrupted"}')
        (stage / "trace.csv").write_text("t\n0.0\n0.1\n")
        raise error
    assert tree(target) == before
    assert tree(staging_dir(target)) == tree(stage)  # the partial run aside, kept
    assert json.loads((stage / "manifest.json").read_text())["status"] == "interrupted"


def test_a_run_stopped_before_it_recorded_anything_leaves_no_staging_folder(tmp_path):
    target = tmp_path / "paper" / "case"
    before = old_run(target)
    with pytest.raises(KeyboardInterrupt), staged(target) as stage:
        (stage / "robot.urdf").write_text("<robot/>")  # no manifest: nothing recorded
        raise KeyboardInterrupt
    assert tree(target) == before
    assert sorted(p.name for p in target.parent.iterdir()) == ["case"]


def test_a_new_run_starts_in_an_emptied_staging_folder(tmp_path):
    """A dead run's files (an old URDF copy, frames) are not carried into the next run."""
    target = tmp_path / "paper" / "case"
    dead = staging_dir(target)
    (dead / "frames").mkdir(parents=True)
    (dead / "frames" / "f_0.png").write_bytes(b"png")
    (dead / "manifest.json").write_text('{"status": "running", "pid": 1}')
    with staged(target) as stage:
        assert stage == dead and list(stage.iterdir()) == []
        (stage / "manifest.json").write_text('{"status": "completed"}')
    assert tree(target).keys() == {"manifest.json"}


def test_a_failed_second_rename_puts_the_old_run_back(tmp_path, monkeypatch):
    target = tmp_path / "paper" / "case"
    before = old_run(target)
    real = os.rename
    calls: list[tuple[Path, Path]] = []

    def rename(src: Any, dst: Any) -> None:
        calls.append((Path(src), Path(dst)))
        if len(calls) == 2:  # staging -> target
            raise OSError(5, "Input/output error")
        real(src, dst)

    monkeypatch.setattr(staging.os, "rename", rename)
    with pytest.raises(OSError), staged(target) as stage:
        (stage / "manifest.json").write_text('{"status": "completed"}')
    assert [c[1] for c in calls] == [target.parent / REPLACED_DIR / "case", target, target]
    assert tree(target) == before  # the third rename: the old run back


def test_another_process_writing_the_same_folder_is_refused(tmp_path):
    """The lock is on the staging folder (an flock: released by the kernel when the holder
    dies); a second process is refused in one line."""
    target = tmp_path / "paper" / "case"
    with staged(target):
        code = ("import sys; from repro.runs.staging import staged\n"
                "with staged(sys.argv[1]): pass\n")
        proc = subprocess.run([sys.executable, "-c", code, str(target)], cwd=ROOT,
                              capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert proc.returncode == 1 and "being written by another repro process" in proc.stderr


# --------------------------------------------------------------------------- killed swaps

KILL_IN_SWAP = textwrap.dedent("""
    import os, shutil, signal, sys
    from pathlib import Path
    from repro.runs import staging

    target, when = Path(sys.argv[1]), sys.argv[2]
    real_rename, real_rmtree, n = os.rename, shutil.rmtree, [0]

    def rename(src, dst):
        real_rename(src, dst)
        n[0] += 1
        if when == "after-first-rename" and n[0] == 1:
            os.kill(os.getpid(), signal.SIGKILL)

    def rmtree(path, *a, **k):
        if when == "before-removal" and staging.REPLACED_DIR in Path(path).parts:
            os.kill(os.getpid(), signal.SIGKILL)
        real_rmtree(path, *a, **k)

    staging.os.rename, staging.shutil.rmtree = rename, rmtree
    with staging.staged(target) as stage:
        (stage / "manifest.json").write_text('{"status": "completed", "run": "new"}')
""")


def _kill_in_swap(target: Path, when: str) -> None:
    proc = subprocess.run([sys.executable, "-c", KILL_IN_SWAP, str(target), when], cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True)
    assert proc.returncode == -signal.SIGKILL, proc.stderr


def test_a_kill_between_the_two_renames_is_undone(tmp_path):
    """Killed with the old run renamed aside and the new one not yet in: the next run of the
    folder (or repro results) puts the old run back, byte for byte."""
    target = tmp_path / "paper" / "case"
    before = old_run(target)
    _kill_in_swap(target, "after-first-rename")
    assert not target.exists() and tree(target.parent / REPLACED_DIR / "case") == before
    assert "restored" in str(recover(target))
    assert tree(target) == before
    assert sorted(p.name for p in target.parent.iterdir()) == [PARTIAL_DIR, "case"]
    assert json.loads((staging_dir(target) / "manifest.json").read_text())["run"] == "new"


def test_a_kill_after_the_new_run_came_in_drops_the_old(tmp_path):
    target = tmp_path / "paper" / "case"
    old_run(target)
    _kill_in_swap(target, "before-removal")
    assert (target.parent / REPLACED_DIR / "case").is_dir()
    assert "removed" in str(recover(target))
    assert json.loads((target / "manifest.json").read_text())["run"] == "new"
    assert sorted(p.name for p in target.parent.iterdir()) == ["case"]


# --------------------------------------------------------------------------- the CLI


@dataclass(frozen=True)
class Cfg:
    gain: float = param(0.4, range=(0.0, 10.0), help="a gain")


class Run:
    """A fake run writing a whole run, or, with ``stop_after`` rows, a partial run closed as
    interrupted before raising the KeyboardInterrupt a SIGINT would."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.stop_after: int | None = None
        self.wrote_in: list[Path] = []

    def __call__(self, config: Any, out_dir: Path) -> Path:
        self.wrote_in.append(out_dir)
        digest = registry.compute_config_hash(config)
        if self.stop_after is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            (out_dir / "trace.csv").write_text("t\n" + "0.1\n" * self.stop_after)
            (out_dir / "manifest.json").write_text(json.dumps({
                "status": "interrupted", "reason": "KeyboardInterrupt: SIGINT",
                "n_rows": self.stop_after, "experiment": self.name, "config_hash": digest}))
            raise KeyboardInterrupt("SIGINT")
        write_whole_run(out_dir, status="completed", experiment=self.name, paper="fake",
                        config_hash=digest, made="new")
        return out_dir


@pytest.fixture
def runs(monkeypatch) -> dict[str, Run]:
    runs = {n: Run(n) for n in ("a", "b", "c")}
    paper = Paper("fake", tuple(Experiment(name=n, paper="fake", description=n, config_cls=Cfg,
                                           run=r) for n, r in runs.items()))
    monkeypatch.setattr(registry, "load_papers", lambda: {"fake": paper})
    return runs


def _committed(results: Path, name: str) -> dict[str, str]:
    write_whole_run(results / "fake" / name, status="completed", experiment=name, paper="fake",
                    config_hash=registry.compute_config_hash(Cfg()), made="old")
    return tree(results / "fake" / name)


def test_a_stopped_forced_remake_keeps_the_run_and_repro_results_reruns_only_what_is_due(
        runs, tmp_path, capsys):
    results = tmp_path / "results"
    kept = {n: _committed(results, n) for n in ("a", "b")}  # c is missing
    for name in ("a", "b"):  # `repro run fake.<name>` onto its complete run, stopped
        runs[name].stop_after = 3
        assert cli.main(["--results", str(results), "run", f"fake.{name}",
                         "--out", str(results / "fake" / name), "--force"]) == 130
        err = capsys.readouterr().err
        partial = results / "fake" / PARTIAL_DIR / name
        assert (f"repro: interrupted (SIGINT) after 3 rows; partial trace in {partial}; "
                f"{results / 'fake' / name} kept as it was") in err
        assert tree(results / "fake" / name) == kept[name]
        runs[name].stop_after = None

    # b made stale (another config recorded): rerun with c (missing), a left alone
    manifest = json.loads((results / "fake" / "b" / "manifest.json").read_text())
    (results / "fake" / "b" / "manifest.json").write_text(
        json.dumps({**manifest, "config_hash": "other"}))
    assert cli.main(["--results", str(results), "results", "-j", "1"]) == 0
    out = capsys.readouterr().out
    pa, pb = (results / "fake" / PARTIAL_DIR / n for n in ("a", "b"))
    assert (f"interrupted  {pa}  (partial run: KeyboardInterrupt: SIGINT; 3 rows; "
            f"{results / 'fake' / 'a'} kept as it was; removed when that run is next made)") \
        in out
    assert f"interrupted  {pb}  (partial run: KeyboardInterrupt: SIGINT; 3 rows; " in out
    assert "rerun now)" in out
    assert "ran    fake.b  (config changed" in out and "ran    fake.c  (no manifest" in out
    assert "fresh  fake.a" in out and "2 ran, 1 fresh" in out
    assert "2 partial" in out
    assert tree(results / "fake" / "a") == kept["a"]  # fresh: not rerun
    assert json.loads((results / "fake" / "b" / "manifest.json").read_text())["made"] == "new"
    assert tree(pa)["trace.csv"] and not pb.exists()  # b's partial went with its rerun

    # a's partial is listed until a runs again, then it goes
    assert cli.main(["--results", str(results), "results", "--force", "-j", "1"]) == 0
    assert "1 partial" in capsys.readouterr().out
    assert sorted(p.name for p in (results / "fake").iterdir()) == ["a", "b", "c"]
    assert cli.main(["--results", str(results), "results"]) == 0
    assert "partial" not in capsys.readouterr().out


def test_repro_results_restores_a_run_a_killed_swap_left_aside(runs, tmp_path, capsys):
    results = tmp_path / "results"
    for name in ("a", "b", "c"):
        _committed(results, name)
    before = tree(results / "fake" / "a")
    _kill_in_swap(results / "fake" / "a", "after-first-rename")
    assert not (results / "fake" / "a").exists()
    assert cli.main(["--results", str(results), "results"]) == 0
    out = capsys.readouterr().out
    assert f"recovered    restored {results / 'fake' / 'a'}" in out
    assert "0 ran, 3 fresh" in out and "1 partial" in out  # the new run that did not come in
    assert tree(results / "fake" / "a") == before


def test_a_partial_folder_is_not_a_run_for_the_report(tmp_path):
    from repro.runs.report import _read_manifests

    paper = tmp_path / "fake"
    write_whole_run(paper / "a", status="completed", config_hash="x")
    write_whole_run(paper / PARTIAL_DIR / "a", status="interrupted", config_hash="x")
    write_whole_run(paper / REPLACED_DIR / "b", status="completed", config_hash="x")
    assert [run for run, _ in _read_manifests(paper)] == ["a"]


@pytest.mark.parametrize("out", [f"results/fake/{PARTIAL_DIR}/a", f"x/{REPLACED_DIR}/b"])
def test_an_out_inside_a_staging_folder_is_refused(runs, tmp_path, monkeypatch, capsys, out):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "fake.a", "--out", out]) == 2
    assert "is inside a .partial or .replaced folder" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == [] and runs["a"].wrote_in == []


def test_a_run_of_a_new_folder_is_written_aside_too(runs, tmp_path):
    out = tmp_path / "mine" / "run"
    runs["a"].stop_after = 2
    assert cli.main(["run", "fake.a", "--out", str(out)]) == 130
    assert not out.exists()  # nothing partial under the run's name
    assert (tmp_path / "mine" / PARTIAL_DIR / "run" / "trace.csv").is_file()
    runs["a"].stop_after = None
    assert cli.main(["run", "fake.a", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.parent.iterdir()) == ["run"]
    assert registry.run_folder_lock is staging.run_folder_lock  # one lock, reused


def test_the_lock_error_names_the_folder(tmp_path):
    with staging.run_folder_lock(tmp_path / "x"), pytest.raises(ReproError, match="x is being"):
        with staging.run_folder_lock(tmp_path / "x"):
            pass


# --------------------------------------------------------------------------- sweeps


def test_a_stopped_variant_leaves_no_folder_a_resumed_sweep_takes_for_judged(tmp_path):
    from test_sweep import Runner, _papers

    from repro.runs.sweep import VERDICTS_FILE, run_sweep

    class Stopping(Runner):
        def __call__(self, config: Any, out_dir: Path) -> Path:
            done = super().__call__(config, out_dir)
            if len(self.calls) == 3:  # the third variant: its files written, then a SIGINT
                raise KeyboardInterrupt("SIGINT")
            return done

    runner = Stopping()
    with pytest.raises(KeyboardInterrupt):
        run_sweep("fake.case", 4, seed=0, results_dir=tmp_path, papers=_papers(runner))
    variants = tmp_path / "sweeps" / "case" / "variants"
    judged = sorted(p.name for p in variants.iterdir() if p.name != PARTIAL_DIR)
    assert len(judged) == 2 and all((variants / h / VERDICTS_FILE).is_file() for h in judged)
    [partial] = (variants / PARTIAL_DIR).iterdir()  # the stopped one, aside, not judged
    assert not (partial / VERDICTS_FILE).exists() and partial.name not in judged

    resumed = Runner()
    path = run_sweep("fake.case", 4, seed=0, results_dir=tmp_path, papers=_papers(resumed))
    assert len(resumed.calls) == 2  # the stopped variant and the one never started
    names = sorted(p.name for p in variants.iterdir())
    assert len(names) == 4 and {*judged, partial.name} <= set(names)  # no .partial left
    assert all((variants / h / VERDICTS_FILE).is_file() for h in names)
    assert len(path.read_text().splitlines()) == 5  # header + 4 rows


def test_a_signal_during_the_swap_is_acted_on_once_the_run_is_in(runs, tmp_path, monkeypatch,
                                                                  capsys):
    """SIGINT between the two renames is held until the swap is done: the new run is whole
    in its folder, the old one gone, and the one line says so (exit 130 all the same)."""
    results = tmp_path / "results"
    _committed(results, "a")
    real = staging._swap

    def signalled(stage: Path, target: Path) -> None:
        os.kill(os.getpid(), signal.SIGINT)
        real(stage, target)

    monkeypatch.setattr(staging, "_swap", signalled)
    try:
        assert cli.main(["--results", str(results), "run", "fake.a"]) == 130
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    err = capsys.readouterr().err
    assert f"repro: interrupted (SIGINT) as the run closed; it is complete in " \
        f"{results / 'fake' / 'a'}" in err
    assert json.loads((results / "fake" / "a" / "manifest.json").read_text())["made"] == "new"
    assert sorted(p.name for p in (results / "fake").iterdir()) == ["a"]


def test_a_live_run_in_a_staging_folder_is_busy_not_partial(runs, tmp_path, capsys):
    import socket

    results = tmp_path / "results"
    for name in ("a", "b", "c"):
        _committed(results, name)
    write_whole_run(results / "fake" / PARTIAL_DIR / "b", status="running", pid=os.getpid(),
                    hostname=socket.gethostname(), config_hash="x")
    assert cli.main(["--results", str(results), "results", "--force", "-j", "1"]) == 0
    out = capsys.readouterr().out
    assert f"busy   fake.b  (running as pid {os.getpid()}" in out
    assert "partial" not in out and "2 ran" in out and runs["b"].wrote_in == []
