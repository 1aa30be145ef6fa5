"""repro.runs.registry and repro.cli, against fake papers (never the real entry points)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types
from dataclasses import dataclass, replace
from importlib import metadata
from pathlib import Path
from typing import Any

import pytest
from runfiles import write_whole_run

from repro import cli
from repro.config import param
from repro.errors import ConfigError, ReproError, SolverError, UnknownChoiceError
from repro.runs import registry
from repro.runs.registry import Experiment, Paper, find_experiment, is_stale


@dataclass(frozen=True)
class FakeCfg:
    gain: float = param(0.4, unit="1/s", range=(0.0, 100.0), help="IBVS gain")
    solver: str = param("proxsuite", choices=("proxsuite", "osqp"))
    video: bool = param(False)


@dataclass(frozen=True)
class NoVideoCfg:
    steps: int = param(10, range=(1, 1000))


def run_folder_of(folder: Path) -> Path:
    """The run folder a run writing in ``folder`` is for: ``<parent>/<name>`` for its staging
    folder ``<parent>/.partial/<name>`` (repro.runs.staging), else ``folder``."""
    folder = Path(folder)
    if folder.parent.name == ".partial":
        return folder.parent.parent / folder.name
    return folder


class Runner:
    """A fake ``Experiment.run`` recording its calls and writing a completed manifest.

    ``calls``: (config, the run folder the run is for); ``wrote_in``: the folder it was given
    (its staging folder)."""

    def __init__(self, paper: str, status: str = "completed",
                 error: Exception | None = None) -> None:
        self.paper = paper
        self.calls: list[tuple[Any, Path]] = []
        self.wrote_in: list[Path] = []
        self.status = status
        self.error = error

    def __call__(self, config: Any, out_dir: Path) -> Path:
        self.calls.append((config, run_folder_of(out_dir)))
        self.wrote_in.append(out_dir)
        if self.error is not None:
            raise self.error
        # As the real run functions do: the experiment named after the folder.
        manifest = {
            "experiment": out_dir.name.split("__")[0],
            "paper": self.paper,
            "status": self.status,
            "config_hash": registry.compute_config_hash(config),
        }
        write_whole_run(out_dir, **manifest)
        return out_dir


@pytest.fixture
def runners() -> dict[str, Runner]:
    keys = ("fake.case1", "fake.case2", "other.case1", "other.case3")
    return {k: Runner(paper=k.split(".")[0]) for k in keys}


def _papers(runners: dict[str, Runner]) -> dict[str, Paper]:
    def exp(paper: str, name: str, cfg: type, slow: bool = False) -> Experiment:
        return Experiment(
            name=name,
            paper=paper,
            description=f"{paper} {name} description\nsecond line",
            config_cls=cfg,
            run=runners[f"{paper}.{name}"],
            slow=slow,
        )

    return {
        "fake": Paper(
            "fake", (exp("fake", "case1", FakeCfg), exp("fake", "case2", NoVideoCfg, slow=True))
        ),
        "other": Paper(
            "other", (exp("other", "case1", FakeCfg), exp("other", "case3", NoVideoCfg))
        ),
    }


@pytest.fixture
def papers(monkeypatch, runners) -> dict[str, Paper]:
    papers = _papers(runners)
    monkeypatch.setattr(registry, "load_papers", lambda: papers)
    return papers


# --------------------------------------------------------------------------- registry


def test_experiment_id(papers):
    assert papers["fake"].experiments[0].id == "fake.case1"


def test_find_experiment_full_and_bare(papers):
    assert find_experiment(papers, "fake.case1") is papers["fake"].experiments[0]
    assert find_experiment(papers, "case3") is papers["other"].experiments[1]
    assert find_experiment(papers, "case2").id == "fake.case2"


def test_find_experiment_unknown_lists_all_ids(papers):
    with pytest.raises(UnknownChoiceError) as info:
        find_experiment(papers, "nope")
    assert info.value.choices == ["fake.case1", "fake.case2", "other.case1", "other.case3"]
    assert "fake.case1, fake.case2, other.case1, other.case3" in str(info.value)
    with pytest.raises(UnknownChoiceError):
        find_experiment(papers, "fake.case3")  # a full id is never matched as a bare name


def test_find_experiment_ambiguous(papers):
    with pytest.raises(UnknownChoiceError) as info:
        find_experiment(papers, "case1")
    msg = str(info.value)
    assert "ambiguous" in msg and "fake.case1, other.case1" in msg
    assert "other.case3" in msg  # still lists every valid choice


def _entry_points(monkeypatch, **values: str) -> None:
    eps = [
        metadata.EntryPoint(name=name, value=value, group=registry.ENTRY_POINT_GROUP)
        for name, value in values.items()
    ]
    monkeypatch.setattr(registry, "_entry_points", lambda group: eps)


def test_load_papers_from_entry_points(monkeypatch, runners):
    module = types.ModuleType("fake_repro_papers")
    module.FAKE = _papers(runners)["fake"]
    module.OTHER = _papers(runners)["other"]
    monkeypatch.setitem(sys.modules, "fake_repro_papers", module)
    _entry_points(monkeypatch, other="fake_repro_papers:OTHER", fake="fake_repro_papers:FAKE")
    papers = registry.load_papers()
    assert list(papers) == ["fake", "other"]
    assert papers["fake"] is module.FAKE


def test_load_papers_broken_entry_point(monkeypatch):
    _entry_points(monkeypatch, broken="no_such_module_for_repro_tests:EXPERIMENTS")
    with pytest.raises(ReproError) as info:
        registry.load_papers()
    msg = str(info.value)
    assert "'broken'" in msg and "ModuleNotFoundError" in msg
    assert "no_such_module_for_repro_tests" in msg


def test_load_papers_rejects_wrong_object_and_key(monkeypatch, runners):
    module = types.ModuleType("fake_repro_papers")
    module.NOT_A_PAPER = 42
    module.FAKE = _papers(runners)["fake"]
    monkeypatch.setitem(sys.modules, "fake_repro_papers", module)
    _entry_points(monkeypatch, wrong="fake_repro_papers:NOT_A_PAPER")
    with pytest.raises(ReproError, match=r"'wrong'.*must be a .*Paper, got int"):
        registry.load_papers()
    _entry_points(monkeypatch, misnamed="fake_repro_papers:FAKE")
    with pytest.raises(ReproError, match=r"key 'fake'; expected 'misnamed'"):
        registry.load_papers()


def _write_manifest(results: Path, exp: Experiment, **fields: Any) -> None:
    out = results / exp.paper / exp.name
    write_whole_run(out, **fields)


def test_is_stale(tmp_path, papers):
    exp = papers["fake"].experiments[0]
    cfg = FakeCfg()
    stale, reason = is_stale(exp, tmp_path, cfg)
    assert stale and "no manifest" in reason

    good_hash = registry.compute_config_hash(cfg)
    _write_manifest(tmp_path, exp, status="crashed", config_hash=good_hash)
    stale, reason = is_stale(exp, tmp_path, cfg)
    assert stale and "crashed" in reason

    _write_manifest(tmp_path, exp, status="completed", config_hash=good_hash)
    assert is_stale(exp, tmp_path, cfg) == (
        False,
        f"fresh (completed, config hash {good_hash[:12]})",
    )

    stale, reason = is_stale(exp, tmp_path, replace(cfg, gain=0.5))
    assert stale and "config changed" in reason

    (tmp_path / "fake" / "case1" / "manifest.json").write_text("{not json")
    stale, reason = is_stale(exp, tmp_path, cfg)
    assert stale and "unreadable" in reason


def test_config_hash_is_stable_and_sensitive():
    assert registry.compute_config_hash(FakeCfg()) == registry.compute_config_hash(FakeCfg())
    assert registry.compute_config_hash(FakeCfg()) != registry.compute_config_hash(
        FakeCfg(gain=0.41)
    )


# --------------------------------------------------------------------------- cli: run


def test_run_unknown_experiment_exits_2_listing_choices(papers, capsys):
    assert cli.main(["run", "nope"]) == 2
    err = capsys.readouterr().err
    assert "unknown experiment 'nope'" in err
    assert "fake.case1, fake.case2, other.case1, other.case3" in err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_run_bad_override_exits_2_before_running(papers, runners, capsys, tmp_path):
    code = cli.main(["--results", str(tmp_path), "run", "fake.case1", "--set", "gain=-1"])
    assert code == 2
    assert runners["fake.case1"].calls == []
    err = capsys.readouterr().err
    assert "gain=-1.0" in err and "[0.0, 100.0]" in err
    assert not (tmp_path / "fake").exists()


@pytest.mark.parametrize(
    ("override", "needle"),
    [
        ("gian=1", "gain, solver, video"),
        ("solver=gurobi", "osqp, proxsuite"),
        ("gain=fast", "expected float"),
        ("gain", "malformed"),
    ],
)
def test_run_bad_overrides_are_reported(papers, runners, capsys, override, needle):
    assert cli.main(["run", "fake.case1", "--set", override]) == 2
    assert needle in capsys.readouterr().err
    assert runners["fake.case1"].calls == []


def test_run_ambiguous_name_exits_2(papers, capsys):
    assert cli.main(["run", "case1"]) == 2
    assert "ambiguous" in capsys.readouterr().err


def test_run_with_overrides_uses_hashed_dir(papers, runners, tmp_path, capsys):
    argv = ["--results", str(tmp_path), "run", "case3", "--set", "steps=7"]
    assert cli.main(argv) == 0
    [(config, out_dir)] = runners["other.case3"].calls
    assert config == NoVideoCfg(steps=7)
    assert out_dir.parent == tmp_path / "other"
    assert out_dir.name.startswith("case3__") and len(out_dir.name) == len("case3__") + 8
    assert not (tmp_path / "other" / "case3").exists()  # default traces untouched
    assert str(out_dir) in capsys.readouterr().out


def test_run_several_overrides(papers, runners, tmp_path):
    argv = ["run", "fake.case1", "--set", "gain=0.9", "--set", "solver=osqp",
            "--results", str(tmp_path)]
    assert cli.main(argv) == 0
    [(config, out_dir)] = runners["fake.case1"].calls
    assert config == FakeCfg(gain=0.9, solver="osqp")
    assert out_dir.parent == tmp_path / "fake"


def test_run_defaults_to_paper_name_dir(papers, runners, tmp_path):
    assert cli.main(["run", "fake.case1", "--results", str(tmp_path)]) == 0
    [(config, out_dir)] = runners["fake.case1"].calls
    assert config == FakeCfg()
    assert out_dir == tmp_path / "fake" / "case1"
    assert (out_dir / "manifest.json").is_file()
    # written aside, then swapped in: no staging folder is left
    assert runners["fake.case1"].wrote_in == [tmp_path / "fake" / ".partial" / "case1"]
    assert sorted(p.name for p in (tmp_path / "fake").iterdir()) == ["case1"]


def test_run_out_dir_option(papers, runners, tmp_path):
    out = tmp_path / "custom"
    assert cli.main(["run", "fake.case1", "--set", "gain=1", "--out", str(out)]) == 0
    assert runners["fake.case1"].calls[0][1] == out


def test_run_video(papers, runners, tmp_path, capsys):
    assert cli.main(["--results", str(tmp_path), "run", "fake.case1", "--video"]) == 0
    [(config, out_dir)] = runners["fake.case1"].calls
    assert config.video is True
    assert out_dir != tmp_path / "fake" / "case1"

    assert cli.main(["--results", str(tmp_path), "run", "other.case3", "--video"]) == 2
    assert runners["other.case3"].calls == []
    err = capsys.readouterr().err
    assert "--video" in err and "steps" in err


def test_run_repro_error_exits_2_other_errors_propagate(papers, runners, tmp_path, capsys):
    runners["fake.case1"].error = SolverError("QP infeasible at t=1.2 s")
    assert cli.main(["--results", str(tmp_path), "run", "fake.case1"]) == 2
    assert "QP infeasible" in capsys.readouterr().err
    runners["fake.case1"].error = RuntimeError("bug")
    with pytest.raises(RuntimeError, match="bug"):
        cli.main(["--results", str(tmp_path), "run", "fake.case1"])


def test_usage_errors_return_2(papers, capsys):
    assert cli.main([]) == 2
    assert cli.main(["frobnicate"]) == 2
    assert cli.main(["--help"]) == 0


# --------------------------------------------------------------------------- cli: list


def test_list(papers, capsys):
    assert cli.main(["list"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert len(lines) == 4
    assert lines[0].startswith("fake.case1") and "fake case1 description" in lines[0]
    assert "second line" not in out
    assert "(slow)" in lines[1]
    assert "gain" not in out


def test_list_verbose(papers, capsys):
    assert cli.main(["list", "-v"]) == 0
    out = capsys.readouterr().out
    assert "gain: float = 0.4" in out
    assert "IBVS gain [1/s]; range [0.0, 100.0]" in out
    assert "choices: proxsuite, osqp" in out
    assert "steps: int = 10" in out


def test_list_broken_entry_point_exits_2(monkeypatch, capsys):
    _entry_points(monkeypatch, broken="no_such_module_for_repro_tests:EXPERIMENTS")
    assert cli.main(["list"]) == 2
    assert "'broken'" in capsys.readouterr().err


# --------------------------------------------------------------------------- cli: results


def test_results_runs_stale_then_nothing(papers, runners, tmp_path, capsys):
    assert cli.main(["--results", str(tmp_path), "results", "-j", "1"]) == 0
    ran = {k for k, r in runners.items() if r.calls}
    assert ran == {"fake.case1", "other.case1", "other.case3"}  # fake.case2 is slow
    out = capsys.readouterr().out
    assert "ran    fake.case1" in out and "skip   fake.case2" in out
    assert runners["fake.case1"].calls[0] == (FakeCfg(), tmp_path / "fake" / "case1")

    assert cli.main(["--results", str(tmp_path), "results"]) == 0
    assert all(len(r.calls) <= 1 for r in runners.values())
    out = capsys.readouterr().out
    assert "fresh  fake.case1" in out and "0 ran, 3 fresh, 1 skipped" in out


def test_results_reruns_crashed_and_changed(papers, runners, tmp_path):
    exp = papers["other"].experiments[1]
    _write_manifest(
        tmp_path, exp, status="crashed", config_hash=registry.compute_config_hash(NoVideoCfg())
    )
    other = papers["other"].experiments[0]
    _write_manifest(
        tmp_path, other, status="completed", config_hash=registry.compute_config_hash(FakeCfg())
    )
    fake = papers["fake"].experiments[0]
    _write_manifest(tmp_path, fake, status="completed", config_hash="old")
    assert cli.main(["results", "--results", str(tmp_path), "-j", "1"]) == 0
    assert len(runners["other.case3"].calls) == 1
    assert len(runners["fake.case1"].calls) == 1
    assert runners["other.case1"].calls == []


def test_results_force_slow_and_paper(papers, runners, tmp_path, capsys):
    argv = ["--results", str(tmp_path), "results", "--paper", "fake", "--include-slow", "-j", "1"]
    assert cli.main(argv) == 0
    assert cli.main([*argv, "--force"]) == 0
    assert len(runners["fake.case1"].calls) == 2
    assert len(runners["fake.case2"].calls) == 2
    assert runners["other.case1"].calls == []

    assert cli.main(["results", "--paper", "nope"]) == 2
    assert "unknown paper 'nope'; valid choices: fake, other" in capsys.readouterr().err


# --------------------------------------------------------------------------- cli: figures, report


def test_figures_and_claims(monkeypatch, papers, tmp_path, capsys):
    figure_calls: list[tuple[Path, Path]] = []

    def figures(results_dir: Path, figures_dir: Path) -> list[Path]:
        figure_calls.append((results_dir, figures_dir))
        return [figures_dir / "fig3.png"]

    papers["fake"] = replace(papers["fake"], figures=figures, claims=lambda: ["claim-a"])
    papers["other"] = replace(papers["other"], claims=lambda: ["claim-b"])

    seen: dict[str, Any] = {}
    fake_claims = types.ModuleType("repro.runs.claims")

    def evaluate_claims(claims, results_dir, clauses_out=None):
        seen["evaluate"] = (list(claims), results_dir)
        clauses_out.append({"paper": "fake"})
        return "TABLE"

    def write_claims_csv(df, path):
        seen["write"] = (df, path)

    def write_clauses_csv(rows, papers, path):
        seen["clauses"] = (rows, papers, path)

    fake_claims.evaluate_claims = evaluate_claims
    fake_claims.write_claims_csv = write_claims_csv
    fake_claims.write_clauses_csv = write_clauses_csv
    monkeypatch.setitem(sys.modules, "repro.runs.claims", fake_claims)

    res, fig = tmp_path / "res", tmp_path / "fig"
    assert cli.main(["--results", str(res), "--figures", str(fig), "figures"]) == 2
    assert "--results" in capsys.readouterr().err and not res.exists()  # nothing written
    res.mkdir()
    assert cli.main(["--results", str(res), "--figures", str(fig), "figures"]) == 0
    assert figure_calls == [(res, fig)]
    assert seen["evaluate"] == (["claim-a", "claim-b"], res)
    assert seen["write"] == ("TABLE", res / "claims.csv")
    assert seen["clauses"] == ([{"paper": "fake"}], ["fake", "other"], res / "claim_clauses.csv")
    out = capsys.readouterr().out
    assert "fig3.png" in out and "other: no figures" in out

    seen.clear()
    assert cli.main(["figures", "--paper", "other", "--results", str(res)]) == 0
    assert seen["evaluate"] == (["claim-b"], res)
    assert len(figure_calls) == 1


def test_report(monkeypatch, tmp_path):
    seen: dict[str, Any] = {}
    fake_report = types.ModuleType("repro.runs.report")

    def render_report(results_dir, figures_dir, source_paths, output, notes=None, ranges=None):
        seen["args"] = (results_dir, figures_dir, list(source_paths), output)
        seen["notes"], seen["ranges"] = notes, ranges
        return output

    fake_report.render_report = render_report
    monkeypatch.setitem(sys.modules, "repro.runs.report", fake_report)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["report", "--results", "r", "--figures", "f"]) == 2  # no results folder
    (tmp_path / "r").mkdir()
    assert cli.main(["report", "--results", "r", "--figures", "f", "--output", "r"]) == 2
    assert not list((tmp_path / "r").iterdir())  # no results.tmp left behind
    assert cli.main(["report", "--results", "r", "--figures", "f"]) == 0
    results_dir, figures_dir, sources, output = seen["args"]
    assert (results_dir, figures_dir, output) == (Path("r"), Path("f"), Path("REPORT.md"))
    assert Path(cli.__file__).resolve() in sources
    assert all(p.suffix == ".py" for p in sources)
    # every registered paper may carry a discussion file next to its experiments
    assert all(path.name == "discussion.md" for path in seen["notes"].values())
    # and its pre-registered sweep ranges (issue 19)
    assert isinstance(seen["ranges"], dict)


def test_python_dash_m_repro_help():
    proc = subprocess.run(
        [sys.executable, "-m", "repro", "--help"], capture_output=True, text=True, check=False
    )
    assert proc.returncode == 0
    assert "results" in proc.stdout and "figures" in proc.stdout


# --------------------------------------------------------------------------- issue 7: inputs


def test_set_takes_one_pair_and_options_may_precede_the_id(papers, runners, tmp_path):
    argv = ["--results", str(tmp_path), "run", "--set", "gain=0.9", "fake.case1",
            "--set", "solver=osqp"]
    assert cli.main(argv) == 0
    [(config, _)] = runners["fake.case1"].calls
    assert config == FakeCfg(gain=0.9, solver="osqp")


def test_set_with_two_pairs_is_a_usage_error(papers, runners, capsys):
    assert cli.main(["run", "fake.case1", "--set", "gain=0.9", "solver=osqp"]) == 2
    assert "unrecognized arguments: solver=osqp" in capsys.readouterr().err
    assert runners["fake.case1"].calls == []


def _checked(papers: dict[str, Paper], message: str) -> list[Any]:
    """Give fake.case1 a ``check`` that refuses every config; return the configs it saw."""
    seen: list[Any] = []

    def check(config: Any) -> None:
        seen.append(config)
        raise ConfigError(message)

    exp = replace(papers["fake"].experiments[0], check=check)
    papers["fake"] = replace(papers["fake"], experiments=(exp, papers["fake"].experiments[1]))
    return seen


def test_run_calls_the_experiment_check_before_creating_any_folder(papers, runners, tmp_path,
                                                                    capsys):
    seen = _checked(papers, "q0_deg needs 7 joint angles [deg], got 2")
    out = tmp_path / "out"
    for argv in (["--results", str(tmp_path), "run", "fake.case1", "--set", "gain=2"],
                 ["run", "fake.case1", "--out", str(out)]):
        assert cli.main(argv) == 2
        assert "q0_deg needs 7 joint angles" in capsys.readouterr().err
    assert [c.gain for c in seen] == [2.0, 0.4]
    assert runners["fake.case1"].calls == []
    assert list(tmp_path.iterdir()) == []  # neither <results>/fake nor --out was created


def test_results_checks_every_config_before_running_any(papers, runners, tmp_path, capsys):
    _checked(papers, "bad default")
    assert cli.main(["--results", str(tmp_path), "results"]) == 2
    assert "bad default" in capsys.readouterr().err
    assert all(not r.calls for r in runners.values())
    assert list(tmp_path.iterdir()) == []


def test_registry_refuses_a_config_with_an_unbounded_numeric_field(monkeypatch, runners):
    @dataclass(frozen=True)
    class Unbounded:
        limit: float | None = param(None)

    module = types.ModuleType("fake_repro_papers")
    exp = replace(_papers(runners)["fake"].experiments[0], config_cls=Unbounded)
    module.FAKE = Paper("fake", (exp,))
    monkeypatch.setitem(sys.modules, "fake_repro_papers", module)
    _entry_points(monkeypatch, fake="fake_repro_papers:FAKE")
    with pytest.raises(ReproError, match=r"'case1'.*Unbounded.limit is numeric.*no range"):
        registry.load_papers()


def test_out_manifest_names_the_registered_experiment(papers, runners, tmp_path):
    out = tmp_path / "my_folder__v2"
    assert cli.main(["run", "fake.case1", "--out", str(out)]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["experiment"] == "case1"  # not "my_folder"


def test_run_passes_the_experiment_name_to_a_run_that_accepts_it(papers, tmp_path):
    seen: dict[str, Any] = {}

    def run(config: Any, out_dir: Path, *, experiment: str | None = None) -> Path:
        seen["experiment"] = experiment
        return out_dir

    exp = replace(papers["other"].experiments[1], run=run)
    papers["other"] = replace(papers["other"], experiments=(papers["other"].experiments[0], exp))
    assert cli.main(["run", "other.case3", "--out", str(tmp_path / "x")]) == 0
    assert seen == {"experiment": "case3"}


def test_out_refuses_a_default_run_folder_unless_forced(papers, runners, tmp_path, capsys):
    results = tmp_path / "results"
    assert cli.main(["--results", str(results), "run", "fake.case1"]) == 0
    default = results / "fake" / "case1"
    committed = (default / "manifest.json").read_text()

    # another config into the default folder of the same experiment
    argv = ["--results", str(results), "run", "fake.case1", "--set", "gain=2", "--out",
            str(default)]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "is the default folder of fake.case1" in err and "--force" in err
    # another experiment into it
    assert cli.main(["--results", str(results), "run", "other.case1", "--out", str(default)]) == 2
    assert "is the default folder of fake.case1" in capsys.readouterr().err
    assert (default / "manifest.json").read_text() == committed
    assert len(runners["fake.case1"].calls) == 1 and runners["other.case1"].calls == []

    # a folder holding a run of another config (not a registered folder)
    elsewhere = tmp_path / "mine"
    assert cli.main(["run", "fake.case1", "--out", str(elsewhere)]) == 0
    assert cli.main(["run", "fake.case1", "--set", "gain=3", "--out", str(elsewhere)]) == 2
    assert "holds a run of fake.case1 (config" in capsys.readouterr().err
    # the same config again, or the default config into its own default folder: fine
    assert cli.main(["run", "fake.case1", "--out", str(elsewhere)]) == 0
    assert cli.main(["--results", str(results), "run", "fake.case1", "--out", str(default)]) == 0

    assert cli.main([*argv, "--force"]) == 0
    assert runners["fake.case1"].calls[-1] == (FakeCfg(gain=2.0), default)


# --------------------------------------------------------------------------- issue 7: dead runs


def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    return int(proc.stdout)


def _running_manifest(run_dir: Path, pid: int, n_lines: int, **fields: Any) -> None:
    import socket

    run_dir.mkdir(parents=True, exist_ok=True)
    manifest = {"experiment": run_dir.name.split("__")[0], "paper": run_dir.parent.name,
                "status": "running", "n_rows": 0, "pid": pid,
                "hostname": socket.gethostname(), "config_hash": "x", **fields}
    (run_dir / "manifest.json").write_text(json.dumps(manifest))
    (run_dir / "trace.csv").write_text("t\n" + "".join(f"{k}\n" for k in range(n_lines)))


def test_results_marks_dead_override_runs_interrupted_without_rerunning(papers, runners,
                                                                       tmp_path, capsys):
    override = tmp_path / "fake" / "case1__1234abcd"
    _running_manifest(override, _dead_pid(), 7)
    live = tmp_path / "other" / "case1__live"
    _running_manifest(live, os.getpid(), 3)
    assert cli.main(["--results", str(tmp_path), "results"]) == 0
    out = capsys.readouterr().out
    assert f"interrupted  {override}  (process gone: pid" in out and "7 rows" in out
    assert "1 marked interrupted" in out
    manifest = json.loads((override / "manifest.json").read_text())
    assert (manifest["status"], manifest["n_rows"]) == ("interrupted", 7)
    assert json.loads((live / "manifest.json").read_text())["status"] == "running"
    ran = [out_dir for r in runners.values() for _, out_dir in r.calls]
    assert override not in ran and all("__" not in d.name for d in ran)


def test_results_reruns_a_dead_default_run_but_not_a_live_one(papers, runners, tmp_path, capsys):
    _running_manifest(tmp_path / "fake" / "case1", _dead_pid(), 2)
    _running_manifest(tmp_path / "other" / "case3", os.getpid(), 2)
    assert cli.main(["--results", str(tmp_path), "results"]) == 0
    out = capsys.readouterr().out
    assert "ran    fake.case1  (last run status is 'interrupted'" in out
    assert f"busy   other.case3  (running as pid {os.getpid()}" in out
    assert runners["other.case3"].calls == []


@pytest.mark.parametrize("jobs", ["1_0", "+2", "0x2", "\u0662", "2.0", "0", "1025"])
def test_jobs_takes_a_plain_whole_number(tmp_path: Path, jobs: str, capsys) -> None:
    """``-j 1_0`` would be int()'s 10: refused before anything is written, like 0 or 1025."""
    assert cli.main(["--results", str(tmp_path / "r"), "results", "-j", jobs]) == 2
    assert "-j/--jobs" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


