"""chan2011 experiment layout (issue 19): the declared sweep ranges, the rules that derive the
rest height, the goal's standoff and the start from them, and check_config's refusals."""

from __future__ import annotations

import collections
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from experiments.chan2011 import layout as lay
from experiments.chan2011 import scene as sc
from experiments.chan2011.config import (
    EXPERIMENT,
    ExperimentConfig,
    IBVSConfig,
    IBVSSaturatedConfig,
    SimulationConfig,
    SimulationRenderConfig,
)
from experiments.chan2011.run import build, check_config
from repro.errors import ConfigError
from repro.sweep_ranges import declared_ranges, sample_variants

DEFAULT = ExperimentConfig()


def variant(**kw: object) -> ExperimentConfig:
    return dataclasses.replace(DEFAULT, **kw)


def test_layout_ranges_are_declared_with_reasons_for_the_experiment_only() -> None:
    ranges = declared_ranges(ExperimentConfig)
    assert set(lay.LAYOUT_FIELDS) == set(ranges)  # the simulation's estimate scales excluded
    assert {"conrod_dx", "conrod_dy", "conrod_yaw_deg", "conrod_tilt_deg", "pliers_dx",
            "pliers_dyaw_deg", "start_height", "start_yaw_deg", "points_spread",
            "points_jitter", "points_seed"} <= set(ranges)
    for name, r in ranges.items():
        assert r.when == EXPERIMENT, name
        assert len(r.reason) > 40, name
        assert r.low <= getattr(DEFAULT, name) <= r.high, name  # the default inside its range
    for cls in (SimulationConfig, SimulationRenderConfig, IBVSConfig, IBVSSaturatedConfig):
        assert not set(declared_ranges(cls)) & set(lay.LAYOUT_FIELDS), cls.__name__


def test_defaults_reproduce_the_committed_experiment_setting() -> None:
    """The rules give today's constants: rest z 0.1789 m, standoff 0.38 m, the printed q0,
    the points, the obstacles; the derived setting equals scene.SETTINGS['experiment']."""
    x, y, _ = sc.CONROD_MEASURED
    assert lay.conrod_rest_z(x, y, 135.0, 12.0, sc.OBSTACLES) == sc.CONROD_REST_Z == 0.1789
    assert lay.conrod_points(1.0, 0.0, 0) is sc.CONROD_POINTS
    got, ref = lay.setting_for(DEFAULT), sc.SETTINGS["experiment"]
    np.testing.assert_array_equal(got.T_object_actual, ref.T_object_actual)
    np.testing.assert_array_equal(got.T_object_actual, sc.T_CONROD_EXPERIMENT)
    np.testing.assert_array_equal(got.T_object_estimate, ref.T_object_estimate)
    assert got.standoff == ref.standoff == 0.38
    assert got.q0_deg == ref.q0_deg == sc.EXPERIMENT_Q0_DEG
    assert got.target is sc.CONROD
    for a, b in zip(got.obstacles, ref.obstacles, strict=True):
        assert a.name == b.name and tuple(a.size) == tuple(b.size)
        np.testing.assert_array_equal(a.T_world, b.T_world)
    assert lay.setting_for(SimulationConfig()) is sc.SETTINGS["simulation"]


def test_the_committed_start_is_the_rules_ik_solution_to_its_printed_precision() -> None:
    """Away from the committed pose the start is the rule's IK solution rounded to 0.01 deg;
    at the committed pose that solution is within 0.05 deg of EXPERIMENT_Q0_DEG (an earlier
    IK of the same rule, kept so the committed runs are unchanged)."""
    from repro.sim.crs_a465 import CRS_JOINTS, CRS_LIMITS, crs_urdf_path
    from repro.sim.robot import Robot
    from repro.sim.world import World

    st = sc.SETTINGS["experiment"]
    P = sc.CONROD.points_world(st.T_object_actual)
    with World() as w:
        robot = Robot(w, crs_urdf_path(), CRS_JOINTS, CRS_LIMITS)
        q_branch = lay.goal_nearest_home(robot, sc.goal_flange_pose(st))
        h, yaw = sc.OVERHEAD_START
        assert lay.overhead_start(robot, P, h, yaw, q_branch) == sc.EXPERIMENT_Q0_DEG
        nudged = lay.overhead_start(robot, P, h, yaw + 1e-9, q_branch)  # the IK itself
    assert nudged != sc.EXPERIMENT_Q0_DEG
    np.testing.assert_allclose(nudged, sc.EXPERIMENT_Q0_DEG, atol=0.05)


