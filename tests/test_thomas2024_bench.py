"""The thomas2024 QP solver table on a short replayed sequence: accuracy against the exact
reference, infeasibility certificates, the bench.csv schema. Speed is not asserted here."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import experiments.thomas2024.config as C
from experiments.thomas2024.bench import (
    _states,
    capture_hard_qps,
    qp_solver_table,
    reference_solutions,
)
from repro.control.qp import SOLVERS, kkt_residuals

RESULTS = Path(__file__).parents[1] / "results"
N_STATES = 30  # 1 s of case2 at 30 Hz: CBF rows active from the first step
#: Max |x - x_ref| [rad/s] per solver: active-set solvers are exact to rounding.
PRIMAL_TOL = {"proxsuite": 1e-5, "osqp": 1e-5, "daqp": 1e-8, "quadprog": 1e-8}
#: Solvers that certify the contradictory QP (proxsuite 0.8.0 does not, see repro.control.qp).
CERTIFY = ("osqp", "daqp", "quadprog")

Sequences = dict[str, tuple[C.Thomas2024Config, np.ndarray]]
Rows = dict[str, dict[str, Any]]


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Sequences:
    tmp = tmp_path_factory.mktemp("states")
    states = _states(RESULTS, "case2", C.Case2Config(), tmp)[:N_STATES]
    return {"case2": (C.Case2Config(), states)}


@pytest.fixture(scope="module")
def rows(sequence: Sequences, tmp_path_factory: pytest.TempPathFactory) -> Rows:
    out = qp_solver_table(sequence, tmp_path_factory.mktemp("table"))
    by_name = {str(r["benchmark"]): r for r in out}
    assert len(by_name) == len(out), "duplicate row names"
    return by_name


def test_capture_and_reference_are_exact(sequence: Sequences, tmp_path: Path) -> None:
    cfg, states = sequence["case2"]
    qps = capture_hard_qps(cfg, states, tmp_path)
    assert (qps.n, qps.m) == (7, 36)
    assert 0 < len(qps.problems) <= N_STATES
    refs = reference_solutions(qps)
    assert all(r.status == "solved" for r in refs)
    assert any((r.z < 0).any() for r in refs), "no active CBF row: a trivial sequence"
    for p, r in zip(qps.problems, refs, strict=True):
        assert max(kkt_residuals(p, r).values()) < 1e-10


def test_schema_and_finite(rows: Rows) -> None:
    for r in rows.values():
        assert set(r) == {"benchmark", "median_s", "p95_s", "n"}
        assert math.isfinite(float(r["median_s"])) and math.isfinite(float(r["p95_s"]))
        assert isinstance(r["n"], int) and r["n"] >= 1
    for solver in SOLVERS:
        assert f"case2.qp_table[{solver}]" in rows
        assert rows[f"case2.qp_table[{solver}]"]["median_s"] > 0.0


@pytest.mark.parametrize("solver", SOLVERS)
def test_primal_error_against_reference(rows: Rows, solver: str) -> None:
    err = rows[f"case2.qp_table[{solver}].max_primal_err"]["median_s"]
    assert 0.0 <= err < PRIMAL_TOL[solver]


@pytest.mark.parametrize("solver", ("daqp", "quadprog"))
def test_active_set_solvers_solve_every_qp(rows: Rows, solver: str) -> None:
    assert rows[f"case2.qp_table[{solver}].n_not_solved"]["median_s"] == 0.0
    assert rows[f"case2.qp_table[{solver}].max_dual_err"]["median_s"] < 1e-8


@pytest.mark.parametrize("solver", CERTIFY)
def test_infeasible_qp_certified(rows: Rows, solver: str) -> None:
    assert rows[f"qp_table[{solver}].certifies_infeasible"]["median_s"] == 1.0


def test_timed_steps_keep_each_states_least_time_over_the_passes(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """The controller-step rows time STEP_PASSES fresh replays and keep, state by state, the
    least time (interference only adds time); the QP times likewise."""
    import experiments.thomas2024.bench as B

    passes = iter([
        {"step": [3.0, 1.0, 5.0], "qp": [2.0, 0.5], "rays": [9.0], "camera": []},
        {"step": [2.0, 4.0, 6.0], "qp": [1.0, 0.7], "rays": [8.0], "camera": []},
        {"step": [4.0, 3.0, 0.5], "qp": [3.0, 0.2], "rays": [7.0], "camera": []},
    ])
    calls = []

    def fake(cfg: Any, states: np.ndarray, tmp: Path, **kw: Any) -> dict[str, list[float]]:
        calls.append(kw)
        return next(passes)

    monkeypatch.setattr(B, "_replay", fake)
    t = B._timed_steps(C.Case1Config(), np.zeros((3, 7)), tmp_path, passes=3)
    assert t["step"] == [2.0, 1.0, 0.5] and t["qp"] == [1.0, 0.2]
    assert len(calls) == 3 and B.STEP_PASSES >= 2
