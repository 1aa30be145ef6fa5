"""Tests of repro.runs.claims on small synthetic runs written with TraceRecorder, checked
against a small registry of their own (the runs' default configs)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from repro.errors import ConfigError, ReproError, UnknownChoiceError
from repro.runs.claims import (
    CLAIMS_COLUMNS,
    Claim,
    ClaimResult,
    RunExtent,
    evaluate_claims,
    extent_note,
    natural_key,
    read_claims_csv,
    run_extent,
    write_claims_csv,
)
from repro.runs.columns import COLUMNS_FILE, Columns
from repro.runs.registry import Experiment, Paper
from repro.runs.trace import RunFiles, TraceRecorder


@dataclass(frozen=True)
class Cfg:
    gain: float = 2.0
    duration: float = 0.02  # [s]


RUN_NAMES = ("good", "bad", "crashed", "short", "override")


def _papers() -> dict[str, Paper]:
    """A registry of p2020 whose experiments all have the default config Cfg()."""
    def run(config: Any, out_dir: Path) -> Path:
        raise AssertionError("not run in these tests")

    exps = tuple(Experiment(name, "p2020", f"{name} run", Cfg, run) for name in RUN_NAMES)
    return {"p2020": Paper("p2020", exps)}


def _write_run(results: Path, paper: str, run: str, errors: list[float], crash: bool = False,
               config: Cfg | None = None, sim_time: float | None = None):
    rec = TraceRecorder(
        results / paper / run, experiment=run, paper=paper, config=config or Cfg(), seed=0
    )
    rec.set_scene({"format": "test/1", "bodies": []})
    for k, err in enumerate(errors):
        rec.record({"t": 0.01 * k, "step": k, "err_m": err})
    rec.summary["sim_time_s"] = 0.01 * (len(errors) - 1) if sim_time is None else sim_time
    rec.summary["stop_reason"] = "duration reached" if sim_time is None else "target lost"
    if crash:
        rec.close(status="crashed", reason="RuntimeError: boom")
    else:
        rec.close()
    Columns().add("t", "s", "time").add("step", "-", "step").add("err_m", "m", "error").write(
        results / paper / run / COLUMNS_FILE, ["t", "step", "err_m"])


def _max_err_below(run: str, bound_m: float):
    def check(runs: dict[str, RunFiles]) -> ClaimResult:
        worst = float(runs[run].trace["err_m"].max())
        status = "reproduced" if worst < bound_m else "not_reproduced"
        return ClaimResult(measured=f"max error {worst * 1e3:.1f} mm", status=status)

    return check


def _claim(claim: str, runs: tuple[str, ...], check, paper: str = "p2020") -> Claim:
    return Claim(
        paper=paper,
        claim=claim,
        description=f"claim {claim}",
        expected="error < 5 mm",
        runs=runs,
        check=check,
    )


@pytest.fixture
def results(tmp_path: Path) -> Path:
    _write_run(tmp_path, "p2020", "good", [0.004, 0.002, 0.001])
    _write_run(tmp_path, "p2020", "bad", [0.004, 0.009, 0.003])
    _write_run(tmp_path, "p2020", "crashed", [0.001], crash=True)
    _write_run(tmp_path, "p2020", "short", [0.004, 0.002], sim_time=0.01)
    _write_run(tmp_path, "p2020", "override", [0.001, 0.001, 0.001], config=Cfg(gain=9.0))
    return tmp_path


def _raise(runs: dict[str, RunFiles]) -> ClaimResult:
    raise KeyError("no column 'force_n'")


def test_evaluate_claims_statuses(results: Path) -> None:
    claims = [
        _claim("1", ("good",), _max_err_below("good", 0.005)),
        _claim("2", ("bad",), _max_err_below("bad", 0.005)),
        _claim("3", ("good", "absent"), _max_err_below("good", 0.005)),
        _claim("4", ("good",), _raise),
        _claim("5", ("crashed",), _max_err_below("crashed", 0.005)),
        _claim("6", ("good",), lambda runs: "reproduced"),
    ]
    df = evaluate_claims(claims, results, _papers())
    assert tuple(df.columns) == CLAIMS_COLUMNS
    assert df["claim"].tolist() == ["1", "2", "3", "4", "5", "6"]
    status = dict(zip(df["claim"], df["status"], strict=True))
    measured = dict(zip(df["claim"], df["measured"], strict=True))
    assert status == {
        "1": "reproduced",
        "2": "not_reproduced",
        "3": "not_run",
        "4": "not_run",
        "5": "not_run",
        "6": "not_run",
    }
    assert measured["1"] == "max error 4.0 mm"
    assert measured["2"] == "max error 9.0 mm"
    assert "'absent'" in measured["3"] and "missing" in measured["3"]
    assert "column" in measured["4"] and "force_n" in measured["4"]
    assert "missing from run(s) p2020/good" in measured["4"]
    assert "crashed" in measured["5"] and "boom" in measured["5"]
    assert "str" in measured["6"]
    assert df.loc[0, "description"] == "claim 1" and df.loc[0, "expected"] == "error < 5 mm"


def test_run_with_missing_file_is_not_run(results: Path) -> None:
    (results / "p2020" / "good" / "scene.json").unlink()
    df = evaluate_claims([_claim("1", ("good",), _max_err_below("good", 0.005))], results,
                         _papers())
    assert df.loc[0, "status"] == "not_run"
    assert "scene.json" in df.loc[0, "measured"]


def test_run_with_another_config_is_not_run(results: Path) -> None:
    """An override run written into the default folder never decides a claim."""
    claim = _claim("1", ("override",), _max_err_below("override", 0.005))
    df = evaluate_claims([claim], results, _papers())
    assert df.loc[0, "status"] == "not_run"
    text = df.loc[0, "measured"]
    assert "another config" in text and "p2020.override" in text and "repro run" in text
    # the same run is accepted once the registered default is its config
    papers = _papers()
    exps = tuple(Experiment(e.name, e.paper, e.description,
                            (lambda: Cfg(gain=9.0)) if e.name == "override" else Cfg, e.run)
                 for e in papers["p2020"].experiments)
    papers["p2020"] = Paper("p2020", exps)
    df = evaluate_claims([claim], results, papers)
    assert df.loc[0, "status"] == "reproduced"


def test_unregistered_run_or_paper_is_not_run(results: Path) -> None:
    papers = _papers()
    papers["p2020"] = Paper("p2020", papers["p2020"].experiments[1:])  # no "good"
    df = evaluate_claims([_claim("1", ("good",), _max_err_below("good", 0.005))], results,
                         papers)
    assert df.loc[0, "status"] == "not_run"
    assert "not a registered experiment" in df.loc[0, "measured"]
    df = evaluate_claims([_claim("1", ("good",), _max_err_below("good", 0.005))], results, {})
    assert df.loc[0, "status"] == "not_run" and "not registered" in df.loc[0, "measured"]


def test_default_registry_is_the_installed_one(results: Path) -> None:
    """Without papers, the registry's entry points decide: p2020 is not among them."""
    df = evaluate_claims([_claim("1", ("good",), _max_err_below("good", 0.005))], results)
    assert df.loc[0, "status"] == "not_run" and "p2020" in df.loc[0, "measured"]


