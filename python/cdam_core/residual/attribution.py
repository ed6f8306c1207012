"""Is a line in the residual the model's own error, or structure the model cannot produce?

A residual line at an excitation frequency (or at a harmonic of one, through a nonlinear term)
is what a model that is slightly off does: its terms, driven by the inputs, carry that
frequency, and a small change of their coefficients moves the residual there. A periodic
disturbance the model does not hold shows at a frequency where the inputs drive none of the
model's terms. The measured regressor columns cannot tell the two apart: they carry the plant's
response to the disturbance as well (the link equation's terms sum to minus its residual), so
a regression on them accounts for every line. What the model produces from the inputs alone
can: the fitted model is free-run from the measured inputs (its positions simulated, then
filtered and differentiated exactly as the measured ones), and its terms ``theta_j x_j`` and
left side are rebuilt from that run (:func:`input_driven_terms`).

The test (:func:`attribute`), per line, on the whole record's Hann-windowed DFT (resolution
1 / T): over the line's main lobe (the peak bin +-2) the residual is regressed on the
input-driven terms with complex coefficients bounded by 1 in each of their real and imaginary
parts (a term's coefficient, its own amplitude and phase, moved by at most its own size in
either part: the largest change a term's parameter can take without changing sign, the physical
bounds of inertias, stiffness and damping), by bounded least squares
(``scipy.optimize.lsq_linear``). What the best such change leaves is compared with the
residual's noise level at the line, from the surrounding bins (+-40 bins beyond the lobe,
lower quartile made unbiased for the exponential law of a periodogram bin): under "explained"
the sum over the lobe's 5 correlated Hann bins is a scaled chi-square (Satterthwaite, with the
Hann bins' correlations -2/3 and 1/6). A line is unexplained when that p-value is below the
level divided by the number of lines tested (Bonferroni). The statement is the model's
structure (its declared terms and the effects found), not a tolerance: no threshold is tuned.
"""
from __future__ import annotations

import numpy as np
from scipy import optimize, stats

from cdam_core.models.greybox.estimation import design
from cdam_core.models.greybox.freerun import free_run_error

__all__ = ["input_driven_terms", "attribute", "hann_dft", "LOBE", "RING"]

LOBE = 2     # bins either side of the peak: the Hann window's main lobe at full resolution
RING = 40    # bins either side of the lobe for the noise level (10 of the line detector's bins)
# white-noise covariance of adjacent Hann DFT bins relative to one bin's variance
_HANN_CORR = {0: 1.0, 1: -2.0 / 3.0, 2: 1.0 / 6.0}


def input_driven_terms(fitted, sig: dict, substeps: int | None = None) -> dict:
    """``{equation: [term arrays]}`` over ``fitted.keep``: the equation's left side and each of
    its terms ``theta_j x_j`` rebuilt from the fitted model free-run from the measured inputs
    (:func:`~cdam_core.models.greybox.freerun.free_run_error`; positions filtered and
    differentiated as the measured ones). Raises ValueError when the model cannot be run."""
    model = fitted.model
    _, sim = free_run_error(fitted, sig, substeps)
    n = np.asarray(sig["t"]).size
    raw = {name: sig[name] for name in model.signals if name not in model.positions}
    for p in model.positions:
        q = np.array(sig[p + "_raw"], dtype=float, copy=True)
        q[n - sim[p].size:] = sim[p]
        if not np.all(np.isfinite(q)):
            raise ValueError("free run: not finite")
        raw[p] = q
    run = model.prepare(sig["t"], raw, sig["filter"], sig.get("extra") or None,
                        sig.get("timing", "sampled"))
    run.measured = False   # a simulated run: no encoder noise in its positions
    _, eqs = design(model, run, fitted.effects)
    out = {}
    for eq, (y, cols) in eqs.items():
        terms = []
        for p, c in cols.items():
            terms.append(float(fitted.theta.get(p, 0.0))
                         * np.broadcast_to(np.asarray(c, dtype=float), (n,))[fitted.keep])
        out[eq] = [t for t in terms if np.any(t != 0)]
    return out


def hann_dft(x) -> np.ndarray:
    """The Hann-windowed DFT of ``x`` (mean removed) the attribution works on."""
    x = np.asarray(x, dtype=float)
    return np.fft.rfft((x - x.mean()) * np.hanning(x.size))


def _satterthwaite(m: int) -> tuple[float, float]:
    """(scale g, dof nu): the sum of ``m`` adjacent Hann periodogram bins of white noise (each
    of mean 1) is about g chi2(nu)."""
    C = np.array([[_HANN_CORR.get(abs(i - j), 0.0) for j in range(m)] for i in range(m)])
    mean, var = float(m), float(np.sum(C ** 2))   # Var sum |Z_b|^2 = sum |cov|^2
    return var / (2 * mean), 2 * mean ** 2 / var


