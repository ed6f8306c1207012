"""The k-step benchmark's numpy reference (benchmarks/bench_kstep.py: chunked sensitivities with
one dsyrk per chunk, trainlm's loop) computes what the core computes, so its ratio compares
like with like."""
import importlib.util
import sys
from pathlib import Path

import numpy as np

from cdam_core import _core
from cdam_core.reference.kstep import kstep_num_params

_DIR = Path(__file__).resolve().parents[2] / "benchmarks"


def _bench():
    sys.path.insert(0, str(_DIR))
    try:
        spec = importlib.util.spec_from_file_location("bench_kstep", _DIR / "bench_kstep.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    finally:
        sys.path.remove(str(_DIR))
    return mod


def _args(seed=0, N=2000, ns=3, ne=6, H=5, K=10):
    rng = np.random.default_rng(seed)
    S = np.cumsum(rng.normal(size=(N, ns)), 0) * 0.05
    E = rng.normal(size=(N, ne))
    Dr = rng.normal(size=(N, ns)) * 0.01
    starts = np.arange(0, N - K - 1, K).astype(np.int64)
    theta = rng.uniform(-0.3, 0.3, kstep_num_params(ns, ne, H))
    return theta, (S, E, Dr, starts, K, H, np.zeros(ns), np.ones(ns), np.full(ns, 0.05),
                   np.ones(ns))


def test_numpy_reference_equals_the_core():
    b = _bench()
    theta, args = _args()
    jtj, jte, sse = b._normal_numpy(theta, args, chunk=37)
    cj, ce, cs = _core.kstep_normal(theta, *args)
    np.testing.assert_allclose(np.tril(jtj), np.tril(cj), rtol=1e-10, atol=1e-10 * np.abs(cj).max())
    np.testing.assert_allclose(jte, ce, rtol=1e-10, atol=1e-10 * np.abs(ce).max())
    assert sse == np.float64(cs) or abs(sse - cs) < 1e-10 * cs
    th_np = b._lm_numpy(theta, args, 3)
    th_c, _ = _core.kstep_train_lm(theta, *args, epochs=3)
    np.testing.assert_allclose(th_np, th_c, rtol=0, atol=1e-7 * np.abs(th_c).max())


def test_numpy_reference_with_a_linear_part_equals_the_core():
    """kstep_anchored_epoch's reference: the ARX-anchored form (a linear part of 2 lags, per-step
    error scales)."""
    b = _bench()
    theta, args = _args(seed=1, ns=4, K=8)
    rng = np.random.default_rng(2)
    lin = rng.normal(size=(4, 8)) * 0.1
    args = args[:9] + (rng.uniform(0.5, 2.0, (8, 4)),)
    starts = args[3][args[3] >= 1]
    args = args[:3] + (starts,) + args[4:]
    jtj, jte, sse = b._normal_numpy(theta, args, chunk=37, lin=lin)
    cj, ce, cs = _core.kstep_normal(theta, *args, lin=lin)
    np.testing.assert_allclose(np.tril(jtj), np.tril(cj), rtol=1e-10, atol=1e-10 * np.abs(cj).max())
    np.testing.assert_allclose(jte, ce, rtol=1e-10, atol=1e-10 * np.abs(ce).max())
    assert abs(sse - cs) < 1e-10 * cs
    th_np = b._lm_numpy(theta, args, 3, lin=lin, chunk=37)
    th_c, _ = _core.kstep_train_lm(theta, *args, epochs=3, lin=lin)
    np.testing.assert_allclose(th_np, th_c, rtol=0, atol=1e-7 * np.abs(th_c).max())
