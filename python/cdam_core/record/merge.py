"""One record from two: the flight controller's and the arm controller's, on different clocks.

The clock offset is estimated by cross-correlating one motion both records see (a column
pair). Convention: ``offset`` is what to add to the second record's (joints') clock to get the
first's (flight's): an event at joints time ``t_j`` happened at flight time ``t_j + offset``.

Estimate (``estimate_offset``): both signals are resampled linearly onto uniform grids at one
rate, detrended and standardised; ``scipy.signal.correlate`` (FFT) gives the correlation at each
lag, divided by the shorter record's length (the biased estimate, so that lags with little
overlap are not favoured); the peak of its absolute value (so an
inverted sign is found too; the sign is reported) is refined to a fraction of a sample by a
parabola through the three samples around it. Uncertainty (1 sigma): the overlap is cut into
``n_segments`` pieces, the sub-sample peak is found in each near the global lag, and the
standard error of those estimates (std / sqrt(n)) is combined with the grid's quantisation
(1 / (rate sqrt(12))). Clock drift shows as a trend across segments (``meta["segments"]``).

Significance (``p_value``): is the peak more than two unrelated smooth signals give by chance?
Under the null (independent signals) the correlation r over n overlapping samples of two
autocorrelated series has variance 1/n_eff, with the effective number of samples of Bartlett
(1935) in the form of Pyper and Peterman (1998): 1/n_eff = 1/n + (2/n) sum_{j=1..n/5}
(n-j)/n rho_a(j) rho_b(j), rho the sample autocorrelations. The single-lag p-value is Student's
t with n_eff - 2 degrees of freedom, and the peak is the best of the lags searched: about
lags * n_eff / n of them are independent (one per decorrelation length n / n_eff), so the
reported p-value is Sidak's 1 - (1 - p1)^m over those m. ``merge_records`` refuses an alignment
with p_value > alpha (0.01 by default): the pair does not see one motion, or too little of it.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import signal, stats

from cdam_core.record.dataset import Dataset
from cdam_core.record.resample import check_time, resample, segmented_grid, uniform_grid

# A step between successive samples longer than GAP_PERIODS of the record's median sampling
# period is a gap (a logger dropout, not jitter): no merged sample falls inside it.
GAP_PERIODS = 5.0

__all__ = ["OffsetEstimate", "WeakAlignment", "estimate_offset", "merge_records",
           "ALIGNMENT_ALPHA"]

# significance level under which an alignment is accepted (the chance that unrelated signals
# peak as high is below 1 %); merge_records(force=True) accepts any (cdam merge --force)
ALIGNMENT_ALPHA = 0.01


class WeakAlignment(ValueError):
    """The peak correlation is not significant: the pair does not show one motion."""


@dataclass
class OffsetEstimate:
    """Clock offset (s) to add to the second record's times, with its 1-sigma uncertainty."""

    offset: float
    uncertainty: float
    correlation: float       # biased correlation at the peak (-1..1; sign = sign of the pair)
    rate: float              # grid rate used (Hz)
    segments: list           # per-segment offset estimates (s)
    p_value: float = float("nan")   # chance of so high a peak from unrelated signals (Sidak)
    n_eff: float = float("nan")     # effective independent samples in the overlap at the peak
    lags_searched: int = 0

    def as_dict(self) -> dict:
        return asdict(self)


def _standardise(x: np.ndarray) -> np.ndarray:
    scale = max(1.0, float(np.abs(x).max()))
    x = signal.detrend(x)
    s = x.std()
    if not s > 1e-12 * scale:
        raise ValueError("signal: constant after detrending, nothing to correlate")
    return x / s


def _peak(a: np.ndarray, b: np.ndarray, lag_lo: int, lag_hi: int):
    """Sub-sample lag k (a[j + k] ~ b[j]) maximising |normalised correlation| in [lag_lo, lag_hi]."""
    c = signal.correlate(a, b, mode="full", method="fft")
    lags = signal.correlation_lags(a.size, b.size, mode="full")
    overlap = np.minimum(a.size, lags + b.size) - np.maximum(0, lags)
    sel = (lags >= lag_lo) & (lags <= lag_hi) & (overlap > 0)
    if not np.any(sel):
        raise ValueError("max_lag: no lag with overlapping samples")
    c, lags, overlap = c[sel], lags[sel], overlap[sel]
    # biased estimate (divided by the shorter length, not the overlap): a lag where the
    # records barely overlap cannot win on a few samples' chance agreement
    cn = c / min(a.size, b.size)
    i = int(np.argmax(np.abs(cn)))
    frac = 0.0
    if 0 < i < cn.size - 1:
        y0, y1, y2 = np.abs(cn[i - 1:i + 2])
        den = y0 - 2 * y1 + y2
        if den < 0:
            frac = 0.5 * (y0 - y2) / den
    return lags[i] + frac, float(cn[i])


def _autocorr(x: np.ndarray, m: int) -> np.ndarray:
    """Sample autocorrelation of a zero-mean x at lags 1..m (biased, FFT)."""
    c = signal.correlate(x, x, mode="full", method="fft")[x.size - 1:x.size + m]
    return c[1:] / c[0]


