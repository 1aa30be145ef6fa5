"""Inputs of the real experiments (issue 7): every numeric field has a finite range, bad
overrides are refused by name before any folder exists, ``--set`` and ``--out`` behave."""

from __future__ import annotations

import dataclasses
import json
import math
import re

import pytest

from repro import cli
from repro.config import config_keys
from repro.runs import registry


@pytest.fixture(scope="module")
def experiments() -> list[registry.Experiment]:
    return registry.all_experiments(registry.load_papers())


def _numeric(value: object) -> bool:
    if isinstance(value, tuple | list):
        return any(_numeric(v) for v in value)
    return isinstance(value, int | float) and not isinstance(value, bool)


def test_every_numeric_field_of_every_config_has_a_finite_range(experiments):
    assert {e.paper for e in experiments} >= {"thomas2024", "chan2011"}
    checked = 0
    for exp in experiments:
        config = exp.config_cls()
        for f in dataclasses.fields(config):
            if not _numeric(getattr(config, f.name)):
                continue
            low, high = f.metadata.get("range") or (None, None)
            assert low is not None and high is not None, f"{exp.id}: {f.name} has no range"
            assert math.isfinite(low) and math.isfinite(high), f"{exp.id}: {f.name}"
            checked += 1
    assert checked > 50


def test_tuple_fields_have_element_ranges_and_choices(experiments):
    case1 = next(e for e in experiments if e.id == "thomas2024.case1")
    meta = {f.name: f.metadata for f in dataclasses.fields(case1.config_cls)}
    assert meta["thresholds"]["range"] == (0.005, 0.5)
    assert meta["ring_gains"]["range"] == (0.0, 100.0) and meta["ring_gains"]["low_open"]
    assert meta["ring_models"]["choices"] == ("coarse", "beta1", "exact")
    assert meta["q0_deg"]["range"] == (-360.0, 360.0)


REJECTED = [
    ("thomas2024.case1", "mu=inf", "inf is not allowed for mu; allowed: [0.0, 10.0]"),
    ("thomas2024.case1", "mu=nan", "NaN is not allowed for mu"),
    ("thomas2024.case1", "lambda_4p=inf", "inf is not allowed for lambda_4p"),
    ("thomas2024.case1", "lambda_4p=0", "lambda_4p=0.0 is out of range; allowed: (0.0, 100.0]"),
    ("thomas2024.case1", "thresholds=-0.04,-0.08",
     "thresholds[0]=-0.04 is out of range; allowed: [0.005, 0.5]"),
    ("thomas2024.case1", "thresholds=0.04,nan", "NaN is not allowed for thresholds[1]"),
    ("thomas2024.case2", "ring_gains=1,-1",
     "ring_gains[1]=-1.0 is out of range; allowed: (0.0, 100.0]"),
    ("thomas2024.case1", "ring_models=foo",
     "unknown ring_models[0] value 'foo'; valid choices: beta1, coarse, exact"),
    ("thomas2024.case1", "q0_deg=0,0", "q0_deg needs 7 joint angles [deg], got 2"),
    ("thomas2024.case1", "q0_deg=1e9,0,0,-90,0,100,45",
     "q0_deg[0]=1000000000.0 is out of range; allowed: [-360.0, 360.0]"),
    ("thomas2024.case1", "q0_deg=0,0,0,0,0,100,45", "outside the Panda's joint limits"),
    ("thomas2024.case1", "qp_max_iter=inf", "inf is not allowed for qp_max_iter"),
    ("thomas2024.case3", "duration=-inf", "-inf is not allowed for duration"),
    ("chan2011.simulation", "Q_weight=0", "Q_weight=0.0 is out of range; allowed: (0.0, 1000.0]"),
    ("chan2011.simulation", "stop_px=inf", "inf is not allowed for stop_px"),
    ("chan2011.simulation", "dt=0.0015", "not a whole number of physics steps"),
    ("chan2011.dcc_audit", "seed=-1", "seed=-1 is out of range; allowed: [0, 4294967295]"),
]


@pytest.mark.parametrize(("exp_id", "override", "message"), REJECTED,
                         ids=[f"{e}:{o}" for e, o, _ in REJECTED])
def test_rejected_input_exits_2_and_creates_no_folder(exp_id, override, message, tmp_path,
                                                     capsys):
    out = tmp_path / "out"
    for extra in ([], ["--out", str(out)]):
        argv = ["--results", str(tmp_path), "run", exp_id, "--set", override, *extra]
        assert cli.main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("repro: error: ") and message in err, err
        assert "cannot parse" not in err and "Traceback" not in err
        assert list(tmp_path.iterdir()) == [], f"{argv} left {list(tmp_path.rglob('*'))}"


def test_set_may_come_before_the_id_and_out_keeps_the_experiment_name(tmp_path, capsys):
    out = tmp_path / "my_try"
    argv = ["--results", str(tmp_path / "results"), "run", "--set", "duration=0.2",
            "--set", "camera_mode=exact", "thomas2024.case1", "--out", str(out)]
    assert cli.main(argv) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "completed" and manifest["n_rows"] > 0
    assert manifest["experiment"] == "case1" and manifest["paper"] == "thomas2024"
    assert manifest["config"]["duration"] == 0.2
    assert str(out) in capsys.readouterr().out


def test_run_help_examples_are_real_keys(experiments, capsys):
    assert cli.main(["run", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    keys = set(re.findall(r"--set (\w[\w.]*)=", text)) - {"KEY"}
    assert keys, text
    case1 = next(e for e in experiments if e.id == "thomas2024.case1")
    assert keys <= set(config_keys(case1.config_cls))
    assert "camera.fu" not in text


def test_out_into_a_committed_default_folder_is_refused(tmp_path, capsys):
    default = tmp_path / "thomas2024" / "case1"
    default.mkdir(parents=True)
    committed = '{"status": "completed", "experiment": "case1", "paper": "thomas2024"}'
    (default / "manifest.json").write_text(committed)
    argv = ["--results", str(tmp_path), "run", "thomas2024.case1", "--set", "duration=3",
            "--out", str(default)]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert f"--out {default} is the default folder of thomas2024.case1" in err
    assert "add --force" in err
    assert (default / "manifest.json").read_text() == committed
    assert sorted(p.name for p in default.iterdir()) == ["manifest.json"]


def test_out_into_a_folder_of_another_run_is_refused(tmp_path, capsys):
    other = tmp_path / "elsewhere"
    other.mkdir()
    (other / "manifest.json").write_text(json.dumps(
        {"experiment": "case2", "paper": "thomas2024", "config_hash": "0123456789abcdef"}))
    argv = ["--results", str(tmp_path / "results"), "run", "thomas2024.case1", "--out",
            str(other)]
    assert cli.main(argv) == 2
    assert "holds a run of thomas2024.case2 (config 01234567)" in capsys.readouterr().err
