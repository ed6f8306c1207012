"""Tests of the numpy reference five-point cubic smoothing against scipy and the known vector."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.signal import savgol_filter

from cdam_core.reference import five_point_cubic_smooth

KNOWN_IN = [54, 145, 227, 359, 401, 342, 259, 112, 65]
# ALGORITHMS.md, "Five-point cubic smoothing" (given to 6 decimals)
KNOWN_OUT = [56.842857, 133.628571, 244.057143, 347.942857, 393.457143, 352.028571, 241.514286,
             123.657143, 62.085714]


def savgol_passes(y, passes):
    for _ in range(passes):
        y = savgol_filter(y, 5, 3, mode="interp", axis=0)
    return y


def test_known_nine_point_vector():
    out = five_point_cubic_smooth(np.array(KNOWN_IN, dtype=float))
    np.testing.assert_allclose(out, KNOWN_OUT, rtol=0, atol=1e-6)


def test_known_vector_integer_input_becomes_float64():
    out = five_point_cubic_smooth(KNOWN_IN)
    assert out.dtype == np.float64
    np.testing.assert_allclose(out, KNOWN_OUT, rtol=0, atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(5, 40), c=st.integers(1, 4), passes=st.integers(0, 6), data=st.data())
def test_equals_savgol_interp(n, c, passes, data):
    y = data.draw(arrays(np.float64, (n, c), elements=st.floats(-1e3, 1e3)))
    out = five_point_cubic_smooth(y, passes=passes)
    ref = savgol_passes(y, passes)
    scale = max(1.0, float(np.abs(y).max()))
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12 * scale * (1 + passes))


def test_one_dimensional_keeps_shape_and_matches_columns():
    rng = np.random.default_rng(0)
    y = rng.normal(size=(30, 3))
    both = five_point_cubic_smooth(y, passes=5)
    for k in range(3):
        col = five_point_cubic_smooth(y[:, k], passes=5)
        assert col.shape == (30,)
        np.testing.assert_array_equal(col, both[:, k])


def test_zero_passes_returns_a_copy():
    y = np.arange(8.0)
    out = five_point_cubic_smooth(y, passes=0)
    np.testing.assert_array_equal(out, y)
    out[0] = 99.0
    assert y[0] == 0.0


def test_cubic_is_reproduced_exactly():
    # a least-squares cubic fit leaves any cubic polynomial unchanged, ends included
    t = np.linspace(-2, 3, 12)
    y = 0.5 * t**3 - t**2 + 2 * t - 1
    np.testing.assert_allclose(five_point_cubic_smooth(y, passes=10), y, atol=1e-11)


def test_float32_stays_float32():
    rng = np.random.default_rng(1)
    y = rng.normal(size=(50, 2))
    out32 = five_point_cubic_smooth(y.astype(np.float32), passes=5)
    assert out32.dtype == np.float32
    np.testing.assert_allclose(out32, savgol_passes(y, 5), atol=1e-5)


def test_fortran_order_input():
    y = np.asfortranarray(np.random.default_rng(2).normal(size=(20, 3)))
    np.testing.assert_allclose(five_point_cubic_smooth(y, 2), savgol_passes(y, 2), atol=1e-12)


@pytest.mark.parametrize("y, passes, match", [
    (np.ones(4), 1, "y: needs at least 5"),
    (np.ones((4, 2)), 1, "y: needs at least 5"),
    (np.array([1, 2, np.nan, 4, 5.0]), 1, "y: contains NaN"),
    (np.array([1, 2, np.inf, 4, 5.0]), 1, "y: contains NaN or Inf"),
    (np.ones((5, 2, 2)), 1, "y: must be 1-D or 2-D"),
    (np.ones((0, 2)), 1, "y: is empty"),
    (np.array(["a"] * 5), 1, "y: must hold real numbers"),
    (np.ones(5, dtype=bool), 1, "y: must hold real numbers"),
    (np.ones(5), -1, "passes: must be >= 0"),
    (np.ones(5), 1.5, "passes: must be an integer"),
    (np.ones(5), True, "passes: must be an integer"),
])
def test_bad_input(y, passes, match):
    with pytest.raises(ValueError, match=match):
        five_point_cubic_smooth(y, passes=passes)
