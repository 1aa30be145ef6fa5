"""The faster pieces of pomares2011's 1 kHz loop (issue 15, item 1) compute what the code
before them computed, to the bit (a zero's sign included): the committed traces must not
change. Each is compared with a verbatim copy of the code it replaced, on seeded random
data; timings are not tested (``make bench`` measures them).

- :func:`repro.control.interpolation.quintic`, joint by joint in Python floats;
- the person's joints (body-frame skeleton kept per arm pose), capsules built on owned
  arrays, :func:`repro.planning.capsules.rotation_z_to` and ``Capsule.T_world``;
- the Barrett finger drive, which does not resend the joint commands the motors hold;
- :meth:`repro.sim.closest.ClosestPoints.minima_of` against :meth:`minima`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pybullet as p
import pytest

from experiments.pomares2011 import scene as sc
from repro.control.interpolation import quintic, quintic_reference
from repro.planning.capsules import Capsule, rotation_z_to
from repro.sim import barrett as B
from repro.sim.human import HumanMotion, _ArmPose
from repro.sim.world import World, WorldConfig


def _same(a: object, b: object) -> bool:
    """The same bits (shape and dtype too)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return x.shape == y.shape and x.tobytes() == y.tobytes()


# ---------------------------------------------------------------------------- quintic
def test_quintic_equals_the_numpy_form_to_the_bit() -> None:
    rng = np.random.default_rng(3)
    for i in range(3000):
        n = int(rng.integers(1, 8))
        q0, v0, q1, v1 = (rng.normal(size=n) * rng.choice([1e-9, 1e-3, 1.0, 30.0])
                          for _ in range(4))
        if i % 5 == 0:  # a still joint: zeros, and negative zeros
            v0, v1, q1 = -0.0 * np.ones(n), np.zeros(n), q0.copy()
        T = float(rng.choice([1e-3, 1.0 / 30.0, rng.uniform(1e-4, 0.2)]))
        t = float(rng.choice([0.0, T, 1e-3, T * rng.uniform(-0.5, 1.5)]))
        for a, b in zip(quintic(q0, v0, q1, v1, T, t), quintic_reference(q0, v0, q1, v1, T, t),
                        strict=True):
            assert _same(a, b), (q0, v0, q1, v1, T, t)


def test_quintic_meets_its_ends_and_a_zero_period_is_numpy_s() -> None:
    q0, v0, q1, v1 = np.array([0.1, -0.2]), np.array([0.5, 0.0]), np.array([0.3, 0.1]), \
        np.array([0.0, 1.0])
    q, qd = quintic(q0, v0, q1, v1, 0.5, 0.5)
    assert np.allclose(q, q1, atol=1e-12) and np.allclose(qd, v1, atol=1e-12)
    with np.errstate(all="ignore"):
        a = quintic(q0, v0, q1, v1, 0.0, 0.0)
        b = quintic_reference(q0, v0, q1, v1, 0.0, 0.0)
    assert all(_same(x, y) for x, y in zip(a, b, strict=True))


