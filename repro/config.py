"""Experiment configurations: frozen dataclasses whose fields carry metadata.

A config field is declared with :func:`param`, which records a unit, an
allowed range and/or a finite set of choices, and a help string in the
field's ``metadata``::

    @dataclass(frozen=True)
    class Case1Config:
        gain: float = param(0.4, unit="1/s", range=(0.0, 100.0), low_open=True,
                            help="IBVS gain lambda_4p")
        solver: str = param("proxsuite", choices=("proxsuite", "osqp"), help="QP solver")
        q0: tuple[float, ...] = param((0.0, -60.0, 0.0), unit="deg", range=(-360.0, 360.0),
                                      help="initial joints")
        camera: CameraConfig = param(CameraConfig())

:func:`validate` checks every field (recursively) against that metadata;
:func:`apply_overrides` applies ``key=value`` strings from the command line
(``duration=5``, ``q0=0,-60,0``, nested: ``camera.fu=600``), parsing each value by
the field's type annotation; :func:`describe` lists the fields for ``repro list -v``.

Every numeric field (``int``, ``float``, tuples of them, ``float | None``...) must
declare a ``range`` finite on both sides: :func:`param` refuses a numeric default
without one when the class is defined, and :func:`validate` refuses a config with
an undeclared numeric field. Ranges are inclusive; ``low_open=True`` excludes the
low end (a gain in ``(0, 100]``). NaN and infinities are never valid values. For
tuple and list fields the range and choices apply to every element.
"""

from __future__ import annotations

import copy
import dataclasses
import enum
import functools
import math
import re
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

from repro.errors import ConfigError, UnknownChoiceError

__all__ = [
    "param",
    "validate",
    "check_declared",
    "apply_overrides",
    "describe",
    "config_keys",
]

T = TypeVar("T")

Range = tuple[float, float]

_TRUE = ("true", "1", "yes", "on")
_FALSE = ("false", "0", "no", "off")
_NONE = ("none", "null")


# --------------------------------------------------------------------------- declaring fields


def param(
    default: Any,
    *,
    unit: str = "",
    range: Range | None = None,
    low_open: bool = False,
    choices: tuple[str, ...] | None = None,
    help: str = "",
    output_only: bool = False,
    sweep: Any = None,
) -> Any:
    """A ``dataclasses.field`` with ``default`` and metadata unit/range/choices/help.

    ``sweep``: a :class:`repro.sweep_ranges.SweepRange`, the pre-registered plausible values
    of a value the paper does not give (issue 19), inside ``range``.

    ``range`` is an inclusive ``(low, high)`` pair of finite numbers, required for
    every numeric field (``low_open=True``: ``low < value <= high``). Tuples, lists
    and other unhashable defaults are stored as a ``default_factory`` (a deep copy),
    so each instance gets its own value. Raises :class:`ConfigError` at
    class-definition time if the metadata is malformed, a numeric default has no
    range, or the default itself violates the metadata.
    """
    metadata: dict[str, Any] = {}
    if unit:
        metadata["unit"] = unit
    if range is not None:
        metadata["range"] = _check_range_spec(range, low_open)
        if low_open:
            metadata["low_open"] = True
    elif low_open:
        raise ConfigError("param(low_open=True) needs a range=(low, high)")
    elif _has_number(default):
        raise ConfigError(
            f"param({default!r}{f', help={help!r}' if help else ''}) is numeric and needs "
            "range=(low, high), finite on both sides (the physically meaningful values)"
        )
    if choices is not None:
        choices = tuple(choices)
        if not choices:
            raise ConfigError("param(choices=...) must list at least one choice")
        metadata["choices"] = choices
    if help:
        metadata["help"] = help
    if output_only:
        # Changes what a run writes (a video...), not its trace: left out of the config hash.
        metadata["output_only"] = True
    _check_value("default", default, metadata)
    if sweep is not None:
        from repro.sweep_ranges import SweepRange

        if not isinstance(sweep, SweepRange):
            raise ConfigError(f"param(sweep={sweep!r}) must be a SweepRange")
        sweep.check_field(f"param({default!r})", metadata, default)
        metadata["sweep"] = sweep

    if isinstance(default, (list, dict, set, tuple)) or type(default).__hash__ is None:
        factory = functools.partial(copy.deepcopy, default)
        return dataclasses.field(default_factory=factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _has_number(value: Any) -> bool:
    if isinstance(value, (tuple, list)):
        return any(_is_number(item) for item in value)
    return _is_number(value)


def _check_range_spec(spec: Any, low_open: bool = False) -> Range:
    try:
        low, high = spec
    except (TypeError, ValueError):
        raise ConfigError(f"param(range={spec!r}) must be a (low, high) pair") from None
    if not (_is_number(low) and _is_number(high) and math.isfinite(low) and math.isfinite(high)):
        raise ConfigError(
            f"param(range={spec!r}) must be finite on both sides: every numeric field "
            "needs physically meaningful bounds"
        )
    if low > high:
        raise ConfigError(f"param(range={spec!r}) has low > high")
    if low_open and low == high:
        raise ConfigError(f"param(range={spec!r}, low_open=True) is empty")
    return (low, high)


def _is_numeric_type(tp: Any) -> bool:
    """Whether an annotation holds numbers: int, float, X | None, tuple/list of those."""
    if tp is bool:
        return False
    if tp in (int, float):
        return True
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType, tuple, list):
        return any(_is_numeric_type(arg) for arg in typing.get_args(tp) if arg is not Ellipsis)
    return False


