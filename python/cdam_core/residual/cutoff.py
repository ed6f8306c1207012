"""The derivative filter's cut-off chosen from the record, per position signal.

A fixed cut-off is right for one record only: at 100 Hz a 250 Hz record is not filtered at all
and a coarse encoder's twice-differentiated angle is mostly noise (errors-in-variables bias the
least-squares estimates: stiffness too low, inertia moved between equations); a cut-off far
below the motion distorts the motion itself.

The rule reads each position's spectrum (Welch, ``scipy.signal.welch``, segments of about an
eighth of the record, linear detrend). The encoder's noise (quantisation, electrical noise) is
white: its level is the median of the spectrum over the top of the band (0.35..0.5 x the
sampling rate, where a mechanical system's motion has fallen by orders of magnitude), made
median-unbiased for the chi-square spread of a Welch estimate. The cut-off is the highest
frequency at which the spectrum still exceeds that level by more than the chi-square quantile
of the estimate at level 0.1 % / the number of frequencies tested (Bonferroni: the chance that
noise alone exceeds the threshold anywhere in the spectrum is at most 0.1 %; the motion is
there, not only noise). Without the correction (0.1 % per frequency, about one false
exceedance per spectrum of 10^3 bins) one bin far above the motion set the cut-off: on the
independent generator's axis with long stops (Fc 2, 8192 counts, 500 Hz, seed 2) a single bin
at 168 Hz among noise, where the motion ends near 12 Hz; the twice-differentiated angle was
then noise, M came out at 0.4 % of the truth and Coulomb friction was not found), at most 0.4 x the sampling
rate and at least the motion's own frequency (:func:`motion_frequency`: the frequency of a
sinusoid whose autocorrelation falls to 1/e at the velocities' correlation time, those read at
each position's own noise cut-off; session 20 replaced 1 / the correlation time, read at a fixed
100 Hz, which is 5.3 times a sinusoid's frequency and lifted a noisy link's cut-off into its
noise: every parameter 12-15 % low on a link-PD joint, 64 % on a chattering one). The
choice depends on the record only, not on the model structure being tested (a misspecified
model would otherwise pick the filter that hides what it lacks).

An encoder's quantisation is white only while the axis moves fast against its resolution.
Creeping at speed v it is a sawtooth at v / resolution, lines that stand above the white level:
on the independent generator's heavy axis with dry friction (M 2, Fv 1, Fc 2, 16384 counts,
1 kHz, a third of the record stuck) the cut-off came out at 95 and 212 Hz (seeds 0, 1) where
the noise-free motion meets the white level near 10 Hz, the twice-differentiated angle was
noise, IDIM-LS's M 5 % of the truth and the dry friction was not found. So when a position lies
on a grid (its differences integer multiples of one step: an encoder's counts, read from the
record, :func:`encoder_step`), the quantisation error is estimated from the record itself
(:func:`creep_error`: within each run of one count the angle interpolated linearly between the
cell boundaries it crossed, at the half-sample instants of the changes; the measured angle minus
that) and the level a bin is compared with is the larger of the white level and that error's
spectrum at the bin. Measured: the heavy axis's cut-offs 7.3 / 21 / 7.8 Hz (seeds 0-2; white
noise of the quantisation's variance on the noise-free motion: 10.3 / 11.2 / 10.7 Hz); DATA_EMPS
(a 5e-8 m grid, the count changing at nearly every sample) unchanged at 400 Hz.

White noise added after the quantisation (an analogue stage, a simulator's sensor model) takes
the record off its grid; the white rule alone then let the creep's lines through: on the
generator's heavy axis (as above, 3e-5 rad noise, seed 1) the cut-off was 157 Hz, M +90 %,
Fv +870 % and no friction found; on its axis with long stops (Fc 3, 8192 counts, 1e-4 rad,
500 Hz, seed 1) 42 Hz, M +5.2 %, Fv +11 %. When the noise is small against the step (the
regime where it does not dither the quantisation) and the axis creeps, the grid is found under
the noise (:func:`noisy_grid`) and the counts read from it give the creep error (where the
count changes at most samples the quantisation is white, the search's scale is then a third of
a step or more and the white level holds it): the heavy axis's
cut-offs are then those of its noise-free counts (7.3 / 21 / 7.8 Hz, seeds 0-2; seed 1 M -1.0 %,
Fc +0.6 %), the axis with long stops 11.7 / 7.8 / 7.8 Hz (seed 1 M +2.5 %, Fv +6.6 %).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import optimize
from scipy import signal as sps
from scipy import stats

from cdam_core.models.greybox.declared import DerivativeFilter, SignalFilters
from cdam_core.residual.validation import motion_horizon

__all__ = ["at_rest", "choose_cutoff", "creep_error", "edge_trim", "encoder_step", "given_cutoff",
           "main_lobe", "noise_cutoff", "noisy_grid"]

TOP = 0.4            # highest cut-off, x the sampling rate
FLOOR_BAND = 0.35    # noise level read above this fraction of the sampling rate
LEVEL = 1e-3         # chance that noise alone exceeds the threshold anywhere in the spectrum


def edge_trim(cutoff_hz: float, fs: float) -> int:
    """Samples left out at each edge: three periods of the cut-off, at least 50."""
    return max(50, int(np.ceil(3.0 * fs / cutoff_hz)))


def encoder_step(x) -> float | None:
    """The step of the grid the samples of ``x`` lie on (every difference an integer multiple
    of the smallest nonzero one, to 1e-6 of it and the values' rounding), or None: not
    quantised, or noise added after the quantisation, or fewer than 10 changes."""
    x = np.asarray(x, dtype=float)
    d = np.abs(np.diff(x))
    d = d[d > 0]
    if d.size < 10:
        return None
    step = float(d.min())
    k = d / step
    tol = 1e-6 + 8 * np.finfo(float).eps * float(np.max(np.abs(x))) / step
    return step if np.max(np.abs(k - np.round(k))) <= tol else None


def _robust_std(v, centre: float | None = None) -> float:
    """1.4826 x the median absolute deviation from ``centre`` (default the median): the
    standard deviation of normal data."""
    v = np.asarray(v, dtype=float)
    return float(1.4826 * np.median(np.abs(v - (np.median(v) if centre is None else centre))))


def noisy_grid(x) -> dict | None:
    """The grid of an encoder whose counts were read with white noise added after the
    quantisation (an analogue stage, a simulator's sensor model), or None.

    The search's scale is the noise read independently of any grid from the second differences
    (robust standard deviation / sqrt 6; an upper bound where count changes are frequent). The
    step is the period at which the angles' phases concentrate most (the magnitude of the
    characteristic function of the angles' histogram, FFT on bins of a quarter of that scale,
    refined on the samples), from 3 x that scale to a tenth of the range moved; of the step
    and its multiples up to 16 the coarsest grid that concentrates them as much (a finer one
    holds every point of a coarser one); the offset is their mean phase. Under the grid, the angle minus its nearest grid point is the noise: its
    level sigma is read there (1.4826 x the median absolute value). The grid is reported only
    where it matters, a step of at least 6 sigma (below, the noise dithers the quantisation into
    white noise that the white level already holds), and only when it explains the samples at
    which the count changes: there the residual is the noise as well (spread sigma, by the same
    robust measure: the noise's own crossings of half a step are among those samples), where
    without a grid it is spread over the step (evenly, or near half a step where a slow angle
    crosses a cell's boundary: a spread of at least 0.37 step, 2.2 sigma), however many samples
    sit still at a few positions. The spread at the changes must be nearer sigma than 0.37 step
    in ratio (below their geometric mean; a few hundred changes estimate it to about 6 %)."""
    x = np.asarray(x, dtype=float)
    if x.size < 32:
        return None
    scale = _robust_std(np.diff(x, 2)) / np.sqrt(6.0)
    span = float(np.ptp(x))
    if not scale > 0 or span < 30 * scale:
        return None
    h = scale / 4.0
    bins = int(span / h) + 1
    if bins > 2 ** 24:
        return None
    nfft = 1 << int(np.ceil(np.log2(bins)))
    hist = np.bincount(((x - x.min()) / h).astype(np.int64), minlength=nfft)
    mag = np.abs(np.fft.rfft(hist.astype(float))) / x.size
    u = np.arange(mag.size) / (nfft * h)
    search = np.flatnonzero((u >= 10.0 / span) & (u <= 1.0 / (3.0 * scale)))
    if search.size == 0:
        return None
    j = int(search[np.argmax(mag[search])])
    du = 1.0 / (nfft * h)
    best = optimize.minimize_scalar(lambda f: -abs(np.mean(np.exp(2j * np.pi * f * x))),
                                    bounds=(max(u[j] - du, du), u[j] + du), method="bounded",
                                    options={"xatol": du * 1e-4})
    found = 1.0 / float(best.x)
    step, z = found, np.mean(np.exp(2j * np.pi * x / found))
    for m in range(2, 17):    # a harmonic's bin may stand higher (the FFT's scalloping)
        if m * found > span / 10.0:
            break
        zm = np.mean(np.exp(2j * np.pi * x / (m * found)))
        if abs(zm) >= abs(z):
            step, z = m * found, zm
    offset = float(np.angle(z)) * step / (2 * np.pi)
    c = np.round((x - offset) / step)
    r = x - offset - step * c
    sigma = _robust_std(r, 0.0)
    moving = np.flatnonzero(np.diff(c) != 0) + 1
    if moving.size < 10 or not 0 < 6.0 * sigma <= step:
        return None
    spread = _robust_std(r[moving], 0.0)
    even = 1.4826 * step / 4.0        # the spread of residuals even over the step
    if spread >= np.sqrt(sigma * even):
        return None
    return {"step": step, "offset": offset, "noise_sigma": sigma,
            "phase_concentration": float(abs(z)), "residual_spread_at_changes": spread,
            "changes": int(moving.size)}


def creep_error(x, step: float) -> np.ndarray:
    """The quantisation error of ``x`` on a grid of ``step``, estimated from the record: within
    each run of one count at least two samples long the angle is interpolated linearly between
    the cell boundaries it crossed on entering and on leaving, placed at the half-sample
    instants of the changes; the error is ``x`` minus that (0 on samples whose count changes on
    both sides and on the first and last runs, where no crossing bounds them)."""
    x = np.asarray(x, dtype=float)
    c = np.round((x - x[0]) / float(step)).astype(np.int64)
    ch = np.flatnonzero(np.diff(c) != 0)          # the count changes between ch and ch + 1
    a, b = ch[:-1], ch[1:]                        # a run: samples a + 1 .. b
    keep = b - a >= 2
    a, b = a[keep], b[keep]
    est = x.copy()
    if a.size:
        lo = x[0] + step * 0.5 * (c[a] + c[a + 1])
        hi = x[0] + step * 0.5 * (c[b] + c[b + 1])
        length = b - a
        run = np.repeat(np.arange(a.size), length)
        k = np.arange(length.sum()) - np.repeat(np.cumsum(length) - length, length) + 1
        est[a[run] + k] = lo[run] + (hi - lo)[run] * (k - 0.5) / length[run]
    return x - est


def noise_cutoff(x, fs: float) -> tuple[float, dict]:
    """The cut-off of one position signal (module doc) and the evidence; the motion's own
    frequency bounds it from below in :func:`choose_cutoff`."""
    x = np.asarray(x, dtype=float)
    n = x.size
    nper = int(min(n, max(256, 2 ** int(np.log2(max(n / 8, 2))))))
    f, P = sps.welch(x, fs=fs, nperseg=nper, detrend="linear")
    dof = 2 * max(1, n // nper)     # non-overlapping segments: a conservative count
    band = (f >= FLOOR_BAND * fs) & (f < 0.5 * fs)
    top = TOP * fs
    if not band.any() or not np.any(P[band] > 0):
        return top, {"noise_level": 0.0, "reason": "no noise floor in the record"}
    level = float(np.median(P[band])) / (stats.chi2.median(dof) / dof)
    floor = np.full(P.shape, level)
    step, grid = encoder_step(x), None
    counts = x
    if step is None:          # the counts under white noise added after the quantisation
        grid = noisy_grid(x)
        if grid is not None:
            step = grid["step"]
            counts = grid["offset"] + step * np.round((x - grid["offset"]) / step)
    if step is not None:      # the quantisation's own spectrum where the axis creeps
        floor = np.maximum(floor, sps.welch(creep_error(counts, step), fs=fs, nperseg=nper,
                                            detrend="linear")[1])
    tested = int(np.count_nonzero(f > 0))
    q = stats.chi2.isf(LEVEL / tested, dof) / dof
    thr = level * q
    above = np.flatnonzero((P > floor * q) & (f > 0))
    fc = float(f[above[-1]]) if above.size else 0.0
    fc = float(min(max(fc, f[1] if f.size > 1 else 0.0), top))
    return fc, {"noise_level": level, "threshold": thr, "frequencies_tested": tested,
                "resolution_hz": float(f[1] - f[0]),
                "encoder_step": step,
                "noisy_grid": grid,
                "bins_above_white_by_creep": int(np.count_nonzero(floor > level)),
                "last_frequency_above_noise_hz": float(f[above[-1]]) if above.size else None}


def motion_frequency(model, t, raw: dict, cut: dict, order: int = 4, extra=None) -> float:
    """The motion's own frequency (Hz): that of a sinusoid whose autocorrelation falls to 1/e
    at the velocities' correlation time (:func:`motion_horizon`, the longest over the
    positions), arccos(1/e) / (2 pi horizon dt), about 0.19 / horizon. The velocities are
    read each at its noise cut-off ``cut``. (Before session 20 the bound was 1 / horizon,
    5.3 times a sinusoid's frequency, read at a fixed 100 Hz: on a link held by PD against a
    4096-count encoder, its 11 Hz chatter put the link's cut-off at 50 Hz where its
    spectrum meets the noise at 13 Hz, and every parameter came out 12-15 % low.)"""
    dt = float(np.mean(np.diff(np.asarray(t, dtype=float))))
    ref = model.prepare(t, raw, SignalFilters.of(cut, order), extra)
    return float(np.arccos(1.0 / np.e) / (2 * np.pi * motion_horizon(ref, model.positions) * dt))


def choose_cutoff(model, t, raw: dict, extra: dict | None = None, order: int = 4) -> tuple[DerivativeFilter, dict]:
    """Return (filter, report) for ``model`` on the record: one cut-off per position
    (:func:`noise_cutoff`); ``report`` holds each signal's evidence and the edge trim."""
    t = np.asarray(t, dtype=float)
    dt = float(np.mean(np.diff(t)))
    fs = 1.0 / dt
    cut, evidence = {}, {}
    for p in model.positions:
        cut[p], evidence[p] = noise_cutoff(raw[p], fs)
    lowest = min(motion_frequency(model, t, raw, cut, order, extra), TOP * fs)
    cut = {p: max(c, lowest) for p, c in cut.items()}
    filt = SignalFilters.of(cut, order)
    trim = edge_trim(min(cut.values()), fs)
    return filt, {"rule": "per position: the highest frequency where its spectrum exceeds the "
                          "encoder's white-noise level (read at 0.35..0.5 fs; on a position "
                          "on a grid of counts, read exactly or found under white noise, "
                          "or its quantisation error's spectrum where that is higher) "
                          "beyond the "
                          f"chi-square quantile at {100 * LEVEL:g} % / the frequencies tested "
                          "(Bonferroni); within "
                          f"[{lowest:.3g}, {TOP * fs:.4g}] Hz (the motion's own frequency, "
                          "0.4 fs)",
                  "chosen_hz": {p: float(v) for p, v in cut.items()}, "signals": evidence,
                  "trim_samples": trim, "fs": fs, "order": int(order)}


def given_cutoff(model, t, raw: dict, cutoff_hz: float, order: int = 4) -> dict:
    """The report of a cut-off the user gave (one for every position), with each position's
    noise evidence read as :func:`noise_cutoff` reads it: the rows at rest are then left out
    of a dry-friction fit (:func:`at_rest`) and the cable's deflection check weighs the encoder
    noise, as with a chosen cut-off; the cut-off the record would choose is reported beside."""
    t = np.asarray(t, dtype=float)
    fs = 1.0 / float(np.mean(np.diff(t)))
    evidence = {}
    for p in model.positions:
        fc, evidence[p] = noise_cutoff(raw[p], fs)
        evidence[p]["record_would_choose_hz"] = fc
    return {"rule": "given", "chosen_hz": {p: float(cutoff_hz) for p in model.positions},
            "signals": evidence, "fs": fs, "order": int(order)}


def velocity_noise(noise_level: float, cutoff_hz: float) -> float:
    """Standard deviation of the velocity that white position noise of one-sided density
    ``noise_level`` (units^2 / Hz) leaves after differentiation through an ideal low-pass at
    ``cutoff_hz``: sqrt(int_0^fc (2 pi f)^2 N0 df) = 2 pi sqrt(N0 fc^3 / 3)."""
    return float(2 * np.pi * np.sqrt(max(noise_level, 0.0) * cutoff_hz ** 3 / 3.0))


def main_lobe(cutoff_hz: float, fs: float, order: int = 4) -> int:
    """Half-width in samples of the main lobe of the zero-phase Butterworth filter's impulse
    response (``scipy.signal.sosfiltfilt``, as :class:`DerivativeFilter`): the lag of its first
    zero crossing, about half a period of the cut-off (0.50-0.54 at 10-100 Hz)."""
    sos = sps.butter(int(order), min(float(cutoff_hz), 0.49 * fs), fs=fs, output="sos")
    half = int(np.ceil(20 * fs / cutoff_hz)) + 10
    x = np.zeros(2 * half + 1)
    x[half] = 1.0
    h = sps.sosfiltfilt(sos, x)[half:]
    z = np.flatnonzero(h <= 0)
    return int(z[0]) if z.size else half


def at_rest(model, candidates, choice: dict, alpha: float) -> list:
    """Dry-friction candidates that leave out the rows at rest: those whose velocity is not
    distinguishable from zero at level ``alpha`` given the encoder noise (two-sided normal
    quantile x :func:`velocity_noise` of the velocity's position), and the rows within the
    derivative filter's main lobe (:func:`main_lobe`) of a stop, a run at rest longer than
    that half-width (a shorter run is, at the filter's resolution, the velocity crossing zero:
    DATA_EMPS's 5 rows at rest are 4 such runs of 1-2 samples, its half-width 2 samples at
    400 Hz). At rest the dry friction is
    anywhere in [-Fc, Fc] (it balances the applied torque) and the equation with Fc sign(v)
    does not hold; a row beside a stop holds filtered signals that are mostly the stop's (the
    zero-phase filter weighs its neighbours over the main lobe). Measured on the independent
    generator's axis with long stops (Fc 2, 8192 counts, 500 Hz, seeds 0-3, IDIM-LS with the
    Coulomb term): rows at rest only, Fv +10..+18 % and Fc -6..-12 %; the main lobe left out as
    well, every one of M, Fv, Fc within 0.7 %. At Fc 3 (more than half the record stuck) the
    sign column at the rows at rest, the sign of the velocity noise, low-passed into the rows
    kept, still gave Fv +7.6 % (seed 2): it is 0 there (``CoulombFriction.regressors``),
    Fv -0.9 %."""
    z = float(stats.norm.ppf(1 - alpha / 2))
    out = []
    for c in candidates:
        if c.name == "coulomb_friction" and not getattr(c, "smooth", False):
            pos = model.viscous[c.channel][1][:-2]     # "theta_m_d" -> "theta_m"
            ev = choice["signals"].get(pos, {})
            fc = choice["chosen_hz"].get(pos)
            if fc and ev.get("noise_level"):
                reach = main_lobe(fc, choice["fs"], choice.get("order", 4)) \
                    if "fs" in choice else 0
                c = replace(c, rest_speed=z * velocity_noise(ev["noise_level"], fc),
                            rest_reach=reach)
        out.append(c)
    return out
