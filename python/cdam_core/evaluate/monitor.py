"""The residual monitor: a fitted model beside the measurements, an EWMA and a two-sided CUSUM of
its normalised one-step residual per output channel, and alarms.

Per channel c and row t >= t0 (one-step prediction p(t) from the measured history):

    r = y(t) - p(t)                         float32 (the firmware's rounding)
    z = (r - mean_c) / std_c                the training record's residual statistics
    e = e + lam (z - e)                     EWMA
    s+ = max(0, (s+ + z) - k)               CUSUM, upward
    s- = max(0, (s- - z) - k)               CUSUM, downward
    alarm when s+ > h_c, s- > h_c or |e| > L_c; the channel's three statistics restart at 0

Every operation is float32 in this order, as fw/monitor.hpp does it on the target, so the
decisions agree sample for sample whenever the two predictions (float64 here, float32 there)
round to the same float32 residual's side of a threshold.

Settings (:func:`calibrate`), none tuned to a record:
  - k = 0.5: Page's CUSUM for a shift of one standard deviation of z (the textbook choice,
    k = delta / 2 with delta = 1);
  - lam = 1 - exp(-dt / TAU_S), TAU_S = 0.1 s: the EWMA's time constant a fifth of the
    0.5 s delay the alarm must meet;
  - h_c and L_c by simulation of the training residual's own autocorrelation: z is fitted
    as an AR(p) process (Yule-Walker, p <= MAX_AR_ORDER by AIC), ``paths`` in-control paths of
    WINDOW_S seconds are simulated (numpy's generator, ``seed``; Gaussian innovations), and
    h_c (L_c) is the (1 - FALSE_ALARM_PROB / (3 C)) quantile of the largest CUSUM (|EWMA|)
    over a path, both CUSUM sides pooled: the probability that any of the 3 C statistics
    alarms within WINDOW_S of in-control data is at most FALSE_ALARM_PROB (Bonferroni), so
    the in-control average run length is far above WINDOW_S (about WINDOW_S /
    -ln(1 - FALSE_ALARM_PROB) = 20 WINDOW_S for a geometric run length).
  - a unit quaternion among the outputs (a model's ``unit_quaternion``: the flight kinds'
    qx, qy, qz, qw) has three degrees of freedom, not four: |q| = 1 gives q . dq = 0 to first
    order, so the residual of its largest component q_k (over the training record; qw near
    hover) is -(sum_{i != k} q_i dq_i) / q_k, a combination of the other three, second order
    in the attitude error where q_k is near 1 and with a spread that follows the attitude
    (not the model's error): a heavy-tailed, heteroscedastic channel no stationary threshold
    fits. That component is not watched (``watched`` 0: its thresholds are set as for any
    output, but it never alarms); the three others carry the attitude's residual to first order.
  A model that lacks part of the machine's dynamics is not watched by a stationary monitor.
  Measured on the independent quad generator with a 30 ms rotor lag the model lacks
  (benchmarks/monitor_missing_lag.py): the normalised residual's variance is the same on
  every flight (z std 0.97-1.04), but 53-67 % of the vertical-velocity and rate residual is a
  linear map of the last input increments (the missing lag's error, driven by the
  manoeuvres), and the part below ~1.6 Hz that the EWMA and the CUSUM accumulate differs from
  flight to flight (EWMA std 0.9-1.3 x the training flight's): 5 of 6 clean 60 s flights
  alarm. Thresholds from AR models of the training record's segments (4 of 6), a residual
  corrected by the input increments (5 of 6) or thresholds the largest over four training
  flights (3 of 6) do not change that: the training flights do not show how aggressive the
  next one will be. The lag itself, chosen from the training flight
  (held-out one-step error), removes it (0 of 6; delays of three effects 0.02-0.06 s): the
  remedy is the model, not the monitor.
  Simulation, not Siegmund's approximation: the one-step residual of a 1 kHz record is
  strongly autocorrelated (a smoothed record, a model error that varies slowly), and
  Siegmund's formula assumes independent samples; with an AR(1) coefficient of 0.9 it would
  put h about four times too low.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdam_core.base.checks import as_2d, same_rows

__all__ = ["calibrate", "run_monitor", "watched_channels", "one_step_residuals", "MonitorResult", "K", "TAU_S",
           "WINDOW_S", "FALSE_ALARM_PROB", "MONITOR_VERSION", "CUSUM_UP", "CUSUM_DOWN", "EWMA"]

MONITOR_VERSION = 1
K = 0.5                  # CUSUM reference value (a one-sigma shift)
TAU_S = 0.1              # EWMA time constant, s
WINDOW_S = 60.0          # in-control window without a false alarm, s
FALSE_ALARM_PROB = 0.05  # probability of any false alarm within WINDOW_S, all channels
MAX_AR_ORDER = 20
CUSUM_UP, CUSUM_DOWN, EWMA = 1, 2, 4   # alarm flag bits (also the firmware's)


def one_step_residuals(model, U, Y, segments=None) -> tuple[np.ndarray, np.ndarray]:
    """(R, valid): R = float32(Y) - float32(one-step prediction), float32 (N, m); ``valid``
    (N,) bool marks the rows with a prediction (each segment's rows from t0 on)."""
    from cdam_core.models.protocol import segment_bounds
    U = as_2d(U, "U")
    Y = as_2d(Y, "Y")
    same_rows(U, Y, "U, Y")
    P = np.asarray(model.predict(U, Y, mode="one_step", segments=segments), np.float64)
    P = P.reshape(Y.shape)
    valid = np.zeros(Y.shape[0], bool)
    for a, b in segment_bounds(segments, Y.shape[0]):
        valid[a + int(model.t0):b] = True
    R = Y.astype(np.float32) - P.astype(np.float32)
    return R, valid & np.all(np.isfinite(R), axis=1)


def _ar_fit(z: np.ndarray) -> tuple[np.ndarray, float]:
    """AR(p) coefficients and innovation variance of z (Yule-Walker, p by AIC)."""
    from scipy.linalg import solve_toeplitz
    z = z - z.mean()
    n = z.size
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(z, nfft)
    r = np.fft.irfft(f * np.conj(f), nfft)[:MAX_AR_ORDER + 1] / n
    best = (n * np.log(r[0]), np.zeros(0), float(r[0]))
    for p in range(1, min(MAX_AR_ORDER, n // 10) + 1):
        a = solve_toeplitz(r[:p], r[1:p + 1])
        s2 = float(r[0] - a @ r[1:p + 1])
        if s2 <= 0:
            break
        aic = n * np.log(s2) + 2 * p
        if aic < best[0]:
            best = (aic, a, s2)
    return best[1], best[2]


def _simulated_maxima(a, s2, lam, n, paths, seed, block=4096):
    """Largest CUSUM (both sides pooled) and |EWMA| over each of ``paths`` AR paths of n rows,
    the AR process normalised to unit variance as z is, started from its stationary state."""
    from scipy.signal import lfilter
    rng = np.random.default_rng(seed)
    den = np.r_[1.0, -np.asarray(a)]
    # unit variance: the AR's variance for innovations s2 (from its impulse response)
    imp = lfilter([1.0], den, np.r_[1.0, np.zeros(20000)])
    scale = 1.0 / np.sqrt(s2 * np.sum(imp ** 2))
    burn = 2000 if a.size else 0
    zi = np.zeros((paths, max(a.size, 1)))[:, :a.size] if a.size else None
    up = np.zeros(paths)
    dn = np.zeros(paths)
    ew = np.zeros(paths)
    mc = np.zeros(paths)
    me = np.zeros(paths)
    done = -burn
    while done < n:
        m = min(block, n - done) if done >= 0 else burn
        w = rng.standard_normal((paths, m)) * np.sqrt(s2)
        if a.size:
            x, zi = lfilter([1.0], den, w, axis=1, zi=zi)
        else:
            x = w
        x = x * scale
        if done >= 0:
            for j in range(m):
                zj = x[:, j]
                up = np.maximum(up + zj - K, 0.0)
                dn = np.maximum(dn - zj - K, 0.0)
                ew = ew + lam * (zj - ew)
                np.maximum(mc, np.maximum(up, dn), out=mc)
                np.maximum(me, np.abs(ew), out=me)
        done += m
    return mc, me


def calibrate(model, U, Y, dt: float, segments=None, *, paths: int = 1000, seed: int = 0,
              window_s: float = WINDOW_S, false_alarm_prob: float = FALSE_ALARM_PROB) -> dict:
    """The model file's ``monitor`` section from a training record: residual mean and std per
    channel, k, lam and the thresholds h, L (see the module doc)."""
    dt = float(dt)
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt: must be a positive number of seconds, got {dt}")
    if not 0 < false_alarm_prob < 1:
        raise ValueError(f"false_alarm_prob: must be in (0, 1), got {false_alarm_prob}")
    if int(paths) < 100:
        raise ValueError(f"paths: at least 100 simulated paths, got {paths}")
    R, valid = one_step_residuals(model, U, Y, segments)
    R = R[valid].astype(np.float64)
    if R.shape[0] < 200:
        raise ValueError(f"U, Y: {R.shape[0]} rows with a one-step prediction; the residual "
                         f"statistics need at least 200")
    mean, std = R.mean(axis=0), R.std(axis=0, ddof=1)
    watched = _watched(model, np.asarray(Y, np.float64)[valid], R.shape[1])
    if np.any(~(std > 0)):
        c = int(np.argmin(std))
        raise ValueError(f"Y: output {c} has a constant one-step residual; nothing to monitor")
    lam = 1.0 - np.exp(-dt / TAU_S)
    n = int(round(window_s / dt))
    q = 1.0 - false_alarm_prob / (3 * R.shape[1])
    h, L, orders = [], [], []
    for c in range(R.shape[1]):
        z = (R[:, c] - mean[c]) / std[c]
        a, s2 = _ar_fit(z)
        mc, me = _simulated_maxima(a, s2, lam, n, int(paths), int(seed) + c)
        h.append(float(np.quantile(mc, q)))
        L.append(float(np.quantile(me, q)))
        orders.append(int(a.size))
    return {"version": MONITOR_VERSION, "mean": mean.tolist(), "std": std.tolist(), "k": K,
            "lambda": float(lam), "h": h, "ewma_limit": L, "dt": dt, "window_s": float(window_s),
            "false_alarm_prob": float(false_alarm_prob), "ar_order": orders, "paths": int(paths),
            "seed": int(seed), "training_rows": int(R.shape[0]),
            "watched": [int(w) for w in watched]}


def _watched(model, Y, m: int) -> np.ndarray:
    """Which outputs the monitor watches: all but the largest component (mean |q_i| over the
    training rows Y) of a unit quaternion the model declares (module doc)."""
    watched = np.ones(m, bool)
    quat = getattr(model, "unit_quaternion", None)
    if quat is not None:
        quat = list(quat)
        watched[quat[int(np.argmax(np.mean(np.abs(Y[:, quat]), axis=0)))]] = False
    return watched


def watched_channels(section: dict) -> np.ndarray:
    """The ``watched`` flags of a monitor section (all outputs when it has none: version 1
    files before the field)."""
    w = section.get("watched")
    return np.ones(len(section["mean"]), bool) if w is None else np.asarray(w, bool)


@dataclass
class MonitorResult:
    """Per row (N) and channel (m): the flags (bits CUSUM_UP, CUSUM_DOWN, EWMA; 0 where no
    alarm or no prediction), the normalised residual z, the EWMA and the two CUSUMs (after the
    row's update, before a restart), all float32; ``valid`` rows with a prediction."""

    flags: np.ndarray
    z: np.ndarray
    ewma: np.ndarray
    up: np.ndarray
    down: np.ndarray
    valid: np.ndarray
    alarms: list = field(default_factory=list)   # (row, channel, flags)


def run_monitor(section: dict, R, valid=None, starts=(0,)) -> MonitorResult:
    """Run the monitor of a ``monitor`` section on residuals R (N, m) (float32 arithmetic as on
    the target); an output not ``watched`` never alarms. The state restarts at 0 at each row of ``starts`` (segment starts) and, per
    channel, after each alarm; rows not ``valid`` are skipped."""
    R = np.asarray(R)
    if R.ndim != 2 or R.shape[1] != len(section["mean"]):
        raise ValueError(f"R: expected shape (N, {len(section['mean'])}), got {R.shape}")
    R = R.astype(np.float32)
    n, m = R.shape
    valid = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
    f32 = np.float32
    mean = np.asarray(section["mean"], f32)
    std = np.asarray(section["std"], f32)
    watched = watched_channels(section)
    h = np.asarray(section["h"], f32)
    L = np.asarray(section["ewma_limit"], f32)
    k, lam, zero = f32(section["k"]), f32(section["lambda"]), f32(0)
    out = {name: np.zeros((n, m), f32) for name in ("z", "ewma", "up", "down")}
    flags = np.zeros((n, m), np.uint8)
    e = np.zeros(m, f32)
    up = np.zeros(m, f32)
    dn = np.zeros(m, f32)
    starts = set(int(s) for s in starts)
    alarms = []
    with np.errstate(over="ignore", invalid="ignore"):
        for t in range(n):
            if t in starts:
                e[:], up[:], dn[:] = 0, 0, 0
            if not valid[t]:
                continue
            z = (R[t] - mean) / std
            e = e + lam * (z - e)
            up = np.maximum((up + z) - k, zero)
            dn = np.maximum((dn - z) - k, zero)
            out["z"][t], out["ewma"][t], out["up"][t], out["down"][t] = z, e, up, dn
            fl = (((up > h) * CUSUM_UP + (dn > h) * CUSUM_DOWN
                   + (np.abs(e) > L) * EWMA) * watched).astype(np.uint8)
            if fl.any():
                flags[t] = fl
                for c in np.flatnonzero(fl):
                    alarms.append((t, int(c), int(fl[c])))
                hit = fl > 0
                e[hit], up[hit], dn[hit] = 0, 0, 0
    return MonitorResult(flags, out["z"], out["ewma"], out["up"], out["down"], valid, alarms)