def check_declared(config_cls: Any) -> None:
    """Refuse a config class (or instance) with a numeric field that declares no range.

    Nested dataclass fields are checked too. Raises :class:`ConfigError` naming the field.
    """
    cls = config_cls if isinstance(config_cls, type) else type(config_cls)
    if not dataclasses.is_dataclass(cls):
        raise ConfigError(f"{cls.__name__} is not a dataclass config")
    hints = _field_types(cls)
    for f in dataclasses.fields(cls):
        tp = hints.get(f.name)
        if tp is None:  # unresolvable annotation: judge by the default value
            default = f.default_factory() if callable(f.default_factory) else f.default
            numeric = _has_number(default)
        else:
            numeric = _is_numeric_type(tp)
            if dataclasses.is_dataclass(tp):
                check_declared(tp)
        if numeric and f.metadata.get("range") is None:
            raise ConfigError(
                f"config field {cls.__name__}.{f.name} is numeric but declares no range: "
                "declare it with param(..., range=(low, high)), finite on both sides"
            )


# --------------------------------------------------------------------------- validation


def validate(config: Any) -> None:
    """Check every field of ``config`` (recursively) against its range/choices metadata.

    Raises :class:`ConfigError` naming the field, the value and the allowed range
    (``NaN is not allowed for mu``, ``mu=20.0 is out of range; allowed: [0.0, 10.0]``),
    or :class:`UnknownChoiceError` listing the valid choices. A numeric field without a
    declared range is refused too (see :func:`check_declared`).
    """
    _require_instance(config)
    check_declared(config)
    _validate(config, prefix="")


def _validate(config: Any, prefix: str) -> None:
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        name = prefix + f.name
        if _is_dataclass_instance(value):
            _validate(value, prefix=name + ".")
        else:
            _check_value(name, value, f.metadata)


def _check_value(name: str, value: Any, metadata: Any) -> None:
    """Check one value (or each element of a tuple/list value) against the metadata."""
    if value is None:
        return
    if isinstance(value, (tuple, list)):
        for i, item in enumerate(value):
            _check_scalar(f"{name}[{i}]", item, metadata)
    else:
        _check_scalar(name, value, metadata)


