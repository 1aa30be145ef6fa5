"""Pre-registered sweep ranges (repro/sweep_ranges.py, issue 19): declared on the config
fields, refused when malformed or outside the field's range, sampled quasi-randomly and
reproducibly, and listed in the report with the commit that declared them."""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from repro.config import describe, param
from repro.errors import ConfigError, UnknownChoiceError
from repro.runs.report import _ranges_section
from repro.sweep_ranges import (
    RANGES_COLUMNS,
    SweepRange,
    declared_ranges,
    ranges_rows,
    sample_variants,
)

REASON = "a physical argument written down first"


@dataclass(frozen=True)
class Cfg:
    gain: float = param(1.0, range=(0.0, 10.0), help="a gain",
                        sweep=SweepRange(0.5, 2.0, reason=REASON))
    stiffness: float = param(2000.0, unit="N/m", range=(100.0, 1e6),
                             sweep=SweepRange(500.0, 20000.0, dist="log-uniform", reason=REASON))
    steps: int = param(10, range=(1, 100),
                       sweep=SweepRange(5, 20, dist="discrete", values=(5, 10, 20), reason=REASON))
    fixed: float = param(3.0, range=(0.0, 5.0), help="a constant")


@pytest.mark.parametrize("kw, error, match", [
    ({"low": 1.0, "high": 0.5}, ConfigError, "low <= high"),
    ({"low": 0.0, "high": math.inf}, ConfigError, "finite"),
    ({"reason": ""}, ConfigError, "needs its reason"),
    ({"dist": "normal"}, UnknownChoiceError, "normal"),
    ({"low": 0.0, "dist": "log-uniform"}, ConfigError, "low > 0"),
    ({"dist": "discrete"}, ConfigError, "non-empty"),
    ({"dist": "discrete", "values": (3.0,)}, ConfigError, "within"),
    ({"values": (1.0,)}, ConfigError, "only for a discrete"),
])
def test_malformed_ranges_are_refused(kw: dict[str, object], error: type, match: str) -> None:
    args: dict[str, object] = {"low": 0.5, "high": 2.0, "reason": REASON, **kw}
    with pytest.raises(error, match=match):
        SweepRange(**args)  # type: ignore[arg-type]


def test_a_range_must_lie_inside_the_fields_range_on_a_scalar_field() -> None:
    with pytest.raises(ConfigError, match="leaves the field's range"):
        param(1.0, range=(0.0, 1.5), sweep=SweepRange(0.5, 2.0, reason=REASON))
    with pytest.raises(ConfigError, match="scalar numeric field"):
        param((1.0, 2.0), range=(0.0, 5.0), sweep=SweepRange(0.5, 2.0, reason=REASON))
    with pytest.raises(ConfigError, match="must be a SweepRange"):
        param(1.0, range=(0.0, 5.0), sweep=(0.5, 2.0))


def test_declared_ranges_and_describe() -> None:
    assert list(declared_ranges(Cfg)) == ["gain", "stiffness", "steps"]
    rows = {r[0]: r[3] for r in describe(Cfg)}
    assert "swept: uniform [0.5, 2]" in rows["gain"] and "swept" not in rows["fixed"]


def test_samples_are_reproducible_inside_the_ranges_and_spread() -> None:
    a, b = sample_variants(Cfg, 16, seed=3), sample_variants(Cfg, 16, seed=3)
    assert a == b and sample_variants(Cfg, 16, seed=4) != a
    g = np.array([v["gain"] for v in a])
    k = np.array([v["stiffness"] for v in a])
    assert g.min() >= 0.5 and g.max() <= 2.0 and k.min() >= 500.0 and k.max() <= 20000.0
    # a scrambled Sobol set of 16 puts one point in each sixteenth of every dimension
    assert sorted(np.floor((g - 0.5) / 1.5 * 16).astype(int)) == list(range(16))
    logk = (np.log(k) - np.log(500.0)) / (np.log(20000.0) - np.log(500.0))
    assert sorted(np.floor(logk * 16).astype(int)) == list(range(16))  # log-uniform
    assert {v["steps"] for v in a} == {5, 10, 20} and all(isinstance(v["steps"], int)
                                                          for v in a)
    assert len(sample_variants(Cfg, 5, seed=0)) == 5
    # a larger sweep extends a smaller one: its first variants are the smaller one's, so a
    # resumed sweep with a larger n keeps every finished variant
    assert sample_variants(Cfg, 2000, seed=3)[:16] == a
    assert sample_variants(Cfg, 1100, seed=0)[:1024] == sample_variants(Cfg, 1024, seed=0)
    with pytest.raises(ConfigError, match="at least one"):
        sample_variants(Cfg, 0, seed=0)

    @dataclass(frozen=True)
    class Plain:
        x: float = param(1.0, range=(0.0, 2.0))

    with pytest.raises(ConfigError, match="declares no sweep range"):
        sample_variants(Plain, 4, seed=0)


def test_ranges_reach_the_report_with_their_declaring_line() -> None:
    exps = [SimpleNamespace(paper="p2020", name="a", config_cls=Cfg),
            SimpleNamespace(paper="p2020", name="b", config_cls=Cfg)]
    rows = ranges_rows(exps)["p2020"]  # type: ignore[arg-type]
    assert [r[1] for r in rows] == ["gain", "stiffness", "steps"]
    gain = rows[0]
    assert gain[0] == "a, b" and gain[2] == "1" and gain[5:7] == ("0.5", "2")
    assert gain[7] == REASON and "tests/test_sweep_ranges.py:" in gain[8]
    assert rows[1][3] == "N/m" and rows[1][4] == "log-uniform"
    text = "\n".join(_ranges_section(rows))
    assert all(c in text for c in RANGES_COLUMNS) and REASON in text
    assert "No sweep range declared yet" in "\n".join(_ranges_section(None))


