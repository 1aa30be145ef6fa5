"""The experiment registry: papers and their experiments, found through entry points.

Each paper package (``experiments/<paper>/``) exposes a :class:`Paper` and
declares it in ``pyproject.toml``::

    [project.entry-points."repro.experiments"]
    thomas2024 = "experiments.thomas2024:EXPERIMENTS"

``repro`` never imports ``experiments`` directly; :func:`load_papers` reads
the ``repro.experiments`` entry-point group.

Results layout: ``<results_dir>/<paper>/<name>/`` holds one experiment's trace
files and its ``manifest.json`` (with at least ``status`` and ``config_hash``). A run is
written into ``<results_dir>/<paper>/.partial/<name>/`` and swapped in when it returns
(:mod:`repro.runs.staging`); a stopped run stays there, the complete one in place.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib
import inspect
import json
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

from repro.config import check_declared, validate
from repro.errors import ReproError, UnknownChoiceError
from repro.runs.staging import run_folder_lock, staged

__all__ = [
    "ENTRY_POINT_GROUP",
    "Experiment",
    "Paper",
    "load_papers",
    "find_experiment",
    "all_experiments",
    "experiment_dir",
    "compute_config_hash",
    "check_config",
    "run_experiment",
    "run_folder_lock",
    "run_in",
    "is_stale",
]

ENTRY_POINT_GROUP = "repro.experiments"
MANIFEST_NAME = "manifest.json"


@dataclass(frozen=True)
class Experiment:
    """One runnable experiment of a paper.

    ``config_cls()`` gives the paper's default configuration (a frozen
    dataclass). ``run(config, out_dir)`` writes trace files and a
    ``manifest.json`` into ``out_dir`` and returns ``out_dir``; :func:`run_experiment`
    gives it the staging folder of the run's folder (``results/<paper>/.partial/<name>``,
    swapped in for ``results/<paper>/<name>`` when it returns), so a run must name its own
    files by relative paths only; if it accepts an ``experiment`` keyword,
    :func:`run_experiment` passes the registered name through it. ``slow``
    experiments are skipped by ``repro results`` unless ``--include-slow`` is
    given. ``check(config)`` (optional) raises :class:`~repro.errors.ConfigError`
    for a config that passes the field ranges but cannot run (lengths, joint
    limits...); :func:`check_config` calls it before any folder is created.
    """

    name: str
    paper: str
    description: str
    config_cls: type
    run: Callable[..., Path]
    slow: bool = False
    check: Callable[[Any], None] | None = None

    @property
    def id(self) -> str:
        """Full id ``"<paper>.<name>"``, e.g. ``"thomas2024.case1"``."""
        return f"{self.paper}.{self.name}"


@dataclass(frozen=True)
class Paper:
    """A reproduced paper: its experiments, figure builder and checked claims.

    ``figures(results_dir, figures_dir)`` draws the paper's figures from the
    traces and returns the written paths; ``claims()`` returns
    ``repro.runs.claims.Claim`` objects.
    """

    key: str
    experiments: tuple[Experiment, ...]
    figures: Callable[[Path, Path], list[Path]] | None = None
    claims: Callable[[], Sequence[Any]] | None = None
    #: ``bench(results_dir)`` -> rows (dicts with benchmark, median_s, p95_s, n) for
    #: ``make bench``; may read the committed traces to replay realistic states.
    bench: Callable[[Path], list[dict[str, Any]]] | None = None
    #: ``{experiment: (partner, ...)}``: experiments swept on the same variants as
    #: ``experiment`` (an ablation on the same scene; :mod:`repro.runs.sweep`)
    sweep_groups: Mapping[str, tuple[str, ...]] = dataclasses.field(default_factory=dict)
    #: claims the paper makes together, whose joint rate a sweep reports (e.g. thomas2024
    #: 1, 2, 3: case 1 converges, its ablation collides, in that order of events)
    joint_claims: tuple[tuple[str, ...], ...] = ()
    #: ``causes()`` -> a :class:`repro.runs.causes.CauseModel`: why each clause fails over
    #: the sweeps' scenes (issue 37), or None
    causes: Callable[[], Any] | None = None


# --------------------------------------------------------------------------- discovery


def _entry_points(group: str) -> Iterable[metadata.EntryPoint]:
    """The installed entry points of ``group`` (a seam for tests)."""
    return metadata.entry_points(group=group)


def load_papers() -> dict[str, Paper]:
    """Every registered :class:`Paper`, keyed by ``paper.key``, in sorted key order.

    Raises :class:`ReproError` naming the entry point if it cannot be imported,
    is not a :class:`Paper`, or is inconsistent (key differs from the entry-point
    name, an experiment names another paper, duplicate experiment names).
    """
    papers: dict[str, Paper] = {}
    for ep in sorted(_entry_points(ENTRY_POINT_GROUP), key=lambda e: e.name):
        try:
            obj = ep.load()
        except Exception as exc:
            raise ReproError(
                f"cannot load experiment entry point {ep.name!r} ({ep.value}): "
                f"{type(exc).__name__}: {exc}"
            ) from exc
        _check_paper(ep.name, ep.value, obj)
        if obj.key in papers:
            raise ReproError(f"paper {obj.key!r} is registered twice (entry point {ep.name!r})")
        papers[obj.key] = obj
    return papers


def _check_paper(ep_name: str, ep_value: str, obj: Any) -> None:
    where = f"entry point {ep_name!r} ({ep_value})"
    if not isinstance(obj, Paper):
        raise ReproError(f"{where} must be a repro.runs.registry.Paper, got {type(obj).__name__}")
    if obj.key != ep_name:
        raise ReproError(f"{where} gives a Paper with key {obj.key!r}; expected {ep_name!r}")
    seen: set[str] = set()
    for exp in obj.experiments:
        if not isinstance(exp, Experiment):
            raise ReproError(
                f"{where}: experiments must be Experiment objects, got {type(exp).__name__}"
            )
        if exp.paper != obj.key:
            raise ReproError(
                f"{where}: experiment {exp.name!r} has paper={exp.paper!r}; expected {obj.key!r}"
            )
        if exp.name in seen:
            raise ReproError(f"{where}: experiment name {exp.name!r} is used twice")
        seen.add(exp.name)
        try:
            check_declared(exp.config_cls)
        except ReproError as exc:
            raise ReproError(f"{where}: experiment {exp.name!r}: {exc}") from exc


def all_experiments(papers: Mapping[str, Paper]) -> list[Experiment]:
    """Every experiment of ``papers``, in paper order then declaration order."""
    return [exp for paper in papers.values() for exp in paper.experiments]


def find_experiment(papers: Mapping[str, Paper], name: str) -> Experiment:
    """The experiment with full id ``name`` (``"thomas2024.case1"``) or unique bare name.

    Raises :class:`UnknownChoiceError` listing every experiment id if ``name``
    matches nothing or a bare name matches experiments of several papers.
    """
    experiments = all_experiments(papers)
    ids = [exp.id for exp in experiments]
    matches = [exp for exp in experiments if exp.id == name]
    if not matches and "." not in name:
        matches = [exp for exp in experiments if exp.name == name]
    if len(matches) == 1:
        return matches[0]
    err = UnknownChoiceError("experiment", name, ids)
    if len(matches) > 1:
        err.args = (
            f"ambiguous experiment {name!r}: it names "
            f"{', '.join(exp.id for exp in matches)}; use the full id "
            f"(valid choices: {', '.join(err.choices)})",
        )
    raise err


# --------------------------------------------------------------------------- staleness


def experiment_dir(results_dir: Path, exp: Experiment) -> Path:
    """Default output directory of ``exp``: ``<results_dir>/<paper>/<name>``."""
    return Path(results_dir) / exp.paper / exp.name


def _fallback_config_hash(config: Any) -> str:
    """sha256 hex digest of the canonical JSON of ``dataclasses.asdict(config)``."""
    payload = json.dumps(
        dataclasses.asdict(config), sort_keys=True, separators=(",", ":"), default=str
    )
    return hashlib.sha256(payload.encode("utf-8")).hexdigest()


def compute_config_hash(config: Any) -> str:
    """The hash recorded in manifests: ``repro.runs.trace.config_hash`` if available."""
    try:
        from repro.runs.trace import config_hash
    except ImportError:
        return _fallback_config_hash(config)
    return str(config_hash(config))


def check_config(exp: Experiment, config: Any) -> None:
    """Validate ``config`` for ``exp``: field ranges and choices, then ``exp.check``.

    Call it before creating any output folder. Raises :class:`~repro.errors.ConfigError`.
    """
    validate(config)
    if exp.check is not None:
        exp.check(config)


def _accepts_keyword(fn: Callable[..., Any], name: str) -> bool:
    try:
        parameters = inspect.signature(fn).parameters
    except (TypeError, ValueError):
        return False
    param = parameters.get(name)
    return param is not None and param.kind in (
        inspect.Parameter.KEYWORD_ONLY,
        inspect.Parameter.POSITIONAL_OR_KEYWORD,
    )


def run_experiment(exp: Experiment, config: Any, out_dir: Path) -> Path:
    """Run ``exp`` with ``config`` for the run folder ``out_dir``; return the run's folder.

    The run is written into ``out_dir``'s staging folder and replaces ``out_dir`` only when
    ``exp.run`` returns (:func:`repro.runs.staging.staged`): an interrupted, crashed or
    killed run leaves ``out_dir`` as it was and its partial files in
    ``<parent>/.partial/<name>``. A path the run returns inside the staging folder is given
    back inside ``out_dir``.
    """
    out_dir = Path(out_dir)
    with staged(out_dir) as stage:
        result = run_in(exp, config, stage)
    with contextlib.suppress(ValueError):
        return out_dir / result.relative_to(stage)
    return result


def run_in(exp: Experiment, config: Any, folder: Path) -> Path:
    """Run ``exp`` with ``config`` straight into ``folder``, which the caller holds (a staging
    folder: :func:`run_experiment`, a sweep's variant, :func:`repro.runs.sweep.run_variant`);
    return what ``exp.run`` returned (``folder`` if nothing).

    The manifest names the registered experiment (``exp.name``) whatever the folder is
    called (``--out``, ``<name>__<hash>``): passed as ``experiment=`` when ``exp.run``
    accepts that keyword, else written into the manifest the run wrote (also after an
    interrupt or a crash).
    """
    folder = Path(folder)
    kwargs = {"experiment": exp.name} if _accepts_keyword(exp.run, "experiment") else {}
    started = time.time()
    try:
        result = exp.run(config, folder, **kwargs)
    finally:
        _name_experiment(folder, exp.name, since=started)
    return Path(result) if result is not None else folder


def _name_experiment(out_dir: Path, name: str, *, since: float) -> None:
    """Set the manifest's ``experiment`` to ``name`` if this run wrote it (not an old one)."""
    from repro.runs.trace import update_manifest

    path = out_dir / MANIFEST_NAME
    try:
        if path.stat().st_mtime < since - 1.0:  # 1 s: coarse file-system clocks
            return
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return
    if isinstance(manifest, dict) and manifest.get("experiment") != name:
        update_manifest(out_dir, experiment=name)


def is_stale(exp: Experiment, results_dir: Path, config: Any) -> tuple[bool, str]:
    """Whether ``exp``'s trace under ``results_dir`` must be (re)made for ``config``.

    Stale if ``<results_dir>/<paper>/<name>/manifest.json`` is missing or
    unreadable, its ``status`` is not ``"completed"``, its ``config_hash``
    differs from the hash of ``config``, or the folder fails a rule of
    :func:`repro.runs.validate.check_run`. Returns ``(stale, reason)``.
    """
    manifest_path = experiment_dir(results_dir, exp) / MANIFEST_NAME
    if not manifest_path.is_file():
        return True, f"no manifest at {manifest_path}"
    try:
        manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return True, f"unreadable manifest {manifest_path}: {exc}"
    if not isinstance(manifest, dict):
        return True, f"malformed manifest {manifest_path}: not a JSON object"
    status = manifest.get("status")
    if status != "completed":
        return True, f"last run status is {status!r}, not 'completed'"
    recorded = manifest.get("config_hash")
    expected = compute_config_hash(config)
    if recorded != expected:
        return True, f"config changed (manifest hash {recorded!r}, current {expected!r})"
    from repro.runs.validate import DamagedRun, check_run

    try:  # a damaged folder (cut trace, wrong row count...) is remade, not called fresh
        check_run(manifest_path.parent)
    except DamagedRun as exc:
        return True, exc.rule
    return False, f"fresh (completed, config hash {expected[:12]})"


def lazy(module: str, attribute: str) -> Callable[..., Any]:
    """A callable that imports ``module`` only when called and forwards to ``attribute``
    (so that listing experiments does not import matplotlib, CasADi...)."""

    def call(*args: Any, **kwargs: Any) -> Any:
        target = getattr(importlib.import_module(module), attribute)
        return target(*args, **kwargs) if callable(target) else target

    call.__name__ = f"{module}.{attribute}"
    return call
