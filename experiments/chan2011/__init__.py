"""chan2011: Chan, Leonard, Croft, Little, "Collision-Free Visual Servoing of an Eye-in-Hand
Manipulator via Constraint-Aware Planning and Control", ACC 2011."""

from __future__ import annotations

from experiments.chan2011 import config as _c
from experiments.chan2011.dcc_audit import DCCAuditConfig
from experiments.chan2011.dcc_audit import run as _audit
from experiments.chan2011.run import check_config, run
from repro.runs.registry import Experiment, Paper, lazy

EXPERIMENTS = Paper(
    key="chan2011",
    experiments=(
        Experiment("simulation", "chan2011", "Sec. III: NMPC, Np = 5, dt = 10 ms (Figs. 3-6)",
                   _c.SimulationConfig, run,
                   check=check_config),
        Experiment("simulation_render", "chan2011", "Beyond the paper: the Sec. III task "
                   "with the rendered camera and dot detection", _c.SimulationRenderConfig, run,
                   check=check_config),
        Experiment("experiment", "chan2011", "Sec. V: conrod among four obstacles, Np = 10, "
                   "dt = 0.1 s, 5 % speeds, DCC (Figs. 12-13)", _c.ExperimentConfig, run,
                   check=check_config),
        Experiment("ibvs", "chan2011", "Baseline: classical IBVS on the simulation task",
                   _c.IBVSConfig, run,
                   check=check_config),
        Experiment("ibvs_saturated", "chan2011", "Baseline: IBVS with a joint-velocity "
                   "saturator on the simulation task", _c.IBVSSaturatedConfig, run,
                   check=check_config),
        Experiment("dcc_audit", "chan2011", "DCC conservativeness: random segments certified "
                   "by eq. (20) + bisection, verified by dense fcl checks", DCCAuditConfig,
                   _audit),
    ),
    figures=lazy("experiments.chan2011.figures", "make_figures"),
    claims=lazy("experiments.chan2011.claims", "CLAIMS"),
    bench=lazy("experiments.chan2011.bench", "bench"),
)
