"""Why a clause fails over a sweep's scenes (issue 37): a named cause for every failing variant.

A sweep's rate says how often a clause holds; it does not say why it fails where it fails.
A paper declares a :class:`CauseModel`:

* per swept experiment, an **evidence** function of the variant's runs (the
  :class:`~repro.runs.trace.RunFiles` of the swept experiment and its partners): a flat
  mapping of named figures computed from their traces and events (which link touched, how
  far the nearest ray read, which limit saturated...). The sweep computes it while the
  variant's trace is there and keeps it in the variant's ``verdicts.json`` (the trace itself
  is pruned), with the model's ``version``;
* per clause, a :class:`Diagnosis`: a pure function of that evidence (and of the variant's
  own verdicts and parameters) naming the cause of the clause's failure, one of
  :data:`CLASSES` -- or a reason the clause fits only the paper's own scene
  (``scene_specific``: class ``check``; it is judged on the canonical run alone and no rate
  is reported for it);
* **counterfactuals**: the same failing variants with one cause removed
  (:class:`Counterfactual`: config overrides), whose rate shows the class instead of
  asserting it (:func:`repro.runs.sweep.run_counterfactual`).

The tables (:func:`write_causes`): ``<sweep>/causes.csv`` (one row per failing variant of
every clause whose rate is under :data:`RATE_BAR`: its class, cause, evidence line and
figure) and ``<sweep>/cause_shares.csv`` (per clause and cause: the share of the failing
variants, an example variant, and the counterfactual's rate beside it).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from repro.errors import ConfigError, ReproError, UnknownChoiceError
from repro.runs.trace import RunFiles

__all__ = [
    "CAUSES_COLUMNS",
    "CLASSES",
    "COUNTERFACTUALS_DIR",
    "RATE_BAR",
    "SHARES_COLUMNS",
    "UNKNOWN",
    "Cause",
    "CauseModel",
    "Counterfactual",
    "Diagnosis",
    "Variant",
    "classify_variants",
    "compute_evidence",
    "counterfactual_variants",
    "needs_evidence",
    "scene_specific",
    "write_causes",
]

#: The classes of a cause (issue 37): the paper's design cannot do it here (``method``); our
#: implementation is wrong (``ours-defect``); the sweep's range reaches scenes the paper rules
#: out (``ours-range``); the clause cannot be judged on a varied scene (``check``).
CLASSES = ("method", "ours-defect", "ours-range", "check")
#: A failing variant no diagnosis names (a clause without a classifier, or one that could
#: not decide): counted, never hidden.
UNKNOWN = "unknown"
#: Clauses whose sweep rate is below this get a cause for each failing variant (issue 37:
#: "for each clause whose sweep rate is below 0.9").
RATE_BAR = 0.9
#: Sub-folder of a sweep's folder holding its counterfactual sweeps, one folder each.
COUNTERFACTUALS_DIR = "counterfactuals"
CAUSES_COLUMNS = ("experiment", "variant", "config_hash", "claim", "clause", "class", "cause",
                  "evidence", "figure", "unit")
SHARES_COLUMNS = ("experiment", "claim", "clause", "rate", "failing", "class", "cause", "n",
                  "share", "example_variant", "example_hash", "example_evidence",
                  "counterfactual", "cf_variants", "cf_held", "cf_rate", "scope")
#: scope of a clause in the sweep tables: judged over the variants, or on the canonical
#: scene only (a :attr:`Diagnosis.scene_specific` clause: no rate reported)
SCOPES = ("variants", "canonical only")

Scalar = float | int | str | bool


@dataclass(frozen=True)
class Cause:
    """Why one clause failed on one variant.

    Attributes:
        cls: one of :data:`CLASSES`, or :data:`UNKNOWN`.
        name: a short stable name of the cause (e.g. ``"blind-link5"``), the key of its
            share and of the counterfactual that removes it.
        evidence: one line, the measured figures that name it (units included).
        figure: the deciding figure (NaN if none).
        unit: its unit (``"-"`` for a count or a ratio).
    """

    cls: str
    name: str
    evidence: str
    figure: float = math.nan
    unit: str = "-"

    def __post_init__(self) -> None:
        if self.cls not in (*CLASSES, UNKNOWN):
            raise UnknownChoiceError("cause class", self.cls, (*CLASSES, UNKNOWN))
        if not self.name or any(ch in self.name for ch in ",\n"):
            raise ConfigError(f"cause name must be a non-empty word list without commas or "
                              f"newlines, got {self.name!r}")
        object.__setattr__(self, "figure", float(self.figure))


@dataclass(frozen=True)
class Variant:
    """What a classifier may read of one judged variant: its swept parameters (without the
    ``p.`` prefix), its evidence (:attr:`CauseModel.evidence`), and its clauses' verdicts."""

    index: int
    config_hash: str
    params: Mapping[str, Any]
    evidence: Mapping[str, Any]
    verdicts: Mapping[str, Any]

    def clause(self, claim: str, name: str) -> Mapping[str, Any]:
        """The verdict of clause ``name`` of ``claim`` (measured, margin, holds).

        Raises:
            ReproError: if the variant's verdicts have no such clause (a renamed clause
                must not be read as a missing one).
        """
        for c in (self.verdicts.get(claim) or {}).get("clauses", []):
            if c.get("name") == name:
                return c
        raise ReproError(f"variant {self.index}: claim {claim} has no clause {name!r}")

    def holds(self, claim: str, name: str) -> bool:
        """Whether clause ``name`` of ``claim`` held on this variant."""
        return bool(self.clause(claim, name).get("holds"))

    def figure(self, key: str) -> float:
        """Evidence ``key`` as a float (NaN when absent or not a number)."""
        value = self.evidence.get(key)
        try:
            return float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            return math.nan


