"""thomas2024 experiment configuration: the paper's parameters and ours.

Every value the paper gives is cited; every value it does not give is marked
``# ours:`` with the reason, and REPORT.md lists them.
"""

from __future__ import annotations

from dataclasses import dataclass

from repro.config import param
from repro.control.qp import SOLVERS as QP_SOLVERS  # proxsuite, osqp, daqp, quadprog
from repro.sweep_ranges import SweepRange

CASES = ("case1", "case2", "case3", "parallel")
RING_MODELS = ("coarse", "beta1", "exact")

# Allowed ranges (ours: what is physically meaningful for this robot and these sensors).
GAIN_RANGE = (0.0, 100.0)  # [1/s], open at 0
GAIN_WHY = ("0 stops the task; the sampled loop e+ = (1 - gain/rate) e is stable only for "
            "gain < 2 rate (60/s at 30 Hz)")
THRESHOLD_RANGE = (0.005, 0.5)  # [m]
THRESHOLD_WHY = ("below ~5 mm the 2 mm ToF noise reaches the obstacle; beyond 0.5 m "
                 "(half the 1 m range) the rings keep the arm away from everything")
DURATION_RANGE = (0.1, 600.0)  # [s]: at least 3 control steps, at most 10 minutes
Q0_RANGE_DEG = (-360.0, 360.0)  # [deg]
Q0_WHY = "within one turn; check_config enforces the Panda's joint limits"
SEED_RANGE = (0, 2**32 - 1)  # numpy SeedSequence entropy: any 32-bit unsigned integer

# Case 1's boards (Sec. V-A: "we place two planar obstacles in the workspace to create a
# congested space around the robot arm while it has to converge to the goal position ...
# a final configuration of the manipulator in between the obstacles", Fig. 4). The paper
# gives no dimension; the sweep ranges (issue 19) are what that text and figure allow.
CASE1 = (("case", "case1"),)
#: ring 2's radius 0.07 m + its delta* 0.08 m + the board's half thickness 0.005 m: a board
#: nearer than this to ring 2's goal puts the goal inside the threshold (no global minimum)
CASE1_LATERAL_MIN = 0.155
LATERAL_WHY = ("from ring 2's threshold at the goal (0.07 m radius + 0.08 m delta* + 5 mm half "
               "board: nearer, the goal is infeasible and case 1's global convergence "
               "impossible) to ~10 cm beyond it (Sec. V: the workspace is set up 'in such a "
               "manner that it leads to close encounters with obstacles')")
TOP_WHY = ("Fig. 4b: the boards flank the final arm; the top edge from just above ring 2 at the "
           "goal (0.53 m + 0.07 m radius) to the flange's start height (0.98 m), above which "
           "a board is taller than the whole motion")
CASE2 = (("case", "case2"),)
CASE3 = (("case", "case3"),)
#: ring 2's radius 0.07 m + case 2's delta* 0.04 m + half a board: a start board nearer
#: than this to ring 2's start puts the start inside the threshold
CASE2_LATERAL_MIN = 0.115
START_WHY = ("Sec. V-B: the start boards form a passage the robot navigates 'while being very "
             "close to the threshold distance' (Sec. VI: 'a narrow passage'): from ring 2's "
             "threshold at its start (0.07 m radius + 0.04 m delta* + 5 mm half board) to "
             "~13 cm beyond it")
BACK_WHY = ("how far the board reaches back from the goal towards the start: from 15 cm "
            "(only ring 2's final stretch) to 50 cm (ring 2's whole horizontal path from its "
            "start, 0.50 m)")


