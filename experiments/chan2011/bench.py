"""chan2011 benchmarks: NMPC solve time for Np = 5 and Np = 10, cold and warm-started,
on the states of the committed runs (the paper's controller ran at 10 Hz)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd
import pinocchio as pin

from experiments.chan2011 import scene as sc
from repro.bench import timing_row
from repro.control.nmpc import NMPCConfig, VisualNMPC
from repro.planning.dcc import CollisionModel, static_links
from repro.sim.casadi_kinematics import frame_pose_casadi
from repro.sim.crs_a465 import (
    CRS_JOINTS,
    CRS_LIMITS,
    T_FLANGE_CAMERA,
    crs_urdf_path,
    velocity_limits,
)

CASES = (  # (run, Np, dt, W, velocity fraction) from chan2011 Secs. III-A and V-A6
    ("simulation", 5, 0.01, 2500.0, 1.0),
    ("experiment", 10, 0.1, 10000.0, 0.05),
)


def bench(results_dir: Path) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    model = pin.buildModelFromUrdf(str(crs_urdf_path()))
    fk = frame_pose_casadi(model, "flange", CRS_JOINTS, T_frame_child=T_FLANGE_CAMERA)
    for name, Np, dt, W, frac in CASES:
        trace = Path(results_dir) / "chan2011" / name / "trace.csv"
        if not trace.exists():
            continue
        df = pd.read_csv(trace)
        setting = sc.SETTINGS[name]
        import json

        p_d = np.asarray(json.loads((trace.parent / "scene.json").read_text())[
            "desired_pixels"], float).ravel()
        states = df.iloc[:: max(1, len(df) // 200)]
        for mode in ("warm", "cold"):
            nmpc = VisualNMPC(fk, sc.CONTROLLER_INTRINSICS, sc.N_POINTS, CRS_LIMITS.q_min,
                              CRS_LIMITS.q_max, velocity_limits(frac),
                              NMPCConfig(Np=Np, dt=dt, W_weight=W, max_iter=100),
                              image_bounds=sc.CONTROLLER_IMAGE_BOUNDS)
            times = []
            for _, row in states.iterrows():
                q = row[[f"q{i}" for i in range(1, 7)]].to_numpy(float)
                p_k = row[[f"p{j}_{a}" for j in range(1, 11) for a in "uv"]].to_numpy(float)
                if not np.isfinite(p_k).all():
                    continue
                d_k = nmpc.disturbance(p_k, q, setting.T_object_estimate, sc.CONROD_POINTS)
                if mode == "cold":
                    nmpc.reset()
                sol = nmpc.solve(q, p_d, d_k, setting.T_object_estimate, sc.CONROD_POINTS)
                times.append(sol.solve_time_s)
            rows.append(timing_row(f"nmpc_solve[Np={Np},{mode}]", times))
    dcc = CollisionModel(crs_urdf_path(), CRS_JOINTS, sc.OBSTACLES,
                         skip_links=static_links(crs_urdf_path()))
    rng = np.random.default_rng(0)
    qs = rng.uniform(np.asarray(CRS_LIMITS.q_min), np.asarray(CRS_LIMITS.q_max), (300, 6))
    t = []
    for q in qs:
        tic = time.perf_counter()
        dcc.distance(q)
        t.append(time.perf_counter() - tic)
    rows.append(timing_row("fcl_distance_d(q)", t))
    return rows
