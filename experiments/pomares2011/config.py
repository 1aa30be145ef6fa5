"""pomares2011 experiment configuration: the paper's parameters and ours."""

from __future__ import annotations

from dataclasses import dataclass

from repro.config import param

EXPERIMENTS = ("exp1", "exp2")


@dataclass(frozen=True)
class Pomares2011Config:
    """One pomares2011 run (defaults: experiment 1, Sec. 7.1)."""

    experiment: str = param("exp1", choices=EXPERIMENTS,
                            help="exp1: approach, no human; exp2: a human enters (Sec. 7.2)")
    duration: float = param(20.0, unit="s", range=(0.01, 120.0),
                            help="run time")  # ours: the RVC error decays as exp(-0.3 t)
    physics_rate: float = param(1000.0, unit="Hz", range=(500.0, 5000.0),
                                help="physics = torque-control rate")  # ours: 1 kHz keeps the light mini-robot stable (facts sheet)
    camera_period: int = param(5, range=(1, 100),
                               help="control steps between camera frames")  # pomares2011 Sec. 7: 200 fps at 1 kHz
    camera_mode: str = param("render", choices=("render", "exact"),
                             help="render = PyBullet image + OpenCV; exact = projection")
    rvc_gain: float = param(0.3, unit="1/s", range=(0.01, 10.0),
                            help="lambda of the RVC law (18)")  # ours: the paper gives none; at 0.6/s the PA-10 carries the camera faster than the 3-DoF mini-robot (180 deg/s) can follow and the dots leave the image at 0.2 s
    omega_max: float = param(60.0, unit="rad/s", range=(1.0, 300.0),
                             help="fastest mode of the mini-robot loop (gain rule, ours)")  # ours: K_P, K_v "estimated by the user" (Sec. 3); 60 rad/s keeps omega dt = 0.06 at 1 kHz
    zeta: float = param(1.0, range=(0.1, 5.0), help="damping ratio of every mode (ours)")  # ours: critical damping, no overshoot of the image features
    mini_controller: str = param("direct", choices=("direct", "indirect"),
                                 help="direct: torque-level hybrid VS (eq. 5); indirect: "
                                      "kinematic IBVS tracked by a joint PD (baseline)")
    secondary_task: bool = param(True, help="eq. (17) human avoidance on (exp2)")
    dmin: float = param(0.30, unit="m", range=(0.01, 2.0),
                        help="d_min of eq. (17)")  # ours
    push_force: float = param(1.0, unit="N", range=(0.01, 50.0),
                              help="virtual push at contact: alpha = F dmin / k_P")  # ours
    seed: int = param(0, range=(0, 2**31 - 1), help="seed (tracking noise)")
    video: bool = param(False, help="also write an animated GIF of the run (video.gif)",
                        output_only=True)


@dataclass(frozen=True)
class Exp1Config(Pomares2011Config):
    """Experiment 1 (Sec. 7.1): approach with the RVC and the direct hybrid controller."""
