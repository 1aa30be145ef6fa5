"""pomares2011 Sec. 5.1 step (4): the learning stage that gives the RVC its desired features."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from experiments.pomares2011 import scene as sc
from repro.control.rvc import learn_desired_features
from repro.errors import SensorError
from repro.geometry import inv_T
from repro.sim.episode import CameraRig
from repro.sim.robot import Robot
from repro.sim.scene import Scene
from repro.vision.pose import pose_from_points
from repro.vision.vvs import vvs_pose


class Learned(NamedTuple):
    """The learning stage's outcome (pomares2011 Sec. 5.1, step 4)."""

    s_u_star: np.ndarray  # (4, 2) [px] learned desired RVC features
    uv_goal: np.ndarray  # (4, 2) [px] what the camera detected at the goal
    vvs_residual_px: float
    vvs_pos_err_m: float  # audit: VVS position error vs the true object pose


def learn_s_u_star(scene: Scene, chain: Robot, rig: CameraRig, layout: sc.Layout = sc.LAYOUT
                   ) -> Learned:
    """s_u* by the learning stage: the robot placed at its goal configuration
    (:data:`scene.Q_GOAL`), one camera frame (rendered and detected like every frame of the
    run), the object pose by PnP + VVS (22)-(24), M_O^RVC from the kinematics, and the
    projection of P_u (19)-(21) (:func:`repro.control.rvc.learn_desired_features`). The
    robot is put back where it was.

    Raises:
        SensorError: the camera does not see the four dots at the goal, or no pose is found.
    """
    q0 = chain.q()
    chain.reset(np.asarray(layout.q_goal, float))
    try:
        body = scene[rig.target]
        assert body.dot_target is not None
        T_wc = rig.pose(chain.q())
        uv, found, _ = rig.camera.measure(scene.render_client, T_wc, body.dot_target,
                                          body.T_world)
        if not found.all():
            raise SensorError(f"learning stage: dots {(np.flatnonzero(~found) + 1).tolist()} "
                              "not detected with the robot at its goal")
        T0 = pose_from_points(sc.POINTS_P, uv, sc.INTRINSICS.K())
        if T0 is None:
            raise SensorError("learning stage: PnP found no object pose at the goal")
        res = vvs_pose(sc.POINTS_P, uv, sc.INTRINSICS, T0)
        q = chain.q()
        T_world_rvc = chain.frame_pose("pa10_flange", q) @ sc.T_FLANGE_RVC
        T_rvc_obj = inv_T(T_world_rvc) @ T_wc @ res.T_cam_obj  # M_O^RVC at the goal
        s_u = learn_desired_features(sc.RVC_INTRINSICS, T_rvc_obj, layout.points_u)
        T_true = inv_T(T_wc) @ sc.OBJECT.T_world
        err = float(np.linalg.norm(res.T_cam_obj[:3, 3] - T_true[:3, 3]))
        return Learned(np.asarray(s_u), uv, float(res.residual_px), err)
    finally:
        chain.reset(q0)
