"""Resampling of irregular logged signals onto one uniform grid.

Three kinds of signal, one interpolation each:
- ``"linear"``: continuous measured signals (position, speed, current): linear interpolation
  (``numpy.interp``).
- ``"hold"``: setpoints and commands, which are piecewise constant between updates: zero-order
  hold, the last value at or before each grid time (``scipy.interpolate.interp1d``,
  ``kind="previous"``).
- ``"angle"``: angles that may wrap at +-pi: unwrapped (``numpy.unwrap``) then linear; the
  result stays unwrapped (continuous), which is what identification wants.

The grid covers only the span where every signal has data (no extrapolation). Every grid is
sized by ``grid_size``, which refuses more than MAX_GRID_SAMPLES samples (GridTooLarge): a grid
derived from data (one timestamp far from the rest, a tiny step) must not exhaust memory.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
from scipy.interpolate import interp1d

__all__ = ["KINDS", "MAX_GRID_SAMPLES", "GridTooLarge", "grid_size", "uniform_grid",
           "segmented_grid", "resample", "find_gaps", "check_time"]

KINDS = ("linear", "hold", "angle")

# Largest grid any resampling builds: 10 million samples is 2.8 h at 1 kHz, 80 MB per float64
# column, about 1 GB for a 12-column record in memory and 2 GB of CSV text; a larger grid comes
# from a bad timestamp or rate far more often than from a real record (split it instead).
MAX_GRID_SAMPLES = 10_000_000


class GridTooLarge(ValueError):
    """A resampling grid above MAX_GRID_SAMPLES samples."""


def grid_size(start: float, stop: float, rate: float) -> int:
    """Samples of the grid start, start + 1/rate, ... <= stop; GridTooLarge above the limit."""
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate: expected a positive finite rate in Hz, got {rate!r}")
    if not (np.isfinite(start) and np.isfinite(stop)) or stop <= start:
        raise ValueError(f"start, stop: empty or invalid span [{start!r}, {stop!r}]")
    n = float(np.floor((stop - start) * rate + 1e-9)) + 1
    if not n <= MAX_GRID_SAMPLES:
        raise GridTooLarge(
            f"rate: {stop - start:.6g} s at {rate:g} Hz is {n:.4g} samples, above the limit of "
            f"{MAX_GRID_SAMPLES:,} (MAX_GRID_SAMPLES); check the timestamps or lower the rate")
    return int(n)


def check_time(t, name: str = "t") -> np.ndarray:
    """t as a float64 1-D array, finite, at least 2 samples, strictly increasing."""
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"{name}: expected a 1-D array of at least 2 times, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name}: contains NaN or Inf")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise ValueError(f"{name}: not strictly increasing at sample {int(bad[0]) + 1}")
    return t


def uniform_grid(start: float, stop: float, rate: float) -> np.ndarray:
    """Times start, start + 1/rate, ... <= stop (computed as start + k / rate, no drift)."""
    return start + np.arange(grid_size(start, stop, rate)) / rate


def segmented_grid(intervals, rate: float, origin: float) -> tuple[np.ndarray, list]:
    """Grid times origin + k / rate inside each (start, stop) interval, none between them.

    Returns (grid, [(first row, end row) per interval with at least 2 samples]). The total is
    bounded by MAX_GRID_SAMPLES like every grid.
    """
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate: expected a positive finite rate in Hz, got {rate!r}")
    ks = []
    for s, e in intervals:
        k0 = int(np.ceil((s - origin) * rate))
        k0 += origin + k0 / rate < s                      # grid times exactly inside [s, e]
        k0 -= k0 > 0 and origin + (k0 - 1) / rate >= s
        k1 = int(np.floor((e - origin) * rate))
        k1 -= origin + k1 / rate > e
        k1 += origin + (k1 + 1) / rate <= e
        if k1 > k0:
            ks.append((k0, k1))
    total = sum(k1 - k0 + 1 for k0, k1 in ks)
    if total > MAX_GRID_SAMPLES:
        raise GridTooLarge(f"rate: {total:,} samples at {rate:g} Hz, above the limit of "
                           f"{MAX_GRID_SAMPLES:,} (MAX_GRID_SAMPLES)")
    parts, rows, r = [], [], 0
    for k0, k1 in ks:
        parts.append(origin + np.arange(k0, k1 + 1) / rate)
        rows.append((r, r + k1 - k0 + 1))
        r += k1 - k0 + 1
    return (np.concatenate(parts) if parts else np.empty(0)), rows


def resample(t, x, grid, kind: str = "linear") -> np.ndarray:
    """Resample samples ``x`` (N,) or (N, C) taken at ``t`` (N,) onto ``grid`` (M,).

    ``kind`` is one of KINDS. Grid times outside [t[0], t[-1]] are an error (no extrapolation).
    """
    t = check_time(t)
    x = np.asarray(x, dtype=np.float64)
    squeeze = x.ndim == 1
    x2 = x[:, None] if squeeze else x
    if x2.ndim != 2 or x2.shape[0] != t.size:
        raise ValueError(f"x: expected {t.size} samples (rows), got shape {x.shape}")
    if not np.all(np.isfinite(x2)):
        raise ValueError("x: contains NaN or Inf")
    grid = np.asarray(grid, dtype=np.float64)
    if grid.ndim != 1 or grid.size == 0 or not np.all(np.isfinite(grid)):
        raise ValueError("grid: expected a non-empty finite 1-D array")
    if grid[0] < t[0] - 1e-12 or grid[-1] > t[-1] + 1e-12:
        raise ValueError(f"grid: [{grid[0]}, {grid[-1]}] outside the data span [{t[0]}, {t[-1]}]")
    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")
    g = np.clip(grid, t[0], t[-1])
    if kind == "hold":
        out = interp1d(t, x2, kind="previous", axis=0, assume_sorted=True)(g)
    else:
        src = np.unwrap(x2, axis=0) if kind == "angle" else x2
        out = np.column_stack([np.interp(g, t, src[:, j]) for j in range(src.shape[1])])
    return out[:, 0] if squeeze else out


def find_gaps(t, threshold: float) -> list[dict]:
    """Intervals between successive samples longer than ``threshold`` seconds.

    Returns a list of ``{"start": s, "end": s, "duration": s}`` (JSON-ready).
    """
    t = check_time(t)
    if not (np.isfinite(threshold) and threshold > 0):
        raise ValueError(f"threshold: expected a positive duration, got {threshold!r}")
    d = np.diff(t)
    idx = np.flatnonzero(d > threshold)
    return [{"start": float(t[i]), "end": float(t[i + 1]), "duration": float(d[i])} for i in idx]


def resample_signals(signals: Mapping[str, tuple], rate: float,
                     span: Sequence[float] | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Resample several named signals onto one grid at ``rate`` Hz.

    Args:
        signals: name -> (t, x, kind) with x of shape (N,).
        rate: grid rate in Hz.
        span: (start, stop) of the grid; default the intersection of all signals' spans.

    Returns:
        (grid, {name: resampled}).
    """
    if not signals:
        raise ValueError("signals: nothing to resample")
    starts = [float(np.asarray(v[0])[0]) for v in signals.values()]
    stops = [float(np.asarray(v[0])[-1]) for v in signals.values()]
    start, stop = (max(starts), min(stops)) if span is None else span
    if stop <= start:
        raise ValueError(f"signals: the signals' time spans do not overlap "
                         f"(latest start {start}, earliest end {stop})")
    grid = uniform_grid(start, stop, rate)
    return grid, {name: resample(t, x, grid, kind) for name, (t, x, kind) in signals.items()}


__all__.append("resample_signals")