@dataclass(frozen=True)
class Thomas2024Config:
    """One thomas2024 run. Angles in degrees where the paper gives degrees."""

    case: str = param("case1", choices=CASES, help="scene: obstacle layout and start")
    # --- controller, thomas2024 Sec. V
    lambda_4p: float = param(0.4, unit="1/s", range=GAIN_RANGE, low_open=True,
                             help="IBVS gain lambda_4p (Sec. V); " + GAIN_WHY)
    mu: float = param(0.01, range=(0.0, 10.0),
                      help="QP regularisation mu (Sec. V); above ~10 it outweighs J^T J "
                           "(entries ~1 in normalised units) and the robot barely moves")
    ring_gains: tuple[float, ...] = param((1.0, 3.0), unit="1/s", range=GAIN_RANGE,
                                          low_open=True,
                                          help="CBF gains lambda_1, lambda_2 (table in Sec. V); "
                                               + GAIN_WHY)
    thresholds: tuple[float, ...] = param((0.04, 0.08), unit="m", range=THRESHOLD_RANGE,
                                          help="delta* of ring 1, ring 2 (Sec. V); "
                                               + THRESHOLD_WHY)
    ring_models: tuple[str, ...] = param(("coarse", "coarse"), choices=RING_MODELS,
                                         help="interaction model per ring: coarse=(6), "
                                              "beta1=(5), exact=(2)")
    proximity: bool = param(True, help="CBF constraints on (False = ablation)")
    eps_4p: float = param(0.005, range=(0.0, 0.1),
                          help="stop when ||e_4p|| <= eps_4p (normalised; 0.1 ~ 43 px)")  # ours: ~2 px; the paper gives no value
    eps_qd: float = param(0.01, range=(0.0, 1.0),
                          help="stop when ||grad L(0, kappa*)|| <= eps_qd (Sec. V-B); "
                               "1 is of the order of the unconstrained gradient")
    stop_conditions: bool = param(True, help="apply the stopping conditions of Sec. III-C")
    control_rate: float = param(30.0, unit="Hz", range=(1.0, 1000.0),
                                help="control loop rate (Sec. V: 30 Hz)")
    physics_rate: float = param(240.0, unit="Hz", range=(30.0, 10000.0),
                                help="physics rate")  # ours: PyBullet's default step
    duration: float = param(30.0, unit="s", range=DURATION_RANGE,
                            help="maximum run time")  # ours: the paper's plots span ~10-30 s
    q0_deg: tuple[float, ...] = param((0.0, -60.0, 0.0, -90.0, 0.0, 100.0, 45.0), unit="deg",
                                      range=Q0_RANGE_DEG, help="initial joint positions "
                                      "(Sec. V-A); " + Q0_WHY)
    # --- case 1's board layout (used only when case == "case1"; scene.case1_planes)
    case1_turn_deg: float = param(
        -15.0, unit="deg", range=(-90.0, 90.0),
        help="the corridor's yaw relative to ring 2's straight path to the goal (negative: "
             "the path runs into the right board)",
        sweep=SweepRange(-30.0, 30.0, when=CASE1, reason=(
            "Fig. 4b: the boards run along the arm's final configuration; at 30 deg, ring 2's "
            "0.50 m straight path to the goal crosses a board's plane (~0.17 m aside) 0.33 m "
            "before the goal, so beyond it a board stands across the path, not beside it")))  # ours: the straight path meets the right board
    case1_right_lateral: float = param(
        0.165, unit="m", range=(0.0, 1.0),
        help="right board's centre plane from the corridor axis through ring 2's goal",
        sweep=SweepRange(CASE1_LATERAL_MIN, 0.25, when=CASE1, reason=LATERAL_WHY))  # ours: 1 cm beyond the threshold
    case1_left_lateral: float = param(
        0.19, unit="m", range=(0.0, 1.0),
        help="left board's centre plane from the corridor axis through ring 2's goal",
        sweep=SweepRange(CASE1_LATERAL_MIN, 0.25, when=CASE1, reason=LATERAL_WHY))  # ours: 3.5 cm beyond it
    case1_right_top: float = param(0.85, unit="m", range=(0.31, 2.0),
                                   help="right board's top edge (bottom at 0.30 m)",
                                   sweep=SweepRange(0.60, 1.0, when=CASE1, reason=TOP_WHY))  # ours
    case1_left_top: float = param(0.85, unit="m", range=(0.31, 2.0),
                                  help="left board's top edge (bottom at 0.30 m)",
                                  sweep=SweepRange(0.60, 1.0, when=CASE1, reason=TOP_WHY))  # ours
    case1_right_back: float = param(0.30, unit="m", range=(0.0, 1.5),
                                    help="right board's extent from the goal back along the "
                                         "corridor", sweep=SweepRange(0.15, 0.50, when=CASE1,
                                                                      reason=BACK_WHY))  # ours
    case1_left_back: float = param(0.45, unit="m", range=(0.0, 1.5),
                                   help="left board's extent from the goal back along the "
                                        "corridor", sweep=SweepRange(0.15, 0.50, when=CASE1,
                                                                     reason=BACK_WHY))  # ours
    case1_front: float = param(
        0.25, unit="m", range=(0.0, 1.0),
        help="both boards' extent past the goal along the corridor",
        sweep=SweepRange(0.10, 0.40, when=CASE1, reason=(
            "past ring 2's goal: from 10 cm (ring 2 and the camera) to 40 cm (beyond the "
            "target, 30 cm ahead of the camera, and its card)")))  # ours
    # --- case 2's boards (used only when case == "case2"; scene.case2_planes)
    case2_start_right_lateral: float = param(
        0.22, unit="m", range=(0.0, 1.0),
        help="right start board's centre plane from ring 2's start, across the corridor",
        sweep=SweepRange(CASE2_LATERAL_MIN, 0.25, when=CASE2, reason=START_WHY))  # ours
    case2_start_left_lateral: float = param(
        0.16, unit="m", range=(0.0, 1.0),
        help="left start board's centre plane from ring 2's start, across the corridor",
        sweep=SweepRange(CASE2_LATERAL_MIN, 0.25, when=CASE2, reason=START_WHY))  # ours
    case2_start_skew_deg: float = param(
        0.0, unit="deg", range=(-45.0, 45.0),
        help="angle between the start boards (each turned by half; > 0: they diverge "
             "towards the goal)",
        sweep=SweepRange(-10.0, 10.0, when=CASE2, reason=(
            "Sec. V-B: 'aligned approximately parallel to each other': ours, 'approximately' "
            "read as within 10 deg")))  # ours: parallel
    case2_v_lean_deg: float = param(
        35.0, unit="deg", range=(0.0, 90.0),
        help="lean of each V board towards ring 2's axis (0: along the axis)",
        sweep=SweepRange(15.0, 75.0, when=CASE2, reason=(
            "Sec. V-B: the two boards 'are aligned with each other at an angle'; at 0 deg a "
            "board runs along ring 2's axis (then the coarse model (6) is exact and Sec. VI's "
            "eq. (24) contrast vanishes), at 90 deg it faces the ring head-on (a wall, not "
            "a V): 15-75 deg, 15 deg clear of both")))  # ours
    case2_v_ahead: float = param(
        -0.05, unit="m", range=(-0.5, 0.5),
        help="where the V's threshold surface meets ring 2's sensors 4 and 12, along the "
             "ring's axis from its goal (< 0: before the goal)",
        sweep=SweepRange(-0.10, -0.01, when=CASE2, reason=(
            "Sec. V-B: the V is placed 'to stop convergence of e_4p before its global "
            "minimum': before the goal, by at least 1 cm (5 noise std: a stop, not a "
            "convergence) and at most 10 cm (the boards' 'closer to the final goal')")))  # ours
    # --- case 3's hand (used only when case == "case3"; scene.hand_motion)
    case3_near_gap: float = param(
        0.03, unit="m", range=(0.0, 0.3),
        help="the hand's face from the ring's rim at its nearest point",
        sweep=SweepRange(0.01, 0.04, when=CASE3, reason=(
            "Sec. V-C: at each approach 'proximity sensors ... reach close to virtual "
            "contact': the hand comes inside both thresholds (ring 1's 4 cm), down to 1 cm "
            "(a hand that nearly touches the ring)")))  # ours: under every threshold
    case3_duration_scale: float = param(
        1.0, range=(0.1, 2.0),
        help="every approach's duration times this (start times kept)",
        sweep=SweepRange(0.5, 1.03, when=CASE3, reason=(
            "Fig. 9: four approaches in 5-18 s and four in 20-30 s; ring 2's last (14.9 s + "
            "3.0 s) still ends by 18 s up to x1.03; down to half as long (a hand at ~0.45 "
            "m/s, still a slow hand: Sec. VI warns of 'high speed moving obstacles')")))  # ours
    case3_aim_offset_deg: float = param(
        0.0, unit="deg", range=(-180.0, 180.0),
        help="every approach direction turned by this about its ring's axis",
        sweep=SweepRange(-45.0, 45.0, when=CASE3, reason=(
            "the paper shows two approaches (Fig. 6c-d), not their directions: ours turned "
            "together by up to half the 90 deg spacing of ring 2's four approaches")))  # ours
    # --- sensors
    camera_mode: str = param("render", choices=("render", "exact"),
                             help="render = PyBullet image + OpenCV; exact = projection")
    proximity_noise: float = param(
        0.002, unit="m", range=(0.0, 0.1), help="std of ToF noise",
        sweep=SweepRange(0.0005, 0.005, dist="log-uniform", reason=(
            "VL53L-class ToF ranging at 4-30 cm indoors: a standard deviation of a few mm; "
            "a decade around the default, from a well-calibrated sensor (0.5 mm) to the "
            "paper's 'accuracy of data reduces around minimum distance' (5 mm)")))  # ours: VL53L-class ToF, a few mm
    tof_fov_deg: float = param(
        0.0, unit="deg", range=(0.0, 90.0),
        help="each ToF sensor's full field of view: 0 = one ray along its axis (the paper's "
             "thin field), else a cone of rays returning the nearest hit",
        sweep=SweepRange(0.0, 27.0, dist="discrete", values=(0.0, 27.0), reason=(
            "Sec. II-A models 'a thin-field range finder in which detection occurs along the "
            "axis of sensor'; the VL53L-class parts of such rings have a 25-27 deg cone "
            "(data sheets): either")))  # ours: the paper's model
    normal_history: int = param(
        15, unit="steps", range=(1, 300),
        help="control steps of past detections the normal estimator keeps (Sec. II-A1)",
        sweep=SweepRange(5, 30, when=CASE2, reason=(
            "Sec. II-A1 fits 'successive measurements ... in previous instances' without a "
            "count: from 1/6 s to 1 s of the 30 Hz loop (used by model (5), case 2's ring "
            "2)")))  # ours: 0.5 s at 30 Hz
    normal_neighbours: int = param(
        1, range=(1, 8),
        help="adjacent sensors on each side whose past points the estimator uses",
        sweep=SweepRange(1, 2, dist="discrete", values=(1.0, 2.0), when=CASE2, reason=(
            "Sec. II-A1: 'successive measurements on adjacent sensors located on the same "
            "ring': the nearest on each side, or the two nearest (20 or 40 deg of an "
            "18-sensor ring)")))  # ours: the nearest
    max_range: float = param(1.0, unit="m", range=(0.05, 10.0),
                             help="reading with no detection (Sec. V: 1 m)")
    qp_solver: str = param("proxsuite", choices=QP_SOLVERS,
                           help="QP solver (the paper: ProxQP = proxsuite); osqp = ADMM, "
                                "daqp = dual active set (warm-started), quadprog = "
                                "Goldfarb-Idnani dual active set (cold, H > 0)")
    qp_max_iter: int = param(200, range=(1, 100000),
                             help="iteration budget per QP solve")  # ours: bounds an infeasible solve to ~2 ms
    seed: int = param(0, range=SEED_RANGE, help="seed of the sensor noise (32-bit)")
    video: bool = param(False, help="also write video.mp4, replayed from the run's files after it ends (as repro video)",
                        output_only=True)