def test_run_that_ended_early(results: Path) -> None:
    """A run that ended before its duration is named; a whole-run claim cannot pass on it."""
    part = _claim("1", ("short",), _max_err_below("short", 0.005))
    whole = Claim("p2020", "2", "d", "e", ("short",), _max_err_below("short", 0.005),
                  whole_run=("short",))
    failing = Claim("p2020", "3", "d", "e", ("short",), _max_err_below("short", 0.001),
                    whole_run=("short",))
    full = Claim("p2020", "4", "d", "e", ("good",), _max_err_below("good", 0.005),
                 whole_run=("good",))
    df = evaluate_claims([part, whole, failing, full], results, _papers())
    status = df["status"].tolist()
    measured = df["measured"].tolist()
    assert status == ["reproduced", "not_reproduced", "not_reproduced", "reproduced"]
    assert "short ended at 0.01 s of its 0.02 s (target lost)" in measured[0]
    assert "judged on what ran" in measured[0]
    assert "covers the whole run" in measured[1] and "0.0 s that never ran" in measured[1]
    assert measured[2].startswith("max error 4.0 mm") and "covers the whole run" in measured[2]
    assert measured[3] == "max error 4.0 mm"


def test_run_extent() -> None:
    def run(t: list[float], summary: dict, config: dict) -> RunFiles:
        return RunFiles(pd.DataFrame({"t": t}), pd.DataFrame(),
                        {"summary": summary, "config": config}, {})

    full = run_extent(run([0.0, 0.1, 0.2], {"sim_time_s": 0.2}, {"duration": 0.2}))
    assert not full.ended_early and full.missing_s == 0.0 and full.step_s == pytest.approx(0.1)
    # within half a control period of the duration: not early
    assert not run_extent(run([0.0, 0.1, 0.2], {}, {"duration": 0.24})).ended_early
    short = run_extent(run([0.0, 0.1], {"stop_reason": "lost"}, {"duration": 0.5}))
    assert short.ended_early and short.missing_s == pytest.approx(0.4)
    assert short.stop_reason == "lost" and short.sim_time_s == pytest.approx(0.1)
    assert not run_extent(run([0.0], {}, {})).ended_early  # no duration: an audit, say
    assert RunExtent(None, 1.0, "x").missing_s == 0.0
    text, failed = extent_note({"a": run([0.0, 0.1], {}, {"duration": 1.0})}, ("a",))
    assert failed and "a ended at 0.10 s of its 1 s" in text
    assert extent_note({"a": run([0.0, 0.1], {}, {"duration": 0.1})}, ("a",)) == ("", False)
    # a run that ended on a done event (its task complete) counts as whole
    done = run([0.0, 0.1], {"stop_reason": "converged"}, {"duration": 1.0})
    done = RunFiles(done.trace, pd.DataFrame({"t": [0.1], "step": [1], "kind": ["converged"],
                                              "detail": [""]}), done.manifest, {})
    text, failed = extent_note({"a": done}, ("a",), ("converged",))
    assert not failed and "its task was complete" in text
    assert extent_note({"a": done}, ("a",))[1]  # without done events: early


