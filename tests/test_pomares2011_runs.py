"""Short runs of pomares2011 experiment 1 checked against a committed reference trace, the
Lyapunov function (10) on an undisturbed run, and the experiment not built yet."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from experiments.pomares2011.config import Exp1Config, Pomares2011Config
from experiments.pomares2011.run import run
from repro.errors import ConfigError
from repro.runs.trace import load_run

REF = Path(__file__).parent / "reference" / "pomares2011" / "exp1.csv"
TIMING = ("ctrl_s", "camera_render_s")


def short_config(**kw: object) -> Pomares2011Config:
    fields: dict[str, object] = {"duration": 0.5, "camera_mode": "exact", **kw}
    return dataclasses.replace(Exp1Config(), **fields)


def make_reference(tmp: Path) -> pd.DataFrame:
    df = load_run(run(short_config(), tmp / "exp1")).trace
    return df.drop(columns=[c for c in TIMING if c in df.columns])


def test_short_run_matches_reference(tmp_path: Path) -> None:
    got = make_reference(tmp_path)
    ref = pd.read_csv(REF)
    assert len(got) == len(ref) == 501
    compared = [c for c in ref.columns if ref[c].dtype.kind == "f"]
    assert len(compared) > 60
    for c in compared:
        tol = 1e-3 if c.startswith(("s", "e_", "su")) else 1e-6
        np.testing.assert_allclose(got[c].to_numpy(float), ref[c].to_numpy(float), atol=tol,
                                   rtol=1e-6, err_msg=c)


def test_lyapunov_function_is_non_increasing_with_the_base_still(tmp_path: Path) -> None:
    """pomares2011 claim 2 (eq. 15): with the PA-10 (nearly) still and a frame every step,
    V (10) of the mini-robot's loop does not increase."""
    cfg = short_config(duration=1.0, rvc_gain=0.01, camera_period=1)
    df = load_run(run(cfg, tmp_path / "still")).trace
    V = df["V"].to_numpy(float)
    assert V[-1] < 0.5 * V[0]
    assert np.max(np.diff(V)) <= 1e-3 * V[0], np.max(np.diff(V))
    assert df["e_s_px"].iloc[-1] < df["e_s_px"].iloc[0]


def test_the_rvc_drives_the_arm_towards_s_u_star(tmp_path: Path) -> None:
    df = load_run(run(short_config(duration=2.0), tmp_path / "rvc")).trace
    e = df["e_u_px"].to_numpy(float)
    # law (18) with lambda = 0.3/s: exponential decay, ~exp(-0.3 * 2) = 0.55 of the start
    assert 0.45 < e[-1] / e[0] < 0.7
    assert (df["vvs_pos_err_m"] < 1e-3).all()  # the VVS pose is right (exact camera)


def test_experiment_2_is_refused_until_built(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not built yet"):
        run(dataclasses.replace(Exp1Config(), experiment="exp2"), tmp_path / "exp2")
    assert not (tmp_path / "exp2").exists()