# Per-experiment defaults (thomas2024 Sec. V, table of cases in shared/papers/README.md).
@dataclass(frozen=True)
class Case1Config(Thomas2024Config):
    """Case 1, global convergence: lambda = (1, 3), delta* = (4, 8) cm, model (6)."""


@dataclass(frozen=True)
class Case1NoProximityConfig(Thomas2024Config):
    """Ablation of case 1 (Sec. V-A: 'the robot arm collides with the obstacles')."""

    proximity: bool = param(False, help="CBF constraints on (False = ablation)")
    stop_conditions: bool = param(False, help="apply the stopping conditions of Sec. III-C")
    duration: float = param(15.0, unit="s", range=DURATION_RANGE, help="maximum run time")  # ours


@dataclass(frozen=True)
class Case2Config(Thomas2024Config):
    """Case 2, local convergence: lambda = (1, 1), delta* = (4, 4) cm, (5) on ring 2."""

    case: str = param("case2", choices=CASES, help="scene: obstacle layout and start")
    ring_gains: tuple[float, ...] = param((1.0, 1.0), unit="1/s", range=GAIN_RANGE,
                                          low_open=True,
                                          help="CBF gains lambda_1, lambda_2 (Sec. V-B)")
    thresholds: tuple[float, ...] = param((0.04, 0.04), unit="m", range=THRESHOLD_RANGE,
                                          help="delta* of ring 1, ring 2 (Sec. V-B)")
    ring_models: tuple[str, ...] = param(("coarse", "beta1"), choices=RING_MODELS,
                                         help="(6) on ring 1, (5) with estimated normals "
                                              "on ring 2 (Sec. V-B)")


