"""Variant sweeps over the pre-registered ranges (issue 19, item 2): one experiment's claims
judged on many plausible scenes.

``run_sweep(exp_id, n, seed)`` draws ``n`` variants of the experiment's declared ranges
(:func:`repro.sweep_ranges.sample_variants`), runs each as an ordinary run of the same
runner into ``<results>/sweeps/<exp>/variants/<config hash>/`` (the same files as any run),
judges there every claim that needs only this experiment, and writes the tidy table
``<results>/sweeps/<exp>/variants.csv`` (one row per variant: its parameters, every clause's
figure, margin and verdict, each claim's status, the run's status and wall time) with its
column dictionary ``variants.columns.json``. A rerun skips the variants already judged
(``verdicts.json`` beside a completed manifest) and reruns the others. The full trace is
kept only with ``keep_traces``; the manifest, events and verdicts always.

:func:`run_variant` is the unit of work: a pure function of its arguments, so that an
engine other than the serial loop here (a Dask cluster) can map it over the variants.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import shutil
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from repro.errors import ConfigError, ReproError
from repro.runs import registry
from repro.runs.causes import (
    COUNTERFACTUALS_DIR,
    CauseModel,
    compute_evidence,
    counterfactual_variants,
    needs_evidence,
    scene_specific,
    write_causes,
)
from repro.runs.claims import Claim, ClaimResult, extent_note
from repro.runs.registry import Experiment, Paper, run_folder_lock
from repro.runs.staging import staged
from repro.runs.sweep_rates import REFUSED
from repro.runs.trace import load_run
from repro.sweep_ranges import declared_ranges, sample_variants

__all__ = ["SWEEPS_DIR", "VERDICTS_FILE", "cause_model", "cause_videos", "run_counterfactual",
           "run_sweep", "run_variant", "sweep_claims", "variant_config"]

VERDICTS_FILE = "verdicts.json"
CAMERAS = ("exact", "render")
ENGINES = ("serial", "dask")


def _experiment(exp_id: str, papers: Mapping[str, Paper] | None) -> tuple[Experiment, Paper]:
    papers = registry.load_papers() if papers is None else papers
    exp = registry.find_experiment(papers, exp_id)
    return exp, papers[exp.paper]


def sweep_members(exp: Experiment, paper: Paper) -> tuple[Experiment, ...]:
    """``exp`` and the experiments swept with it on the same variants (the paper's
    ``sweep_groups``: an ablation on the same scene, e.g. thomas2024 case 1 without the
    CBFs). Every member must declare the same ranges, so one variant is one scene."""
    by_name = {e.name: e for e in paper.experiments}
    names = (exp.name, *[n for n in paper.sweep_groups.get(exp.name, ()) if n != exp.name])
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise ConfigError(f"{paper.key}: sweep group of {exp.name} names unknown experiments "
                          f"{unknown}")
    members = tuple(by_name[n] for n in names)
    ranges = declared_ranges(exp.config_cls)
    for m in members[1:]:
        if declared_ranges(m.config_cls) != ranges:
            raise ConfigError(f"{m.id} is swept with {exp.id} but declares other ranges "
                              f"({sorted(declared_ranges(m.config_cls))} vs {sorted(ranges)})")
    return members


def sweep_claims(exp: Experiment, paper: Paper) -> list[Claim]:
    """The paper's claims judged on each variant: those that need no run but ``exp`` and its
    sweep partners (:func:`sweep_members`), and those judged per run (``Claim.per_run``) on
    the members among their runs (their clauses of those runs only)."""
    names = {m.name for m in sweep_members(exp, paper)}
    claims = list(paper.claims()) if paper.claims is not None else []
    return [c for c in claims if c.runs and (set(c.runs) <= names or set(c.per_run) & names)]


def _claim_runs(claim: Claim, runs: Mapping[str, Any]) -> dict[str, Any]:
    """The runs of ``runs`` a claim is judged on in a sweep: all of its runs, or, judged per
    run, its ``per_run`` runs among them."""
    if set(claim.runs) <= set(runs):
        return {n: runs[n] for n in claim.runs}
    return {n: runs[n] for n in claim.per_run if n in runs}


def variant_config(exp: Experiment, overrides: Mapping[str, Any], camera: str | None,
                   check: bool = True) -> Any:
    """The default config with ``overrides`` (and ``camera_mode=camera``), checked unless
    ``check`` is False (the caller checks it, e.g. to record a refused variant)."""
    config = exp.config_cls()
    names = {f.name for f in dataclasses.fields(config)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ConfigError(f"{exp.id}: no config fields {unknown}")
    changes = dict(overrides)
    if camera is not None:
        if camera not in CAMERAS:
            raise ConfigError(f"--camera {camera!r}: choose one of {CAMERAS}")
        if "camera_mode" in names:
            changes["camera_mode"] = camera
    config = dataclasses.replace(config, **changes)
    if check:
        registry.check_config(exp, config)
    return config


def cause_model(paper: Paper) -> CauseModel | None:
    """The paper's :class:`~repro.runs.causes.CauseModel` (issue 37), None if it has none."""
    if paper.causes is None:
        return None
    model = paper.causes()
    if not isinstance(model, CauseModel):
        raise ReproError(f"{paper.key}: causes() returned {type(model).__name__}, not a "
                         "CauseModel")
    return model


