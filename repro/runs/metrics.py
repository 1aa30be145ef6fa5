"""Trace metrics shared by claims and figures (plain functions of arrays).

Every function takes the time column ``t`` [s] and signals as NumPy arrays read
from trace files; nothing here touches a simulator.
"""

from __future__ import annotations

import numpy as np


def sign_changes_per_second(t: np.ndarray, x: np.ndarray, deadband: float) -> float:
    """Sign changes of ``x`` per second, ignoring samples with |x| <= deadband.

    A measure of oscillation (chattering) of a velocity signal: a smooth
    convergence changes sign a few times at most, an oscillating one at every
    half period.
    """
    x = np.asarray(x, dtype=float)
    keep = np.abs(x) > deadband
    s = np.sign(x[keep])
    if s.size < 2 or t[-1] <= t[0]:
        return 0.0
    return float(np.count_nonzero(np.diff(s) != 0) / (t[-1] - t[0]))


def high_frequency_fraction(x: np.ndarray, dt: float, cutoff_hz: float) -> float:
    """Fraction of the signal's (mean-removed) spectral energy above ``cutoff_hz`` [Hz]."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size < 4:
        return 0.0
    spec = np.abs(np.fft.rfft(x - x.mean())) ** 2
    freq = np.fft.rfftfreq(x.size, dt)
    total = spec.sum()
    return float(spec[freq > cutoff_hz].sum() / total) if total > 0 else 0.0


def high_frequency_rms(x: np.ndarray, dt: float, cutoff_hz: float) -> float:
    """RMS [units of x] of the part of the (mean-removed) signal above ``cutoff_hz`` [Hz]:
    the amplitude of an oscillation, where :func:`high_frequency_fraction` is its share.
    Parseval on the one-sided spectrum of the finite samples."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    n = x.size
    if n < 4:
        return 0.0
    X = np.fft.rfft(x - x.mean())
    freq = np.fft.rfftfreq(n, dt)
    keep = freq > cutoff_hz
    w = np.where((freq == 0) | ((n % 2 == 0) & (freq == freq[-1])), 1.0, 2.0)
    return float(np.sqrt(np.sum(w[keep] * np.abs(X[keep]) ** 2)) / n)


def first_time_below(t: np.ndarray, x: np.ndarray, level: float) -> float:
    """First time [s] at which ``x <= level`` (NaN if never)."""
    idx = np.flatnonzero(np.asarray(x) <= level)
    return float(t[idx[0]]) if idx.size else float("nan")


def contact_episodes(t: np.ndarray, x: np.ndarray, level: float, min_gap: float) -> list[float]:
    """Start times [s] of episodes where ``x <= level``; episodes closer than
    ``min_gap`` [s] are merged."""
    below = np.asarray(x) <= level
    starts: list[float] = []
    last_end = -np.inf
    in_ep = False
    for ti, b in zip(t, below, strict=True):
        if b and not in_ep:
            if ti - last_end > min_gap:
                starts.append(float(ti))
            in_ep = True
        elif not b and in_ep:
            in_ep = False
            last_end = float(ti)
    return starts
