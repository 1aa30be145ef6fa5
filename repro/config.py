"""Experiment configurations: frozen dataclasses whose fields carry metadata.

A config field is declared with :func:`param`, which records a unit, an
allowed range and/or a finite set of choices, and a help string in the
field's ``metadata``::

    @dataclass(frozen=True)
    class Case1Config:
        gain: float = param(0.4, unit="1/s", range=(0.0, None), help="IBVS gain lambda_4p")
        solver: str = param("proxsuite", choices=("proxsuite", "osqp"), help="QP solver")
        q0: tuple[float, ...] = param((0.0, -60.0, 0.0), unit="deg", help="initial joints")
        camera: CameraConfig = param(CameraConfig())

:func:`validate` checks every field (recursively) against that metadata;
:func:`apply_overrides` applies ``key=value`` strings from the command line
(``camera.fu=600``, ``q0=0,-60,0``), parsing each value by the field's type
annotation; :func:`describe` lists the fields for ``repro list -v``.

Ranges are inclusive; ``None`` leaves that side unbounded. For tuple and list
fields the range and choices apply to every element.
"""

from __future__ import annotations

import copy
import dataclasses
import enum
import functools
import math
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

from repro.errors import ConfigError, UnknownChoiceError

__all__ = ["param", "validate", "apply_overrides", "describe", "config_keys"]

T = TypeVar("T")

Range = tuple[float | None, float | None]

_TRUE = ("true", "1", "yes", "on")
_FALSE = ("false", "0", "no", "off")
_NONE = ("none", "null")


# --------------------------------------------------------------------------- declaring fields


def param(
    default: Any,
    *,
    unit: str = "",
    range: Range | None = None,
    choices: tuple[str, ...] | None = None,
    help: str = "",
    output_only: bool = False,
) -> Any:
    """A ``dataclasses.field`` with ``default`` and metadata unit/range/choices/help.

    ``range`` is an inclusive ``(low, high)`` pair, ``None`` meaning unbounded on
    that side. Tuples, lists and other unhashable defaults are stored as a
    ``default_factory`` (a deep copy), so each instance gets its own value.
    Raises :class:`ConfigError` at class-definition time if the metadata is
    malformed or the default itself violates it.
    """
    metadata: dict[str, Any] = {}
    if unit:
        metadata["unit"] = unit
    if range is not None:
        metadata["range"] = _check_range_spec(range)
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

    if isinstance(default, (list, dict, set, tuple)) or type(default).__hash__ is None:
        factory = functools.partial(copy.deepcopy, default)
        return dataclasses.field(default_factory=factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def _check_range_spec(spec: Any) -> Range:
    try:
        low, high = spec
    except (TypeError, ValueError):
        raise ConfigError(
            f"param(range={spec!r}) must be a (low, high) pair, None meaning unbounded"
        ) from None
    if low is not None and high is not None and low > high:
        raise ConfigError(f"param(range={spec!r}) has low > high")
    return (low, high)


# --------------------------------------------------------------------------- validation


def validate(config: Any) -> None:
    """Check every field of ``config`` (recursively) against its range/choices metadata.

    Raises :class:`ConfigError` naming the field, the value and the allowed range,
    or :class:`UnknownChoiceError` listing the valid choices.
    """
    _require_instance(config)
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
    choices = metadata.get("choices")
    if choices is not None and value not in choices:
        raise UnknownChoiceError(f"{name} value", value, [str(c) for c in choices])
    bounds = metadata.get("range")
    if bounds is None:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(
            f"{name}={value!r} must be a number in {format_range(bounds)}, "
            f"not {type(value).__name__}"
        )
    low, high = bounds
    # Written as "not (inside)" so that NaN is rejected.
    if not ((low is None or value >= low) and (high is None or value <= high)):
        raise ConfigError(f"{name}={value!r} is out of range; allowed: {format_range(bounds)}")


def format_range(bounds: Range) -> str:
    """``(0.0, None)`` -> ``"[0.0, +inf)"``: inclusive bounds, open at infinity."""
    low, high = bounds
    left = "(-inf" if low is None else f"[{low}"
    right = "+inf)" if high is None else f"{high}]"
    return f"{left}, {right}"


# --------------------------------------------------------------------------- overrides


def apply_overrides(config: T, overrides: Sequence[str]) -> T:
    """Apply ``key=value`` strings to a frozen config and return the validated copy.

    Keys may reach into nested dataclass fields with dots (``camera.fu=600``).
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
    """Parse ``text`` as a value of type ``tp``; ConfigError names ``key`` and the type."""
    try:
        return _parse_as(text, tp, key)
    except (ValueError, TypeError) as exc:
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"cannot parse {key}={text!r}: expected {type_name(tp)}") from None


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
        return int(text)
    if tp is float:
        value = float(text)
        if math.isnan(value):
            raise ValueError(text)
        return value
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
        parts.append(f"range {format_range(metadata['range'])}")
    if metadata.get("choices") is not None:
        parts.append("choices: " + ", ".join(str(c) for c in metadata["choices"]))
    return "; ".join(parts)


# --------------------------------------------------------------------------- helpers


def _is_dataclass_instance(value: Any) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _require_instance(config: Any) -> None:
    if not _is_dataclass_instance(config):
        raise ConfigError(
            f"expected a dataclass config instance, got {type(config).__name__}: {config!r}"
        )
