"""The committed short-run references: one registry for the tests that compare a fresh short
run with its reference, for ``tests/make_reference.py`` (which writes the references) and
for ``tests/measure_tolerances.py`` (which measures how far each compared quantity moves on
another machine and writes the tolerance files beside the references).

A reference is ``tests/reference/<paper>/<name>.csv`` (the short run's trace without its
timing columns, floats to 10 significant digits) and its tolerance file
``<name>.tol.json`` (see :mod:`repro.runs.compare`).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))

REF_ROOT = Path(__file__).parent / "reference"
RESULTS = Path(__file__).resolve().parent.parent / "results"
#: Timing columns of every paper (wall-clock, never compared).
TIMING_COLUMNS = ("ctrl_s", "camera_render_s", "qp_solve_s", "solve_s")


@dataclass(frozen=True)
class Reference:
    """One short-run reference: ``make(tmp, **overrides)`` runs it in ``tmp`` (with config
    fields overridden, for the mutation tests) and returns its trace without timing
    columns; ``gains`` are the config fields a 1 % change of which the comparison must
    catch."""

    paper: str
    name: str
    make: Callable[..., pd.DataFrame]
    gains: tuple[str, ...] = ()
    #: a committed run of results/ (its whole default config), not a short run
    committed: bool = False

    @property
    def id(self) -> str:
        return (f"committed/{self.paper}.{self.name}" if self.committed
                else f"{self.paper}/{self.name}")

    @property
    def csv(self) -> Path:
        if self.committed:
            return RESULTS / self.paper / self.name / "trace.csv"
        return REF_ROOT / self.paper / f"{self.name}.csv"

    @property
    def tol_json(self) -> Path:
        if self.committed:
            return REF_ROOT / "committed" / f"{self.paper}.{self.name}.tol.json"
        return REF_ROOT / self.paper / f"{self.name}.tol.json"

    def load(self) -> pd.DataFrame:
        """The reference trace as the tests read it (timing columns dropped)."""
        if self.committed:
            from repro.runs.trace import load_run

            return _drop_timing(load_run(self.csv.parent).trace)
        return pd.read_csv(self.csv)


def _drop_timing(df: pd.DataFrame) -> pd.DataFrame:
    return df.drop(columns=[c for c in TIMING_COLUMNS if c in df.columns])


def _thomas(name: str) -> Callable[..., pd.DataFrame]:
    def make(tmp: Path, **kw: object) -> pd.DataFrame:
        from test_thomas2024_runs import short_config

        from experiments.thomas2024.run import run
        from repro.runs.trace import load_run

        return _drop_timing(load_run(run(short_config(name, **kw), tmp / name)).trace)
    return make


def _chan(name: str) -> Callable[..., pd.DataFrame]:
    def make(tmp: Path, **kw: object) -> pd.DataFrame:
        from test_chan2011 import short_run

        return _drop_timing(short_run(name, tmp / ("chan_" + name), **kw).trace)
    return make


def _pomares(name: str) -> Callable[..., pd.DataFrame]:
    def make(tmp: Path, **kw: object) -> pd.DataFrame:
        import test_pomares2011_runs

        return _drop_timing(test_pomares2011_runs.make_reference(tmp, name, **kw))
    return make


def _exp3(tmp: Path, **kw: object) -> pd.DataFrame:
    import test_pomares2011_exp3

    return _drop_timing(test_pomares2011_exp3.make_reference(tmp, **kw))


THOMAS = ("case1", "case1_no_proximity", "case2", "case2_coarse", "case3", "parallel",
          "parallel_noisy")
CHAN = ("simulation", "simulation_render", "experiment", "ibvs", "ibvs_saturated",
        "dcc_audit")
POMARES = ("exp1", "exp1_indirect", "exp2")

#: The loop gains whose 1 % change each reference must detect (the mutation tests).
GAINS = {
    "thomas2024": ("lambda_4p",),  # the IBVS gain of the QP cost
    "chan2011/nmpc": ("W_weight",),  # the NMPC's velocity weight (only W/Q matters)
    "chan2011/ibvs": ("ibvs_gain",),
    # the scaling saturator commands the velocity limit at every step of the short run:
    # the gain only sets a magnitude the saturator replaces, so it cannot reach the trace
    # (the Jacobian sign and the one-step delay still must)
    "chan2011/ibvs_saturated": (),
    "chan2011/dcc_audit": ("max_step",),  # no loop: the largest joint change of a segment
    # the PA-10's RVC law and the mini-robot's loop (its damping: omega_max is 0, the gain
    # rule, by default; a 1 % zeta changes K_v by 1 %)
    "pomares2011": ("rvc_gain", "zeta"),
    "pomares2011/exp1_indirect": ("rvc_gain", "indirect_gain"),
    "pomares2011/exp3": ("closing_speed_deg_s",),  # the fingers' closing
}


def _gains(paper: str, name: str) -> tuple[str, ...]:
    """The :data:`GAINS` entry of experiment ``name`` of ``paper``."""
    if paper == "chan2011":
        key = name if name in ("dcc_audit", "ibvs_saturated") else (
            "ibvs" if name.startswith("ibvs") else "nmpc")
        return GAINS[f"chan2011/{key}"]
    if name.startswith("exp3"):
        return GAINS["pomares2011/exp3"]
    return GAINS.get(f"{paper}/{name}", GAINS[paper])


REFERENCES: dict[str, Reference] = {
    r.id: r for r in (
        [Reference("thomas2024", n, _thomas(n), _gains("thomas2024", n)) for n in THOMAS]
        + [Reference("chan2011", n, _chan(n), _gains("chan2011", n)) for n in CHAN]
        + [Reference("pomares2011", n, _pomares(n), _gains("pomares2011", n))
           for n in POMARES]
        + [Reference("pomares2011", "exp3", _exp3, _gains("pomares2011", "exp3"))])
}


def _committed(exp_id: str) -> Reference:
    paper, name = exp_id.split(".")

    def make(tmp: Path, **kw: object) -> pd.DataFrame:
        import dataclasses

        from repro.runs.registry import find_experiment, load_papers
        from repro.runs.trace import load_run

        exp = find_experiment(load_papers(), exp_id)
        config = dataclasses.replace(exp.config_cls(), **kw)  # the committed runs: defaults
        return _drop_timing(load_run(exp.run(config, tmp / name)).trace)

    return Reference(paper, name, make, _gains(paper, name), committed=True)


#: Committed runs that ``make test-slow`` reruns whole and compares with results/.
COMMITTED: dict[str, Reference] = {
    r.id: r for r in (_committed(e) for e in (
        "thomas2024.case1", "thomas2024.case2", "thomas2024.case2_coarse", "chan2011.simulation",
        "chan2011.ibvs_saturated", "pomares2011.exp3", "pomares2011.exp3_no_tactile"))
}


def write_reference(ref: Reference, df: pd.DataFrame) -> None:
    """Write a reference trace as the tests read it (10 significant digits)."""
    ref.csv.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(ref.csv, index=False, float_format="%.10g")


def load_tolerances(ref: Reference) -> dict[str, object]:
    import json

    if not ref.tol_json.is_file():
        raise AssertionError(f"{ref.tol_json} is missing: run tests/measure_tolerances.py "
                             f"--only {ref.id}")
    return json.loads(ref.tol_json.read_text())


def assert_matches_reference(ref: Reference, got: pd.DataFrame) -> None:
    """Fail with the worst comparisons (column, row or window, deviation over tolerance)
    if ``got`` leaves its reference's measured tolerances anywhere."""
    from repro.runs.compare import compare_to_reference

    bad = compare_to_reference(got, ref.load(), load_tolerances(ref))
    if bad:
        lines = "\n  ".join(str(v) for v in bad[:12])
        raise AssertionError(f"{ref.id}: {len(bad)} comparisons outside their measured "
                             f"tolerance ({ref.tol_json.name}); the worst:\n  {lines}")


