"""Tidy, self-describing trace of one experiment run.

A run directory holds four files that can be audited or replayed without repro:

- ``trace.csv``: one row per control step, fixed column order (set by the first row).
  Floats are written with ``repr`` (shortest round-trip form), so re-reading the file gives
  bit-identical values. A missing value is an empty field (NaN when read back).
- ``events.csv``: columns ``t`` (s, simulated time), ``step`` (control step index), ``kind``,
  ``detail``; one row per discrete event, written and flushed immediately.
- ``manifest.json``: what ran (experiment, paper, config and its hash, seed), how it ended
  (status, reason), when and where (UTC times, wall time, Python, CPU, package versions,
  git sha) and an optional ``summary`` set by the caller.
- ``scene.json``: the simulated scene (bodies, poses...) as plain JSON.

``manifest.json`` is written with status ``"running"`` when the recorder is created, with the
pid, hostname and boot id of the process, so a process killed without unwinding (SIGKILL,
power loss) leaves a run that claims treat as not completed rather than a stale manifest from
an earlier run; :func:`effective_manifest` reads such a run as ``"interrupted"`` ("process
gone", rows counted in trace.csv) and :func:`mark_if_gone` rewrites its manifest so.
"""

from __future__ import annotations

import csv
import dataclasses
import enum
import functools
import hashlib
import importlib.metadata
import io
import json
import math
import os
import platform
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any, TextIO

import numpy as np
import pandas as pd

from repro.errors import ConfigError, ReproError, UnknownChoiceError

__all__ = [
    "EVENTS_COLUMNS",
    "FORMAT_VERSION",
    "MANIFEST_KEYS",
    "RUN_FILES",
    "RUN_STATUSES",
    "TRACKED_PACKAGES",
    "RunFiles",
    "TraceRecorder",
    "config_hash",
    "cpu_name",
    "environment",
    "git_state",
    "add_vector",
    "count_trace_rows",
    "effective_manifest",
    "load_run",
    "recover_manifest_tmp",
    "mark_if_gone",
    "package_versions",
    "process_gone",
    "to_jsonable",
    "update_manifest",
]

FORMAT_VERSION = 1
"""Version of the run-directory layout; bump when a file's schema changes."""

RUN_FILES = ("trace.csv", "events.csv", "manifest.json", "scene.json")
EVENTS_COLUMNS = ("t", "step", "kind", "detail")

RUN_STATUSES = ("completed", "crashed", "interrupted", "failed")
"""Final statuses accepted by :meth:`TraceRecorder.close` (``"running"`` is only transient)."""

TRACKED_PACKAGES = (
    "pybullet",
    "numpy",
    "pin",
    "proxsuite",
    "osqp",
    "casadi",
    "python-fcl",
    "opencv-python-headless",
    "pandas",
    "matplotlib",
    "scipy",
    "numba",
)
NOT_INSTALLED = "not installed"

MANIFEST_KEYS = (
    "format_version",
    "experiment",
    "paper",
    "status",
    "reason",
    "config",
    "config_hash",
    "seed",
    "columns",
    "n_rows",
    "n_events",
    "started_at",
    "ended_at",
    "wall_time_s",
    "concurrent_runs",
    "hostname",
    "pid",
    "boot_id",
    "python",
    "platform",
    "cpu",
    "packages",
    "git_sha",
    "git_dirty",
    "repro_version",
    "summary",
)
"""Keys of manifest.json, in the order they are written."""

# Paths whose changes do not make the code "dirty": run outputs are committed too.
_GIT_OUTPUT_PATHSPECS = (
    ":(top,exclude)results",
    ":(top,exclude)figures",
    ":(top,exclude)REPORT.md",
)

Scalar = float | int | str | bool

STALE_AFTER_S = 6 * 3600.0
"""A ``running`` run of another host (whose pid cannot be checked) is taken as gone when none
of its files changed for this long [s]; the trace is flushed at least every second while the
process lives (``TraceRecorder.flush_interval_s``)."""


# --------------------------------------------------------------------------- JSON helpers


def to_jsonable(obj: Any) -> Any:
    """Convert ``obj`` to plain JSON types (dict with str keys, list, str, int, float, bool, None).

    Dataclasses become dicts of their fields, tuples/sets become lists, numpy arrays and
    scalars become lists / Python scalars, paths and enums their string / value. Non-finite
    floats become the strings ``"nan"``, ``"inf"``, ``"-inf"`` so the output is strict JSON.

    Raises:
        ReproError: if a value has no JSON form (e.g. a function or an arbitrary object).
    """
    return _jsonable(obj, "$")


