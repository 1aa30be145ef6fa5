"""REPORT.md, generated only from the files under results/ and figures/ (and source comments).

Layout: provenance (live environment vs. what the run manifests recorded), an overview, then
per paper its claims (from results/claims.csv), its runs (from every manifest.json under
results/<paper>/), its figures (every PNG under figures/<paper>/), its benchmarks (from
results/bench.csv) and the values we chose where the paper is silent (``# ours:`` comments).
"""

from __future__ import annotations

import io
import json
import os
import re
import tokenize
import urllib.parse
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pandas as pd

from repro.errors import ReproError
from repro.runs.claims import STATUSES, natural_key, read_claims_csv
from repro.runs.report_causes import causes_section
from repro.runs.staging import is_aside
from repro.runs.trace import TRACKED_PACKAGES, effective_manifest
from repro.runs.validate import DamagedRun, check_run

__all__ = [
    "BENCH_COLUMNS",
    "OURS_COLUMNS",
    "collect_ours",
    "markdown_table",
    "render_report",
]

OURS_COLUMNS = ("file", "line", "code", "why")
BENCH_COLUMNS = ("benchmark", "median_s", "p95_s", "n", "machine")
OURS_HEADING = "Values chosen by us (the papers are silent)"

_OURS = re.compile(r"#\s*ours:\s*(?P<why>.*)$", re.IGNORECASE)
#: A documentation comment (``#: ...``, the one Sphinx reads for the value below it) whose
#: text says ``ours: <why>``; the why runs on over the following ``#:`` lines.
_OURS_DOC = re.compile(r"#:(?:.*?[\s(])?ours:\s*(?P<why>.*)$", re.IGNORECASE)
_SKIP_DIRS = {".venv", "venv", "__pycache__", ".git", "build", ".mypy_cache", ".ruff_cache"}
_MISSING = "—"


# --------------------------------------------------------------------------- markdown