def _check_scalar(name: str, value: Any, metadata: Any) -> None:
    if isinstance(value, float) and not math.isfinite(value):
        allowed = f"; allowed: {_metadata_range(metadata)}" if "range" in metadata else ""
        raise ConfigError(f"{_nonfinite_name(value)} is not allowed for {name}{allowed}")
    choices = metadata.get("choices")
    if choices is not None and value not in choices:
        raise UnknownChoiceError(f"{name} value", value, [str(c) for c in choices])
    bounds = metadata.get("range")
    if bounds is None:
        return
    if not _is_number(value):
        raise ConfigError(
            f"{name}={value!r} must be a number in {_metadata_range(metadata)}, "
            f"not {type(value).__name__}"
        )
    low, high = bounds
    above_low = value > low if metadata.get("low_open") else value >= low
    if not (above_low and value <= high):
        raise ConfigError(
            f"{name}={value!r} is out of range; allowed: {_metadata_range(metadata)}"
        )


def _nonfinite_name(value: float) -> str:
    return "NaN" if math.isnan(value) else ("inf" if value > 0 else "-inf")


def _metadata_range(metadata: Any) -> str:
    return format_range(metadata["range"], bool(metadata.get("low_open")))


def format_range(bounds: Range, low_open: bool = False) -> str:
    """``(0.0, 10.0)`` -> ``"[0.0, 10.0]"``; with ``low_open`` -> ``"(0.0, 10.0]"``."""
    low, high = bounds
    return f"{'(' if low_open else '['}{low}, {high}]"


# --------------------------------------------------------------------------- overrides


def apply_overrides(config: T, overrides: Sequence[str]) -> T:
    """Apply ``key=value`` strings to a frozen config and return the validated copy.

    Keys may reach into nested dataclass fields with dots (``camera.fu=600``).
    ``nan``, ``inf`` and ``-inf`` are refused with that word (``NaN is not allowed
    for mu``), never silently accepted.
    Values are parsed by the field's annotation: ``float``, ``int``, ``bool``
    (true/false/1/0/yes/no/on/off), ``str``, ``Path``, ``Literal``, ``Enum``,
    ``X | None`` (``none``/``null``), and tuples/lists of those as
    comma-separated text (``q0=0,-60,0``; ``q0=`` is the empty tuple).
    Later overrides of the same key win. The result is checked with
    :func:`validate`, so an out-of-range value raises here.

    Raises :class:`ConfigError` for a malformed item (no ``=``) or an
    unparsable value (naming the expected type), and
    :class:`UnknownChoiceError` for an unknown key (listing the valid keys)
    or a value outside the field's choices.
    """
    _require_instance(config)
    if isinstance(overrides, str):
        overrides = [overrides]
    for item in overrides:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(
                f"malformed override {item!r}: expected key=value; valid keys: "
                + ", ".join(config_keys(config))
            )
        config = _set_path(config, config, key.split("."), key, text.strip())
    validate(config)
    return config


def _set_path(root: Any, obj: Any, parts: list[str], key: str, text: str) -> Any:
    by_name = {f.name: f for f in dataclasses.fields(obj) if f.init}
    name = parts[0]
    if name not in by_name:
        raise UnknownChoiceError("config key", key, config_keys(root))
    current = getattr(obj, name)
    if len(parts) > 1:
        if not _is_dataclass_instance(current):
            raise UnknownChoiceError("config key", key, config_keys(root))
        return dataclasses.replace(obj, **{name: _set_path(root, current, parts[1:], key, text)})
    if _is_dataclass_instance(current):
        raise ConfigError(
            f"{key} is a nested config, not a value; set one of its fields: "
            + ", ".join(f"{key}.{k}" for k in config_keys(current))
        )
    annotation = _field_types(type(obj)).get(name)
    if annotation is None:
        annotation = _infer_type(current)
    return dataclasses.replace(obj, **{name: _parse(text, annotation, key)})