def _jsonable(obj: Any, where: str) -> Any:
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        value = float(obj)
        return value if math.isfinite(value) else repr(value)
    if isinstance(obj, enum.Enum):
        return _jsonable(obj.value, where)
    if isinstance(obj, Path):
        return obj.as_posix()
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {
            f.name: _jsonable(getattr(obj, f.name), f"{where}.{f.name}")
            for f in dataclasses.fields(obj)
        }
    if isinstance(obj, Mapping):
        out: dict[str, Any] = {}
        for key, value in obj.items():
            if not isinstance(key, str | int | float | bool | enum.Enum):
                raise ReproError(f"cannot write a JSON key of type {type(key).__name__} at {where}")
            name = str(key.value) if isinstance(key, enum.Enum) else str(key)
            out[name] = _jsonable(value, f"{where}.{name}")
        return out
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist(), where)
    if isinstance(obj, list | tuple):
        return [_jsonable(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, set | frozenset):
        return sorted((_jsonable(v, where) for v in obj), key=repr)
    raise ReproError(
        f"cannot write a value of type {type(obj).__name__} at {where} as JSON: {obj!r}"
    )


def _canonical_json(obj: Any) -> str:
    return json.dumps(
        to_jsonable(obj), sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False
    )


def config_hash(config: Any) -> str:
    """Return the sha256 hex digest of the canonical JSON of ``config``.

    ``config`` is a dataclass instance or a mapping. Canonical JSON: :func:`to_jsonable`,
    sorted keys, no whitespace, ASCII. Field order and tuple-vs-list do not change the hash;
    any value change does, except in fields declared ``output_only`` (e.g. ``video``: it
    changes which files a run writes, not its trace). The class name is not part of the hash.
    """
    _check_config(config)
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        config = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)
                  if not f.metadata.get("output_only")}
    return hashlib.sha256(_canonical_json(config).encode("ascii")).hexdigest()


def _check_config(config: Any) -> None:
    is_instance = dataclasses.is_dataclass(config) and not isinstance(config, type)
    if not (is_instance or isinstance(config, Mapping)):
        raise ConfigError(
            f"config must be a dataclass instance or a mapping, got {type(config).__name__}"
        )


def _write_json_atomic(path: Path, obj: Any) -> None:
    """Write ``path`` through ``<path>.tmp`` and a rename; a SIGINT / SIGTERM is held until
    both are done (:func:`repro.runs.signals.deferred`)."""
    from repro.runs.signals import deferred

    tmp = path.with_name(path.name + ".tmp")
    text = json.dumps(obj, indent=2, allow_nan=False) + "\n"
    with deferred():
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)


