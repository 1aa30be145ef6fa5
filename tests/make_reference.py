"""Regenerate the reference traces of tests/test_thomas2024_runs.py, tests/test_chan2011.py
and tests/test_pomares2011_runs.py (``--paper pomares2011``: only those).

Run after an intended behaviour change: ``.venv/bin/python tests/make_reference.py``.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import test_chan2011  # noqa: E402
import test_pomares2011_runs  # noqa: E402
from test_thomas2024_runs import REF_DIR, TIMING_COLUMNS, short_config  # noqa: E402

from experiments.thomas2024 import EXPERIMENTS  # noqa: E402
from experiments.thomas2024.run import run  # noqa: E402
from repro.runs.trace import load_run  # noqa: E402


def pomares2011(d: Path) -> None:
    ref = test_pomares2011_runs.REF_DIR
    ref.mkdir(parents=True, exist_ok=True)
    for name in sorted(test_pomares2011_runs.CONFIGS):
        df = test_pomares2011_runs.make_reference(d, name)
        df.to_csv(ref / f"{name}.csv", index=False, float_format="%.10g")
        print("pomares2011", name, len(df))


def main() -> None:
    if "--paper" in sys.argv and sys.argv[sys.argv.index("--paper") + 1] == "pomares2011":
        with tempfile.TemporaryDirectory() as d:
            pomares2011(Path(d))
        return
    REF_DIR.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as d:
        pomares2011(Path(d))
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
