"""Causes of failing variants (repro/runs/causes.py, issue 37) on a fake paper whose clause
fails for a known reason per variant: the evidence is computed while the trace is there and
kept in verdicts.json, every failing variant of a low-rate clause is named (class, cause,
figure), a scene-specific clause keeps its counts but no rate, a variant judged before the
evidence is rerun alone, and a counterfactual reruns only one cause's variants with it
removed, its rate beside the cause."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from runfiles import complete_run_files

from repro import cli
from repro.config import param
from repro.errors import ConfigError, ReproError
from repro.runs import registry
from repro.runs.causes import (
    UNKNOWN,
    Cause,
    CauseModel,
    Counterfactual,
    Diagnosis,
    Variant,
    classify_variants,
)
from repro.runs.claims import Claim, ClaimResult, Clause
from repro.runs.registry import Experiment, Paper
from repro.runs.sweep import VERDICTS_FILE, run_counterfactual, run_sweep
from repro.runs.trace import RunFiles
from repro.sweep_ranges import SweepRange, sample_variants

SATURATION = 1.5  # the fake drive saturates here: a gain above it cannot track


@dataclass(frozen=True)
class Cfg:
    gain: float = param(1.0, range=(0.0, 3.0), help="a gain",
                        sweep=SweepRange(0.0, 3.0, reason="a range written down first"))
    offset: float = param(0.0, range=(-1.0, 1.0), help="a scene offset",
                          sweep=SweepRange(-1.0, 1.0, reason="another one"))
    unsaturated: bool = param(False, help="counterfactual hook: no saturation")


class Runner:
    """err = gain (clipped at SATURATION unless unsaturated) + |offset|; sat = clipped."""

    def __init__(self) -> None:
        self.calls: list[Cfg] = []

    def __call__(self, config: Cfg, out_dir: Path) -> Path:
        self.calls.append(config)
        out_dir.mkdir(parents=True, exist_ok=True)
        sat = config.gain > SATURATION and not config.unsaturated
        err = (0.2 if sat else 0.0) + abs(config.offset)  # a clipped drive leaves an error
        pd.DataFrame({"t": np.arange(3) * 0.1, "err": err * np.ones(3),
                      "n_sat": [int(sat)] * 3}).to_csv(out_dir / "trace.csv", index=False)
        (out_dir / "events.csv").write_text("t,step,kind,detail\n")
        (out_dir / "manifest.json").write_text(json.dumps({
            "experiment": "case", "paper": "fake", "status": "completed", "n_rows": 3,
            "config": {"duration": 0.2}, "summary": {},
            "config_hash": registry.compute_config_hash(config)}))
        complete_run_files(out_dir)
        return out_dir


def _check(runs: dict[str, RunFiles]) -> ClaimResult:
    err = float(runs["case"].trace["err"].max())
    return ClaimResult.from_clauses(f"error {err:.2f}", [
        Clause("the error stays under 0.5", err, "<", 0.5, "-", "paper: 'under 0.5'"),
        Clause("the error is exactly 0", err, "<=", 0.0, "-", "paper: 'zero'",
               relative=False),
        Clause("a clause of one scene", err, "<=", 0.0, "-", "paper: 'its scene'",
               relative=False)])


def _evidence(runs: dict[str, RunFiles]) -> dict[str, float]:
    tr = runs["case"].trace
    return {"saturated_rows": int(tr["n_sat"].sum()), "err": float(tr["err"].max())}


def _saturation(v: Variant) -> Cause:
    if v.figure("saturated_rows") > 0:
        return Cause("ours-defect", "drive-saturation",
                     f"{v.figure('saturated_rows'):.0f} rows saturated", v.figure("saturated_rows"))
    return Cause("ours-range", "offset", f"|offset| {abs(v.params['offset']):.2f}",
                 abs(v.params["offset"]), "m")


def _model(version: str = "1") -> CauseModel:
    return CauseModel(
        version, {"case": _evidence},
        (Diagnosis("case", "1", "the error is exactly 0", _saturation),
         Diagnosis("case", "1", "a clause of one scene",
                   scene_specific="fits only the paper's scene")),
        (Counterfactual("unsat", "case", "drive-saturation", {"unsaturated": True},
                        "the same scenes with an unsaturated drive"),))


def _papers(runner: Runner, model: CauseModel | None = None) -> dict[str, Paper]:
    exp = Experiment(name="case", paper="fake", description="a case", config_cls=Cfg,
                     run=runner)
    claims = (Claim("fake", "1", "error small", "< 0.5", ("case",), _check),)
    the_model = model or _model()
    return {"fake": Paper(key="fake", experiments=(exp,), claims=lambda: claims,
                          causes=lambda: the_model)}


def _truth(n: int, seed: int) -> list[dict[str, float]]:
    return sample_variants(Cfg, n, seed)


def test_every_failing_variant_of_a_low_rate_clause_is_named(tmp_path: Path) -> None:
    runner = Runner()
    path = run_sweep("fake.case", 16, seed=1, results_dir=tmp_path, papers=_papers(runner))
    sweep = path.parent
    doc = json.loads(next((sweep / "variants").glob(f"*/{VERDICTS_FILE}")).read_text())
    assert doc["evidence_version"] == "1" and set(doc["evidence"]) == {"saturated_rows", "err"}
    causes = pd.read_csv(sweep / "causes.csv", dtype={"claim": str})
    truth = _truth(16, 1)
    exact = causes[causes["clause"] == "the error is exactly 0"].rename(columns={"class": "cls"})
    # the known answer: it fails wherever the drive saturates or the offset is not 0
    failing = [i for i, v in enumerate(truth) if v["gain"] > SATURATION or v["offset"] != 0]
    assert sorted(exact["variant"]) == failing
    for r in exact.itertuples():
        want = "drive-saturation" if truth[r.variant]["gain"] > SATURATION else "offset"
        assert r.cause == want and r.cls == ("ours-defect" if want != "offset" else "ours-range")
    # the "under 0.5" clause (rate 6/16 here) has no diagnosis: each failure is unknown
    rates = pd.read_csv(sweep / "rates.csv", dtype={"claim": str}, keep_default_na=False)
    under = rates[rates["clause"] == "the error stays under 0.5"].iloc[0]
    assert float(under["rate"]) < 0.9 and under["scope"] == "variants"
    unknown = causes[causes["clause"] == "the error stays under 0.5"]
    assert len(unknown) == 16 - int(under["held"]) and set(unknown["class"]) == {UNKNOWN}
    # the scene-specific clause: class check for every failing variant, counts but no rate
    local = rates[rates["clause"] == "a clause of one scene"].iloc[0]
    assert local["scope"] == "canonical only" and local["rate"] == "" and int(local["variants"])
    claim_row = rates[(rates["claim"] == "1") & (rates["clause"] == "")].iloc[0]
    assert claim_row["scope"] == "canonical only" and claim_row["rate"] == ""
    assert set(causes.loc[causes["clause"] == "a clause of one scene", "class"]) == {"check"}
    shares = pd.read_csv(sweep / "cause_shares.csv", dtype={"claim": str})
    mine = shares[shares["clause"] == "the error is exactly 0"]
    assert mine["n"].sum() == len(failing) and math.isclose(mine["share"].sum(), 1.0)


def test_a_variant_judged_before_the_evidence_is_rerun_alone(tmp_path: Path) -> None:
    runner = Runner()
    run_sweep("fake.case", 8, seed=0, results_dir=tmp_path, papers=_papers(runner))
    assert len(runner.calls) == 8
    run_sweep("fake.case", 8, seed=0, results_dir=tmp_path, papers=_papers(runner))
    assert len(runner.calls) == 8  # same version: nothing rerun
    run_sweep("fake.case", 8, seed=0, results_dir=tmp_path,
              papers=_papers(runner, _model(version="2")))
    truth = _truth(8, 0)
    n_failing = sum(v["gain"] > SATURATION or v["offset"] != 0 for v in truth)
    assert len(runner.calls) == 8 + n_failing  # only the variants whose clause fails
    docs = [json.loads(p.read_text()) for p in
            (tmp_path / "sweeps" / "case" / "variants").glob(f"*/{VERDICTS_FILE}")]
    assert sum(d.get("evidence_version") == "2" for d in docs) == n_failing


def test_a_counterfactual_reruns_one_cause_with_it_removed(tmp_path: Path) -> None:
    runner = Runner()
    papers = _papers(runner)
    run_sweep("fake.case", 16, seed=1, results_dir=tmp_path, papers=papers)
    n0 = len(runner.calls)
    truth = _truth(16, 1)
    sat = [i for i, v in enumerate(truth) if v["gain"] > SATURATION]
    path = run_counterfactual("fake.case", "unsat", tmp_path, papers=papers)
    assert len(runner.calls) == n0 + len(sat)
    assert all(c.unsaturated for c in runner.calls[n0:])
    assert sorted(pd.read_csv(path)["variant"]) == sat
    shares = pd.read_csv(tmp_path / "sweeps" / "case" / "cause_shares.csv",
                         dtype={"claim": str}, keep_default_na=False)
    row = shares[shares["cause"] == "drive-saturation"].iloc[0]
    # without saturation the clause holds where the offset is 0 (never, for Sobol draws):
    held = sum(truth[i]["offset"] == 0 for i in sat)
    assert row["counterfactual"] == "unsat" and int(row["cf_variants"]) == len(sat)
    assert int(row["cf_held"]) == held
    with pytest.raises(ReproError, match="counterfactual of case"):
        run_counterfactual("fake.case", "nope", tmp_path, papers=papers)


def test_a_counterfactual_shows_its_class_when_the_cause_is_the_only_one(
        tmp_path: Path) -> None:
    """With the offset's range at 0 the saturation is the only cause: removing it makes
    every rerun hold (the class shown, not asserted)."""

    @dataclass(frozen=True)
    class NoOffset(Cfg):
        offset: float = param(0.0, range=(-1.0, 1.0), help="fixed")

    runner = Runner()
    exp = Experiment(name="case", paper="fake", description="a case", config_cls=NoOffset,
                     run=runner)
    claims = (Claim("fake", "1", "error small", "< 0.5", ("case",), _check),)
    model = _model()
    papers = {"fake": Paper(key="fake", experiments=(exp,), claims=lambda: claims,
                            causes=lambda: model)}
    run_sweep("fake.case", 16, seed=3, results_dir=tmp_path, papers=papers)
    run_counterfactual("fake.case", "unsat", tmp_path, papers=papers)
    shares = pd.read_csv(tmp_path / "sweeps" / "case" / "cause_shares.csv",
                         dtype={"claim": str})
    row = shares[shares["cause"] == "drive-saturation"].iloc[0]
    assert row["cf_rate"] == 1.0 and row["cf_held"] == row["cf_variants"] > 0


def test_a_clause_without_a_diagnosis_is_unknown_and_a_renamed_one_is_an_error(
        tmp_path: Path) -> None:
    runner = Runner()
    bare = CauseModel("1", {"case": _evidence},
                      (Diagnosis("case", "1", "a clause of one scene", scene_specific="x"),))
    run_sweep("fake.case", 8, seed=0, results_dir=tmp_path, papers=_papers(runner, bare))
    causes = pd.read_csv(tmp_path / "sweeps" / "case" / "causes.csv", dtype={"claim": str})
    assert set(causes.loc[causes["clause"] == "the error is exactly 0", "class"]) == {UNKNOWN}
    renamed = CauseModel("1", {"case": _evidence},
                         (Diagnosis("case", "1", "the error is 0", _saturation),))
    with pytest.raises(ReproError, match="never judged"):
        classify_variants(renamed, "case", tmp_path / "sweeps" / "case")


def test_causes_and_diagnoses_refuse_what_names_nothing() -> None:
    with pytest.raises(ReproError, match="cause class"):
        Cause("ours", "x", "y")
    with pytest.raises(ConfigError, match="cause name"):
        Cause("method", "a,b", "y")
    with pytest.raises(ConfigError, match="either"):
        Diagnosis("case", "1", "c")
    with pytest.raises(ConfigError, match="either"):
        Diagnosis("case", "1", "c", _saturation, scene_specific="both")
    with pytest.raises(ConfigError, match="no override"):
        Counterfactual("x", "case", "c", {}, "nothing")
    broken = Diagnosis("case", "1", "c", lambda v: 1 / 0)  # type: ignore[arg-type,return-value]
    got = broken.cause(Variant(0, "h", {}, {}, {}))
    assert got.cls == UNKNOWN and "ZeroDivisionError" in got.evidence


def test_the_cli_refuses_an_unknown_counterfactual_before_anything_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = cli.main(["--results", str(tmp_path), "counterfactual", "thomas2024.case1",
                     "no-such-thing"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_cause_videos_rerun_each_example_and_refuse_a_moved_verdict(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """One video per named cause (not per scene-specific clause), from the example variant
    rerun with its trace; a rerun whose verdicts differ from the sweep's is refused."""
    from repro.replay import video
    from repro.runs.sweep import cause_videos

    made: list[tuple[Path, Path]] = []

    def fake_video(run_dir: Path, out: Path, **_: object) -> Path:
        assert (run_dir / "trace.csv").is_file()  # the rerun kept its trace
        out.write_bytes(b"mp4")
        made.append((run_dir, out))
        return out

    monkeypatch.setattr(video, "write_video", fake_video)
    runner = Runner()
    papers = _papers(runner)
    run_sweep("fake.case", 16, seed=1, results_dir=tmp_path, papers=papers)
    figs = tmp_path / "figures"
    out = cause_videos("fake.case", tmp_path, figs, papers=papers)
    assert sorted(p.name for p in out) == ["case__drive-saturation.mp4", "case__no-classifier.mp4",
                                           "case__offset.mp4"]
    assert all(p.parent == figs / "fake" / "videos" / "causes" for p in out)
    # the sweep's record says otherwise (as if the code had changed since): refused
    shares = pd.read_csv(tmp_path / "sweeps" / "case" / "cause_shares.csv", dtype=str)
    h = shares.loc[shares["cause"] == "offset", "example_hash"].iloc[0]
    path = tmp_path / "sweeps" / "case" / "variants" / h / VERDICTS_FILE
    doc = json.loads(path.read_text())
    doc["row"]["claim1.c2.holds"] = True
    path.write_text(json.dumps(doc))
    with pytest.raises(ReproError, match="differ from the sweep's"):
        cause_videos("fake.case", tmp_path, figs, papers=papers)
