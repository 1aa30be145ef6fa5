"""thomas2024: Thomas & Chaumette, "Positioning in Congested Space by Combining
Vision-based and Proximity-based Control", IEEE RA-L 9(10), 2024."""

from __future__ import annotations

from experiments.thomas2024 import config as _c
from experiments.thomas2024.run import check_config, run
from repro.runs.registry import Experiment, Paper, lazy

EXPERIMENTS = Paper(
    key="thomas2024",
    experiments=(
        Experiment("case1", "thomas2024", "Case 1: two planes, global convergence (Fig. 7)",
                   _c.Case1Config, run, check=check_config),
        Experiment("case2", "thomas2024", "Case 2: four planes, local convergence, model (5) "
                   "on ring 2 (Fig. 8)", _c.Case2Config, run,
                   check=check_config),
        Experiment("case3", "thomas2024", "Case 3: a hand approaches ring 2 then ring 1 (Fig. 9)",
                   _c.Case3Config, run,
                   check=check_config),
        Experiment("case1_no_proximity", "thomas2024", "Ablation: case 1 without the CBF "
                   "constraints (Sec. V-A says it collides)", _c.Case1NoProximityConfig, run,
                   check=check_config),
        Experiment("case2_coarse", "thomas2024", "Ablation: case 2 with the coarse model (6) on "
                   "ring 2 (Sec. VI says it oscillates)", _c.Case2CoarseConfig, run,
                   check=check_config),
        Experiment("parallel", "thomas2024", "Sec. VI eq. (20): goal between two parallel planes",
                   _c.ParallelConfig, run,
                   check=check_config),
        Experiment("parallel_noisy", "thomas2024", "The parallel-planes run with 2 mm ToF noise",
                   _c.ParallelNoisyConfig, run,
                   check=check_config),
    ),
    figures=lazy("experiments.thomas2024.figures", "make_figures"),
    claims=lazy("experiments.thomas2024.claims", "CLAIMS"),
    bench=lazy("experiments.thomas2024.bench", "bench"),
    # Sec. V-A: "in case safety inequalities from proximity sensors are not taken into
    # account, the robot arm collides with the obstacles": the ablation on the same boards
    # Sec. VI: model (6) oscillates where (5) does not, on the same four boards
    sweep_groups={"case1": ("case1_no_proximity",), "case2": ("case2_coarse",)},
    # Sec. V-A says 1 (it converges without collision) and 2 (without the CBFs it collides)
    # of the same boards, and 3 (the order of events) of the same run
    joint_claims=(("1", "2"), ("1", "2", "3")),
)
