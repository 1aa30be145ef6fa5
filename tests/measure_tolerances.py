"""Measure how far every compared quantity of the short-run references moves under the
perturbations another machine produces, and write each reference's tolerance file.

Run by hand (never in tests or CI), after ``tests/make_reference.py`` or a change that
moves a reference::

    .venv/bin/python tests/measure_tolerances.py               # every reference
    .venv/bin/python tests/measure_tolerances.py --only pomares2011/exp1 --keep /tmp/sens
    .venv/bin/python tests/measure_tolerances.py --only committed   # make test-slow's reruns
    .venv/bin/python tests/measure_tolerances.py --only chan2011/experiment --merge  # add a machine

Each perturbation is a child process that reruns the references and writes their traces at
full precision:

* ``blas:default`` (the kernels OpenBLAS picks itself on this CPU) and ``blas:<family>``:
  ``OPENBLAS_CORETYPE=<family>`` (numpy's OpenBLAS picks other kernels on other CPUs; these
  are the families this machine can run; a forced family is not always the one the same
  name picks by itself);
* ``q0:+1e-12`` / ``q0:-1e-12``: every joint reset (the initial state) moved by 1e-12 rad,
  an envelope for the last-bit differences of a build of pybullet or pinocchio by another
  compiler.

The tolerance file (:mod:`repro.runs.compare`) records, per column, the largest deviation
from the committed reference over all perturbations, which one gave it, and the tolerance
``margin x measured`` (plus the CSV rounding of the reference); columns that move by more
than ``CHAOTIC_FRACTION`` of their own range are chaotic and compared by windowed means.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from references import COMMITTED, REFERENCES, Reference  # noqa: E402

ALL = {**REFERENCES, **COMMITTED}

from repro.runs import compare  # noqa: E402

#: OpenBLAS kernel families that run on an x86-64 CPU with AVX-512 (SkylakeX is the default
#: on AVX-512 machines; Haswell on AVX2 ones and AMD Zen; the older families on older CPUs).
BLAS_FAMILIES = ("SkylakeX", "Haswell", "Sandybridge", "Nehalem", "Prescott")
Q0_EPS = 1e-12  # [rad]
PERTURBATIONS = (("blas:default",) + tuple(f"blas:{f}" for f in BLAS_FAMILIES)
                 + (f"q0:+{Q0_EPS:g}", f"q0:-{Q0_EPS:g}"))


def _apply(perturbation: str) -> None:
    """In the child: perturb joint resets (the BLAS family is set in the environment)."""
    if not perturbation.startswith("q0:"):
        return
    eps = float(perturbation[3:])
    from repro.sim.robot import JointSet

    original = JointSet.reset

    def reset(self: JointSet, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        original(self, np.asarray(q, dtype=float) + eps, qd)

    JointSet.reset = reset  # type: ignore[method-assign]


def child(perturbation: str, out: Path, ids: list[str]) -> None:
    _apply(perturbation)
    out.mkdir(parents=True, exist_ok=True)
    for rid in ids:
        ref = ALL[rid]
        with tempfile.TemporaryDirectory() as d:
            df = ref.make(Path(d))
        df.to_csv(out / f"{rid.replace('/', '__')}.csv", index=False, float_format="%.17g")
        print(perturbation, rid, len(df), flush=True)


def _run_children(ids: list[str], keep: Path) -> dict[str, Path]:
    dirs = {}
    for pert in PERTURBATIONS:
        d = keep / pert.replace(":", "_")
        dirs[pert] = d
        if all((d / f"{rid.replace('/', '__')}.csv").is_file() for rid in ids):
            continue  # resumable: --keep holds what an earlier call measured
        env = dict(os.environ)
        env.pop("OPENBLAS_CORETYPE", None)
        if pert.startswith("blas:") and pert != "blas:default":
            env["OPENBLAS_CORETYPE"] = pert[5:]
        done = subprocess.run([sys.executable, __file__, "--child", pert, "--out", str(d),
                               "--only", *ids], env=env, check=False)
        if done.returncode == -signal.SIGILL:  # a kernel family this CPU cannot run
            print(f"{pert}: not measured here (SIGILL: this CPU lacks its instructions); "
                  "measure on a CPU that has them to keep it in the tolerance", flush=True)
            del dirs[pert]
        elif done.returncode != 0:
            raise subprocess.CalledProcessError(done.returncode, done.args)
    return dirs


def measure(ref: Reference, dirs: dict[str, Path], margin: float) -> dict[str, object]:
    committed = ref.load()
    runs = {pert: pd.read_csv(d / f"{ref.id.replace('/', '__')}.csv")
            for pert, d in dirs.items()}
    return compare.measure_tolerances(committed, runs, margin=margin,
                                      machine=compare.machine_description())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="+", default=sorted(REFERENCES),
                    help="reference ids (default: every short run; committed/<paper>.<name> "
                         "for the committed runs make test-slow reruns)")
    ap.add_argument("--keep", type=Path, help="keep the perturbed traces here (resumable)")
    ap.add_argument("--margin", type=float, default=compare.DEFAULT_MARGIN)
    ap.add_argument("--merge", action="store_true",
                    help="keep what the tolerance file already holds (measured on another "
                         "machine): write the looser of the two rules per column "
                         "(repro.runs.compare.merge_tolerances)")
    ap.add_argument("--child")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    if args.only == ["committed"]:
        args.only = sorted(COMMITTED)
    unknown = sorted(set(args.only) - set(ALL))
    if unknown:
        sys.exit(f"unknown reference(s) {unknown}; valid: {sorted(ALL)} or 'committed'")
    if args.child:
        child(args.child, args.out, args.only)
        return
    with tempfile.TemporaryDirectory() as tmp:
        keep = args.keep or Path(tmp)
        dirs = _run_children(args.only, keep)
        for rid in args.only:
            ref = ALL[rid]
            tol = measure(ref, dirs, args.margin)
            if args.merge and ref.tol_json.is_file():
                tol = compare.merge_tolerances(json.loads(ref.tol_json.read_text()), tol)
            ref.tol_json.parent.mkdir(parents=True, exist_ok=True)
            ref.tol_json.write_text(json.dumps(tol, indent=1, sort_keys=False) + "\n")
            print(compare.summary(rid, tol))


if __name__ == "__main__":
    main()
