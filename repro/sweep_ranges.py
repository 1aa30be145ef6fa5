"""Pre-registered sweep ranges of the values the papers do not give (issue 19).

A config field whose value is ours (``# ours``) and that a claim's verdict can depend on
declares, next to its default, the range of values that are equally plausible, with the
reason for that range written before any sweep is run::

    friction: float = param(1.0, range=(0.05, 2.0), help="Coulomb friction",
                            sweep=SweepRange(0.5, 1.5, reason="dry rubber on wood/plastic"))

:func:`declared_ranges` lists a config's ranges; :func:`sample_variants` draws quasi-random
variants of them (scipy's scrambled Sobol sequence, seeded), each a ``{field: value}``
override of the default config. A range is a promise: it is committed before the sweep that
uses it, and narrowing it after seeing results must be said in the report.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from repro.errors import ConfigError, UnknownChoiceError

__all__ = ["DISTRIBUTIONS", "RANGES_COLUMNS", "SweepRange", "declared_ranges", "ranges_rows",
           "sample_variants"]

_MISSING = object()

#: How a range is sampled: uniform in value, uniform in log(value), or one of ``values``.
DISTRIBUTIONS = ("uniform", "log-uniform", "discrete")


@dataclass(frozen=True)
class SweepRange:
    """The plausible values of one field the paper leaves open.

    Attributes:
        low, high: bounds, in the field's unit (inclusive).
        reason: why these bounds (the paper's text or figures, a data sheet, a physical or
            numerical argument); never the verdict.
        dist: one of :data:`DISTRIBUTIONS`.
        values: the choices of a ``discrete`` range (each within ``[low, high]``).
        when: ``((field, value), ...)``: the range applies only to the configs whose
            defaults have these values (e.g. ``(("case", "case1"),)``: a scene's layout is
            swept only in the experiments of that scene); a ``frozenset`` value means one
            of its members (e.g. ``(("experiment", frozenset({"exp3", "exp3_no_tactile"})),)``);
            empty = every config that has the field.
    """

    low: float
    high: float
    reason: str
    dist: str = "uniform"
    values: tuple[float, ...] = ()
    when: tuple[tuple[str, Any], ...] = ()

    def applies(self, defaults: Any) -> bool:
        """Whether this range is swept in the config whose defaults are ``defaults``."""
        return all(getattr(defaults, f, _MISSING) in v if isinstance(v, frozenset)
                   else getattr(defaults, f, _MISSING) == v for f, v in self.when)

    def __post_init__(self) -> None:
        if self.dist not in DISTRIBUTIONS:
            raise UnknownChoiceError("sweep distribution", self.dist, DISTRIBUTIONS)
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or self.low > self.high:
            raise ConfigError(f"sweep range ({self.low}, {self.high}) must be finite, low <= high")
        if len(self.reason.strip()) < 10:
            raise ConfigError(f"sweep range ({self.low}, {self.high}) needs its reason")
        if self.dist == "log-uniform" and self.low <= 0:
            raise ConfigError(f"a log-uniform sweep range needs low > 0, got {self.low}")
        if self.dist == "discrete":
            if not self.values or any(not (self.low <= v <= self.high) for v in self.values):
                raise ConfigError(f"discrete sweep values {self.values} must be non-empty and "
                                  f"within ({self.low}, {self.high})")
        elif self.values:
            raise ConfigError("values are only for a discrete sweep range")
        if any(not (isinstance(w, tuple) and len(w) == 2 and isinstance(w[0], str))
               for w in self.when):
            raise ConfigError(f"sweep range when={self.when!r}: give ((field, value), ...)")

    def check_field(self, name: str, metadata: dict[str, Any], default: Any) -> None:
        """Refuse a range outside the field's declared ``range`` or on a non-scalar field."""
        if isinstance(default, (tuple, list)) or isinstance(default, bool) or not isinstance(
                default, (int, float)):
            raise ConfigError(f"{name}: a sweep range needs a scalar numeric field, default "
                              f"{default!r}")
        lo, hi = metadata.get("range", (-math.inf, math.inf))
        if self.low < lo or self.high > hi:
            raise ConfigError(f"{name}: sweep range ({self.low}, {self.high}) leaves the "
                              f"field's range ({lo}, {hi})")

    def value(self, u: float, integer: bool = False) -> float:
        """The value at quantile ``u`` in [0, 1) of this range."""
        if self.dist == "discrete":
            return float(self.values[min(int(u * len(self.values)), len(self.values) - 1)])
        if self.dist == "log-uniform":
            x = math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        else:
            x = self.low + u * (self.high - self.low)
        x = min(max(x, self.low), self.high)
        return float(round(x)) if integer else x

    def describe(self) -> str:
        extra = f" {list(self.values)}" if self.dist == "discrete" else ""
        only = "".join(f" (only where {f} is one of {sorted(v)})" if isinstance(v, frozenset)
                       else f" (only where {f} = {v!r})" for f, v in self.when)
        return f"{self.dist} [{self.low:g}, {self.high:g}]{extra}{only}: {self.reason}"


