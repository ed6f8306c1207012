"""A residual line against the model's input-driven terms (residual.attribution), on signals
built here in plain numpy: what the test must call explained and unexplained follows from
their construction (closed forms), and its p-values are checked on white noise."""
import numpy as np
import pytest

from cdam_core.residual.attribution import _satterthwaite, attribute

FS, N = 200.0, 8000          # 40 s: lines at whole numbers of cycles sit on bin centres
T = np.arange(N) / FS


def _sine(a, f, ph=0.0):
    return a * np.sin(2 * np.pi * f * T + ph)


def test_a_small_error_at_a_term_line_is_explained_a_line_no_term_holds_is_not():
    rng = np.random.default_rng(1)
    terms = [_sine(1.0, 3.0), _sine(0.5, 7.0, 0.3)]
    # 2 % of the 3 Hz term with another phase (a model error there), and 0.05 at 11.3 Hz,
    # where no term has anything (a disturbance), in white noise
    r = _sine(0.02, 3.0, 0.4) + _sine(0.05, 11.3) + rng.normal(0, 0.01, N)
    at3 = attribute(r, terms, FS, 3.0)
    assert at3["p_value"] > 0.01 and at3["explained_share"] > 0.99
    at11 = attribute(r, terms, FS, 11.3)
    assert at11["p_value"] < 1e-6 and at11["explained_share"] < 0.01
    assert at11["unexplained_amplitude"] == pytest.approx(0.05, rel=0.1)
    assert at11["resolution_hz"] == pytest.approx(FS / N)


def test_a_line_larger_than_a_term_can_move_is_unexplained_by_what_is_left():
    """Coefficients bounded by 1 in their in-phase and quadrature parts: a line in phase with
    the only term there, of twice its amplitude, leaves exactly one term's amplitude."""
    r = _sine(2.0, 3.0) + np.random.default_rng(2).normal(0, 0.01, N)
    a = attribute(r, [_sine(1.0, 3.0)], FS, 3.0)
    assert a["p_value"] < 1e-6
    assert a["unexplained_amplitude"] == pytest.approx(1.0, rel=0.05)
    assert a["explained_share"] == pytest.approx(1 - (1.0 / 2.0) ** 2, abs=0.02)


def test_hann_bin_sum_law():
    """Satterthwaite's scale and degrees of freedom for 5 adjacent Hann periodogram bins of
    white noise, against a Monte Carlo of the same sums (mean 5, variance from the samples)."""
    g, nu = _satterthwaite(5)
    rng = np.random.default_rng(3)
    x = rng.normal(size=(4000, 512))
    P = np.abs(np.fft.rfft(x * np.hanning(512), axis=1)) ** 2 / np.sum(np.hanning(512) ** 2)
    s = P[:, 100:105].sum(axis=1)
    assert np.mean(s) == pytest.approx(g * nu, rel=0.03)
    assert np.var(s) == pytest.approx(2 * g * g * nu, rel=0.1)
