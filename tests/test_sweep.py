"""Variant sweeps (repro/runs/sweep.py, issue 19 item 2) on a fake paper whose one claim has
a known answer per variant: the variants are the seeded Sobol samples, each an ordinary run
judged alone, the table says each clause's figure and verdict, reruns skip what was judged,
and a failing variant is a row, not a lost sweep."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from runfiles import complete_run_files

from repro import cli
from repro.config import param
from repro.errors import ConfigError, ReproError, SolverError
from repro.runs import registry
from repro.runs.claims import Claim, ClaimResult, Clause
from repro.runs.registry import Experiment, Paper
from repro.runs.sweep import VERDICTS_FILE, run_sweep, variant_config
from repro.runs.trace import RunFiles
from repro.sweep_ranges import SweepRange, sample_variants

BOUND = 1.0  # the claim: the error stays under 1 (holds for gain < 0.5)
RENDER_BIAS = 0.2  # the fake rendered camera reads 0.2 more: verdicts differ for gain in [0.4, 0.5)


@dataclass(frozen=True)
class GainCfg:
    gain: float = param(0.3, range=(0.0, 2.0), help="a gain",
                        sweep=SweepRange(0.1, 0.9, reason="a range written down first"))
    camera_mode: str = param("render", choices=("render", "exact"))
    snapshots: float = param(0.5, range=(0.0, 10.0), output_only=True)
    fail_above: float = param(2.0, range=(0.0, 2.0), help="test hook: fail for gain above")


@dataclass(frozen=True)
class TwoCfg(GainCfg):
    other: float = param(0.5, range=(0.0, 1.0),
                         sweep=SweepRange(0.0, 1.0, reason="a value that decides nothing"))


class Runner:
    def __init__(self) -> None:
        self.calls: list[GainCfg] = []

    def __call__(self, config: GainCfg, out_dir: Path) -> Path:
        self.calls.append(config)
        if config.gain > config.fail_above:
            raise SolverError(f"no solution at gain {config.gain}")
        out_dir.mkdir(parents=True, exist_ok=True)
        t = np.arange(5) * 0.1
        bias = RENDER_BIAS if config.camera_mode == "render" else 0.0
        pd.DataFrame({"t": t, "err": (2.0 * config.gain + bias) * np.ones(5)}).to_csv(
            out_dir / "trace.csv", index=False)
        (out_dir / "events.csv").write_text("t,step,kind,detail\n")
        (out_dir / "manifest.json").write_text(json.dumps({
            "experiment": "case", "paper": "fake", "status": "completed", "n_rows": 5,
            "config": {"duration": 0.4}, "summary": {},
            "config_hash": registry.compute_config_hash(config)}))
        complete_run_files(out_dir)
        if config.snapshots > 0:
            (out_dir / "frames").mkdir(exist_ok=True)
        return out_dir


def _check(runs: dict[str, RunFiles]) -> ClaimResult:
    err = float(runs["case"].trace["err"].max())
    return ClaimResult.from_clauses(f"max error {err:.2f}", [
        Clause("the error stays under 1", err, "<", BOUND, "-", "paper: 'under 1'")])


def _papers(runner: Runner) -> dict[str, Paper]:
    exp = Experiment(name="case", paper="fake", description="a case", config_cls=GainCfg,
                     run=runner)
    other = Experiment(name="other", paper="fake", description="needs two runs",
                       config_cls=GainCfg, run=runner)
    claims = (Claim("fake", "1", "error under 1", "< 1", ("case",), _check),
              Claim("fake", "2", "two runs", "-", ("case", "other"), _check))
    return {"fake": Paper(key="fake", experiments=(exp, other), claims=lambda: claims)}


def test_a_sweep_judges_every_variant_and_resumes(tmp_path: Path) -> None:
    runner = Runner()
    papers = _papers(runner)
    path = run_sweep("fake.case", 8, seed=2, results_dir=tmp_path, papers=papers)
    df = pd.read_csv(path)
    want = [v["gain"] for v in sample_variants(GainCfg, 8, seed=2)]
    np.testing.assert_allclose(df["p.gain"], want, rtol=1e-9)
    assert len(runner.calls) == 8 and {c.camera_mode for c in runner.calls} == {"exact"}
    assert all(c.snapshots == 0.0 for c in runner.calls)  # outputs off without traces
    # the known answer: the clause holds iff 2 gain < 1; claim 2 needs another run: not here
    np.testing.assert_allclose(df["claim1.c1.measured"], 2.0 * np.asarray(want))
    assert list(df["claim1.c1.holds"]) == [2 * g < BOUND for g in want]
    assert list(df["claim1.status"]) == ["reproduced" if 2 * g < BOUND else "not_reproduced"
                                         for g in want]
    assert "claim2.status" not in df.columns
    np.testing.assert_allclose(df["claim1.c1.margin"], BOUND - 2.0 * np.asarray(want))
    cols = json.loads((path.parent / "variants.columns.json").read_text())
    assert set(cols["columns"]) >= {"variant", "p.gain", "claim1.status"}
    assert "a range written down first" in cols["columns"]["p.gain"]["definition"]
    # the variants' folders: manifest, events, verdicts; no trace, no frames
    dirs = sorted((path.parent / "variants").iterdir())
    assert len(dirs) == 8 and all((d / VERDICTS_FILE).is_file() for d in dirs)
    assert all(sorted(p.name for p in d.iterdir()) == ["events.csv", "manifest.json",
                                                        VERDICTS_FILE] for d in dirs)
    # a rerun judges nothing again; a variant without its verdicts is rerun alone
    (dirs[3] / VERDICTS_FILE).unlink()
    again = pd.read_csv(run_sweep("fake.case", 8, seed=2, results_dir=tmp_path, papers=papers))
    assert len(runner.calls) == 9
    pd.testing.assert_frame_equal(again.drop(columns="wall_time_s"),
                                  df.drop(columns="wall_time_s"))


def test_a_second_sweep_of_the_same_folder_is_refused_before_it_runs(tmp_path: Path) -> None:
    """Two sweeps of one folder ran, judged and deleted each other's variant files (two
    'missing trace.csv' failures in a real rendered subsample); the second is refused."""
    runner = Runner()
    papers = _papers(runner)
    sweep_dir = tmp_path / "sweeps" / "case"
    with registry.run_folder_lock(sweep_dir):  # as a live sweep holds it
        with pytest.raises(ReproError, match="being swept by another repro process"):
            run_sweep("fake.case", 2, seed=0, results_dir=tmp_path, papers=papers)
    assert runner.calls == [] and list(sweep_dir.iterdir()) == []
    run_sweep("fake.case", 2, seed=0, results_dir=tmp_path, papers=papers)  # free again
    assert len(runner.calls) == 2


def test_traces_are_kept_when_asked_and_failures_are_rows(tmp_path: Path) -> None:
    runner = Runner()
    path = run_sweep("fake.case", 4, seed=0, results_dir=tmp_path, keep_traces=True,
                     papers=_papers(runner))
    assert all((d / "trace.csv").is_file() for d in (path.parent / "variants").iterdir())

    @dataclass(frozen=True)
    class Failing(GainCfg):
        fail_above: float = param(0.5, range=(0.0, 2.0))

    papers = _papers(runner)
    other = papers["fake"].experiments[1]
    papers["fake"] = Paper(key="fake", experiments=(Experiment(
        name="case", paper="fake", description="fails", config_cls=Failing, run=runner),
        other), claims=papers["fake"].claims)
    df = pd.read_csv(run_sweep("fake.case", 8, seed=1, results_dir=tmp_path / "f",
                               papers=papers))
    failed = df["run_status"] == "failed"
    assert list(failed) == list(df["p.gain"] > 0.5) and failed.any() and not failed.all()
    assert df.loc[failed, "run_reason"].str.contains("no solution").all()
    assert df.loc[failed, "claim1.status"].isna().all()


def test_bad_sweeps_are_refused(tmp_path: Path) -> None:
    papers = _papers(Runner())
    exp = papers["fake"].experiments[0]
    with pytest.raises(ConfigError, match="no config fields"):
        variant_config(exp, {"nope": 1.0}, None)
    with pytest.raises(ConfigError, match="out of range"):
        variant_config(exp, {"gain": 5.0}, None)
    with pytest.raises(ConfigError, match="--camera"):
        variant_config(exp, {}, "fisheye")
    with pytest.raises(ConfigError, match="needs only this run"):
        run_sweep("fake.other", 2, 0, tmp_path, papers={"fake": Paper(
            key="fake", experiments=papers["fake"].experiments,
            claims=lambda: (papers["fake"].claims() or ())[1:])})


def test_the_cli_sweeps_and_reports(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    runner = Runner()
    monkeypatch.setattr(registry, "load_papers", lambda: _papers(runner))
    code = cli.main(["sweep", "fake.case", "--n", "3", "--results", str(tmp_path), "--serial"])
    out: Any = capsys.readouterr().out
    assert code == 0 and "3 variants: 3 judged, 0 refused starts, 0 failed runs" in out
    assert (tmp_path / "sweeps" / "case" / "variants.csv").is_file()
    assert cli.main(["sweep", "fake.case", "--n", "0", "--results", str(tmp_path),
                     "--serial"]) == 2
    # more than 1024 variants parse (a sweep that refuses most starts needs them); 2**16 + 1
    # and more workers than 1024 do not
    args = cli.build_parser().parse_args(["sweep", "fake.case", "--n", "1100"])
    assert args.n == 1100
    for bad in (["--n", "65537"], ["--n", "4", "-j", "1025"]):
        assert cli.main(["sweep", "fake.case", *bad, "--results", str(tmp_path)]) == 2


# ----------------------------------------------------------------- paired sweeps
OTHER_BOUND = 0.8  # claim 2 on the partner run: its error (2 gain) stays under 0.8


def _check_other(runs: dict[str, RunFiles]) -> ClaimResult:
    err = float(runs["other"].trace["err"].max())
    return ClaimResult.from_clauses(f"other's error {err:.2f}", [
        Clause("the partner's error stays under 0.8", err, "<", OTHER_BOUND, "-",
               "ours: a test bound")])


def _paired(runner: Runner) -> dict[str, Paper]:
    base = _papers(runner)["fake"]
    claims = (base.claims() or ())[:1] + (
        Claim("fake", "2", "the partner's error", "< 0.8", ("case", "other"), _check_other),)
    return {"fake": Paper(key="fake", experiments=base.experiments, claims=lambda: claims,
                          sweep_groups={"case": ("other",)}, joint_claims=(("1", "2"),))}


def test_a_paired_sweep_runs_the_partner_on_each_variant_and_rates_them_jointly(
        tmp_path: Path) -> None:
    (tmp_path / "claims.csv").write_text("paper,claim,status\nfake,1,reproduced\n"
                                         "fake,2,not_reproduced\n")
    runner = Runner()
    path = run_sweep("fake.case", 16, seed=3, results_dir=tmp_path, papers=_paired(runner))
    df = pd.read_csv(path)
    gains = np.array([v["gain"] for v in sample_variants(GainCfg, 16, seed=3)])
    # both members of every variant ran with the variant's value, the swept one first
    assert [c.gain for c in runner.calls] == [g for g in gains for _ in range(2)]
    assert list(df["claim1.c1.holds"]) == list(2 * gains < BOUND)
    assert list(df["claim2.c1.holds"]) == list(2 * gains < OTHER_BOUND)
    for d in (path.parent / "variants").iterdir():  # the partner's run in its own folder
        assert sorted(p.name for p in (d / "other").iterdir()) == ["events.csv",
                                                                    "manifest.json"]
        assert json.loads((d / VERDICTS_FILE).read_text())["members"] == {"case": ".",
                                                                          "other": "other"}
    rates = pd.read_csv(path.parent / "rates.csv", dtype={"claim": str})
    joint = rates[rates["claim"] == "1+2"].iloc[0]
    k = int(((2 * gains < BOUND) & (2 * gains < OTHER_BOUND)).sum())
    assert (joint["variants"], joint["held"]) == (16, k) and 0 < k < 16
    assert joint["canonical"] == "not jointly"
    cols = json.loads((path.parent / "variants.columns.json").read_text())
    assert cols["members"] == ["fake.case", "fake.other"]


def test_a_partner_with_other_ranges_is_refused(tmp_path: Path) -> None:
    @dataclass(frozen=True)
    class OtherRange(GainCfg):
        gain: float = param(0.3, range=(0.0, 2.0),
                            sweep=SweepRange(0.2, 0.9, reason="a wider range"))

    papers = _paired(Runner())
    exps = papers["fake"].experiments
    odd = Experiment(name="other", paper="fake", description="x", config_cls=OtherRange,
                     run=exps[1].run)
    bad = {"fake": Paper(key="fake", experiments=(exps[0], odd), claims=papers["fake"].claims,
                         sweep_groups={"case": ("other",)})}
    with pytest.raises(ConfigError, match="declares other ranges"):
        run_sweep("fake.case", 2, 0, tmp_path, papers=bad)
    unknown = {"fake": Paper(key="fake", experiments=exps, claims=papers["fake"].claims,
                             sweep_groups={"case": ("nope",)})}
    with pytest.raises(ConfigError, match="unknown experiments"):
        run_sweep("fake.case", 2, 0, tmp_path, papers=unknown)
    assert not (tmp_path / "sweeps" / "case" / "variants").exists()


# ----------------------------------------------------------------- the Dask engine
def _by_value() -> None:
    """Workers are fresh processes that cannot import this test module: ship its fake
    configs and runners by value."""
    import sys

    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])


class KillOnce(Runner):
    """Kills its worker process the first time it meets the variant with ``gain`` closest
    to ``target`` (a marker file says it happened)."""

    def __init__(self, marker: Path, target: float) -> None:
        super().__init__()
        self.marker, self.target = marker, target

    def __call__(self, config: GainCfg, out_dir: Path) -> Path:
        if abs(config.gain - self.target) < 1e-12 and not self.marker.exists():
            self.marker.write_text("killed")
            import os

            os._exit(1)  # the worker dies mid-variant
        return super().__call__(config, out_dir)


def test_dask_gives_the_serial_table_and_survives_a_killed_worker(tmp_path: Path) -> None:
    _by_value()
    serial = pd.read_csv(run_sweep("fake.case", 6, seed=5, results_dir=tmp_path / "s",
                                   papers=_papers(Runner())))
    target = sample_variants(GainCfg, 6, seed=5)[2]["gain"]
    runner = KillOnce(tmp_path / "killed", target)
    path = run_sweep("fake.case", 6, seed=5, results_dir=tmp_path / "d",
                     papers=_papers(runner), engine="dask", workers=2)
    dask = pd.read_csv(path)
    assert (tmp_path / "killed").read_text() == "killed"  # a worker did die
    pd.testing.assert_frame_equal(dask.drop(columns="wall_time_s"),
                                  serial.drop(columns="wall_time_s"))
    assert sorted(dask["variant"]) == list(range(6))  # nothing lost, nothing twice
    assert len(list((path.parent / "variants").iterdir())) == 6


# ----------------------------------------------------------------- rates
def test_wilson_interval_known_values() -> None:
    from repro.runs.sweep_rates import wilson_interval

    lo, hi = wilson_interval(8, 10)  # the textbook example: 0.490-0.943
    assert lo == pytest.approx(0.4902, abs=1e-4) and hi == pytest.approx(0.9433, abs=1e-4)
    assert wilson_interval(0, 10)[0] == 0.0 and wilson_interval(10, 10)[1] == 1.0
    assert all(math.isnan(x) for x in wilson_interval(0, 0))
    with pytest.raises(ReproError):
        wilson_interval(11, 10)


def test_rates_count_the_variants_with_their_interval(tmp_path: Path) -> None:
    import csv

    (tmp_path / "claims.csv").write_text("paper,claim,status\nfake,1,reproduced\n")
    with open(tmp_path / "claim_clauses.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["paper", "claim", "clause", "holds"])
        w.writerow(["fake", "1", "the error stays under 1", "True"])
    path = run_sweep("fake.case", 16, seed=0, results_dir=tmp_path, papers=_papers(Runner()))
    rates = pd.read_csv(path.parent / "rates.csv")
    gains = np.array([v["gain"] for v in sample_variants(GainCfg, 16, seed=0)])
    k = int((2 * gains < BOUND).sum())
    claim = rates[rates["clause"].isna()].iloc[0]
    assert (claim["variants"], claim["held"]) == (16, k) and claim["canonical"] == "reproduced"
    assert claim["rate"] == pytest.approx(k / 16)
    assert claim["wilson_low"] < k / 16 < claim["wilson_high"]
    clause = rates[rates["clause"] == "the error stays under 1"].iloc[0]
    assert clause["held"] == k and clause["canonical"] == "holds"


def test_an_infinite_margin_is_drawn_at_the_edge_not_lost() -> None:
    from repro.plots.sweeps import _clip_infinite

    y, inf = _clip_infinite(np.array([0.0, 1.0, np.inf, -np.inf, np.nan]))
    assert inf.tolist() == [False, False, True, True, False]
    assert y[2] == pytest.approx(1.1) and y[3] == pytest.approx(-0.1) and np.isnan(y[4])
    y, _ = _clip_infinite(np.array([np.inf]))  # no finite value: still on the axes
    assert np.isfinite(y).all()


def test_sweep_figures_and_the_report_section_come_from_the_files(tmp_path: Path) -> None:
    from repro.plots.sweeps import sweep_figures
    from repro.runs.report import _robustness_section

    run_sweep("fake.case", 8, seed=0, results_dir=tmp_path, papers=_papers(Runner()))
    written = sweep_figures(tmp_path, tmp_path / "figures")
    assert [p.name for p in written] == ["sweep_case_claim1.png", "sweep_case_claim1.pdf"]
    text = "\n".join(_robustness_section(tmp_path, "fake", tmp_path))
    assert "**fake.case**: 8 variants" in text and "the error stays under 1" in text
    assert "No sweep yet" in "\n".join(_robustness_section(tmp_path, "other", tmp_path))


# ----------------------------------------------------------------- which unknown decides
def test_best_split_finds_the_known_threshold() -> None:
    from repro.runs.sweep_sensitivity import best_split

    x = np.array([0.9, 0.1, 0.5, 0.3, 0.7, 0.2])
    cut, side, acc = best_split(x, x < 0.4)
    assert cut == pytest.approx(0.4) and side == "< 0.4" and acc == 1.0
    cut, side, acc = best_split(x, x >= 0.6)  # the other orientation
    assert cut == pytest.approx(0.6) and side.startswith(">=") and acc == 1.0
    assert best_split(np.ones(4), np.array([1, 0, 1, 0], bool))[1] == "none"  # no cut exists
    assert best_split(x, np.ones(6, bool)) == (pytest.approx(np.nan, nan_ok=True), "none", 1.0)


def test_sensitivity_ranks_the_deciding_parameter_first(tmp_path: Path) -> None:
    """A known answer: the claim holds iff 2 gain < 1, a second swept value decides nothing.
    The gain ranks first with a tiny permutation p, the other does not decide it."""
    from repro.runs.sweep_sensitivity import write_sensitivity

    runner = Runner()
    papers = _papers(runner)
    exps = papers["fake"].experiments
    papers = {"fake": Paper(key="fake", experiments=(Experiment(
        name="case", paper="fake", description="two", config_cls=TwoCfg, run=runner),
        exps[1]), claims=papers["fake"].claims)}
    path = run_sweep("fake.case", 32, seed=4, results_dir=tmp_path, papers=papers)
    sens = pd.read_csv(write_sensitivity(path.parent, "case"), dtype={"claim": str})
    claim = sens[(sens["claim"] == "1") & sens["clause"].isna()].set_index("parameter")
    assert claim.loc["gain", "rank"] == 1 and claim.loc["gain", "split_accuracy"] == 1.0
    assert claim.loc["gain", "split_at"] == pytest.approx(0.5, abs=0.05)
    assert claim.loc["gain", "permutation_p"] < 0.01 and claim.loc["other", "permutation_p"] > 0.05
    assert claim.loc["gain", "spearman"] < -0.8  # holds at low gain
    assert (path.parent / "sensitivity.csv").is_file()  # run_sweep writes it too


def test_a_rendered_subsample_is_compared_with_its_exact_twins(tmp_path: Path) -> None:
    """The rendered-camera sweep goes to <exp>/render/; render_agreement.csv counts the twin
    variants (same values) whose verdicts agree: here all but those with gain in [0.4, 0.5),
    where the fake rendered camera's bias flips the verdict."""
    from repro.runs.report import _robustness_section

    papers = _papers(Runner())
    run_sweep("fake.case", 32, seed=6, results_dir=tmp_path, papers=papers)
    path = run_sweep("fake.case", 12, seed=6, results_dir=tmp_path, camera="render",
                     papers=papers)
    assert path == tmp_path / "sweeps" / "case" / "render" / "variants.csv"
    agreement = pd.read_csv(tmp_path / "sweeps" / "case" / "render_agreement.csv",
                            dtype={"claim": str})
    claim = agreement[agreement["clause"].isna()].iloc[0]
    gains = np.array([v["gain"] for v in sample_variants(GainCfg, 12, seed=6)])
    flips = int(((gains >= 0.4) & (gains < 0.5)).sum())
    assert claim["twins"] == 12 and claim["agree"] == 12 - flips and 0 < flips < 12
    assert claim["exact_held"] == int((gains < 0.5).sum())
    assert claim["render_held"] == int((gains < 0.4).sum())
    # the exact sweep's own table is untouched by the rendered one
    assert len(pd.read_csv(tmp_path / "sweeps" / "case" / "variants.csv")) == 32
    (tmp_path / "sweeps" / "case" / "variants.columns.json").write_text(json.dumps(
        {"experiment": "fake.case", "n": 32, "seed": 6, "camera": "exact"}))
    text = "\n".join(_robustness_section(tmp_path, "fake", tmp_path))
    assert f"{2 * 12 - 2 * flips} of 24 verdicts agree" in text