@dataclass(frozen=True)
class Case2CoarseConfig(Case2Config):
    """Ablation of case 2 with the coarse model (6) on ring 2 (Sec. VI, eq. (24))."""

    ring_models: tuple[str, ...] = param(("coarse", "coarse"), choices=RING_MODELS,
                                         help="(6) on both rings (ablation)")
    stop_conditions: bool = param(False, help="run the full duration to expose oscillation")
    duration: float = param(20.0, unit="s", range=DURATION_RANGE, help="maximum run time")  # ours


@dataclass(frozen=True)
class Case3Config(Thomas2024Config):
    """Case 3, dynamic obstacle: lambda = (1, 3), delta* = (4, 6) cm, model (6)."""

    case: str = param("case3", choices=CASES, help="scene: obstacle layout and start")
    thresholds: tuple[float, ...] = param((0.04, 0.06), unit="m", range=THRESHOLD_RANGE,
                                          help="delta* of ring 1, ring 2 (Sec. V-C)")
    q0_deg: tuple[float, ...] = param((-20.0, -10.0, 0.0, -135.0, 0.0, 190.0, 45.0), unit="deg",
                                      range=Q0_RANGE_DEG,
                                      help="start at the converged pose (Sec. V-C)")  # ours: = scene goal
    stop_conditions: bool = param(False, help="no stop: the hand comes after convergence")
    duration: float = param(32.0, unit="s", range=DURATION_RANGE, help="run time")  # ours: paper's plot ~30 s


