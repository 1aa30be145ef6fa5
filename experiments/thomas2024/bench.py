"""thomas2024 benchmarks: the controller step, the QP, the sensors, whole-loop speed.

The controller step is timed on realistic states: the joint positions recorded
in results/thomas2024/<case>/trace.csv are replayed (robot reset to each q,
sensors read, then ``Thomas2024Controller.step`` timed). Without those traces,
the run is made first (exact camera, 4 s).
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from experiments.thomas2024 import config as C
from experiments.thomas2024.run import build, run
from repro.bench import timing_row
from repro.runs.trace import load_run

QPS = C.QP_SOLVERS  # every qp_solver choice


def _states(results_dir: Path, case: str, cfg: C.Thomas2024Config, tmp: Path) -> np.ndarray:
    trace = results_dir / "thomas2024" / case / "trace.csv"
    if not trace.exists():
        run(replace(cfg, camera_mode="exact", duration=4.0), tmp / case)
        trace = tmp / case / "trace.csv"
    df = pd.read_csv(trace)
    return df[[f"q{i}" for i in range(1, 8)]].to_numpy(dtype=float)


def _replay(cfg: C.Thomas2024Config, states: np.ndarray, tmp: Path) -> dict[str, list[float]]:
    ep, ctrl = build(cfg, tmp / "bench_setup")
    rig, scene = ep.cameras[0], ep.scene
    target = scene[rig.target]
    assert target.dot_target is not None
    out: dict[str, list[float]] = {"step": [], "qp": [], "rays": [], "camera": []}
    try:
        for q in states:
            rig.robot.reset(q)
            tic = time.perf_counter()
            uv, found, Z = rig.camera.measure(scene.render_client, rig.pose(q), target.dot_target,
                                              target.T_world)
            out["camera"].append(time.perf_counter() - tic)
            tic = time.perf_counter()
            readings = [s.read(0.0, {rig.robot.name: q}) for s in ep.sensors]
            out["rays"].append(time.perf_counter() - tic)
            tic = time.perf_counter()
            res = ctrl.step(q, uv, found, Z, readings)
            out["step"].append(time.perf_counter() - tic)
            if res.status != "no_features":
                out["qp"].append(res.solve_s)
    finally:
        scene.close()
    return out


def bench(results_dir: Path) -> list[dict[str, object]]:
    """Rows for results/bench.csv."""
    rows: list[dict[str, object]] = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for case, cls in (("case1", C.Case1Config), ("case2", C.Case2Config)):
            states = _states(results_dir, case, cls(), tmp)
            for solver in QPS:
                cfg = replace(cls(), camera_mode="exact", qp_solver=solver)
                t = _replay(cfg, states, tmp)
                rows.append(timing_row(f"{case}.controller_step[{solver}]", t["step"]))
                rows.append(timing_row(f"{case}.qp_solve[{solver}]", t["qp"]))
                if solver == "proxsuite":
                    rows.append(timing_row(f"{case}.ray_casts_36", t["rays"]))
            t = _replay(replace(cls(), camera_mode="render"), states[::5], tmp)
            rows.append(timing_row(f"{case}.camera_render_detect_640x480", t["camera"]))
    # Whole closed loop, from the committed runs' manifests (render mode).
    for name in ("case1", "case2", "case3"):
        path = results_dir / "thomas2024" / name
        if (path / "manifest.json").exists():
            m = load_run(path).manifest
            steps = m["summary"]["n_steps"]
            per_step = m["wall_time_s"] / steps
            rows.append({"benchmark": f"{name}.closed_loop_step_mean(budget 0.0333)",
                         "median_s": per_step, "p95_s": per_step, "n": steps})
    return rows