def _centroid(s: sc.Setting) -> np.ndarray:
    return (s.T_object_actual @ np.append(sc.CONROD_CENTROID, 1.0))[:3]


def test_a_moved_pliers_moves_the_rest_height_and_the_dcc_boxes(tmp_path: Path) -> None:
    """Moving the pliers (the conrod rests on them) changes the rest height and the boxes of
    the scene and of the DCC model; moving the conrod moves its centroid and its height."""
    base = lay.setting_for(DEFAULT)
    moved = lay.setting_for(variant(pliers_dx=0.01, pliers_dyaw_deg=3.0))
    pl0, pl1 = (next(b for b in s.obstacles if b.name == "pliers") for s in (base, moved))
    np.testing.assert_allclose(pl1.T_world[:3, 3] - pl0.T_world[:3, 3], (0.01, 0.0, 0.0),
                               atol=1e-15)
    np.testing.assert_allclose(np.degrees(np.arctan2(pl1.T_world[1, 0], pl1.T_world[0, 0])),
                               63.0, atol=1e-9)
    assert _centroid(moved)[2] != _centroid(base)[2]  # rests on the moved pliers
    conrod = lay.setting_for(variant(conrod_dx=-0.01, conrod_tilt_deg=8.0))
    np.testing.assert_allclose(_centroid(conrod)[:2], (0.120, 0.460), atol=1e-12)
    assert _centroid(conrod)[2] != _centroid(base)[2]
    # the run's scene and DCC model use the config's boxes (ibvs: no NMPC to build)
    ep = build(variant(pliers_dx=0.01, pliers_dyaw_deg=3.0, controller="ibvs",
                       camera_mode="exact", snapshot_period=0.0), tmp_path / "run")
    try:
        dcc_pliers = next(b for b in ep.controller.dcc.obstacles if b.name == "pliers")  # type: ignore[attr-defined]
        np.testing.assert_array_equal(dcc_pliers.T_world, pl1.T_world)
        np.testing.assert_array_equal(ep.scene["pliers"].T_world, pl1.T_world)
        np.testing.assert_array_equal(ep.scene["conrod"].T_world, moved.T_object_actual)
    finally:
        ep.scene.close()


def test_the_rest_height_touches_without_penetrating_for_a_variant() -> None:
    """The rule for a moved conrod: touching within 0.1 mm (the grid), 0.1 mm lower it
    penetrates."""
    import pybullet as p

    from repro.sim.scene import Scene
    from repro.sim.world import WorldConfig

    x, y, yaw, tilt = 0.140, 0.455, 130.0, 9.0
    z = lay.conrod_rest_z(x, y, yaw, tilt, sc.OBSTACLES)
    for zz, want_free in ((z, True), (z - 1e-4, False)):
        with Scene(WorldConfig(physics_dt=1e-3, control_dt=0.1)) as s:
            for b in sc.OBSTACLES:
                s.add_box(b.name, b.size, b.T_world, sc.OBSTACLE_RGBA)
            s.add_compound("conrod", lay.conrod_parts(), lay.conrod_pose(x, y, zz, yaw, tilt),
                           sc.CONROD_RGBA, obstacle=False)
            d = min(pt[8] for i in s["conrod"].ids for b in sc.OBSTACLES for j in s[b.name].ids
                    for pt in p.getClosestPoints(i, j, 1.0, physicsClientId=s.physics.client))
        assert (d >= 0.0) == want_free
        if want_free:
            assert d < 5e-4


