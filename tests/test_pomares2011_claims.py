"""pomares2011 claim checks on synthetic traces with known answers.

Every check gets runs that reproduce the claim and, for each of its clauses, a variant that
breaks only that clause: a check replaced by a constant, or a clause dropped, fails here.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd
import pytest

from experiments.pomares2011 import claims as cl
from repro.runs.trace import RunFiles

N = 2501  # 25 s at 100 Hz rows
T = np.arange(N) * 0.01




def _fails(res) -> bool:  # type: ignore[no-untyped-def]
    """A failing claim: partly reproduced when some clause still holds, else not."""
    failing = [c for c in res.clauses if not c.holds]
    want = "partly_reproduced" if 0 < len(failing) < len(res.clauses) else "not_reproduced"
    return bool(failing) and res.status == want

def _alone(res, key: str, *also: str) -> None:  # type: ignore[no-untyped-def]
    """Issue 18: exactly one clause fails, the one named by ``key`` (or exactly those named,
    when the others cannot be measured without it)."""
    failing = [c.name for c in res.clauses if not c.holds]
    want = (key, *also)
    assert len(failing) == len(want) and all(any(w in f for f in failing) for w in want), \
        failing


def _run(df: pd.DataFrame, mins: dict[str, float] | None = None) -> RunFiles:
    ev = pd.DataFrame([], columns=["t", "step", "kind", "detail"])
    summary = {"stop_reason": "duration reached",
               "min_over_all_steps": {k: {"min_m": v, "t_s": 11.0}
                                      for k, v in (mins or {}).items()}}
    return RunFiles(trace=df, events=ev, manifest={"summary": summary,
                                                   "config": {"duration": 25.0}},
                    scene={})


def _exp1(**kw: object) -> pd.DataFrame:
    """s* reached at 5 s while the arm moves (stops at 19 s), V decaying once still,
    the VVS converged."""
    e_s = np.where(T < 5.0, 90.0 * np.exp(-T), 1.0)
    e_u = 281.0 * np.exp(-0.3 * T)
    arm = T >= 19.0
    qd = np.where(arm, 0.0, 0.01)
    V = 2e-3 * np.exp(-0.2 * T)
    data: dict[str, object] = {
        "t": T, "e_s_px": e_s, "e_u_px": e_u, "arm_reached": arm, "V": V, "V_true": V,
        "vvs_residual_px": np.full(N, 0.2), "vvs_pos_err_m": np.full(N, 5e-4),
        "vvs_converged": np.ones(N, bool)}
    for i in range(1, 7):
        data[f"pa10_qd{i}"] = qd
    data.update(kw)
    return pd.DataFrame(data)


def _exp2(active_span: tuple[float, float] = (9.7, 14.6), **kw: object) -> pd.DataFrame:
    df = _exp1()
    act = (T >= active_span[0]) & (T < active_span[1])
    df["secondary_active"] = act
    df["e_f2y_px"] = np.where(act, 0.5, 8.0)
    df["dist_m"] = np.where(act, 0.2, 0.5)
    for a in "xyz":
        df[f"camera_{a}"] = np.where(act, 0.05, 0.0)
    for k, v in kw.items():
        df[k] = v
    return df


def _base() -> pd.DataFrame:
    df = _exp2(active_span=(0.0, 0.0))
    for a in "xyz":
        df[f"camera_{a}"] = 0.0
    return df


def _cold() -> pd.DataFrame:
    """Cold VVS starts (2 cm / 10 deg) that all converge."""
    return pd.DataFrame({"start": range(4), "frame": [0, 0, 1, 1], "offset_m": 0.02,
                         "offset_deg": 10.0, "residual_px": 0.05, "pos_err_m": 3e-4,
                         "to_warm_m": 1e-5})


def _runs(exp1: pd.DataFrame | None = None, exp2: pd.DataFrame | None = None,
          d_mini: float = 0.06, d_arm: float = 0.3, d_base: float = 0.03,
          d_hand: float = 0.25) -> dict[str, RunFiles]:
    return {"vvs_cold": _run(_cold()), "exp1": _run(_exp1() if exp1 is None else exp1),
            "exp2": _run(_exp2() if exp2 is None else exp2,
                         {"mini_dist_human_hand_r": d_mini, "mini_dist_table": 0.01,
                          "pa10_dist_human_torso": d_arm, "bh8_dist_human_hand_l": d_hand}),
            "exp2_no_secondary": _run(_base(), {"mini_dist_human_hand_r": d_base})}


CHECKS: dict[str, Callable[[dict[str, RunFiles]], object]] = {
    "1": cl.check_1, "2": cl.check_2, "3": cl.check_3, "4": cl.check_4}


@pytest.mark.parametrize("claim", sorted(CHECKS))
def test_every_claim_reproduces_on_a_trace_that_does_what_it_says(claim: str) -> None:
    res = CHECKS[claim](_runs())
    assert res.status == "reproduced", res.measured  # type: ignore[attr-defined]


def _late_reach() -> pd.DataFrame:
    e_s = np.where(T < 20.0, 18.0, 1.0)  # s* only once the arm has stopped (19 s)
    return _exp1(e_s_px=e_s)


def _wander() -> pd.DataFrame:
    e_s = np.where(T < 5.0, 90.0 * np.exp(-T), 1.0)
    e_s[(T > 8) & (T < 9)] = 6.0  # leaves s* while the arm still moves
    return _exp1(e_s_px=e_s)


@pytest.mark.parametrize("runs, clause", [
    (_runs(exp1=_exp1(e_s_px=np.full(N, 18.0))), "reach s*"),
    (_runs(exp1=_late_reach()), "still moves"),
    (_runs(exp1=_wander()), "stay there"),
    (_runs(exp1=_exp1(e_u_px=np.full(N, 5.0))), "reach s_u*"),
])
def test_claim_1_fails_on_each_clause(runs: dict[str, RunFiles], clause: str) -> None:
    res = cl.check_1(runs)
    assert _fails(res) and clause in res.measured, res.measured
    # never reached, or reached only once the arm stopped: "stay there while it moves"
    # (and "while it still moves") have nothing to be measured on
    also = {"reach s*": ("still moves", "stay there"), "still moves": ("stay there",)}
    _alone(res, clause, *also.get(clause, ()))


def test_claim_2_fails_when_V_rises_or_the_base_never_stops() -> None:
    V = 2e-3 * np.exp(-0.2 * T)
    V[2200] *= 1.5  # a rise of the exact-feature V after the base stopped
    res = cl.check_2(_runs(exp1=_exp1(V_true=V)))
    assert _fails(res) and "non-increasing" in res.measured
    assert res.clauses[0].measured == pytest.approx((V[2200] - V[2199]) / V[1900], rel=1e-9)
    # issue 18: a rise of the detected points' V alone (detection noise) is reported, not
    # judged: eq. (15) is about the law with exact features
    res = cl.check_2(_runs(exp1=_exp1(V=V)))
    assert res.status == "reproduced" and "1 of 600 intervals rise" in res.measured, res.measured
    # without the exact-feature column the clause cannot be measured: it fails
    assert _fails(cl.check_2(_runs(exp1=_exp1().drop(columns=["V_true"]))))
    V = 2e-3 * np.exp(-0.2 * T)
    V[1000] *= 1.5  # a rise while the base moves: allowed
    assert cl.check_2(_runs(exp1=_exp1(V=V, V_true=V))).status == "reproduced"
    moving = _exp1(**{f"pa10_qd{i}": np.full(N, 0.01) for i in range(1, 7)})
    res = cl.check_2(_runs(exp1=moving))
    assert res.status == "not_reproduced" and "never still" in res.measured
    short = _exp1(**{f"pa10_qd{i}": np.where(T > 24.5, 0.0, 0.01) for i in range(1, 7)})
    res = cl.check_2(_runs(exp1=short))
    assert res.status == "not_reproduced" and "not testable" in res.measured


@pytest.mark.parametrize("col, value, clause", [
    ("vvs_residual_px", 2.0, "e_v -> 0"),
    ("vvs_pos_err_m", 0.01, "true pose"),
])
def test_claim_3_fails_on_each_clause(col: str, value: float, clause: str) -> None:
    res = cl.check_3(_runs(exp2=_exp2(**{col: np.full(N, value)})))
    assert _fails(res) and clause in res.measured, res.measured
    _alone(res, f"exp2: {clause}" if clause == "e_v -> 0" else clause)


def test_claim_4_fails_on_each_clause() -> None:
    res = cl.check_4(_runs(d_mini=0.035))
    assert _fails(res) and "moves the mini-robot away" in res.measured
    _alone(res, "moves the mini-robot away")
    res = cl.check_4(_runs(d_mini=-0.01, d_base=-0.05))
    assert _fails(res) and "dist > 0" in res.measured
    _alone(res, "dist > 0")
    res = cl.check_4(_runs(d_arm=-0.001))
    assert _fails(res) and "dist > 0" in res.measured
    _alone(res, "dist > 0")
    res = cl.check_4(_runs(d_hand=-0.001))  # issue 18: the hand on the PA-10 counts too
    assert _fails(res) and "dist > 0" in res.measured
    _alone(res, "dist > 0")
    f1y = _exp2()
    f1y.loc[(T > 10) & (T < 10.5), "e_f2y_px"] = 30.0
    res = cl.check_4(_runs(exp2=f1y))
    assert _fails(res) and "held coordinate (f2y) stays" in res.measured
    _alone(res, "held coordinate (f2y) stays")
    res = cl.check_4(_runs(exp2=_exp2(e_s_px=np.full(N, 20.0))))
    assert _fails(res) and "s -> s*" in res.measured
    _alone(res, "s -> s*")
    lost = _exp2()  # issue 18: dots lost at the end are not "s -> s*"
    lost.loc[N - 5:, "e_s_px"] = np.nan
    res = cl.check_4(_runs(exp2=lost))
    assert _fails(res) and "(a dot is out of the image at the end)" in res.measured
    _alone(res, "s -> s*")
    offset = _exp2()  # a constant offset from 272 px held steadily is no variation
    offset["e_f2y_px"] = 5.0
    assert cl.check_4(_runs(exp2=offset)).status == "reproduced"
    res = cl.check_4(_runs(exp2=_exp2(active_span=(9.7, 30.0))))  # the human never leaves
    assert _fails(res) and "(the human never leaves)" in res.measured
    _alone(res, "NaN if the human never leaves")
    res = cl.check_4(_runs(exp2=_exp2(active_span=(0.0, 0.0))))
    assert res.status == "not_reproduced" and "never came within dmin" in res.measured
    # the human touching without e2 is said
    assert "touches" in cl.check_4(_runs(d_base=-0.01)).measured


def test_claim_2_window_starts_after_the_last_motion() -> None:
    """A base at rest before it starts moving is not 'still': the window begins after its
    last motion (a rise of V at the start, before the arm moves, does not count)."""
    qd = np.where((T >= 1.0) & (T < 19.0), 0.01, 0.0)
    V = 2e-3 * np.exp(-0.2 * T)
    V[50] *= 1.5
    df = _exp1(V=V, V_true=V, **{f"pa10_qd{i}": qd for i in range(1, 7)})
    res = cl.check_2(_runs(exp1=df))
    assert res.status == "reproduced" and "still from 19.00 s" in res.measured, res.measured


def test_claims_1_to_4_quote_the_paper() -> None:
    """Issue 18: the paper's words beside each check."""
    for claim in cl.CLAIMS_1_4:
        assert claim.quote.startswith("Sec.") and '"' in claim.quote, claim.claim


def test_claim_2_and_3_figures_draw_from_the_files() -> None:
    """The figures of claims 2 (V and V_true) and 3 (the cold starts) read only the runs."""
    import matplotlib.pyplot as plt

    from experiments.pomares2011.figures import lyapunov, vvs_cold_starts

    fig = lyapunov(_run(_exp1()))
    assert [len(ax.lines) for ax in fig.axes] == [2, 2]
    right = fig.axes[1].lines[0].get_xdata()
    assert right.min() >= 19.0  # the window in which the PA-10 is still
    plt.close(fig)
    fig = vvs_cold_starts(_run(_cold()))
    assert len(fig.axes[0].lines) == 2 and len(fig.axes[0].get_xticks()) == 1  # + the bound
    plt.close(fig)