Classifier = Callable[[Variant], Cause]


@dataclass(frozen=True)
class Diagnosis:
    """How the failure of one clause is named on a variant.

    Attributes:
        experiment: the swept experiment (its name, e.g. ``"case1"``).
        claim, clause: the clause, by its claim id and its exact name (as judged).
        classify: the variant -> its :class:`Cause` (called only where the clause fails);
            None for a scene-specific clause.
        scene_specific: non-empty: why the clause fits only the paper's own scene (the
            paper's words); then every failing variant is of class ``check``, and the
            clause's rate is not reported.
    """

    experiment: str
    claim: str
    clause: str
    classify: Classifier | None = None
    scene_specific: str = ""

    def __post_init__(self) -> None:
        if (self.classify is None) == (not self.scene_specific):
            raise ConfigError(f"diagnosis of claim {self.claim} {self.clause!r}: give either "
                              "a classifier or a scene_specific reason, not both or neither")

    def cause(self, variant: Variant) -> Cause:
        """The cause of this clause's failure on ``variant`` (never raises: a classifier
        that fails gives :data:`UNKNOWN` with its error)."""
        if self.scene_specific:
            return Cause("check", "scene-specific", self.scene_specific)
        assert self.classify is not None
        try:
            got = self.classify(variant)
        except Exception as exc:  # one broken classifier must not hide the others
            return Cause(UNKNOWN, "classifier-error", f"{type(exc).__name__}: {exc}")
        if not isinstance(got, Cause):
            raise ReproError(f"classifier of claim {self.claim} {self.clause!r} returned "
                             f"{type(got).__name__}, not a Cause")
        return got


@dataclass(frozen=True)
class Counterfactual:
    """The failing variants of one cause, rerun with only that cause removed.

    Attributes:
        name: its name (the folder under ``<sweep>/counterfactuals/``).
        experiment: the swept experiment.
        removes: the :attr:`Cause.name` it removes; its variants are those in which some
            clause failed by that cause.
        overrides: config changes applied to every member of the sweep (fields they have).
        why: what it changes, and why that removes only this cause.
    """

    name: str
    experiment: str
    removes: str
    overrides: Mapping[str, Any]
    why: str

    def __post_init__(self) -> None:
        if not self.name.replace("_", "").replace("-", "").isalnum():
            raise ConfigError(f"counterfactual name {self.name!r}: letters, digits, - and _")
        if not self.overrides:
            raise ConfigError(f"counterfactual {self.name}: no override (nothing removed)")


@dataclass(frozen=True)
class CauseModel:
    """A paper's causes: evidence per swept experiment, diagnoses, counterfactuals.

    ``version``: change it whenever an evidence function changes what it returns; a variant
    judged with another version is rerun by the next sweep where one of its failing clauses
    needs evidence (:func:`needs_evidence`)."""

    version: str
    evidence: Mapping[str, Callable[[Mapping[str, RunFiles]], Mapping[str, Scalar]]]
    diagnoses: tuple[Diagnosis, ...]
    counterfactuals: tuple[Counterfactual, ...] = field(default=())

    def for_experiment(self, experiment: str) -> list[Diagnosis]:
        return [d for d in self.diagnoses if d.experiment == experiment]

    def counterfactual(self, experiment: str, name: str) -> Counterfactual:
        """The counterfactual ``name`` of ``experiment``.

        Raises:
            UnknownChoiceError: naming the ones it has.
        """
        mine = {c.name: c for c in self.counterfactuals if c.experiment == experiment}
        if name not in mine:
            raise UnknownChoiceError(f"counterfactual of {experiment}", name, tuple(mine))
        return mine[name]


def scene_specific(model: CauseModel | None, experiment: str) -> dict[tuple[str, str], str]:
    """``{(claim, clause): reason}`` of the clauses of ``experiment`` judged on the canonical
    scene only."""
    if model is None:
        return {}
    return {(d.claim, d.clause): d.scene_specific for d in model.for_experiment(experiment)
            if d.scene_specific}


