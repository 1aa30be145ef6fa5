"""pomares2011: Pomares, Perea, Garcia, Jara, Corrales, Torres, "A Multi-Sensorial Hybrid
Control for Robotic Manipulation in Human-Robot Workspaces", Sensors 11(10), 2011.

Built so far (issue 8, open): experiment 1 (the PA-10 under the Reference Virtual Camera,
the mini-robot under the direct hybrid controller). Experiment 2 (the human), the figures
and the claims come next.
"""

from __future__ import annotations

from experiments.pomares2011 import config as _c
from experiments.pomares2011.run import check_config, run
from repro.runs.registry import Experiment, Paper, lazy

EXPERIMENTS = Paper(
    key="pomares2011",
    experiments=(
        Experiment("exp1", "pomares2011", "Sec. 7.1: approach, no human: RVC for the PA-10, "
                   "direct hybrid VS for the mini-robot (Figs. 5-7)", _c.Exp1Config, run,
                   check=check_config),
    ),
    figures=lazy("experiments.pomares2011.figures", "make_figures"),
)
