"""SIGINT / SIGTERM during a run: stop between steps, never inside native code or a write.

:func:`stop_on_signals` (used by ``repro run`` and each run of ``repro results``) installs a
handler that turns the first SIGINT or SIGTERM into ``KeyboardInterrupt(<signal name>)``,
which the runner catches to close its trace and manifest as ``interrupted``. Two places
must not be interrupted: native solvers (a KeyboardInterrupt raised inside a CasADi call is
swallowed or turned into ``SystemError: DM.__array__ returned a result with an exception
set``) and the manifest writes (a signal between writing the temporary file and renaming
it left no manifest.json, or a ``running`` one after the last row). Code wraps them in
:func:`deferred`: a signal that arrives inside is held and raised when the outermost such
block ends. Later signals, while the run unwinds and closes, are recorded and ignored.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator
from types import FrameType

__all__ = ["STOP_SIGNALS", "StepGuard", "deferred", "stop_on_signals"]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

_fired: list[int] = []  # signals received while a handler of this module was installed
_depth = [0]  # nesting of deferred() blocks
_pending: list[int] = []  # the first signal, held until the outermost deferred() ends
_active = [0]  # nesting of stop_on_signals()


def _raise(signum: int) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _handler(signum: int, frame: FrameType | None) -> None:
    first = not _fired
    _fired.append(signum)
    if not first:
        return  # the run is already stopping: let it close whole
    if _depth[0] > 0:
        _pending.append(signum)
        return
    _raise(signum)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold SIGINT / SIGTERM (as :func:`stop_on_signals` handles them) until the block ends,
    then raise the held one. Outside :func:`stop_on_signals` it changes nothing."""
    _depth[0] += 1
    try:
        yield
    finally:
        _depth[0] -= 1
        if _depth[0] == 0 and _pending:
            signum = _pending.pop()
            _pending.clear()
            _raise(signum)


class StepGuard:
    """Signals held through each step of a loop and raised between steps.

    ``step()`` at the top of every iteration raises a signal held during the previous step,
    then holds again; ``close()`` after the loop raises one held during the last step (pass
    ``raise_pending=False`` when an exception is already propagating). A simulation loop
    whose steps call CasADi, PyBullet or a QP solver is thus stopped only between steps."""

    def __init__(self) -> None:
        self._holding = False

    def _release(self, raise_pending: bool) -> None:
        if not self._holding:
            return
        self._holding = False
        _depth[0] -= 1
        if _depth[0] == 0 and _pending:
            signum = _pending.pop()
            _pending.clear()
            if raise_pending:
                _raise(signum)

    def step(self) -> None:
        self._release(True)
        _depth[0] += 1
        self._holding = True

    def close(self, raise_pending: bool = True) -> None:
        self._release(raise_pending)


@contextlib.contextmanager
def stop_on_signals(fired: list[int]) -> Iterator[None]:
    """While active, the first SIGINT or SIGTERM raises ``KeyboardInterrupt`` (held inside
    :func:`deferred` blocks) and every signal received is appended to ``fired``; later ones
    are ignored, so the trace and manifest are closed whole."""
    if _active[0] == 0:
        _fired.clear()
        _pending.clear()
    _active[0] += 1
    previous = {sig: signal.signal(sig, _handler) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        fired.extend(_fired)
        _active[0] -= 1
        if _active[0] == 0 and _fired:
            # signals that come once the run is closed (a second Ctrl-C while the one-line
            # report is printed) must not kill the process either: keep ignoring them
            for sig in STOP_SIGNALS:
                signal.signal(sig, signal.SIG_IGN)
        else:
            for sig, old in previous.items():
                signal.signal(sig, old)