def _judge(claims: Sequence[Claim], runs: Mapping[str, Any]) -> dict[str, Any]:
    """Every claim on the variant's runs (``{experiment name: RunFiles}``): status and
    clause figures (a check that raises is recorded as ``not_run`` with its error)."""
    out: dict[str, Any] = {}
    for claim in claims:
        mine = _claim_runs(claim, runs)
        try:
            res = claim.check(mine)
        except Exception as exc:  # one broken variant must not end the sweep
            out[claim.claim] = {"status": "not_run", "error": f"{type(exc).__name__}: {exc}",
                                "clauses": []}
            continue
        if not isinstance(res, ClaimResult):
            raise ReproError(f"claim {claim.claim}: check returned {type(res).__name__}")
        _, cut_short = extent_note(mine, claim.whole_run, claim.done_events)
        status = ("not_reproduced" if cut_short and res.status != "not_reproduced"
                  else res.status)
        out[claim.claim] = {"status": status, "clauses": [
            {"name": c.name, "measured": c.measured, "margin": c.margin, "holds": c.holds,
             "evidence": c.evidence} for c in res.clauses]}
    return out


def _outputs_off(config: Any) -> Any:
    """``config`` with its output-only fields (snapshots, videos: not in the config hash)
    set to 0 / False: a variant without its trace writes no pictures either."""
    off = {f.name: (False if isinstance(getattr(config, f.name), bool) else 0)
           for f in dataclasses.fields(config) if f.metadata.get("output_only")
           and isinstance(getattr(config, f.name), (bool, int, float))}
    return dataclasses.replace(config, **off) if off else config


#: What a variant keeps without ``keep_traces``: the judged verdicts and the run's record
#: (its manifest and events); the trace and everything that only serves to read or rebuild
#: it (columns, scene, URDF copies, snapshots) go.
_KEEP = ("manifest.json", "events.csv", VERDICTS_FILE)
#: The folder of the sweeps under the results folder (not a paper).
SWEEPS_DIR = "sweeps"


def _member_dir(run_dir: Path, primary: str, name: str) -> Path:
    """A member's run folder: the variant's folder for the swept experiment, a sub-folder
    named after it for a partner."""
    return run_dir if name == primary else run_dir / name


