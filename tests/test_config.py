"""repro.config: param metadata, validation, CLI overrides, describe."""

from __future__ import annotations  # string annotations must be resolved via get_type_hints

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import pytest

from repro.config import apply_overrides, config_keys, describe, param, validate
from repro.errors import ConfigError, UnknownChoiceError


@dataclass(frozen=True)
class Camera:
    fu: float = param(500.0, unit="px", range=(1.0, 5000.0), help="focal length")
    width: int = param(640, unit="px", range=(1, 4096))


@dataclass(frozen=True)
class Cfg:
    gain: float = param(0.4, unit="1/s", range=(0.0, 100.0), help="IBVS gain lambda_4p")
    steps: int = param(100, range=(1, 10000))
    video: bool = param(False)
    solver: str = param("proxsuite", choices=("proxsuite", "osqp"), help="QP solver")
    label: str = param("run")
    q0: tuple[float, ...] = param((0.0, -60.0, 0.0), unit="deg", range=(-180.0, 180.0))
    xy: tuple[float, float] = param((1.0, 2.0), unit="m", range=(-10.0, 10.0))
    names: tuple[str, ...] = param(("a",), choices=("a", "b", "c"))
    limit: float | None = param(None, range=(0.0, 5.0))
    path: Path = param(Path("x"))
    camera: Camera = param(Camera())


# --------------------------------------------------------------------------- param


def test_param_stores_metadata_and_tuple_default_factory():
    fields = {f.name: f for f in dataclasses.fields(Cfg)}
    gain = fields["gain"]
    assert gain.default == 0.4
    assert gain.metadata["unit"] == "1/s"
    assert gain.metadata["range"] == (0.0, 100.0)
    assert gain.metadata["help"] == "IBVS gain lambda_4p"
    assert fields["solver"].metadata["choices"] == ("proxsuite", "osqp")
    assert fields["q0"].default is dataclasses.MISSING
    assert fields["q0"].default_factory() == (0.0, -60.0, 0.0)


def test_param_list_default_is_not_shared():
    @dataclass(frozen=True)
    class WithList:
        xs: list = param(["a", "b"])

    a, b = WithList(), WithList()
    assert a.xs == ["a", "b"]
    assert a.xs is not b.xs


def test_param_rejects_default_outside_its_own_range_or_choices():
    with pytest.raises(ConfigError, match=r"\[0.0, 1.0\]"):
        param(-1.0, range=(0.0, 1.0))
    with pytest.raises(UnknownChoiceError, match="osqp, proxsuite"):
        param("gurobi", choices=("proxsuite", "osqp"))
    with pytest.raises(ConfigError, match="low > high"):
        param(1.0, range=(2.0, 1.0))


# --------------------------------------------------------------------------- validate


def test_validate_accepts_defaults():
    validate(Cfg())


def test_validate_reports_field_value_and_range():
    with pytest.raises(ConfigError) as info:
        validate(Cfg(gain=-0.5))
    msg = str(info.value)
    assert "gain" in msg and "-0.5" in msg and "[0.0, 100.0]" in msg


def test_validate_nested_and_tuple_elements():
    with pytest.raises(ConfigError, match=r"camera\.fu.*\[1\.0, 5000\.0\]"):
        validate(Cfg(camera=Camera(fu=0.0)))
    with pytest.raises(ConfigError, match=r"q0\[1\]=-200\.0.*\[-180\.0, 180\.0\]"):
        validate(Cfg(q0=(0.0, -200.0)))


def test_validate_choices_lists_valid_ones():
    with pytest.raises(UnknownChoiceError) as info:
        validate(Cfg(solver="gurobi"))
    assert "'gurobi'" in str(info.value)
    assert "osqp, proxsuite" in str(info.value)
    assert info.value.choices == ["osqp", "proxsuite"]


def test_validate_requires_a_dataclass_instance():
    with pytest.raises(ConfigError, match="dataclass"):
        validate(Cfg)


# --------------------------------------------------------------------------- overrides


@pytest.mark.parametrize(
    ("item", "field", "expected"),
    [
        ("gain=0.75", "gain", 0.75),
        ("gain=1e-2", "gain", 0.01),
        ("gain=3", "gain", 3.0),
        ("steps=250", "steps", 250),
        ("video=true", "video", True),
        ("video=YES", "video", True),
        ("video=1", "video", True),
        ("video=false", "video", False),
        ("video=no", "video", False),
        ("video=0", "video", False),
        ("solver=osqp", "solver", "osqp"),
        ("label=hello world", "label", "hello world"),
        ("label=a=b", "label", "a=b"),
        ("q0=0,-60,0", "q0", (0.0, -60.0, 0.0)),
        ("q0=10, 20.5", "q0", (10.0, 20.5)),
        ("q0=(1,2,3)", "q0", (1.0, 2.0, 3.0)),
        ("q0=", "q0", ()),
        ("xy=3,4", "xy", (3.0, 4.0)),
        ("names=b,c", "names", ("b", "c")),
        ("limit=2.5", "limit", 2.5),
        ("limit=none", "limit", None),
        ("path=out/dir", "path", Path("out/dir")),
    ],
)
def test_override_parses_every_supported_type(item, field, expected):
    cfg = apply_overrides(Cfg(), [item])
    value = getattr(cfg, field)
    assert value == expected
    assert type(value) is type(expected)


