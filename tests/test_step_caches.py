"""The per-step caches of the 1 kHz loop (issue 15): each one must give the values the
uncached code gives, bit for bit, and must notice when its input changes.

- Robot joint states: read once per physics step; a step, a reset or
  :func:`joint_states_changed` makes them stale.
- g(q) of the last q, M(q) from a second pinocchio workspace (the kinematics cache stays
  valid): compared with pinocchio called directly.
- the hybrid controller's W of the last L_s; the scene's list of other bodies (until a body
  is added); python-fcl objects of capsules seen before.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from repro.control.hybrid_vs import HybridVSConfig, HybridVSController, weight_matrix
from repro.planning.capsules import Capsule, min_distance
from repro.sim.pa10 import ALL_JOINTS, ALL_LIMITS, MINI_JOINTS, pa10_urdf_path
from repro.sim.robot import JointGroup, Robot, joint_states_changed
from repro.sim.scene import Scene
from repro.sim.world import World, WorldConfig

Q1 = np.linspace(-0.4, 0.5, len(ALL_JOINTS))  # ours: any joint vector inside the limits


@pytest.fixture()
def chain():  # type: ignore[no-untyped-def]
    with World(WorldConfig(physics_dt=1e-3, control_dt=1e-3)) as world:
        yield Robot(world, pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS)


def _pb_q(robot: Robot) -> np.ndarray:
    return np.array([s[0] for s in p.getJointStates(robot.body, robot.pb_joints,
                                                    physicsClientId=robot.client)])


def test_joint_states_follow_steps_resets_and_outside_changes(chain: Robot) -> None:
    chain.reset(Q1)
    assert np.array_equal(chain.q(), Q1)
    q = chain.q()
    q[0] = 99.0  # a copy: the cache is not changed through it
    assert chain.q()[0] == Q1[0]
    chain.torque_mode()
    chain.world.step_physics()  # gravity moves the arm
    assert not np.array_equal(chain.q(), Q1)
    assert np.array_equal(chain.q(), _pb_q(chain))
    assert np.array_equal(chain.qd(), [s[1] for s in p.getJointStates(
        chain.body, chain.pb_joints, physicsClientId=chain.client)])
    # behind the module's back: stale until told
    p.resetJointState(chain.body, chain.pb_joints[0], 0.25, physicsClientId=chain.client)
    joint_states_changed()
    assert chain.q()[0] == 0.25
    # a group reads the chain's states
    mini = JointGroup(chain, "mini", MINI_JOINTS, "mini_")
    chain.reset(Q1 + 0.1)
    assert np.array_equal(mini.q(), (Q1 + 0.1)[mini.idx])


def test_gravity_and_mass_matrix_equal_pinocchio(chain: Robot) -> None:
    model, data = chain.model, chain.model.createData()
    for q in (Q1, -Q1, Q1):  # back to a q seen before: the memo must not serve -Q1's
        qp = np.zeros(model.nq)
        qp[chain._pin_q_idx] = q
        model.gravity.linear = np.asarray(chain.world.config.gravity) @ chain.T_world_base[:3, :3]
        g = np.asarray(pin.computeGeneralizedGravity(model, data, qp))[chain._pin_q_idx]
        assert np.array_equal(chain.gravity_torques(q), g)
        M = pin.crba(model, data, qp)
        M = (np.triu(M) + np.triu(M, 1).T)[np.ix_(chain._pin_q_idx, chain._pin_q_idx)]
        assert np.array_equal(chain.mass_matrix(q), M)
    g = chain.gravity_torques(Q1)
    g[:] = 0.0  # a copy
    assert np.any(chain.gravity_torques(Q1) != 0.0)


def test_dynamics_leave_the_kinematics_cache_valid(chain: Robot) -> None:
    T = chain.frame_pose("mini_camera_optical", Q1)
    chain.mass_matrix(-Q1)
    chain.gravity_torques(-Q1)
    assert np.array_equal(chain.frame_pose("mini_camera_optical", Q1), T)
    assert not np.array_equal(chain.frame_pose("mini_camera_optical", -Q1), T)


def test_weight_matrix_memo_follows_its_input() -> None:
    rng = np.random.default_rng(3)
    ctrl = HybridVSController(HybridVSConfig(np.zeros(8), 1.0, np.eye(3), 0.1, 0.3))
    L1, L2 = rng.normal(size=(8, 6)), rng.normal(size=(8, 6))
    rows = list(range(8))
    assert np.array_equal(ctrl._weight_matrix(L1, rows), weight_matrix(L1, rows))
    assert np.array_equal(ctrl._weight_matrix(L2, rows), weight_matrix(L2, rows))
    assert np.array_equal(ctrl._weight_matrix(L2, [1]), weight_matrix(L2, [1]))


def test_primary_task_memo_gives_the_uncached_torques() -> None:
    """HybridVSController.step keeps (e_s, W, e1, e) of the last bit-identical (s, L_s, rows):
    each step equals a fresh controller's, across held and new frames, the secondary task
    switching on and off, and M = None (V not computed, all else the same)."""
    rng = np.random.default_rng(5)
    cfg = HybridVSConfig(rng.normal(size=8), 2.0, np.diag([0.3, 0.2, 0.1]), 0.5, 0.3,
                         avoid_rows=(1,))
    ctrl = HybridVSController(cfg)
    frames = [(rng.normal(size=8), rng.normal(size=(8, 6))) for _ in range(3)]
    M = np.diag([1.0, 2.0, 3.0])
    for k in range(24):
        s, L = frames[(k // 4) % 3]  # a frame held for 4 steps, then the next
        qd, J_g, G = rng.normal(size=3), rng.normal(size=(6, 3)), rng.normal(size=3)
        dist = 0.2 if k % 7 < 3 else 0.5  # the secondary task on and off
        grad = rng.normal(size=6)
        tau, diag = ctrl.step(np.zeros(3), qd, s.copy(), L.copy(), J_g, G, None, dist, grad)
        tau_ref, ref = HybridVSController(cfg).step(np.zeros(3), qd, s, L, J_g, G, M, dist,
                                                    grad)
        assert tau.tobytes() == tau_ref.tobytes()
        for key in ("e", "e_s", "e1", "rows", "active", "e2"):
            assert np.array_equal(diag[key], ref[key]), key
        assert math.isnan(diag["V"]) and math.isfinite(ref["V"])
    with pytest.raises(ValueError, match="finite"):  # a new frame is still validated
        ctrl.step(np.zeros(3), qd, np.full(8, np.nan), L, J_g, G, None)


def test_scene_others_follow_added_bodies() -> None:
    scene = Scene(WorldConfig(physics_dt=1e-3, control_dt=1e-3))
    try:
        robot = scene.add_urdf("pa10", pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS, np.eye(4))
        T = np.eye(4)
        T[:3, 3] = (0.6, 0.3, 0.1)
        scene.add_box("a", (0.1, 0.1, 0.1), T, (1.0, 0.0, 0.0, 1.0))
        assert scene._others(robot)[0] == ("a",)
        T[:3, 3] = (0.5, -0.3, 0.2)
        scene.add_box("b", (0.1, 0.1, 0.1), T, (0.0, 1.0, 0.0, 1.0))
        assert scene._others(robot)[0] == ("a", "b")
        assert set(scene.distances(robot)) == {"a", "b"}
    finally:
        scene.close()


def test_fcl_objects_of_new_capsules_are_new() -> None:
    a = Capsule(np.zeros(3), np.array([0.0, 0.0, 0.2]), 0.05)
    b = Capsule(np.array([0.3, 0.0, 0.0]), np.array([0.3, 0.0, 0.2]), 0.05)
    assert min_distance([a], [b], "fcl")[0] == pytest.approx(0.2, abs=1e-12)
    c = Capsule(np.array([0.5, 0.0, 0.0]), np.array([0.5, 0.0, 0.2]), 0.05)
    assert min_distance([a], [c], "fcl")[0] == pytest.approx(0.4, abs=1e-12)
    assert min_distance([a], [b], "fcl")[0] == pytest.approx(0.2, abs=1e-12)
