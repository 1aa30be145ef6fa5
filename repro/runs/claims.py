"""Paper claims checked against recorded runs, and the tidy claims table (results/claims.csv).

A :class:`Claim` names the run directories it needs (under ``results/<paper>/``) and a check
that turns their :class:`~repro.runs.trace.RunFiles` into a :class:`ClaimResult`. The table
never crashes: a missing or unfinished run, a run made with another configuration than the
registered experiment's default, or a check that raises, gives status ``"not_run"`` with the
reason in ``measured``.

Each run directory ``results/<paper>/<name>`` must be the default run of the registered
experiment ``<paper>.<name>`` (:mod:`repro.runs.registry`): its manifest's ``config_hash``
must equal the hash of that experiment's default config, so that an override run written into
the default folder (a 3 s test run, a changed gain) never decides a claim.

A run that ended before its configured ``duration`` (manifest ``summary.sim_time_s`` against
``config.duration``: a lost feature, a stop test) is named in ``measured``. A claim lists in
:attr:`Claim.whole_run` the runs it needs in full ("never", "the whole time"): on those, an
early end makes the claim ``"not_reproduced"`` -- it cannot hold on the part that never ran.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import pandas as pd

from repro.errors import ConfigError, ReproError, UnknownChoiceError
from repro.runs.registry import Paper, compute_config_hash, load_papers
from repro.runs.trace import RunFiles
from repro.runs.validate import DamagedRun, check_run

__all__ = [
    "CLAIMS_COLUMNS",
    "CLAUSE_COLUMNS",
    "ABSOLUTE_MAX",
    "MARGINAL_FRACTION",
    "VARIATION_COLUMNS",
    "VARIATION_FILE",
    "STATUSES",
    "Claim",
    "ClaimResult",
    "Clause",
    "RunExtent",
    "audit_note",
    "evaluate_claims",
    "extent_note",
    "run_extent",
    "natural_key",
    "read_claims_csv",
    "validate_claims_table",
    "write_claims_csv",
]

STATUSES = ("reproduced", "partly_reproduced", "not_reproduced", "not_run")
CLAIMS_COLUMNS = ("paper", "claim", "description", "expected", "measured", "status", "quote",
                  "clauses", "marginal")
#: The tidy clause table (results/claim_clauses.csv): one row per clause of every claim.
CLAUSE_COLUMNS = ("paper", "claim", "clause", "measured", "op", "threshold", "unit", "source",
                  "holds", "margin", "relative_margin", "varied_min", "varied_max",
                  "flips_within_variation", "marginal")
#: The measured machine-to-machine variation of every clause's figure
#: (``tests/measure_clause_variation.py``), read from the results folder when present.
VARIATION_FILE = "clause_variation.csv"
VARIATION_COLUMNS = ("paper", "claim", "clause", "committed", "min", "max", "n_perturbations",
                     "perturbations", "flips", "runs_remade", "machine")
#: A clause whose measured figure is within this fraction of its threshold is ``marginal``
#: (issue 18: within 10 %).
MARGINAL_FRACTION = 0.10
#: The largest threshold a ``relative=False`` clause with a unit may have: a numerical
#: tolerance around zero (e.g. 1e-6 rad), not a size bound
ABSOLUTE_MAX = 1e-3  # ours: above the checks' tolerances (<= 1e-6), below their sizes (>= 0.01)
_OPS = {"<=": lambda a, b: a <= b, ">=": lambda a, b: a >= b, "<": lambda a, b: a < b,
        ">": lambda a, b: a > b}


@dataclass(frozen=True)
class Clause:
    """One clause of a claim: one measured figure against one threshold.

    Attributes:
        name: what the clause says (the paper's words where they exist).
        measured: the figure measured on the runs (NaN: could not be measured; fails).
        op: how it must compare with ``threshold``: "<=", ">=", "<" or ">".
        threshold: the bound.
        unit: unit of ``measured`` and ``threshold`` ("-" for a count or a ratio).
        source: where the threshold comes from: "paper: <quote or section>" or
            "ours: <why>".
        relative: the margin relative to the threshold means something (a bound on a size);
            False for a count or a numerical tolerance around zero (then no relative margin
            and never ``marginal``: the signed margin says it).
        evidence: False for a clause that holds by construction of the run (e.g. a phase in
            which the code sends no command): reported, but not counted for the verdict.
        variation: (smallest, largest) figure measured on the same runs remade under the
            perturbations of another machine (:data:`VARIATION_FILE`); None: not measured.
    """

    name: str
    measured: float
    op: str
    threshold: float
    unit: str
    source: str
    relative: bool = True
    evidence: bool = True
    variation: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.op not in _OPS:
            raise UnknownChoiceError("clause op", self.op, tuple(_OPS))
        if not (self.source.startswith("paper:") or self.source.startswith("ours:")):
            raise ConfigError(f"clause {self.name!r}: source must start with 'paper:' or "
                              f"'ours:', got {self.source!r}")
        object.__setattr__(self, "measured", float(self.measured))
        object.__setattr__(self, "threshold", float(self.threshold))
        if (not self.relative and self.unit != "-" and self.threshold != 0.0
                and abs(self.threshold) > ABSOLUTE_MAX):
            raise ConfigError(
                f"clause {self.name!r}: a bound of {self.threshold:g} {self.unit} on a size is "
                "relative (its relative margin and the marginal flag mean something); "
                "relative=False is for counts, flags and tolerances around zero (issue 38: "
                "chan2011 1's 0.4963 vs 0.5 px was never flagged)")

    @classmethod
    def flag(cls, name: str, ok: bool, source: str, evidence: bool = True) -> Clause:
        """A yes/no clause (1 = holds) for a statement with no figure of its own (an order,
        an event, a match); its margin says nothing."""
        return cls(name, float(bool(ok)), ">=", 1.0, "-", source, relative=False,
                   evidence=evidence)

    @property
    def holds(self) -> bool:
        """True when ``measured op threshold`` (False for a NaN figure; an infinite one
        compares, e.g. a ratio over zero)."""
        return bool(not math.isnan(self.measured) and _OPS[self.op](self.measured,
                                                                   self.threshold))

    @property
    def margin(self) -> float:
        """Signed distance to the threshold in ``unit``, positive on the holding side."""
        d = self.measured - self.threshold
        return (d if self.op in (">=", ">") else -d) + 0.0  # + 0.0: no "-0" at the bound

    @property
    def relative_margin(self) -> float:
        """``margin / |threshold|`` (NaN for a zero threshold or ``relative=False``)."""
        if not self.relative or self.threshold == 0:
            return math.nan
        return self.margin / abs(self.threshold)

    def _holds_at(self, x: float) -> bool:
        return bool(not math.isnan(x) and _OPS[self.op](x, self.threshold))

    @property
    def flips(self) -> bool:
        """The verdict differs somewhere within the measured :attr:`variation` (False when
        none was measured)."""
        if self.variation is None:
            return False
        lo, hi = self.variation
        return len({self.holds, self._holds_at(lo), self._holds_at(hi)}) > 1

    @property
    def marginal(self) -> bool:
        """Within :data:`MARGINAL_FRACTION` of its threshold, on either side, or its verdict
        flips within the measured machine-to-machine variation (issue 18)."""
        r = self.relative_margin
        return bool(math.isfinite(r) and abs(r) < MARGINAL_FRACTION) or self.flips

    def summary(self) -> str:
        """One line: figure, bound, verdict, margin."""
        u = "" if self.unit == "-" else f" {self.unit}"
        flag = (", MARGINAL" + (": flips within the machine variation" if self.flips else "")
                if self.marginal else "") + (
            "" if self.evidence else ", by construction: not counted")
        return (f"{self.name}: {self.measured:.4g}{u} {self.op} {self.threshold:.4g}{u} "
                f"({'holds' if self.holds else 'fails'}, margin {self.margin:+.3g}{u}{flag})")


@dataclass(frozen=True)
class ClaimResult:
    """Outcome of one claim check.

    Attributes:
        measured: what was measured, with units, e.g. "max error 1.8 mm".
        status: one of STATUSES.
        clauses: the clauses the status was judged on (:meth:`from_clauses`); empty for a
            check not yet written clause by clause.
    """

    measured: str
    status: str
    clauses: tuple[Clause, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.measured, str):
            raise ConfigError(f"measured must be a string, got {type(self.measured).__name__}")
        if self.status not in STATUSES:
            raise UnknownChoiceError("claim status", self.status, STATUSES)

    @classmethod
    def from_clauses(cls, measured: str, clauses: Sequence[Clause]) -> ClaimResult:
        """The claim is ``reproduced`` when every clause holds, ``partly_reproduced`` when
        some do (``measured`` names those that hold, then those that fail: issue 18),
        ``not_reproduced`` when none does."""
        clauses = tuple(clauses)
        counted = [c for c in clauses if c.evidence]
        if not counted:
            raise ConfigError("a claim needs at least one clause that is evidence")
        held = [c for c in counted if c.holds]
        failed = [c.name for c in counted if not c.holds]
        status = ("reproduced" if not failed else
                  "partly_reproduced" if held else "not_reproduced")
        text = measured
        if failed and held:
            text += f" -- held ({len(held)} of {len(counted)}): {'; '.join(c.name for c in held)}"
        text += f" -- not met: {'; '.join(failed)}" if failed else ""
        return cls(text, status, clauses)


@dataclass(frozen=True)
class Claim:
    """One quantitative claim of a paper and how to check it.

    Attributes:
        paper: paper key, e.g. "thomas2024".
        claim: claim id within the paper, e.g. "1" or "2b".
        description: what the paper states.
        expected: the paper's value or bound, with units.
        runs: run-directory names relative to results/<paper>/ that the check needs; each is
            also the name of a registered experiment of ``paper``.
        check: maps {run name: RunFiles} to a ClaimResult.
        whole_run: the runs of ``runs`` the claim needs up to their configured duration (it
            speaks of the whole motion: "never", "the whole time"); if one of them ended
            early, the claim is not reproduced.
        quote: the paper's words the check tests, with their section.
    """

    paper: str
    claim: str
    description: str
    expected: str
    runs: tuple[str, ...]
    check: Callable[[dict[str, RunFiles]], ClaimResult]
    whole_run: tuple[str, ...] = ()
    #: the paper's sentence(s) the check tests, with their section
    quote: str = ""
    #: event kinds that end a run with its task complete (a convergence stop): such a run
    #: counts as whole for ``whole_run``
    done_events: tuple[str, ...] = ()
    #: runs of ``runs`` the claim can be judged on alone, each with its own clauses (the
    #: check judges the runs it is given): a sweep of one of them judges this part of the
    #: claim (:func:`repro.runs.sweep.sweep_claims`); the canonical verdict needs them all
    per_run: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("paper", "claim"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value.strip():
                raise ConfigError(f"claim {name} must be a non-empty string, got {value!r}")
        if isinstance(self.runs, str):
            raise ConfigError(
                f"claim runs must be a sequence of names, got the string {self.runs!r}"
            )
        object.__setattr__(self, "runs", tuple(self.runs))
        for run in self.runs:
            if (
                not isinstance(run, str)
                or not run
                or Path(run).is_absolute()
                or ".." in Path(run).parts
            ):
                raise ConfigError(f"claim run must be a relative directory name, got {run!r}")
        if not callable(self.check):
            raise ConfigError(f"claim check must be callable, got {self.check!r}")
        if isinstance(self.whole_run, str):
            raise ConfigError(
                f"claim whole_run must be a sequence of names, got the string {self.whole_run!r}"
            )
        object.__setattr__(self, "whole_run", tuple(self.whole_run))
        unknown = [run for run in self.whole_run if run not in self.runs]
        if unknown:
            raise ConfigError(
                f"claim whole_run names {unknown}, which are not among its runs {list(self.runs)}"
            )
        object.__setattr__(self, "per_run", tuple(self.per_run))
        unknown = [run for run in self.per_run if run not in self.runs]
        if unknown:
            raise ConfigError(
                f"claim per_run names {unknown}, which are not among its runs {list(self.runs)}"
            )


@dataclass(frozen=True)
class RunExtent:
    """How much of its configured duration a run covered.

    Attributes:
        sim_time_s: simulated time at the last row [s] (manifest ``summary.sim_time_s``, else
            the trace's last ``t``), None if unknown.
        duration_s: the configured duration [s] (manifest ``config.duration``), None if the
            run has none (e.g. an audit over random samples).
        stop_reason: why the run stopped (manifest ``summary.stop_reason`` or ``reason``).
        step_s: the control period [s] (median step of the trace's ``t``), 0 if unknown.
    """

    sim_time_s: float | None
    duration_s: float | None
    stop_reason: str
    step_s: float = 0.0

    @property
    def ended_early(self) -> bool:
        """True if the run stopped more than half a control period before its duration."""
        if self.sim_time_s is None or self.duration_s is None:
            return False
        return self.sim_time_s < self.duration_s - max(0.5 * self.step_s, 1e-9)

    @property
    def missing_s(self) -> float:
        """Simulated time that never ran [s] (0 if the run reached its duration)."""
        if not self.ended_early:
            return 0.0
        assert self.sim_time_s is not None and self.duration_s is not None
        return self.duration_s - self.sim_time_s


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


def run_extent(run: RunFiles) -> RunExtent:
    """The :class:`RunExtent` of a run, read from its manifest and trace."""
    summary = run.manifest.get("summary") or {}
    config = run.manifest.get("config") or {}
    t = run.trace["t"].to_numpy(float) if "t" in run.trace.columns else None
    sim_time = _number(summary.get("sim_time_s"))
    if sim_time is None and t is not None and len(t):
        sim_time = float(t[-1])
    step = float(pd.Series(t).diff().median()) if t is not None and len(t) > 1 else 0.0
    reason = summary.get("stop_reason") or run.manifest.get("reason") or "no reason recorded"
    return RunExtent(sim_time, _number(config.get("duration")), str(reason),
                     step if math.isfinite(step) else 0.0)


def extent_note(runs: Mapping[str, RunFiles], whole_run: Sequence[str] = (),
                done_events: Sequence[str] = ()) -> tuple[str, bool]:
    """(text for ``measured``, True if a run of ``whole_run`` ended early).

    Names every run that ended before its configured duration, with its stop reason; for a
    run of ``whole_run`` it adds that the claim cannot be reproduced on the part that never
    ran -- unless the run ended on one of ``done_events`` (its task complete, e.g. a
    convergence test): then the whole task ran. Empty text when every run covered its
    duration."""
    notes, failed = [], False
    for name, run in runs.items():
        extent = run_extent(run)
        if not extent.ended_early:
            continue
        note = (f"{name} ended at {extent.sim_time_s:.2f} s of its {extent.duration_s:g} s "
                f"({extent.stop_reason})")
        ev = run.events
        done = bool(done_events) and len(ev) > 0 and bool(ev["kind"].isin(done_events).any())
        if done:
            note += "; its task was complete: judged on the whole task"
        elif name in whole_run:
            failed = True
            note += (f"; the claim covers the whole run: not reproduced on the "
                     f"{extent.missing_s:.1f} s that never ran")
        else:
            note += "; judged on what ran"
        notes.append(note)
    return (" [RUN LENGTH: " + "; ".join(notes) + "]") if notes else "", failed


def _row(claim: Claim, measured: str, status: str,
         clauses: Sequence[Clause] = ()) -> dict[str, str]:
    return {
        "paper": claim.paper,
        "claim": claim.claim,
        "description": claim.description,
        "expected": claim.expected,
        "measured": measured,
        "status": status,
        "quote": claim.quote,
        "clauses": " | ".join(c.summary() for c in clauses),
        "marginal": "; ".join(c.name for c in clauses if c.marginal),
    }


def clause_rows(claim: Claim, clauses: Sequence[Clause]) -> list[dict[str, object]]:
    """The claim's rows of the tidy clause table (:data:`CLAUSE_COLUMNS`)."""
    return [{"paper": claim.paper, "claim": claim.claim, "clause": c.name,
             "measured": c.measured, "op": c.op, "threshold": c.threshold, "unit": c.unit,
             "source": c.source, "holds": c.holds, "margin": c.margin,
             "relative_margin": c.relative_margin,
             "varied_min": c.variation[0] if c.variation else math.nan,
             "varied_max": c.variation[1] if c.variation else math.nan,
             "flips_within_variation": c.flips, "marginal": c.marginal} for c in clauses]


def read_variation(results_dir: Path) -> dict[tuple[str, str, str], tuple[float, float]]:
    """The measured variation of each clause's figure, keyed (paper, claim, clause), from
    ``results_dir / VARIATION_FILE`` ({} when the file is absent). The committed figure of
    today's run joins the range, so a stale file cannot narrow it."""
    path = Path(results_dir) / VARIATION_FILE
    if not path.is_file():
        return {}
    df = pd.read_csv(path, dtype={"paper": str, "claim": str, "clause": str})
    missing = set(VARIATION_COLUMNS) - set(df.columns)
    if missing:
        raise ReproError(f"{path}: columns {sorted(missing)} missing")
    return {(r.paper, r.claim, r.clause): (float(r.min), float(r.max))
            for r in df.itertuples(index=False)}


def with_variation(claim: Claim, clauses: Sequence[Clause],
                   variation: Mapping[tuple[str, str, str], tuple[float, float]]
                   ) -> tuple[Clause, ...]:
    """``clauses`` with their measured variation attached (widened to today's figure)."""
    out = []
    for c in clauses:
        v = variation.get((claim.paper, claim.claim, c.name))
        if v is not None and not math.isnan(c.measured):
            v = (min(v[0], c.measured), max(v[1], c.measured))
        out.append(replace(c, variation=v) if v is not None else c)
    return tuple(out)


def stale_variation_note(claim: Claim, clauses: Sequence[Clause],
                         variation: Mapping[tuple[str, str, str], tuple[float, float]]) -> str:
    """A warning for the claim's ``measured`` text when the variation file names clauses of
    this claim that its check no longer has (a renamed clause), and which of its clauses
    then have no measured variation: the join is by the clause's words, and a renamed
    clause must not silently lose its variation (issue 38). Empty when all match."""
    names = {c.name for c in clauses}
    known = {k[2] for k in variation if k[:2] == (claim.paper, claim.claim)}
    gone = sorted(known - names)
    if not gone:
        return ""
    bare = sorted(c.name for c in clauses if c.variation is None)
    return (f" [VARIATION: {VARIATION_FILE} names clauses {gone} that this check no longer "
            f"has; without a measured variation: {bare}; re-measure with "
            "tests/measure_clause_variation.py]")


def _default_hash(papers: Mapping[str, Paper], paper: str, name: str) -> str:
    """The config hash of the registered experiment ``paper.name``'s default config, or
    raise ReproError saying why there is none."""
    if paper not in papers:
        raise ReproError(f"paper {paper!r} is not registered (registered: {sorted(papers)})")
    names = [exp.name for exp in papers[paper].experiments]
    for exp in papers[paper].experiments:
        if exp.name == name:
            return compute_config_hash(exp.config_cls())
    raise ReproError(f"run {name!r} is not a registered experiment of {paper} "
                     f"(experiments: {', '.join(names)})")


def _load_runs(
    claim: Claim,
    results_dir: Path,
    cache: dict[Path, RunFiles | str],
    papers: Callable[[], Mapping[str, Paper]],
) -> dict[str, RunFiles] | str:
    """The claim's runs, or a message saying why one is unusable."""
    runs: dict[str, RunFiles] = {}
    for name in claim.runs:
        run_dir = results_dir / claim.paper / name
        if run_dir not in cache:
            if not run_dir.is_dir():
                cache[run_dir] = f"run {name!r} missing ({run_dir} does not exist)"
            else:
                try:
                    cache[run_dir] = check_run(run_dir)
                except DamagedRun as exc:  # names the folder and the first failing rule
                    cache[run_dir] = f"run {name!r} not usable: {exc}"
        loaded = cache[run_dir]
        if isinstance(loaded, str):
            return loaded
        try:  # load_papers() raises ReproError too if an entry point is broken
            expected = _default_hash(papers(), claim.paper, name)
        except ReproError as exc:
            return f"run {name!r} cannot be matched to an experiment: {exc}"
        recorded = loaded.manifest.get("config_hash")
        if recorded != expected:
            shown = recorded[:12] if isinstance(recorded, str) else recorded
            return (f"run {name!r} was made with another config than the default of "
                    f"{claim.paper}.{name} (manifest config_hash {shown!r}, default "
                    f"{expected[:12]!r}); rerun it with `repro run {claim.paper}.{name}`")
        runs[name] = loaded
    return runs


def evaluate_claims(
    claims: Sequence[Claim], results_dir: Path, papers: Mapping[str, Paper] | None = None,
    clauses_out: list[dict[str, object]] | None = None,
) -> pd.DataFrame:
    """Check every claim against the runs in results_dir/<paper>/<run>.

    Args:
        claims: the claims to check.
        results_dir: the results folder (``results/``).
        papers: the registered papers whose experiments' default configs the runs must have
            been made with (default: :func:`repro.runs.registry.load_papers`, read once).
        clauses_out: receives the rows of the tidy clause table (:func:`clause_rows`) of
            every claim that was judged clause by clause.

    Returns:
        One row per claim, columns CLAIMS_COLUMNS (all strings), in the order of ``claims``.
        ``measured`` is the check's text, then the runs that ended early
        (:func:`extent_note`), then the camera-audit warnings (:func:`audit_note`).
    """
    results_dir = Path(results_dir)
    cache: dict[Path, RunFiles | str] = {}
    registered: list[Mapping[str, Paper]] = [] if papers is None else [papers]

    def get_papers() -> Mapping[str, Paper]:
        if not registered:
            registered.append(load_papers())
        return registered[0]

    variation = read_variation(results_dir)
    rows = []
    for claim in claims:
        runs = _load_runs(claim, results_dir, cache, get_papers)
        if isinstance(runs, str):
            rows.append(_row(claim, runs, "not_run"))
            continue
        try:
            result = claim.check(runs)
        except Exception as exc:  # a broken check must not take the whole table down
            if isinstance(exc, KeyError):  # a column the check reads is not in the trace
                where = ", ".join(f"{claim.paper}/{r}" for r in claim.runs)
                message = f"check failed: column {exc} missing from run(s) {where}"
            else:
                message = f"check failed: {type(exc).__name__}: {exc}"
            rows.append(_row(claim, message, "not_run"))
            continue
        if not isinstance(result, ClaimResult):
            message = f"check returned {type(result).__name__}, not ClaimResult"
            rows.append(_row(claim, message, "not_run"))
            continue
        stale = ""
        if variation and result.clauses:
            result = replace(result, clauses=with_variation(claim, result.clauses, variation))
            stale = stale_variation_note(claim, result.clauses, variation)
        extent, cut_short = extent_note(runs, claim.whole_run, claim.done_events)
        status = ("not_reproduced" if cut_short and result.status in (
            "reproduced", "partly_reproduced") else result.status)
        rows.append(_row(claim, result.measured + extent + audit_note(runs) + stale, status,
                         result.clauses))
        if clauses_out is not None:
            clauses_out.extend(clause_rows(claim, result.clauses))
    return pd.DataFrame(rows, columns=list(CLAIMS_COLUMNS), dtype=object)


def audit_note(runs: Mapping[str, RunFiles]) -> str:
    """A warning for the claim's ``measured`` text when a run's camera audit (manifest
    ``summary.audit``) found that the controller used a wrong feature (a detection more
    than the tolerance from its model point's projection) or a hidden point reported found.
    Empty when every audit is clean."""
    notes = []
    for name, run in runs.items():
        audit = (run.manifest.get("summary") or {}).get("audit") or {}
        for cam, a in audit.items():
            if a.get("mismatch_rows"):
                notes.append(f"{name}: {cam} points {a.get('points_mismatched')} detected "
                             f"> tolerance from their projection in {a['mismatch_rows']} rows "
                             f"(max {a.get('max_err_px', float('nan')):.1f} px)")
            if a.get("hidden_found_rows"):
                notes.append(f"{name}: {cam} points {a.get('points_hidden_found')} reported "
                             f"found while hidden in {a['hidden_found_rows']} rows")
    return (" [AUDIT: " + "; ".join(notes) + "]") if notes else ""


def natural_key(text: str) -> tuple[tuple[int, int | str], ...]:
    """Sort key ordering digit runs numerically: "2" < "10", "2a" < "2b" < "10"."""
    return tuple(
        (0, int(part)) if part.isdigit() else (1, part) for part in re.split(r"(\d+)", text) if part
    )


def validate_claims_table(df: pd.DataFrame) -> pd.DataFrame:
    """Return df as a claims table (columns CLAIMS_COLUMNS, str cells) or raise ReproError.

    Checks: exactly the columns CLAIMS_COLUMNS (any order; a table with only the first six,
    written before clauses existed, gets empty quote/clauses/marginal), no missing
    paper/claim/status,
    every status in STATUSES, no duplicate (paper, claim).
    """
    columns = set(df.columns)
    if columns == set(CLAIMS_COLUMNS[:6]) and len(df.columns) == 6:  # a table of before issue 18
        df = df.assign(**{c: "" for c in CLAIMS_COLUMNS[6:]})
        columns = set(df.columns)
    if columns != set(CLAIMS_COLUMNS) or len(df.columns) != len(CLAIMS_COLUMNS):
        raise ReproError(
            f"claims table has columns {list(df.columns)}, expected {list(CLAIMS_COLUMNS)}"
        )
    out = df.loc[:, list(CLAIMS_COLUMNS)].copy()
    for name in ("paper", "claim", "status"):
        empty = out[name].isna() | (out[name].astype(str).str.strip() == "")
        if empty.any():
            raise ReproError(
                f"claims table has an empty {name!r} in row(s) {list(out.index[empty])}"
            )
    out = out.fillna("").astype(str).astype(object)
    bad = sorted(set(out["status"]) - set(STATUSES))
    if bad:
        raise UnknownChoiceError("claim status", bad[0], STATUSES)
    duplicated = out.duplicated(subset=["paper", "claim"])
    if duplicated.any():
        pairs = out.loc[duplicated, ["paper", "claim"]].itertuples(index=False)
        raise ReproError(f"claims table has duplicate (paper, claim): {[tuple(p) for p in pairs]}")
    return out.reset_index(drop=True)


def read_claims_csv(path: Path) -> pd.DataFrame:
    """Read and validate a claims CSV (all cells strings; an empty cell is "")."""
    path = Path(path)
    if not path.is_file():
        raise ReproError(f"claims file {path} does not exist")
    df = pd.read_csv(path, dtype=str, keep_default_na=False)
    try:
        return validate_claims_table(df)
    except ReproError as exc:
        raise ReproError(f"{path}: {exc}") from exc


def write_clauses_csv(rows: Sequence[Mapping[str, object]], papers: Sequence[str],
                      path: Path) -> None:
    """Merge clause rows (:data:`CLAUSE_COLUMNS`) into the tidy clause table at ``path``:
    the rows of ``papers`` replace theirs, other papers' rows are kept; atomic."""
    path = Path(path)
    new = pd.DataFrame(list(rows), columns=list(CLAUSE_COLUMNS))
    if path.is_file():
        old = pd.read_csv(path, dtype=str, keep_default_na=False)
        if tuple(old.columns) == CLAUSE_COLUMNS:
            new = pd.concat([old[~old["paper"].isin(set(papers))], new.astype(str)],
                            ignore_index=True)
    new = new.astype(str)
    order = sorted(range(len(new)), key=lambda i: (new["paper"].iloc[i],
                                                   natural_key(new["claim"].iloc[i])))
    new = new.iloc[order]
    tmp = path.with_name(path.name + ".tmp")
    path.parent.mkdir(parents=True, exist_ok=True)
    new.to_csv(tmp, index=False, lineterminator="\n")
    os.replace(tmp, path)


def write_claims_csv(df: pd.DataFrame, path: Path) -> None:
    """Validate df and merge it into the claims CSV at path.

    Rows of the papers present in df replace that paper's rows in the existing file; rows of
    other papers are kept. The file is sorted by paper, then claim in natural order, and
    replaced atomically.
    """
    path = Path(path)
    new = validate_claims_table(df)
    if path.exists():
        old = read_claims_csv(path)
        old = old[~old["paper"].isin(set(new["paper"]))]
        merged = pd.concat([old, new], ignore_index=True)
    else:
        merged = new
    records = sorted(
        merged.itertuples(index=False, name=None),
        key=lambda r: (r[0], natural_key(r[1])),
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(CLAIMS_COLUMNS)
        writer.writerows(records)
    os.replace(tmp, path)
