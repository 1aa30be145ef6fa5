"""Regenerate the reference traces of tests/test_thomas2024_runs.py.

Run after an intended behaviour change: ``.venv/bin/python tests/make_reference.py``.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import test_chan2011  # noqa: E402
from test_thomas2024_runs import REF_DIR, TIMING_COLUMNS, short_config  # noqa: E402

from experiments.thomas2024 import EXPERIMENTS  # noqa: E402
from experiments.thomas2024.run import run  # noqa: E402
from repro.runs.trace import load_run  # noqa: E402


def main() -> None:
    REF_DIR.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as d:
        for exp in EXPERIMENTS.experiments:
            out = run(short_config(exp.name), Path(d) / exp.name)
            df = load_run(out).trace.drop(columns=list(TIMING_COLUMNS))
            df.to_csv(REF_DIR / f"{exp.name}.csv", index=False, float_format="%.10g")
            print(exp.name, len(df))
        test_chan2011.REF_DIR.mkdir(parents=True, exist_ok=True)
        for exp in test_chan2011.EXPERIMENTS.experiments:
            got = test_chan2011.short_run(exp.name, Path(d) / ("chan_" + exp.name))
            df = got.trace.drop(columns=[c for c in test_chan2011.TIMING_COLUMNS
                                         if c in got.trace.columns])
            df.to_csv(test_chan2011.REF_DIR / f"{exp.name}.csv", index=False,
                      float_format="%.10g")
            print("chan2011", exp.name, len(df))


if __name__ == "__main__":
    main()