def test_claim_validation() -> None:
    with pytest.raises(UnknownChoiceError):
        ClaimResult(measured="x", status="kind of")
    with pytest.raises(ConfigError):
        _claim("", ("a",), _raise)
    with pytest.raises(ConfigError):
        _claim("1", "good", _raise)  # type: ignore[arg-type]
    assert _claim("1", ["a", "b"], _raise).runs == ("a", "b")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="not among its runs"):
        Claim("p", "1", "d", "e", ("a",), _raise, whole_run=("b",))
    with pytest.raises(ConfigError):
        Claim("p", "1", "d", "e", ("a",), _raise, whole_run="a")  # type: ignore[arg-type]


def _table(paper: str, claims: list[str], status: str = "reproduced") -> pd.DataFrame:
    rows = [(paper, c, f"d{c}", "e", "m", status) for c in claims]
    return pd.DataFrame(rows, columns=list(CLAIMS_COLUMNS[:6]))


def test_write_claims_csv_merges_and_sorts(tmp_path: Path) -> None:
    path = tmp_path / "results" / "claims.csv"
    write_claims_csv(_table("b2011", ["10", "2", "1"]), path)
    write_claims_csv(_table("a2024", ["3", "1"]), path)
    write_claims_csv(_table("b2011", ["2", "1b", "1"], status="not_run"), path)
    df = read_claims_csv(path)
    assert tuple(df.columns) == CLAIMS_COLUMNS
    assert list(zip(df["paper"], df["claim"], strict=True)) == [
        ("a2024", "1"),
        ("a2024", "3"),
        ("b2011", "1"),
        ("b2011", "1b"),
        ("b2011", "2"),
    ]  # b2011's old "10" replaced, a2024 kept
    assert set(df.loc[df["paper"] == "b2011", "status"]) == {"not_run"}
    assert set(df.loc[df["paper"] == "a2024", "status"]) == {"reproduced"}


