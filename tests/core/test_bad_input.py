"""Every binding and public function rejects bad input with an error naming the problem, and no
input (random shapes, dtypes, values) crashes the interpreter."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import cdam_core
from cdam_core import _core

DTYPES = [np.float64, np.float32, np.int32, np.int64, np.bool_, np.complex128, np.uint8, object, "U3"]


@st.composite
def any_array(draw):
    ndim = draw(st.integers(0, 3))
    shape = tuple(draw(st.integers(0, 6)) for _ in range(ndim))
    dtype = draw(st.sampled_from(DTYPES))
    vals = draw(st.sampled_from([0.0, 1.0, -3.5, np.nan, np.inf, 1e308]))
    try:
        with np.errstate(all="ignore"):
            a = np.full(shape, vals).astype(dtype)
    except (ValueError, OverflowError):
        a = np.zeros(shape, dtype=dtype)
    if draw(st.booleans()) and a.ndim == 2:
        a = np.asfortranarray(a)
    return a


SMALL_INT = st.integers(-2, 6)
CALLS = [
    lambda a, b, c, k: _core.five_point_cubic_smooth(a, k),
    lambda a, b, c, k: _core.minmax_fit(a),
    lambda a, b, c, k: _core.minmax_apply(a, b, c, bool(k % 2)),
    lambda a, b, c, k: _core.mlp_forward(a, b, k, k, "tansig"),
    lambda a, b, c, k: _core.mlp_mse_gradient(a, b, c, k, "logsig"),
    lambda a, b, c, k: _core.mlp_jacobian(a, b, k, 2),
    lambda a, b, c, k: _core.mlp_jtj(a, b, c, k, "tansig", 1),
    lambda a, b, c, k: _core.train_lm(a, b, c, k, epochs=2),
    lambda a, b, c, k: _core.train_gd(a, b, c, k, epochs=2),
    lambda a, b, c, k: _core.narx_regressors(a, b, k, 1, 0),
    lambda a, b, c, k: _core.narx_simulate(a, b, c, 2, "tansig", k, 1, 0),
    lambda a, b, c, k: cdam_core.five_point_cubic_smooth(a, passes=k),
    lambda a, b, c, k: cdam_core.MinMaxScaler().fit(a).transform(b),
    lambda a, b, c, k: cdam_core.BPNetwork(hidden=max(k, 1), epochs=1).fit(a, b),
]


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(range(len(CALLS))), any_array(), any_array(), any_array(), SMALL_INT)
def test_random_input_never_crashes(which, a, b, c, k):
    try:
        CALLS[which](a, b, c, k)
    except (ValueError, TypeError):
        pass


@pytest.mark.parametrize("call, match", [
    (lambda: cdam_core.five_point_cubic_smooth(np.ones(4)), "at least 5 samples"),
    (lambda: cdam_core.five_point_cubic_smooth(np.ones(10), passes=-1), "passes"),
    (lambda: cdam_core.five_point_cubic_smooth(np.array([1, 2, np.nan, 4, 5.0])), "NaN"),
    (lambda: cdam_core.five_point_cubic_smooth(np.ones((0, 3))), "empty"),
    (lambda: cdam_core.five_point_cubic_smooth(np.ones(10, dtype=complex)), "dtype"),
    (lambda: cdam_core.BPNetwork(hidden=0), "hidden"),
    (lambda: cdam_core.BPNetwork().fit(np.ones((10, 2)), np.ones((9, 1))), "mismatched sample counts"),
    (lambda: cdam_core.BPNetwork().fit(np.ones((10, 2)), np.full((10, 1), np.inf)), "Y: contains NaN"),
    (lambda: cdam_core.BPNetwork().predict(np.ones((3, 2))), "not fitted"),
    (lambda: _core.mlp_forward(np.ones(5), np.ones((4, 2)), 3, 1), "theta: expected length"),
    (lambda: _core.train_lm(np.ones(9), np.ones((4, 2)), np.ones((4, 1)), 2, mu=-1.0), "mu"),
    (lambda: _core.narx_regressors(np.ones((3, 1)), np.ones((3, 1)), 0, 0, 0), "na"),
    (lambda: cdam_core.MinMaxScaler().fit(np.ones((5, 2))).transform(np.ones((5, 3))), "columns"),
])
def test_errors_name_the_problem(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def _float_dtype_variants(a, folder):
    """The same float64 / float32 values under dtype objects that are equal to numpy's own but
    not the same object (an unpickled array, a dtype carrying metadata), a non-native byte
    order, and a memory-mapped file's array."""
    import pickle
    out = {"unpickled": pickle.loads(pickle.dumps(a)),
           "metadata": a.astype(np.dtype(a.dtype.str, metadata={"unit": "rad"})),
           "big-endian": a.astype(a.dtype.newbyteorder(">"))}
    np.save(folder / "a.npy", a)
    out["memmap"] = np.load(folder / "a.npy", mmap_mode="r")
    return out


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_equal_float_dtypes_are_accepted_by_the_bindings(dtype, tmp_path):
    """The bindings compared dtypes by identity, so an unpickled float64 array was refused with
    'dtype float64 is not supported; pass float32 or float64'. Each variant now gives exactly
    the plain array's result."""
    X = np.linspace(-1, 1, 24, dtype=dtype).reshape(12, 2) ** 3
    want = _core.five_point_cubic_smooth(X, 2)
    want_f = _core.mlp_forward(np.linspace(-0.5, 0.5, 13).astype(dtype), X, 3, 1)
    for name, v in _float_dtype_variants(X, tmp_path).items():
        assert v.dtype == X.dtype.newbyteorder(v.dtype.byteorder) or v.dtype == X.dtype
        got = _core.five_point_cubic_smooth(v, 2)
        assert got.dtype == want.dtype, name
        np.testing.assert_array_equal(got, want, err_msg=name)
        np.testing.assert_array_equal(_core.mlp_forward(
            np.linspace(-0.5, 0.5, 13).astype(dtype), v, 3, 1), want_f, err_msg=name)
