"""The comparison with a reference (repro.runs.compare): its rules on synthetic traces, the
committed tolerance files against their references, and the real changes it must catch.

A tolerance measured on perturbed reruns is only worth something if a real change still
fails it: each reference's short run with a loop gain 1 % off, with the angular-z row of
every geometric Jacobian negated, and with the command applied one control step late
must leave its tolerance somewhere (tests/references.py lists which apply).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from references import (
    REFERENCES,
    apply_mutation,
    load_tolerances,
    mutated_trace,
    mutations,
)

from repro.runs.compare import (
    DEFAULT_MARGIN,
    compare_to_reference,
    measure_tolerances,
    merge_tolerances,
)

N = 100
T = np.linspace(0.0, 1.0, N)


def _trace(**over: object) -> pd.DataFrame:
    """A smooth column, a chattering one, a flag and a phase label."""
    df = pd.DataFrame({
        "t": T, "q": np.sin(T), "qd": 1e-3 * np.sign(np.sin(400 * T)),
        "found": np.ones(N, bool), "phase": np.where(T < 0.5, "a", "b")})
    for k, v in over.items():
        df[k] = v
    return df


@pytest.fixture(scope="module")
def rules() -> dict[str, object]:
    """Reruns: q moved by 1e-9 (pointwise), qd's chatter shifted by a sample (chaotic)."""
    ref = _trace()
    runs = {"a": _trace(q=np.sin(T) + 1e-9),
            "b": _trace(q=np.sin(T) - 0.5e-9, qd=np.roll(ref["qd"].to_numpy(), 1))}
    return measure_tolerances(ref, runs)


def test_a_smooth_column_is_pointwise_with_margin_times_measured(rules: dict) -> None:
    r = rules["columns"]["q"]
    assert r["kind"] == "float" and r["stable"] == N
    assert r["measured"] == pytest.approx(1e-9, rel=1e-6) and r["by"] == "a"
    assert r["atol"] == pytest.approx(DEFAULT_MARGIN * 1e-9, rel=1e-6)
    assert rules["columns"]["found"] == {"kind": "exact"}
    assert rules["columns"]["phase"] == {"kind": "exact"}


def test_a_chattering_column_is_compared_by_windows(rules: dict) -> None:
    r = rules["columns"]["qd"]
    assert r["stable"] < N and len(r["windows"]) >= 1
    # the windows cover the chaotic stretch, end to end, without gaps
    edges = [w["rows"] for w in r["windows"]]
    assert edges[0][0] == r["stable"] and edges[-1][1] == N
    assert all(a[1] == b[0] for a, b in zip(edges[:-1], edges[1:], strict=True))
    # and each window's tolerance is the margin times its own measured deviation
    for w in r["windows"]:
        assert all(w["atol"][k] == DEFAULT_MARGIN * w["measured"][k] for k in w["atol"])


def test_the_reruns_pass_and_the_reference_passes_itself(rules: dict) -> None:
    ref = _trace()
    assert compare_to_reference(ref, ref, rules) == []
    assert compare_to_reference(_trace(q=np.sin(T) + 1e-9), ref, rules) == []


@pytest.mark.parametrize("change, column", [
    ({"q": np.sin(T) + 2e-8}, "q"),  # 2x the tolerance, one column
    ({"q": np.sin(1.01 * T)}, "q"),  # a 1 % change of the "gain"
    ({"qd": 2e-3 * np.sign(np.sin(400 * T))}, "qd"),  # the chatter's RMS doubled
    ({"qd": 1e-3 * np.sign(np.sin(400 * T)) + 2e-4}, "qd"),  # its mean shifted
    ({"found": np.r_[np.ones(N - 1, bool), False]}, "found"),
    ({"phase": np.where(T < 0.6, "a", "b")}, "phase"),
    ({"q": np.r_[np.sin(T[:-1]), np.nan]}, "q"),  # NaN where the reference has a number
])
def test_a_real_change_fails(rules: dict, change: dict, column: str) -> None:
    bad = compare_to_reference(_trace(**change), _trace(), rules)
    assert bad and bad[0].column == column, bad


def test_other_length_and_other_columns_fail(rules: dict) -> None:
    ref = _trace()
    assert compare_to_reference(ref.iloc[:-1], ref, rules)[0].column == "<rows>"
    assert compare_to_reference(ref.drop(columns=["qd"]), ref, rules)[0].column == "<columns>"
    with pytest.raises(ValueError, match="another reference"):
        compare_to_reference(ref, ref.iloc[:-1], rules)


def test_reruns_of_another_length_widen_the_length_check_by_the_margin() -> None:
    ref = _trace()
    tol = measure_tolerances(ref, {"short": ref.iloc[:-2].reset_index(drop=True)})
    assert tol["rows_compared"] == N - 2 and tol["length_atol"] == DEFAULT_MARGIN * 2
    assert compare_to_reference(ref.iloc[:-5], ref, tol) == []