def test_write_claims_csv_validates(tmp_path: Path) -> None:
    path = tmp_path / "claims.csv"
    with pytest.raises(UnknownChoiceError):
        write_claims_csv(_table("a", ["1"], status="maybe"), path)
    with pytest.raises(ReproError, match="columns"):
        write_claims_csv(_table("a", ["1"]).drop(columns="measured"), path)
    with pytest.raises(ReproError, match="duplicate"):
        write_claims_csv(_table("a", ["1", "1"]), path)
    assert not path.exists()


def test_evaluated_table_writes_and_reads_back(results: Path) -> None:
    df = evaluate_claims([_claim("1", ("good",), _max_err_below("good", 0.005))], results,
                         _papers())
    write_claims_csv(df, results / "claims.csv")
    back = read_claims_csv(results / "claims.csv")
    pd.testing.assert_frame_equal(back, df)


def test_natural_key() -> None:
    assert sorted(["10", "2", "1b", "1", "1a"], key=natural_key) == ["1", "1a", "1b", "2", "10"]


def test_audit_note_names_wrong_and_hidden_features() -> None:
    import pandas as pd

    from repro.runs.claims import audit_note
    from repro.runs.trace import RunFiles

    def run(audit: dict) -> RunFiles:
        return RunFiles(pd.DataFrame(), pd.DataFrame(), {"summary": {"audit": audit}}, {})

    clean = {"camera": {"mismatch_rows": 0, "hidden_found_rows": 0}}
    assert audit_note({"a": run(clean)}) == ""
    bad = {"camera": {"mismatch_rows": 250, "points_mismatched": [2], "max_err_px": 322.0,
                      "hidden_found_rows": 14, "points_hidden_found": [3]}}
    note = audit_note({"a": run(clean), "experiment": run(bad)})
    assert "experiment" in note and "[2]" in note and "250 rows" in note and "322.0" in note
    assert "hidden" in note and "14 rows" in note


# ------------------------------------------------------------ issue 18: clause by clause
def test_clause_verdict_margin_and_marginal_flag() -> None:
    from repro.runs.claims import Clause

    c = Clause("error small", 1.8, "<=", 2.0, "mm", "paper: Sec. 1 'under 2 mm'")
    assert c.holds and c.margin == pytest.approx(0.2) and c.marginal  # 10 % of 2 mm
    far = Clause("error small", 1.0, "<=", 2.0, "mm", "ours: 4x the noise")
    assert far.holds and not far.marginal and far.relative_margin == pytest.approx(0.5)
    fail = Clause("fast", 5.0, ">=", 10.0, "Hz", "paper: Sec. V")
    assert not fail.holds and fail.margin == pytest.approx(-5.0) and not fail.marginal
    assert not Clause("nan", float("nan"), "<", 1.0, "-", "ours: x").holds
    zero = Clause("no collision", 0.0, "<=", 0.0, "-", "paper: 'collision-free'")
    assert zero.holds and not zero.marginal  # no relative margin against a zero bound
    assert "holds" in c.summary() and "MARGINAL" in c.summary()
    count = Clause("broke a constraint", 1, ">=", 1, "-", "paper: x", relative=False)
    assert count.holds and not count.marginal and count.margin == 0.0
    with pytest.raises(UnknownChoiceError):
        Clause("x", 1.0, "=<", 2.0, "-", "ours: x")
    with pytest.raises(ConfigError):
        Clause("x", 1.0, "<=", 2.0, "-", "a number I like")