# --------------------------------------------------------------------------- issue 16: paths


def _snapshot(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.mark.parametrize("argv, message", [
    (["run", "fake.case1", "--out", "README.md"], "is a file, not a folder"),
    (["run", "fake.case1", "--out", "README.md/sub"], "README.md is a file"),
    (["run", "fake.case1", "--out", ""], "an empty path"),
    (["run", "fake.case1", "--out", "results"], "holds runs, not a run folder"),
    (["run", "fake.case1", "--out", "results/fake"], "holds runs, not a run folder"),
    (["run", "fake.case1", "--out", "results/fake/case2/sub"], "inside the run folder"),
    (["run", "fake.case1", "--out", "runs"], "holds other runs"),
    (["--results", "README.md", "results"], "is a file, not a folder"),
    (["--results", "README.md", "run", "fake.case1"], "is a file, not a folder"),
    (["--figures", "README.md", "figures"], "is a file, not a folder"),
    (["--results", "nonexistent", "figures"], "does not exist"),
    (["report", "--output", "results"], "is a folder"),
    (["--results", "", "results"], "an empty path"),
])
def test_bad_paths_are_refused_in_one_line_before_anything_is_written(
        papers, runners, tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "README.md").write_text("a file\n")
    write_whole_run(tmp_path / "results" / "fake" / "case2", status="completed",
                    experiment="case2", paper="fake", config_hash="x")
    write_whole_run(tmp_path / "runs" / "a", status="completed", config_hash="x")
    before = _snapshot(tmp_path)
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert len(err.strip().splitlines()) == 1 or "usage:" in err, err  # argparse: usage too
    assert "Traceback" not in err
    assert _snapshot(tmp_path) == before
    assert all(not r.calls for r in runners.values())


def test_an_unwritable_out_is_one_line(papers, runners, tmp_path, monkeypatch, capsys):
    def refuse(self, *a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(Path, "mkdir", refuse)
    assert cli.main(["run", "fake.case1", "--out", str(tmp_path / "x" / "y")]) == 2
    err = capsys.readouterr().err
    assert "cannot be created: Permission denied" in err and "Traceback" not in err
    assert runners["fake.case1"].calls == []


def test_run_refuses_a_folder_a_live_run_is_writing(papers, runners, tmp_path, capsys):
    import socket

    out = tmp_path / "live"
    write_whole_run(out, status="running", pid=os.getpid(), hostname=socket.gethostname(),
                    experiment="case1", paper="fake",
                    config_hash=registry.compute_config_hash(FakeCfg()))
    assert cli.main(["run", "fake.case1", "--out", str(out), "--force"]) == 2
    assert "being written by another run" in capsys.readouterr().err
    assert runners["fake.case1"].calls == []


def test_run_refuses_a_folder_another_process_has_locked(papers, runners, tmp_path, capsys):
    """Two `repro run`s of one config into one folder: the second is refused in one line
    (an flock on the folder, race-free; released when the holder ends or dies)."""
    from repro.runs.staging import staged

    out = tmp_path / "run"
    with staged(out):  # what a live run of that folder holds: its staging folder
        assert cli.main(["run", "fake.case1", "--out", str(out), "--force"]) == 2
        assert "being written by another repro process" in capsys.readouterr().err
    assert cli.main(["run", "fake.case1", "--out", str(out), "--force"]) == 0
