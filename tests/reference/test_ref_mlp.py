"""Tests of the numpy reference BP network: layout, forward, gradient, Jacobian, J'J."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdam_core.reference import (mlp_forward, mlp_jacobian, mlp_jtj, mlp_mse_gradient,
                                 mlp_num_params, mlp_unpack)

ACTS = {"tansig": math.tanh, "logsig": lambda z: 1.0 / (1.0 + math.exp(-z))}


def problem(seed, n, i, h, m, scale=1.0):
    rng = np.random.default_rng(seed)
    theta = rng.normal(scale=scale, size=mlp_num_params(i, h, m))
    X = rng.uniform(-1, 1, size=(n, i))
    T = rng.uniform(-1, 1, size=(n, m))
    return theta, X, T


def loop_forward(theta, X, h, m, act):
    """Per-sample scalar loops straight from the MATLAB layout theta[j + l*h] = W1(j, l)."""
    n, i = X.shape
    f = ACTS[act]
    o_b1, o_w2 = i * h, i * h + h
    o_b2 = o_w2 + h * m
    Y = np.zeros((n, m))
    for s in range(n):
        a = [f(sum(theta[j + l * h] * X[s, l] for l in range(i)) + theta[o_b1 + j])
             for j in range(h)]
        for k in range(m):
            Y[s, k] = sum(theta[o_w2 + k + j * m] * a[j] for j in range(h)) + theta[o_b2 + k]
    return Y


def test_paper_size_has_308_parameters():
    assert mlp_num_params(6, 20, 8) == 308


def test_unpack_is_matlab_column_major():
    i, h, m = 3, 4, 2
    theta = np.arange(float(mlp_num_params(i, h, m)))
    W1, b1, W2, b2 = mlp_unpack(theta, i, h, m)
    assert W1.shape == (h, i) and W2.shape == (m, h)
    for j in range(h):
        for l in range(i):
            assert W1[j, l] == j + l * h
    np.testing.assert_array_equal(b1, i * h + np.arange(h))
    for k in range(m):
        for j in range(h):
            assert W2[k, j] == i * h + h + k + j * m
    np.testing.assert_array_equal(b2, i * h + h + h * m + np.arange(m))


@pytest.mark.parametrize("act", ["tansig", "logsig"])
def test_forward_matches_scalar_loops(act):
    theta, X, _ = problem(0, 7, 3, 4, 2)
    np.testing.assert_allclose(mlp_forward(theta, X, 4, 2, act), loop_forward(theta, X, 4, 2, act),
                               rtol=1e-13, atol=1e-13)


sizes = st.tuples(st.integers(1, 12), st.integers(1, 4), st.integers(1, 5), st.integers(1, 3),
                  st.integers(0, 2**31), st.sampled_from(["tansig", "logsig"]))


@settings(max_examples=40, deadline=None)
@given(sizes)
def test_gradient_matches_central_differences(args):
    n, i, h, m, seed, act = args
    theta, X, T = problem(seed, n, i, h, m)
    mse, grad = mlp_mse_gradient(theta, X, T, h, act)
    e = T - loop_forward(theta, X, h, m, act)
    assert mse == pytest.approx(np.sum(e**2) / (n * m), rel=1e-12)
    step = 1e-6
    fd = np.empty_like(theta)
    for p in range(theta.size):
        tp, tm = theta.copy(), theta.copy()
        tp[p] += step
        tm[p] -= step
        up, down = mlp_mse_gradient(tp, X, T, h, act)[0], mlp_mse_gradient(tm, X, T, h, act)[0]
        fd[p] = (up - down) / (2 * step)
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-8)


@settings(max_examples=40, deadline=None)
@given(sizes)
def test_jacobian_matches_central_differences(args):
    n, i, h, m, seed, act = args
    theta, X, _ = problem(seed, n, i, h, m)
    J = mlp_jacobian(theta, X, h, m, act)
    assert J.shape == (n * m, theta.size)
    step = 1e-6
    for p in range(theta.size):
        tp, tm = theta.copy(), theta.copy()
        tp[p] += step
        tm[p] -= step
        col = (mlp_forward(tp, X, h, m, act) - mlp_forward(tm, X, h, m, act)) / (2 * step)
        # row n*m + k is dY[n, k]/dtheta: C-order ravel of (N, m)
        np.testing.assert_allclose(J[:, p], col.ravel(), rtol=1e-6, atol=1e-8)


@settings(max_examples=40, deadline=None)
@given(sizes)
def test_jtj_and_gradient_relation(args):
    n, i, h, m, seed, act = args
    theta, X, T = problem(seed, n, i, h, m)
    JtJ, Jte, sse = mlp_jtj(theta, X, T, h, act)
    J = mlp_jacobian(theta, X, h, m, act)
    e = (T - mlp_forward(theta, X, h, m, act)).ravel()
    np.testing.assert_allclose(JtJ, J.T @ J, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Jte, J.T @ e, rtol=1e-12, atol=1e-12)
    assert sse == pytest.approx(float(e @ e), rel=1e-12)
    mse, grad = mlp_mse_gradient(theta, X, T, h, act)
    assert mse == pytest.approx(sse / (n * m), rel=1e-12)
    np.testing.assert_allclose(grad, -2.0 / (n * m) * Jte, rtol=1e-10, atol=1e-13)


def test_logsig_saturates_without_warnings():
    theta, X, T = problem(3, 5, 2, 3, 1, scale=1e3)
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        Y = mlp_forward(theta, X, 3, 1, "logsig")
        mlp_mse_gradient(theta, X, T, 3, "logsig")
    assert np.all(np.isfinite(Y))


def test_float32_in_float32_out():
    theta, X, T = problem(4, 30, 3, 5, 2)
    t32, x32, T32 = (a.astype(np.float32) for a in (theta, X, T))
    Y32 = mlp_forward(t32, x32, 5, 2)
    assert Y32.dtype == np.float32
    np.testing.assert_allclose(Y32, mlp_forward(theta, X, 5, 2), rtol=1e-5, atol=1e-5)
    mse, g32 = mlp_mse_gradient(t32, x32, T32, 5)
    assert g32.dtype == np.float32
    np.testing.assert_allclose(g32, mlp_mse_gradient(theta, X, T, 5)[1], rtol=1e-4, atol=1e-5)
    assert mlp_jacobian(t32, x32, 5, 2).dtype == np.float32
    # mixing float32 and float64 computes in float64
    assert mlp_forward(theta, x32, 5, 2).dtype == np.float64


def test_fortran_order_input():
    theta, X, _ = problem(5, 9, 3, 2, 2)
    np.testing.assert_array_equal(mlp_forward(theta, np.asfortranarray(X), 2, 2),
                                  mlp_forward(theta, X, 2, 2))


def _ok():
    return problem(6, 4, 2, 3, 1)


@pytest.mark.parametrize("change, match", [
    (dict(theta=np.ones(5)), "theta: has length 5, expected 13"),
    (dict(theta=np.ones((13, 1))), "theta: must be 1-D"),
    (dict(hidden=0), "hidden: must be >= 1"),
    (dict(hidden=2.0), "hidden: must be an integer"),
    (dict(activation="relu"), "activation: must be one of"),
    (dict(X=np.ones(4)), "X: must be 2-D"),
    (dict(X=np.full((4, 2), np.nan)), "X: contains NaN"),
    (dict(X=np.ones((0, 2))), "X: is empty"),
    (dict(T=np.ones((3, 1))), "T: has 3 samples but X has 4"),
    (dict(T=np.ones((4, 1)) * np.inf), "T: contains NaN or Inf"),
])
def test_bad_input(change, match):
    theta, X, T = _ok()
    args = dict(theta=theta, X=X, T=T, hidden=3, activation="tansig")
    args.update(change)
    with pytest.raises(ValueError, match=match):
        mlp_mse_gradient(**args)
    if "T" not in change:
        with pytest.raises(ValueError, match=match):
            mlp_jacobian(args["theta"], args["X"], args["hidden"], 1, args["activation"])


def test_bad_sizes():
    with pytest.raises(ValueError, match="outputs: must be >= 1"):
        mlp_forward(np.ones(13), np.ones((4, 2)), 3, 0)
    with pytest.raises(ValueError, match="i: must be >= 1"):
        mlp_num_params(0, 3, 1)
    with pytest.raises(ValueError, match="theta: has length 12"):
        mlp_unpack(np.ones(12), 2, 3, 1)