def test_the_pomares2011_ranges_are_declared_with_reasons() -> None:
    """The first registered ranges (issue 19 item 1): every one inside its field's range
    (checked at import), with a reason, and the committed runs' defaults unchanged."""
    from experiments.pomares2011.config import Exp1Config
    from experiments.pomares2011.exp3_config import Exp3Config

    assert set(declared_ranges(Exp1Config)) >= {"omega_max", "zeta", "dmin", "avoid_omega",
                                                 "push_force"}
    assert set(declared_ranges(Exp3Config)) >= {"friction", "cylinder_mass",
                                                 "contact_stiffness"}
    om = declared_ranges(Exp1Config)["omega_max"]
    assert om.low == pytest.approx(2 * math.pi * 200 / 60) and om.dist == "log-uniform"


def test_a_range_can_apply_to_one_scene_only() -> None:
    """``when``: case 1's board layout is swept in the case-1 experiments, not in case 2's."""

    @dataclass(frozen=True)
    class Scenes:
        case: str = param("a", choices=("a", "b"))
        width: float = param(1.0, range=(0.0, 5.0),
                             sweep=SweepRange(0.5, 2.0, when=(("case", "a"),),
                                              reason="only scene a has a width"))
        noise: float = param(0.1, range=(0.0, 1.0),
                             sweep=SweepRange(0.0, 0.2, reason="every scene has noise"))

    @dataclass(frozen=True)
    class SceneB(Scenes):
        case: str = param("b", choices=("a", "b"))

    assert list(declared_ranges(Scenes)) == ["width", "noise"]
    assert list(declared_ranges(SceneB)) == ["noise"]
    assert set(sample_variants(SceneB, 4, 0)[0]) == {"noise"}
    assert "(only where case = 'a')" in declared_ranges(Scenes)["width"].describe()
    with pytest.raises(ConfigError, match="when="):
        SweepRange(0.0, 1.0, when=("case", "a"), reason="a malformed condition")  # type: ignore[arg-type]


def test_a_range_can_apply_to_some_experiments() -> None:
    """``when`` with a frozenset: one of its values (pomares2011's cylinder size is swept in
    experiment 3 and its ablation, not in the whole task, whose layout is solved for one)."""
    from experiments.pomares2011.exp3_config import Exp3Config, Exp3NoTactileConfig
    from experiments.pomares2011.task import TaskConfig

    @dataclass(frozen=True)
    class Runs:
        run: str = param("a", choices=("a", "b", "c"))
        size: float = param(1.0, range=(0.0, 5.0), sweep=SweepRange(
            0.5, 2.0, when=(("run", frozenset({"a", "b"})),), reason="runs a and b only"))

    @dataclass(frozen=True)
    class RunB(Runs):
        run: str = param("b", choices=("a", "b", "c"))

    @dataclass(frozen=True)
    class RunC(Runs):
        run: str = param("c", choices=("a", "b", "c"))

    assert [list(declared_ranges(c)) for c in (Runs, RunB, RunC)] == [["size"], ["size"], []]
    assert "(only where run is one of ['a', 'b'])" in declared_ranges(Runs)["size"].describe()
    size = {"cylinder_radius", "cylinder_length", "palm_gap", "translation_m"}
    assert size <= set(declared_ranges(Exp3Config))
    assert size <= set(declared_ranges(Exp3NoTactileConfig))
    assert not size & set(declared_ranges(TaskConfig))


def test_each_thomas2024_scene_is_swept_in_its_own_experiments_only() -> None:
    from experiments.thomas2024 import config as c

    case1 = {"case1_turn_deg", "case1_right_lateral", "case1_left_lateral", "case1_right_top",
             "case1_left_top", "case1_right_back", "case1_left_back", "case1_front"}
    case2 = {"case2_start_right_lateral", "case2_start_left_lateral", "case2_start_skew_deg",
             "case2_v_lean_deg", "case2_v_ahead"}
    case3 = {"case3_near_gap", "case3_duration_scale", "case3_aim_offset_deg"}
    sensors = {"proximity_noise", "tof_fov_deg"}
    estimator = {"normal_history", "normal_neighbours"}  # only model (5) uses it: case 2
    assert set(declared_ranges(c.Case1Config)) == case1 | sensors
    assert declared_ranges(c.Case1NoProximityConfig) == declared_ranges(c.Case1Config)
    assert set(declared_ranges(c.Case2Config)) == case2 | sensors | estimator
    assert declared_ranges(c.Case2CoarseConfig) == declared_ranges(c.Case2Config)
    assert set(declared_ranges(c.Case3Config)) == case3 | sensors
    assert set(declared_ranges(c.ParallelConfig)) == {"tof_fov_deg"}  # noise-free by design
    # every default inside its range (the canonical scene is one plausible scene)
    for cls in (c.Case1Config, c.Case2Config, c.Case3Config):
        d = cls()
        for name, rng in declared_ranges(cls).items():
            assert rng.low <= getattr(d, name) <= rng.high, (cls.__name__, name)
    assert declared_ranges(c.Case1Config)["case1_right_lateral"].low == pytest.approx(
        0.07 + 0.08 + 0.005)  # ring 2's radius + its delta* + half a board
