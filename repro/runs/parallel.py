"""Independent runs in parallel worker processes (``repro results -j N``).

Each run gets a forked worker of its own, which runs it exactly as the serial path does
(the same function, the same SIGINT/SIGTERM handling: an interrupted run closes its trace
and manifest as ``interrupted``), with :data:`repro.runs.trace.CONCURRENT_RUNS_ENV` set so
that its manifest says how many runs shared the machine. The parent starts at most
``workers`` at a time, in the order given, and:

* on SIGINT or SIGTERM starts no new run, passes the signal to every live worker (each
  closes its run as interrupted; a second signal is ignored by a closing worker), waits
  for them and reports the exit code ``128 + signal``;
* marks a worker that died without closing its run (SIGKILL, out of memory) as lost: the
  manifest of its partial run (in the run folder's staging folder,
  :func:`repro.runs.staging.staging_dir`) is rewritten ``interrupted`` ("process gone", rows
  counted) by :func:`repro.runs.trace.mark_if_gone`, a swap it cut short is undone or
  finished (:func:`repro.runs.staging.recover`), and the other runs go on.

A run replaces its folder only when it returns (:mod:`repro.runs.staging`): whatever stops
a worker, the run folder it was remaking is left as it was.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import sys
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import wait
from pathlib import Path
from types import FrameType
from typing import Any, Literal

from repro.runs.staging import recover, staging_dir
from repro.runs.trace import CONCURRENT_RUNS_ENV, mark_if_gone

__all__ = ["Outcome", "run_parallel"]

Status = Literal["ran", "interrupted", "crashed", "lost", "not_started"]
#: Exit code of a worker whose run raised (its manifest says ``crashed``).
CRASHED = 1


@dataclass(frozen=True)
class Outcome:
    """How one run ended: ``index`` into the jobs, its folder, status, exit code."""

    index: int
    out_dir: Path
    status: Status
    exitcode: int | None


def _worker(run: Callable[[int], Path | int], index: int, n_concurrent: int) -> None:
    os.environ[CONCURRENT_RUNS_ENV] = str(n_concurrent)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.default_int_handler if sig == signal.SIGINT
                      else signal.SIG_DFL)
    try:
        result = run(index)
    except BaseException:  # the runner has written its crashed manifest
        traceback.print_exc(file=sys.stderr)
        sys.stderr.flush()
        os._exit(CRASHED)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(result if isinstance(result, int) else 0)


def run_parallel(out_dirs: Sequence[Path], run: Callable[[int], Path | int], workers: int,
                 on_done: Callable[[Outcome], None] | None = None
                 ) -> tuple[list[Outcome], int | None]:
    """Run ``run(i)`` for every ``i`` of ``out_dirs`` in at most ``workers`` processes.

    Args:
        out_dirs: the run folder of each job (for reporting and for marking lost runs: the
            partial run is in its staging folder).
        run: the serial runner of job ``i``: its run folder, or the exit code of an
            interrupted run (``repro.cli._run_interruptible``).
        workers: most runs at once (>= 1).
        on_done: called in the parent as each run ends.

    Returns:
        (outcomes in job order, the signal that stopped the batch or None).
    """
    ctx = mp.get_context("fork")
    n_concurrent = max(1, min(workers, len(out_dirs)))
    fired: list[int] = []
    live: dict[int, Any] = {}  # job index -> Process
    outcomes: dict[int, Outcome] = {}

    def handler(signum: int, frame: FrameType | None) -> None:
        if not fired:
            fired.append(signum)
        for proc in live.values():
            if proc.pid is not None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(proc.pid, signum)

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    pending = list(range(len(out_dirs)))
    try:
        while pending or live:
            while pending and len(live) < n_concurrent and not fired:
                i = pending.pop(0)
                proc = ctx.Process(target=_worker, args=(run, i, n_concurrent), daemon=False)
                proc.start()
                live[i] = proc
            if fired:
                pending.clear()
            if not live:
                break
            wait([p.sentinel for p in live.values()])
            for i, proc in list(live.items()):
                if proc.exitcode is None:
                    continue
                proc.join()
                del live[i]
                outcome = _outcome(i, Path(out_dirs[i]), proc.exitcode)
                outcomes[i] = outcome
                if on_done is not None:
                    on_done(outcome)
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
    for i in range(len(out_dirs)):
        outcomes.setdefault(i, Outcome(i, Path(out_dirs[i]), "not_started", None))
    return [outcomes[i] for i in range(len(out_dirs))], (fired[0] if fired else None)


def _outcome(i: int, out_dir: Path, code: int) -> Outcome:
    if code == 0:
        return Outcome(i, out_dir, "ran", code)
    if code == CRASHED:
        return Outcome(i, out_dir, "crashed", code)
    if code > 128:
        return Outcome(i, out_dir, "interrupted", code)
    # killed outright (code = -signal): the run never closed, maybe not even swapped in
    recover(out_dir)
    mark_if_gone(staging_dir(out_dir))
    return Outcome(i, out_dir, "lost", code)
