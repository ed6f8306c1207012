"""The residual diagnostics' autocorrelation (diagnostics._acf, written out so that a residual
run does not import statsmodels) against statsmodels' acf itself, bit for bit, and a direct
sum; and the start-up it saves."""
import subprocess
import sys

import numpy as np
import pytest
from statsmodels.compat.scipy import _next_regular as sm_next_regular
from statsmodels.tsa.stattools import acf as sm_acf

from cdam_core.residual import diagnostics as dg


@pytest.mark.parametrize("n", [2, 7, 64, 1000, 2001, 4097, 25_000])
def test_acf_equals_statsmodels_bit_for_bit(n):
    rng = np.random.default_rng(n)
    r = np.cumsum(rng.standard_normal(n)) * 0.1 + rng.standard_normal(n)
    lags = min(n - 1, 60)
    got = dg._acf(r, lags)
    assert got.tobytes() == sm_acf(r, nlags=lags, fft=True).tobytes()
    # and a plain direct sum (biased estimator, demeaned) to rounding
    x = r - r.mean()
    direct = np.array([x[k:] @ x[:n - k] for k in range(lags + 1)]) / (x @ x)
    np.testing.assert_allclose(got, direct, rtol=0, atol=1e-12)


def test_next_regular_equals_statsmodels():
    for t in list(range(1, 2000)) + [50_001, 65_537, 123_457]:
        assert dg._next_regular(t) == sm_next_regular(t), t


def test_residual_diagnostics_import_without_statsmodels():
    code = ("import sys; import cdam_core.residual, cdam_core.residual.identifiability; "
            "print('statsmodels' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
