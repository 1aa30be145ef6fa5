"""pomares2011 trace columns: declared once, read by the run, the figures and the claims.

The runner adds its own: ``pa10_q{i}``/``pa10_qd{i}``/``pa10_u{i}`` (the PA-10: joint
velocity commands [rad/s]), ``mini_q{i}``/``mini_qd{i}``/``mini_u{i}`` (the mini-robot:
joint torques [N m]), ``motor_q{i}``/``motor_qd{i}``/``motor_u{i}`` (the hand's three finger
motors: motor angle targets [rad]), ``bh8_q{i}``/``bh8_qd{i}`` (the hand's joints, observed),
the camera's points ``s{i}_*`` with their audit, ``*_dist_*``.
"""

from __future__ import annotations

from repro.runs.columns import Columns

N_POINTS = 4  # pomares2011 Sec. 7: four points
__all__ = ["N_POINTS", "declare_columns"]


def declare_columns(human: bool = False) -> Columns:
    """The controller's columns (``human``: the distance columns of experiment 2)."""
    cols = Columns()
    cols.add("su{i}_u", "px", "RVC feature {i} (u): projection of P_u through the Reference "
             "Virtual Camera, object pose from VVS (eqs. 19-21); held between frames",
             n=N_POINTS)
    cols.add("su{i}_v", "px", "RVC feature {i} (v)", n=N_POINTS)
    cols.add("su{i}_u_true", "px", "audit: RVC feature {i} (u) from the true object pose",
             n=N_POINTS, audit=True)
    cols.add("su{i}_v_true", "px", "audit: RVC feature {i} (v) from the true object pose",
             n=N_POINTS, audit=True)
    cols.add("e_u_px", "px", "RMS distance of the RVC features to s_u* (learned before the run, "
             "scene.json s_u_star_px)")
    cols.add("arm_reached", "bool", "the RVC error fell under arm_stop_px: the PA-10 "
             "stopped for good (end of the approach)")
    cols.add("e_s_px", "px", "RMS distance of the camera's detected points to s*")
    cols.add("e_f2y_px", "px", "f2y - 272 px: v of detected point 2 minus its s* value, "
             "272 px: the one row the primary task keeps while the human is within dmin "
             "(Sec. 7.2's f*_1py = 272 px, read as f2y: scene.PRIMARY_TASK_ROW)")
    cols.add("V", "J", "Lyapunov function (10): 1/2 qd^T M qd + 1/2 k_P e_s^T e_s of the "
             "mini-robot: qd its joint velocities, M its block of the chain's joint-space "
             "inertia (pinocchio CRBA of the run's URDF at the measured q), e_s = s* - s over "
             "the rows in use [px], k_P of the gain_rule event")
    cols.add("V_true", "J", "audit: V (10) with e_s from the exact projections of the dots' "
             "model points through the true camera pose at this step (the s<i>_u_true, "
             "s<i>_v_true of a frame row) instead of the detected points; same qd, M, k_P and "
             "rows", audit=True)
    cols.add("e2", "-", "secondary task (17), alpha (1 - dist/dmin) when dist < dmin, else 0")
    cols.add("secondary_active", "bool", "the human is within dmin: primary task reduced")
    for a in "xyz":
        cols.add(f"flange_{a}", "m", f"{a} of the PA-10 flange (pa10_flange) in the world, "
                 "forward kinematics of the measured q (for the 3D paths of Fig. 10)")
    cols.add("vvs_iter", "-", "iterations of the VVS pose estimate of the last frame")
    cols.add("vvs_residual_px", "px", "RMS reprojection residual of the VVS pose")
    cols.add("vvs_converged", "bool", "the VVS stopped on its tolerance, not its budget")
    cols.add("vvs_pos_err_m", "m", "audit: distance between the VVS and the true object "
             "position in the camera frame", audit=True)
    cols.add("vvs_rot_err_deg", "deg", "audit: rotation angle between the VVS and the true "
             "object orientation in the mini-robot camera frame", audit=True)
    for pre, what in (("vvs_", "the VVS estimate of"), ("vvs_true_", "audit: the true")):
        for a in ("x", "y", "z"):
            cols.add(f"{pre}{a}", "m", f"{what} the object pose in the mini-robot camera "
                     f"frame (mini_camera_optical): position {a} (last frame)",
                     audit=pre == "vvs_true_")
        for a in ("qx", "qy", "qz", "qw"):
            cols.add(f"{pre}{a}", "-", f"{what} the object pose in the mini-robot camera "
                     f"frame: orientation quaternion {a} (PyBullet order x, y, z, w)",
                     audit=pre == "vvs_true_")
    if human:
        cols.add("dist_m", "m", "dist of eq. (17), sampled every tracker_period control steps "
                 "and held: minimum python-fcl distance between the tracked human capsules "
                 "(true skeleton + tracking noise) and the mini-robot capsules (scene.json "
                 "mini_capsules) at the measured q")
        cols.add("dist_true_m", "m", "audit: the same distance with the true skeleton "
                 "(no tracking noise)", audit=True)
        cols.add("dist_pair", "text", "closest pair of dist_m: <mini-robot capsule>|<human "
                 "capsule>")
    return cols
