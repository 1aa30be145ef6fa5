"""pomares2011: Pomares, Perea, Garcia, Jara, Corrales, Torres, "A Multi-Sensorial Hybrid
Control for Robotic Manipulation in Human-Robot Workspaces", Sensors 11(10), 2011.

Experiments 1 (approach, Sec. 7.1) and 2 (the operator enters, Sec. 7.2) and two
baselines the paper argues for without showing them: experiment 2 without the secondary
task, and experiment 1 with an indirect (kinematic) visual servo of the mini-robot.
Experiment 3: the Barrett hand (fixed base: the PA-10 is still while manipulating) grasps a
cylinder and moves it under Algorithm 1, and the same trajectory without tactile control.
The whole task of Table 1: the approach, then the manipulation with the hand on the PA-10.
"""

from __future__ import annotations

from experiments.pomares2011 import config as _c
from experiments.pomares2011 import exp3 as _e3
from experiments.pomares2011 import task as _task
from experiments.pomares2011 import vvs_cold as _vvs
from experiments.pomares2011.run import check_config, run
from repro.runs.registry import Experiment, Paper, lazy

EXPERIMENTS = Paper(
    key="pomares2011",
    experiments=(
        Experiment("exp1", "pomares2011", "Sec. 7.1: approach, no human: RVC for the PA-10, "
                   "direct hybrid VS for the mini-robot (Figs. 5-7)", _c.Exp1Config, run,
                   check=check_config),
        Experiment("exp2", "pomares2011", "Sec. 7.2: the same approach, the operator walks in "
                   "and reaches near the mini-robot; secondary task (17) (Figs. 8-10)",
                   _c.Exp2Config, run, check=check_config),
        Experiment("exp2_no_secondary", "pomares2011", "baseline: experiment 2 without the "
                   "secondary task (the distance is only measured)", _c.Exp2NoSecondaryConfig,
                   run, check=check_config),
        Experiment("exp1_indirect", "pomares2011", "baseline: experiment 1 with an indirect "
                   "(kinematic IBVS + joint PD) servo of the mini-robot",
                   _c.Exp1IndirectConfig, run, check=check_config),
        Experiment("exp3", "pomares2011", "Secs. 6, 7.3: the Barrett hand grasps a cylinder, "
                   "then a planned finger trajectory under Algorithm 1 (Figs. 11-12)",
                   _e3.Exp3Config, _e3.run, check=_e3.check_config),
        Experiment("exp3_no_tactile", "pomares2011", "ablation: the same trajectory without "
                   "tactile control", _e3.Exp3NoTactileConfig, _e3.run,
                   check=_e3.check_config),
        Experiment("task", "pomares2011", "Table 1: the whole task in one run: the approach "
                   "(RVC, hybrid VS, hand idle), then the manipulation (PA-10 still, hybrid VS, "
                   "Algorithm 1) with the hand on the PA-10", _task.TaskConfig, _task.run,
                   check=_task.check_config),
        Experiment("vvs_cold", "pomares2011", "audit of claim 3: the VVS pose (22)-(24) from "
                   "cold starts (the true pose moved 2-10 cm, 10-30 deg) on rendered frames "
                   "of experiment 1's camera", _vvs.VVSColdConfig, _vvs.run,
                   check=_vvs.check_config),
    ),
    figures=lazy("experiments.pomares2011.figures", "make_figures"),
    claims=lazy("experiments.pomares2011.claims", "CLAIMS"),
    bench=lazy("experiments.pomares2011.bench", "bench"),
    # claim 4 compares experiment 2 with and without (17) on the same visit of the operator
    sweep_groups={"exp2": ("exp2_no_secondary",)},
)