def recover_manifest_tmp(run_dir: Path) -> bool:
    """A run killed (SIGKILL) between writing ``manifest.json.tmp`` and renaming it has no
    manifest.json: put the temporary file in its place if it is a whole JSON object (it is
    then read like any manifest, e.g. marked interrupted by :func:`mark_if_gone`); True if
    it did."""
    run_dir = Path(run_dir)
    tmp, path = run_dir / "manifest.json.tmp", run_dir / "manifest.json"
    if path.exists() or not tmp.is_file():
        return False
    try:
        obj = json.loads(tmp.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if not isinstance(obj, dict):
        return False
    os.replace(tmp, path)
    return True


# --------------------------------------------------------------------------- environment


@functools.lru_cache(maxsize=1)
def package_versions() -> dict[str, str]:
    """Installed version of each of :data:`TRACKED_PACKAGES` (``"not installed"`` if absent)."""
    versions = {}
    for name in TRACKED_PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = NOT_INSTALLED
    return versions


@functools.lru_cache(maxsize=1)
def cpu_name() -> str:
    """Human-readable CPU model (from /proc/cpuinfo on Linux), with the logical core count."""
    name = ""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.lower().startswith(("model name", "hardware", "cpu model")):
                name = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    if not name:
        name = platform.processor() or platform.machine() or "unknown"
    return f"{name} ({os.cpu_count()} logical cores)"


@functools.lru_cache(maxsize=1)
def _repro_version() -> str:
    try:
        return importlib.metadata.version("repro")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


CONCURRENT_RUNS_ENV = "REPRO_CONCURRENT_RUNS"


def concurrent_runs() -> int:
    """How many runs shared the machine with this one (``repro results -j N`` sets
    :data:`CONCURRENT_RUNS_ENV` in its workers; 1 for a run on its own): its wall time and
    timing columns were measured with that many runs on the cores."""
    try:
        return max(1, int(os.environ.get(CONCURRENT_RUNS_ENV, "1")))
    except ValueError:
        return 1


def environment() -> dict[str, Any]:
    """The live environment: python, platform, cpu, packages, repro_version."""
    return {
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "cpu": cpu_name(),
        "packages": dict(package_versions()),
        "repro_version": _repro_version(),
    }


def git_state(path: Path | None = None) -> tuple[str | None, bool | None]:
    """Return ``(sha, dirty)`` of the git checkout containing ``path``, ``(None, None)`` if none.

    ``path`` defaults to the directory of the repro package. ``dirty`` is True when tracked or
    untracked files differ from HEAD, ignoring run outputs (results/, figures/, REPORT.md).
    Uses ``--no-optional-locks`` so it never takes the index lock of a concurrent commit.
    """
    cwd = Path(path) if path is not None else Path(__file__).resolve().parents[1]
    if cwd.is_file():
        cwd = cwd.parent

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "--no-optional-locks", *args],
            cwd=cwd,
            capture_output=True,
            text=True,
            check=True,
            timeout=20,
        ).stdout

    try:
        sha = git("rev-parse", "HEAD").strip()
    except (OSError, subprocess.SubprocessError):
        return None, None
    try:
        dirty: bool | None = bool(
            git("status", "--porcelain", "--", *_GIT_OUTPUT_PATHSPECS).strip()
        )
    except (OSError, subprocess.SubprocessError):
        dirty = None
    return sha or None, dirty


def _utc_now() -> str:
    return _utc_iso(datetime.now(UTC))


def _utc_iso(when: datetime) -> str:
    return when.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _hostname() -> str:
    return socket.gethostname()


def _boot_id() -> str | None:
    """Linux's id of the current boot (a pid of an earlier boot names another process)."""
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text(encoding="ascii").strip()
    except OSError:
        return None


# --------------------------------------------------------------------------- recorder


def _bool_text(value: Any) -> str:
    return "True" if value else "False"


def _float_text(value: Any) -> str:
    return repr(float(value))


def _int_text(value: Any) -> str:
    return str(int(value))


def _str_text(value: Any) -> str:
    return str(value)


#: :func:`_format_cell` of the common exact types, found by one lookup (the isinstance
#: chain below is the definition, and handles subclasses)
_CELL_TEXT: dict[type, Callable[[Any], str]] = {
    float: _float_text, np.float64: _float_text, np.float32: _float_text,
    bool: _bool_text, np.bool_: _bool_text, int: _int_text, np.int64: _int_text,
    np.int32: _int_text, str: _str_text}


def _format_cell(value: Any, key: str) -> str:
    """CSV text of one trace value; floats via repr so they round-trip bit-identically."""
    text = _CELL_TEXT.get(type(value))
    if text is not None:
        return text(value)
    if value is None:
        return ""
    if isinstance(value, bool | np.bool_):
        return "True" if value else "False"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return repr(float(value))
    if isinstance(value, str):
        return value
    raise ReproError(
        f"trace column {key!r}: value of type {type(value).__name__} is not a scalar "
        f"(float, int, str or bool): {value!r}"
    )


def _csv_bytes(rows: list[list[str]]) -> bytes:
    """CSV text of ``rows`` (the recorder's dialect: ',' and '\\n'), UTF-8."""
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    return buf.getvalue().encode("utf-8")