@dataclass(frozen=True)
class ParallelConfig(Thomas2024Config):
    """Sec. VI eq. (20): goal between two parallel planes at ring 2's threshold."""

    case: str = param("parallel", choices=CASES, help="scene: obstacle layout and start")
    ring_gains: tuple[float, ...] = param((1.0, 1.0), unit="1/s", range=GAIN_RANGE,
                                          low_open=True, help="CBF gains")  # ours: as case 2
    thresholds: tuple[float, ...] = param((0.04, 0.04), unit="m", range=THRESHOLD_RANGE,
                                          help="delta*")  # ours: as case 2
    stop_conditions: bool = param(False, help="run the full duration to expose oscillation")
    duration: float = param(20.0, unit="s", range=DURATION_RANGE, help="run time")  # ours
    proximity_noise: float = param(0.0, unit="m", range=(0.0, 0.1),
                                   help="noise-free: eq. (20) holds at the exact threshold")  # ours: see parallel_noisy


@dataclass(frozen=True)
class ParallelNoisyConfig(ParallelConfig):
    """The parallel-planes run with the ToF noise of the other cases: both opposite
    constraints sit at their threshold, so noise makes the hard QP intermittently
    infeasible (handled by the slack-relaxed fallback, logged as events)."""

    proximity_noise: float = param(0.002, unit="m", range=(0.0, 0.1), help="std of ToF noise")
