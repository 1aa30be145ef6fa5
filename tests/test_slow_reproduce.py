"""Slow: rerunning a committed experiment with its committed config reproduces the committed
trace within measured tolerances, and a real change does not.

Run with ``make test-slow``. The tolerances (``tests/reference/committed/*.tol.json``) were
measured by ``tests/measure_tolerances.py --only committed``: each run rerun whole under six
OpenBLAS kernel families and with its initial joints moved by +-1e-12 rad, tolerance 10x
the largest deviation from the committed trace, pointwise where a column is stable and by
windowed mean/RMS where it is chaotic (repro.runs.compare). What moved, measured
2026-12-02 on an AMD EPYC (AVX-512), is in each test's docstring. Timing columns are never
compared.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from references import COMMITTED, assert_matches_reference, load_tolerances, mutated_trace

from repro.runs.compare import compare_to_reference

#: What moved in the measurement (largest deviation from the committed trace, perturbation).
MEASURED = {
    "committed/thomas2024.case1": "rendered camera: features identical on every rerun; joints "
    "<= 1e-8 rad, commands <= 7.6e-8 rad/s (SkylakeX, q0-1e-12); proxsuite's iteration "
    "counts jump by up to 172 near the stop (chaotic from a row on: windowed)",
    "committed/thomas2024.case2": "joints <= 2.4e-6 rad and the Lagrangian gradient <= 1e-4 "
    "at the local minimum (q0+1e-12); the detection error of point 2 by 0.03 px in the last "
    "rows (windowed)",
    "committed/thomas2024.case2_coarse": "model (6) oscillates after ring-2 contact: the "
    "committed run (made on another AMD EPYC) and every rerun here part from 7.4 s (u4 by "
    "0.14 rad/s); commands and CBFs pointwise to 12.5 s, windowed after; the claim-5 figures "
    "move (sign changes per s 2.11 -> 1.82)",
    "committed/chan2011.simulation": "CasADi/qpOASES do not use numpy's BLAS: the cost moves by "
    "<= 7.2e-6 (of 1.8e6) with q0 +-1e-12, the joints by <= 5e-10 rad",
    "committed/chan2011.ibvs_saturated": "the audit's detection errors by <= 5.8e-9 px",
    "committed/pomares2011.exp3": "physics identical on every kernel family (integer motor "
    "counts); the pad pressures of fingers 2-3 jump by up to 12.6 kPa at single rows "
    "(Sandybridge, Nehalem, Prescott: a contact point binned into another tactel), so those 7 "
    "columns are windowed; Algorithm 1's decisions, the stop step and the length never move",
    "committed/pomares2011.exp3_no_tactile": "as exp3: 10 pressure columns windowed (7.7 kPa "
    "under the default kernels, SkylakeX and q0 +-1e-12)",
}


@pytest.mark.slow
@pytest.mark.parametrize("rid", sorted(COMMITTED))
def test_committed_trace_is_reproduced(rid: str, tmp_path: Path) -> None:
    ref = COMMITTED[rid]
    assert_matches_reference(ref, ref.make(tmp_path))


@pytest.mark.slow
@pytest.mark.parametrize("rid, gain", [(rid, g) for rid in sorted(COMMITTED)
                                       for g in COMMITTED[rid].gains[:1]])
def test_a_one_percent_gain_change_is_not_reproduced(rid: str, gain: str, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The tolerances of a whole run still tell a 1 % gain change from the committed run."""
    ref = COMMITTED[rid]
    got = mutated_trace(ref, "gain+1%", tmp_path, monkeypatch, gain)
    bad = compare_to_reference(got, ref.load(), load_tolerances(ref))
    assert bad, f"{rid}: a 1 % change of {gain} reproduces the committed run"


def test_every_committed_rerun_has_its_measured_tolerances() -> None:
    """(Fast) each committed run that make test-slow reruns has a tolerance file measured on
    the committed trace as it is now (same columns and rows)."""
    for rid, ref in COMMITTED.items():
        tol = load_tolerances(ref)
        df: pd.DataFrame = ref.load()
        assert list(tol["columns"]) == list(df.columns) and tol["rows"] == len(df), rid
        assert rid in MEASURED
