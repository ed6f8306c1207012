"""The C++ core equals its independent numpy twin (cdam_core.reference) on random sizes and
values: 1e-12 relative in double and 1e-5 in float; LM gives the same per-epoch MSE and mu."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cdam_core import _core, reference as ref

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
TOL = {np.float64: 1e-12, np.float32: 1e-5}


def close(a, b, dtype, scale=None):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    assert a.shape == b.shape
    tol = TOL[dtype]
    s = scale if scale is not None else max(1.0, float(np.max(np.abs(b))) if b.size else 1.0)
    np.testing.assert_allclose(a, b, rtol=tol, atol=tol * s)


@st.composite
def net_case(draw, max_n=120):
    dtype = draw(st.sampled_from([np.float64, np.float32]))
    i, h, m = (draw(st.integers(1, 5)) for _ in range(3))
    n = draw(st.integers(1, max_n))
    seed = draw(st.integers(0, 2**31))
    rng = np.random.default_rng(seed)
    act = draw(st.sampled_from(["tansig", "logsig"]))
    X = rng.uniform(-2, 2, (n, i)).astype(dtype)
    T = rng.uniform(-1, 1, (n, m)).astype(dtype)
    theta = rng.uniform(-1, 1, i * h + h + h * m + m).astype(dtype)
    if draw(st.booleans()):
        X = np.asfortranarray(X)
    return dtype, X, T, theta, h, m, act


@SETTINGS
@given(st.integers(5, 300), st.integers(1, 4), st.integers(0, 10),
       st.sampled_from([np.float64, np.float32]), st.integers(0, 2**31), st.booleans())
def test_smoothing(n, c, passes, dtype, seed, fortran):
    y = (np.random.default_rng(seed).standard_normal((n, c)) * 100).astype(dtype)
    if fortran:
        y = np.asfortranarray(y)
    out = _core.five_point_cubic_smooth(y, passes)
    assert out.dtype == dtype
    close(out, ref.five_point_cubic_smooth(y, passes), dtype)


@SETTINGS
@given(st.integers(1, 200), st.integers(1, 5), st.sampled_from([np.float64, np.float32]),
       st.integers(0, 2**31))
def test_scaling(n, c, dtype, seed):
    rng = np.random.default_rng(seed)
    X = (rng.standard_normal((n, c)) * rng.uniform(0.1, 100, c)).astype(dtype)
    X[:, 0] = X[0, 0]  # a constant column
    sc = ref.MinMaxScaler().fit(X)
    lo, hi = _core.minmax_fit(X)
    close(lo, sc.data_min_, dtype)
    close(hi, sc.data_max_, dtype)
    Z = _core.minmax_apply(X, lo, hi, False)
    close(Z, sc.transform(X), dtype, scale=1.0)
    close(_core.minmax_apply(Z, lo, hi, True), sc.inverse_transform(Z.astype(dtype)), dtype)


@SETTINGS
@given(net_case())
def test_forward_gradient_jacobian(case):
    dtype, X, T, theta, h, m, act = case
    close(_core.mlp_forward(theta, X, h, m, act), ref.mlp_forward(theta, X, h, m, act), dtype)
    mse_c, g_c = _core.mlp_mse_gradient(theta, X, T, h, act)
    mse_r, g_r = ref.mlp_mse_gradient(theta, X, T, h, act)
    close(mse_c, mse_r, dtype)
    close(g_c, g_r, dtype)
    close(_core.mlp_jacobian(theta, X, h, m, act), ref.mlp_jacobian(theta, X, h, m, act), dtype)


@SETTINGS
@given(net_case(max_n=900), st.sampled_from([1, 2]))
def test_jtj(case, threads):
    dtype, X, T, theta, h, m, act = case
    A_c, b_c, sse_c = _core.mlp_jtj(theta, X, T, h, act, threads)
    A_r, b_r, sse_r = ref.mlp_jtj(theta, X, T, h, act)
    # float32 sums over up to 900 samples: allow for the different summation order
    tol_scale = 1.0 if dtype == np.float64 else 10.0
    close(A_c, A_r, dtype, scale=tol_scale * max(1.0, np.abs(A_r).max()))
    close(b_c, b_r, dtype, scale=tol_scale * max(1.0, np.abs(b_r).max()))
    close(sse_c, sse_r, dtype, scale=tol_scale * max(1.0, sse_r))


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**31), st.booleans(), st.sampled_from(["tansig", "logsig"]))
def test_lm_same_history(seed, with_val, act):
    rng = np.random.default_rng(seed)
    i, h, m, n = 3, 4, 2, 200
    X = rng.uniform(-1, 1, (n, i))
    T = np.column_stack([np.sin(2 * X[:, 0]) * X[:, 1], np.tanh(X.sum(1))]) + 0.05 * rng.standard_normal((n, m))
    theta0 = rng.uniform(-1, 1, i * h + h + h * m + m)
    kw = dict(epochs=15, goal=0.0, mu=1e-3, max_fail=3)
    if with_val:
        kw.update(X_val=rng.uniform(-1, 1, (50, i)), T_val=rng.uniform(-1, 1, (50, m)))
    th_c, hc = _core.train_lm(theta0, X, T, h, act, threads=2, **kw)
    th_r, hr = ref.train_lm(theta0, X, T, h, act, **kw)
    assert hc["stop"] == hr["stop"]
    assert hc["best_epoch"] == hr["best_epoch"]
    np.testing.assert_array_equal(hc["mu"], hr["mu"])  # the accept/reject sequence is identical
    # rounding differences (summation order) grow over the epochs on ill-conditioned J'J: 3e-9
    # relative was seen at epoch 11 (seed 1491); the identical mu sequence is the strict check
    np.testing.assert_allclose(hc["mse"], hr["mse"], rtol=1e-7)
    np.testing.assert_allclose(hc["grad_norm"], hr["grad_norm"], rtol=1e-7, atol=1e-12)
    if with_val:
        np.testing.assert_allclose(hc["val_mse"], hr["val_mse"], rtol=1e-9)
    np.testing.assert_allclose(th_c, th_r, rtol=1e-6, atol=1e-8)


def test_gd_same_history():
    rng = np.random.default_rng(4)
    X = rng.uniform(-1, 1, (150, 2))
    T = np.tanh(X @ [[1.0], [-0.5]])
    theta0 = rng.uniform(-1, 1, 2 * 3 + 3 + 3 + 1)
    th_c, hc = _core.train_gd(theta0, X, T, 3, "tansig", lr=0.05, epochs=200, threads=1)
    th_r, hr = ref.train_gd(theta0, X, T, 3, "tansig", lr=0.05, epochs=200)
    np.testing.assert_allclose(hc["mse"], hr["mse"], rtol=1e-11)
    np.testing.assert_allclose(th_c, th_r, rtol=1e-11, atol=1e-13)
    assert hc["mse"][-1] < hc["mse"][0]


@SETTINGS
@given(st.integers(0, 3), st.integers(0, 3), st.integers(0, 3), st.integers(1, 3), st.integers(1, 3),
       st.sampled_from([np.float64, np.float32]), st.integers(0, 2**31))
def test_narx(na, nb, nk, ni, no, dtype, seed):
    if na + nb < 1:
        na = 1
    rng = np.random.default_rng(seed)
    n = 40
    U = rng.uniform(-1, 1, (n, ni)).astype(dtype)
    Y = rng.uniform(-1, 1, (n, no)).astype(dtype)
    close(_core.narx_regressors(U, Y, na, nb, nk), ref.narx_regressors(U, Y, na, nb, nk), dtype)
    t0 = max(na, nk + nb - 1)
    h = 3
    D = (na * no + nb * ni) * h + h + h * no + no
    theta = rng.uniform(-0.5, 0.5, D).astype(dtype)
    close(_core.narx_simulate(theta, U, Y[:t0], h, "tansig", na, nb, nk),
          ref.narx_simulate(theta, U, Y[:t0], h, "tansig", na, nb, nk), dtype)


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=30, deadline=None)
def test_rng_same_stream(seed):
    a, b = _core.Rng(seed), ref.Rng(seed)
    assert [a.next_u32() for _ in range(20)] == [b.next_u32() for _ in range(20)]
    assert a.uniform(-2.0, 3.0) == b.uniform(-2.0, 3.0)
    assert a.index(17) == b.index(17)
    assert a.normal() == pytest.approx(b.normal(), rel=1e-15)
    np.testing.assert_array_equal(a.uniform_array(50, -1, 1), b.uniform_array(50, -1, 1))


@pytest.mark.parametrize("narx", [None, (2, 1, 1)])
def test_estimator_core_equals_reference(narx):
    from cdam_core.models.network import BPNetwork
    from cdam_core.reference.network import BPNetwork as RefBPNetwork

    rng = np.random.default_rng(9)
    U = rng.uniform(-3, 3, (300, 2))
    Y = np.column_stack([np.sin(U[:, 0]), U[:, 0] * U[:, 1]])
    kw = dict(hidden=5, epochs=10, seed=3, narx=narx)
    a = BPNetwork(**kw).fit(U, Y)
    b = RefBPNetwork(**kw).fit(U, Y)
    np.testing.assert_array_equal(a.history_["mu"], b.history_["mu"])
    np.testing.assert_allclose(a.history_["mse"], b.history_["mse"], rtol=1e-9)
    mode = "free_run" if narx else "one_step"
    np.testing.assert_allclose(a.predict(U, Y, mode=mode), b.predict(U, Y, mode=mode), rtol=1e-6, atol=1e-8)
