"""The progress bar of a run: shown on a terminal (simulated time, real-time factor),
silent otherwise."""

from __future__ import annotations

import io

import pytest

from repro.sim import episode


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("tty", [True, False])
def test_progress_bar_only_on_a_terminal(monkeypatch: pytest.MonkeyPatch, tty: bool) -> None:
    err = _Tty() if tty else io.StringIO()
    monkeypatch.setattr("sys.stderr", err)
    bar = episode._Progress(101, 0.01)
    for k in range(101):
        bar.update(k)
    bar.close()
    text = err.getvalue()
    if tty:
        assert "t = 1.00 s" in text and "real time" in text
    else:
        assert text == ""
