"""The float32 LM (issue 23 item 1, session 8): float32 network, products and 32-sample sums
(host/kernels_f32.hpp), the record's sums, J'J, the Cholesky and the step in double. Checked
against the numpy twin in float64 run on the same float32 numbers (so the only difference is
the core's float arithmetic): J'J and J'e to float32 rounding, the LM's path epoch by epoch.
Bit-identity at 1, 2 and 3 threads: tests/robust/test_threads.py (float32 cases)."""
import numpy as np
import pytest

from cdam_core import _core, reference

EPS32 = float(np.finfo(np.float32).eps)
try:
    from numpy._core._multiarray_umath import __cpu_features__ as _CPU
except ImportError:   # numpy < 2
    from numpy.core._multiarray_umath import __cpu_features__ as _CPU
# The float kernels run on AVX2 + FMA CPUs; elsewhere float32 takes Eigen's products (float sums
# over the record: the float32 rounding bound below does not hold there).
needs_avx2 = pytest.mark.skipif(not (_CPU.get("AVX2") and _CPU.get("FMA3")),
                                reason="the float32 LM kernels need AVX2 + FMA")


def _problem(n, h, seed=0, i=6, m=8):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, (n, i))
    T = np.tanh(X @ rng.uniform(-1, 1, (i, m))) + 0.1 * rng.standard_normal((n, m))
    theta = rng.uniform(-1, 1, i * h + h + h * m + m)
    # float32 numbers, and the same numbers in float64 for the twin
    X32, T32, th32 = X.astype(np.float32), T.astype(np.float32), theta.astype(np.float32)
    return X32, T32, th32, X32.astype(np.float64), T32.astype(np.float64), th32.astype(np.float64)


@needs_avx2
@pytest.mark.parametrize("n, h, act", [(10_007, 20, "tansig"), (3_001, 7, "logsig"),
                                       (777, 13, "tansig")])
def test_float32_jtj_equals_the_float64_twin_to_float32_rounding(n, h, act):
    X32, T32, th32, X, T, th = _problem(n, h)
    A, b, sse = _core.mlp_jtj(th32, X32, T32, h, act, 1)
    assert A.dtype == np.float32 and b.dtype == np.float32
    Ar, br, sr = reference.mlp_jtj(th, X, T, h, act)
    # Each entry is a sum over the record of products of float32 numbers (activations within a
    # few float32 ulps), summed in float over at most 32 samples and in double after that, and
    # returned rounded to float32 (half an eps of the entry): within a few eps of the largest
    # entry (measured 0.14-0.45 eps). numpy's float32 J'J from the explicit J (sgemm, float
    # sums over the record) is off by 0.9-1.9 eps on these problems; a plain float running
    # sum over 10,007 samples can be off by up to n eps.
    scale = np.abs(Ar).max()
    assert np.abs(A.astype(np.float64) - Ar).max() <= 4 * EPS32 * scale
    assert np.abs(b.astype(np.float64) - br).max() <= 4 * EPS32 * np.abs(br).max()
    assert abs(sse - sr) <= 4 * EPS32 * sr
    np.testing.assert_array_equal(A, A.T)


@needs_avx2
def test_float32_lm_follows_the_float64_twin():
    X32, T32, th32, X, T, th = _problem(2_000, 6, seed=3)
    t32, h32 = _core.train_lm(th32, X32, T32, 6, "tansig", epochs=8, threads=1)
    t64, h64 = reference.train_lm(th, X, T, 6, "tansig", epochs=8)
    assert t32.dtype == np.float32
    assert h32["stop"] == h64["stop"] and len(h32["mse"]) == len(h64["mse"])
    # the same accepted steps (mu's path) and the MSE to float32 rounding along them (measured
    # 4.3e-6 relative at most: about 36 float32 eps after 8 steps)
    np.testing.assert_array_equal(h32["mu"], h64["mu"])
    np.testing.assert_allclose(h32["mse"], h64["mse"], rtol=2e-5)
    assert h32["mse"][-1] < 0.2 * h32["mse"][0]


def test_float32_lm_with_validation_returns_the_best_epoch():
    X32, T32, th32, X, T, th = _problem(4_000, 8, seed=5)
    Xv32, Tv32 = X32[3000:], T32[3000:]
    t32, h32 = _core.train_lm(th32, X32[:3000], T32[:3000], 8, "tansig", epochs=12,
                              X_val=Xv32, T_val=Tv32, threads=2)
    b = h32["best_epoch"]
    assert h32["val_mse"][b] == h32["val_mse"].min()
    # the returned float32 weights' validation MSE, by numpy in float64
    Y = reference.mlp_forward(t32.astype(np.float64), Xv32.astype(np.float64), 8, 8)
    mse = np.mean((Tv32.astype(np.float64) - Y) ** 2)
    assert mse == pytest.approx(h32["val_mse"][b], rel=1e-5)
