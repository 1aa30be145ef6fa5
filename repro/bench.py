"""``make bench``: timings of every paper's benchmarks -> results/bench.csv.

Speed is measured here, not asserted in tests. Columns: benchmark, median_s,
p95_s, n, machine (CPU model and core count).
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m repro.bench")
    parser.add_argument("--results", type=Path, default=Path("results"))
    parser.add_argument("--paper", default=None)
    args = parser.parse_args(argv)
    machine = f"{cpu_name()} ({os.cpu_count()} cores)"
    rows: list[dict[str, object]] = []
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