def _bounded_rest(Rb: np.ndarray, Tb: np.ndarray) -> np.ndarray:
    """What is left of ``Rb`` after the best ``Tb c`` with c = a + i b, |a|, |b| <= 1 (bounded
    least squares on the real unknowns [a, b])."""
    unit = float(np.max(np.abs(Rb)))
    if unit == 0:
        return Rb
    A = np.block([[Tb.real, -Tb.imag], [Tb.imag, Tb.real]]) / unit   # solved in units of |R|
    y = np.concatenate([Rb.real, Rb.imag]) / unit
    sc = np.linalg.norm(A, axis=0)
    ok = sc > 0
    x = np.zeros(A.shape[1])
    if ok.any():
        res = optimize.lsq_linear(A[:, ok] / sc[ok], y, bounds=(-sc[ok], sc[ok]))
        x[ok] = res.x / sc[ok]
    left = (y - A @ x) * unit
    return left[:Rb.size] + 1j * left[Rb.size:]


def attribute(r, terms, fs: float, f0: float, band_hz: float | None = None,
              spectra: tuple | None = None) -> dict:
    """Test one residual line at ``f0`` against the input-driven ``terms`` (module docstring).

    ``band_hz``: half-width of the band tested (default: the line's main lobe, +-2 bins);
    ``spectra``: (R, [T_j]) Hann DFTs already computed for ``r`` and ``terms``. Returns the
    p-value of "the model's terms account for it", the share of the band's power they account
    for, the amplitude left unexplained, and the bins used."""
    r = np.asarray(r, dtype=float)
    n = r.size
    R, T = spectra if spectra is not None else (hann_dft(r), [hann_dft(t) for t in terms])
    df = fs / n
    k0 = int(round(f0 / df))
    lobe = LOBE if band_hz is None else max(LOBE, int(np.ceil(band_hz / df)))
    k0 = max(1, min(k0, R.size - 2))
    lo0, hi0 = max(1, k0 - 3), min(R.size, k0 + 4)
    k0 = lo0 + int(np.argmax(np.abs(R[lo0:hi0])))          # the line's highest bin
    B = np.arange(max(1, k0 - lobe), min(R.size, k0 + lobe + 1))
    ring = np.r_[np.arange(max(1, B[0] - RING), B[0]), np.arange(B[-1] + 1,
                                                                min(R.size, B[-1] + 1 + RING))]
    # noise level per bin: lower quartile of |R|^2 over the ring, / -ln(0.75) (exponential)
    sigma2 = float(np.quantile(np.abs(R[ring]) ** 2, 0.25) / -np.log(0.75)) if ring.size else 0.0
    Rb = R[B]
    if not T:
        rem = Rb
    elif band_hz is None:      # a line: the coefficients may differ from bin to bin of the lobe
        rem = np.array([_bounded_rest(Rb[i:i + 1], np.array([[t[b] for t in T]]))[0]
                        for i, b in enumerate(B)])
    else:                      # a band: one coefficient per term over the whole band
        rem = _bounded_rest(Rb, np.column_stack([t[B] for t in T]))
    power, left_power = float(np.sum(np.abs(Rb) ** 2)), float(np.sum(np.abs(rem) ** 2))
    if sigma2 > 0:
        g, nu = _satterthwaite(B.size)
        p = float(stats.chi2.sf(left_power / sigma2 / g, nu))
    else:
        p = 0.0 if left_power > 0 else 1.0
    excess = max(left_power - B.size * sigma2, 0.0)
    # a sinusoid of amplitude A gives |DFT| = A sum(w) / 2 at its bin; over the lobe the Hann
    # bins hold sum |W_b|^2 = 1.5 (sum(w) / 2)^2 ... here: sum over bins of |A sum(w)/2 K_b|^2
    # with K = (1, 1/2, 1/2) on bin centre: 1.5 x (A sum(w) / 2)^2
    amp_scale = 0.5 * float(np.sum(np.hanning(n)))
    rho = float(np.sqrt(power) / max([np.linalg.norm(t[B]) for t in T] + [1e-300]))
    return {"p_value": p, "relative_to_terms": rho,
            "explained_share": float(1.0 - left_power / power) if power > 0 else 0.0,
            "unexplained_amplitude": float(np.sqrt(excess / 1.5) / amp_scale),
            "band_hz": [float(B[0] * df), float(B[-1] * df)], "resolution_hz": float(df)}