def _prune(run_dir: Path, keep: Sequence[str] = ()) -> None:
    """Drop what a variant without its trace does not keep (:data:`_KEEP`; ``keep``: the
    partners' sub-folders, pruned the same way)."""
    for path in run_dir.iterdir():
        if path.name in keep and path.is_dir():
            _prune(path)
        elif path.name not in _KEEP:
            shutil.rmtree(path) if path.is_dir() else path.unlink()


def run_variant(exp_id: str, index: int, overrides: Mapping[str, Any], camera: str | None,
                sweep_dir: Path, keep_traces: bool = False,
                papers: Mapping[str, Paper] | None = None) -> dict[str, Any]:
    """Run (or, if already judged, read) variant ``index`` and return its row: the swept
    experiment and each partner (:func:`sweep_members`) with the same ``overrides``.

    The variant is made whole in its staging folder (``variants/.partial/<hash>``: the
    members' runs, the judging, ``verdicts.json``, the pruning) and swapped in for
    ``variants/<hash>`` at the end (:func:`repro.runs.staging.staged`): a variant folder is
    there only once judged, and a stopped or killed variant leaves its partial files aside,
    where the next sweep's run of it starts afresh."""
    exp, paper = _experiment(exp_id, papers)
    members = sweep_members(exp, paper)
    model = cause_model(paper)
    configs = {}
    for m in members:  # checked below: a variant the experiment refuses is a row
        config = variant_config(m, overrides, camera, check=False)
        configs[m.name] = config if keep_traces else _outputs_off(config)
    chash = registry.compute_config_hash(configs[exp.name])
    run_dir = Path(sweep_dir) / "variants" / chash[:12]
    verdicts_path = run_dir / VERDICTS_FILE
    if verdicts_path.is_file():
        done = json.loads(verdicts_path.read_text(encoding="utf-8"))
        # a variant judged before its paper's evidence (issue 37) is rerun where a failing
        # clause needs it; every other judged variant is read back
        if done.get("config_hash") == chash and not needs_evidence(
                model, exp.name, done.get("verdicts") or {}, done.get("evidence_version")):
            return {**done["row"], "variant": index}
    with staged(run_dir) as stage:
        row = _make_variant(exp, paper, model, members, configs, chash, index, overrides,
                            stage, keep_traces)
    return row


def _make_variant(exp: Experiment, paper: Paper, model: CauseModel | None,
                  members: Sequence[Experiment], configs: Mapping[str, Any], chash: str,
                  index: int,
                  overrides: Mapping[str, Any], run_dir: Path, keep_traces: bool
                  ) -> dict[str, Any]:
    """Run, judge and prune variant ``index`` in ``run_dir`` (its staging folder, held)."""
    tic = time.perf_counter()
    dirs = {m.name: _member_dir(run_dir, exp.name, m.name) for m in members}
    status, reason, verdicts = "completed", "", {}
    evidence: dict[str, Any] = {}
    try:
        for m in members:
            registry.check_config(m, configs[m.name])
    except ConfigError as exc:  # e.g. a layout through the start pose: not a plausible scene
        status, reason = REFUSED, f"{m.name}: {exc}"
    try:
        for m in members if status == "completed" else ():
            registry.run_in(m, configs[m.name], dirs[m.name])
            manifest = json.loads((dirs[m.name] / "manifest.json").read_text(encoding="utf-8"))
            if manifest.get("status") != "completed" and status == "completed":
                status = str(manifest.get("status"))
                reason = (f"{m.name}: " if m is not exp else "") + str(manifest.get("reason", ""))
        if status != REFUSED:
            runs = {name: load_run(d) for name, d in dirs.items()}
            verdicts = _judge(sweep_claims(exp, paper), runs)
            evidence = compute_evidence(model, exp.name, runs)  # while the traces are here
    except Exception as exc:  # a crashed variant is a row, not a lost sweep (^C still stops)
        status, reason, verdicts = "failed", f"{type(exc).__name__}: {exc}", {}
    row: dict[str, Any] = {"variant": index, "config_hash": chash[:12], "run_status": status,
                           "run_reason": reason,
                           "wall_time_s": round(time.perf_counter() - tic, 3)}
    row.update({f"p.{k}": v for k, v in overrides.items()})
    for cid, v in verdicts.items():
        row[f"claim{cid}.status"] = v["status"]
        for k, c in enumerate(v["clauses"], start=1):
            for what in ("measured", "margin", "holds"):
                row[f"claim{cid}.c{k}.{what}"] = c[what]
    (run_dir / VERDICTS_FILE).write_text(json.dumps({"config_hash": chash, "row": row,
                                                     "members": {n: str(d.relative_to(run_dir))
                                                                 for n, d in dirs.items()},
                                                     "verdicts": verdicts, **evidence},
                                                    indent=1, default=_json), encoding="utf-8")
    if not keep_traces:
        _prune(run_dir, keep=[n for n in dirs if n != exp.name])
    return row