class TraceRecorder:
    """Writes one run's files into out_dir: trace.csv, events.csv, manifest.json, scene.json.

    Use as a context manager so a crash or Ctrl-C still closes the run with status
    ``"crashed"`` / ``"interrupted"`` and the reason::

        with TraceRecorder(out, experiment="reach", paper="thomas2024", config=cfg, seed=0) as rec:
            for k in range(n):
                rec.record({"t": k * dt, "step": k, "err_m": err})
            rec.summary["final_err_m"] = err

    Args:
        out_dir: run directory (created if needed; files of an earlier run are overwritten).
        experiment: experiment name.
        paper: paper key (e.g. "thomas2024").
        config: the run's configuration, a dataclass instance (a mapping is accepted too).
        seed: random seed of the run.
        flush_every: trace rows are written to disk every this many rows (and on close).
        flush_interval_s: ... and at least every this many seconds of wall time, so that a
            killed slow run (an NMPC step can take 0.1 s) loses at most that much.
    """

    def __init__(
        self,
        out_dir: Path,
        *,
        experiment: str,
        paper: str,
        config: Any,
        seed: int,
        flush_every: int = 50,
        flush_interval_s: float = 1.0,
    ) -> None:
        if not experiment or not isinstance(experiment, str):
            raise ConfigError(f"experiment must be a non-empty string, got {experiment!r}")
        if not paper or not isinstance(paper, str):
            raise ConfigError(f"paper must be a non-empty string, got {paper!r}")
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
            raise ConfigError(f"seed must be an int, got {seed!r}")
        if isinstance(flush_every, bool) or not isinstance(flush_every, int) or flush_every < 1:
            raise ConfigError(f"flush_every must be an int >= 1, got {flush_every!r}")
        if not (isinstance(flush_interval_s, int | float) and flush_interval_s >= 0):
            raise ConfigError(f"flush_interval_s must be a number >= 0, got {flush_interval_s!r}")
        _check_config(config)

        self.out_dir = Path(out_dir)
        self.experiment = experiment
        self.paper = paper
        self.seed = int(seed)
        self.flush_every = flush_every
        self.flush_interval_s = float(flush_interval_s)
        self.summary: dict[str, Any] = {}
        """Caller-set results written into manifest.json at close (JSON-able values)."""

        self._config_json = to_jsonable(config)
        self._config_hash = config_hash(config)
        self._columns: tuple[str, ...] | None = None
        self._column_set: frozenset[str] = frozenset()
        self._pending: list[list[str]] = []
        self._n_rows = 0
        self._n_events = 0
        self._closed = False
        self._manifest_path = self.out_dir / "manifest.json"
        self._started_at = _utc_now()
        self._t0 = time.perf_counter()
        self._last_flush = self._t0
        self._git_sha, self._git_dirty = git_state()

        self.out_dir.mkdir(parents=True, exist_ok=True)
        # trace.csv is written as bytes, whole rows at a time, so that the file position
        # tells whether a write interrupted by a signal happened (see flush and close)
        self._trace_file = open(self.out_dir / "trace.csv", "wb")  # closed in close()
        self._inflight: tuple[int, int, list[list[str]]] | None = None
        self._events_file: TextIO = open(  # closed in close()
            self.out_dir / "events.csv", "w", newline="", encoding="utf-8"
        )
        self._events_writer = csv.writer(self._events_file, lineterminator="\n")
        self._events_writer.writerow(EVENTS_COLUMNS)
        self._events_file.flush()
        self._scene_written = False
        scene_path = self.out_dir / "scene.json"
        if scene_path.exists():
            scene_path.unlink()
        self._write_manifest(status="running", reason="", ended_at=None, wall_time_s=None)

    # ------------------------------------------------------------------ properties

    @property
    def columns(self) -> tuple[str, ...] | None:
        """The trace schema (column order), None before the first row."""
        return self._columns

    @property
    def n_rows(self) -> int:
        """Number of trace rows recorded so far (flushed or not)."""
        return self._n_rows

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def manifest_path(self) -> Path:
        return self._manifest_path

    # ------------------------------------------------------------------ recording

    def _check_open(self) -> None:
        if self._closed:
            raise ReproError(f"run {self.out_dir} is closed; cannot record into it")

    def record(self, row: Mapping[str, float | int | str | bool]) -> None:
        """Append one trace row (one control step).

        The first row fixes the schema (its keys, in order). Later rows may omit keys (written
        empty, read back as NaN) but may not add any.

        Raises:
            ReproError: on a key not in the schema, a non-scalar value, or a closed recorder.
        """
        self._check_open()
        if self._columns is None:
            if not row:
                raise ReproError("the first trace row must have at least one column")
            for key in row:
                if not isinstance(key, str) or not key:
                    raise ReproError(f"trace column names must be non-empty strings, got {key!r}")
            self._columns = tuple(row)
            self._column_set = frozenset(self._columns)
            self._trace_file.write(_csv_bytes([list(self._columns)]))
        else:
            unknown = [key for key in row if key not in self._column_set]
            if unknown:
                raise ReproError(
                    f"trace row has column(s) {', '.join(map(repr, unknown))} not in the schema "
                    f"fixed by the first row: {', '.join(self._columns)}"
                )
        self._pending.append(
            [_format_cell(row[key], key) if key in row else "" for key in self._columns]
        )
        self._n_rows += 1
        if (len(self._pending) >= self.flush_every
                or time.perf_counter() - self._last_flush >= self.flush_interval_s):
            self.flush()

    def flush(self) -> None:
        """Write the buffered trace rows to disk."""
        if self._trace_file.closed:
            return
        rows = self._pending
        if rows:
            data = _csv_bytes(rows)
            # An interrupt (KeyboardInterrupt from a signal handler) may land between any two
            # of these lines; close() reads the file position to finish the write exactly
            # once (_settle_inflight).
            self._inflight = (self._trace_file.tell(), len(data), rows)
            self._trace_file.write(data)
            self._pending = []
            self._inflight = None
        self._trace_file.flush()
        self._last_flush = time.perf_counter()

    def _rows_in_file(self) -> int:
        """Data rows written to trace.csv (what the closed run holds)."""
        if not self._trace_file.closed:
            self._trace_file.flush()
        return count_trace_rows(self.out_dir)

    def _settle_inflight(self) -> None:
        """After an interrupted flush: if the rows of the write in flight reached the file
        (its position moved by their length) they must not be written again."""
        if self._inflight is None:
            return
        pos0, size, rows = self._inflight
        self._inflight = None
        pos = self._trace_file.tell()
        if pos == pos0 + size and self._pending is rows:
            self._pending = []  # written, not yet forgotten
        elif pos not in (pos0, pos0 + size):  # a partial write: drop the cut-off bytes
            self._trace_file.seek(pos0)
            self._trace_file.truncate()

    def event(self, t: float, step: int, kind: str, detail: str = "") -> None:
        """Append a row to events.csv and flush it at once.

        Args:
            t: simulated time of the event (s).
            step: control-step index.
            kind: short event type, e.g. "contact", "goal_reached".
            detail: free text.
        """
        self._check_open()
        if not isinstance(kind, str) or not kind:
            raise ReproError(f"event kind must be a non-empty string, got {kind!r}")
        if not isinstance(detail, str):
            raise ReproError(f"event detail must be a string, got {type(detail).__name__}")
        self._events_writer.writerow(
            [_format_cell(float(t), "t"), _format_cell(int(step), "step"), kind, detail]
        )
        self._events_file.flush()
        self._n_events += 1

    def set_scene(self, scene: Mapping[str, Any]) -> None:
        """Write scene.json (replacing it atomically); call again with the updated mapping.

        Numpy arrays become lists, tuples lists, non-finite floats strings (see to_jsonable).
        """
        self._check_open()
        if not isinstance(scene, Mapping):
            raise ReproError(f"scene must be a mapping, got {type(scene).__name__}")
        _write_json_atomic(self.out_dir / "scene.json", to_jsonable(scene))
        self._scene_written = True

    # ------------------------------------------------------------------ closing

    def _write_manifest(
        self, *, status: str, reason: str, ended_at: str | None, wall_time_s: float | None
    ) -> None:
        env = environment()
        try:
            summary = to_jsonable(self.summary)
        except ReproError as exc:  # never lose the manifest over an odd summary value
            summary = {str(k): repr(v) for k, v in self.summary.items()}
            summary["_summary_error"] = str(exc)
        manifest = {
            "format_version": FORMAT_VERSION,
            "experiment": self.experiment,
            "paper": self.paper,
            "status": status,
            "reason": reason,
            "config": self._config_json,
            "config_hash": self._config_hash,
            "seed": self.seed,
            "columns": list(self._columns or ()),
            "n_rows": self._rows_in_file() if ended_at is not None else self._n_rows,
            "n_events": self._n_events,
            "started_at": self._started_at,
            "ended_at": ended_at,
            "wall_time_s": wall_time_s,
            "concurrent_runs": concurrent_runs(),
            "hostname": _hostname(),
            "pid": os.getpid(),
            "boot_id": _boot_id(),
            "python": env["python"],
            "platform": env["platform"],
            "cpu": env["cpu"],
            "packages": env["packages"],
            "git_sha": self._git_sha,
            "git_dirty": self._git_dirty,
            "repro_version": env["repro_version"],
            "summary": summary,
        }
        _write_json_atomic(self._manifest_path, manifest)

    def close(self, status: str = "completed", reason: str = "") -> Path:
        """Flush the trace, write manifest.json and return its path. Idempotent.

        Args:
            status: one of RUN_STATUSES.
            reason: why the run ended that way (free text; empty for a normal completion).
        """
        if self._closed:
            return self._manifest_path
        if status not in RUN_STATUSES:
            raise UnknownChoiceError("run status", status, RUN_STATUSES)
        from repro.runs.signals import deferred

        with deferred():  # a signal while closing: the files are closed whole first
            return self._close(status, reason)

    def _close(self, status: str, reason: str) -> Path:
        self._closed = True
        wall_time_s = time.perf_counter() - self._t0
        try:
            self._settle_inflight()
            self.flush()
        finally:
            self._trace_file.close()
            self._events_file.close()
            if not self._scene_written:
                _write_json_atomic(self.out_dir / "scene.json", {})
            self._write_manifest(
                status=status, reason=reason, ended_at=_utc_now(), wall_time_s=wall_time_s
            )
        return self._manifest_path

    def __enter__(self) -> TraceRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            status = "interrupted" if issubclass(exc_type, KeyboardInterrupt) else "crashed"
            self.close(status=status, reason=f"{exc_type.__name__}: {exc}")
        # returning None re-raises the exception