def _parse(text: str, tp: Any, key: str) -> Any:
    """Parse ``text`` as a value of type ``tp``; ConfigError names ``key`` and the type.

    Non-finite floats parse (``validate`` then rejects them by name); a non-finite
    number given for an ``int`` field is reported as such, not as unparsable.
    """
    try:
        return _parse_as(text, tp, key)
    except (ValueError, TypeError) as exc:
        if isinstance(exc, ConfigError):
            raise
        for i, item in enumerate(_split_sequence(text)):
            try:
                number = float(item)
            except ValueError:
                continue
            if not math.isfinite(number):
                where = key if item == text.strip() else f"{key}[{i}]"
                raise ConfigError(f"{_nonfinite_name(number)} is not allowed for {where}") from None
        raise ConfigError(f"cannot parse {key}={text!r}: expected {type_name(tp)}") from None


#: Plain decimal numbers only: Python's int() and float() also take ``1_0`` (= 10), other
#: scripts' digits and, for int, nothing else surprising; a config value must mean what it
#: reads. Floats may also be nan/inf by name (then refused by name, see validate()).
_INT_RE = re.compile(r"[+-]?[0-9]+")
_FLOAT_RE = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?"
                       r"|[+-]?(nan|inf|infinity)", re.IGNORECASE)


def _plain_number(text: str, pattern: re.Pattern[str]) -> str:
    """``text`` without surrounding blanks if it is a plain decimal number; ValueError else."""
    t = text.strip()
    if not pattern.fullmatch(t):
        raise ValueError(text)
    return t


def _parse_as(text: str, tp: Any, key: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)

    if tp is Any:
        return text
    if origin in (typing.Union, types.UnionType):
        if type(None) in args and text.lower() in _NONE:
            return None
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _parse_as(text, arg, key)
            except (ValueError, TypeError):
                continue
        raise ValueError(text)
    if origin is typing.Literal:
        for arg in args:
            if isinstance(arg, str) and arg == text:
                return arg
            if not isinstance(arg, str):
                try:
                    if _parse_as(text, type(arg), key) == arg:
                        return arg
                except (ValueError, TypeError):
                    continue
        raise UnknownChoiceError(f"{key} value", text, [str(a) for a in args])
    if origin in (tuple, list) or tp in (tuple, list):
        items = _split_sequence(text)
        container = origin or tp
        if not args:
            elem_types: list[Any] = [str] * len(items)
        elif container is tuple and not (len(args) == 2 and args[1] is Ellipsis):
            if len(items) != len(args):
                raise ConfigError(
                    f"cannot parse {key}={text!r}: expected {type_name(tp)} "
                    f"({len(args)} comma-separated values, got {len(items)})"
                )
            elem_types = list(args)
        else:
            elem_types = [args[0]] * len(items)
        values = [_parse_as(item, et, key) for item, et in zip(items, elem_types, strict=True)]
        return tuple(values) if container is tuple else values
    if tp is bool:
        low = text.lower()
        if low in _TRUE:
            return True
        if low in _FALSE:
            return False
        raise ConfigError(
            f"cannot parse {key}={text!r}: expected bool, one of {', '.join(_TRUE + _FALSE)}"
        )
    if tp is int:
        return int(_plain_number(text, _INT_RE))
    if tp is float:
        return float(_plain_number(text, _FLOAT_RE))  # validate() rejects nan/inf by name
    if tp is str:
        return text
    if tp is Path:
        return Path(text)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        for member in tp:
            if text in (member.name, str(member.value)):
                return member
        raise UnknownChoiceError(f"{key} value", text, [m.name for m in tp])
    if dataclasses.is_dataclass(tp):
        raise ConfigError(f"{key} is a nested config, not a value; set one of its fields")
    raise ConfigError(f"cannot override {key}: unsupported field type {type_name(tp)}")


def _split_sequence(text: str) -> list[str]:
    text = text.strip()
    if len(text) >= 2 and text[0] + text[-1] in ("()", "[]"):
        text = text[1:-1].strip()
    if not text:
        return []
    return [item.strip() for item in text.split(",")]