def test_bench_rates_a_committed_sweep_from_its_wall_times(tmp_path: Path) -> None:
    """make bench's committed-sweep row: variants x workers / summed wall time, per hour."""
    from repro.bench import sweep_rows

    d = tmp_path / "sweeps" / "case"
    d.mkdir(parents=True)
    pd.DataFrame({"variant": [0, 1], "run_status": ["completed"] * 2,
                  "wall_time_s": [10.0, 20.0]}).to_csv(d / "variants.csv", index=False)
    (d / "variants.columns.json").write_text(json.dumps({"experiment": "fake.case",
                                                          "workers": 2}))
    rows = sweep_rows(tmp_path, workers=())
    assert rows == [{"benchmark": "sweep.fake.case.variants_per_hour[committed]",
                     "median_s": pytest.approx(3600 * 2 * 2 / 30), "p95_s": pytest.approx(480),
                     "n": 2}]


def _check_each(runs: dict[str, RunFiles]) -> ClaimResult:
    clauses = [Clause(f"{name}: the error stays under 1", float(run.trace["err"].max()), "<",
                      BOUND, "-", "ours: a test bound") for name, run in sorted(runs.items())]
    return ClaimResult.from_clauses("per run", clauses)


def test_a_per_run_claim_is_judged_on_the_swept_run_alone(tmp_path: Path) -> None:
    base = _papers(Runner())["fake"]
    claims = (Claim("fake", "3", "each run's error under 1", "< 1", ("case", "other"),
                    _check_each, per_run=("case", "other")),)
    papers = {"fake": Paper(key="fake", experiments=base.experiments, claims=lambda: claims)}
    path = run_sweep("fake.case", 4, seed=0, results_dir=tmp_path, papers=papers)
    df = pd.read_csv(path)
    assert "claim3.c1.holds" in df.columns and "claim3.c2.holds" not in df.columns
    names = json.loads(next((path.parent / "variants").glob("*/" + VERDICTS_FILE)).read_text())
    assert names["verdicts"]["3"]["clauses"][0]["name"] == "case: the error stays under 1"
    with pytest.raises(ConfigError, match="per_run names"):
        Claim("fake", "4", "x", "-", ("case",), _check_each, per_run=("other",))


