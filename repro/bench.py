"""``make bench``: timings of every paper's benchmarks -> results/bench.csv.

The ``sweep.*`` rows (issue 19): variants per hour of a short sweep on 1 and 2 workers and
the speed-up between them, and of every committed sweep.

Speed is measured here, not asserted in tests. Columns: benchmark, median_s,
p95_s, n, machine (CPU model and core count). The ``real_time_factor`` rows (simulated time
over the loop's wall time) and ``loop_split`` rows (each part's share of it) are ratios in
the ``median_s`` column; they come from short runs timed whole per camera mode, the fastest
of :data:`PASSES` (the slowest's factor in ``p95_s``).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import pandas as pd

from repro.runs.registry import load_papers
from repro.runs.trace import cpu_name

BENCH_COLUMNS = ("benchmark", "median_s", "p95_s", "n", "machine")


def timing_row(name: str, samples: list[float] | np.ndarray) -> dict[str, object]:
    """One bench.csv row from a list of durations [s]."""
    a = np.asarray(samples, dtype=float)
    return {"benchmark": name, "median_s": float(np.median(a)),
            "p95_s": float(np.percentile(a, 95)), "n": int(a.size)}


#: Short runs whose loop is timed whole (real-time factor and split), per camera mode:
#: (experiment id, simulated seconds). ours: long enough that set-up is < 10 % of the wall
#: time; pomares2011 exp2 whole (25 s), so that its rate is the operator's whole visit
#: (walk in, reach, hold, withdraw, walk out: 8-19 s) and the still parts around it.
REALTIME_RUNS = (("pomares2011.exp1", 6.0), ("pomares2011.exp2", 25.0),
                 ("thomas2024.case1", 10.0), ("thomas2024.case2", 10.0),
                 ("thomas2024.case3", 10.0), ("chan2011.simulation", 10.0))
#: Modes timed: (name, config fields). ``render_full`` (every frame rendered in full) only
#: where the config has ``camera_windows`` (pomares2011), beside its windowed ``render``.
MODES = (("exact", {"camera_mode": "exact"}), ("render", {"camera_mode": "render"}),
         ("render_full", {"camera_mode": "render", "camera_windows": False}))
#: Runs per mode. The factor reported (``median_s``) is the fastest pass's, the slowest's
#: beside it (``p95_s``); the split is the fastest pass's. ours: 3 exact passes: on a shared
#: host other processes only ever add wall time, so the least of a few runs is the code's
#: own speed (timeit's convention; single passes of pomares2011 exp2 moved between 0.86x
#: and 1.03x within minutes here); 1 rendered pass: those factors are far from their goals
#: and a pass costs 60-80 s.
PASSES = {"exact": 3, "render": 1, "render_full": 1}
#: Full-frame pomares2011 runs cost ~16 ms a step: a shorter stretch [s]. ours: 1 s (1000
#: steps, 200 frames) keeps the two full-frame rows under ~40 s of make bench.
RENDERED_FULL_S = {"pomares2011.exp1": 1.0, "pomares2011.exp2": 1.0}


def run_timing(exp_id: str, duration: float, overrides: dict[str, object]
               ) -> dict[str, float]:
    """The manifest's ``timing`` summary of one run of ``exp_id`` (its default config with
    ``duration`` [s] and ``overrides``), made in a fresh Python process, as ``repro run``
    and ``repro results`` make each run: a run's speed does not depend on the runs timed
    before it (in one process, pomares2011 exp1 went from 1.63x to 1.57x over four runs in a
    row, and exp2 ran at 0.99x after a rendered run and at 1.065x alone, minutes apart)."""
    import json
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        subprocess.run([sys.executable, "-m", "repro.bench", "--one-run", exp_id,
                        json.dumps({"duration": duration, **overrides}), d],
                       check=True, stdout=subprocess.DEVNULL)
        manifest = json.loads((Path(d) / "run" / "manifest.json").read_text())
    return {k: float(v) for k, v in manifest["summary"]["timing"].items()}


def _one_run(exp_id: str, fields_json: str, out_dir: Path) -> None:
    """``--one-run``: the run :func:`run_timing` asks for, into ``out_dir/run``."""
    import dataclasses
    import json

    from repro.runs.registry import find_experiment

    exp = find_experiment(load_papers(), exp_id)
    exp.run(dataclasses.replace(exp.config_cls(), **json.loads(fields_json)), out_dir / "run")


def realtime_rows(only_paper: str | None = None) -> list[dict[str, object]]:
    """Rows ``<id>.real_time_factor[<mode>]`` (simulated / loop wall time, a ratio, not
    seconds: the fastest of :data:`PASSES` runs in ``median_s``, the slowest in ``p95_s``)
    and ``<id>.loop_split[<mode>,<part>]`` (share of the fastest run's loop wall time), from
    the manifest summary every run writes (``repro.sim.episode.TIMING_SPLIT``), each run in
    a fresh process (:func:`run_timing`)."""
    import dataclasses

    from repro.runs.registry import find_experiment

    papers = load_papers()
    rows: list[dict[str, object]] = []
    for exp_id, duration in REALTIME_RUNS:
        if only_paper and not exp_id.startswith(only_paper + "."):
            continue
        exp = find_experiment(papers, exp_id)
        fields = {f.name for f in dataclasses.fields(exp.config_cls)}
        for mode, overrides in MODES:
            if not set(overrides) <= fields:
                continue
            dur = RENDERED_FULL_S.get(exp_id, duration) if mode == "render_full" else duration
            passes = [run_timing(exp_id, dur, dict(overrides)) for _ in range(PASSES[mode])]
            timing = max(passes, key=lambda tm: tm["real_time_factor"])
            rtf = timing["real_time_factor"]
            slowest = min(tm["real_time_factor"] for tm in passes)
            rows.append({"benchmark": f"{exp_id}.real_time_factor[{mode}]", "median_s": rtf,
                         "p95_s": slowest, "n": len(passes)})
            wall = timing["loop_wall_s"]
            for part, v in timing.items():
                if part.endswith("_s") and part != "loop_wall_s":
                    share = v / wall
                    rows.append({"benchmark": f"{exp_id}.loop_split[{mode},{part[:-2]}]",
                                 "median_s": share, "p95_s": share, "n": 1})
    return rows


#: The sweep timed with 1 and 2 LocalCluster workers (issue 19 item 6): (experiment, variants).
#: ours: thomas2024 case 1 with its ablation (~5 s a pair): 12 variants keep both timings
#: under ~2 minutes, and 6 per worker amortise the cluster's start-up.
SWEEP_BENCH = ("thomas2024.case1", 12)


def sweep_rows(results_dir: Path, workers: tuple[int, ...] = (1, 2)) -> list[dict[str, object]]:
    """Rows ``sweep.<exp>.variants_per_hour[<k> workers]`` (wall time of the whole sweep,
    cluster start-up included, in ``median_s`` as variants per hour), the speed-up of the
    most workers over one, and ``sweep.<exp>.variants_per_hour[committed]`` for every
    committed sweep (its variants' summed wall times over its workers)."""
    import json
    import tempfile
    import time

    from repro.runs.sweep import run_sweep

    rows: list[dict[str, object]] = []
    exp_id, n = SWEEP_BENCH
    per_hour = {}
    for k in workers:
        with tempfile.TemporaryDirectory() as d:
            tic = time.perf_counter()
            run_sweep(exp_id, n, 0, Path(d), engine="dask", workers=k)
            wall = time.perf_counter() - tic
        per_hour[k] = 3600.0 * n / wall
        rows.append({"benchmark": f"sweep.{exp_id}.variants_per_hour[{k} workers]",
                     "median_s": per_hour[k], "p95_s": per_hour[k], "n": n})
    if len(per_hour) > 1:  # (workers=() times nothing: the committed sweeps' rows only)
        ratio = per_hour[max(per_hour)] / per_hour[min(per_hour)]
        rows.append({"benchmark": f"sweep.{exp_id}.speedup[{max(per_hour)} over "
                     f"{min(per_hour)} workers]", "median_s": ratio, "p95_s": ratio, "n": n})
    for csv in sorted((Path(results_dir) / "sweeps").glob("*/variants.csv")):
        meta = json.loads((csv.parent / "variants.columns.json").read_text(encoding="utf-8"))
        df = pd.read_csv(csv)
        k = int(meta.get("workers") or 2)  # ours: the sweeps before issue 19's bench ran -j 2
        rate = 3600.0 * len(df) * k / float(df["wall_time_s"].sum())
        rows.append({"benchmark": f"sweep.{meta['experiment']}.variants_per_hour[committed]",
                     "median_s": rate, "p95_s": rate, "n": len(df)})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m repro.bench")
    parser.add_argument("--results", type=Path, default=Path("results"))
    parser.add_argument("--paper", default=None)
    parser.add_argument("--one-run", nargs=3, metavar=("EXPERIMENT", "FIELDS_JSON", "DIR"),
                        help=argparse.SUPPRESS)  # one timed run (run_timing's child)
    args = parser.parse_args(argv)
    if args.one_run:
        _one_run(args.one_run[0], args.one_run[1], Path(args.one_run[2]))
        return 0
    machine = f"{cpu_name()} ({os.cpu_count()} cores)"
    rows: list[dict[str, object]] = []
    rows += [{**r, "machine": machine} for r in realtime_rows(args.paper)]
    if not args.paper:
        rows += [{**r, "machine": machine} for r in sweep_rows(args.results)]
    for key, paper in load_papers().items():
        if paper.bench is None or (args.paper and key != args.paper):
            continue
        for row in paper.bench(args.results):
            rows.append({**row, "benchmark": f"{key}.{row['benchmark']}", "machine": machine})
    df = pd.DataFrame(rows, columns=list(BENCH_COLUMNS))
    out = args.results / "bench.csv"
    if out.exists() and args.paper:
        old = pd.read_csv(out)
        old = old[~old["benchmark"].str.startswith(f"{args.paper}.")]
        df = pd.concat([old, df], ignore_index=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out, index=False)
    with pd.option_context("display.width", 160, "display.max_colwidth", 60):
        print(df.drop(columns="machine").to_string(index=False))
    print(f"machine: {machine}; written {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