# --------------------------------------------------------------------------- loading


@dataclasses.dataclass(frozen=True)
class RunFiles:
    """The four files of one run, read back."""

    trace: pd.DataFrame
    events: pd.DataFrame
    manifest: dict[str, Any]
    scene: dict[str, Any]


def _read_csv_kwargs() -> dict[str, Any]:
    # pandas >= 3 parses floats round-trip by default and deprecates the argument.
    major = int(pd.__version__.split(".", 1)[0])
    return {} if major >= 3 else {"float_precision": "round_trip"}


def load_run(run_dir: Path) -> RunFiles:
    """Read the four files of a run directory.

    Raises:
        ReproError: if the directory or one of its files is missing or unreadable.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ReproError(f"run directory {run_dir} does not exist")
    missing = [name for name in RUN_FILES if not (run_dir / name).is_file()]
    if missing:
        raise ReproError(f"run directory {run_dir} is missing {', '.join(missing)}")
    try:
        manifest = json.loads((run_dir / "manifest.json").read_text(encoding="utf-8"))
        scene = json.loads((run_dir / "scene.json").read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ReproError(f"cannot read the JSON files of run {run_dir}: {exc}") from exc
    trace_path = run_dir / "trace.csv"
    try:
        if trace_path.stat().st_size == 0:
            trace = pd.DataFrame(columns=list(manifest.get("columns") or ()))
        else:
            # low_memory=False: a column's type inferred from the whole file, not per chunk
            trace = pd.read_csv(trace_path, low_memory=False, **_read_csv_kwargs())
        events = pd.read_csv(
            run_dir / "events.csv",
            dtype={"kind": str, "detail": str},
            keep_default_na=False,
            na_values={"t": ["nan", "NaN"]},
            **_read_csv_kwargs(),
        )
    except (OSError, ValueError) as exc:
        raise ReproError(f"cannot read the CSV files of run {run_dir}: {exc}") from exc
    if tuple(events.columns) != EVENTS_COLUMNS:
        raise ReproError(
            f"{run_dir / 'events.csv'} has columns {list(events.columns)}, "
            f"expected {list(EVENTS_COLUMNS)}"
        )
    events = events.astype({"t": float, "step": "int64"})
    return RunFiles(trace=trace, events=events, manifest=manifest, scene=scene)


def add_vector(row: dict[str, Any], name: str, values: Any) -> None:
    """Put a vector into a trace row as columns ``name1, name2, ...`` (1-based, as papers
    number joints and sensors)."""
    for i, v in enumerate(values):
        row[f"{name}{i + 1}"] = v


# --------------------------------------------------------------------------- dead runs


def count_trace_rows(run_dir: Path) -> int:
    """Complete data rows of ``run_dir/trace.csv`` (header and a cut-off last line excluded)."""
    path = Path(run_dir) / "trace.csv"
    newlines = 0
    try:
        with open(path, "rb") as f:
            while chunk := f.read(1 << 20):
                newlines += chunk.count(b"\n")
    except OSError:
        return 0
    return max(newlines - 1, 0)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, owned by another user
        return True
    except (OSError, OverflowError, ValueError):
        return False
    return True


def _last_update(run_dir: Path) -> float | None:
    """Latest modification time [s since the epoch] of the run's files, None if none."""
    times = []
    for name in RUN_FILES:
        try:
            times.append((Path(run_dir) / name).stat().st_mtime)
        except OSError:
            continue
    return max(times) if times else None


