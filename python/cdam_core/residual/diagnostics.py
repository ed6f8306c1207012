"""Residual diagnostics: autocorrelation with the 99 % band, residual-input cross-correlation
(as MATLAB ``resid``), the Ljung-Box test, the residual spectrum and its peaks, and the
effective sample size that makes F-tests honest on autocorrelated residuals.

The autocorrelation is statsmodels' ``acf(x, nlags, fft=True)`` written out (``_acf``: the same
operations in the same order, equal to it bit for bit; tests/residual/test_acf_twin.py), so a
``cdam residual`` run does not import statsmodels (with pandas, about 0.7 s of its start-up,
[speed] 23 item 3); statsmodels is imported only where it is still used: the Ljung-Box test of
records up to 2,000 samples and the flexible joint's identifiability regression.
"""
from __future__ import annotations

import numpy as np
from scipy import optimize
from scipy import signal as sps
from scipy import stats
from scipy.stats import chi2

from cdam_core.base.signals import as_signal, positive

Z99 = 2.58  # two-sided 99 % normal quantile, as MATLAB resid's band


def _next_regular(target: int) -> int:
    """The smallest 5-smooth number >= target (statsmodels.compat.scipy._next_regular)."""
    if target <= 6 or not (target & (target - 1)):
        return target
    match = float("inf")
    p5 = 1
    while p5 < target:
        p35 = p5
        while p35 < target:
            quotient = -(-target // p35)
            p2 = 2 ** ((quotient - 1).bit_length())
            n = p2 * p35
            if n == target:
                return n
            match = min(match, n)
            p35 *= 3
            if p35 == target:
                return p35
        match = min(p35, match)
        p5 *= 5
        if p5 == target:
            return p5
    return int(min(p5, match))


def _acf(x: np.ndarray, nlags: int) -> np.ndarray:
    """statsmodels' ``acf(x, nlags=nlags, fft=True)`` (not adjusted, demeaned): the
    autocovariance by a zero-padded FFT over n, divided by its lag 0."""
    x = np.asarray(x, dtype=float)
    nobs = x.size
    xo = x - x.mean()
    frf = np.fft.fft(xo, n=_next_regular(2 * nobs + 1))
    acov = (np.fft.ifft(frf * np.conjugate(frf))[:nobs] / (nobs * np.ones(nobs))).real
    return acov[: nlags + 1] / acov[0]


def autocorrelation(r, max_lag: int = 25) -> dict:
    """Normalised autocorrelation at lags 0..max_lag and the 99 % band +-2.58/sqrt(N)."""
    r = as_signal(r, "r")
    if int(max_lag) < 1 or int(max_lag) >= r.size:
        raise ValueError(f"max_lag: must be in 1..{r.size - 1}, got {max_lag}")
    if np.std(r) == 0:
        raise ValueError("r: constant residual has no autocorrelation")
    rho = _acf(r, int(max_lag))
    band = Z99 / np.sqrt(r.size)
    outside = [int(k) for k in range(1, rho.size) if abs(rho[k]) > band]
    return {"lags": np.arange(rho.size), "acf": rho, "band": float(band), "outside": outside}


def cross_correlation(r, u, max_lag: int = 25) -> dict:
    """Normalised cross-correlation E[r(t) u(t - k)] for k = -max_lag..max_lag, with the band."""
    r = as_signal(r, "r")
    u = as_signal(u, "u", r.size)
    if np.std(r) == 0 or np.std(u) == 0:
        raise ValueError("r/u: constant signal has no cross-correlation")
    a = (r - r.mean()) / r.std()
    b = (u - u.mean()) / u.std()
    n = r.size
    lags = np.arange(-int(max_lag), int(max_lag) + 1)
    full = sps.correlate(a, b, mode="full", method="fft") / n   # index n-1 is lag 0
    cc = full[n - 1 + lags]
    band = Z99 / np.sqrt(n)
    return {"lags": lags, "ccf": cc, "band": float(band),
            "outside": [int(k) for k, c in zip(lags, cc) if abs(c) > band]}


def ljung_box(r, lags: int = 25) -> dict:
    """Ljung-Box Q statistic and p-value at ``lags`` (statsmodels ``acorr_ljungbox``)."""
    r = as_signal(r, "r")
    h = int(lags)
    if h < 1 or h >= r.size:
        raise ValueError(f"lags: must be in 1..{r.size - 1}, got {lags}")
    if r.size <= 2000:
        from statsmodels.stats.diagnostic import acorr_ljungbox
        res = acorr_ljungbox(r, lags=[h])
        return {"lags": h, "statistic": float(res["lb_stat"].iloc[0]),
                "pvalue": float(res["lb_pvalue"].iloc[0])}
    # the same Q = N (N + 2) sum rho_k^2 / (N - k) with the FFT autocorrelation:
    # acorr_ljungbox correlates directly, O(N^2), seconds on a 25k-sample record
    n = r.size
    rho = _acf(r, h)[1:]
    q = float(n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, h + 1))))
    return {"lags": h, "statistic": q, "pvalue": float(chi2.sf(q, h))}


