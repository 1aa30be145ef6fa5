"""Measure how far every claim clause's figure moves when the canonical runs are remade under
the perturbations another machine produces, and write ``results/clause_variation.csv``.

Run by hand (never in tests or CI), after the committed runs are remade::

    .venv/bin/python tests/measure_clause_variation.py                    # every canonical run
    .venv/bin/python tests/measure_clause_variation.py --runs thomas2024.case1 --keep /tmp/cv

Each perturbation (see ``tests/measure_tolerances.py``: ``q0:+-1e-12`` moves every joint
reset by 1e-12 rad, ``blas:<family>`` forces numpy's OpenBLAS kernels) is a child process
that remakes the listed runs with their default configs into ``<keep>/<perturbation>/``;
the runs not remade are linked from ``results/``. Every claim is then judged on each
perturbed results folder, and each clause's figure is compared with the committed one.

``results/clause_variation.csv`` (one row per clause): the committed figure, the smallest and
largest figure over the committed run and the perturbed ones, how many perturbations, which,
and whether the verdict differs among them (``flips``). ``repro figures`` reads it: a clause
whose verdict flips within that variation is ``marginal`` in claims.csv and REPORT.md.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from measure_tolerances import _apply  # noqa: E402

from repro.runs import compare  # noqa: E402
from repro.runs.claims import VARIATION_COLUMNS, VARIATION_FILE, evaluate_claims  # noqa: E402
from repro.runs.registry import all_experiments, find_experiment, load_papers  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
#: ours: two initial-state perturbations (a build of pybullet or pinocchio by another
#: compiler) and one kernel family other than this CPU's own (another CPU's numpy)
PERTURBATIONS = ("q0:+1e-12", "q0:-1e-12", "blas:Sandybridge")


def child(perturbation: str, out: Path, ids: list[str]) -> None:
    """Remake ``ids`` with their default configs into ``out/<paper>/<name>``."""
    _apply(perturbation)
    papers = load_papers()
    for exp_id in ids:
        exp = find_experiment(papers, exp_id)
        d = out / exp.paper / exp.name
        if (d / "manifest.json").is_file():
            continue  # resumable
        tmp = d.with_name(d.name + ".partial")
        exp.run(exp.config_cls(), tmp, experiment=exp.name)
        tmp.rename(d)
        print(perturbation, exp_id, flush=True)


def _link_missing(results: Path, out: Path) -> None:
    """Link every committed run that was not remade into the perturbed folder."""
    for paper in sorted(p for p in results.iterdir() if p.is_dir()):
        for run in sorted(r for r in paper.iterdir() if (r / "manifest.json").is_file()):
            dst = out / paper.name / run.name
            if not dst.exists():
                dst.parent.mkdir(parents=True, exist_ok=True)
                dst.symlink_to(run.resolve(), target_is_directory=True)


def _clauses(results: Path) -> pd.DataFrame:
    papers = load_papers()
    claims = [c for p in papers.values() if p.claims is not None for c in p.claims()]
    rows: list[dict[str, object]] = []
    evaluate_claims(claims, results, papers, clauses_out=rows)
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", nargs="+", help="paper.experiment ids (default: every one)")
    ap.add_argument("--keep", type=Path, help="keep the perturbed runs here (resumable)")
    ap.add_argument("--results", type=Path, default=ROOT / "results")
    ap.add_argument("-j", "--jobs", type=int, default=os.cpu_count() or 1,
                    help="perturbations remade at once")
    ap.add_argument("--child")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    ids = args.runs or [e.id for e in all_experiments(load_papers())]
    if args.child:
        child(args.child, args.out, ids)
        return
    with tempfile.TemporaryDirectory() as tmp:
        keep = args.keep or Path(tmp)
        procs = {}
        pending = list(PERTURBATIONS)
        done: list[str] = []
        while pending or procs:
            while pending and len(procs) < args.jobs:
                pert = pending.pop(0)
                env = dict(os.environ)
                env.pop("OPENBLAS_CORETYPE", None)
                if pert.startswith("blas:"):
                    env["OPENBLAS_CORETYPE"] = pert[5:]
                out = keep / pert.replace(":", "_")
                procs[pert] = subprocess.Popen(
                    [sys.executable, __file__, "--child", pert, "--out", str(out), "--runs",
                     *ids], env=env)
            for pert, proc in list(procs.items()):
                code = proc.poll()
                if code is None:
                    continue
                del procs[pert]
                if code == -signal.SIGILL:
                    print(f"{pert}: not measured here (SIGILL)", flush=True)
                elif code != 0:
                    raise SystemExit(f"{pert}: child failed with code {code}")
                else:
                    done.append(pert)
            if procs:
                import time

                time.sleep(2.0)
        base = _clauses(args.results)
        key = ["paper", "claim", "clause"]
        figures = {"committed": base.set_index(key)}
        for pert in done:
            out = keep / pert.replace(":", "_")
            _link_missing(args.results, out)
            figures[pert] = _clauses(out).set_index(key)
        rows = []
        for k, row in figures["committed"].iterrows():
            vals = {name: f.loc[k] for name, f in figures.items() if k in f.index}
            measured = [float(v["measured"]) for v in vals.values()]
            holds = {bool(v["holds"]) for v in vals.values()}
            rows.append({**dict(zip(key, k, strict=True)), "committed": float(row["measured"]),
                         "min": min(measured), "max": max(measured),
                         "n_perturbations": len(vals) - 1,
                         "perturbations": " ".join(n for n in vals if n != "committed"),
                         "flips": len(holds) > 1, "runs_remade": " ".join(ids),
                         "machine": compare.machine_description()})
        table = pd.DataFrame(rows, columns=list(VARIATION_COLUMNS))
        path = args.results / VARIATION_FILE
        table.to_csv(path, index=False, float_format="%.10g")
        print(f"wrote {path}: {int(table['flips'].sum())} of {len(table)} clauses flip")


if __name__ == "__main__":
    main()