def needs_evidence(model: CauseModel | None, experiment: str, verdicts: Mapping[str, Any],
                   stored_version: str | None) -> bool:
    """Whether a judged variant must be rerun for its evidence: some clause with a
    classifier fails on it and its evidence is missing or of another version."""
    if model is None or experiment not in model.evidence or stored_version == model.version:
        return False
    keyed = {(d.claim, d.clause) for d in model.for_experiment(experiment)
             if d.classify is not None}
    return any((cid, c.get("name")) in keyed and not c.get("holds")
               for cid, v in verdicts.items() for c in (v or {}).get("clauses", []))


def compute_evidence(model: CauseModel | None, experiment: str,
                     runs: Mapping[str, RunFiles]) -> dict[str, Any]:
    """The evidence of one variant for ``verdicts.json``: ``{"evidence": {...},
    "evidence_version": ...}``, or ``{"evidence_error": ...}``; empty without a model."""
    if model is None or experiment not in model.evidence:
        return {}
    try:
        ev = dict(model.evidence[experiment](runs))
    except Exception as exc:  # recorded: its clauses' causes are then unknown
        return {"evidence_error": f"{type(exc).__name__}: {exc}",
                "evidence_version": model.version}
    bad = [k for k, v in ev.items() if not isinstance(v, Scalar)]
    if bad:
        raise ReproError(f"evidence of {experiment}: {bad} are not numbers, text or flags")
    return {"evidence": ev, "evidence_version": model.version}


# ------------------------------------------------------------------------------ tables
def _load_variants(sweep_dir: Path) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """(row, verdicts.json) of every judged variant of a sweep, by variant index."""
    from repro.runs.sweep_rates import NOT_JUDGED

    df = pd.read_csv(sweep_dir / "variants.csv", dtype={"config_hash": str})
    out = []
    for row in df.to_dict("records"):
        if row.get("run_status") in NOT_JUDGED:
            continue
        path = sweep_dir / "variants" / str(row["config_hash"]) / "verdicts.json"
        doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
        out.append((row, doc))
    return out


def _variant(row: Mapping[str, Any], doc: Mapping[str, Any]) -> Variant:
    return Variant(int(row["variant"]), str(row["config_hash"]),
                   {k[2:]: v for k, v in row.items() if str(k).startswith("p.")},
                   doc.get("evidence") or {}, doc.get("verdicts") or {})


def classify_variants(model: CauseModel | None, experiment: str, sweep_dir: Path,
                      rate_bar: float = RATE_BAR) -> tuple[pd.DataFrame, dict[tuple[str, str],
                                                                           tuple[int, int]]]:
    """Every failing variant of every clause whose rate is under ``rate_bar`` (or that is
    scene-specific), with its cause: the rows of causes.csv, and ``{(claim, clause):
    (judged, held)}`` of those clauses.

    Raises:
        ReproError: if a diagnosis names a clause the sweep's verdicts do not have.
    """
    variants = _load_variants(Path(sweep_dir))
    diagnoses = {(d.claim, d.clause): d for d in (model.for_experiment(experiment)
                                                  if model else [])}
    counts: dict[tuple[str, str], list[int]] = {}
    for _, doc in variants:
        for cid, v in (doc.get("verdicts") or {}).items():
            for c in (v or {}).get("clauses", []):
                n_h = counts.setdefault((cid, c["name"]), [0, 0])
                n_h[0] += 1
                n_h[1] += bool(c.get("holds"))
    missing = sorted(set(diagnoses) - set(counts))
    if missing and variants:
        raise ReproError(f"{experiment}: diagnoses name clauses the sweep never judged: "
                         f"{missing} (renamed? the sweep's clauses: {sorted(counts)})")
    low = {key for key, (n, h) in counts.items()
           if n and (h / n < rate_bar or (key in diagnoses and diagnoses[key].scene_specific))}
    rows = []
    for row, doc in variants:
        var = _variant(row, doc)
        for cid, v in (doc.get("verdicts") or {}).items():
            for c in (v or {}).get("clauses", []):
                key = (cid, c["name"])
                if key not in low or c.get("holds"):
                    continue
                diag = diagnoses.get(key)
                if diag is None:
                    cause = Cause(UNKNOWN, "no-classifier", "no diagnosis declared")
                elif diag.classify is not None and "evidence_error" in doc:
                    cause = Cause(UNKNOWN, "evidence-error", str(doc["evidence_error"]))
                elif (diag.classify is not None and not diag.scene_specific
                      and model is not None and doc.get("evidence_version") != model.version):
                    cause = Cause(UNKNOWN, "no-evidence", "judged before this evidence "
                                  f"(version {doc.get('evidence_version')!r}, the model's "
                                  f"{model.version!r}): rerun the sweep")
                else:
                    cause = diag.cause(var)
                rows.append((experiment, var.index, var.config_hash, cid, c["name"], cause.cls,
                             cause.name, cause.evidence, cause.figure, cause.unit))
    table = pd.DataFrame(rows, columns=list(CAUSES_COLUMNS))
    return table, {k: (counts[k][0], counts[k][1]) for k in sorted(low)}