def test_claim_status_from_its_clauses() -> None:
    from repro.runs.claims import Clause

    ok = Clause("a", 1.0, "<=", 2.0, "-", "ours: a")
    bad = Clause("b", 3.0, "<=", 2.0, "-", "ours: b")
    assert ClaimResult.from_clauses("m", [ok, ok]).status == "reproduced"
    part = ClaimResult.from_clauses("m", [ok, bad])
    assert part.status == "partly_reproduced"
    assert part.measured == "m -- held (1 of 2): a -- not met: b"
    assert ClaimResult.from_clauses("m", [bad]).status == "not_reproduced"
    with pytest.raises(ConfigError):
        ClaimResult.from_clauses("m", [])
    built = Clause("b", 3.0, "<=", 2.0, "-", "ours: b", evidence=False)
    res = ClaimResult.from_clauses("m", [ok, built])  # by construction: reported, not counted
    assert res.status == "reproduced" and "by construction" in built.summary()
    with pytest.raises(ConfigError):
        ClaimResult.from_clauses("m", [built])


def test_clauses_reach_the_claims_table_and_the_clause_table(results: Path,
                                                             tmp_path: Path) -> None:
    from repro.runs.claims import CLAUSE_COLUMNS, Clause, write_clauses_csv

    def check(runs: dict[str, RunFiles]) -> ClaimResult:
        worst = float(runs["good"].trace["err_m"].max()) * 1e3
        return ClaimResult.from_clauses(f"max error {worst:.1f} mm", [
            Clause("error under 5 mm", worst, "<", 5.0, "mm", "paper: 'under 5 mm'"),
            Clause("error under 1 mm", worst, "<", 1.0, "mm", "ours: stricter")])

    claim = Claim("p2020", "1", "claim 1", "< 5 mm", ("good",), check,
                  quote="Sec. 2: 'the error stays under 5 mm'")
    rows: list[dict[str, object]] = []
    df = evaluate_claims([claim], results, _papers(), clauses_out=rows)
    row = df.iloc[0]
    assert row["status"] == "partly_reproduced" and "Sec. 2" in row["quote"]
    assert "error under 5 mm: 4 mm < 5 mm (holds" in row["clauses"]
    assert row["marginal"] == ""
    assert [r["clause"] for r in rows] == ["error under 5 mm", "error under 1 mm"]
    path = tmp_path / "claim_clauses.csv"
    write_clauses_csv(rows, ["p2020"], path)
    write_clauses_csv(rows, ["p2020"], path)  # replaces, does not append
    got = pd.read_csv(path)
    assert tuple(got.columns) == CLAUSE_COLUMNS and len(got) == 2
    assert list(got["holds"]) == [True, False]


def test_a_clause_whose_verdict_flips_within_the_measured_variation_is_marginal() -> None:
    """Issue 18: marginal also when the verdict flips within the machine-to-machine
    variation measured by tests/measure_clause_variation.py, not only within 10 %."""
    from dataclasses import replace

    from repro.runs.claims import Clause

    c = Clause("excess", 0.0, "<=", 1e-6, "rad/s", "ours: tolerance", relative=False)
    assert c.holds and not c.marginal and not c.flips  # no relative margin, no variation
    flips = replace(c, variation=(0.0, 1.2e-6))
    assert flips.flips and flips.marginal and "flips within the machine variation" in (
        flips.summary())
    steady = replace(c, variation=(0.0, 5e-7))
    assert not steady.flips and not steady.marginal
    far = Clause("error", 1.0, "<=", 2.0, "mm", "ours: x", variation=(0.9, 2.1))
    assert far.flips and far.marginal  # 50 % margin, but another machine fails it


