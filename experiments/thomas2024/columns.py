"""thomas2024 trace columns: declared once, read by the run, the figures and the claims.

The runner adds its own columns (time, joints ``q{i}``/``qd{i}``/``u{i}``, camera points
``s{i}_*`` with their audit, ``dist_*``, the hand's pose); the rings add ``r{k}_d{i}``,
``r{k}_dtrue{i}``, ``r{k}_cbf{i}`` (:class:`repro.sensors.proximity.RingSensor`).
"""

from __future__ import annotations

from experiments.thomas2024.scene import N_SENSORS
from repro.runs.columns import Columns

N_POINTS = 4  # thomas2024 Sec. V: four image points
N_JOINTS = 7  # the Panda
__all__ = ["N_JOINTS", "N_POINTS", "N_RINGS", "N_SENSORS", "declare_columns", "ring_columns"]
N_RINGS = 2


def ring_columns(ring: int, kind: str) -> list[str]:
    """Names of one ring's columns of one kind (``d``, ``dtrue``, ``cbf``, ``kappa``)."""
    return [f"r{ring}_{kind}{i}" for i in range(1, N_SENSORS + 1)]


def declare_columns(n_joints: int, proximity: bool, estimated: tuple[int, ...] = ()
                    ) -> Columns:
    """The controller's columns (ring sensor columns are declared by the rings);
    ``estimated``: the 1-based rings whose model uses estimated normals (their audit)."""
    cols = Columns()
    cols.add("e{i}_u", "px", "IBVS error of point {i} along u: fu (x - x*) (NaN if a dot is "
             "lost)", n=N_POINTS)
    cols.add("e{i}_v", "px", "IBVS error of point {i} along v: fv (y - y*)", n=N_POINTS)
    cols.add("e_norm", "-", "||e_4p||, norm of the 8-vector of normalised-coordinate errors "
             "(multiply by fu for ~px)")
    cols.add("n_found", "-", "number of image points detected")
    for k in range(1, N_RINGS + 1):
        cols.add(f"r{k}_kappa{{i}}", "-", f"QP multiplier kappa of the CBF row of ring {k} "
                 "sensor {i} (0 when inactive or without proximity)", n=N_SENSORS)
    cols.add("qp_status", "text", "solved | relaxed (slack-relaxed CBFs) | failed (u = 0) | "
             "no_features (u = 0)")
    cols.add("qp_iter", "-", "iterations of the one QP solve whose solution is the command "
             "(proxsuite: outer iterations; osqp: ADMM iterations); <= qp_max_iter for the "
             "hard QP, <= the relaxed QP's budget when qp_status is relaxed")
    cols.add("qp_max_slack", "m/s", "largest slack of the relaxed CBF rows (0 when hard)")
    cols.add("qp_solve_s", "s", "solver time of the QP solves of this step")
    cols.add("grad_L0", "-", "||grad_u L(0, kappa*)||, the Lagrangian stop test of Sec. III-C")
    for k in estimated:  # issue 17 item 6 (repro.control.proximity_features.NormalEstimator)
        cols.add(f"r{k}_ncond{{i}}", "-", f"audit: ring {k} sensor {{i}}: cond(B) of the "
                 "normal fit, eq. (4) (NaN: not detecting, nothing fitted)", n=N_SENSORS,
                 audit=True)
        cols.add(f"r{k}_nspread{{i}}", "m", f"audit: ring {k} sensor {{i}}: the fit's least "
                 "RMS extent sqrt(lambda_min(B) / count); under 3 x the range noise (1e-6 m "
                 "noise-free) the fit is degenerate and not used", n=N_SENSORS, audit=True)
        cols.add(f"r{k}_nsrc{{i}}", "-", f"ring {k} sensor {{i}}: the normal the model used: "
                 "0 none (the coarse row (6)), 1 this step's fit, 2 the last well-posed fit "
                 "held (world-fixed) over a degenerate one", n=N_SENSORS)
        cols.add(f"r{k}_nerr{{i}}", "deg", f"audit: ring {k} sensor {{i}}: angle between the "
                 "normal used and the true surface normal at the noise-free hit (NaN: none "
                 "used or nothing hit)", n=N_SENSORS, audit=True)
    return cols