def test_a_verdict_the_same_everywhere_ranks_what_moves_its_margin(tmp_path: Path) -> None:
    from repro.runs.sweep_sensitivity import write_sensitivity

    x = np.linspace(0.0, 1.0, 9)
    pd.DataFrame({"variant": range(9), "run_status": ["completed"] * 9, "p.a": x,
                  "p.b": np.roll(x, 4), "claim1.status": ["reproduced"] * 9,
                  "claim1.c1.measured": 2 * x, "claim1.c1.margin": 0.5 + 2 * x,
                  "claim1.c1.holds": [True] * 9}).to_csv(tmp_path / "variants.csv",
                                                         index=False)
    sens = pd.read_csv(write_sensitivity(tmp_path, "case"), dtype={"claim": str})
    clause = sens[sens["clause"] == "clause 1"].set_index("parameter")
    assert clause.loc["a", "rank"] == 1 and clause.loc["a", "spearman"] == pytest.approx(1.0)
    assert (clause["holds_when"] == "every variant holds").all()
    assert abs(clause.loc["b", "spearman"]) < 1.0


def test_the_report_flags_a_sweep_whose_ranges_changed(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    from repro.runs.report import _ranges_changed

    monkeypatch.setattr(registry, "load_papers", lambda: _papers(Runner()))
    d = tmp_path / "sweep"
    d.mkdir()
    pd.DataFrame({"variant": [0, 1], "p.gain": [0.2, 0.8]}).to_csv(d / "variants.csv",
                                                                   index=False)
    assert _ranges_changed(d, "fake.case") == []  # inside today's 0.1-0.9
    pd.DataFrame({"variant": [0, 1], "p.gain": [0.05, 0.8], "p.old": [1, 2]}).to_csv(
        d / "variants.csv", index=False)
    text = " ".join(_ranges_changed(d, "fake.case"))
    assert "no longer declared: old" in text and "gain swept over [0.05, 0.8]" in text


def _refuse_high_gain(config: GainCfg) -> None:
    if config.gain > 0.7:
        raise ConfigError(f"gain {config.gain:.2f}: no scene of the paper's")


def test_a_variant_its_experiment_refuses_is_a_refused_row_not_a_judged_one(
        tmp_path: Path) -> None:
    runner = Runner()
    base = _papers(runner)["fake"]
    exp = Experiment(name="case", paper="fake", description="refuses", config_cls=GainCfg,
                     run=runner, check=_refuse_high_gain)
    papers = {"fake": Paper(key="fake", experiments=(exp, base.experiments[1]),
                            claims=base.claims)}
    path = run_sweep("fake.case", 16, seed=7, results_dir=tmp_path, papers=papers)
    df = pd.read_csv(path)
    gains = np.array([v["gain"] for v in sample_variants(GainCfg, 16, seed=7)])
    refused = df["run_status"] == "refused"
    assert list(refused) == list(gains > 0.7) and 0 < refused.sum() < 16
    assert df.loc[refused, "run_reason"].str.contains("no scene of the paper's").all()
    assert df.loc[refused, "claim1.status"].isna().all()
    assert len(runner.calls) == int((~refused).sum())  # a refused variant never runs
    rates = pd.read_csv(path.parent / "rates.csv", dtype={"claim": str})
    claim = rates[rates["clause"].isna()].iloc[0]
    assert claim["variants"] == int((~refused).sum()) and claim["refused"] == refused.sum()
    assert claim["failed_runs"] == 0