def test_the_variation_file_reaches_the_tables(results: Path, tmp_path: Path) -> None:
    from repro.runs.claims import VARIATION_COLUMNS, VARIATION_FILE, Clause, read_variation

    def check(runs: dict[str, RunFiles]) -> ClaimResult:
        worst = float(runs["good"].trace["err_m"].max()) * 1e3
        return ClaimResult.from_clauses("m", [
            Clause("error under 5 mm", worst, "<", 5.0, "mm", "paper: 'under 5 mm'"),
            Clause("error under 8 mm", worst, "<", 8.0, "mm", "ours: x")])

    claim = Claim("p2020", "1", "claim 1", "< 5 mm", ("good",), check)
    assert read_variation(results) == {}
    row = dict.fromkeys(VARIATION_COLUMNS, "")
    pd.DataFrame([{**row, "paper": "p2020", "claim": "1", "clause": "error under 5 mm",
                   "committed": 4.0, "min": 3.9, "max": 5.2},
                  {**row, "paper": "p2020", "claim": "1", "clause": "error under 8 mm",
                   "committed": 4.0, "min": 3.0, "max": 4.1}]).to_csv(
        results / VARIATION_FILE, index=False)
    rows: list[dict[str, object]] = []
    df = evaluate_claims([claim], results, _papers(), clauses_out=rows)
    assert df.iloc[0]["marginal"] == "error under 5 mm"  # 20 % margin, flips at 5.2 mm
    assert [r["flips_within_variation"] for r in rows] == [True, False]
    assert rows[0]["varied_min"] == 3.9 and rows[0]["varied_max"] == 5.2
    # today's figure widens a stale range (4 mm is outside [3.0, 3.5])
    pd.DataFrame([{**row, "paper": "p2020", "claim": "1", "clause": "error under 8 mm",
                   "min": 3.0, "max": 3.5}]).to_csv(results / VARIATION_FILE, index=False)
    rows = []
    evaluate_claims([claim], results, _papers(), clauses_out=rows)
    assert rows[1]["varied_max"] == 4.0 and np.isnan(rows[0]["varied_min"])
    pd.DataFrame([{"paper": "p2020"}]).to_csv(results / VARIATION_FILE, index=False)
    with pytest.raises(ReproError, match="missing"):
        read_variation(results)


def test_a_size_bound_cannot_hide_from_the_marginal_flag() -> None:
    """Issue 38: relative=False silenced the flag on a size bound (chan2011 1: 0.4963 vs
    0.5 px, a 0.7 % margin); it is refused there and kept for counts, flags and tolerances
    around zero."""
    from repro.runs.claims import Clause

    with pytest.raises(ConfigError, match="relative"):
        Clause("final error", 0.4963, "<", 0.5, "px", "ours: the stop test", relative=False)
    sized = Clause("final error", 0.4963, "<", 0.5, "px", "ours: the stop test")
    assert sized.holds and sized.marginal and "MARGINAL" in sized.summary()
    for ok in (Clause("no contact", 0.002, ">", 0.0, "m", "paper: x", relative=False),
               Clause("tolerance", 0.0, "<=", 1e-6, "rad", "ours: x", relative=False),
               Clause("two sensors", 6, ">=", 2, "-", "paper: x", relative=False)):
        assert ok.holds and not ok.marginal


def test_a_renamed_clause_does_not_silently_lose_its_variation(results: Path) -> None:
    """Issue 38: the variation file is joined by the clause's words; a clause renamed since
    it was measured is named in the claim's measured text, not dropped in silence."""
    from repro.runs.claims import VARIATION_COLUMNS, VARIATION_FILE, Clause

    def check(runs: dict[str, RunFiles]) -> ClaimResult:
        worst = float(runs["good"].trace["err_m"].max()) * 1e3
        return ClaimResult.from_clauses("m", [
            Clause("error under 5 mm (renamed)", worst, "<", 5.0, "mm", "paper: x"),
            Clause("error under 8 mm", worst, "<", 8.0, "mm", "ours: x")])

    claim = Claim("p2020", "1", "claim 1", "< 5 mm", ("good",), check)
    row = dict.fromkeys(VARIATION_COLUMNS, "")
    pd.DataFrame([{**row, "paper": "p2020", "claim": "1", "clause": name, "committed": 4.0,
                   "min": 3.9, "max": 4.1}
                  for name in ("error under 5 mm", "error under 8 mm")]).to_csv(
        results / VARIATION_FILE, index=False)
    measured = evaluate_claims([claim], results, _papers()).iloc[0]["measured"]
    assert "VARIATION" in measured and "'error under 5 mm'" in measured
    assert "'error under 5 mm (renamed)'" in measured  # the clause left without a variation
    assert "'error under 8 mm'" not in measured.split("without a measured variation")[1]