def _significance(a: np.ndarray, b: np.ndarray, k: float, corr: float,
                  n_lags: int) -> tuple[float, float]:
    """(p_value, n_eff) of the peak ``corr`` at lag ``k`` among ``n_lags`` lags searched (see
    the module's docstring)."""
    n = int(min(a.size, int(np.floor(k)) + b.size) - max(0, int(np.ceil(k))))
    n = max(n, 3)
    r = min(abs(corr) * min(a.size, b.size) / n, 1.0)     # the correlation over the overlap
    m = max(1, n // 5)
    j = np.arange(1, m + 1)
    s = float(np.sum((n - j) / n * _autocorr(a, m)[:m] * _autocorr(b, m)[:m]))
    n_eff = float(np.clip(n / (1.0 + 2.0 * s), 3.0, n))
    df = n_eff - 2.0
    if r >= 1.0:
        return 0.0, n_eff
    t = r * np.sqrt(df / (1.0 - r * r))
    p1 = float(2.0 * stats.t.sf(t, df))
    indep = max(1.0, n_lags * n_eff / n)
    return float(-np.expm1(indep * np.log1p(-min(p1, 1.0 - 1e-16)))), n_eff


def estimate_offset(t_a, x_a, t_b, x_b, rate: float | None = None,
                    max_lag: float | None = None, n_segments: int = 8) -> OffsetEstimate:
    """Offset to add to record b's clock to match record a's, from one shared motion.

    Args:
        t_a, x_a: times (s) and samples of the signal in record a (e.g. the flight).
        t_b, x_b: the same motion seen in record b (e.g. the joints).
        rate: grid rate for the correlation (Hz); default the faster of the two median rates.
        max_lag: largest |offset - (t_a[0] - t_b[0])| searched, s; default such that at least
            a quarter of the shorter record overlaps.
        n_segments: pieces of the overlap used for the uncertainty (>= 3).
    """
    t_a, t_b = check_time(t_a, "t_a"), check_time(t_b, "t_b")
    x_a, x_b = np.asarray(x_a, np.float64), np.asarray(x_b, np.float64)
    for name, t, x in (("x_a", t_a, x_a), ("x_b", t_b, x_b)):
        if x.shape != t.shape:
            raise ValueError(f"{name}: expected shape {t.shape}, got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name}: contains NaN or Inf")
    if rate is None:
        rate = 1.0 / min(np.median(np.diff(t_a)), np.median(np.diff(t_b)))
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate: expected a positive rate, got {rate!r}")
    if n_segments < 3:
        raise ValueError(f"n_segments: expected at least 3, got {n_segments}")
    ga = uniform_grid(t_a[0], t_a[-1], rate)
    gb = uniform_grid(t_b[0], t_b[-1], rate)
    if ga.size < 16 or gb.size < 16:
        raise ValueError("t_a, t_b: too short for a correlation (fewer than 16 grid samples)")
    a = _standardise(resample(t_a, x_a, ga))
    b = _standardise(resample(t_b, x_b, gb))
    if max_lag is None:
        lo = -(gb.size - min(ga.size, gb.size) // 4)
        hi = ga.size - min(ga.size, gb.size) // 4
    else:
        if not (np.isfinite(max_lag) and max_lag > 0):
            raise ValueError(f"max_lag: expected a positive duration, got {max_lag!r}")
        lo, hi = -int(np.ceil(max_lag * rate)), int(np.ceil(max_lag * rate))
    k, corr = _peak(a, b, lo, hi)
    n_lags = min(hi, ga.size - 1) - max(lo, -(gb.size - 1)) + 1
    p_value, n_eff = _significance(a, b, k, corr, n_lags)
    base = ga[0] - gb[0]
    offset = base + k / rate
    # segments of b that overlap a at the global lag
    j0 = max(0, -int(np.floor(k)))
    j1 = min(gb.size, ga.size - int(np.ceil(k)))
    seg_len = (j1 - j0) // n_segments
    if seg_len < 16:
        raise ValueError("t_a, t_b: overlap too short to estimate the uncertainty")
    window = max(3, int(0.1 * seg_len))
    segs = []
    for s in range(n_segments):
        js = j0 + s * seg_len
        bs = b[js:js + seg_len]
        # lag relative to this piece: a[js + k + m] ~ bs[m]
        ks, _ = _peak(a, bs, js + int(round(k)) - window, js + int(round(k)) + window)
        segs.append(base + (ks - js) / rate)
    segs = np.asarray(segs)
    se = float(np.std(segs, ddof=1) / np.sqrt(segs.size))
    unc = float(np.hypot(se, 1.0 / (rate * np.sqrt(12.0))))
    return OffsetEstimate(float(offset), unc, corr, float(rate), segs.tolist(), p_value, n_eff,
                          int(n_lags))


def _gaps(t: np.ndarray, which: str) -> list[dict]:
    """Steps of ``t`` longer than GAP_PERIODS median sampling periods, in flight time."""
    d = np.diff(t)
    if d.size == 0:
        return []
    limit = GAP_PERIODS * float(np.median(d))
    return [{"record": which, "start": float(t[i]), "end": float(t[i + 1])}
            for i in np.flatnonzero(d > limit)]


def _without(start: float, stop: float, gaps: list) -> list[tuple[float, float]]:
    """[start, stop] minus the open gap intervals, as (start, stop) pieces."""
    pieces, a = [], start
    for g in sorted(gaps, key=lambda g: g["start"]):
        if g["end"] <= a or g["start"] >= stop:
            continue
        if g["start"] > a:
            pieces.append((a, g["start"]))
        a = max(a, g["end"])
    if a < stop:
        pieces.append((a, stop))
    return pieces


def merge_records(flight: Dataset, joints: Dataset, pair: tuple[str, str] | None = None,
                  rate: float | None = None, max_lag: float | None = None,
                  alpha: float = ALIGNMENT_ALPHA, force: bool = False
                  ) -> tuple[Dataset, OffsetEstimate]:
    """Align ``joints`` to ``flight``'s clock and resample both onto one grid.

    Args:
        pair: (flight column, joints column) seeing one motion; default the first column name
            the two records share.
        rate: output rate (Hz); default the flight's rate.
        max_lag: search range for the offset (s), see estimate_offset.
        alpha: refuse (WeakAlignment) an offset whose peak correlation has a p-value above
            this (see the module's docstring).
        force: accept it anyway, marked ``meta["clock_offset"]["significant"] = False``.

    Columns of ``joints`` whose names are already in ``flight`` get the suffix ``_joints``.
    Each column is resampled as its record's ``meta["interpolation"]`` says (default linear).
    A gap in either record (a step longer than GAP_PERIODS sampling periods) stays a gap: no
    merged sample falls inside it (``t`` jumps over it); ``meta["gapless_rows"]`` lists the row
    ranges between gaps (also ``meta["segments"]``, so no model predicts across a gap),
    ``meta["gaps"]`` the gaps and ``meta["gap_samples"]`` the samples left out.
    """
    if not isinstance(flight, Dataset) or not isinstance(joints, Dataset):
        raise ValueError("flight, joints: expected Dataset objects")
    if pair is None:
        common = [c for c in flight.columns if c in joints.columns]
        if not common:
            raise ValueError("pair: the records share no column name; name a pair seeing one "
                             "motion (--pair FLIGHT_COL:JOINT_COL)")
        pair = (common[0], common[0])
    fa, jb = pair
    xa, xb = flight.column(fa), joints.column(jb)   # ValueError names an unknown column
    if not 0 < alpha < 1:
        raise ValueError(f"alpha: expected a significance level in (0, 1), got {alpha!r}")
    est = estimate_offset(flight.t, xa, joints.t, xb, max_lag=max_lag)
    significant = est.p_value <= alpha
    if not (significant or force):
        raise WeakAlignment(
            f"pair {fa}:{jb}: peak correlation {est.correlation:+.3f} at offset "
            f"{est.offset:.6f} s is not significant (p = {est.p_value:.2g} > {alpha:g}; "
            f"{est.n_eff:.0f} effective samples, {est.lags_searched} lags searched): the pair "
            "does not show one motion; name another --pair, or --force to merge anyway")
    rate = float(rate or flight.rate)
    tj = joints.t + est.offset
    start, stop = max(flight.t[0], tj[0]), min(flight.t[-1], tj[-1])
    if stop <= start:
        raise ValueError("records do not overlap after alignment "
                         f"(offset {est.offset:.6f} s)")
    gaps = _gaps(flight.t, "flight") + _gaps(tj, "joints")
    grid, rows = segmented_grid(_without(start, stop, gaps), rate, start)
    if not rows:
        raise ValueError("records: no stretch of their overlap is free of gaps")
    full = uniform_grid(start, stop, rate).size
    cols, data, units, interp = [], [], {}, {}
    for ds, t, rename in ((flight, flight.t, False), (joints, tj, True)):
        kinds = ds.meta.get("interpolation") or {}
        for c in ds.columns:
            name = f"{c}_joints" if rename and c in flight.columns else c
            kind = kinds.get(c, "linear")
            cols.append(name)
            data.append(resample(t, ds.column(c), grid, kind))
            interp[name] = kind
            if c in ds.units:
                units[name] = ds.units[c]
    rn = {c: (f"{c}_joints" if c in flight.columns else c) for c in joints.columns}
    meta = {
        "source": {"flight": flight.meta.get("source"), "joints": joints.meta.get("source")},
        "rate": rate,
        "clock_offset": {**est.as_dict(), "pair": [fa, jb], "significant": bool(significant),
                         "meaning": "joints time + offset = flight time"},
        "units": units,
        "interpolation": interp,
        "inputs": flight.inputs + [rn[c] for c in joints.inputs],
        "outputs": flight.outputs + [rn[c] for c in joints.outputs],
        "gaps": gaps,
        "gapless_rows": [list(r) for r in rows],
        "gap_samples": int(full - grid.size),
    }
    if len(rows) > 1:                       # no model predicts across a gap
        meta["segments"] = [list(r) for r in rows]
    return Dataset(t=grid, columns=cols, data=np.column_stack(data), meta=meta), est
