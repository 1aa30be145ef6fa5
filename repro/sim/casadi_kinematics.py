r"""Symbolic (CasADi) forward kinematics of a fixed-base serial chain, from a pinocchio model.

``pinocchio.casadi`` is not available in our build, so the chain is rebuilt here from the
numbers pinocchio parsed from the URDF: for every joint ``j`` on the path from the root to a
frame,

.. math::

    {}^{0}T_{j}(q) = {}^{0}T_{\lambda(j)}(q) \; M_j \; X_j(q_j), \qquad
    {}^{0}T_{f}(q) = {}^{0}T_{j_f}(q) \; M_f,

with :math:`\lambda(j)` the parent joint, :math:`M_j` = ``model.jointPlacements[j]`` (pose of
the joint frame in the parent joint frame at :math:`q_j = 0`), :math:`X_j(q_j)` the joint
motion (a rotation by :math:`q_j` about the joint axis, or a translation along it), and
:math:`M_f` = ``model.frames[f].placement`` (pose of the frame in its parent joint frame).
The "base" is pinocchio's universe frame, i.e. the URDF root link.

Supported joints (1 DoF, ``nq = nv = 1``): revolute ``JointModelRX/RY/RZ`` and
``JointModelRevoluteUnaligned``, prismatic ``JointModelPX/PY/PZ`` and
``JointModelPrismaticUnaligned``. Continuous (unbounded, ``nq = 2``), free-flyer and other
joints raise :class:`~repro.errors.ConfigError`.

The functions are built with ``casadi.SX`` (scalar graph), which is the fast choice for a
few hundred operations evaluated many times inside an NLP solver; derivatives come from
CasADi's algorithmic differentiation.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np
import pinocchio as pin

from repro.errors import ConfigError, UnknownChoiceError

#: Joint types of pinocchio (``JointModel.shortname()``) handled here, with their unit axis
#: in the joint frame (None: read from the joint model, the "Unaligned" types).
REVOLUTE_AXES: dict[str, tuple[float, float, float] | None] = {
    "JointModelRX": (1.0, 0.0, 0.0),
    "JointModelRY": (0.0, 1.0, 0.0),
    "JointModelRZ": (0.0, 0.0, 1.0),
    "JointModelRevoluteUnaligned": None,
}
PRISMATIC_AXES: dict[str, tuple[float, float, float] | None] = {
    "JointModelPX": (1.0, 0.0, 0.0),
    "JointModelPY": (0.0, 1.0, 0.0),
    "JointModelPZ": (0.0, 0.0, 1.0),
    "JointModelPrismaticUnaligned": None,
}


def _axis(joint: pin.JointModel, table: dict[str, tuple[float, float, float] | None]
          ) -> np.ndarray:
    """Unit axis (3,) of a 1-DoF joint, in its joint frame."""
    fixed = table[joint.shortname()]
    axis = np.asarray(joint.extract().axis if fixed is None else fixed, dtype=float)
    norm = np.linalg.norm(axis)
    if not norm > 0:
        raise ConfigError(f"joint axis {axis} has zero length")
    return axis / norm


def rotation_about_axis(axis: np.ndarray, angle: ca.SX) -> ca.SX:
    r"""3x3 rotation by ``angle`` [rad] about the unit ``axis`` (Rodrigues).

    .. math:: R = I + \sin\theta \, [a]_\times + (1 - \cos\theta) \, [a]_\times^2
    """
    ax, ay, az = (float(a) for a in axis)
    K = np.array([[0.0, -az, ay], [az, 0.0, -ax], [-ay, ax, 0.0]])
    c, s = ca.cos(angle), ca.sin(angle)
    # Write the axis-aligned cases without the zero entries (a smaller graph).
    if (ax, ay, az) == (1.0, 0.0, 0.0):
        return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))
    if (ax, ay, az) == (0.0, 1.0, 0.0):
        return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))
    if (ax, ay, az) == (0.0, 0.0, 1.0):
        return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
    return ca.SX(np.eye(3)) + s * ca.SX(K) + (1 - c) * ca.SX(K @ K)


def _homogeneous(R: ca.SX, t: ca.SX) -> ca.SX:
    return ca.vertcat(ca.horzcat(R, t), ca.horzcat(0, 0, 0, 1))


def joint_motion(joint: pin.JointModel, q_j: ca.SX) -> ca.SX:
    """4x4 symbolic motion X_j(q_j) of a supported 1-DoF joint (joint frame at q_j vs q_j=0).

    Raises ConfigError for unsupported joint types.
    """
    name = joint.shortname()
    if name in REVOLUTE_AXES:
        return _homogeneous(rotation_about_axis(_axis(joint, REVOLUTE_AXES), q_j), ca.SX.zeros(3))
    if name in PRISMATIC_AXES:
        return _homogeneous(ca.SX.eye(3), q_j * ca.SX(_axis(joint, PRISMATIC_AXES)))
    supported = sorted([*REVOLUTE_AXES, *PRISMATIC_AXES])
    raise ConfigError(
        f"joint type {name!r} is not supported by casadi_kinematics; "
        f"supported 1-DoF types: {', '.join(supported)}"
    )


def frame_pose_expr(model: pin.Model, frame: str, joint_names: Sequence[str], q: ca.SX,
                    T_frame_child: np.ndarray | None = None) -> ca.SX:
    """Symbolic 4x4 pose T_base_frame(q) (see :func:`frame_pose_casadi`) for a given ``q``."""
    if not model.existFrame(frame):
        raise UnknownChoiceError("frame", frame, [f.name for f in model.frames])
    joint_names = list(joint_names)
    if len(set(joint_names)) != len(joint_names):
        raise ConfigError(f"joint_names has duplicates: {joint_names}")
    if q.shape != (len(joint_names), 1):
        raise ConfigError(f"q must be a ({len(joint_names)}, 1) symbol, got {q.shape}")
    known = {model.names[i] for i in range(1, model.njoints)}
    for name in joint_names:
        if name not in known:
            raise UnknownChoiceError("joint", name, known)
    column = {name: k for k, name in enumerate(joint_names)}

    fr = model.frames[model.getFrameId(frame)]
    chain = []  # joint ids from the frame's parent joint up to (not including) the universe
    j = fr.parentJoint
    while j > 0:
        chain.append(j)
        j = model.parents[j]
    T = ca.SX.eye(4)
    for j in reversed(chain):
        name = model.names[j]
        joint = model.joints[j]
        if name not in column:
            raise ConfigError(f"joint {name!r} is on the chain to frame {frame!r} but not in "
                              f"joint_names {joint_names}")
        if joint.nq != 1 or joint.nv != 1:
            raise ConfigError(f"joint {name!r} ({joint.shortname()}) has nq={joint.nq}, "
                              f"nv={joint.nv}; only 1-DoF joints are supported")
        M = ca.SX(model.jointPlacements[j].homogeneous)
        T = ca.mtimes([T, M, joint_motion(joint, q[column[name]])])
    T = ca.mtimes(T, ca.SX(fr.placement.homogeneous))
    if T_frame_child is not None:
        T_fc = np.asarray(T_frame_child, dtype=float)
        if T_fc.shape != (4, 4):
            raise ConfigError(f"T_frame_child must be 4x4, got {T_fc.shape}")
        T = ca.mtimes(T, ca.SX(T_fc))
    return T


def frame_pose_casadi(model: pin.Model, frame: str, joint_names: Sequence[str],
                      T_frame_child: np.ndarray | None = None) -> ca.Function:
    """CasADi function ``q (n,) -> T_base_frame (4x4)`` of a fixed-base serial chain.

    Args:
        model: pinocchio model (``pin.buildModelFromUrdf``, fixed base).
        frame: name of a pinocchio frame (URDF link or joint name).
        joint_names: the n joints, in the order of the entries of ``q``. Every joint on the
            path from the root to ``frame`` must be listed; listed joints off that path have
            no effect (zero Jacobian columns).
        T_frame_child: optional constant 4x4 pose of a child frame (e.g. a camera) in
            ``frame`` [m]; the function then returns ``T_base_frame @ T_frame_child``.

    Returns:
        ``casadi.Function`` named ``T_base_<frame>`` with input ``q`` (n x 1) [rad or m] and
        output ``T`` (4 x 4), the homogeneous pose of the frame in the base (universe) frame
        [m]. ``casadi.jacobian`` of its entries gives exact derivatives.

    Raises:
        UnknownChoiceError: unknown frame or joint name.
        ConfigError: a joint on the chain is missing from ``joint_names`` or unsupported.
    """
    q = ca.SX.sym("q", len(joint_names))
    T = frame_pose_expr(model, frame, joint_names, q, T_frame_child)
    return ca.Function(f"T_base_{frame}", [q], [T], ["q"], ["T"])
