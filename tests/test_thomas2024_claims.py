"""thomas2024 claim checks on synthetic traces with known answers."""

from __future__ import annotations

import numpy as np
import pandas as pd

from experiments.thomas2024 import claims as cl
from repro.runs.trace import RunFiles


def _run(df: pd.DataFrame, events: list[str] | None = None) -> RunFiles:
    ev = pd.DataFrame({"t": [0.0] * len(events or []), "step": 0, "kind": events or [],
                       "detail": ""})
    return RunFiles(trace=df, events=ev, manifest={"summary": {}}, scene={})


def _base(n: int = 60) -> pd.DataFrame:
    t = np.arange(n) / 30.0
    data: dict[str, np.ndarray] = {"t": t, "dist_min": np.full(n, 0.05),
                                   "dist_a": np.full(n, 0.05), "grad_L0": np.full(n, 0.5)}
    for r in (1, 2):
        for i in range(1, 19):
            data[f"r{r}_cbf{i}"] = np.full(n, 0.5)
            data[f"r{r}_kappa{i}"] = np.zeros(n)
    for i in range(1, 5):
        data[f"e{i}_u"] = np.linspace(100, 0.1, n)
        data[f"e{i}_v"] = np.linspace(-100, -0.1, n)
    for i in range(1, 8):
        data[f"u{i}"] = np.linspace(0.5, 0.0, n)
    return pd.DataFrame(data)


def test_claim2_needs_contact() -> None:
    df = _base()
    assert cl.check_2({"case1_no_proximity": _run(df)}).status == "not_reproduced"
    df.loc[30:, "dist_min"] = -0.001
    df.loc[30:, "dist_a"] = -0.001
    res = cl.check_2({"case1_no_proximity": _run(df)})
    assert res.status == "reproduced" and "'a' at 1.00 s" in res.measured


def test_claim8_kappa_zero() -> None:
    df = _base()
    assert cl.check_8({"case1": _run(df)}).status == "reproduced"
    df.loc[len(df) - 1, "r1_kappa3"] = 0.05
    res = cl.check_8({"case1": _run(df)})
    assert res.status == "not_reproduced" and "not met" in res.measured


def test_groups_are_adjacent_and_cyclic() -> None:
    contacts = [(1.0, 17), (1.1, 18), (1.2, 1), (3.0, 9), (3.5, 10)]
    assert cl._groups(contacts) == [(1.0, [17, 18, 1]), (3.0, [9, 10])]


def test_claim5_oscillation_metric_orders_runs() -> None:
    smooth, osc = _base(300), _base(300)
    t = osc["t"].to_numpy()
    for i in range(1, 8):
        osc[f"u{i}"] = 0.1 * np.sin(2 * np.pi * 4.0 * t)  # 4 Hz chatter
    res = cl.check_5({"case2": _run(smooth), "case2_coarse": _run(osc)})
    assert res.status == "reproduced"
    res = cl.check_5({"case2": _run(osc), "case2_coarse": _run(smooth)})
    assert res.status == "not_reproduced"
