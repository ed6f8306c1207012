"""Random shapes, dtypes and values thrown at every reference function: ValueError or a result."""
import warnings

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes, arrays

from cdam_core import reference as ref

dtypes = st.sampled_from([np.float64, np.float32, np.int32, np.bool_, np.complex128])


@st.composite
def any_array(draw):
    dtype = draw(dtypes)
    shape = draw(array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=6))
    return draw(arrays(dtype, shape))


small_int = st.one_of(st.integers(-2, 4), st.just(1.5), st.none())
act = st.sampled_from(["tansig", "logsig", "relu", None])


def call(f, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            f(*args, **kw)
        except ValueError:
            pass


@settings(max_examples=150, deadline=None)
@given(a=any_array(), b=any_array(), c=any_array(), n1=small_int, n2=small_int, n3=small_int,
       n4=small_int, activation=act)
def test_every_function_raises_only_value_error(a, b, c, n1, n2, n3, n4, activation):
    call(ref.five_point_cubic_smooth, a, passes=n1)
    call(ref.MinMaxScaler().fit, a)
    call(ref.mlp_num_params, n1, n2, n3)
    call(ref.mlp_unpack, a, n1, n2, n3)
    call(ref.mlp_forward, a, b, n1, n2, activation)
    call(ref.mlp_jacobian, a, b, n1, n2, activation)
    call(ref.mlp_mse_gradient, a, b, c, n1, activation)
    call(ref.mlp_jtj, a, b, c, n1, activation)
    call(ref.train_lm, a, b, c, n1, activation, epochs=2)
    call(ref.train_gd, a, b, c, n1, activation, epochs=2)
    call(ref.narx_regressors, a, b, n1, n2, n3)
    call(ref.narx_simulate, a, b, c, n4, activation, n1, n2, n3)
    call(ref.Rng, n1)


@settings(max_examples=100, deadline=None)
@given(fit=any_array(), other=any_array())
def test_scaler_transform_raises_only_value_error(fit, other):
    s = ref.MinMaxScaler()
    call(s.transform, other)
    try:
        s.fit(fit)
    except ValueError:
        return
    call(s.transform, other)
    call(s.inverse_transform, other)