def process_gone(
    manifest: Mapping[str, Any],
    run_dir: Path,
    *,
    now: float | None = None,
    stale_after_s: float = STALE_AFTER_S,
) -> str | None:
    """Why a ``running`` run's process is known to be gone, or None (alive, or not running).

    On this host (same hostname): gone if the boot id changed or the pid is not alive.
    On another host, or for a manifest without a pid: gone if none of the run's files changed
    for ``stale_after_s`` seconds (``now`` defaults to the current time).
    """
    if manifest.get("status") != "running":
        return None
    pid, host = manifest.get("pid"), manifest.get("hostname")
    if isinstance(pid, int) and host == _hostname():
        boot = manifest.get("boot_id")
        if boot is not None and _boot_id() is not None and boot != _boot_id():
            return f"process gone: host {host} rebooted since pid {pid} started"
        if not _pid_alive(pid):
            return f"process gone: pid {pid} on {host} is not running"
        return None
    last = _last_update(run_dir)
    now = time.time() if now is None else now
    if last is None or now - last >= stale_after_s:
        where = f"pid {pid} on {host}" if isinstance(pid, int) else "an unknown process"
        idle = "no run file" if last is None else f"no update for {(now - last) / 3600:.1f} h"
        return f"process gone: {where}, {idle}"
    return None


