"""Child of the Python-API fuzz: hypothesis draws arrays, lists, texts and numbers for the public
Python functions (models, preprocessing, records, metrics, orders, segments, units, column
maps); prints the count of calls and of each exception type as one JSON line at the end.
Before each call it writes the function name to stdout, so a crash names its last call.
A named error is a ValueError (or a subclass of the package's, not numpy's LinAlgError, whose
messages name nothing); anything else is counted as ``other:``."""
import json
import sys
import warnings

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes, arrays

import cdam_core
from cdam_core.base.metrics import output_metrics
from cdam_core.base.orders import parse_orders
from cdam_core.models.protocol import segment_bounds
from cdam_core.record.columns import check_segments, gap_cuts, parse_column_map
from cdam_core.record.dataset import Dataset
from cdam_core.record.merge import estimate_offset
from cdam_core.record.resample import find_gaps, resample, uniform_grid
from cdam_core.record.units import check_standard_units

N = int(sys.argv[1])
counts = {"calls": 0}
dtypes = st.sampled_from([np.float64, np.float32, np.int64, np.bool_])
values = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-3, 3))


@st.composite
def arr(draw):
    shape = draw(array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=9))
    return draw(arrays(draw(dtypes), shape))


@st.composite
def good(draw):
    """A consistent record now and then hostile: (t, U, Y)."""
    n = draw(st.integers(0, 60))
    i, m = draw(st.integers(1, 2)), draw(st.integers(1, 2))
    el = st.one_of(st.floats(-5, 5), st.sampled_from([np.nan, np.inf, 1e300, 0.0]))
    el = st.floats(-5, 5) if draw(st.booleans()) else el
    t = np.cumsum(draw(arrays(np.float64, (n,), elements=st.floats(1e-3, 0.1))))
    return t, draw(arrays(np.float64, (n, i), elements=el)), draw(arrays(np.float64, (n, m),
                                                                          elements=el))


objs = st.one_of(st.none(), st.integers(-3, 2 ** 40), st.floats(allow_nan=True), st.text(max_size=8),
                 st.lists(st.integers(-2, 50), max_size=4),
                 st.lists(st.lists(st.integers(-2, 50), max_size=3), max_size=4),
                 st.dictionaries(st.text(max_size=4), st.text(max_size=6), max_size=3))


def call(name, f, *a, **k):
    counts["calls"] += 1
    print(name, flush=True)
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            f(*a, **k)
        key = "ok"
    except np.linalg.LinAlgError as exc:    # a ValueError, but numpy's, naming nothing
        key = f"other:{name}:LinAlgError:{str(exc)[:80]}"
    except ValueError as exc:
        key = type(exc).__name__
    except BaseException as exc:       # noqa: BLE001 - counted, judged by the parent
        key = f"other:{name}:{type(exc).__name__}:{str(exc)[:80]}"
    counts[key] = counts.get(key, 0) + 1


def _arx(a, b, orders, mode):
    m = cdam_core.ArxModel(orders).fit(a, b)
    return m.predict(a, b, mode=mode, k=2)


def _net(a, b, h, orders):
    return cdam_core.BPNetwork(hidden=h, epochs=2, narx=orders, seed=0).fit(a, b).predict(a)


@settings(max_examples=N, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(a=arr(), b=arr(), o=objs, p=objs, x=values, i=st.integers(-2, 6), j=st.integers(-2, 6),
       txt=st.text(max_size=30), mode=st.sampled_from(["one_step", "k_step", "free_run", "x"]))
def campaign(a, b, o, p, x, i, j, txt, mode):
    call("five_point_cubic_smooth", cdam_core.five_point_cubic_smooth, a, i)
    call("MinMaxScaler", lambda: cdam_core.MinMaxScaler().fit(a).transform(b))
    call("ArxModel", _arx, a, b, (i, j, 1), mode)
    call("BPNetwork", _net, a, b, i, o)
    call("segment_bounds", segment_bounds, o, i)
    call("check_segments", check_segments, o, i)
    call("parse_column_map", parse_column_map, txt)
    call("parse_orders", parse_orders, o)
    call("output_metrics", output_metrics, a, b)
    call("Dataset", Dataset, t=a, columns=[txt or "c"], data=b, meta={"units": o} if p else {})
    call("resample", resample, a, b, a, txt or "linear")
    call("find_gaps", find_gaps, a, x)
    call("uniform_grid", uniform_grid, x, x + abs(i), abs(j) + 1e-3)
    call("gap_cuts", gap_cuts, {"gaps": o, "gapless_rows": p}, np.sort(np.ravel(a)[:50]), "f")
    call("check_standard_units", check_standard_units, o if isinstance(o, dict) else {}, [txt], "f")
    call("estimate_offset", estimate_offset, a, b, a, b)


@settings(max_examples=N, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(r=good(), na=st.integers(0, 3), nb=st.integers(0, 3), nk=st.integers(0, 2),
       mode=st.sampled_from(["one_step", "k_step", "free_run"]), seg=st.integers(1, 4))
def campaign_valid(r, na, nb, nk, mode, seg):
    t, U, Y = r
    n = len(t)
    segs = [n // seg] * (seg - 1) + [n - (n // seg) * (seg - 1)] if n else None
    call("ArxModel", _arx, U, Y, (na, nb, nk), mode)
    call("ArxModel.segments", lambda: cdam_core.ArxModel((na, nb, nk)).fit(
        U, Y, segments=segs).predict(U, Y, mode=mode, k=2, segments=segs))
    call("BPNetwork", _net, U, Y, 2, (na, nb, nk) if na + nb else None)
    call("Dataset", Dataset, t=t, columns=[f"c{k}" for k in range(U.shape[1])], data=U,
         meta={"segments": [[0, n]] if n else []})
    call("output_metrics", output_metrics, Y, U[:, :Y.shape[1]] if U.shape[1] >= Y.shape[1] else Y)
    call("five_point_cubic_smooth", cdam_core.five_point_cubic_smooth, U, na)
    call("estimate_offset", estimate_offset, t, U[:, 0], t, Y[:, 0])
    call("find_gaps", find_gaps, t, 0.05)
    call("resample", resample, t, U[:, 0], t[::2] if n else t, "angle")


campaign()
campaign_valid()
print(json.dumps(counts), flush=True)