# ----------------------------------------------------------------- mutations (real changes)
#: Real changes the comparison with a reference must catch: a loop gain 1 % off, a sign
#: flipped in a Jacobian, the command applied one control step late.
MUTATIONS = ("gain+1%", "jacobian_sign", "delay_1_step")


#: Mutations that do not apply: no geometric Jacobian in the loop (the NMPC differentiates
#: its CasADi model itself, the hand's fingers are commanded in motor counts), no loop
#: at all (the DCC audit certifies random segments).
NOT_APPLICABLE = {
    "jacobian_sign": {"chan2011/simulation", "chan2011/simulation_render",
                      "chan2011/experiment", "chan2011/dcc_audit", "pomares2011/exp3"},
    "delay_1_step": {"chan2011/dcc_audit"},
}


def mutations(ref: Reference) -> list[tuple[str, str | None]]:
    """(mutation, gain field) pairs that apply to ``ref``."""
    out: list[tuple[str, str | None]] = [("gain+1%", g) for g in ref.gains]
    return out + [(m, None) for m in MUTATIONS[1:] if ref.id not in NOT_APPLICABLE[m]]


def apply_mutation(kind: str, monkeypatch: object) -> None:
    """Patch the code, through pytest's ``monkeypatch``, for ``jacobian_sign`` (the
    angular-z row of every geometric frame Jacobian negated from the first command on:
    the set-up's inverse kinematics stays right) or ``delay_1_step`` (every drive applies
    the previous control step's command, zero at the first)."""
    import numpy as np

    from repro.sim import barrett, drives
    from repro.sim.robot import Robot

    if kind not in MUTATIONS:
        raise ValueError(f"unknown mutation {kind!r}; valid: {MUTATIONS}")
    if kind == "gain+1%":
        return
    classes = (drives.VelocityDrive, drives.PositionReferenceDrive, drives.TorqueDrive,
               barrett.BarrettHandDrive)
    started = {"yes": False}
    for cls in classes:
        def command(self: object, u: np.ndarray, dt: float,
                    _orig: Callable[..., np.ndarray] = cls.command) -> np.ndarray:
            started["yes"] = True
            if kind != "delay_1_step":
                return _orig(self, u, dt)
            previous = getattr(self, "_mutation_previous", None)
            self._mutation_previous = np.array(u, copy=True)  # type: ignore[attr-defined]
            return _orig(self, np.zeros_like(u) if previous is None else previous, dt)

        monkeypatch.setattr(cls, "command", command)  # type: ignore[attr-defined]
    if kind == "jacobian_sign":
        original = Robot.frame_jacobian

        def flipped(self: Robot, frame: str, q: np.ndarray, reference: str = "local"
                    ) -> np.ndarray:
            J = original(self, frame, q, reference)
            if started["yes"]:
                J = np.array(J, copy=True)
                J[5] *= -1.0
            return J

        monkeypatch.setattr(Robot, "frame_jacobian", flipped)  # type: ignore[attr-defined]


def mutated_trace(ref: Reference, kind: str, tmp: Path, monkeypatch: object,
                  gain: str | None = None) -> pd.DataFrame:
    """The reference's short run under a mutation (``gain``: which field for gain+1%)."""
    apply_mutation(kind, monkeypatch)
    if kind != "gain+1%":
        return ref.make(tmp)
    from dataclasses import fields

    field = gain or ref.gains[0]
    cfg = _default_config(ref)
    value = getattr(cfg, field)
    assert field in {f.name for f in fields(cfg)}
    return ref.make(tmp, **{field: value * 1.01})


def _default_config(ref: Reference) -> object:
    from repro.runs.registry import find_experiment, load_papers

    return find_experiment(load_papers(), f"{ref.paper}.{ref.name}").config_cls()
