"""pomares2011 scene: the PA-10 with the Barrett hand and the RRR mini-robot, a table, the
part to grasp with its four dots, and the desired features of experiment 1 (Sec. 7.1).

Paper values are cited; ours are marked ``# ours:``. Frames (``T_a_b``: pose of ``b`` in
``a``, metres):

* **world** = the PA-10 base frame ``pa10_link0`` (mounting surface, ``+z`` up); the table
  top is the plane ``z = 0``.
* ``{o}`` **object**: the centre of the box part, axes along its edges (``+z`` up); the dots
  and the characteristic points ``P_u`` are given in it.
* ``{mc}`` the real camera ``mini_camera_optical`` at the mini-robot's end; ``{rvc}`` the
  Reference Virtual Camera, rigidly on the PA-10's end (:data:`T_FLANGE_RVC`). Both in the
  camera convention of :mod:`repro.sensors.camera` (x right, y down, z forward); pixels
  ``(u, v)`` in that module's pixel-centre convention.

**How the paper's desired features hold here.** The paper gives the desired features of
both cameras (Sec. 7.1) but no geometry. We choose a plausible goal, the hand 0.32 m above
the part and pointing down at it (:data:`T_WORLD_FLANGE_GOAL`, solved with
:func:`repro.sim.robot.solve_ik`), and a mini-robot configuration that leans the camera
back and points it at the part (:data:`Q_GOAL`). Then the model points are *defined* from
the features:

* ``P_p`` (:data:`DOTS`): the rays of ``s*`` from the real camera at :data:`Q_GOAL` cut the
  plane of the dot discs (:data:`DOT_PROUD` above the top face): the dots lie on the part
  and project exactly to ``s*``.
* ``P_u`` (:data:`POINTS_U`): the rays of ``s_u*`` from the RVC at :data:`Q_GOAL` cut the
  plane of the top face: ``learn_desired_features`` at the goal gives exactly ``s_u*``.

Both are computed here at import from the forward kinematics (pinocchio, the same model as
:class:`repro.sim.robot.Robot`) of the stored :data:`Q_GOAL`. The tests
(``tests/test_pomares2011_scene.py``) check the projections (1e-6 px), the rendered
detections (< 1 px), the geometry, the clearances and the IK.

The mini-robot has 3 DoF and ``s*`` has 8 coordinates: ``s*`` is reached exactly only with
the PA-10 at its goal (elsewhere the mini-robot can only approach it).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from repro.geometry import Rx, Ry, Rz, inv_T, trans
from repro.planning.capsules import Capsule
from repro.sensors.camera import (
    DEFAULT_DOT_COLORS,
    DotTarget,
    Intrinsics,
    check_scene_colors,
)
from repro.sim import barrett as B
from repro.sim.human import HumanBody, HumanInScene, HumanMotion, HumanPath
from repro.sim.pa10 import (
    ALL_JOINTS,
    ALL_LIMITS,
    MINI_CAPSULES,
    PALM_HEIGHT,
    pa10_urdf_path,
)
from repro.sim.robot import Robot
from repro.sim.scene import Scene

DEG = np.pi / 180.0

# --------------------------------------------------------------- cameras (Sec. 7)
IMAGE_W, IMAGE_H = 640, 480  # pomares2011 Sec. 7: TM-6740GEV, 640 x 480 px, 200 fps
#: The mini-robot camera: pomares2011 Sec. 7, (u0, v0) = (298, 225) px, (fu, fv) =
#: (1082.3, 1073.7) px, no distortion given. near/far ours: the part is 0.19-0.45 m away,
#: the far table edge < 1.2 m; nothing of interest closer than 2 cm.
INTRINSICS = Intrinsics(width=IMAGE_W, height=IMAGE_H, fu=1082.3, fv=1073.7, u0=298.0,
                        v0=225.0, near=0.02, far=3.0)
#: The RVC's intrinsics: the paper projects ``P_u`` with eqs. (20)-(21) and "the camera
#: intrinsic parameters" (f_u, f_v, u_0, v_0), the real camera's symbols, and its s_u* lie
#: inside a 640 x 480 image: our reading is the same intrinsics as the real camera
#: (repro/control/rvc.py). Being virtual it has no image bounds.
RVC_INTRINSICS = INTRINSICS

#: Speed bounds of the mini-robot camera that size the rendered camera's windows
#: (repro.sensors.camera_window.WindowPolicy.for_camera_speed): [rad/s], [m/s], nearest dot
#: depth [m]. ours: the camera's largest speeds along the committed exp1 run, 2.27 rad/s
#: and 0.17 m/s (a 200 fps replay of its first 0.3 s; 1.8 rad/s and 0.17 m/s between the
#: trace's 100 Hz rows), rounded up; the dots are >= 0.21 m
#: from the camera along it, 0.19 m is the scene's nearest. A faster motion costs full
#: frames ("edge", "missed"), never a different detection.
WINDOW_OMEGA_MAX = 2.5
WINDOW_V_MAX = 0.2
WINDOW_Z_MIN = 0.19
#: Pose of the RVC in ``pa10_flange``. ours: the paper puts the RVC "at the end of the
#: robotic manipulator" (Sec. 5.1); we put it in the palm (``bh8_palm``, 79 mm out on the
#: hand axis, same axes as the flange): a virtual eye-in-hand camera looking along the
#: approach direction, image x = flange x, image y = flange y.
T_FLANGE_RVC = trans(0.0, 0.0, PALM_HEIGHT)

# --------------------------------------------------------------- desired features (Sec. 7.1)
#: s* of the mini-robot camera, f1..f4 [px] (pomares2011 Sec. 7.1); dot i images at row i.
S_STAR = np.array([(324.0, 207.0), (377.0, 272.0), (307.0, 322.0), (257.0, 259.0)])
#: Experiment 2's one-DoF primary task while the human is within dmin (Sec. 7.2): "the goal
#: of the mini-robot is to observe the y-coordinate of f_1p at position 272, i.e. f*_1py =
#: 272 px"; "this DOF compensates the motion of the robotic manipulator" and the secondary
#: task "causes a small variation in the image features". s*'s f1y is 207 px and its f2y
#: 272 px. ours (issue 17 item 12): we hold f2y at 272 px, the feature whose s* coordinate
#: the text names: holding a coordinate where s* already has it is the pure compensation
#: the text describes, while moving f1 from 207 to 272 px would be a 65 px image motion of
#: its own, no "small variation". The literal reading (f1y to 272 px) is not implemented.
#: Row of s (x1, y1, x2, y2, ...) and its target [px].
PRIMARY_TASK_ROW = 3
PRIMARY_TASK_TARGET_PX = 272.0
assert S_STAR.ravel()[PRIMARY_TASK_ROW] == PRIMARY_TASK_TARGET_PX
#: s_u* of the RVC at the PA-10 goal [px] (pomares2011 Sec. 7.1); P_u row i images at row i.
S_U_STAR = np.array([(254.0, 79.0), (293.0, 226.0), (131.0, 274.0), (93.0, 116.0)])
S_STAR.setflags(write=False)
S_U_STAR.setflags(write=False)


# --------------------------------------------------------------- bodies
@dataclass(frozen=True, eq=False)
class BoxBody:
    """A static box of the scene.

    Attributes:
        size: full extents along the box's x, y, z [m] (the Scene convention).
        T_world: 4x4 pose of the box centre frame in the world [m].
        rgba: colour, 4 floats in [0, 1].
    """

    size: tuple[float, float, float]
    T_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    rgba: tuple[float, float, float, float] = (0.5, 0.5, 0.5, 1.0)

    @property
    def top_z(self) -> float:
        """Height of the top face above the box centre, in the box frame [m]."""
        return self.size[2] / 2.0


# The dots are red, green, blue, yellow (hues all round the circle): every other body the
# camera sees must be desaturated (checked by check_scene_colors below and in build_scene).
#: ours: a table in front of the robot, its top the plane z = 0 (the PA-10 stands on a
#: pedestal beside it, its mounting surface level with the top); 0.8 x 1.0 m from x = 0.2 m,
#: clear of the base column (r 0.115 m); greyish beige (HSV saturation 29/255).
TABLE = BoxBody(size=(0.80, 1.00, 0.04), T_world=trans(0.60, 0.0, -0.02),
                rgba=(0.70, 0.67, 0.62, 1.0))
#: ours: the part to grasp, a 14 x 14 x 5 cm box lying on the table 0.55 m in front of the
#: robot (within the Barrett hand's opening; large enough to carry P_u with >= 2 cm margin);
#: steel grey (HSV saturation 13/255). Its frame {o} is the box centre.
OBJECT = BoxBody(size=(0.14, 0.14, 0.05), T_world=trans(0.55, 0.0, 0.025),
                 rgba=(0.50, 0.50, 0.53, 1.0))
#: Dot radius [m]. ours: 1.5 mm discs image 15-17 px across (9-12 px along the view
#: direction, seen ~50 deg off their normal) at the goal, 7-8 px at the start.
DOT_RADIUS = 0.0015
#: Height of the dot discs above the top face [m]. ours: as chan2011, no z-fighting.
DOT_PROUD = 0.0003

# --------------------------------------------------------------- configurations
#: Flange above the part's top face at the goal [m]. ours: "ready to grasp": the half-open
#: fingertips (0.18 m out) 14 cm above the top face.
GOAL_STANDOFF = 0.32
#: The PA-10 goal: the hand axis (flange +z) straight down through the top-face centre,
#: flange x along the world x (the fingers close across the part's y edges). ours: a top
#: grasp.
T_WORLD_FLANGE_GOAL = (OBJECT.T_world @ trans(0.0, 0.0, OBJECT.top_z + GOAL_STANDOFF)
                       @ Rx(np.pi))
#: The PA-10 start of experiment 1: 0.30 m higher, 0.10 m back towards the robot and 0.15 m
#: to the side, the hand turned 25 deg about its axis and tilted 10 deg. ours: "the robotic
#: manipulator describes a trajectory in order to approach the robotic hand towards the
#: object" (Sec. 7); the start is not given.
T_WORLD_FLANGE_START = (trans(-0.10, 0.15, 0.30) @ T_WORLD_FLANGE_GOAL @ Rz(25.0 * DEG)
                        @ Ry(10.0 * DEG))
#: The hand during the approach (Table 1: "no control"; its motors hold): spread 0, every
#: finger half open, its motor at 125 x 60 deg (engaged clutch: proximal 60 deg, distal 20
#: deg). ours: the fingertips clear of the part and of the mini-robot (tests).
HAND_APPROACH_PROXIMAL_DEG = 60.0
#: That pose's motor angle per finger [rad of the motor].
HAND_APPROACH_MOTOR = B.J2_RATIO * HAND_APPROACH_PROXIMAL_DEG * DEG


#: The hand's joints during the approach [rad] (HAND_JOINTS order).
Q_HAND = B.hand_joints_from_motors((HAND_APPROACH_MOTOR,) * 3)
#: Seed of solve_ik for the goal (elbow up, wrist bent down); the start is solved from the goal.
IK_SEED_GOAL = np.r_[0.0, -0.6, -1.6, 0.0, -0.9, 0.0, 0.0, 0.0, 0.0, Q_HAND]

#: Goal configuration, ALL_JOINTS order [rad] (PA-10, mini-robot, then the hand at
#: :data:`Q_HAND`). PA-10: solve_ik(pa10_flange,
#: T_WORLD_FLANGE_GOAL, IK_SEED_GOAL) (re-solved in the tests). Mini-robot ours: turned 90 deg
#: around the hand (to the world -y side), leaning back (q2 = -50 deg) for depth (0.19-0.21
#: m), q3 pointing the optical axis so that the top-face centre images at v = 265 px, the
#: mean v of s* (its u stays at u0: the pointing plane contains the hand axis).
Q_GOAL = np.r_[np.array([0.0, -18.624802, -107.027660, 0.0, -54.347538, 0.0,
                         90.0, -50.0, 101.2]) * DEG, Q_HAND]
#: Start configuration of experiment 1 [rad]. PA-10: solve_ik(pa10_flange,
#: T_WORLD_FLANGE_START, Q_GOAL). Mini-robot ours: pointing at the part from q2 = -30 deg
#: (q1, q3 put the top-face centre near (360, 200) px): all four dots in view, 0.41 m away,
#: 67-107 px from s*. The hand at :data:`Q_HAND`.
Q_START = np.r_[np.array([19.613526, 4.515521, -96.213856, -7.088649, -81.213912, 45.263252,
                          78.0, -30.0, 38.4]) * DEG, Q_HAND]
Q_GOAL.setflags(write=False)
Q_START.setflags(write=False)


# --------------------------------------------------------------- model points
def kinematic_frames(q: np.ndarray) -> dict[str, np.ndarray]:
    """World poses (4x4) [m] of ``pa10_flange``, ``mini_camera_optical`` and the RVC at
    joint positions ``q`` (ALL_JOINTS order) [rad], from the URDF with pinocchio (the
    computation of :meth:`repro.sim.robot.Robot.frame_pose` with the base at the world
    origin; no PyBullet client needed)."""
    q = np.asarray(q, dtype=float)
    qp = np.zeros(_MODEL.nq)
    qp[_Q_IDX] = q
    pin.framesForwardKinematics(_MODEL, _DATA, qp)
    out = {name: _DATA.oMf[_MODEL.getFrameId(name)].homogeneous.copy()
           for name in ("pa10_flange", "mini_camera_optical")}
    out["rvc"] = out["pa10_flange"] @ T_FLANGE_RVC
    return out


def backproject_to_plane(intr: Intrinsics, T_world_camera: np.ndarray, uv: np.ndarray,
                         T_world_frame: np.ndarray, z: float) -> np.ndarray:
    """Points of the plane ``z`` = const of a frame that image at pixels ``uv``.

    The ray of pixel ``(u, v)`` is ``c + t R (x, y, 1)`` with ``(x, y)`` its normalised
    coordinates (:meth:`Intrinsics.to_normalized`) and ``R, c`` the camera's rotation and
    centre in the frame; ``t`` solves its third coordinate ``= z``.

    Args:
        intr: camera intrinsics.
        T_world_camera: 4x4 camera pose (x right, y down, z forward) in the world [m].
        uv: (N, 2) pixel coordinates [px].
        T_world_frame: 4x4 pose of the frame holding the plane [m].
        z: height of the plane in that frame [m].

    Returns:
        (N, 3) points in that frame [m].

    Raises:
        ValueError: a ray is parallel to the plane or meets it behind the camera.
    """
    T = inv_T(np.asarray(T_world_frame, float)) @ np.asarray(T_world_camera, float)
    xy = intr.to_normalized(np.asarray(uv, dtype=float))
    d = np.c_[xy, np.ones(len(xy))] @ T[:3, :3].T
    c = T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (z - c[2]) / d[:, 2]
    if not np.all(np.isfinite(t) & (t > 0)):
        raise ValueError(f"rays of {np.asarray(uv).tolist()} do not meet the plane z = {z} m "
                         f"in front of the camera (t = {t.tolist()})")
    return np.asarray(c + t[:, None] * d)


_MODEL = pin.buildModelFromUrdf(str(pa10_urdf_path()))
_DATA = _MODEL.createData()
_Q_IDX = np.array([_MODEL.joints[_MODEL.getJointId(n)].idx_q for n in ALL_JOINTS])
_GOAL_FRAMES = kinematic_frames(Q_GOAL)

#: P_p in {o} [m]: s* back-projected from the real camera at Q_GOAL onto the dot plane.
POINTS_P = backproject_to_plane(INTRINSICS, _GOAL_FRAMES["mini_camera_optical"], S_STAR,
                                OBJECT.T_world, OBJECT.top_z + DOT_PROUD)
#: The observed points P_p as coloured dots (red, green, blue, yellow = f1..f4), flat discs
#: facing +z of {o} just above the top face (no plate: the part carries them).
DOTS = DotTarget(points_target=POINTS_P, colors=DEFAULT_DOT_COLORS[:4],
                 dot_radius=DOT_RADIUS, plate_size=None)
#: P_u in {o} [m]: s_u* back-projected from the RVC at Q_GOAL onto the top face's plane
#: (virtual characteristic points; pomares2011 Sec. 5.1, Fig. 3).
POINTS_U = backproject_to_plane(RVC_INTRINSICS, _GOAL_FRAMES["rvc"], S_U_STAR,
                                OBJECT.T_world, OBJECT.top_z)
POINTS_U.setflags(write=False)

@dataclass(frozen=True, eq=False)
class Layout:
    """Where a pomares2011 run starts and ends and what it wants to see there.

    Attributes:
        name: "exp1" (experiments 1-2 and their baselines) or "task" (the whole task).
        q_start, q_goal: (17,) ALL_JOINTS order [rad].
        s_star: (4, 2) desired features of the mini-robot camera [px] (the exact
            projections of the dots at ``q_goal``).
        s_u_star: (4, 2) the RVC's desired features [px] (before the learning stage
            re-learns them).
        points_u: (4, 3) the RVC's characteristic points P_u in {o} [m].
    """

    name: str
    q_start: np.ndarray
    q_goal: np.ndarray
    s_star: np.ndarray
    s_u_star: np.ndarray
    points_u: np.ndarray


#: Experiments 1-2: the paper's s*, s_u*.
LAYOUT = Layout("exp1", Q_START, Q_GOAL, S_STAR, S_U_STAR, POINTS_U)

#: Every body other than the dots and their colours (the robot is not in the render world).
SCENE_RGBA: dict[str, tuple[float, float, float, float]] = {
    "table": TABLE.rgba, "object": OBJECT.rgba}
check_scene_colors(DOTS, SCENE_RGBA)  # raises at import if a body could be taken for a dot


# --------------------------------------------------------------- the human (experiment 2)
#: The floor is this far below the table top (the world z = 0) [m]. ours: a 0.75 m
#: workbench, the PA-10 on a pedestal level with its top.
FLOOR_Z = -0.75
#: The operator's visit of experiment 2 (pomares2011 Sec. 7.2: "during the approaching
#: phase the human enters within the robot workspace", when "the robotic manipulator is near
#: its desired location"; the path is not given). ours: the operator stands 2.2 m to the
#: robot's right (-y), walks in from t = 8 s (the RVC error is then ~25 px of 281), reaches
#: with the right hand towards the part, the hand tip stopping 0.12 m beside the point where
#: the mini-robot's camera is at the goal (0.55, -0.152, 0.182) m, on the operator's side,
#: holds 2.5 s, withdraws and walks back, standing at the start again from t = 19 s. Base
#: frame = the floor below the world origin.
HUMAN_PATH = HumanPath(start=(0.55, -2.2), approach=(0.55, -0.272, 0.182 - FLOOR_Z),
                       t_enter=8.0, t_reach=11.5, t_hold=14.0, t_leave=19.0, arm="right")
#: Clothes colour. ours: light grey-beige (HSV saturation 29/255): no dot mask can take it.
HUMAN_RGBA = (0.62, 0.58, 0.55, 1.0)


#: The camera's goal point the hand approaches (HUMAN_PATH.approach without the gap) [m]
HUMAN_TARGET = (0.55, -0.152, 0.182)
HUMAN_GAP = 0.12  # ours: the hand tip's default distance beside HUMAN_TARGET [m]


def human_path(gap: float = HUMAN_GAP, t_enter: float = HUMAN_PATH.t_enter) -> HumanPath:
    """HUMAN_PATH with the hand tip ``gap`` [m] beside the camera's goal point (towards the
    operator, -y) and every time shifted so that the walk starts at ``t_enter`` [s]."""
    shift = t_enter - HUMAN_PATH.t_enter
    x, y, z = HUMAN_TARGET
    return dataclasses.replace(
        HUMAN_PATH, approach=(x, y - gap, z - FLOOR_Z),
        t_enter=HUMAN_PATH.t_enter + shift, t_reach=HUMAN_PATH.t_reach + shift,
        t_hold=HUMAN_PATH.t_hold + shift, t_leave=HUMAN_PATH.t_leave + shift)


def human_motion(path: HumanPath = HUMAN_PATH) -> HumanMotion:
    """The scripted operator of experiment 2 (Winter-fraction skeleton, tight radii)."""
    return HumanMotion(path, HumanBody(), T_world_base=trans(0.0, 0.0, FLOOR_Z))


def mini_capsules(chain: Robot, q: np.ndarray) -> list[tuple[str, Capsule]]:
    """The mini-robot's capsules (:data:`repro.sim.pa10.MINI_CAPSULES`) in the world at
    joint positions ``q`` (ALL_JOINTS order) [rad], named ``<link>_<k>``."""
    out = []
    for k, (link, p0, p1, r) in enumerate(MINI_CAPSULES):
        T = chain.frame_pose(link, q)
        out.append((f"{link}_{k}", Capsule(T[:3, :3] @ np.asarray(p0) + T[:3, 3],
                                           T[:3, :3] @ np.asarray(p1) + T[:3, 3], r)))
    return out


def rvc_object_pose(T_world_flange: np.ndarray) -> np.ndarray:
    """``M_O^RVC = T_rvc_obj`` (4x4) [m] from the kinematics: the object's true pose in the
    RVC with the flange at ``T_world_flange`` (what the VVS estimate converges to)."""
    return inv_T(np.asarray(T_world_flange, float) @ T_FLANGE_RVC) @ OBJECT.T_world


def build_scene(scene: Scene, q: np.ndarray | None = None, name: str = "pa10",
                column_prefix: str = "", render_robot: bool = False,
                human: HumanMotion | None = None) -> tuple[Robot, HumanInScene | None]:
    """Add the robot, the table, the part and its dots to ``scene``; return the robot.

    Args:
        scene: the scene (with ``render=True`` for rendered cameras).
        q: initial joint positions, ALL_JOINTS order [rad] (default :data:`Q_START`).
        name: the robot's body name; column_prefix: its trace-column prefix.
        render_robot: also put the robot in the render mirror (costly; the mini-robot
            camera does not see it in the chosen configurations).
        human: the operator (experiment 2): his capsules become moving bodies
            ``human_<bone>`` (rendered, with collision shapes: ground-truth distances).

    Returns:
        The robot and the human's scene bodies (None without a human).

    Raises:
        ConfigError: a body already in the scene has a colour a dot mask could take
            (:func:`repro.sensors.camera.check_scene_colors`).
    """
    robot = scene.add_urdf(name, pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS,
                           column_prefix=column_prefix, render=render_robot)
    robot.reset(np.asarray(Q_START if q is None else q, dtype=float))
    scene.add_box("table", TABLE.size, TABLE.T_world, TABLE.rgba)
    scene.add_box("object", OBJECT.size, OBJECT.T_world, OBJECT.rgba)
    scene.add_dot_target("dots", DOTS, OBJECT.T_world)
    bodies = None
    if human is not None:
        bodies = HumanInScene(human, rgba=HUMAN_RGBA)
        bodies.add(scene, t=0.0)
    scene.check_colors(check_scene_colors)
    return robot, bodies