def _counterfactual_rates(sweep_dir: Path, model: CauseModel, experiment: str
                          ) -> dict[tuple[str, str, str], tuple[str, int, int]]:
    """``{(claim, clause, cause): (counterfactual, variants, held)}`` from the
    counterfactual sweeps under ``sweep_dir``: the clause's verdict on each rerun variant
    whose original failed by the cause the counterfactual removes."""
    out: dict[tuple[str, str, str], tuple[str, int, int]] = {}
    causes_path = sweep_dir / "causes.csv"
    for cf in model.counterfactuals:
        if cf.experiment != experiment:
            continue
        cf_dir = sweep_dir / COUNTERFACTUALS_DIR / cf.name
        if not (cf_dir / "variants.csv").is_file() or not causes_path.is_file():
            continue
        causes = pd.read_csv(causes_path, dtype={"claim": str, "config_hash": str},
                             keep_default_na=False)
        mine = causes[causes["cause"] == cf.removes]
        reruns = {int(r["variant"]): doc for r, doc in _load_variants(cf_dir)}
        for (cid, clause), grp in mine.groupby(["claim", "clause"]):
            n = h = 0
            for idx in grp["variant"].astype(int):
                doc = reruns.get(idx)
                if doc is None:
                    continue
                var = _variant({"variant": idx, "config_hash": ""}, doc)
                try:
                    held = var.holds(str(cid), str(clause))
                except ReproError:
                    continue
                n, h = n + 1, h + held
            out[(str(cid), str(clause), cf.removes)] = (cf.name, n, h)
    return out


def write_causes(sweep_dir: Path, model: CauseModel | None, experiment: str) -> list[Path]:
    """Write ``causes.csv`` and ``cause_shares.csv`` of a sweep (nothing without a model or
    a clause to explain); return the paths written."""
    sweep_dir = Path(sweep_dir)
    if model is None or not model.for_experiment(experiment):
        return []
    table, counts = classify_variants(model, experiment, sweep_dir)
    causes_path = sweep_dir / "causes.csv"
    table.to_csv(causes_path, index=False, float_format="%.6g")
    specific = scene_specific(model, experiment)
    cf = _counterfactual_rates(sweep_dir, model, experiment)
    rows = []
    for (cid, clause), (n, h) in counts.items():
        mine = table[(table["claim"] == cid) & (table["clause"] == clause)]
        failing = n - h
        scope = SCOPES[1] if (cid, clause) in specific else SCOPES[0]
        for (cls, name), grp in mine.groupby(["class", "cause"], sort=False):
            ex = grp.sort_values("variant").iloc[0]
            cf_name, cf_n, cf_h = cf.get((cid, clause, str(name)), ("", 0, 0))
            rows.append((experiment, cid, clause, h / n if n else math.nan, failing, cls, name,
                         len(grp), len(grp) / failing if failing else math.nan,
                         int(ex["variant"]), ex["config_hash"], ex["evidence"], cf_name,
                         cf_n if cf_name else "", cf_h if cf_name else "",
                         (cf_h / cf_n if cf_n else math.nan) if cf_name else "", scope))
    shares = pd.DataFrame(rows, columns=list(SHARES_COLUMNS))
    if len(shares):
        shares = shares.sort_values(["claim", "clause", "n"], ascending=[True, True, False],
                                    kind="stable")
    shares_path = sweep_dir / "cause_shares.csv"
    shares.to_csv(shares_path, index=False, float_format="%.6g")
    return [causes_path, shares_path]


def counterfactual_variants(sweep_dir: Path, cf: Counterfactual) -> list[dict[str, Any]]:
    """The rows of the sweep's variants.csv (parameters and index) whose failing clauses
    include cause ``cf.removes`` in causes.csv, in variant order."""
    causes_path = Path(sweep_dir) / "causes.csv"
    if not causes_path.is_file():
        raise ReproError(f"{sweep_dir} has no causes.csv: run its sweep (and `repro figures`) "
                         "first")
    causes = pd.read_csv(causes_path, keep_default_na=False)
    wanted = set(causes.loc[causes["cause"] == cf.removes, "variant"].astype(int))
    df = pd.read_csv(Path(sweep_dir) / "variants.csv", dtype={"config_hash": str})
    return [r for r in df.to_dict("records") if int(r["variant"]) in wanted]
