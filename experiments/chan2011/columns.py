"""chan2011 trace columns: declared once, read by the run, the figures and the claims.

The runner adds its own (time, joints ``q{i}``/``qd{i}``/``u{i}``, image points ``p{j}_*``
with their audit, the true camera pose ``camera_x`` ... ``camera_qw``, ``dist_*``).
"""

from __future__ import annotations

import numpy as np

from experiments.chan2011.scene import N_POINTS
from repro.runs.columns import Columns

__all__ = ["N_POINTS", "declare_columns", "point_columns"]


def point_columns(axis: str, suffix: str = "") -> list[str]:
    """``p1_u`` ... ``p10_u`` (``axis`` u or v; ``suffix`` e.g. ``"_true"``)."""
    return [f"p{j}_{axis}{suffix}" for j in range(1, N_POINTS + 1)]


def declare_columns() -> Columns:
    """The controller's columns."""
    cols = Columns()
    cols.add("e_rms_px", "px", "RMS over the ten points of the distance between the detected "
             "point and the reference image (NaN when a point is lost)")
    cols.add("status", "text", "NMPC solver status (Solve_Succeeded...), ibvs / "
             "ibvs_saturated for the baselines, no_features when a point is lost")
    cols.add("iterations", "-", "SQP iterations of the NMPC solve whose solution is the command")
    cols.add("solve_s", "s", "solver time of the step (NMPC solves incl. DCC re-solve and "
             "retry; the IBVS law for the baselines)")
    cols.add("cost", "-", "NMPC cost (9) at the solution")
    cols.add("max_violation", "-", "largest constraint violation at the NMPC solution")
    cols.add("nmpc_command", "text", "what the NMPC step commanded: converged (a converged, "
             "feasible solution), feasible_iterate (the solver stopped on its iteration limit; "
             "its last iterate satisfies every constraint within feas_tol and is applied), "
             "zero (no feasible point: qdot = 0); empty for the baselines")
    cols.add("dcc_free", "bool", "eq. (20) certifies the planned motion q_k -> q_{k+Np|k}")
    cols.add("dcc_checks", "-", "distance queries used by DCC at this step")
    cols.add("dcc_box", "bool", "joint bounds replaced by the collision-free hyper-rectangle")
    cols.add("dcc_box_halfwidth", "rad", "largest half-width of that hyper-rectangle")
    cols.add("d_fcl", "m", "python-fcl distance of the DCC model (robot links vs obstacles) at q_k")
    return cols


def scene_limits(scene: dict) -> dict:
    """The CRS-A465's joint limits from a run's scene.json, with the speed limits the
    controller used (``qd_max_used``: a fraction of the maximum speeds)."""
    robot = next(b for b in scene["bodies"] if b["kind"] == "urdf")
    return {**robot["joint_limits"], "qd_max_used": scene["controller_model"]["qd_max_used"]}


def target_points_world(scene: dict) -> np.ndarray:
    """(N, 3) world positions of the conrod's dots from a run's scene.json."""
    from scipy.spatial.transform import Rotation

    body = next(b for b in scene["bodies"] if b["kind"] == "dot_target")
    R = Rotation.from_quat(body["pose"]["quaternion_xyzw"]).as_matrix()
    return np.asarray(body["points_target"], float) @ R.T + np.asarray(body["pose"]["position"])