def _json(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    if hasattr(x, "item"):
        return x.item()
    return str(x)


def _columns(exp: Experiment, paper: Paper) -> dict[str, dict[str, str]]:
    """The column dictionary of variants.csv."""
    cols = {
        "variant": {"unit": "-", "definition": "index in the seeded Sobol sequence"},
        "config_hash": {"unit": "text", "definition": "first 12 hex digits of the variant's "
                        "config hash (its run folder under variants/)"},
        "run_status": {"unit": "text", "definition": "the run's manifest status, or failed"},
        "run_reason": {"unit": "text", "definition": "the manifest's reason, or the error"},
        "wall_time_s": {"unit": "s", "definition": "wall time of the run and its judging"},
    }
    defaults = exp.config_cls()
    for f in dataclasses.fields(defaults):
        rng = f.metadata.get("sweep")
        if rng is not None:
            cols[f"p.{f.name}"] = {"unit": f.metadata.get("unit", "-"), "definition":
                                   f"{f.metadata.get('help', f.name)}: {rng.describe()}"}
    for claim in sweep_claims(exp, paper):
        cols[f"claim{claim.claim}.status"] = {"unit": "text", "definition":
                                              f"claim {claim.claim}: {claim.description}"}
        cols[f"claim{claim.claim}.c<k>.measured|margin|holds"] = {
            "unit": "clause's", "definition": f"clause k of claim {claim.claim} (names in "
            f"each variant's {VERDICTS_FILE}): its figure, signed margin, verdict"}
    return cols


def _map_dask(exp_id: str, variants: Sequence[tuple[int, Mapping[str, Any]]],
              camera: str | None,
              sweep_dir: Path, keep_traces: bool, papers: Mapping[str, Paper] | None,
              scheduler: str | None, workers: int | None,
              on_done: Callable[[dict[str, Any]], None] | None) -> list[dict[str, Any]]:
    """The variants on Dask distributed: an existing cluster at ``scheduler``, or a
    LocalCluster of ``workers`` processes (default: one per core), one thread each, on
    loopback. A variant whose worker dies is rerun by the scheduler (its folder is
    rewritten: nothing lost, nothing duplicated); rows come back where this runs."""
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, host="127.0.0.1", dashboard_address=":0")
    client = Client(cluster if cluster is not None else scheduler)
    try:
        futures = {client.submit(run_variant, exp_id, i, dict(ov), camera, Path(sweep_dir),
                                 keep_traces, papers,
                                 key=f"variant-{i}-{exp_id}-{Path(sweep_dir).name}",
                                 pure=False, retries=1): k
                   for k, (i, ov) in enumerate(variants)}
        rows: dict[int, dict[str, Any]] = {}
        for fut in as_completed(futures):
            row = fut.result()
            rows[futures[fut]] = row
            if on_done is not None:
                on_done(row)
        return [rows[k] for k in range(len(variants))]
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_sweep(exp_id: str, n: int, seed: int, results_dir: Path, camera: str | None = "exact",
              keep_traces: bool = False, papers: Mapping[str, Paper] | None = None,
              on_done: Callable[[dict[str, Any]], None] | None = None,
              engine: str = "serial", scheduler: str | None = None,
              workers: int | None = None) -> Path:
    """Run ``n`` variants of ``exp_id`` (``engine``: "serial", one after another in this
    process, or "dask", on Dask distributed: :func:`_map_dask`); write variants.csv and its
    column dictionary; return the CSV's path."""
    if engine not in ENGINES:
        raise ConfigError(f"sweep engine {engine!r}: choose one of {ENGINES}")
    exp, paper = _experiment(exp_id, papers)
    if not declared_ranges(exp.config_cls):
        raise ConfigError(f"{exp.id} declares no sweep range (repro.sweep_ranges)")
    if not sweep_claims(exp, paper):
        raise ConfigError(f"{exp.id}: no claim of {exp.paper} needs only this run")
    variants = sample_variants(exp.config_cls, n, seed)
    sweep_dir = sweep_folder(Path(results_dir), exp, camera)
    with _sweep_lock(sweep_dir):
        return _run_locked(exp, paper, variants, n, seed, sweep_dir, Path(results_dir), camera,
                           keep_traces, papers, on_done, engine, scheduler, workers)


