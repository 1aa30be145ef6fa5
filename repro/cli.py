"""The ``repro`` command line (also ``python -m repro``).

Subcommands::

    repro list [-v]                       experiments (and with -v their config fields)
    repro run EXP [--set KEY=VALUE]... [--video] [--out DIR [--force]]
    repro results [--force] [--paper P] [--include-slow] [-j N]
    repro figures [--paper P]             figures, then results/claims.csv
    repro video RUN_DIR [--out FILE] [--fps N] [--size WxH] [--speed X] | --all [--paper P]
    repro report [--output REPORT.md]

Global options ``--results DIR`` (default ``./results``) and ``--figures DIR``
(default ``./figures``) may be given before or after the subcommand.
A :class:`~repro.errors.ReproError` prints one line on stderr and exits 2.
Every config is validated (ranges, choices, the experiment's own check) before any
folder is created. A run is written beside its folder (``<parent>/.partial/<name>/``) and
swapped in when it returns (:mod:`repro.runs.staging`). SIGINT and SIGTERM during a run
close it with status ``interrupted`` there, leave the folder it would replace as it was,
print one line and exit 130 / 143 (128 + the signal number).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import signal
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from repro.config import apply_overrides, config_keys, describe
from repro.errors import ConfigError, ReproError, UnknownChoiceError
from repro.runs import registry
from repro.runs.registry import Experiment, Paper
from repro.runs.signals import stop_on_signals
from repro.runs.staging import PARTIAL_DIR, REPLACED_DIR, staging_dir

__all__ = ["main", "build_parser"]

DEFAULT_RESULTS = Path("results")
DEFAULT_FIGURES = Path("figures")
DEFAULT_REPORT = Path("REPORT.md")
EXIT_USAGE = 2
SHORT_HASH_LEN = 8


# --------------------------------------------------------------------------- parser


def _path(text: str) -> Path:
    """An argparse path that is not empty (``Path("")`` would be the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path; give a folder or file name")
    return Path(text)


def _add_global_options(parser: argparse.ArgumentParser, *, top_level: bool) -> None:
    # Sub-parsers use SUPPRESS so an option given before the subcommand is not
    # reset to its default by the sub-parser.
    parser.add_argument(
        "--results",
        type=_path,
        metavar="DIR",
        default=DEFAULT_RESULTS if top_level else argparse.SUPPRESS,
        help="results directory (default: ./results)",
    )
    parser.add_argument(
        "--figures",
        type=_path,
        metavar="DIR",
        default=DEFAULT_FIGURES if top_level else argparse.SUPPRESS,
        help="figures directory (default: ./figures)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of ``repro``; each subcommand sets ``func``."""
    parser = argparse.ArgumentParser(
        prog="repro", description="Reproduce robotics papers in PyBullet."
    )
    _add_global_options(parser, top_level=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("list", help="list the registered experiments")
    _add_global_options(p, top_level=False)
    p.add_argument("-v", "--verbose", action="store_true", help="also list config fields")
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser("run", help="run one experiment")
    _add_global_options(p, top_level=False)
    p.add_argument("experiment", help="experiment id, e.g. thomas2024.case1 (or a unique name)")
    p.add_argument(
        "--set",
        dest="overrides",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        help="override one config field; repeat for several "
        "(--set duration=5 --set camera_mode=exact); keys: repro list -v",
    )
    p.add_argument("--video", action="store_true", help="record a video (sets video=True)")
    p.add_argument(
        "--out",
        type=_path,
        metavar="DIR",
        default=None,
        help="output directory (default: <results>/<paper>/<name>, "
        "or <name>__<hash> when the config differs from the defaults)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="let --out overwrite a registered default run or a run of another config",
    )
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser(
        "results",
        help="run every experiment whose trace is missing or stale; mark runs whose "
        "process is gone as interrupted",
    )
    _add_global_options(p, top_level=False)
    p.add_argument("--force", action="store_true", help="rerun even fresh experiments")
    p.add_argument("--paper", metavar="P", default=None, help="only this paper")
    p.add_argument("--include-slow", action="store_true", help="also run slow experiments")
    p.add_argument("-j", "--jobs", type=_positive_int, default=None, metavar="N",
                   help="run up to N experiments at once, each in its own process (default: "
                        "the number of cores; 1: one after another in this process)")
    p.set_defaults(func=_cmd_results)

    p = sub.add_parser("sweep", help="run quasi-random variants of an experiment's declared "
                       "ranges and judge its claims on each (results/sweeps/<exp>/)")
    _add_global_options(p, top_level=False)
    p.add_argument("experiment", help="experiment id, e.g. pomares2011.exp3")
    p.add_argument("--n", type=_variant_count, required=True,
                   help="number of variants (a larger n extends a sweep: its first variants "
                        "are the smaller sweep's)")
    p.add_argument("--seed", type=int, default=0, help="seed of the Sobol sequence")
    p.add_argument("--camera", choices=("exact", "render"), default="exact",
                   help="camera mode of every variant (default: exact, for throughput)")
    p.add_argument("--keep-traces", action="store_true",
                   help="keep each variant's trace.csv (default: manifest, events, verdicts)")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="run on an existing Dask cluster (tcp://host:port); default: a "
                        "LocalCluster of one single-threaded worker process per core")
    p.add_argument("-j", "--workers", type=_positive_int, default=None, metavar="N",
                   help="LocalCluster workers (default: the number of cores)")
    p.add_argument("--serial", action="store_true",
                   help="no Dask: the variants one after another in this process")
    p.set_defaults(func=_cmd_sweep)

    p = sub.add_parser("counterfactual", help="rerun a sweep's variants that failed by one "
                       "cause with only that cause removed (issue 37; "
                       "results/sweeps/<exp>/counterfactuals/<name>/)")
    _add_global_options(p, top_level=False)
    p.add_argument("experiment", help="experiment id of a committed sweep, e.g. "
                   "thomas2024.case1")
    p.add_argument("name", help="the counterfactual (`repro list -v` names them)")
    p.add_argument("--camera", choices=("exact", "render"), default="exact",
                   help="the sweep it reruns (default: the exact-camera one)")
    p.add_argument("-j", "--workers", type=_positive_int, default=None, metavar="N",
                   help="LocalCluster workers (default: the number of cores)")
    p.add_argument("--serial", action="store_true",
                   help="no Dask: the variants one after another in this process")
    p.set_defaults(func=_cmd_counterfactual)

    p = sub.add_parser("cause-videos", help="one MP4 per named cause of a sweep: its example "
                       "variant rerun and replayed (<figures>/<paper>/videos/causes/)")
    _add_global_options(p, top_level=False)
    p.add_argument("experiment", help="experiment id of a committed sweep, e.g. "
                   "thomas2024.case1")
    p.add_argument("--camera", choices=("exact", "render"), default="exact",
                   help="the sweep whose causes to show (default: the exact-camera one)")
    p.set_defaults(func=_cmd_cause_videos)

    p = sub.add_parser("figures", help="draw figures and evaluate claims from the traces")
    _add_global_options(p, top_level=False)
    p.add_argument("--paper", metavar="P", default=None, help="only this paper")
    p.set_defaults(func=_cmd_figures)

    p = sub.add_parser("video", help="an MP4 of a run replayed from its own files (scene.json, "
                       "trace.csv, its URDFs); --all: one per canonical run under "
                       "<figures>/<paper>/videos/")
    _add_global_options(p, top_level=False)
    p.add_argument("run_dir", nargs="?", type=_path, default=None, metavar="RUN_DIR",
                   help="a run folder, e.g. results/thomas2024/case3")
    p.add_argument("--all", action="store_true",
                   help="every registered experiment's canonical run that has a time axis")
    p.add_argument("--paper", metavar="P", default=None, help="with --all: only this paper")
    p.add_argument("--out", type=_path, metavar="FILE", default=None,
                   help="output file (default: RUN_DIR/video.mp4)")
    p.add_argument("--fps", type=float, default=None, help="frames per second (default 20)")
    p.add_argument("--size", type=_frame_size, default=None, metavar="WxH",
                   help="frame size, multiples of 16 (default 960x480)")
    p.add_argument("--speed", type=float, default=None,
                   help="simulated seconds per video second (default 1, faster for runs "
                        "longer than 40 s so the video lasts 40 s)")
    p.set_defaults(func=_cmd_video)

    p = sub.add_parser("report", help="render REPORT.md")
    _add_global_options(p, top_level=False)
    p.add_argument(
        "--output", type=_path, metavar="FILE", default=DEFAULT_REPORT, help="(default: REPORT.md)"
    )
    p.set_defaults(func=_cmd_report)
    return parser


def _frame_size(text: str) -> tuple[int, int]:
    """``WxH`` in pixels, e.g. ``960x480``."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"{text!r} is not WxH, e.g. 960x480")
    return int(m.group(1)), int(m.group(2))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``repro``; returns the process exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    try:
        return int(args.func(args))
    except ReproError as exc:
        message = " ".join(str(exc).split("\n"))
        print(f"repro: error: {message}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:  # outside a run (loading, listing...): nothing to close
        print("repro: interrupted", file=sys.stderr)
        return 128 + signal.SIGINT


# --------------------------------------------------------------------------- helpers


def _select_papers(papers: Mapping[str, Paper], key: str | None) -> dict[str, Paper]:
    if key is None:
        return dict(papers)
    if key not in papers:
        raise UnknownChoiceError("paper", key, papers)
    return {key: papers[key]}


def _first_line(text: str) -> str:
    lines = text.strip().splitlines()
    return lines[0] if lines else ""


def prepare_config(exp: Experiment, overrides: Sequence[str], video: bool = False) -> Any:
    """``exp``'s default config with ``overrides`` (and ``video=True``) applied, validated
    and checked by the experiment (:func:`repro.runs.registry.check_config`)."""
    config = exp.config_cls()
    if video:
        names = {f.name for f in dataclasses.fields(config)}
        if "video" not in names:
            raise ConfigError(
                f"experiment {exp.id} does not support --video: its config "
                f"{type(config).__name__} has no 'video' field; "
                f"valid keys: {', '.join(config_keys(config))}"
            )
        overrides = [*overrides, "video=true"]
    config = apply_overrides(config, overrides)
    registry.check_config(exp, config)
    return config


def default_out_dir(exp: Experiment, results_dir: Path, config: Any) -> Path:
    """``<results>/<paper>/<name>``, or ``<name>__<short config hash>`` for a non-default config.

    Any override that changes the config gets its own directory, so the default traces are
    never overwritten by a variant; ``--video`` is output-only (same trace, plus video.mp4)
    and keeps the default directory.
    """
    base = registry.experiment_dir(results_dir, exp)
    digest = registry.compute_config_hash(config)
    if digest == registry.compute_config_hash(exp.config_cls()):
        return base
    return base.with_name(f"{exp.name}__{digest[:SHORT_HASH_LEN]}")


def _interrupted(fired: list[int], out_dir: Path, since: float) -> int:
    """Print the one-line report of a run of ``out_dir`` interrupted after ``since``
    (time.time()); return the exit code 128 + signum. The partial run is in the staging
    folder, ``out_dir`` as it was; a signal that came as the run was swapped in (it is
    acted on once the swap is done) finds no staging folder and a fresh manifest."""
    from repro.runs.trace import count_trace_rows

    signum = fired[0] if fired else int(signal.SIGINT)
    name = signal.Signals(signum).name
    stage = staging_dir(out_dir)
    manifest = out_dir / registry.MANIFEST_NAME
    if (stage / registry.MANIFEST_NAME).is_file():
        kept = (f"; {out_dir} kept as it was" if manifest.is_file()
                else f"; nothing in {out_dir}")
        line = (f"after {count_trace_rows(stage)} rows; partial trace in {stage}{kept}")
    elif manifest.is_file() and manifest.stat().st_mtime >= since - 1.0:  # coarse fs clocks
        line = f"as the run closed; it is complete in {out_dir}"
    else:
        line = f"before the run recorded anything; {out_dir} as it was"
    print(f"repro: interrupted ({name}) {line}", file=sys.stderr)
    return 128 + signum


def check_dir_arg(path: Path, option: str, must_exist: bool = False) -> None:
    """Refuse a folder argument that cannot be one, before anything is written: a
    file (or below one), missing when it must exist, or not writable where it would be
    made. Raises :class:`ConfigError` with one line naming ``option``. (An empty path is
    refused by the parser, :func:`_path`.)"""
    probe = Path(path)
    if probe.exists() and not probe.is_dir():
        raise ConfigError(f"{option} {path} is a file, not a folder")
    for parent in probe.parents:
        if parent.exists():
            if not parent.is_dir():
                raise ConfigError(f"{option} {path}: {parent} is a file, not a folder")
            break
    if not probe.exists():
        if must_exist:
            raise ConfigError(f"{option} {path} does not exist")
        existing = next((q for q in probe.parents if q.exists()), Path("."))
        if not os.access(existing, os.W_OK | os.X_OK):
            raise ConfigError(f"{option} {path} cannot be created: {existing} is not writable")
    elif not must_exist and not os.access(probe, os.W_OK | os.X_OK):
        raise ConfigError(f"{option} {path} is not writable")


def make_dir(path: Path, option: str) -> None:
    """``mkdir -p path``, or a one-line :class:`ConfigError` naming ``option``."""
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{option} {path} cannot be created: {exc.strerror or exc}") from exc


def check_run_location(out_dir: Path, results_dir: Path, papers: Mapping[str, Paper]) -> None:
    """Refuse an ``--out`` where no run belongs: the results folder itself, a paper's folder
    in it, a folder inside another run, or a folder that holds runs."""
    target = Path(out_dir).resolve()
    root = Path(results_dir).resolve()
    if any(part in (PARTIAL_DIR, REPLACED_DIR) for part in target.parts):
        raise ConfigError(f"--out {out_dir} is inside a {PARTIAL_DIR} or {REPLACED_DIR} "
                          "folder, where runs are written aside before they replace their "
                          "folder: give a folder of its own")
    if target == root or (target.parent == root and target.name in papers):
        raise ConfigError(f"--out {out_dir} is a results folder that holds runs, not a run "
                          "folder: give a folder of its own (e.g. <results>/<paper>/<name>)")
    for parent in target.parents:
        if (parent / registry.MANIFEST_NAME).is_file():
            raise ConfigError(f"--out {out_dir} is inside the run folder {parent}: give a "
                              "folder of its own")
    if target.is_dir() and any(target.glob(f"*/{registry.MANIFEST_NAME}")):
        raise ConfigError(f"--out {out_dir} holds other runs: give a folder of its own")


def _registered_run(papers: Mapping[str, Paper], results_dir: Path, path: Path) -> str | None:
    """The id of the experiment whose default folder ``path`` is, if any."""
    target = path.resolve()
    for other in registry.all_experiments(papers):
        if registry.experiment_dir(results_dir, other).resolve() == target:
            return other.id
    return None


def check_out_dir(
    exp: Experiment, config: Any, out_dir: Path, papers: Mapping[str, Paper], results_dir: Path
) -> None:
    """Refuse an ``--out`` folder holding another run: a registered default folder (unless
    this is that experiment with its default config) or a manifest of another experiment or
    config. Raises :class:`ConfigError` (``--force`` skips this check)."""
    digest = registry.compute_config_hash(config)
    owner = _registered_run(papers, results_dir, out_dir)
    is_default = digest == registry.compute_config_hash(exp.config_cls())
    if owner is not None and not (owner == exp.id and is_default):
        raise ConfigError(
            f"--out {out_dir} is the default folder of {owner}; a run of {exp.id} with this "
            "config would overwrite its committed trace: choose another folder (or drop "
            "--out: overrides go to <name>__<hash>), or add --force"
        )
    manifest_path = out_dir / registry.MANIFEST_NAME
    if not manifest_path.is_file():
        return
    try:
        manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        manifest = {}
    if not isinstance(manifest, dict):
        manifest = {}
    same_run = (
        manifest.get("paper") == exp.paper
        and manifest.get("experiment") == exp.name
        and manifest.get("config_hash") == digest
    )
    if not same_run:
        held = f"{manifest.get('paper', '?')}.{manifest.get('experiment', '?')}"
        held_hash = str(manifest.get("config_hash") or "?")[:SHORT_HASH_LEN]
        raise ConfigError(
            f"--out {out_dir} holds a run of {held} (config {held_hash}), not of {exp.id} with "
            f"config {digest[:SHORT_HASH_LEN]}; refusing to overwrite it: choose another "
            "folder, or add --force"
        )


# --------------------------------------------------------------------------- commands


def _cmd_list(args: argparse.Namespace) -> int:
    out = sys.stdout
    papers = registry.load_papers()
    experiments = registry.all_experiments(papers)
    if not experiments:
        print(
            f"no experiments registered (entry-point group {registry.ENTRY_POINT_GROUP!r})",
            file=out,
        )
        return 0
    width = max(len(exp.id) for exp in experiments)
    for exp in experiments:
        slow = "  (slow)" if exp.slow else ""
        print(f"{exp.id:<{width}}  {_first_line(exp.description)}{slow}", file=out)
        if args.verbose:
            rows = describe(exp.config_cls)
            if not rows:
                continue
            head = max(len(f"{name}: {tname} = {default}") for name, tname, default, _ in rows)
            for name, tname, default, info in rows:
                left = f"{name}: {tname} = {default}"
                print(f"    {left:<{head}}  {info}".rstrip(), file=out)
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    papers = registry.load_papers()
    exp = registry.find_experiment(papers, args.experiment)
    # Validate everything before creating anything.
    config = prepare_config(exp, args.overrides, video=args.video)
    check_dir_arg(args.results, "--results")
    if args.out is not None:
        out_dir = args.out
        check_dir_arg(out_dir, "--out")
        check_run_location(out_dir, args.results, papers)
        if not args.force:
            check_out_dir(exp, config, out_dir, papers, args.results)
    else:
        out_dir = default_out_dir(exp, args.results, config)
    running = _running_elsewhere(out_dir)
    if running is not None:
        raise ConfigError(f"{out_dir} is being written by another run ({running}); wait for "
                          "it or choose another --out")
    # the run is written in <parent>/.partial/<name> and swapped in when it returns
    make_dir(out_dir.parent, "--out" if args.out is not None else "--results")
    print(f"running {exp.id} -> {out_dir}", file=sys.stderr)
    result = _run_interruptible(exp, config, out_dir)
    if isinstance(result, int):
        return result
    print(result)
    return 0


def _run_interruptible(exp: Experiment, config: Any, out_dir: Path) -> Path | int:
    """Run ``exp`` with SIGINT/SIGTERM closing it as interrupted; the run's folder, or the
    exit code of an interrupted run (one line printed)."""
    fired: list[int] = []
    started = time.time()
    try:
        # the first SIGINT / SIGTERM stops the run between two steps; it closes whole
        with stop_on_signals(fired):
            return registry.run_experiment(exp, config, out_dir)
    except KeyboardInterrupt:
        return _interrupted(fired, out_dir, started)


@dataclasses.dataclass(frozen=True)
class DeadRuns:
    """What ``repro results`` found of runs that did not end where they were going.

    ``marked``: run folders whose ``running`` manifest's process is gone, now marked
    interrupted (``(folder, new manifest)``); ``partial``: staging folders a stopped run left
    (``(staging folder, its manifest as read)``: interrupted or crashed; the run they would
    have replaced is untouched); ``recovered``: swaps a killed process cut short, undone or
    finished (one line each).
    """

    marked: list[tuple[Path, dict[str, Any]]]
    partial: list[tuple[Path, dict[str, Any]]]
    recovered: list[str]


def _fix_dead_runs(papers: Mapping[str, Paper], results_dir: Path) -> DeadRuns:
    """Under ``<results>/<paper>/`` of every paper: finish or undo a swap cut short
    (:func:`repro.runs.staging.recover_all`), mark every ``running`` run whose process is
    gone as interrupted (default and override folders alike), and find the partial runs in
    ``.partial/`` (live ones, still ``running``, excepted)."""
    from repro.runs.staging import partial_runs, recover_all
    from repro.runs.trace import effective_manifest, mark_if_gone, recover_manifest_tmp

    found = DeadRuns([], [], [])
    for paper in papers:
        paper_dir = Path(results_dir) / paper
        if not paper_dir.is_dir():
            continue
        found.recovered.extend(recover_all(paper_dir))
        partials = partial_runs(paper_dir)
        for run_dir in [*(p.parent for p in paper_dir.glob(f"*/{registry.MANIFEST_NAME}.tmp")),
                        *partials]:
            recover_manifest_tmp(run_dir)
        for manifest_path in sorted(paper_dir.glob(f"*/{registry.MANIFEST_NAME}")):
            manifest = mark_if_gone(manifest_path.parent)
            if manifest is not None:
                found.marked.append((manifest_path.parent, manifest))
        for run_dir in partials:
            mark_if_gone(run_dir)
            try:
                manifest = effective_manifest(run_dir)
            except ReproError:  # a staging folder without a manifest: a run just starting
                continue
            if manifest.get("status") != "running":  # a live run is busy, not partial
                found.partial.append((run_dir, manifest))
    return found


def _running_elsewhere(run_dir: Path) -> str | None:
    """``"pid N on HOST"`` if a live process is writing a run of ``run_dir``: a ``running``
    manifest in its staging folder (or, from a run made in place, in ``run_dir``)."""
    for folder in (staging_dir(run_dir), run_dir):
        try:
            manifest = json.loads((folder / registry.MANIFEST_NAME).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(manifest, dict) and manifest.get("status") == "running":
            return f"pid {manifest.get('pid', '?')} on {manifest.get('hostname', '?')}"
    return None


def _bounded_int(text: str, high: int) -> int:
    if not re.fullmatch(r"[0-9]+", text.strip()):  # int() would also take 1_0, +5, other digits
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number")
    value = int(text)
    if not 1 <= value <= high:
        raise argparse.ArgumentTypeError(f"{value} is not in [1, {high}]")
    return value


def _positive_int(text: str) -> int:
    """Worker and job counts: 1..1024."""
    return _bounded_int(text, 1024)


def _variant_count(text: str) -> int:
    """A sweep's variant count: 1..65536 (2**16 Sobol points; a sweep whose ranges refuse
    most starts, as thomas2024 case 2's do, needs more than 1024 to judge 100)."""
    return _bounded_int(text, 65536)


def _run_todo_parallel(todo: Sequence[tuple[Experiment, Any, str]], results: Path,
                       jobs: int, bar: Any) -> tuple[list[tuple[Experiment, str, Path]], int]:
    """The stale experiments in worker processes (repro.runs.parallel); (ran, exit code)."""
    from repro.runs.parallel import run_parallel

    out_dirs = [registry.experiment_dir(results, exp) for exp, _, _ in todo]
    for d in out_dirs:  # each run is written in <paper>/.partial/<name>, then swapped in
        make_dir(d.parent, "--results")

    def one(i: int) -> Path | int:
        exp, config, _ = todo[i]
        return _run_interruptible(exp, config, out_dirs[i])

    outcomes, fired = run_parallel(out_dirs, one, jobs, on_done=lambda o: bar.update(1))
    ran, code = [], 0
    for o in outcomes:
        exp, _, reason = todo[o.index]
        if o.status == "ran":
            ran.append((exp, reason, o.out_dir))
        else:
            detail = {"interrupted": "closed as interrupted", "crashed": "crashed (see its "
                      "manifest)", "lost": f"worker died (exit {o.exitcode}); marked "
                      "interrupted", "not_started": "not started"}[o.status]
            where = staging_dir(o.out_dir)  # the partial run, the run folder untouched
            if o.status == "not_started" or not where.is_dir():
                where = o.out_dir
            elif (o.out_dir / registry.MANIFEST_NAME).is_file():
                detail += f"; {o.out_dir} kept as it was"
            print(f"{o.status:<6} {exp.id}  ({detail}) -> {where}", file=sys.stderr)
            code = code or (1 if o.status in ("crashed", "lost") else 0)
    if fired is not None:
        code = 128 + fired
    return ran, code


def _partial_line(run_dir: Path, manifest: Mapping[str, Any], rerun: set[Path]) -> str:
    """The line of ``repro results`` for the partial run in the staging folder ``run_dir``
    (``rerun``: the run folders this invocation makes, each reusing its staging folder)."""
    target = run_dir.parent.parent / run_dir.name
    kept = ("kept as it was" if (target / registry.MANIFEST_NAME).is_file() else "has no run")
    fate = "rerun now" if target in rerun else "removed when that run is next made"
    return (f"{manifest.get('status', '?'):<11}  {run_dir}  (partial run: "
            f"{manifest.get('reason', '')}; {manifest.get('n_rows', '?')} rows; {target} "
            f"{kept}; {fate})")


def _cmd_results(args: argparse.Namespace) -> int:
    papers = _select_papers(registry.load_papers(), args.paper)
    check_dir_arg(args.results, "--results")
    fixed = _fix_dead_runs(papers, args.results)
    todo: list[tuple[Experiment, Any, str]] = []
    fresh: list[tuple[Experiment, str]] = []
    busy: list[tuple[Experiment, str]] = []
    skipped: list[Experiment] = []
    for exp in registry.all_experiments(papers):
        if exp.slow and not args.include_slow:
            skipped.append(exp)
            continue
        config = exp.config_cls()
        registry.check_config(exp, config)
        running = _running_elsewhere(registry.experiment_dir(args.results, exp))
        if running is not None:  # never write into a folder a live run is writing
            busy.append((exp, running))
            continue
        if args.force:
            todo.append((exp, config, "forced"))
            continue
        stale, reason = registry.is_stale(exp, args.results, config)
        if stale:
            todo.append((exp, config, reason))
        else:
            fresh.append((exp, reason))

    for line in fixed.recovered:
        print(f"recovered    {line}")
    for run_dir, manifest in fixed.marked:
        print(f"interrupted  {run_dir}  ({manifest['reason']})")
    rerun = {registry.experiment_dir(args.results, exp) for exp, _, _ in todo}
    for run_dir, manifest in fixed.partial:
        print(_partial_line(run_dir, manifest, rerun))
    ran: list[tuple[Experiment, str, Path]] = []
    jobs = args.jobs if args.jobs is not None else (os.cpu_count() or 1)
    code = 0
    with tqdm(
        total=len(todo),
        desc="experiments",
        unit="exp",
        file=sys.stderr,
        disable=not sys.stderr.isatty(),
    ) as bar:
        if jobs > 1 and len(todo) > 1:
            ran, code = _run_todo_parallel(todo, args.results, jobs, bar)
            todo = []
        for exp, config, reason in todo:
            bar.set_postfix_str(exp.id)
            out_dir = registry.experiment_dir(args.results, exp)
            make_dir(out_dir.parent, "--results")  # the run is written in .partial/<name>
            path = _run_interruptible(exp, config, out_dir)
            if isinstance(path, int):
                return path
            ran.append((exp, reason, path))
            bar.update(1)

    for exp, reason, path in ran:
        print(f"ran    {exp.id}  ({reason}) -> {path}")
    for exp, reason in fresh:
        print(f"fresh  {exp.id}  ({reason})")
    for exp, running in busy:
        print(f"busy   {exp.id}  (running as {running}; not rerun)")
    for exp in skipped:
        print(f"skip   {exp.id}  (slow; use --include-slow)")
    counts = f"{len(ran)} ran, {len(fresh)} fresh, {len(skipped)} skipped"
    if busy:
        counts += f", {len(busy)} busy"
    if fixed.marked:
        counts += f", {len(fixed.marked)} marked interrupted"
    if fixed.partial:
        counts += f", {len(fixed.partial)} partial"
    print(counts)
    return code


def _cmd_video(args: argparse.Namespace) -> int:
    """Issue 20: ``repro video RUN_DIR`` or ``repro video --all``."""
    from repro.replay import video

    opts: dict[str, Any] = {k: v for k, v in (("fps", args.fps), ("size", args.size),
                                              ("speed", args.speed)) if v is not None}
    if args.all == (args.run_dir is not None):
        raise ConfigError("give either RUN_DIR or --all")
    if args.run_dir is not None:
        if args.paper is not None:
            raise ConfigError("--paper goes with --all")
        video.check_options(**opts)
        video.check_run_dir(args.run_dir)
        print(f"wrote {video.write_video(args.run_dir, args.out, **opts)}")
        return 0
    if args.out is not None:
        raise ConfigError("--out names one file: give RUN_DIR, or --figures for --all")
    video.check_options(**opts)
    papers = _select_papers(registry.load_papers(), args.paper)
    jobs = []
    for exp in registry.all_experiments(papers):
        run_dir = registry.experiment_dir(args.results, exp)
        try:
            video.check_run_dir(run_dir)
        except ConfigError as exc:
            print(f"{exp.id}: no video ({_first_line(str(exc))})")
            continue
        jobs.append((exp, run_dir))
    check_dir_arg(args.figures, "--figures")
    for exp, run_dir in jobs:
        out = video.write_video(run_dir, args.figures / exp.paper / "videos" / f"{exp.name}.mp4",
                                **opts)
        print(f"{exp.id}: wrote {out} ({out.stat().st_size / 1e6:.2f} MB)")
    return 0


def _cmd_figures(args: argparse.Namespace) -> int:
    papers = _select_papers(registry.load_papers(), args.paper)
    results_dir: Path = args.results
    figures_dir: Path = args.figures
    check_dir_arg(results_dir, "--results", must_exist=True)
    check_dir_arg(figures_dir, "--figures")
    drew_any = False
    code = 0
    for paper in papers.values():
        if paper.figures is None:
            print(f"{paper.key}: no figures")
            continue
        make_dir(figures_dir, "--figures")
        try:
            for path in paper.figures(results_dir, figures_dir) or []:
                print(f"{paper.key}: wrote {path}")
        except Exception as exc:  # one paper's broken figure must not hide the others
            print(f"repro: error: {paper.key} figures failed: {type(exc).__name__}: "
                  f"{_first_line(str(exc))}", file=sys.stderr)
            code = 1
        drew_any = True

    claims = [c for paper in papers.values() if paper.claims is not None for c in paper.claims()]
    if claims:
        from repro.runs.claims import evaluate_claims, write_claims_csv, write_clauses_csv

        clause_rows: list[dict[str, object]] = []
        table = evaluate_claims(claims, results_dir, clauses_out=clause_rows)
        csv_path = results_dir / "claims.csv"
        results_dir.mkdir(parents=True, exist_ok=True)
        write_claims_csv(table, csv_path)
        write_clauses_csv(clause_rows, sorted(p.key for p in papers.values()
                                              if p.claims is not None),
                          results_dir / "claim_clauses.csv")
        if hasattr(table, "to_string"):
            print(table.to_string(index=False))
        print(f"wrote {len(claims)} claims to {csv_path}")
    elif not drew_any:
        print("no paper has figures or claims")
    if (results_dir / "sweeps").is_dir():  # after claims.csv: rates name the canonical verdicts
        from repro.plots.sweeps import sweep_figures
        from repro.runs.sweep import refresh_tables

        try:
            for path in refresh_tables(results_dir, papers):
                print(f"sweeps: wrote {path}")
            for path in sweep_figures(results_dir, figures_dir):
                print(f"sweeps: wrote {path}")
        except Exception as exc:  # a broken sweep figure must not hide the claims
            print(f"repro: error: sweep figures failed: {type(exc).__name__}: "
                  f"{_first_line(str(exc))}", file=sys.stderr)
            code = 1
    return code


def source_paths() -> list[Path]:
    """Every ``*.py`` file of the ``repro`` and ``experiments`` packages, sorted."""
    root = Path(__file__).resolve().parent.parent
    paths: list[Path] = []
    for package in ("repro", "experiments"):
        folder = root / package
        if folder.is_dir():
            paths.extend(sorted(p for p in folder.rglob("*.py") if "__pycache__" not in p.parts))
    return paths


def _cmd_sweep(args: argparse.Namespace) -> int:
    from repro.runs.sweep import run_sweep
    from repro.runs.sweep_rates import REFUSED

    check_dir_arg(args.results, "--results")
    counts: dict[str, int] = {}
    with tqdm(total=args.n, desc="variants", unit="variant", file=sys.stderr,
              disable=not sys.stderr.isatty()) as bar:
        def done(row: dict[str, Any]) -> None:
            status = str(row.get("run_status"))
            counts[status] = counts.get(status, 0) + 1
            bar.set_postfix_str(f"failed {counts.get('failed', 0)}, "
                                f"refused {counts.get(REFUSED, 0)}")
            bar.update(1)

        path = run_sweep(args.experiment, args.n, args.seed, args.results, args.camera,
                         args.keep_traces, on_done=done,
                         engine="serial" if args.serial else "dask",
                         scheduler=args.scheduler, workers=args.workers)
    # a refused start (check_config said no) is not a failed run: count them apart
    failed, refused = counts.get("failed", 0), counts.get(REFUSED, 0)
    judged = sum(counts.values()) - failed - refused
    print(f"wrote {path} ({args.n} variants: {judged} judged, {refused} refused starts, "
          f"{failed} failed runs)")
    return 0


def _cmd_counterfactual(args: argparse.Namespace) -> int:
    """Issue 37, item 3: ``repro counterfactual EXP NAME``."""
    from repro.runs.causes import COUNTERFACTUALS_DIR
    from repro.runs.sweep import cause_model, run_counterfactual

    exp = registry.find_experiment(registry.load_papers(), args.experiment)
    model = cause_model(registry.load_papers()[exp.paper])
    if model is None:
        raise ConfigError(f"{exp.paper} declares no causes, hence no counterfactual")
    model.counterfactual(exp.name, args.name)  # an unknown name: the valid ones, now
    check_dir_arg(args.results, "--results", must_exist=True)
    path = run_counterfactual(exp.id, args.name, args.results, args.camera,
                              engine="serial" if args.serial else "dask",
                              workers=args.workers)
    print(f"wrote {path} (under {COUNTERFACTUALS_DIR}/; the sweep's cause_shares.csv has its "
          "rate beside the cause)")
    return 0


def _cmd_cause_videos(args: argparse.Namespace) -> int:
    """Issue 37: ``repro cause-videos EXP``."""
    from repro.runs.sweep import cause_videos

    exp = registry.find_experiment(registry.load_papers(), args.experiment)
    check_dir_arg(args.results, "--results", must_exist=True)
    check_dir_arg(args.figures, "--figures")
    for path in cause_videos(exp.id, args.results, args.figures, args.camera):
        print(f"wrote {path}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from repro.runs.report import render_report

    root = Path(__file__).resolve().parent.parent
    check_dir_arg(args.results, "--results", must_exist=True)
    out = Path(args.output)
    if out.is_dir():
        raise ConfigError(f"--output {out} is a folder; give the report's file name")
    check_dir_arg(out.parent if str(out.parent) else Path("."), "--output's folder")
    notes = {key: root / "experiments" / key / "discussion.md" for key in registry.load_papers()}
    from repro.sweep_ranges import ranges_rows

    ranges = ranges_rows(list(registry.all_experiments(registry.load_papers())))
    result = render_report(args.results, args.figures, source_paths(), args.output, notes=notes,
                           ranges=ranges)
    print(f"wrote {result if result is not None else args.output}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
