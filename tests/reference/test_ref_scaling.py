"""Tests of the numpy reference min-max scaler (mapminmax to [-1, 1])."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from cdam_core.reference import MinMaxScaler


def test_matches_interp_and_hits_the_ends():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 3)) * [1, 10, 1e-3] + [0, 5, -2]
    Z = MinMaxScaler().fit_transform(X)
    for k in range(3):
        lo, hi = X[:, k].min(), X[:, k].max()
        np.testing.assert_allclose(Z[:, k], np.interp(X[:, k], [lo, hi], [-1, 1]), atol=1e-12)
    np.testing.assert_array_equal(Z.min(axis=0), -1.0)
    np.testing.assert_allclose(Z.max(axis=0), 1.0, atol=1e-15)


def test_attributes_and_new_data():
    X = np.array([[0.0, 10.0], [4.0, 30.0]])
    s = MinMaxScaler().fit(X)
    np.testing.assert_array_equal(s.data_min_, [0.0, 10.0])
    np.testing.assert_array_equal(s.data_max_, [4.0, 30.0])
    # outside the fitted range maps outside [-1, 1] linearly: 2*(8-0)/4-1 = 3; 2*(0-10)/20-1 = -2
    np.testing.assert_allclose(s.transform([[8.0, 0.0]]), [[3.0, -2.0]])


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 30), c=st.integers(1, 4), data=st.data())
def test_round_trip(n, c, data):
    X = data.draw(arrays(np.float64, (n, c), elements=st.floats(-1e6, 1e6)))
    s = MinMaxScaler().fit(X)
    Z = s.transform(X)
    assert np.all(Z >= -1 - 1e-12) and np.all(Z <= 1 + 1e-12)
    scale = np.maximum(1.0, np.abs(X).max(axis=0))
    np.testing.assert_allclose(s.inverse_transform(Z), X, rtol=0, atol=1e-9 * scale.max())


def test_constant_column():
    X = np.array([[1.0, 7.0], [2.0, 7.0], [3.0, 7.0]])
    s = MinMaxScaler().fit(X)
    Z = s.transform(X)
    np.testing.assert_array_equal(Z[:, 1], 0.0)
    np.testing.assert_array_equal(s.transform([[0.0, 100.0]])[:, 1], [0.0])
    np.testing.assert_array_equal(s.inverse_transform([[0.0, 0.5], [1.0, -3.0]])[:, 1], [7.0, 7.0])
    np.testing.assert_allclose(Z[:, 0], [-1.0, 0.0, 1.0])


def test_float32_stays_float32():
    X = np.random.default_rng(1).normal(size=(20, 2)).astype(np.float32)
    s = MinMaxScaler().fit(X)
    Z = s.transform(X)
    assert Z.dtype == np.float32 and s.inverse_transform(Z).dtype == np.float32
    np.testing.assert_allclose(s.inverse_transform(Z), X, atol=1e-5)


@pytest.mark.parametrize("X, match", [
    (np.ones(5), "X: must be 2-D"),
    (np.ones((0, 2)), "X: is empty"),
    (np.array([[1.0, np.nan]]), "X: contains NaN"),
    (np.array([[1.0, np.inf]]), "X: contains NaN or Inf"),
    (np.array([["a", "b"]]), "X: must hold real numbers"),
])
def test_bad_fit_input(X, match):
    with pytest.raises(ValueError, match=match):
        MinMaxScaler().fit(X)


def test_bad_transform_input():
    with pytest.raises(ValueError, match="X: the scaler is not fitted"):
        MinMaxScaler().transform(np.ones((2, 2)))
    s = MinMaxScaler().fit(np.arange(6.0).reshape(3, 2))
    with pytest.raises(ValueError, match="X: has 3 columns"):
        s.transform(np.ones((2, 3)))
    with pytest.raises(ValueError, match="X: has 1 columns"):
        s.inverse_transform(np.ones((2, 1)))
    with pytest.raises(ValueError, match="X: contains NaN"):
        s.inverse_transform(np.array([[np.nan, 0.0]]))