@contextlib.contextmanager
def _sweep_lock(sweep_dir: Path) -> Iterator[None]:
    """One sweep at a time per sweep folder: two would run, judge and delete the same
    variants' files under each other (seen: "missing trace.csv" failures)."""
    try:
        with run_folder_lock(sweep_dir):
            yield
    except ReproError as exc:
        if "being written by another" not in str(exc):
            raise
        raise ReproError(f"{sweep_dir} is being swept by another repro process; wait for it "
                         "(a sweep resumes: rerun it afterwards to add variants)") from None


def _map_variants(exp: Experiment, variants: Sequence[tuple[int, Mapping[str, Any]]],
                  camera: str | None, sweep_dir: Path, keep_traces: bool,
                  papers: Mapping[str, Paper] | None,
                  on_done: Callable[[dict[str, Any]], None] | None, engine: str,
                  scheduler: str | None, workers: int | None) -> list[dict[str, Any]]:
    """The rows of ``variants`` (``(index, overrides)``) run by ``engine``, in their order."""
    if engine == "dask":
        return _map_dask(exp.id, variants, camera, sweep_dir, keep_traces, papers, scheduler,
                         workers, on_done)
    rows = []
    for i, overrides in variants:
        row = run_variant(exp.id, i, overrides, camera, sweep_dir, keep_traces, papers)
        rows.append(row)
        if on_done is not None:
            on_done(row)
    return rows


def _write_variants(sweep_dir: Path, rows: Sequence[Mapping[str, Any]],
                    meta: Mapping[str, Any]) -> Path:
    """variants.csv (atomically) and variants.columns.json of a sweep folder."""
    path = sweep_dir / "variants.csv"
    tmp = path.with_name(path.name + ".tmp")
    pd.DataFrame(list(rows)).to_csv(tmp, index=False, float_format="%.10g")
    tmp.replace(path)
    (sweep_dir / "variants.columns.json").write_text(json.dumps(meta, indent=1) + "\n",
                                                     encoding="utf-8")
    return path


def _run_locked(exp: Experiment, paper: Paper, variants: list[dict[str, Any]], n: int,
                seed: int, sweep_dir: Path, results_dir: Path, camera: str | None,
                keep_traces: bool, papers: Mapping[str, Paper] | None,
                on_done: Callable[[dict[str, Any]], None] | None, engine: str,
                scheduler: str | None, workers: int | None) -> Path:
    rows = _map_variants(exp, list(enumerate(variants)), camera, sweep_dir, keep_traces,
                         papers, on_done, engine, scheduler, workers)
    path = _write_variants(sweep_dir, rows, {
        "experiment": exp.id, "n": n, "seed": seed, "camera": camera,
        "members": [m.id for m in sweep_members(exp, paper)], "engine": engine,
        "workers": (1 if engine == "serial" else
                    workers or (None if scheduler else os.cpu_count())),
        "columns": _columns(exp, paper)})
    _write_tables(sweep_dir, results_dir, exp, paper)
    return path