# ---------------------------------------------------------------------------- the person
def _joints_before(m: HumanMotion, pos: np.ndarray, yaw: float, reach_arm: _ArmPose
                   ) -> dict[str, np.ndarray]:
    """HumanMotion._joints before issue 15's change (verbatim)."""
    b = m.body
    H = b.stature
    z = np.array([0.0, 0.0, 1.0])
    P: dict[str, np.ndarray] = {}
    P["hip"] = np.array([0.0, 0.0, b.hip_height])
    P["neck"] = np.array([0.0, 0.0, b.shoulder_height])
    P["head_top"] = P["neck"] + b.length("head_neck") * z
    L1, L2, L3 = b.length("upper_arm"), b.length("forearm"), b.length("hand")
    for side, tag in ((1.0, "l"), (-1.0, "r")):
        a = reach_arm if side == m._side else _ArmPose()
        e = np.array([math.cos(a.phi), math.sin(a.phi), 0.0])  # arm-plane forward
        u1 = math.sin(a.theta) * e - math.cos(a.theta) * z
        u2 = math.sin(a.theta + a.beta) * e - math.cos(a.theta + a.beta) * z
        P[f"shoulder_{tag}"] = P["neck"] + np.array([0.0, side * b.shoulder_half_width * H,
                                                     0.0])
        P[f"elbow_{tag}"] = P[f"shoulder_{tag}"] + L1 * u1
        P[f"wrist_{tag}"] = P[f"elbow_{tag}"] + L2 * u2
        P[f"fingertip_{tag}"] = P[f"wrist_{tag}"] + L3 * u2
        P[f"hip_{tag}"] = P["hip"] + np.array([0.0, side * b.hip_half_width * H, 0.0])
        P[f"knee_{tag}"] = P[f"hip_{tag}"] - b.length("thigh") * z
        P[f"ankle_{tag}"] = P[f"knee_{tag}"] - b.length("shank") * z
    c, s = math.cos(yaw), math.sin(yaw)
    T_base_body = np.array([[c, -s, 0.0, pos[0]], [s, c, 0.0, pos[1]],
                            [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    T = m.T_world_base @ T_base_body
    return {k: T[:3, :3] @ v + T[:3, 3] for k, v in P.items()}


def _rotation_z_to_before(axis: np.ndarray) -> np.ndarray:
    """repro.planning.capsules.rotation_z_to before issue 15's change (verbatim)."""
    axis = np.asarray(axis, dtype=float)
    n = math.sqrt(float(axis.dot(axis)))
    if n * n <= 1e-12:
        return np.eye(3)
    u = axis / n
    c = u[2]
    if c < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    K = np.array([[0.0, 0.0, u[0]], [0.0, 0.0, u[1]], [-u[0], -u[1], 0.0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def _T_world_before(c: Capsule) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _rotation_z_to_before(c.p1 - c.p0)
    T[:3, 3] = 0.5 * (c.p0 + c.p1)
    return T


@pytest.fixture(scope="module")
def motion() -> HumanMotion:
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    T[:3, 3] = (0.2, -0.1, -0.05)  # a base frame that is not the world's
    return HumanMotion(sc.HUMAN_PATH, T_world_base=T)


def test_joints_and_capsules_equal_the_code_before(motion: HumanMotion) -> None:
    """Every phase (still, walking, reaching, turning), the cached body-frame skeleton and the
    owned-array capsules against the joints and capsules of the code before, and against a
    fresh person (cold caches) at each time."""
    ts = np.concatenate([np.arange(0.0, 25.0, 0.0371), [8.0, 8.001, 8.001, 11.5, 14.0]])
    for t in ts:
        pos, yaw, arm, _ = motion._state(float(t))
        J = motion._joints(pos, yaw, arm)
        J0 = _joints_before(motion, pos, yaw, arm)
        assert J.keys() == J0.keys() and all(_same(J[k], J0[k]) for k in J)
        fresh = HumanMotion(motion.path, T_world_base=motion.T_world_base)
        for (na, a), (nb, b) in zip(motion.capsules(float(t)), fresh.capsules(float(t)),
                                    strict=True):
            assert na == nb and a.radius == b.radius
            assert _same(a.p0, b.p0) and _same(a.p1, b.p1)
            assert _same(a.T_world(), _T_world_before(a))
            assert not a.p0.flags.writeable and not a.p1.flags.writeable


def test_a_body_part_that_did_not_move_keeps_its_capsule(motion: HumanMotion) -> None:
    """Reaching (standing, one arm moving), the other parts' capsules are the same objects
    from step to step (a mover and the tracker then see them unchanged by identity) and the
    reaching arm's are new; walking, every capsule is new. Their values are a fresh
    person's (the test above)."""
    m = HumanMotion(motion.path, T_world_base=motion.T_world_base)
    reach = m.path.t_reach - 0.5 * m.path.reach_duration
    a, b = m.capsules(reach), m.capsules(reach + 1e-3)
    kept = {n for (n, x), (_, y) in zip(a, b, strict=True) if x is y}
    side = "l" if m.path.arm == "left" else "r"
    assert kept == {n for n, _ in a} - {f"{k}_{side}" for k in ("upper_arm", "forearm",
                                                                  "hand")}
    walk = 0.5 * (m.path.t_enter + reach - 0.5 * m.path.reach_duration)
    a, b = m.capsules(walk), m.capsules(walk + 1e-3)
    assert m.phase(walk) == "walk_in" and not any(x is y for (_, x), (_, y) in zip(
        a, b, strict=True))


def test_a_frozen_pose_given_again_is_not_placed_again(monkeypatch: pytest.MonkeyPatch
                                                       ) -> None:
    """Scene.move keeps a read-only array that owns its data as the body's pose and takes
    the same object again as the same pose (no PyBullet call); a writeable array written in
    place, or a read-only view of one, is compared by value and placed when it changed."""
    from repro.sim import scene as scene_mod
    s = scene_mod.Scene(WorldConfig(physics_dt=1e-3, control_dt=1e-3))
    try:
        s.add_capsule("limb", 0.05, 0.3, np.eye(4), (1, 0, 0, 1), moving=True)
        placed: list[int] = []
        real = scene_mod._place
        monkeypatch.setattr(scene_mod, "_place",
                            lambda c, ids, body, T: (placed.append(1), real(c, ids, body, T)))
        T = np.eye(4)
        T[0, 3] = 0.5
        T.setflags(write=False)
        s.move("limb", T)
        s.move("limb", T)
        assert len(placed) == 1 and s["limb"].T_world is T
        W = np.eye(4)
        s.move("limb", W)
        W[1, 3] = 0.25  # written in place after the move
        s.move("limb", W)
        assert len(placed) == 3 and s["limb"].T_world[1, 3] == 0.25
        V = W.view()
        V.setflags(write=False)  # read-only, but its base is not
        s.move("limb", V)
        W[2, 3] = 0.75
        s.move("limb", V)
        assert len(placed) == 4 and s["limb"].T_world[2, 3] == 0.75
        pos = p.getBasePositionAndOrientation(s["limb"].ids[0],
                                              physicsClientId=s.physics.client)[0]
        assert pos == pytest.approx((0.0, 0.25, 0.75))
    finally:
        s.close()


def test_the_skeleton_cache_tells_zero_from_negative_zero(motion: HumanMotion) -> None:
    """An arm pose equal to another but for a zero's sign is a new entry (its arithmetic may
    differ in that sign), and a new pose gives a new skeleton."""
    R = motion.reach_pose
    a, b = _ArmPose(R.phi, 0.0, 0.0), _ArmPose(R.phi, -0.0, -0.0)
    assert a == b
    motion._body_cache.clear()
    motion._body_joints(a)
    motion._body_joints(b)
    assert len(motion._body_cache) == 2
    c = _ArmPose(R.phi, 0.5 * R.theta, 0.5 * R.beta)
    assert not all(_same(x, y) for (_, x), (_, y) in zip(
        motion._body_joints(a), motion._body_joints(c), strict=True))


def test_a_non_finite_state_is_refused(motion: HumanMotion) -> None:
    m = HumanMotion(replace(motion.path))
    m._state = lambda t: (np.array([np.nan, 0.0]), 0.0, _ArmPose(), "walk_in")  # type: ignore[method-assign]
    with pytest.raises(ValueError, match="not finite"):
        m.capsules(1.0)
    with pytest.raises(ValueError, match="finite 4x4"):
        HumanMotion(motion.path, T_world_base=np.full((4, 4), np.nan))


def test_rotation_z_to_equals_the_code_before() -> None:
    rng = np.random.default_rng(5)
    axes = [rng.normal(size=3) * rng.choice([1e-7, 1.0, 10.0]) for _ in range(3000)]
    axes += [np.array(v, dtype=float) for v in ((0, 0, 1), (0, 0, -1), (0, 0, 0),
                                                (-0.0, 0.0, -2.0), (1e-300, 0, -1),
                                                (0.0, -0.0, 1.0), (3, 0, 0))]
    for v in axes:
        assert _same(rotation_z_to(v), _rotation_z_to_before(v)), v
        c = Capsule(np.array([0.1, -0.2, 0.3]), np.array([0.1, -0.2, 0.3]) + v, 0.05)
        assert _same(c.T_world(), _T_world_before(c)), v


# ---------------------------------------------------------------------------- the hand
def test_finger_commands_are_sent_only_when_they_change(monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    """A finger that holds its target sends nothing new (the motors keep their settings);
    a new target, or the same value with the other zero sign, is sent."""
    with World(WorldConfig(physics_dt=1e-3, control_dt=1e-3)) as world:
        body = p.loadURDF(str(B.bh8_urdf_path()), useFixedBase=True,
                          physicsClientId=world.client)
        couplings = B.add_coupling_constraints(body, world.client)
        finger = B.FingerDrive(body, world.client, 1, couplings)
        sent: list[tuple] = []
        real = p.setJointMotorControl2

        def spy(*args, **kw):  # type: ignore[no-untyped-def]
            sent.append((args, tuple(sorted(kw.items()))))
            return real(*args, **kw)

        monkeypatch.setattr(B.p, "setJointMotorControl2", spy)
        m0 = finger.motor_angle
        for _ in range(3):  # hold where it is
            finger.step(m0, 1e-3)
            world.step_physics()
        assert len(sent) == 2  # the first step's two joint commands, then none
        finger.step(m0 + 0.5, 1e-3)  # move: commands again
        assert len(sent) == 4
        assert B._same_floats((True, 0.0, 1.0), (True, 0.0, 1.0))
        assert not B._same_floats((True, 0.0, 1.0), (True, -0.0, 1.0))
        assert not B._same_floats((math.nan,), (math.nan,))


# ---------------------------------------------------------------------------- distances
def test_distance_table_is_each_body_s_full_query_compounds_included() -> None:
    """The scene's per-step distance table (one minima_of call per chain) against one full
    query per PyBullet body, the minimum over a compound's parts, to the bit, over poses."""
    from repro.geometry import trans
    from repro.sim.crs_a465 import CRS_JOINTS, CRS_LIMITS, crs_urdf_path
    from repro.sim.scene import DISTANCE_CAP, Part, Scene

    grey = (0.5, 0.5, 0.5, 1.0)
    scene = Scene(WorldConfig(physics_dt=1e-3, control_dt=1e-3))
    try:
        robot = scene.add_urdf("crs", crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
        scene.add_compound("thing", [Part("box", (0.05, 0.05, 0.05), trans(0.6, 0.0, 0.3)),
                                     Part("sphere", (0.03,), trans(0.0, 0.45, 0.3))],
                           np.eye(4), grey)
        scene.add_capsule("limb", 0.03, 0.2, trans(0.0, -0.45, 0.3), grey, moving=True)
        client = scene.physics.client
        rng = np.random.default_rng(2)
        for k in range(40):
            robot.reset(rng.uniform(-1.0, 1.0, size=6))
            scene.move("limb", trans(*rng.uniform(-0.6, 0.6, size=2), 0.3))
            ((names, values),) = scene.distance_table([robot])
            want = []
            for name in names:
                best = DISTANCE_CAP
                for bid in scene[name].ids:
                    for pt in p.getClosestPoints(robot.body, bid, DISTANCE_CAP,
                                                 physicsClientId=client):
                        best = min(best, pt[8])
                want.append(best)
            assert names == ("thing", "limb") and values == want, k
    finally:
        scene.close()


# ---------------------------------------------------------------------------- small pieces
def _pose_to_pb_before(T: np.ndarray) -> tuple[list[float], list[float]]:
    """repro.sim.world.pose_to_pb before issue 15's change (verbatim)."""
    (r00, r01, r02, x), (r10, r11, r12, y), (r20, r21, r22, z) = np.asarray(
        T, dtype=float)[:3].tolist()
    tr = r00 + r11 + r22
    diag = (r00, r11, r22, tr)
    choice = diag.index(max(diag))
    if choice == 3:
        q = [r21 - r12, r02 - r20, r10 - r01, 1.0 + tr]
    else:
        R = ((r00, r01, r02), (r10, r11, r12), (r20, r21, r22))
        i = choice
        j, k = (i + 1) % 3, (i + 2) % 3
        q = [0.0, 0.0, 0.0, R[k][j] - R[j][k]]
        q[i] = 1.0 - tr + 2.0 * R[i][i]
        q[j] = R[j][i] + R[i][j]
        q[k] = R[k][i] + R[i][k]
    qa = np.array(q)
    qa /= np.sqrt(qa @ qa)
    return [x, y, z], qa.tolist()


def test_pose_to_pb_equals_the_code_before() -> None:
    from scipy.spatial.transform import Rotation

    from repro.sim.world import pose_to_pb

    rng = np.random.default_rng(11)
    Ts = []
    for R in Rotation.random(3000, random_state=rng).as_matrix():
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, rng.normal(size=3)
        Ts.append(T)
    for R in (np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]),
              -np.eye(3), np.zeros((3, 3))):  # (the last: not a rotation, 0/0 as before)
        T = np.eye(4)
        T[:3, :3] = R
        Ts.append(T)
    with np.errstate(all="ignore"):
        for T in Ts:
            a, b = pose_to_pb(T), _pose_to_pb_before(T)
            assert _same(a[0], b[0]) and _same(a[1], b[1]), T


def test_vvs_pinv_is_numpy_s_to_the_bit() -> None:
    from repro.vision.vvs import pinv

    rng = np.random.default_rng(13)
    for i in range(2000):
        A = rng.normal(size=(int(rng.integers(6, 13)), 6)) * rng.choice([1e-4, 1.0, 1e4])
        if i % 7 == 0:
            A[:, 3] = A[:, 1]  # rank deficient: a cut singular value
        if i % 50 == 0:
            A[:] = 0.0
        assert _same(pinv(A), np.linalg.pinv(A))


def test_drive_clips_equal_np_clip_and_torques_are_set_torque_command_s(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from repro.sim.drives import TorqueDrive, clip_nonzero
    from repro.sim.pa10 import ALL_JOINTS, ALL_LIMITS, pa10_urdf_path
    from repro.sim.robot import Robot

    rng = np.random.default_rng(17)
    for _ in range(3000):
        hi = rng.uniform(1e-6, 5.0, 7)
        x = rng.normal(size=7) * 3.0
        pick = rng.integers(0, 6, 7)
        x = np.where(pick == 0, hi, np.where(pick == 1, -hi, np.where(
            pick == 2, -0.0, np.where(pick == 3, np.nan, x))))
        assert _same(clip_nonzero(x, -hi, hi), np.clip(x, -hi, hi))
    with World(WorldConfig(physics_dt=1e-3, control_dt=1e-3)) as world:
        robot = Robot(world, pa10_urdf_path(), ALL_JOINTS, ALL_LIMITS)
        drive = TorqueDrive(robot)
        sent: list[list[float]] = []
        real = p.setJointMotorControlArray
        monkeypatch.setattr(p, "setJointMotorControlArray",
                            lambda *a, **kw: sent.append(list(kw["forces"])) or real(*a, **kw))
        for _ in range(20):
            u = rng.normal(size=robot.n) * 3.0 * np.asarray(ALL_LIMITS.tau_max)
            drive.command(u, 1e-3)
            drive.substep(1, 1e-3)
            robot.set_torque_command(u)  # the definition: clip, then send
            assert _same(sent[-2], sent[-1])


def test_the_runner_s_ground_truth_projection_is_the_camera_s() -> None:
    """Camera.measure keeps the exact projection it made; it equals project_points of the
    same poses (what the runner's audit computed itself before)."""
    from repro.sensors.camera import project_points

    cam = sc_camera()
    target = sc.DOTS
    T_wc = np.eye(4)
    T_wc[:3, 3] = (0.0, 0.0, -0.4)
    T_target = np.eye(4)
    uv, found, Z = cam.measure(-1, T_wc, target, T_target)
    P, uv_true, Z2 = cam.last_projection  # type: ignore[misc]
    assert _same(P, target.points_world(T_target))
    want, Zw = project_points(cam.intrinsics, T_wc, P)
    assert _same(uv_true, want) and _same(Z2, Zw) and _same(Z, Zw)


def sc_camera():  # type: ignore[no-untyped-def]
    from repro.sensors.camera import Camera

    return Camera(sc.INTRINSICS, mode="exact")


def test_position_reference_substeps_send_what_the_numpy_form_sends(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """PositionReferenceDrive's PD substeps (quintic and clip in Python floats) against the
    numpy form (quintic_reference, np.clip, tolist), joint by joint, over commands that
    saturate, stand still (zeros of both signs) and move."""
    from repro.sim.crs_a465 import CRS_JOINTS, CRS_LIMITS, crs_urdf_path
    from repro.sim.drives import PositionReferenceDrive
    from repro.sim.robot import Robot

    with World(WorldConfig(physics_dt=1e-3, control_dt=1e-3)) as world:
        robot = Robot(world, crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
        drive = PositionReferenceDrive(robot, "pd")
        sent: list[tuple[list[float], list[float]]] = []
        real = p.setJointMotorControlArray

        def spy(*a, **kw):  # type: ignore[no-untyped-def]
            if a[2] == p.POSITION_CONTROL:
                sent.append((list(kw["targetPositions"]), list(kw["targetVelocities"])))
            return real(*a, **kw)

        monkeypatch.setattr(p, "setJointMotorControlArray", spy)
        rng = np.random.default_rng(19)
        qd_max = np.asarray(CRS_LIMITS.qd_max)
        for k in range(200):
            u = rng.normal(size=robot.n) * qd_max * (3.0 if k % 4 == 0 else 0.5)
            if k % 5 == 0:
                u = np.where(rng.random(robot.n) < 0.5, -0.0, 0.0)
            q0, v0 = drive.q_ref.copy(), drive.v_ref.copy()
            drive.command(u, 2e-3)  # a 2 ms period: substeps at t = h and 2h
            for i in (1, 2):
                drive.substep(i, 1e-3)
                qr, vr = quintic_reference(q0, v0, drive.q_ref, drive.v_ref, 2e-3, i * 1e-3)
                vr = np.clip(vr, -qd_max, qd_max)
                assert _same(sent[-1][0], qr) and _same(sent[-1][1], vr)
