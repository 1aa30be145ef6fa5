"""pomares2011 experiment 3: its phases, the tactile decisions and the declared trace
columns."""

from __future__ import annotations

import math

from experiments.pomares2011.exp3_audit import declare_hand_joint_columns
from experiments.pomares2011.exp3_config import BREAKAWAY_DETECT_RAD, DROP_M, FINGERS, N_FINGERS
from repro.control.tactile_control import (
    LOG_FIELDS,
)
from repro.runs.columns import Columns

PHASES = {
    "waiting": "the whole task only: the approach is on, the finger motors hold (Table 1)",
    "preshape": "the whole task only: the fingers move to the pre-shape at preshape_speed",
    "closing": "automatic closing: fingers close until each one's pressure reaches grasp_kpa "
               "(or its clutch breaks away)",
    "support": "every finger stopped: held while the support is lowered and the cylinder "
               "settles in the fingers",
    "manipulation": "the planned trajectory, under Algorithm 1 (or open loop in the ablation)",
    "stopped": "Algorithm 1 line 13 ended the task: fingers held",
    "done": "every trajectory step executed: fingers held",
}
#: Per-finger decision of an Algorithm-1 tick (column ``alg_decision{i}``).
DECISIONS = ("", "ok", "readjust", "readjust_blocked_torque", "give_up_continue", "stop")