def run_counterfactual(exp_id: str, name: str, results_dir: Path, camera: str | None = "exact",
                       papers: Mapping[str, Paper] | None = None,
                       on_done: Callable[[dict[str, Any]], None] | None = None,
                       engine: str = "serial", scheduler: str | None = None,
                       workers: int | None = None) -> Path:
    """Rerun the variants of ``exp_id``'s sweep that failed by the cause counterfactual
    ``name`` removes (issue 37, item 3), each with the same parameters and the
    counterfactual's overrides, into ``<sweep>/counterfactuals/<name>/``; then rewrite the
    sweep's cause tables (the counterfactual's rate beside the cause). Return the
    counterfactual's variants.csv."""
    if engine not in ENGINES:
        raise ConfigError(f"sweep engine {engine!r}: choose one of {ENGINES}")
    exp, paper = _experiment(exp_id, papers)
    model = cause_model(paper)
    if model is None:
        raise ConfigError(f"{exp.paper} declares no causes, hence no counterfactual")
    cf = model.counterfactual(exp.name, name)
    base = sweep_folder(Path(results_dir), exp, camera)
    meta_path = base / "variants.columns.json"
    if not meta_path.is_file():
        raise ConfigError(f"{exp.id} has no {camera} sweep under {base}: run `repro sweep` "
                          "first")
    meta = json.loads(meta_path.read_text(encoding="utf-8"))
    sampled = sample_variants(exp.config_cls, int(meta["n"]), int(meta["seed"]))
    chosen = [(int(r["variant"]), {**sampled[int(r["variant"])], **cf.overrides})
              for r in counterfactual_variants(base, cf)]
    cf_dir = base / COUNTERFACTUALS_DIR / cf.name
    with _sweep_lock(base):
        rows = _map_variants(exp, chosen, camera, cf_dir, False, papers, on_done, engine,
                             scheduler, workers)
        cf_dir.mkdir(parents=True, exist_ok=True)
        path = _write_variants(cf_dir, rows, {
            "experiment": exp.id, "counterfactual": cf.name, "removes": cf.removes,
            "overrides": dict(cf.overrides), "why": cf.why, "source_n": meta["n"],
            "source_seed": meta["seed"], "camera": camera, "engine": engine,
            "columns": {"variant": {"unit": "-", "definition": "the source variant's index "
                                    "in the sweep this reruns"}, **_columns(exp, paper)}})
        _write_tables(base, Path(results_dir), exp, paper)
    return path


