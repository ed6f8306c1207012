"""Child of the binding fuzz: hypothesis draws arrays, sizes and options for every `_core`
function; prints the count of calls and of each exception type as one JSON line at the end.
Before each call it writes the function name to stdout, so a crash names its last call."""
import json
import sys
import warnings

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes, arrays

from cdam_core import _core

N = int(sys.argv[1])
dtypes = st.sampled_from([np.float64, np.float32, np.int64, np.bool_])
floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-3, 3))


@st.composite
def arr(draw):
    shape = draw(array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=7))
    return draw(arrays(draw(dtypes), shape, elements=st.floats(-1e6, 1e6) if False else None))


ints = st.one_of(st.integers(-3, 6), st.sampled_from([0, 2 ** 31 - 1, -2 ** 31, 2 ** 40]))
acts = st.sampled_from(["tansig", "logsig", "purelin", "relu", "", "x" * 100])
counts = {"calls": 0}


def call(name, f, *a, **k):
    counts["calls"] += 1
    print(name, flush=True)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            f(*a, **k)
        key = "ok"
    except (ValueError, TypeError, OverflowError) as exc:
        key = type(exc).__name__
    except BaseException as exc:       # noqa: BLE001 - counted, judged by the parent
        key = f"other:{type(exc).__name__}:{str(exc)[:80]}"
    counts[key] = counts.get(key, 0) + 1


@settings(max_examples=N, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(a=arr(), b=arr(), c=arr(), i=ints, j=ints, k=ints, x=floats, act=acts)
def campaign(a, b, c, i, j, k, x, act):
    c_ = _core
    call("bp_fitness", c_.bp_fitness, a, b, c, i, act, threads=1)
    call("five_point_cubic_smooth", c_.five_point_cubic_smooth, a, passes=min(i, 3))
    call("minmax_apply", c_.minmax_apply, a, b, c)
    call("minmax_fit", c_.minmax_fit, a)
    call("mlp_forward", c_.mlp_forward, a, b, i, j, act)
    call("mlp_jacobian", c_.mlp_jacobian, a, b, i, j, act)
    call("mlp_jtj", c_.mlp_jtj, a, b, c, i, act, threads=1)
    call("mlp_mse_gradient", c_.mlp_mse_gradient, a, b, c, i, act)
    call("mlp_num_params", c_.mlp_num_params, i, j, k)
    call("narx_regressors", c_.narx_regressors, a, b, i, j, k)
    call("narx_simulate", c_.narx_simulate, a, b, c, i, act, j, k, min(i, 3))
    call("train_lm", c_.train_lm, a, b, c, i, act, epochs=2, threads=1, mu=x)
    call("train_gd", c_.train_gd, a, b, c, i, act, epochs=2, threads=1, lr=x)
    call("optimise", c_.optimise, act or "iboa", "bp", X=b, T=c, hidden=i, dim=j, seed=k,
         options={"iterations": 2, "population": 3}, threads=1)
    call("sim_open_loop", c_.sim_open_loop, a, b, c, x, min(abs(i), 4))
    call("sim_closed_loop", c_.sim_closed_loop, a, b, c, a, x, min(abs(i), 4))
    call("sim_rhs", c_.sim_rhs, a, x, b, c)
    call("sim_fastest_rate", c_.sim_fastest_rate, a)
    call("sim_substeps", c_.sim_substeps, a, x)


@st.composite
def problem(draw):
    """Consistent shapes (a network, its data) with hostile values now and then."""
    n_in, h, m = draw(st.integers(1, 3)), draw(st.integers(1, 4)), draw(st.integers(1, 3))
    n = draw(st.integers(0, 40))
    el = st.one_of(st.floats(-5, 5), st.sampled_from([np.nan, np.inf, -np.inf, 1e300, 0.0]))
    el = st.floats(-5, 5) if draw(st.booleans()) else el
    p = (n_in + 1) * h + (h + 1) * m
    theta = draw(arrays(np.float64, (p + draw(st.sampled_from([0, 0, 0, 1, -1])),), elements=el))
    X = draw(arrays(np.float64, (n, n_in), elements=el))
    T = draw(arrays(np.float64, (n, m), elements=el))
    return n_in, h, m, theta, X, T


@settings(max_examples=N, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(pr=problem(), act=st.sampled_from(["tansig", "logsig", "purelin"]), x=floats,
       na=st.integers(0, 3), nb=st.integers(0, 3), nk=st.integers(0, 2))
def campaign_valid(pr, act, x, na, nb, nk):
    n_in, h, m, theta, X, T = pr
    c_ = _core
    call("mlp_forward", c_.mlp_forward, theta, X, h, m, act)
    call("mlp_jacobian", c_.mlp_jacobian, theta, X, h, m, act)
    call("mlp_jtj", c_.mlp_jtj, theta, X, T, h, act, threads=2)
    call("mlp_mse_gradient", c_.mlp_mse_gradient, theta, X, T, h, act)
    call("bp_fitness", c_.bp_fitness, theta[None, :], X, T, h, act, threads=2)
    call("train_lm", c_.train_lm, theta, X, T, h, act, epochs=3, threads=2)
    call("train_gd", c_.train_gd, theta, X, T, h, act, epochs=3, lr=abs(x) % 1, threads=2)
    call("five_point_cubic_smooth", c_.five_point_cubic_smooth, X, passes=na)
    call("minmax_fit", c_.minmax_fit, X)
    call("narx_regressors", c_.narx_regressors, X, T, na, nb, nk)
    call("optimise", c_.optimise, "iboa", "bp", X=X, T=T, hidden=h, seed=na,
         options={"iterations": 2, "population": 4}, threads=2)


campaign()
campaign_valid()
print(json.dumps(counts), flush=True)
