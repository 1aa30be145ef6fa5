"""Tests of repro.runs.claims on small synthetic runs written with TraceRecorder."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pytest

from repro.errors import ConfigError, ReproError, UnknownChoiceError
from repro.runs.claims import (
    CLAIMS_COLUMNS,
    Claim,
    ClaimResult,
    evaluate_claims,
    natural_key,
    read_claims_csv,
    write_claims_csv,
)
from repro.runs.trace import RunFiles, TraceRecorder


@dataclass(frozen=True)
class Cfg:
    gain: float = 2.0


def _write_run(results: Path, paper: str, run: str, errors: list[float], crash: bool = False):
    rec = TraceRecorder(
        results / paper / run, experiment="reach", paper=paper, config=Cfg(), seed=0
    )
    for k, err in enumerate(errors):
        rec.record({"t": 0.01 * k, "step": k, "err_m": err})
    if crash:
        rec.close(status="crashed", reason="RuntimeError: boom")
    else:
        rec.close()


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
    df = evaluate_claims(claims, results)
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
    assert "KeyError" in measured["4"] and "force_n" in measured["4"]
    assert "crashed" in measured["5"] and "boom" in measured["5"]
    assert "str" in measured["6"]
    assert df.loc[0, "description"] == "claim 1" and df.loc[0, "expected"] == "error < 5 mm"


def test_run_with_missing_file_is_not_run(results: Path) -> None:
    (results / "p2020" / "good" / "scene.json").unlink()
    df = evaluate_claims([_claim("1", ("good",), _max_err_below("good", 0.005))], results)
    assert df.loc[0, "status"] == "not_run"
    assert "scene.json" in df.loc[0, "measured"]


def test_claim_validation() -> None:
    with pytest.raises(UnknownChoiceError):
        ClaimResult(measured="x", status="kind of")
    with pytest.raises(ConfigError):
        _claim("", ("a",), _raise)
    with pytest.raises(ConfigError):
        _claim("1", "good", _raise)  # type: ignore[arg-type]
    assert _claim("1", ["a", "b"], _raise).runs == ("a", "b")  # type: ignore[arg-type]


def _table(paper: str, claims: list[str], status: str = "reproduced") -> pd.DataFrame:
    rows = [(paper, c, f"d{c}", "e", "m", status) for c in claims]
    return pd.DataFrame(rows, columns=list(CLAIMS_COLUMNS))


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
    df = evaluate_claims([_claim("1", ("good",), _max_err_below("good", 0.005))], results)
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