def spectrum(r, fs: float, seconds: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Welch power spectral density (``scipy.signal.welch``, Hann segments of ``seconds``)."""
    r = as_signal(r, "r")
    fs = positive(fs, "fs")
    nper = int(min(r.size, max(16, round(positive(seconds, "seconds") * fs))))
    return sps.welch(r, fs=fs, nperseg=nper)


def spectral_peaks(r, fs: float, min_prominence: float = 1.0, fmin: float = 1.0,
                   fmax: float | None = None, seconds: float = 1.0) -> list[dict]:
    """Peaks of the residual spectrum standing ``min_prominence`` decades above their base.

    Peaks are found on log10 of the Welch PSD with ``scipy.signal.find_peaks`` (prominence);
    returned strongest first with their frequency, prominence (decades) and width (Hz).
    """
    f, p = spectrum(r, fs, seconds)
    fmax = 0.5 * fs if fmax is None else float(fmax)
    lp = np.log10(np.maximum(p, np.max(p) * 1e-15 + 1e-300))
    pk, prop = sps.find_peaks(lp, prominence=float(min_prominence))
    width = sps.peak_widths(lp, pk, rel_height=0.5)[0] * (f[1] - f[0]) if pk.size else []
    out = [{"frequency_hz": float(f[i]), "prominence_decades": float(pr), "width_hz": float(w),
            "share_of_power": float(_band_share(f, p, f[i], max(0.5 * w, 2 * (f[1] - f[0]))))}
           for i, pr, w in zip(pk, prop.get("prominences", []), width) if fmin <= f[i] <= fmax]
    return sorted(out, key=lambda d: -d["prominence_decades"])


def _line_spectrum(r, fs: float):
    """Welch PSD with quarter-record segments, its local background and degrees of freedom.

    The background of a bin is the lower quartile of the log spectrum over +-10 bins, the
    window first detrended by the local power law: a lower quartile, not the median, so that
    a dense excitation's lines in many neighbouring bins do not raise it; detrended, because
    on a sloped spectrum a window's lower quartile lies below the bin's level (differentiated
    encoder noise rises as f^4 below the derivative filter's cut-off: there the plain
    quartile was 2-3 times low and noise bins passed as lines, on 189 of 200 such records
    against 3 of 200 now; tests/residual/test_residual_diagnostics.py). The exponent is the
    difference of the medians of log PSD over the two halves of +-20 bins (the bin's own main
    lobe left out) over the difference of their mean log frequencies: a power law is a line
    in log-log; twice the quartile's window, so that a cluster of lines filling half of that
    window (the mains' line with its sidebands) moves neither median."""
    r = as_signal(r, "r")
    fs = positive(fs, "fs")
    n = r.size
    nper = int(max(16, n // 4))
    f, p = sps.welch(r - r.mean(), fs=fs, nperseg=nper)
    dof = 2 * max(1, n // nper)
    half = 10
    lp = np.log(np.maximum(p, np.max(p) * 1e-30 + 1e-300))
    wide = 2 * half
    view = np.lib.stride_tricks.sliding_window_view
    sw = view(np.pad(lp, wide, mode="reflect"), 2 * wide + 1)
    lf = np.log(np.maximum(f, 0.5 * f[1] if f.size > 1 else 1.0))
    sf = view(np.pad(lf, wide, mode="reflect"), 2 * wide + 1) - lf[:, None]
    lo, hi = slice(0, wide - 1), slice(wide + 2, 2 * wide + 1)   # the bin's +-2 bins left out
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = (np.median(sw[:, hi], axis=1) - np.median(sw[:, lo], axis=1)) / (
            sf[:, hi].mean(axis=1) - sf[:, lo].mean(axis=1))
    slope = np.where(np.isfinite(slope), slope, 0.0)
    mid = slice(wide - half, wide + half + 1)
    level = np.quantile(sw[:, mid] - slope[:, None] * sf[:, mid], 0.25, axis=1)
    bg = np.exp(level) / (stats.chi2.ppf(0.25, dof) / dof)
    return f, p, bg, dof


def spectral_lines(r, fs: float, alpha: float = 0.01, fmin: float = 0.0,
                   fmax: float | None = None) -> list[dict]:
    """Narrow lines (periodic components) in ``r`` at the resolution the record allows.

    Welch PSD (Hann) with segments of a quarter of the record: bins of 4 / T Hz (0.2 Hz on a
    20 s record). Each bin is tested against the local background: a line exceeds it by more than the
    chi-square quantile of a Welch estimate (2 x the number of non-overlapping segments degrees
    of freedom; the background is the lower quartile over +-10 bins of the spectrum detrended
    by its local power law, made unbiased for that distribution, so a dense excitation's
    neighbouring lines do not raise it and a sloped noise floor does not lower it:
    :func:`_line_spectrum`) at level ``alpha`` / the number of bins tested (Bonferroni).
    Returned strongest
    first: frequency (parabolic interpolation of the log spectrum around the highest bin),
    amplitude of the sinusoid (from the power above the background over the
    line's bins), ratio to the background and p-value.
    """
    f, p, bg, dof = _line_spectrum(r, fs)
    fmax = 0.5 * fs if fmax is None else float(fmax)
    test = (f >= max(fmin, f[1] if f.size > 1 else 0.0)) & (f <= fmax) & (bg > 0)
    m = int(test.sum())
    if m == 0:
        return []
    ratio = np.where(bg > 0, p / np.where(bg > 0, bg, 1.0), 0.0)
    pv = stats.chi2.sf(ratio * dof, dof)
    df = float(f[1] - f[0])
    out = []
    for i in np.flatnonzero(test & (pv < alpha / m)):
        if (i > 0 and p[i - 1] > p[i]) or (i + 1 < p.size and p[i + 1] >= p[i]):
            continue                     # the line's highest bin only
        lo, hi = max(0, i - 2), min(p.size, i + 3)
        power = float(np.sum(np.maximum(p[lo:hi] - bg[lo:hi], 0.0)) * df)
        f0 = float(f[i])
        if 0 < i < p.size - 1 and min(p[i - 1], p[i], p[i + 1]) > 0:   # parabolic on log PSD
            a, b, c = np.log(p[i - 1]), np.log(p[i]), np.log(p[i + 1])
            den = a - 2 * b + c
            if den < 0:
                f0 += float(0.5 * (a - c) / den) * df
        out.append({"frequency_hz": f0, "amplitude": float(np.sqrt(2.0 * power)),
                    "ratio_to_background": float(ratio[i]), "p_value": float(pv[i]),
                    "resolution_hz": df})
    return sorted(out, key=lambda d: -d["ratio_to_background"])


def remove_lines(r, fs: float, lines) -> tuple[np.ndarray, list[float]]:
    """``r`` with the sinusoids of ``lines`` (dicts of :func:`spectral_lines`: frequency and
    resolution) taken out, and the frequencies used.

    Each frequency is first refined to the peak of the record's periodogram (on an 8x
    zero-padded grid within +-1 resolution of the line, then between its neighbours), the
    frequency a sinusoid's least-squares fit would choose; then one least-squares fit of a
    cosine and a sine at every refined frequency (and the mean) is subtracted. A frequency off
    by 0.003 Hz over a 20 s record would leave a tenth of the sinusoid (its phase drifting by
    0.38 rad); the refined one leaves the noise's share at that frequency."""
    r = as_signal(r, "r")
    fs = positive(fs, "fs")
    n = r.size
    t = np.arange(n) / fs
    x = r - r.mean()
    nfft = 8 * int(2 ** np.ceil(np.log2(n)))
    F = np.fft.rfftfreq(nfft, 1.0 / fs)
    P = np.abs(np.fft.rfft(x, nfft)) ** 2
    used = []
    for ln in lines:
        f0, res = float(ln["frequency_hz"]), float(ln.get("resolution_hz", 4.0 * fs / n))
        m = np.flatnonzero(np.abs(F - f0) <= res)
        if m.size:                     # the grid's peak, then the continuous maximum near it
            g, step = float(F[m[np.argmax(P[m])]]), float(F[1] - F[0])
            f0 = float(optimize.minimize_scalar(
                lambda f: -abs(np.dot(x, np.exp(-2j * np.pi * f * t))) ** 2,
                bounds=(g - step, g + step), method="bounded",
                options={"xatol": 1e-6 * step}).x)
        used.append(f0)
    if not used:
        return r.copy(), used
    cols = [np.ones(n)]
    for f in used:
        cols += [np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)]
    A = np.column_stack(cols)
    coef = np.linalg.lstsq(A, r, rcond=None)[0]
    return r - A[:, 1:] @ coef[1:], used


def _band_share(f, p, f0, w):
    m = np.abs(f - f0) <= w
    return np.sum(p[m]) / np.sum(p) if np.sum(p) > 0 else 0.0


def dominant_frequency(r, fs: float, seconds: float = 1.0) -> float:
    """Frequency of the largest Welch PSD value (excluding DC)."""
    f, p = spectrum(r, fs, seconds)
    return float(f[1:][np.argmax(p[1:])])


def effective_sample_size(r, max_lag: int | None = None) -> dict:
    """N_eff = N / tau_int with tau_int = 1 + 2 sum_k rho_k (Sokal's automatic window, c = 5).

    A residual correlated over many samples carries fewer independent errors than it has
    samples; tests on N_eff instead of N stop 1 kHz records from calling everything significant.
    """
    r = as_signal(r, "r")
    n = r.size
    max_lag = min(n - 1, int(max_lag or max(50, n // 20)))
    rho = _acf(r, max_lag)
    tau = 1.0
    window = max_lag
    for m in range(1, max_lag + 1):
        tau = 1.0 + 2.0 * np.sum(rho[1:m + 1])
        if m >= 5 * max(tau, 1.0):
            window = m
            break
    tau = max(float(tau), 1.0)
    return {"n": int(n), "tau_int": tau, "window": int(window), "n_eff": float(n / tau)}


def whiteness(r, lags: int = 25, alpha: float = 0.01) -> dict:
    """Is the residual white? Ljung-Box at ``lags`` with level ``alpha``, and the acf band."""
    lb = ljung_box(r, lags)
    ac = autocorrelation(r, lags)
    return {"white": bool(lb["pvalue"] >= alpha), "ljung_box": lb,
            "acf_outside_band": ac["outside"], "band": ac["band"]}