def test_override_returns_a_copy_and_applies_in_order():
    base = Cfg()
    cfg = apply_overrides(base, ["gain=1", "steps=5", "gain=2"])
    assert (cfg.gain, cfg.steps) == (2.0, 5)
    assert base.gain == 0.4  # untouched
    assert apply_overrides(base, []) == base


def test_override_nested_key():
    cfg = apply_overrides(Cfg(), ["camera.fu=600", "camera.width=800"])
    assert cfg.camera == Camera(fu=600.0, width=800)
    assert isinstance(cfg.camera.fu, float)
    assert Cfg().camera.fu == 500.0


@pytest.mark.parametrize("item", ["steps=1_0", "gain=1_0.5", "steps=0x10", "gain=0x10",
                                  "steps=\u0661\u0662", "gain=1e", "steps=1e3", "steps=5.0",
                                  "gain=..5", "q0=1_0,2"])
def test_override_takes_plain_decimal_numbers_only(item):
    """Python's int()/float() read ``1_0`` as 10 and other scripts' digits: a value must
    mean what it reads, so only plain decimals parse (issue 16)."""
    with pytest.raises(ConfigError, match="cannot parse"):
        apply_overrides(Cfg(), [item])


@pytest.mark.parametrize(("item", "field", "expected"),
                         [("gain=+.5e-3", "gain", 5e-4), ("steps=+7", "steps", 7),
                          ("q0=-7,+.5", "q0", (-7.0, 0.5)),
                          ("gain= 2 ", "gain", 2.0), ("gain=5.", "gain", 5.0)])
def test_plain_decimal_forms_parse(item, field, expected):
    assert getattr(apply_overrides(Cfg(), [item]), field) == expected


def test_override_malformed():
    with pytest.raises(ConfigError, match=r"malformed override 'gain'.*key=value"):
        apply_overrides(Cfg(), ["gain"])
    with pytest.raises(ConfigError, match="malformed"):
        apply_overrides(Cfg(), ["=3"])


def test_override_unknown_key_lists_valid_keys():
    with pytest.raises(UnknownChoiceError) as info:
        apply_overrides(Cfg(), ["gian=1"])
    msg = str(info.value)
    assert "'gian'" in msg
    for key in ("gain", "steps", "camera.fu", "camera.width"):
        assert key in msg


def test_override_unknown_nested_key():
    with pytest.raises(UnknownChoiceError, match=r"camera\.fv.*camera\.fu"):
        apply_overrides(Cfg(), ["camera.fv=1"])
    with pytest.raises(UnknownChoiceError, match=r"gain\.x"):
        apply_overrides(Cfg(), ["gain.x=1"])


def test_override_whole_nested_config_is_refused():
    with pytest.raises(ConfigError, match=r"nested config.*camera\.fu"):
        apply_overrides(Cfg(), ["camera=1"])


@pytest.mark.parametrize(
    ("item", "expected_type"),
    [
        ("gain=fast", "float"),
        ("steps=2.5", "int"),
        ("q0=0,x,0", r"tuple\[float, \.\.\.\]"),
        ("limit=abc", r"float \| None"),
    ],
)
def test_override_bad_value_names_expected_type(item, expected_type):
    key, _, text = item.partition("=")
    with pytest.raises(ConfigError, match=rf"{key}.*{text!r}.*expected {expected_type}"):
        apply_overrides(Cfg(), [item])


def test_override_bad_bool_lists_spellings():
    with pytest.raises(ConfigError, match=r"expected bool.*true.*yes.*false.*no"):
        apply_overrides(Cfg(), ["video=maybe"])


def test_override_fixed_length_tuple():
    with pytest.raises(ConfigError, match=r"xy.*2 comma-separated values, got 3"):
        apply_overrides(Cfg(), ["xy=1,2,3"])


def test_override_out_of_range_names_range():
    with pytest.raises(ConfigError) as info:
        apply_overrides(Cfg(), ["gain=-1"])
    msg = str(info.value)
    assert "gain=-1.0" in msg and "[0.0, 100.0]" in msg
    with pytest.raises(ConfigError, match=r"camera\.width=0.*\[1, 4096\]"):
        apply_overrides(Cfg(), ["camera.width=0"])
    with pytest.raises(ConfigError, match=r"q0\[0\]=999\.0"):
        apply_overrides(Cfg(), ["q0=999"])


def test_override_bad_choice_lists_choices():
    with pytest.raises(UnknownChoiceError) as info:
        apply_overrides(Cfg(), ["solver=gurobi"])
    assert "'gurobi'" in str(info.value) and "osqp, proxsuite" in str(info.value)
    with pytest.raises(UnknownChoiceError, match="a, b, c"):
        apply_overrides(Cfg(), ["names=a,z"])


