"""``make bench``'s real-time rows (repro.bench.realtime_rows): each factor is the fastest of
PASSES runs, the slowest beside it, the split the fastest run's; each run is timed in a
fresh process (run_timing)."""

from __future__ import annotations

import dataclasses
import subprocess
from pathlib import Path

import pytest

from repro import bench


@dataclasses.dataclass
class _Config:
    duration: float = 1.0
    camera_mode: str = "exact"


class _Exp:
    config_cls = _Config


def test_the_real_time_factor_is_the_fastest_of_its_passes(
        monkeypatch: pytest.MonkeyPatch) -> None:
    walls = [2.0, 1.6, 2.5, 9.0]  # three exact passes, then one rendered
    asked: list[tuple[str, float, dict]] = []

    def timing(exp_id: str, duration: float, overrides: dict) -> dict[str, float]:
        asked.append((exp_id, duration, overrides))
        wall = walls.pop(0)
        return {"physics_s": 0.5 * wall, "controller_s": 0.25 * wall, "loop_wall_s": wall,
                "real_time_factor": duration / wall}

    monkeypatch.setattr(bench, "REALTIME_RUNS", (("fake.case", 2.0),))
    monkeypatch.setattr(bench, "load_papers", lambda: {})
    monkeypatch.setattr("repro.runs.registry.find_experiment", lambda papers, exp_id: _Exp)
    monkeypatch.setattr(bench, "run_timing", timing)
    rows = {r["benchmark"]: r for r in bench.realtime_rows()}
    exact = rows["fake.case.real_time_factor[exact]"]
    assert exact["n"] == bench.PASSES["exact"] == 3
    assert exact["median_s"] == pytest.approx(2.0 / 1.6)  # the fastest
    assert exact["p95_s"] == pytest.approx(2.0 / 2.5)  # the slowest
    assert rows["fake.case.loop_split[exact,physics]"]["median_s"] == pytest.approx(0.5)
    render = rows["fake.case.real_time_factor[render]"]
    assert render["n"] == 1 and render["median_s"] == pytest.approx(2.0 / 9.0)
    assert walls == []  # (no render_full: the config has no camera_windows)
    assert asked[-1] == ("fake.case", 2.0, {"camera_mode": "render"})


def test_a_timed_run_is_made_in_its_own_process(tmp_path: Path) -> None:
    """run_timing runs ``python -m repro.bench --one-run`` and reads the run's manifest."""
    t = bench.run_timing("thomas2024.case1", 0.2, {"camera_mode": "exact"})
    assert t["real_time_factor"] > 0 and t["loop_wall_s"] > 0
    assert set(t) >= {"controller_s", "physics_s", "audit_s"}
    with pytest.raises(subprocess.CalledProcessError):  # an unknown experiment: loudly
        bench.run_timing("nopaper.nocase", 0.2, {})