def _infer_type(value: Any) -> Any:
    """Fallback annotation from a field's current value (when hints cannot be resolved)."""
    if isinstance(value, tuple):
        return tuple[type(value[0]), ...] if value else tuple  # type: ignore[misc]
    if isinstance(value, list):
        return list[type(value[0])] if value else list  # type: ignore[misc]
    if value is None:
        return Any
    return type(value)


def _field_types(cls: type) -> dict[str, Any]:
    """Resolved annotations of a dataclass (works with ``from __future__ import annotations``).

    Fields whose string annotation cannot be resolved (a class defined inside a
    function) are left out; the caller then infers the type from the value.
    """
    try:
        return typing.get_type_hints(cls)
    except Exception:
        return {f.name: f.type for f in dataclasses.fields(cls) if not isinstance(f.type, str)}


def type_name(tp: Any) -> str:
    """Readable name of an annotation: ``float``, ``tuple[float, ...]``, ``str | None``."""
    if tp is type(None):
        return "None"
    if tp is Ellipsis:
        return "..."
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(type_name(a) for a in typing.get_args(tp))
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(tp))
    if origin is not None:
        args = typing.get_args(tp)
        base = getattr(origin, "__name__", str(origin))
        return f"{base}[{', '.join(type_name(a) for a in args)}]" if args else base
    if isinstance(tp, type):
        return tp.__name__
    return str(tp).replace("typing.", "")


# --------------------------------------------------------------------------- describing


def config_keys(config: Any) -> list[str]:
    """Every settable dotted key of a config instance or class, nested fields flattened."""
    return [row[0] for row in describe(config)]


def describe(config_cls: Any) -> list[tuple[str, str, str, str]]:
    """Rows ``(name, type, default, unit/help)`` of every leaf field, for ``repro list -v``.

    Nested dataclass fields are flattened with dotted names (``camera.fu``).
    Accepts a config class (instantiated with its defaults) or an instance.
    The last column joins help, ``[unit]``, range and choices.
    """
    instance = config_cls
    if isinstance(config_cls, type):
        if not dataclasses.is_dataclass(config_cls):
            raise ConfigError(f"{config_cls.__name__} is not a dataclass config")
        try:
            instance = config_cls()
        except TypeError as exc:
            raise ConfigError(
                f"config class {config_cls.__name__} must be constructible with no arguments "
                f"(its defaults): {exc}"
            ) from None
    _require_instance(instance)
    rows: list[tuple[str, str, str, str]] = []
    _describe(instance, "", rows)
    return rows


def _describe(config: Any, prefix: str, rows: list[tuple[str, str, str, str]]) -> None:
    hints = _field_types(type(config))
    for f in dataclasses.fields(config):
        if not f.init:
            continue
        value = getattr(config, f.name)
        name = prefix + f.name
        if _is_dataclass_instance(value):
            _describe(value, name + ".", rows)
            continue
        tp = hints.get(f.name)
        tname = type_name(tp) if tp is not None else type_name(_infer_type(value))
        rows.append((name, tname, repr(value), _describe_meta(f.metadata)))


def _describe_meta(metadata: Any) -> str:
    head = " ".join(
        part
        for part in (
            metadata.get("help", ""),
            f"[{metadata['unit']}]" if "unit" in metadata else "",
        )
        if part
    )
    parts = [head] if head else []
    if metadata.get("range") is not None:
        parts.append(f"range {_metadata_range(metadata)}")
    if metadata.get("choices") is not None:
        parts.append("choices: " + ", ".join(str(c) for c in metadata["choices"]))
    if metadata.get("sweep") is not None:
        parts.append("swept: " + metadata["sweep"].describe())
    return "; ".join(parts)


# --------------------------------------------------------------------------- helpers


def _is_dataclass_instance(value: Any) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _require_instance(config: Any) -> None:
    if not _is_dataclass_instance(config):
        raise ConfigError(
            f"expected a dataclass config instance, got {type(config).__name__}: {config!r}"
        )
