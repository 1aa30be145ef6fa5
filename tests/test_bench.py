"""``make bench``'s real-time rows (repro.bench.realtime_rows): each factor is the fastest of
PASSES runs, the slowest beside it, and the split is the fastest run's."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from repro import bench


@dataclasses.dataclass
class _Config:
    duration: float = 1.0
    camera_mode: str = "exact"


class _Exp:
    """An experiment whose runs take the given loop wall times [s] in turn."""

    config_cls = _Config

    def __init__(self, walls: list[float]) -> None:
        self.walls = list(walls)

    def run(self, cfg: _Config, out: Path) -> Path:
        wall = self.walls.pop(0)
        out.mkdir(parents=True)
        timing = {"physics_s": 0.5 * wall, "controller_s": 0.25 * wall, "loop_wall_s": wall,
                  "real_time_factor": cfg.duration / wall}
        (out / "manifest.json").write_text(json.dumps({"summary": {"timing": timing}}))
        return out


def test_the_real_time_factor_is_the_fastest_of_its_passes(
        monkeypatch: pytest.MonkeyPatch) -> None:
    exp = _Exp([2.0, 1.6, 2.5, 9.0])  # three exact passes, then one rendered
    monkeypatch.setattr(bench, "REALTIME_RUNS", (("fake.case", 2.0),))
    monkeypatch.setattr(bench, "load_papers", lambda: {})
    monkeypatch.setattr("repro.runs.registry.find_experiment", lambda papers, exp_id: exp)
    rows = {r["benchmark"]: r for r in bench.realtime_rows()}
    exact = rows["fake.case.real_time_factor[exact]"]
    assert exact["n"] == bench.PASSES["exact"] == 3
    assert exact["median_s"] == pytest.approx(2.0 / 1.6)  # the fastest
    assert exact["p95_s"] == pytest.approx(2.0 / 2.5)  # the slowest
    assert rows["fake.case.loop_split[exact,physics]"]["median_s"] == pytest.approx(0.5)
    render = rows["fake.case.real_time_factor[render]"]
    assert render["n"] == 1 and render["median_s"] == pytest.approx(2.0 / 9.0)
    assert exp.walls == []  # (no render_full: the config has no camera_windows)