def cause_videos(exp_id: str, results_dir: Path, figures_dir: Path,
                 camera: str | None = "exact", papers: Mapping[str, Paper] | None = None,
                 size: tuple[int, int] = (640, 320)) -> list[Path]:
    """Issue 37: one video per named cause of a sweep (cause_shares.csv): its example
    variant rerun with its trace into a scratch folder (the same parameters, drawn again
    from the sweep's seed), checked to give the verdicts the sweep recorded, and replayed
    from those files (:mod:`repro.replay.video`) into
    ``<figures>/<paper>/videos/causes/<exp>__<cause>.mp4``. Returns the videos written."""
    import tempfile

    from repro.replay.video import write_video
    from repro.runs.report_causes import example_video

    exp, paper = _experiment(exp_id, papers)
    base = sweep_folder(Path(results_dir), exp, camera)
    shares_path = base / "cause_shares.csv"
    if not shares_path.is_file():
        raise ConfigError(f"{exp.id} has no cause table under {base}: run its sweep first")
    meta = json.loads((base / "variants.columns.json").read_text(encoding="utf-8"))
    sampled = sample_variants(exp.config_cls, int(meta["n"]), int(meta["seed"]))
    shares = pd.read_csv(shares_path, dtype={"claim": str, "example_hash": str},
                         keep_default_na=False)
    written: list[Path] = []
    done: set[str] = set()
    for r in shares.to_dict("records"):
        cause = str(r["cause"])
        if cause in done or r["class"] == "check":  # a scene-specific clause: no scene shows it
            continue
        done.add(cause)
        index = int(r["example_variant"])
        with tempfile.TemporaryDirectory() as tmp:
            row = run_variant(exp.id, index, sampled[index], camera, Path(tmp), True, papers)
            if str(row["config_hash"]) != str(r["example_hash"]):
                raise ReproError(f"{exp.id} variant {index}: drawn again it hashes to "
                                 f"{row['config_hash']}, the sweep's to {r['example_hash']}")
            run_dir = Path(tmp) / "variants" / str(row["config_hash"])
            recorded = json.loads((base / "variants" / str(r["example_hash"]) / VERDICTS_FILE
                                   ).read_text(encoding="utf-8"))["row"]
            moved = [k for k, v in row.items() if k.endswith(".holds") and recorded.get(k) != v]
            if moved:
                raise ReproError(f"{exp.id} variant {index} rerun: verdicts {moved} differ "
                                 "from the sweep's (the code changed: rerun the sweep)")
            out = example_video(Path(figures_dir), exp.paper, exp.name, cause)
            out.parent.mkdir(parents=True, exist_ok=True)
            written.append(write_video(run_dir, out, size=size))
    return written


#: Sub-folder of a sweep's folder holding its rendered-camera subsample (item 5)
RENDER_DIR = "render"


def sweep_folder(results_dir: Path, exp: Experiment, camera: str | None) -> Path:
    """``<results>/sweeps/<exp>/``, or its ``render/`` sub-folder for a rendered-camera
    sweep (the subsample whose verdicts are compared with their exact-camera twins)."""
    base = Path(results_dir) / SWEEPS_DIR / exp.name
    return base / RENDER_DIR if camera == "render" else base


def _write_tables(sweep_dir: Path, results_dir: Path, exp: Experiment, paper: Paper
                  ) -> list[Path]:
    from repro.runs.sweep_rates import write_agreement, write_rates
    from repro.runs.sweep_sensitivity import write_sensitivity

    model = cause_model(paper)
    out = [write_rates(sweep_dir, results_dir, exp.paper, exp.name, paper.joint_claims,
                       scene_specific(model, exp.name)),
           write_sensitivity(sweep_dir, exp.name)]
    out += write_causes(sweep_dir, model, exp.name)
    exact = sweep_dir.parent if sweep_dir.name == RENDER_DIR else sweep_dir
    if (exact / RENDER_DIR / "variants.csv").is_file() and (exact / "variants.csv").is_file():
        out.append(write_agreement(exact, exact / RENDER_DIR, exp.name))
    return out


def refresh_tables(results_dir: Path, papers: Mapping[str, Paper] | None = None) -> list[Path]:
    """Rewrite every committed sweep's rates.csv and sensitivity.csv from its variants.csv
    (``repro figures``: the canonical verdicts they quote come from the current
    claims.csv); runs nothing."""
    papers = registry.load_papers() if papers is None else papers
    written: list[Path] = []
    root = Path(results_dir) / SWEEPS_DIR
    for meta_path in sorted([*root.glob("*/variants.columns.json"),
                             *root.glob(f"*/{RENDER_DIR}/variants.columns.json")]):
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        try:
            exp, paper = _experiment(str(meta.get("experiment")), papers)
        except ReproError:
            continue  # a sweep of an experiment no longer registered: left as it is
        if (meta_path.parent / "variants.csv").is_file():
            written += _write_tables(meta_path.parent, Path(results_dir), exp, paper)
    return written