def declare_columns(hand_joints: bool = True, supports: tuple[str, ...] = ("support",)
                    ) -> Columns:
    """The experiment's own columns (the runner adds ``t``, ``motor_*``, the pose columns of
    the cylinder and the support; the tactile sensor its ``tac_*``); ``hand_joints``: also
    ``hand_q{i}`` (False: someone else declares them); ``supports``: the support bodies."""
    cols = Columns()
    cols.add("phase", "text", "controller phase: " + "; ".join(f"{k}: {v}"
                                                                for k, v in PHASES.items()))
    if hand_joints:
        declare_hand_joint_columns(cols)
    cols.add("counts{i}", "counts", "motor counts of finger {i}: measured motor angle "
             "motor_q{i} x 4096 / (2 pi) (pomares2011 Fig. 12a)", n=N_FINGERS)
    cols.add("cmd_counts{i}", "counts", "commanded motor target of finger {i} in counts "
             "(motor_u{i} x 4096 / (2 pi))", n=N_FINGERS)
    cols.add("p{i}", "kPa", "maximum reported pressure of finger {i} over its two pads "
             "(proximal, distal), the held 30 Hz sample: Algorithm 1's p", n=N_FINGERS)
    cols.add("Fmap_total", "N", "total normal force implied by the seven reported pressure "
             "maps, sum of tac_<pad>_Fmap (compare the audit F_raw_total)")
    cols.add("closed{i}", "bool", "finger {i} has stopped closing (phase 1)", n=N_FINGERS)
    cols.add("broken_away{i}", "bool", "finger {i}'s TorqueSwitch has broken away, from the "
             f"measured joints: q_distal - q_proximal / 3 > {math.degrees(BREAKAWAY_DETECT_RAD)}"
             " deg", n=N_FINGERS)
    cols.add("plan_step", "-", "trajectory step last commanded, 0-based (-1: none)")
    cols.add("plan_dy", "m", "planned displacement of the cylinder along the palm's y at that "
             "step (negative: towards fingers 1-2; NaN before the trajectory)")
    cols.add("tick", "bool", "an Algorithm-1 tick happened at this row (a new tactile sample "
             "during the manipulation)")
    for name, (unit, definition) in LOG_FIELDS.items():
        if name == "tactile_state":
            definition += "; off: tactile control disabled (the ablation)"
        cols.add(name, unit, definition + " (Algorithm 1, repro.control.tactile_control)",
                 n=N_FINGERS if "{i}" in name else None)
    cols.add("alg_decision{i}", "text", "decision of this tick on finger {i} (empty: finger "
             "not checked): " + ", ".join(d for d in DECISIONS if d), n=N_FINGERS)
    cols.add("alg_p{i}", "kPa", "the pressure p of finger {i} that decision used (NaN: not "
             "checked at this tick)", n=N_FINGERS)
    cols.add("alg_num_readjust{i}", "-", "numReadjust of finger {i} right after that decision "
             "(-1: not checked at this tick)", n=N_FINGERS)
    cols.add("tau_prox{i}", "N m", "applied motor torque of finger {i}'s proximal joint, last "
             "physics step (PyBullet joint state)", n=N_FINGERS)
    cols.add("tau_dist{i}", "N m", "applied motor torque of finger {i}'s distal joint (0 "
             "while engaged: its motor is off)", n=N_FINGERS)
    cols.add("tau{i}", "N m", "largest |joint torque| of finger {i}: what line 7 compares with "
             "max_torque_nm", n=N_FINGERS)
    audit = "audit (PyBullet ground truth, never read by the controller): "
    for a in "xyz":
        cols.add(f"obj_{a}", "m", audit + f"{a} of the cylinder's centre in the palm frame "
                 "bh8_palm (z out of the palm, axes of bh8_base)", audit=True)
    for a in ("qx", "qy", "qz", "qw"):
        cols.add(f"obj_{a}", "-", audit + "orientation of the cylinder frame (z = its axis) in "
                 "the palm frame, quaternion xyzw", audit=True)
    cols.add("obj_axis_tilt", "rad", audit + "angle between the cylinder's axis and the palm's "
             "x axis", audit=True)
    for a in "xyz":
        cols.add(f"obj_d{a}", "m", audit + f"displacement along the palm's {a} of the cylinder's "
                 "centre from its pose at the start of the manipulation (NaN before)", audit=True)
    cols.add("obj_disp", "m", audit + "norm of (obj_dx, obj_dy, obj_dz)", audit=True)
    cols.add("obj_rot", "rad", audit + "rotation angle of the cylinder since the start of the "
             "manipulation (in the palm frame)", audit=True)
    for k in FINGERS:
        cols.add(f"contact{k}", "bool", audit + f"finger {k}'s proximal or distal link touches "
                 "the cylinder", audit=True)
        cols.add(f"F_raw{k}", "N", audit + f"sum of the PyBullet normal forces between finger "
                 f"{k}'s proximal and distal links and the cylinder", audit=True)
    cols.add("contact_palm", "bool", audit + "the palm plate touches the cylinder", audit=True)
    cols.add("contact_other", "bool", audit + "another hand link (knuckle, base) touches the "
             "cylinder", audit=True)
    cols.add("contact_support", "bool", audit + "the support rail touches the cylinder",
             audit=True)
    cols.add("support_dist", "m", audit + "signed distance cylinder - support rail (PyBullet "
             "closest points; < 0: the soft contact's deflection under the weight; capped at "
             "0.05 m)", audit=True)
    cols.add("F_raw_palm", "N", audit + "normal force palm - cylinder", audit=True)
    cols.add("F_raw_other", "N", audit + "normal force other hand links - cylinder", audit=True)
    cols.add("F_raw_total", "N", audit + "sum of every normal force between the hand and the "
             "cylinder (compare Fmap_total, from the pressure maps)", audit=True)
    for body in ("cylinder", *supports, "min"):
        what = ("minimum over the obstacles (the supports)" if body == "min" else
                f"minimum distance between the whole hand and {body}")
        cols.add(f"hand_dist_{body}", "m", audit + what + " (PyBullet closest points; < 0 "
                 "penetration)", audit=True)
    cols.add("dropped", "bool", audit + "no finger, no palm and no support touches the "
             f"cylinder and it is more than {DROP_M * 1e3:g} mm from its pose at the start of "
             "the manipulation", audit=True)
    return cols
