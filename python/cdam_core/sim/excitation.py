"""Operator-like excitation, seedable per channel: steps, chirps and multisines.

Each generator takes the time vector ``t`` (s, 1-D, strictly increasing) and returns an array
of the same length. Randomness comes from a ``numpy.random.Generator`` the caller seeds, so the
same seed gives the same signal. ``scipy.signal.chirp`` makes the sweeps.
"""
from __future__ import annotations

import numpy as np
from scipy.signal import chirp

__all__ = ["steps", "chirp_sweep", "multisine", "fade_in", "experiment_setpoints", "CHANNELS"]

CHANNELS = ("X", "Y", "Z", "phi", "theta", "psi", "q1", "q2")


def _check_t(t) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError("t: expected a 1-D array of at least 2 samples")
    if not np.all(np.isfinite(t)):
        raise ValueError("t: contains NaN or Inf")
    if np.any(np.diff(t) <= 0):
        raise ValueError("t: not strictly increasing")
    return t


def _check_amp(a: float) -> float:
    a = float(a)
    if not np.isfinite(a) or a < 0:
        raise ValueError(f"amplitude: must be finite and >= 0, got {a}")
    return a


def steps(t, rng: np.random.Generator, amplitude: float, min_hold: float = 1.0,
          max_hold: float = 3.0) -> np.ndarray:
    """Piecewise-constant levels uniform in [-amplitude, amplitude], each held for a time
    uniform in [min_hold, max_hold] s (draw order: hold, level, per segment)."""
    t = _check_t(t)
    amplitude = _check_amp(amplitude)
    if not 0 < min_hold <= max_hold:
        raise ValueError("min_hold: need 0 < min_hold <= max_hold")
    out = np.zeros_like(t)
    start = t[0]
    while start <= t[-1]:
        hold = rng.uniform(min_hold, max_hold)
        level = rng.uniform(-amplitude, amplitude)
        out[(t >= start) & (t < start + hold)] = level
        start += hold
    return out


def chirp_sweep(t, amplitude: float, f0: float = 0.1, f1: float = 2.0,
                method: str = "logarithmic") -> np.ndarray:
    """A sine sweep from f0 to f1 Hz over the record (scipy.signal.chirp)."""
    t = _check_t(t)
    amplitude = _check_amp(amplitude)
    if not (f0 > 0 and f1 > 0):
        raise ValueError("f0: frequencies must be positive")
    tt = t - t[0]
    return amplitude * chirp(tt, f0=f0, t1=tt[-1], f1=f1, method=method, phi=-90.0)


def multisine(t, rng: np.random.Generator, amplitude: float, f_min: float = 0.1,
              f_max: float = 2.0, n_tones: int = 6) -> np.ndarray:
    """Sum of ``n_tones`` sines at log-spaced frequencies in [f_min, f_max] Hz with random
    phases (Schroeder-like crest control is not attempted), scaled to peak ``amplitude``."""
    t = _check_t(t)
    amplitude = _check_amp(amplitude)
    if n_tones < 1:
        raise ValueError("n_tones: must be at least 1")
    if not 0 < f_min <= f_max:
        raise ValueError("f_min: need 0 < f_min <= f_max")
    freqs = np.geomspace(f_min, f_max, n_tones)
    phases = rng.uniform(0, 2 * np.pi, n_tones)
    y = np.sin(2 * np.pi * np.outer(t - t[0], freqs) + phases).sum(axis=1)
    peak = np.max(np.abs(y))
    return amplitude * y / peak if peak > 0 else y


def fade_in(t, signal, t_on: float = 1.0, ramp: float = 0.5) -> np.ndarray:
    """Zero before ``t_on`` s, a raised-cosine ramp over ``ramp`` s, then ``signal``."""
    t = _check_t(t)
    s = (t - t[0] - t_on) / ramp
    w = np.where(s <= 0, 0.0, np.where(s >= 1, 1.0, 0.5 - 0.5 * np.cos(np.pi * np.clip(s, 0, 1))))
    return w * np.asarray(signal, dtype=float)


# per channel: (steps amplitude, chirp amplitude, multisine amplitude, f_max Hz)
_OPERATOR = {
    "phi": (0.05, 0.04, 0.06, 1.5),
    "theta": (0.05, 0.04, 0.06, 1.5),
    "psi": (0.30, 0.08, 0.08, 0.8),
    "Z": (0.20, 0.05, 0.08, 0.6),
    "q1": (0.30, 0.10, 0.15, 1.5),
    "q2": (0.35, 0.10, 0.15, 2.0),
}


def experiment_setpoints(experiment: str, t, rng: np.random.Generator,
                         altitude: float = 1.0) -> np.ndarray:
    """Setpoints (N, 8) in the order of :data:`CHANNELS` for experiment ``"i"`` (arm held at
    rest; roll, pitch, yaw and altitude excited), ``"ii"`` (hovering; both joints excited) or
    ``"both"`` (all at once). Each excited channel is steps + a chirp + a multisine, faded in
    after 1 s; channels are drawn in the order phi, theta, psi, Z, q1, q2."""
    if experiment not in ("i", "ii", "both"):
        raise ValueError(f"experiment: expected 'i', 'ii' or 'both', got {experiment!r}")
    t = _check_t(t)
    sp = np.zeros((t.size, len(CHANNELS)))
    sp[:, 2] = altitude
    excited = {"i": ("phi", "theta", "psi", "Z"), "ii": ("q1", "q2"),
               "both": ("phi", "theta", "psi", "Z", "q1", "q2")}[experiment]
    for name in ("phi", "theta", "psi", "Z", "q1", "q2"):
        if name not in excited:
            continue
        a_st, a_ch, a_ms, fmax = _OPERATOR[name]
        sig = (steps(t, rng, a_st) + chirp_sweep(t, a_ch, 0.1, fmax)
               + multisine(t, rng, a_ms, 0.1, fmax))
        sp[:, CHANNELS.index(name)] += fade_in(t, sig)
    return sp
