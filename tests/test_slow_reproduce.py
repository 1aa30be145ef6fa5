"""Slow: rerunning an experiment with its committed config reproduces the committed trace.

Run with ``make test-slow``. Timing columns are excluded; everything else must match to
round-off (the runs are deterministic: a fresh PyBullet client, fixed steps, seeded noise).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from repro.runs.registry import find_experiment, load_papers
from repro.runs.trace import load_run

RESULTS = Path(__file__).resolve().parent.parent / "results"
TIMING = ("ctrl_s", "camera_render_s", "qp_solve_s", "solve_s")


@pytest.mark.slow
@pytest.mark.parametrize("exp_id", ["thomas2024.case1", "thomas2024.case2",
                                    "chan2011.simulation", "chan2011.ibvs_saturated"])
def test_committed_trace_is_reproduced(exp_id: str, tmp_path: Path) -> None:
    exp = find_experiment(load_papers(), exp_id)
    committed = load_run(RESULTS / exp.paper / exp.name)
    config = exp.config_cls()  # the committed runs use the defaults
    fresh = load_run(exp.run(config, tmp_path / exp.name))
    a = committed.trace.drop(columns=[c for c in TIMING if c in committed.trace.columns])
    b = fresh.trace.drop(columns=[c for c in TIMING if c in fresh.trace.columns])
    assert list(a.columns) == list(b.columns) and len(a) == len(b)
    for c in a.columns:
        if a[c].dtype.kind == "f":
            np.testing.assert_allclose(b[c].to_numpy(), a[c].to_numpy(), atol=1e-9, rtol=1e-9,
                                       err_msg=c)
        else:
            assert (a[c] == b[c]).all(), c
