"""Tests of repro.runs.trace: the run files are complete, exact and survive crashes."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from repro.errors import ConfigError, ReproError, UnknownChoiceError
from repro.runs.trace import (
    MANIFEST_KEYS,
    TRACKED_PACKAGES,
    TraceRecorder,
    config_hash,
    count_trace_rows,
    effective_manifest,
    load_run,
    mark_if_gone,
    process_gone,
    to_jsonable,
    update_manifest,
)


@dataclass(frozen=True)
class Cfg:
    gain: float = 1.5
    n_steps: int = 10
    target: tuple[float, ...] = (0.1, 0.2, 0.3)
    name: str = "reach"
    weights: np.ndarray = field(default_factory=lambda: np.array([1.0, 2.0]))


def _recorder(path: Path, **kwargs) -> TraceRecorder:
    defaults = dict(experiment="reach", paper="thomas2024", config=Cfg(), seed=3)
    defaults.update(kwargs)
    return TraceRecorder(path, **defaults)


def test_round_trip_floats_are_bit_identical(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    values = np.concatenate(
        [
            rng.standard_normal(500) * 10.0 ** rng.integers(-300, 300, 500),
            [0.1 + 0.2, 1 / 3, 5e-324, 1.7976931348623157e308, -0.0, np.pi],
        ]
    )
    with _recorder(tmp_path, flush_every=7) as rec:
        for k, v in enumerate(values):
            rec.record({"t": k * 0.01, "step": k, "x": np.float64(v), "ok": bool(k % 2), "m": "a"})
    run = load_run(tmp_path)
    assert list(run.trace.columns) == ["t", "step", "x", "ok", "m"]
    assert len(run.trace) == len(values)
    x = run.trace["x"].to_numpy()
    assert x.dtype == np.float64
    assert np.array_equal(x.view(np.int64), values.view(np.int64))  # same bits, incl. -0.0
    assert np.array_equal(run.trace["t"].to_numpy(), np.arange(len(values)) * 0.01)
    assert run.trace["step"].dtype == np.int64
    assert run.trace["ok"].dtype == bool
    assert run.trace["ok"].tolist() == [bool(k % 2) for k in range(len(values))]


def test_missing_key_reads_back_as_nan_and_nonfinite_round_trip(tmp_path: Path) -> None:
    with _recorder(tmp_path) as rec:
        rec.record({"t": 0.0, "x": 1.0, "label": "a"})
        rec.record({"t": 0.1, "label": 'b,"quoted"\nline'})
        rec.record({"t": 0.2, "x": float("inf"), "label": "c"})
        rec.record({"t": 0.3, "x": float("nan"), "label": "d"})
    trace = load_run(tmp_path).trace
    assert np.isnan(trace["x"][1]) and np.isinf(trace["x"][2]) and np.isnan(trace["x"][3])
    assert trace["label"][1] == 'b,"quoted"\nline'


def test_schema_violation_raises_naming_the_key(tmp_path: Path) -> None:
    rec = _recorder(tmp_path)
    rec.record({"t": 0.0, "x": 1.0})
    with pytest.raises(ReproError, match="'surprise'"):
        rec.record({"t": 0.1, "x": 2.0, "surprise": 3.0})
    with pytest.raises(ReproError, match="not a scalar"):
        rec.record({"t": 0.1, "x": np.zeros(3)})
    rec.close()
    with pytest.raises(ReproError, match="closed"):
        rec.record({"t": 0.2, "x": 1.0})


def test_rows_are_flushed_every_flush_every(tmp_path: Path) -> None:
    rec = _recorder(tmp_path, flush_every=50, flush_interval_s=3600.0)
    for k in range(120):
        rec.record({"step": k})
    on_disk = pd.read_csv(tmp_path / "trace.csv")
    assert len(on_disk) == 100
    rec.close()
    assert len(pd.read_csv(tmp_path / "trace.csv")) == 120


def test_crash_inside_with_leaves_partial_trace_and_crashed_manifest(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError, match="solver diverged"):
        with _recorder(tmp_path, flush_every=10) as rec:
            for k in range(37):
                rec.record({"t": k * 0.1, "step": k})
            rec.event(3.6, 36, "warning", "about to fail")
            raise RuntimeError("solver diverged")
    run = load_run(tmp_path)
    assert len(run.trace) == 37
    assert run.trace["step"].tolist() == list(range(37))
    assert run.manifest["status"] == "crashed"
    assert run.manifest["reason"] == "RuntimeError: solver diverged"
    assert run.manifest["n_rows"] == 37 and run.manifest["n_events"] == 1


def test_keyboard_interrupt_is_recorded_as_interrupted(tmp_path: Path) -> None:
    with pytest.raises(KeyboardInterrupt):
        with _recorder(tmp_path) as rec:
            rec.record({"t": 0.0})
            raise KeyboardInterrupt
    assert load_run(tmp_path).manifest["status"] == "interrupted"


def test_manifest_is_running_until_closed(tmp_path: Path) -> None:
    rec = _recorder(tmp_path)
    rec.record({"t": 0.0})
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["status"] == "running"
    rec.close()
    assert json.loads((tmp_path / "manifest.json").read_text())["status"] == "completed"


def test_manifest_fields(tmp_path: Path) -> None:
    cfg = Cfg()
    with _recorder(tmp_path, config=cfg, seed=7) as rec:
        rec.record({"t": 0.0, "err_m": 0.5})
        rec.record({"t": 0.1, "err_m": 0.25})
        rec.event(0.1, 1, "goal_reached")
        rec.summary["final_err_m"] = np.float64(0.25)
        rec.summary["path"] = np.array([1, 2])
    manifest = load_run(tmp_path).manifest
    assert tuple(manifest) == MANIFEST_KEYS
    assert manifest["experiment"] == "reach" and manifest["paper"] == "thomas2024"
    assert manifest["status"] == "completed" and manifest["reason"] == ""
    assert manifest["config"] == {
        "gain": 1.5,
        "n_steps": 10,
        "target": [0.1, 0.2, 0.3],
        "name": "reach",
        "weights": [1.0, 2.0],
    }
    assert manifest["config_hash"] == config_hash(cfg)
    assert manifest["seed"] == 7
    assert manifest["columns"] == ["t", "err_m"]
    assert manifest["n_rows"] == 2 and manifest["n_events"] == 1
    assert manifest["started_at"].endswith("Z") and manifest["ended_at"] >= manifest["started_at"]
    assert manifest["wall_time_s"] >= 0.0
    assert manifest["python"].count(".") == 2
    assert manifest["platform"] and manifest["cpu"]
    assert set(manifest["packages"]) == set(TRACKED_PACKAGES)
    assert manifest["packages"]["numpy"] == np.__version__
    assert all(isinstance(v, str) and v for v in manifest["packages"].values())
    assert manifest["git_sha"] is None or len(manifest["git_sha"]) == 40
    assert manifest["git_dirty"] in (None, True, False)
    assert manifest["repro_version"]
    assert manifest["summary"] == {"final_err_m": 0.25, "path": [1, 2]}


def test_close_is_idempotent(tmp_path: Path) -> None:
    rec = _recorder(tmp_path)
    rec.record({"t": 0.0})
    first = rec.close()
    before = first.read_text()
    assert rec.close(status="crashed", reason="late") == first
    assert first.read_text() == before
    with pytest.raises(UnknownChoiceError):
        _recorder(tmp_path / "other").close(status="fine")


def test_events_and_scene(tmp_path: Path) -> None:
    with _recorder(tmp_path) as rec:
        rec.event(0.5, 5, "contact", "link 7, normal force 3.2 N")
        rec.event(1.0, 10, "goal_reached")
        assert len(pd.read_csv(tmp_path / "events.csv")) == 2  # written immediately
        rec.set_scene({"obstacles": [{"pos": np.array([0.1, 0.2, 0.3])}], "poses": []})
        rec.set_scene({"obstacles": [], "poses": [np.eye(2), (1, 2)]})
    run = load_run(tmp_path)
    assert list(run.events.columns) == ["t", "step", "kind", "detail"]
    assert run.events["kind"].tolist() == ["contact", "goal_reached"]
    assert run.events["detail"].tolist() == ["link 7, normal force 3.2 N", ""]
    assert run.events["step"].tolist() == [5, 10]
    assert run.scene == {"obstacles": [], "poses": [[[1.0, 0.0], [0.0, 1.0]], [1, 2]]}


def test_empty_run_loads(tmp_path: Path) -> None:
    _recorder(tmp_path).close()
    run = load_run(tmp_path)
    assert run.trace.empty and run.events.empty and run.scene == {}


def test_load_run_reports_missing_file(tmp_path: Path) -> None:
    with _recorder(tmp_path) as rec:
        rec.record({"t": 0.0})
    (tmp_path / "events.csv").unlink()
    with pytest.raises(ReproError, match="events.csv"):
        load_run(tmp_path)
    with pytest.raises(ReproError, match="does not exist"):
        load_run(tmp_path / "nope")


def test_config_hash_is_stable_and_sensitive() -> None:
    cfg = Cfg()
    h = config_hash(cfg)
    assert len(h) == 64 and h == config_hash(Cfg())
    assert h == config_hash(replace(cfg, target=[0.1, 0.2, 0.3]))  # tuple vs list
    assert config_hash(replace(cfg, gain=1.5000000000000002)) != h
    assert config_hash(replace(cfg, target=(0.1, 0.2, 0.31))) != h
    assert config_hash(replace(cfg, weights=np.array([1.0, 2.5]))) != h
    assert config_hash(replace(cfg, name="other")) != h
    # independent of key order for mappings
    assert config_hash({"a": 1, "b": 2}) == config_hash({"b": 2, "a": 1})
    with pytest.raises(ConfigError):
        config_hash(42)


def test_to_jsonable_rejects_unknown_objects() -> None:
    assert to_jsonable({"x": float("nan"), "y": np.int32(3)}) == {"x": "nan", "y": 3}
    with pytest.raises(ReproError, match="object"):
        to_jsonable({"f": object()})


# --------------------------------------------------------------------------- dead runs (issue 7)


def test_rows_are_flushed_at_least_every_flush_interval(tmp_path: Path) -> None:
    rec = _recorder(tmp_path, flush_every=1000, flush_interval_s=0.05)
    rec.record({"step": 0})  # the first row comes more than 0 s after the start: flushed
    rec.record({"step": 1})
    time.sleep(0.06)
    rec.record({"step": 2})
    assert count_trace_rows(tmp_path) == 3
    rec.close()
    with pytest.raises(ConfigError, match="flush_interval_s"):
        _recorder(tmp_path / "bad", flush_interval_s=-1.0)


def test_manifest_at_start_records_pid_host_and_start_time(tmp_path: Path) -> None:
    rec = _recorder(tmp_path)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["status"] == "running"
    assert manifest["pid"] == os.getpid()
    assert manifest["hostname"] == socket.gethostname()
    assert manifest["started_at"].endswith("Z")
    assert "boot_id" in manifest
    rec.close()


def test_count_trace_rows_skips_header_and_a_cut_off_line(tmp_path: Path) -> None:
    assert count_trace_rows(tmp_path) == 0  # no trace.csv
    (tmp_path / "trace.csv").write_text("t,x\n")
    assert count_trace_rows(tmp_path) == 0
    (tmp_path / "trace.csv").write_text("t,x\n0,1\n0.1,2\n0.2,")
    assert count_trace_rows(tmp_path) == 2


def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    return int(proc.stdout)


def _killed_run(path: Path, n_rows: int, **manifest_fields: object) -> None:
    """A run as a SIGKILL leaves it: manifest 'running' with 0 rows, rows on disk."""
    rec = _recorder(path, flush_every=1)
    rec.set_scene({"bodies": []})
    for k in range(n_rows):
        rec.record({"t": k * 0.1, "step": k})
    rec._trace_file.close()
    rec._events_file.close()
    if manifest_fields:
        update_manifest(path, **manifest_fields)


def test_running_run_of_a_live_process_is_left_alone(tmp_path: Path) -> None:
    rec = _recorder(tmp_path)
    rec.record({"t": 0.0})
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert process_gone(manifest, tmp_path) is None  # our own pid
    assert effective_manifest(tmp_path) == manifest
    assert mark_if_gone(tmp_path) is None
    rec.close()
    assert mark_if_gone(tmp_path) is None  # completed runs are never touched


def test_dead_pid_on_this_host_reads_as_interrupted_with_counted_rows(tmp_path: Path) -> None:
    _killed_run(tmp_path, 12, pid=_dead_pid())
    on_disk = json.loads((tmp_path / "manifest.json").read_text())
    assert (on_disk["status"], on_disk["n_rows"]) == ("running", 0)

    seen = effective_manifest(tmp_path)
    assert seen["status"] == "interrupted" and seen["n_rows"] == 12
    assert seen["reason"].startswith("process gone: pid")
    assert "12 rows" in seen["reason"] and seen["ended_at"].endswith("Z")
    assert json.loads((tmp_path / "manifest.json").read_text()) == on_disk  # read only

    assert mark_if_gone(tmp_path) == seen
    assert json.loads((tmp_path / "manifest.json").read_text()) == seen
    assert load_run(tmp_path).manifest["n_rows"] == len(load_run(tmp_path).trace) == 12
    assert mark_if_gone(tmp_path) is None  # idempotent


def test_other_host_is_gone_only_after_a_long_silence(tmp_path: Path) -> None:
    _killed_run(tmp_path, 3, hostname="another-host.example", pid=1)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert process_gone(manifest, tmp_path) is None  # files just written
    later = time.time() + 7 * 3600
    why = process_gone(manifest, tmp_path, now=later)
    assert why is not None and "another-host.example" in why and "no update for 7.0 h" in why
    assert effective_manifest(tmp_path, now=later)["status"] == "interrupted"
    assert effective_manifest(tmp_path, now=later, stale_after_s=8 * 3600)["status"] == "running"


def test_rebooted_host_means_the_process_is_gone(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    # The boot id is the system's (/proc on Linux); fix it so the test runs everywhere.
    import repro.runs.trace as trace_module

    monkeypatch.setattr(trace_module, "_boot_id", lambda: "this-boot")
    _killed_run(tmp_path, 1, boot_id="this-boot")  # our own live pid, this boot: alive
    assert effective_manifest(tmp_path)["status"] == "running"
    update_manifest(tmp_path, boot_id="an-earlier-boot")  # our pid, but another boot
    seen = effective_manifest(tmp_path)
    assert seen["status"] == "interrupted" and "rebooted" in seen["reason"]


def test_update_manifest(tmp_path: Path) -> None:
    with _recorder(tmp_path) as rec:
        rec.record({"t": 0.0})
    manifest = update_manifest(tmp_path, experiment="case1")
    assert json.loads((tmp_path / "manifest.json").read_text()) == manifest
    assert manifest["experiment"] == "case1" and tuple(manifest) == MANIFEST_KEYS
    with pytest.raises(ReproError, match="cannot read manifest"):
        update_manifest(tmp_path / "nope", experiment="x")


@pytest.mark.parametrize("when", ["before", "after"])
def test_an_interrupt_during_a_flush_writes_every_row_once(tmp_path: Path, when: str) -> None:
    """A KeyboardInterrupt (a signal's handler) landing just before or just after the bytes
    of a flush reach the file: the closed trace holds every recorded row exactly once and
    the manifest counts the rows in the file (the old recorder wrote them twice when the
    interrupt came after the write and before the buffer was cleared)."""
    rec = _recorder(tmp_path, flush_every=10)
    real = rec._trace_file

    class Interrupted:  # the file, with an interrupt at the first data write
        fired = False

        def write(self, data: bytes) -> int:
            if self.fired or not data.startswith(b"0"):
                return real.write(data)  # the header, or after the interrupt
            self.fired = True
            if when == "before":
                raise KeyboardInterrupt("SIGINT")
            n = real.write(data)
            raise KeyboardInterrupt("SIGINT")
            return n

        def __getattr__(self, name: str) -> object:
            return getattr(real, name)

    rec._trace_file = Interrupted()  # type: ignore[assignment]
    with pytest.raises(KeyboardInterrupt):
        for k in range(25):
            rec.record({"t": float(k), "x": float(k)})
    assert rec.n_rows == 10
    rec.close("interrupted", "KeyboardInterrupt: SIGINT")
    run = load_run(tmp_path)
    assert run.trace["t"].tolist() == [float(k) for k in range(10)]
    assert run.manifest["n_rows"] == 10 and run.manifest["status"] == "interrupted"