def effective_manifest(
    run_dir: Path,
    manifest: Mapping[str, Any] | None = None,
    *,
    now: float | None = None,
    stale_after_s: float = STALE_AFTER_S,
) -> dict[str, Any]:
    """The manifest of ``run_dir`` as it should be read (a copy; nothing is written).

    A ``running`` manifest whose process is gone (:func:`process_gone`) comes back with
    status ``"interrupted"``, reason ``"process gone: ..."``, ``n_rows`` counted in
    trace.csv and ``ended_at`` the time of the last write. Other manifests are returned as is.
    ``manifest`` defaults to ``run_dir/manifest.json``.

    Raises:
        ReproError: if ``manifest`` is None and manifest.json is missing or not a JSON object.
    """
    run_dir = Path(run_dir)
    if manifest is None:
        manifest = _read_manifest(run_dir / "manifest.json")
    out = dict(manifest)
    why = process_gone(out, run_dir, now=now, stale_after_s=stale_after_s)
    if why is None:
        return out
    n_rows = count_trace_rows(run_dir)
    last = _last_update(run_dir)
    out.update(
        status="interrupted",
        reason=f"{why}; {n_rows} rows in trace.csv (rerun it)",
        n_rows=n_rows,
        ended_at=None if last is None else _utc_iso(datetime.fromtimestamp(last, UTC)),
    )
    return out


def mark_if_gone(run_dir: Path, **kwargs: Any) -> dict[str, Any] | None:
    """Rewrite ``run_dir/manifest.json`` as :func:`effective_manifest` reads it, if that
    changes it; return the new manifest, or None when the run was not a dead ``running`` one
    (or has no readable manifest). ``kwargs`` go to :func:`effective_manifest`."""
    path = Path(run_dir) / "manifest.json"
    try:
        manifest = _read_manifest(path)
    except ReproError:
        return None
    fixed = effective_manifest(run_dir, manifest, **kwargs)
    if fixed == manifest:
        return None
    _write_json_atomic(path, fixed)
    return fixed


def update_manifest(run_dir: Path, **fields: Any) -> dict[str, Any]:
    """Set ``fields`` in ``run_dir/manifest.json`` (written atomically); return the manifest.

    Raises:
        ReproError: if manifest.json is missing or not a JSON object.
    """
    path = Path(run_dir) / "manifest.json"
    manifest = _read_manifest(path)
    manifest.update(to_jsonable(fields))
    _write_json_atomic(path, manifest)
    return manifest


def _read_manifest(path: Path) -> dict[str, Any]:
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ReproError(f"cannot read manifest {path}: {exc}") from exc
    if not isinstance(manifest, dict):
        raise ReproError(f"manifest {path} is not a JSON object")
    return manifest