def declared_ranges(config_cls: Any) -> dict[str, SweepRange]:
    """``{field: SweepRange}`` of a config class (or instance), in field order: the fields
    that declare a range that applies to the class's defaults (:meth:`SweepRange.applies`)."""
    cls = config_cls if isinstance(config_cls, type) else type(config_cls)
    if not dataclasses.is_dataclass(cls):
        raise ConfigError(f"{cls.__name__} is not a dataclass config")
    defaults = cls()
    return {f.name: f.metadata["sweep"] for f in dataclasses.fields(cls)
            if f.metadata.get("sweep") is not None and f.metadata["sweep"].applies(defaults)}


def sample_variants(config_cls: Any, n: int, seed: int) -> list[dict[str, float | int]]:
    """``n`` quasi-random overrides of the declared ranges of ``config_cls``: a scrambled
    Sobol sequence (scipy.stats.qmc, ``seed``) over the unit cube, one dimension per range in
    field order, mapped through each range. Integer fields get rounded values. The same
    (class, n, seed) always gives the same variants."""
    from scipy.stats import qmc

    if n < 1:
        raise ConfigError(f"n = {n}: a sweep needs at least one variant")
    ranges = declared_ranges(config_cls)
    if not ranges:
        raise ConfigError(f"{getattr(config_cls, '__name__', config_cls)} declares no sweep "
                          "range")
    cls = config_cls if isinstance(config_cls, type) else type(config_cls)
    defaults = cls()
    names = list(ranges)
    # Sobol points are balanced in powers of two; draw the next one and keep the first n
    m = max(0, math.ceil(math.log2(n)))
    u = qmc.Sobol(d=len(names), scramble=True, seed=np.random.default_rng(seed)).random_base2(m)
    out = []
    for row in u[:n]:
        variant: dict[str, float | int] = {}
        for name, x in zip(names, row, strict=True):
            integer = isinstance(getattr(defaults, name), int)
            v = ranges[name].value(float(x), integer)
            variant[name] = int(v) if integer else v
        out.append(variant)
    return out


#: Columns of the report's table of pre-registered ranges (:func:`ranges_rows`).
RANGES_COLUMNS = ("experiments", "field", "default", "unit", "distribution", "low", "high",
                  "reason", "declared in")


def _declaring_commit(path: str, name: str) -> str:
    """``file:line @ commit`` of the ``sweep=`` of field ``name`` (its first line after the
    field's declaration in ``path``), by ``git blame``; "uncommitted" for a line not
    yet committed, "unknown" without git."""
    import subprocess
    from pathlib import Path

    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except OSError:
        return "unknown"
    start = next((i for i, ln in enumerate(lines) if ln.lstrip().startswith(f"{name}:")), None)
    if start is None:
        return "unknown"
    line = next((i for i in range(start, len(lines)) if "sweep=" in lines[i]), start) + 1
    root = Path(__file__).resolve().parent.parent
    full = Path(path).resolve()
    where = f"{full.relative_to(root) if full.is_relative_to(root) else path}:{line}"
    try:
        out = subprocess.run(["git", "blame", "--porcelain", "-L", f"{line},{line}", "--",
                              str(path)], cwd=root, capture_output=True, text=True, timeout=20,
                             check=False)
    except (OSError, subprocess.SubprocessError):
        return f"{where} (unknown commit)"
    sha = out.stdout.split(" ", 1)[0] if out.returncode == 0 and out.stdout else ""
    if not sha:
        return f"{where} (unknown commit)"
    return f"{where} (uncommitted)" if set(sha) == {"0"} else f"{where} @ {sha[:10]}"


def ranges_rows(experiments: list[Any]) -> dict[str, list[tuple[str, ...]]]:
    """Per paper, the table rows (:data:`RANGES_COLUMNS`) of every declared range of the
    registered ``experiments`` (:class:`repro.runs.registry.Experiment`); a field declared
    once and inherited by several experiments' configs is one row naming them all."""
    import inspect

    found: dict[tuple[str, str, str], dict[str, Any]] = {}
    for exp in experiments:
        cls = exp.config_cls
        defaults = cls()
        for name, rng in declared_ranges(cls).items():
            owner = next(c for c in cls.__mro__ if name in getattr(c, "__annotations__", {}))
            path = inspect.getsourcefile(owner) or ""
            key = (exp.paper, path, name)
            row = found.setdefault(key, {"experiments": [], "range": rng, "owner": owner,
                                         "path": path, "default": getattr(defaults, name),
                                         "unit": next(f.metadata.get("unit", "-") for f in
                                                      dataclasses.fields(cls)
                                                      if f.name == name)})
            row["experiments"].append(exp.name)
    out: dict[str, list[tuple[str, ...]]] = {}
    for (paper, _, name), row in found.items():
        rng = row["range"]
        out.setdefault(paper, []).append((
            ", ".join(row["experiments"]), name, f"{row['default']:g}", row["unit"],
            rng.dist + (f" {list(rng.values)}" if rng.values else ""), f"{rng.low:.4g}",
            f"{rng.high:.4g}", rng.reason, _declaring_commit(row["path"], name)))
    return out
