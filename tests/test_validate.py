"""The validating run loader: every fault of a damaged run folder is named, with its folder
and the first rule it fails, and no consumer (claims, figures, report, results) reads it as
whole."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from repro.runs.validate import DamagedRun, check_run

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "results"
SMALL = RESULTS / "chan2011" / "ibvs"  # 14 rows, text, bool and numeric columns


def _copy(tmp_path: Path, src: Path = SMALL) -> Path:
    dst = tmp_path / src.parent.name / src.name
    shutil.copytree(src, dst)
    return dst


def _lines(run: Path) -> list[str]:
    return (run / "trace.csv").read_text().splitlines(keepends=True)


def _write_lines(run: Path, lines: list[str]) -> None:
    (run / "trace.csv").write_text("".join(lines))


def _cell(run: Path, column: str, row: int, value: str) -> None:
    lines = _lines(run)
    names = lines[0].rstrip("\n").split(",")
    cells = lines[row + 1].rstrip("\n").split(",")
    cells[names.index(column)] = value
    lines[row + 1] = ",".join(cells) + "\n"
    _write_lines(run, lines)


def _json(run: Path, name: str, edit: Callable[[dict], object]) -> None:
    path = run / name
    path.write_text(json.dumps(edit(json.loads(path.read_text()))))


def _first(run: Path, unit: str) -> str:
    cols = json.loads((run / "columns.json").read_text())["columns"]
    return next(c["name"] for c in cols if c["unit"] == unit and c["name"] not in ("t", "step"))


FAULTS: dict[str, tuple[Callable[[Path], None], str]] = {
    "cut mid-line": (lambda r: (r / "trace.csv").write_bytes(
        (r / "trace.csv").read_bytes()[:-40]), "last line is cut"),
    "rows shuffled": (lambda r: _write_lines(r, [_lines(r)[0], *reversed(_lines(r)[1:])]),
                      "not strictly increasing"),
    "NaN last row": (lambda r: _write_lines(r, _lines(r)[:-1] + [",".join(
        ["nan"] * len(_lines(r)[0].split(","))) + "\n"]), "t is not finite"),
    "10 NaN rows": (lambda r: _write_lines(r, _lines(r)[:3] + [",".join(
        ["nan"] * len(_lines(r)[0].split(","))) + "\n"] * 10 + _lines(r)[13:]),
        "t is not finite at row 3"),
    "a row dropped": (lambda r: _write_lines(r, _lines(r)[:-1]), "n_rows"),
    "header only": (lambda r: _write_lines(r, _lines(r)[:1]), "n_rows"),
    "empty trace": (lambda r: (r / "trace.csv").write_text(""), "empty"),
    "a field missing": (lambda r: _write_lines(r, _lines(r)[:3] + [
        _lines(r)[3].rsplit(",", 1)[0] + "\n"] + _lines(r)[4:]), "line 4 has"),
    "a column missing": (lambda r: _write_lines(r, [",".join(
        line.rstrip("\n").split(",")[:-1]) + "\n" for line in _lines(r)]), "header"),
    "non-numeric cell": (lambda r: _cell(r, _first(r, "px"), 2, "abc"), "is not a number"),
    "bool cell abc": (lambda r: _cell(r, _first(r, "bool"), 2, "abc"), "is not True or False"),
    "manifest is a list": (lambda r: (r / "manifest.json").write_text("[]"), "not a JSON object"),
    "manifest unreadable": (lambda r: (r / "manifest.json").write_text("{"), "readable JSON"),
    "scene is empty": (lambda r: (r / "scene.json").write_text("{}"), "scene.json lacks"),
    "n_rows disagrees": (lambda r: _json(r, "manifest.json", lambda m: {**m, "n_rows": 99}),
                         "n_rows = 99"),
    "columns.json missing": (lambda r: (r / "columns.json").unlink(), "missing columns.json"),
    "columns.json malformed": (lambda r: (r / "columns.json").write_text('{"columns": 3}'),
                               "not a list of columns"),
    "interrupted": (lambda r: _json(r, "manifest.json", lambda m: {
        **m, "status": "interrupted", "reason": "SIGINT"}), "'interrupted'"),
    "running, process gone": (lambda r: _json(r, "manifest.json", lambda m: {
        **m, "status": "running", "pid": 2 ** 22 + 17}), "process gone"),
    "unknown status": (lambda r: _json(r, "manifest.json", lambda m: {**m, "status": "ok"}),
                       "status 'ok'"),
    "events.csv missing": (lambda r: (r / "events.csv").unlink(), "missing events.csv"),
    "events header": (lambda r: (r / "events.csv").write_text("a,b\n1,2\n"), "events"),
}


def test_every_committed_run_is_valid():
    runs = sorted(p.parent for p in RESULTS.glob("*/*/manifest.json"))
    assert len(runs) >= 20
    for run in runs:
        check_run(run)


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_a_fault_is_named_with_its_folder_and_rule(tmp_path, fault):
    run = _copy(tmp_path)
    check_run(run)  # whole before
    damage, rule = FAULTS[fault]
    damage(run)
    with pytest.raises(DamagedRun) as err:
        check_run(run)
    assert rule in err.value.rule, err.value.rule
    assert str(run) in str(err.value)


def test_a_text_column_takes_any_text_and_an_empty_cell_is_missing(tmp_path):
    run = _copy(tmp_path, RESULTS / "pomares2011" / "exp3")
    cols = json.loads((run / "columns.json").read_text())["columns"]
    text = next(c["name"] for c in cols if c["unit"] == "text")
    _cell(run, text, 1, "anything at all")
    _cell(run, _first(run, "m"), 1, "")
    check_run(run)


def test_a_damaged_run_makes_its_claims_not_run_and_is_stale(tmp_path):
    from repro.runs.claims import evaluate_claims
    from repro.runs.registry import find_experiment, is_stale, load_papers

    papers = load_papers()
    results = tmp_path / "results"
    for name in ("case1", "case1_no_proximity"):
        shutil.copytree(RESULTS / "thomas2024" / name, results / "thomas2024" / name)
    claims = [c for c in papers["thomas2024"].claims() if set(c.runs) <= {"case1"}]
    assert claims
    before = evaluate_claims(claims, results, papers)
    assert (before["status"] != "not_run").all()
    exp = find_experiment(papers, "thomas2024.case1")
    assert not is_stale(exp, results, exp.config_cls())[0]
    run = results / "thomas2024" / "case1"
    FAULTS["rows shuffled"][0](run)
    after = evaluate_claims(claims, results, papers)
    assert (after["status"] == "not_run").all()
    assert after["measured"].str.contains("not strictly increasing").all()
    assert after["measured"].str.contains(str(run)).all()
    stale, reason = is_stale(exp, results, exp.config_cls())
    assert stale and "not strictly increasing" in reason


def test_figures_skip_a_damaged_run_with_one_line(tmp_path, capsys):
    from repro.runs.validate import load_run_if_present

    run = _copy(tmp_path)
    assert load_run_if_present(run.parent, run.name) is not None
    FAULTS["cut mid-line"][0](run)
    assert load_run_if_present(run.parent, run.name) is None
    err = capsys.readouterr().err
    assert "skipping damaged run" in err and "last line is cut" in err


def test_figures_skip_an_interrupted_run(tmp_path, capsys):
    from repro.runs.validate import load_run_if_present

    run = _copy(tmp_path)
    FAULTS["interrupted"][0](run)
    assert load_run_if_present(run.parent, run.name) is None
    assert "status 'interrupted'" in capsys.readouterr().err


def test_a_column_missing_everywhere_makes_the_claim_not_run_naming_it(tmp_path):
    """Removed from trace.csv and columns.json alike, the run is consistent; the claim
    that needs the column is not_run, and its message names the column and the run."""
    from repro.runs.claims import evaluate_claims
    from repro.runs.registry import load_papers

    papers = load_papers()
    results = tmp_path / "results"
    run = results / "thomas2024" / "case1"
    shutil.copytree(RESULTS / "thomas2024" / "case1", run)
    claims = [c for c in papers["thomas2024"].claims() if set(c.runs) == {"case1"}]
    assert claims
    before = evaluate_claims(claims, results, papers)
    assert (before["status"] != "not_run").all()
    lines = _lines(run)
    names = lines[0].rstrip("\n").split(",")
    cols = json.loads((run / "columns.json").read_text())["columns"]
    # drop every column but the runner's own; a check reads at least one of them
    keep = [i for i, n in enumerate(names) if n in ("t", "step")]
    _write_lines(run, [",".join(line.rstrip("\n").split(",")[i] for i in keep) + "\n"
                       for line in lines])
    (run / "columns.json").write_text(json.dumps(
        {"columns": [c for c in cols if c["name"] in ("t", "step")]}))
    check_run(run)
    after = evaluate_claims(claims, results, papers)
    assert (after["status"] == "not_run").all()
    assert after["measured"].str.contains("missing from run").all(), after["measured"]


def test_the_report_marks_a_damaged_run(tmp_path):
    from repro.runs.report import _read_manifests

    run = _copy(tmp_path)
    FAULTS["rows shuffled"][0](run)
    (got,) = _read_manifests(run.parent)
    assert got[1]["status"] == "damaged" and "strictly increasing" in got[1]["reason"]