def test_a_tolerance_measured_on_two_machines_holds_both_and_no_more() -> None:
    """Machine A moves q by 1e-9 and leaves the flag alone; machine B (other kernels) moves
    q by 4e-9, shifts qd's chatter (chaotic from a row on) and flips one label late. The
    merged file passes every rerun of both, keeps each rule margin x its measured deviation,
    and still fails what neither machine did."""
    ref = _trace()
    late = np.where(T < 0.5, "a", "b")
    late[-1] = "a"
    a_runs = {"a": _trace(q=np.sin(T) + 1e-9)}
    b_runs = {"b": _trace(q=np.sin(T) - 4e-9, qd=np.roll(ref["qd"].to_numpy(), 1),
                          phase=late)}
    a = {**measure_tolerances(ref, a_runs), "measured_on": {"cpu": "A"}}
    b = {**measure_tolerances(ref, b_runs), "measured_on": {"cpu": "B"}}
    assert compare_to_reference(b_runs["b"], ref, a)  # A's file alone fails B's rerun
    m = merge_tolerances(a, b)
    for run in (*a_runs.values(), *b_runs.values()):
        assert compare_to_reference(run, ref, m) == []
    assert m["measured_on"] == [{"cpu": "A"}, {"cpu": "B"}]
    assert set(m["perturbations"]) == {"a", "b"}
    q = m["columns"]["q"]
    assert q["measured"] == pytest.approx(4e-9, rel=1e-6) and q["by"] == "b"
    assert q["atol"] == pytest.approx(DEFAULT_MARGIN * 4e-9, rel=1e-9)
    assert m["columns"]["qd"]["stable"] == b["columns"]["qd"]["stable"] < N
    assert m["columns"]["phase"]["kind"] == "text"  # exact on A, text on B
    for r in m["columns"].values():
        for w in r.get("windows", []):
            assert all(w["atol"][k] == DEFAULT_MARGIN * w["measured"][k] for k in w["atol"])
    assert merge_tolerances(b, a)["columns"]["q"] == q  # order does not matter
    for change in ({"q": np.sin(T) + 1e-7}, {"q": np.sin(1.01 * T)},
                   {"qd": 2e-3 * np.sign(np.sin(400 * T))}):
        assert compare_to_reference(_trace(**change), ref, m)
    with pytest.raises(ValueError, match="other references"):
        merge_tolerances(a, measure_tolerances(ref.iloc[:-1], {"x": ref.iloc[:-1]}))


def test_a_reference_column_of_zeros_equals_a_live_float_column() -> None:
    """A column of zeros reads back from CSV as integers: 0 == 0.0, not '0' != '0.0'."""
    ref = pd.DataFrame({"e": np.zeros(5, int)})
    tol = measure_tolerances(ref, {"a": ref})
    assert compare_to_reference(pd.DataFrame({"e": np.zeros(5)}), ref, tol) == []
    assert compare_to_reference(pd.DataFrame({"e": np.r_[np.zeros(4), 0.5]}), ref, tol)


# --------------------------------------------------------------- the committed files
REQUIRED_PERTURBATIONS = {"blas:default", "q0:+1e-12", "q0:-1e-12"}


@pytest.mark.parametrize("rid", sorted(REFERENCES))
def test_tolerance_file_describes_its_reference(rid: str) -> None:
    """Measured on this reference (its columns and rows), under the default kernels, at
    least three forced kernel families and both initial-state moves, each tolerance the
    margin times its measured deviation."""
    ref = REFERENCES[rid]
    tol = load_tolerances(ref)
    df = pd.read_csv(ref.csv)
    assert list(tol["columns"]) == list(df.columns) and tol["rows"] == len(df)
    perts = set(tol["perturbations"])
    assert REQUIRED_PERTURBATIONS <= perts
    assert len([p for p in perts if p.startswith("blas:") and p != "blas:default"]) >= 3
    assert tol["margin"] == DEFAULT_MARGIN
    for c, r in tol["columns"].items():
        if r["kind"] == "float" and r["stable"] > 0:
            assert r["atol"] == pytest.approx(tol["margin"] * r["measured"], rel=1e-12), c
        for w in r.get("windows", []):
            for s, a in w["atol"].items():
                assert a == pytest.approx(tol["margin"] * w["measured"][s], rel=1e-12), c
    json.dumps(tol)  # plain JSON


@pytest.mark.parametrize("rid, kind, gain", [
    (rid, kind, gain) for rid in sorted(REFERENCES)
    for kind, gain in mutations(REFERENCES[rid])])
def test_a_real_change_leaves_the_measured_tolerance(
        rid: str, kind: str, gain: str | None, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    ref = REFERENCES[rid]
    got = mutated_trace(ref, kind, tmp_path, monkeypatch, gain)
    bad = compare_to_reference(got, pd.read_csv(ref.csv), load_tolerances(ref))
    assert bad, f"{rid}: {kind} {gain or ''} passes the reference's tolerances"


def test_unknown_mutation_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ValueError, match="valid"):
        apply_mutation("gain+2%", monkeypatch)