def test_the_dots_jitter_is_seeded_and_stays_on_the_faces() -> None:
    a = lay.conrod_points(1.0, 0.002, 7)
    np.testing.assert_array_equal(a, lay.conrod_points(1.0, 0.002, 7))
    assert not np.array_equal(a, lay.conrod_points(1.0, 0.002, 8))
    moved = np.linalg.norm(a[:, :2] - sc.CONROD_POINTS[:, :2], axis=1)
    assert 0 < moved.max() <= 0.002 + 1e-15
    np.testing.assert_array_equal(a[:, 2], sc.CONROD_POINTS[:, 2])  # on their faces' planes
    assert lay.points_off_faces(sc.CONROD_POINTS, sc.CONROD.dot_radius) == []
    s = lay.setting_for(variant(points_spread=0.9, points_jitter=0.001, points_seed=3))
    np.testing.assert_array_equal(s.target.points_target, lay.conrod_points(0.9, 0.001, 3))


@pytest.mark.parametrize(("kw", "words"), [
    (dict(conrod_dx=-0.1), "penetrates an obstacle"),  # onto textbook 1
    (dict(points_spread=1.5), "leaves its face"),
    (dict(points_spread=0.3), "overlap"),
    (dict(start_height=0.2, start_yaw_deg=370.0), "inside the start image"),
    (dict(start_yaw_deg=330.0), "out of reach"),
    (dict(conrod_tilt_deg=20.0), "out of the CRS-A465's reach"),
])
def test_check_config_refuses_a_scene_the_paper_could_not_have(kw: dict, words: str) -> None:
    check_config(DEFAULT)
    with pytest.raises(ConfigError, match=words):
        check_config(variant(**kw))


def test_the_simulation_refuses_an_experiment_layout_field() -> None:
    check_config(SimulationConfig())
    with pytest.raises(ConfigError, match="applies only to setting='experiment'"):
        check_config(dataclasses.replace(SimulationConfig(), conrod_dx=0.01))


REFUSAL_KINDS = {  # a phrase of each ConfigError of experiments/chan2011/layout.py -> kind
    "CRS-A465's reach": "goal out of reach", "out of reach from the goal": "start out of reach",
    "inside the start image": "point out of the start view", "penetrates": "conrod penetrates",
    "rests on nothing": "conrod unsupported", "leaves its face": "dot off its face",
    "overlap": "dots overlap", "collides": "robot collides", "branch": "off the IK branch",
    "not reachable from": "goal not reachable from the start",
}


def refusal_kind(message: str) -> str:
    return next((k for phrase, k in REFUSAL_KINDS.items() if phrase in message), message)


def _outcomes(overrides: list[dict]) -> collections.Counter[str]:
    out: collections.Counter[str] = collections.Counter()
    for ov in overrides:
        try:
            check_config(variant(**ov))
            out["accepted"] += 1
        except ConfigError as exc:  # any other exception fails the test
            out[refusal_kind(str(exc))] += 1
    return out


def test_every_sampled_variant_is_accepted_or_refused_with_a_config_error() -> None:
    """16 Sobol variants of the declared box, and every one-at-a-time corner of it (each range
    at its low and its high end, the others at their defaults): each is either accepted or
    refused with a ConfigError of a known kind (never another exception)."""
    sobol = _outcomes(sample_variants(ExperimentConfig, 16, seed=0))
    corners = []
    for name, r in declared_ranges(ExperimentConfig).items():
        integer = isinstance(getattr(DEFAULT, name), int)
        corners += [{name: int(v) if integer else v} for v in (r.low, r.high)]
    edges = _outcomes(corners)
    print("16 Sobol variants:", dict(sobol), "| 42 corners:", dict(edges))
    for counts in (sobol, edges):
        assert set(counts) <= {"accepted", *REFUSAL_KINDS.values()}, counts
    assert sobol["accepted"] >= 6 and edges["accepted"] >= 30