def test_override_in_locally_defined_config_infers_types():
    # get_type_hints cannot resolve annotations of a class local to a function;
    # the parser falls back on the type of the current value.
    @dataclass(frozen=True)
    class Local:
        k: float = param(1.0, range=(0.0, 10.0))
        n: int = param(3, range=(0, 10))
        ts: tuple[float, ...] = param((1.0,), range=(0.0, 10.0))

    cfg = apply_overrides(Local(), ["k=2", "n=4", "ts=1,2"])
    assert (cfg.k, cfg.n, cfg.ts) == (2.0, 4, (1.0, 2.0))
    with pytest.raises(ConfigError, match=r"\[0.0, 10.0\]"):
        apply_overrides(Local(), ["k=11"])


# --------------------------------------------------------------------------- describe


def test_describe_rows():
    rows = {row[0]: row for row in describe(Cfg)}
    assert rows["gain"] == ("gain", "float", "0.4", "IBVS gain lambda_4p [1/s]; range [0.0, 100.0]")
    assert rows["q0"][1] == "tuple[float, ...]"
    assert rows["q0"][2] == "(0.0, -60.0, 0.0)"
    assert rows["solver"][3] == "QP solver; choices: proxsuite, osqp"
    assert rows["limit"][1] == "float | None"
    assert rows["camera.fu"] == (
        "camera.fu",
        "float",
        "500.0",
        "focal length [px]; range [1.0, 5000.0]",
    )
    assert "camera" not in rows
    assert config_keys(Cfg) == [row[0] for row in describe(Cfg())]


def test_describe_rejects_non_dataclass():
    with pytest.raises(ConfigError, match="not a dataclass"):
        describe(int)


# --------------------------------------------------------------------------- finite ranges


@pytest.mark.parametrize(
    "make",
    [
        lambda: param(0.4),  # a float without a range
        lambda: param(3),  # an int
        lambda: param((0.04, 0.08), unit="m"),  # a tuple of numbers
        lambda: param(0.4, range=(0.0, None)),  # open-ended
        lambda: param(0.4, range=(None, 1.0)),
        lambda: param(0.4, range=(0.0, float("inf"))),
        lambda: param(0.4, range=(float("nan"), 1.0)),
    ],
)
def test_param_refuses_numeric_field_without_finite_range(make):
    with pytest.raises(ConfigError, match="range"):
        make()


def test_param_refusal_happens_when_the_class_is_defined():
    with pytest.raises(ConfigError, match=r"param\(0.01, help='mu'\) is numeric and needs range"):

        @dataclass(frozen=True)
        class NoRange:
            mu: float = param(0.01, help="mu")


def test_non_numeric_fields_need_no_range():
    @dataclass(frozen=True)
    class Plain:
        on: bool = param(True)
        name: str = param("a")
        names: tuple[str, ...] = param(("a",), choices=("a", "b"))

    validate(Plain())


def test_validate_refuses_an_undeclared_numeric_field():
    @dataclass(frozen=True)
    class Hidden:
        limit: float | None = param(None)  # numeric by its annotation only

    with pytest.raises(ConfigError, match=r"Hidden.limit is numeric but declares no range"):
        validate(Hidden())


def test_low_open_range():
    @dataclass(frozen=True)
    class Gains:
        k: float = param(1.0, unit="1/s", range=(0.0, 100.0), low_open=True)

    with pytest.raises(ConfigError, match=r"k=0.0 is out of range; allowed: \(0.0, 100.0\]"):
        apply_overrides(Gains(), ["k=0"])
    assert apply_overrides(Gains(), ["k=100"]).k == 100.0
    assert describe(Gains)[0][3] == "[1/s]; range (0.0, 100.0]"
    with pytest.raises(ConfigError, match="empty"):
        param(1.0, range=(1.0, 1.0), low_open=True)


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("gain=nan", "NaN is not allowed for gain; allowed: [0.0, 100.0]"),
        ("gain=NaN", "NaN is not allowed for gain"),
        ("gain=inf", "inf is not allowed for gain; allowed: [0.0, 100.0]"),
        ("gain=-inf", "-inf is not allowed for gain"),
        ("gain=Infinity", "inf is not allowed for gain"),
        ("q0=0,inf,0", "inf is not allowed for q0[1]"),
        ("xy=nan,1", "NaN is not allowed for xy[0]"),
        ("limit=inf", "inf is not allowed for limit"),
        ("camera.fu=inf", "inf is not allowed for camera.fu"),
        ("steps=inf", "inf is not allowed for steps"),
        ("steps=nan", "NaN is not allowed for steps"),
    ],
)
def test_override_rejects_non_finite_values_by_name(item, message):
    with pytest.raises(ConfigError) as info:
        apply_overrides(Cfg(), [item])
    assert str(info.value).startswith(message)
    assert "cannot parse" not in str(info.value)


def test_validate_rejects_non_finite_values_set_in_code():
    with pytest.raises(ConfigError, match=r"^NaN is not allowed for gain"):
        validate(dataclasses.replace(Cfg(), gain=float("nan")))
    with pytest.raises(ConfigError, match=r"^inf is not allowed for q0\[2\]"):
        validate(dataclasses.replace(Cfg(), q0=(0.0, 1.0, float("inf"))))
