"""Tests of the numpy reference NARX regressors and free-run simulation."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter

from cdam_core.reference import (mlp_forward, mlp_num_params, narx_regressors, narx_simulate,
                                 narx_start)


def loop_regressors(U, Y, na, nb, nk):
    n = U.shape[0]
    t0 = max(na, nk + nb - 1)
    rows = []
    for t in range(t0, n):
        row = []
        for a in range(1, na + 1):
            for c in range(Y.shape[1]):
                row.append(Y[t - a, c])
        for b in range(nb):
            for c in range(U.shape[1]):
                row.append(U[t - nk - b, c])
        rows.append(row)
    return np.array(rows)


orders = st.tuples(st.integers(0, 3), st.integers(0, 3), st.integers(0, 3)).filter(
    lambda o: o[0] + o[1] >= 1)


@settings(max_examples=80, deadline=None)
@given(o=orders, i=st.integers(1, 3), m=st.integers(1, 3), extra=st.integers(1, 8),
       seed=st.integers(0, 2**31))
def test_regressors_match_a_plain_loop(o, i, m, extra, seed):
    na, nb, nk = o
    t0 = max(na, nk + nb - 1)
    assert narx_start(na, nb, nk) == t0
    rng = np.random.default_rng(seed)
    n = t0 + extra
    U, Y = rng.normal(size=(n, i)), rng.normal(size=(n, m))
    R = narx_regressors(U, Y, na, nb, nk)
    assert R.shape == (n - t0, na * m + nb * i)
    np.testing.assert_array_equal(R, loop_regressors(U, Y, na, nb, nk))


def test_regressor_layout_by_hand():
    U = np.array([[10.0], [11], [12], [13]])
    Y = np.array([[0.0, 100], [1, 101], [2, 102], [3, 103]])
    # na=2, nb=1, nk=1 -> t0 = 2; rows t = 2, 3: [Y[t-1], Y[t-2], U[t-1]]
    np.testing.assert_array_equal(narx_regressors(U, Y, 2, 1, 1),
                                  [[1, 101, 0, 100, 11], [2, 102, 1, 101, 12]])
    # nk = 0 is direct feed-through: U[t]
    np.testing.assert_array_equal(narx_regressors(U, Y, 0, 2, 0), [[11, 10], [12, 11], [13, 12]])


def linear_net(coeffs, eps=1e-4):
    """A 1-hidden-node tanh net that is y = coeffs . r to O(eps^2): tanh(eps z) / eps."""
    c = np.asarray(coeffs, dtype=float)
    return np.concatenate([eps * c, [0.0], [1.0 / eps], [0.0]])


def test_simulate_linear_recursion_equals_lfilter():
    a1, a2, b1, b2 = 1.5, -0.7, 0.5, 0.25          # stable: poles 0.75 +- 0.37j
    rng = np.random.default_rng(3)
    u = rng.uniform(-1, 1, 200)
    y_ref = lfilter([0.0, b1, b2], [1.0, -a1, -a2], u)
    theta = linear_net([a1, a2, b1, b2])
    assert theta.size == mlp_num_params(4, 1, 1)
    Y = narx_simulate(theta, u[:, None], y_ref[:2, None], 1, "tansig", 2, 2, 1)
    assert Y.shape == (200, 1)
    np.testing.assert_array_equal(Y[:2, 0], y_ref[:2])
    np.testing.assert_allclose(Y[:, 0], y_ref, atol=1e-5 * np.abs(y_ref).max())


def test_simulate_feeds_back_its_own_outputs():
    # the one-step prediction from a free-run's own outputs reproduces that free run
    rng = np.random.default_rng(4)
    na, nb, nk, i, m, h = 2, 3, 1, 2, 2, 5
    t0 = narx_start(na, nb, nk)
    theta = 0.5 * rng.normal(size=mlp_num_params(na * m + nb * i, h, m))
    U = rng.normal(size=(50, i))
    Y0 = rng.normal(size=(t0, m))
    for act in ("tansig", "logsig"):
        Y = narx_simulate(theta, U, Y0, h, act, na, nb, nk)
        np.testing.assert_array_equal(Y[:t0], Y0)
        pred = mlp_forward(theta, narx_regressors(U, Y, na, nb, nk), h, m, act)
        np.testing.assert_allclose(pred, Y[t0:], rtol=1e-13, atol=1e-13)


def test_simulate_differs_from_one_step_prediction_on_measured_data():
    rng = np.random.default_rng(5)
    theta = rng.normal(size=mlp_num_params(2, 3, 1))
    U = rng.normal(size=(30, 1))
    Ymeas = rng.normal(size=(30, 1))
    sim = narx_simulate(theta, U, Ymeas[:1], 3, "tansig", 1, 1, 1)
    pred = mlp_forward(theta, narx_regressors(U, Ymeas, 1, 1, 1), 3, 1)
    assert sim[1, 0] == pytest.approx(pred[0, 0], rel=1e-14)   # same first step
    assert not np.allclose(sim[2:], pred[1:])


def test_simulate_empty_initial_block_and_float32():
    # na=0, nb=1, nk=0 -> t0 = 0: a static map Y[t] = net(U[t])
    rng = np.random.default_rng(6)
    theta = rng.normal(size=mlp_num_params(2, 3, 1))
    U = rng.normal(size=(10, 2))
    Y = narx_simulate(theta, U, np.empty((0, 1)), 3, "tansig", 0, 1, 0)
    np.testing.assert_allclose(Y, mlp_forward(theta, U, 3, 1), rtol=1e-14)
    Y32 = narx_simulate(theta.astype(np.float32), U.astype(np.float32),
                        np.empty((0, 1), np.float32), 3, "tansig", 0, 1, 0)
    assert Y32.dtype == np.float32
    np.testing.assert_allclose(Y32, Y, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("args, match", [
    ((np.ones((5, 1)), np.ones((5, 1)), 0, 0, 1), "na: na \\+ nb must be at least 1"),
    ((np.ones((5, 1)), np.ones((5, 1)), -1, 1, 1), "na: must be >= 0"),
    ((np.ones((5, 1)), np.ones((5, 1)), 1, 1, 1.0), "nk: must be an integer"),
    ((np.ones((5, 1)), np.ones((4, 1)), 1, 1, 1), "Y: has 4 samples but U has 5"),
    ((np.ones((3, 1)), np.ones((3, 1)), 3, 1, 1), "U: needs more than t0 = 3 samples"),
    ((np.ones(5), np.ones((5, 1)), 1, 1, 1), "U: must be 2-D"),
    ((np.ones((5, 1)), np.full((5, 1), np.nan), 1, 1, 1), "Y: contains NaN"),
])
def test_regressors_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        narx_regressors(*args)


def test_simulate_bad_input():
    theta = np.ones(mlp_num_params(2, 3, 1))
    U = np.ones((10, 1))
    with pytest.raises(ValueError, match="Y0: must have t0 = 1 rows, got 2"):
        narx_simulate(theta, U, np.ones((2, 1)), 3, "tansig", 1, 1, 1)
    with pytest.raises(ValueError, match="theta: has length 16, expected 13"):
        narx_simulate(np.ones(16), U, np.ones((1, 1)), 3, "tansig", 1, 1, 1)
    with pytest.raises(ValueError, match="activation"):
        narx_simulate(theta, U, np.ones((1, 1)), 3, "tanh", 1, 1, 1)
    with pytest.raises(ValueError, match="U: contains NaN"):
        narx_simulate(theta, np.full((10, 1), np.nan), np.ones((1, 1)), 3, "tansig", 1, 1, 1)
    with pytest.raises(ValueError, match="U: needs more than t0 = 1"):
        narx_simulate(theta, np.ones((1, 1)), np.ones((1, 1)), 3, "tansig", 1, 1, 1)
    with pytest.raises(ValueError, match="hidden: must be >= 1"):
        narx_simulate(theta, U, np.ones((1, 1)), 0, "tansig", 1, 1, 1)
