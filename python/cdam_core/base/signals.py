"""Input checks shared by the residual package (ValueError naming the argument and the problem)."""
from __future__ import annotations

import numpy as np


def as_signal(x, name: str, n: int | None = None) -> np.ndarray:
    """A finite 1-D float64 array, optionally of length ``n``."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not numeric ({exc})") from None
    if a.ndim == 2 and 1 in a.shape:
        a = a.ravel()
    if a.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D signal, got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"{name}: empty")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or Inf")
    if n is not None and a.size != n:
        raise ValueError(f"{name}: has {a.size} samples, expected {n}")
    return a


def as_time(t, name: str = "t", min_len: int = 3) -> np.ndarray:
    """A finite, strictly increasing, uniformly sampled time vector (1 % jitter allowed)."""
    a = as_signal(t, name)
    if a.size < min_len:
        raise ValueError(f"{name}: needs at least {min_len} samples, got {a.size}")
    d = np.diff(a)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0))
        raise ValueError(f"{name}: not strictly increasing at sample {k + 1}")
    if np.ptp(d) > 0.01 * np.median(d):
        raise ValueError(f"{name}: not uniformly sampled (step varies from {d.min():g} to {d.max():g} s)")
    return a


def positive(x, name: str) -> float:
    v = float(x)
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name}: must be a positive finite number, got {x!r}")
    return v