def _cell(value: Any) -> str:
    if value is None or (isinstance(value, float) and value != value):
        return ""
    text = str(value).replace("\r\n", "\n").replace("\n", "<br>")
    return text.replace("|", "\\|")


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A GitHub-flavoured Markdown table (pipes escaped, newlines as <br>), no dependency."""
    lines = [
        "| " + " | ".join(_cell(h) for h in headers) + " |",
        "|" + "|".join("---" for _ in headers) + "|",
    ]
    for row in rows:
        cells = list(row)
        if len(cells) != len(headers):
            raise ReproError(f"table row has {len(cells)} cells, expected {len(headers)}: {row}")
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(lines)


# --------------------------------------------------------------------------- "# ours:" scan


def _source_files(paths: Sequence[Path]) -> list[Path]:
    files: list[Path] = []
    for path in map(Path, paths):
        if path.is_dir():
            files.extend(
                p
                for p in sorted(path.rglob("*.py"))
                if not _SKIP_DIRS.intersection(p.relative_to(path).parts)
            )
        elif path.is_file():
            files.append(path)
        else:
            raise ReproError(f"source path {path} does not exist")
    return files


def _comment_lines(text: str, is_python: bool) -> list[tuple[int, int, str]]:
    """(line number, column, comment text) of every comment; real tokens for Python files."""
    if is_python:
        try:
            tokens = tokenize.generate_tokens(io.StringIO(text).readline)
            return [
                (tok.start[0], tok.start[1], tok.string)
                for tok in tokens
                if tok.type == tokenize.COMMENT
            ]
        except (tokenize.TokenError, SyntaxError):
            pass  # fall back to a plain text scan
    out = []
    for number, line in enumerate(text.splitlines(), start=1):
        match = _OURS.search(line)
        if match:
            out.append((number, match.start(), line[match.start() :]))
    return out


def collect_ours(paths: Sequence[Path]) -> pd.DataFrame:
    """Every ``# ours: <why>`` comment in the given files (directories: their *.py files).

    A ``# ours:`` comment marks a value the paper does not give. For a comment after code, the
    code is that line's code; for a comment on its own line, the next code line. A
    documentation comment ``#: <what> ours: <why>`` counts too: its why runs on over the
    ``#:`` lines that follow it, and its code is the next code line.

    Returns:
        Columns OURS_COLUMNS: file (path as given, posix), line (1-based, of the comment),
        code (stripped), why (text after "# ours:").
    """
    rows = []
    for path in _source_files(paths):
        text = path.read_text(encoding="utf-8", errors="replace")
        lines = text.splitlines()
        for number, column, comment in _comment_lines(text, path.suffix == ".py"):
            match = _OURS.match(comment.strip())
            doc = None if match else _OURS_DOC.match(comment.strip())
            if not (match or doc):
                continue
            if doc is not None:
                match = doc
            assert match is not None
            why = match.group("why").strip()
            if doc is not None:  # the why runs on over the doc comment's next lines
                for following in lines[number:]:
                    stripped = following.strip()
                    if not stripped.startswith("#:"):
                        break
                    why = f"{why} {stripped[2:].strip()}".strip()
            code = lines[number - 1][:column].strip() if number <= len(lines) else ""
            if not code:
                for following in lines[number:]:
                    stripped = following.strip()
                    if stripped and not stripped.startswith("#"):
                        code = stripped
                        break
            rows.append((path.as_posix(), number, code, why))
    df = pd.DataFrame(rows, columns=list(OURS_COLUMNS))
    return df.astype({"line": "int64"})


# --------------------------------------------------------------------------- inputs


def _read_manifests(paper_dir: Path) -> list[tuple[str, dict[str, Any]]]:
    runs = []
    for manifest_path in paper_dir.rglob("manifest.json"):
        if is_aside(manifest_path.relative_to(paper_dir)):  # a stopped run's staging folder
            continue
        run = manifest_path.parent.relative_to(paper_dir).as_posix()
        try:
            manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
            if not isinstance(manifest, dict):
                raise ValueError("not a JSON object")
            # a "running" run whose process is gone is reported as interrupted
            manifest = effective_manifest(manifest_path.parent, manifest)
        except (OSError, ValueError) as exc:
            manifest = {"status": "unreadable manifest", "reason": str(exc)}
        else:
            if manifest.get("status") == "completed":
                try:  # a completed run whose files fail a rule is reported as damaged
                    check_run(manifest_path.parent)
                except DamagedRun as exc:
                    manifest = {**manifest, "status": "damaged", "reason": exc.rule}
        runs.append((run, manifest))
    return sorted(runs, key=lambda item: natural_key(item[0]))


def _read_bench(path: Path) -> pd.DataFrame | None:
    if not path.is_file():
        return None
    bench = pd.read_csv(path)
    missing = [c for c in BENCH_COLUMNS if c not in bench.columns]
    if missing:
        raise ReproError(
            f"{path} lacks column(s) {missing}; expected at least {list(BENCH_COLUMNS)}"
        )
    return bench


def _discover_papers(
    results_dir: Path, figures_dir: Path, claims: pd.DataFrame | None
) -> list[str]:
    papers: set[str] = set()
    if results_dir.is_dir():
        papers.update(
            d.name
            for d in results_dir.iterdir()
            if d.is_dir() and not d.name.startswith(".") and d.name != "sweeps"
            and any(d.rglob("manifest.json"))
        )
    if figures_dir.is_dir():
        papers.update(
            d.name
            for d in figures_dir.iterdir()
            if d.is_dir() and not d.name.startswith(".") and any(d.rglob("*.png"))
        )
    if claims is not None:
        papers.update(claims["paper"])
    return sorted(papers)


# --------------------------------------------------------------------------- formatting


def _fmt_num(value: Any, fmt: str = "{:.4g}") -> str:
    if value is None or isinstance(value, str):
        return _MISSING if value is None else value
    try:
        return fmt.format(value)
    except (TypeError, ValueError):
        return str(value)


def _fmt_sha(sha: Any, dirty: Any) -> str:
    if not sha:
        return _MISSING
    return str(sha)[:10] + ("+dirty" if dirty else "")


def _distinct(values: Iterable[Any]) -> str:
    seen = sorted({str(v) for v in values if v is not None and v != ""})
    return ", ".join(seen) if seen else _MISSING


def _link(target: Path, base: Path) -> str:
    try:
        rel = os.path.relpath(target.resolve(), base.resolve())
    except ValueError:  # different drives on Windows
        rel = str(target.resolve())
    return urllib.parse.quote(Path(rel).as_posix())


def _display_path(file: str, base: Path) -> str:
    path = Path(file)
    try:
        return path.resolve().relative_to(base.resolve()).as_posix()
    except ValueError:
        return path.as_posix()


def _provenance(
    manifests: list[dict[str, Any]], now: datetime, source_paths: Sequence[Path]
) -> list[str]:
    # The report is a function of the results: only what the runs recorded, never the
    # environment that renders the report (its date, sha or platform would churn the file).
    started = sorted(str(m["started_at"]) for m in manifests if m.get("started_at"))
    run_dates = f"{started[0]} … {started[-1]}" if started else _MISSING
    run_shas = _distinct(_fmt_sha(m.get("git_sha"), m.get("git_dirty")) for m in manifests)
    rows = [
        ("run dates (UTC)", run_dates),
        ("git sha", run_shas),
        ("python", _distinct(m.get("python") for m in manifests)),
        ("platform", _distinct(m.get("platform") for m in manifests)),
        ("CPU", _distinct(m.get("cpu") for m in manifests)),
        ("repro", _distinct(m.get("repro_version") for m in manifests)),
    ]
    for package in TRACKED_PACKAGES:
        rows.append((package, _distinct((m.get("packages") or {}).get(package)
                                        for m in manifests)))
    return [
        "## Provenance",
        "",
        f"{len(manifests)} run manifest(s) read; every distinct value they recorded. The "
        "report is rendered from the results alone, so regenerating it without new results "
        "leaves it unchanged.",
        "",
        markdown_table(("item", "recorded by the runs"), rows),
        "",
    ]


def _claims_counts(claims: pd.DataFrame) -> dict[str, int]:
    return {status: int((claims["status"] == status).sum()) for status in STATUSES}


def _inline_code(code: str) -> str:
    if not code:
        return ""
    fence = "``" if "`" in code else "`"
    pad = " " if "`" in code else ""
    return f"{fence}{pad}{code}{pad}{fence}"


def _ours_table(ours: pd.DataFrame, base: Path) -> str:
    if ours.empty:
        return "_None recorded._"
    rows = [
        (_display_path(r.file, base), r.line, _inline_code(r.code), r.why)
        for r in ours.itertuples(index=False)
    ]
    return markdown_table(OURS_COLUMNS, rows)


def _bench_value(name: str, value: Any) -> str:
    """A duration [s] as it is; the ratio rows of ``make bench`` as ratios (real-time
    factor ``1.12x``, a share of the loop's wall time ``24%``)."""
    if ".real_time_factor[" in name and isinstance(value, int | float):
        return f"{value:.3g}x"
    if ".loop_split[" in name and isinstance(value, int | float):
        return f"{100 * value:.1f}%"
    return _fmt_num(value)


def _bench_table(bench: pd.DataFrame) -> str:
    rows = [
        (r["benchmark"], _bench_value(r["benchmark"], r["median_s"]),
         _bench_value(r["benchmark"], r["p95_s"]), r["n"], r["machine"])
        for _, r in bench.iterrows()
    ]
    return markdown_table(BENCH_COLUMNS, rows) + (
        "\n\nmedian_s / p95_s are seconds, but for the ratio rows: real_time_factor "
        "(simulated time / the loop's wall time, x) and loop_split (a part's share of it, "
        "%), from short runs: for real_time_factor, median_s is the fastest of n runs and "
        "p95_s the slowest; loop_split is the fastest run's.")


def _ranges_section(rows: Sequence[Sequence[str]] | None) -> list[str]:
    """The paper's pre-registered sweep ranges (issue 19), or that none is declared yet."""
    from repro.sweep_ranges import RANGES_COLUMNS

    out = ["### Pre-registered ranges of the values the paper leaves open", ""]
    if not rows:
        return out + ["_No sweep range declared yet._", ""]
    return out + [
        "Declared before any sweep that uses them (the commit is the one that last changed the "
        "declaring line); a range narrowed after seeing results is said here.", "",
        markdown_table(RANGES_COLUMNS, rows), ""]


def _robustness_section(results_dir: Path, paper: str, base: Path) -> list[str]:
    """Issue 19: per sweep of this paper's experiments, the rates of its claims and clauses
    over the variants next to the canonical verdicts (results/sweeps/<exp>/rates.csv)."""
    out = ["### Robustness over the scenes the paper leaves open", ""]
    found = False
    for rates in sorted((Path(results_dir) / "sweeps").glob("*/rates.csv")):
        meta_path = rates.parent / "variants.columns.json"
        if not meta_path.is_file():
            continue
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        if not str(meta.get("experiment", "")).startswith(f"{paper}."):
            continue
        found = True
        df = pd.read_csv(rates, dtype=str, keep_default_na=False)
        rows = [(r.claim, r.clause or "(the claim)", r.variants, r.held,
                 f"{float(r.rate):.2f}" if r.rate else "-",
                 f"[{float(r.wilson_low):.2f}, {float(r.wilson_high):.2f}]"
                 if r.wilson_low else "-", r.canonical or "-") for r in df.itertuples()]
        failed = df["failed_runs"].iloc[0] if len(df) else "0"
        refused = (df["refused"].iloc[0] or "0") if len(df) and "refused" in df else "0"
        out += [f"**{meta['experiment']}**: {meta.get('n')} variants of the ranges above "
                f"(Sobol, seed {meta.get('seed')}, {meta.get('camera')} camera, "
                f"{meta.get('engine', 'serial')} engine; {failed} failed runs; {refused} "
                f"refused as no scene of the paper's{_refusals(rates.parent)}; "
                f"{_link(rates, base)}).", "",
                markdown_table(("claim", "clause", "variants", "held", "rate", "Wilson 95 %",
                                "canonical run"), rows), ""]
        out += _ranges_changed(rates.parent, str(meta["experiment"]))
        out += _deciders(rates.parent / "sensitivity.csv", base)
        out += _agreement(rates.parent / "render_agreement.csv", base)
    if not found:
        out += ["_No sweep yet._", ""]
    return out


#: A best split is reported as deciding a verdict when its permutation p-value is below this
DECIDES_P = 0.05  # ours: the conventional 5 % (sensitivity.csv gives every p)


def _deciders(path: Path, base: Path) -> list[str]:
    """Issue 19: per claim and clause whose verdict varies over the sweep, the parameter
    whose best single split predicts it best (sensitivity.csv, rank 1)."""
    if not path.is_file():
        return []
    df = pd.read_csv(path, dtype={"claim": str, "clause": str}, keep_default_na=False)
    top = df[df["rank"].astype(int) == 1]
    if top.empty:
        return []
    lines = [f"Which unknown decides it (best single split per verdict that varies, "
             f"{_link(path, base)}; deciding when its permutation p < {DECIDES_P:g}):", ""]
    for r in top.itertuples():
        what = f"claim {r.claim}" + (f", \"{r.clause}\"" if r.clause else "")
        rho = f"{float(r.spearman):+.2f}" if r.spearman not in ("", "nan") else "-"
        if str(r.holds_when).startswith("every variant"):
            if r.clause and rho != "-":  # the claim's own 0/1 margin says nothing more
                lines.append(f"- {what}: {r.holds_when}; its margin follows {r.parameter} "
                             f"most (Spearman {rho})")
            continue
        p = float(r.permutation_p)
        if r.holds_when == "none" or p >= DECIDES_P:
            lines.append(f"- {what}: no swept parameter decides it alone (best: {r.parameter}, "
                         f"split accuracy {float(r.split_accuracy):.2f} vs "
                         f"{float(r.majority_accuracy):.2f} by the majority, p = {p:.2f}; "
                         f"Spearman {rho})")
        else:
            lines.append(f"- {what}: **{r.parameter}** (holds when {r.parameter} "
                         f"{r.holds_when}: accuracy {float(r.split_accuracy):.2f} vs "
                         f"{float(r.majority_accuracy):.2f} by the majority, p = {p:.3f}; "
                         f"Spearman {rho})")
    return lines + [""]


def _refusals(sweep_dir: Path) -> str:
    """Why the refused variants were refused: the distinct reasons, without their numbers."""
    import re

    df = pd.read_csv(sweep_dir / "variants.csv", dtype=str, keep_default_na=False)
    why = df.loc[df["run_status"] == "refused", "run_reason"]
    if why.empty:
        return ""
    kinds = sorted({re.sub(r"\(-?[0-9.]+ cm\)", "", w).split(": ", 2)[-1].strip() for w in why})
    return " (" + "; ".join(kinds[:3]) + ")"


def _ranges_changed(sweep_dir: Path, exp_id: str) -> list[str]:
    """Issue 19: a sweep whose parameters are no longer the experiment's declared ranges (a
    range added, dropped, narrowed or moved since it ran) says so: its rates are those of
    the old ranges until it is rerun."""
    from repro.runs.registry import find_experiment, load_papers
    from repro.sweep_ranges import declared_ranges

    try:
        exp = find_experiment(load_papers(), exp_id)
    except Exception:  # an experiment no longer registered: nothing to compare with
        return []
    ranges = declared_ranges(exp.config_cls)
    df = pd.read_csv(sweep_dir / "variants.csv")
    swept = {c[2:] for c in df.columns if c.startswith("p.")}
    notes = []
    if swept != set(ranges):
        added, dropped = sorted(set(ranges) - swept), sorted(swept - set(ranges))
        notes += [f"declared since: {', '.join(added)}"] if added else []
        notes += [f"no longer declared: {', '.join(dropped)}"] if dropped else []
    for name in sorted(swept & set(ranges)):
        x = pd.to_numeric(df[f"p.{name}"], errors="coerce")
        rng = ranges[name]
        if x.min() < rng.low - 1e-12 or x.max() > rng.high + 1e-12:
            notes.append(f"{name} swept over [{x.min():.4g}, {x.max():.4g}], now declared "
                         f"[{rng.low:.4g}, {rng.high:.4g}]")
    if not notes:
        return []
    return [f"**The declared ranges changed since this sweep ran** ({'; '.join(notes)}): its "
            "rates are those of the ranges it sampled (its variants.csv) until it is rerun.",
            ""]


def _agreement(path: Path, base: Path) -> list[str]:
    """Issue 19 item 5: the rendered-camera subsample's verdicts against their exact twins."""
    if not path.is_file():
        return ["Rendered-camera subsample: not run yet (exact camera only).", ""]
    df = pd.read_csv(path, dtype={"claim": str, "clause": str}, keep_default_na=False)
    if df.empty:
        return [f"Rendered-camera subsample: no twin variants ({_link(path, base)}).", ""]
    agree, n = int(df["agree"].astype(int).sum()), int(df["twins"].astype(int).sum())
    twins = int(df["twins"].astype(int).max())
    rows = [(r.claim, r.clause or "(the claim)", r.twins, r.agree,
             f"{float(r.rate):.2f}" if r.rate else "-", r.exact_held, r.render_held)
            for r in df.itertuples()]
    return [f"Rendered camera against the exact projection ({twins} twin variants, "
            f"{_link(path, base)}): {agree} of {n} verdicts agree.", "",
            markdown_table(("claim", "clause", "twins", "agree", "rate", "held (exact)",
                            "held (render)"), rows), ""]


def _variation_note(results_dir: Path, paper: str) -> str:
    """One sentence on the measured machine-to-machine variation of the paper's clauses
    (results/clause_variation.csv), or that it was not measured."""
    from repro.runs.claims import VARIATION_FILE

    path = Path(results_dir) / VARIATION_FILE
    if not path.is_file():
        return " The clauses' machine-to-machine variation has not been measured."
    df = pd.read_csv(path, dtype={"paper": str, "claim": str, "clause": str},
                     keep_default_na=False)
    df = df[df["paper"] == paper]
    if df.empty:
        return " The clauses' machine-to-machine variation has not been measured."
    flips = df["flips"].astype(str).str.lower().eq("true")
    perts = sorted({p for s in df["perturbations"] for p in str(s).split()})
    return (f" Variation measured for {len(df)} clauses under {len(perts)} perturbations "
            f"({', '.join(perts)}; {VARIATION_FILE}): {int(flips.sum())} flip.")


def _video_cell(mp4: Path, base: Path) -> str:
    """Issue 20: a link to the run's replayed video (``make videos``), if it is there."""
    if not mp4.is_file():
        return "-"
    return f"[mp4]({_link(mp4, base)}) ({mp4.stat().st_size / 1e6:.1f} MB)"


def _paper_section(
    paper: str,
    *,
    results_dir: Path,
    figures_dir: Path,
    base: Path,
    claims: pd.DataFrame | None,
    runs: list[tuple[str, dict[str, Any]]],
    bench: pd.DataFrame | None,
    ours: pd.DataFrame,
) -> list[str]:
    out = [f"## {paper}", ""]

    out += ["### Claims", ""]
    paper_claims = None if claims is None else claims[claims["paper"] == paper]
    if paper_claims is None or paper_claims.empty:
        out += ["_No claims evaluated for this paper._", ""]
    else:
        counts = _claims_counts(paper_claims)
        out += [
            f"**{counts['reproduced']} of {len(paper_claims)} reproduced** "
            f"({counts['partly_reproduced']} partly reproduced, "
            f"{counts['not_reproduced']} not reproduced, {counts['not_run']} not run). "
            "Claims judged clause by clause list each clause's figure, bound, verdict and "
            "margin; a clause within 10 % of its bound, or whose verdict flips within the "
            "figure's measured machine-to-machine variation (results/clause_variation.csv, "
            "tests/measure_clause_variation.py), is named under `marginal` "
            "(results/claim_clauses.csv has one row per clause)." + _variation_note(
                results_dir, paper),
            "",
            markdown_table(paper_claims.columns, paper_claims.itertuples(index=False)),
            "",
        ]

    out += ["### Runs", ""]
    if not runs:
        out += [f"_No runs under {_link(results_dir / paper, base)}._", ""]
    else:
        rows = [
            (
                run,
                m.get("experiment", _MISSING),
                m.get("status", _MISSING),
                m.get("reason", ""),
                m.get("n_rows", _MISSING),
                _fmt_num(m.get("wall_time_s"), "{:.2f}"),
                str(m.get("config_hash") or _MISSING)[:12],
                _fmt_sha(m.get("git_sha"), m.get("git_dirty")),
                _video_cell(figures_dir / paper / "videos" / f"{run}.mp4", base),
            )
            for run, m in runs
        ]
        headers = ("run", "experiment", "status", "reason", "rows", "wall time (s)")
        out += [markdown_table((*headers, "config hash", "git sha", "video"), rows), ""]

    out += ["### Figures", ""]
    paper_figures = figures_dir / paper
    pngs = sorted(paper_figures.rglob("*.png"), key=lambda p: natural_key(p.as_posix()))
    if not pngs:
        out += ["_No figures._", ""]
    for png in pngs:
        name = png.relative_to(paper_figures).with_suffix("").as_posix()
        out += [f"![{name}]({_link(png, base)})", ""]

    if bench is not None and "paper" in bench.columns:
        paper_bench = bench[bench["paper"] == paper]
        if not paper_bench.empty:
            out += ["### Benchmarks", "", _bench_table(paper_bench), ""]

    out += [f"### {OURS_HEADING}", "", _ours_table(ours, base), ""]
    return out


def render_report(
    results_dir: Path,
    figures_dir: Path,
    source_paths: Sequence[Path],
    out_path: Path,
    *,
    papers: Sequence[str] | None = None,
    now: datetime | None = None,
    notes: Mapping[str, Path] | None = None,
    ranges: Mapping[str, Sequence[Sequence[str]]] | None = None,
) -> Path:
    """Write REPORT.md at out_path from results_dir, figures_dir and the sources' ``# ours:``.

    Args:
        results_dir: holds claims.csv, bench.csv (optional) and <paper>/<run>/manifest.json.
        figures_dir: holds <paper>/*.png.
        source_paths: files or directories scanned for ``# ours:`` comments; a file belongs
            to a paper when its path contains the paper key, otherwise to the shared library.
        out_path: the report to write (links are relative to its directory).
        papers: paper keys, in order; default: every paper found in results, figures, claims.
        now: unused (the report depends only on the results); kept for compatibility.
        notes: per paper, a Markdown file of discussion (why a claim did or did not
            reproduce, where the time goes) appended to that paper's section.
        ranges: per paper, the rows of its pre-registered sweep ranges
            (:func:`repro.sweep_ranges.ranges_rows`), listed in its section.

    Returns:
        out_path.
    """
    results_dir, figures_dir, out_path = Path(results_dir), Path(figures_dir), Path(out_path)
    base = out_path.parent
    claims_path = results_dir / "claims.csv"
    claims = read_claims_csv(claims_path) if claims_path.is_file() else None
    bench = _read_bench(results_dir / "bench.csv")
    paper_keys = (
        list(papers) if papers is not None else _discover_papers(results_dir, figures_dir, claims)
    )
    runs = {p: _read_manifests(results_dir / p) for p in paper_keys}
    all_manifests = [m for p in paper_keys for _, m in runs[p]]
    ours = collect_ours(source_paths)
    owner = ours["file"].map(lambda f: next((p for p in paper_keys if p in f), ""))

    lines = [
        "# Reproduction report",
        "",
        "Generated by `repro.runs.report` from the files under "
        f"`{_link(results_dir, base)}/` and `{_link(figures_dir, base)}/`; do not edit by hand.",
        "",
    ]
    lines += _provenance(all_manifests, now or datetime.now(UTC), source_paths)

    overview = []
    for paper in paper_keys:
        paper_claims = None if claims is None else claims[claims["paper"] == paper]
        n_claims = 0 if paper_claims is None else len(paper_claims)
        counts = _claims_counts(paper_claims) if n_claims else dict.fromkeys(STATUSES, 0)
        completed = sum(1 for _, m in runs[paper] if m.get("status") == "completed")
        overview.append(
            (
                paper,
                f"{counts['reproduced']} of {n_claims}",
                counts["partly_reproduced"],
                counts["not_reproduced"],
                counts["not_run"],
                f"{completed} of {len(runs[paper])}",
            )
        )
    lines += [
        "## Overview",
        "",
        markdown_table(
            ("paper", "reproduced", "partly reproduced", "not reproduced", "not run",
             "runs completed"), overview
        )
        if overview
        else "_No papers found._",
        "",
    ]
    if claims is None:
        lines += [f"_No claims table ({_link(claims_path, base)} is missing)._", ""]

    for paper in paper_keys:
        lines += _paper_section(
            paper,
            results_dir=results_dir,
            figures_dir=figures_dir,
            base=base,
            claims=claims,
            runs=runs[paper],
            bench=bench,
            ours=ours[owner == paper],
        )
        lines += _ranges_section((ranges or {}).get(paper))
        lines += _robustness_section(results_dir, paper, base)
        lines += causes_section(results_dir, figures_dir, paper, lambda p: _link(p, base),
                                markdown_table)
        note = (notes or {}).get(paper)
        if note is not None and Path(note).is_file():
            lines += ["### Discussion", "", Path(note).read_text(encoding="utf-8").strip(), ""]

    if bench is not None and "paper" not in bench.columns:
        lines += ["## Benchmarks", "", _bench_table(bench), ""]

    lines += [
        f"## {OURS_HEADING}: shared library",
        "",
        _ours_table(ours[owner == ""], base),
        "",
    ]

    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_name(out_path.name + ".tmp")
    tmp.write_text("\n".join(lines).rstrip() + "\n", encoding="utf-8")
    os.replace(tmp, out_path)
    return out_path
