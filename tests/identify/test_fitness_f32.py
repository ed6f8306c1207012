"""The float32 BP fitness of the swarm search (issue 23, item 3): `bp_fitness(...,
precision="float32")` against independent numpy computations (float64, and float32 with
np.tanh), its tanh measured in ulps through the public function, the same values at 1, 2 and 3
threads, and `optimise` / `identify` taking the option (same seed, same run at any thread
count)."""
import numpy as np
import pytest

from cdam_core import _core
from cdam_core.identify import IdentifyConfig, identify


def _mse(th, X, T, h, dtype, act="tansig"):
    """Independent numpy MSE of one network in `dtype` (theta = [W1(:); b1; W2(:); b2])."""
    i, m = X.shape[1], T.shape[1]
    th, X, T = (np.asarray(a, dtype=dtype) for a in (th, X, T))
    W1 = th[:i * h].reshape(h, i, order="F")
    b1 = th[i * h:i * h + h]
    W2 = th[i * h + h:i * h + h + h * m].reshape(m, h, order="F")
    b2 = th[i * h + h + h * m:]
    Z = X @ W1.T + b1
    A = np.tanh(Z) if act == "tansig" else 1 / (1 + np.exp(-Z))
    E = T - (A @ W2.T + b2)
    return float(np.sum(E.astype(np.float64) ** 2) / E.size)


@pytest.mark.parametrize("n,i,h,m,act", [(10_000, 6, 20, 8, "tansig"), (1001, 7, 13, 3, "logsig"),
                                         (777, 15, 5, 1, "tansig"), (9, 2, 3, 5, "tansig")])
def test_float32_fitness_agrees_with_numpy_and_is_thread_independent(n, i, h, m, act):
    g = np.random.default_rng(4)
    X = g.uniform(-2, 2, (n, i)).astype(np.float32).astype(np.float64)
    T = g.uniform(-1, 1, (n, m)).astype(np.float32).astype(np.float64)
    D = i * h + h + h * m + m
    th = g.uniform(-1.5, 1.5, (6, D)).astype(np.float32).astype(np.float64)
    outs = [_core.bp_fitness(th, X, T, h, act, threads=t, precision="float32") for t in (1, 2, 3)]
    np.testing.assert_array_equal(outs[0], outs[1])
    np.testing.assert_array_equal(outs[0], outs[2])
    for k in range(len(th)):
        assert outs[0][k] == pytest.approx(_mse(th[k], X, T, h, np.float64, act), rel=2e-6)
        assert outs[0][k] == pytest.approx(_mse(th[k], X, T, h, np.float32, act), rel=2e-5)
    f64 = _core.bp_fitness(th, X, T, h, act, threads=1)
    np.testing.assert_allclose(outs[0], f64, rtol=2e-6)


def test_float32_tanh_within_3_ulps_through_the_public_function():
    # network 1-1-1: W1 = x, b1 = 0, W2 = 1, b2 = -t with t = tanh(x) rounded to float and the
    # inputs all 1, targets 0: each individual's MSE is (tanh_f32(x) - t)^2 (16 equal samples)
    x = np.r_[np.linspace(-12, 12, 30_001), [1e-30, -1e-20, 1e-7, 3e-4, 0.0]].astype(np.float32)
    t = np.tanh(x.astype(np.float64)).astype(np.float32)
    th = np.c_[x, np.zeros_like(x), np.ones_like(x), -t].astype(np.float64)
    mse = _core.bp_fitness(th, np.ones((16, 1)), np.zeros((16, 1)), 1, threads=1,
                           precision="float32")
    err = np.sqrt(mse)      # |tanh_f32(x) - t|, exact differences of nearby floats
    exact = np.tanh(x.astype(np.float64))
    ulp = np.spacing(np.abs(t)).astype(np.float64)
    ulp[t == 0] = np.float64(np.finfo(np.float32).smallest_subnormal)
    total = (err + np.abs(t.astype(np.float64) - exact)) / ulp   # against the exact tanh
    assert total.max() <= 3.0


def test_float32_optimise_same_seed_same_run_any_thread_count():
    g = np.random.default_rng(0)
    X = g.uniform(-1, 1, (3000, 4))
    T = np.c_[np.tanh(X @ [0.5, -0.2, 0.3, 0.1]), X[:, 0] * X[:, 1]]
    runs = [_core.optimise("iboa", "bp", X=X, T=T, hidden=5, seed=3,
                           options={"iterations": 8, "n": 10}, threads=t, precision="float32")
            for t in (1, 2, 3)]
    for r in runs[1:]:
        np.testing.assert_array_equal(r["curve"], runs[0]["curve"])
        np.testing.assert_array_equal(r["best"], runs[0]["best"])
    # the reported best fitness is the float32 MSE of the reported best, checked in float64
    best = runs[0]["best"]
    assert runs[0]["best_fitness"] == pytest.approx(
        _mse(best.astype(np.float32).astype(np.float64), X.astype(np.float32), T.astype(np.float32),
             5, np.float64), rel=2e-6)
    assert np.all(np.diff(runs[0]["curve"]) <= 0)


def test_precision_rejected_by_name():
    X, T = np.zeros((20, 2)), np.zeros((20, 1))
    with pytest.raises(ValueError, match="precision"):
        _core.bp_fitness(np.zeros(2 * 3 + 3 + 3 + 1), X, T, 3, precision="half")
    with pytest.raises(ValueError, match="precision"):
        _core.optimise("iboa", "bp", X=X, T=T, hidden=3, precision="float16")
    with pytest.raises(ValueError, match="fitness_precision"):
        IdentifyConfig(fitness_precision="float16")
    big = X.copy()
    big[3, 1] = 1e300     # fine in float64, beyond the float32 range
    th = np.zeros(2 * 3 + 3 + 3 + 1)
    assert np.isfinite(_core.bp_fitness(th, big, T, 3)[0])
    with pytest.raises(ValueError, match="X: values beyond the float32 range"):
        _core.bp_fitness(th, big, T, 3, precision="float32")
    with pytest.raises(ValueError, match="thetas: values beyond the float32 range"):
        _core.bp_fitness(th + 1e39, X, T, 3, precision="float32")
    with pytest.raises(ValueError, match="T: values beyond the float32 range"):
        _core.optimise("iboa", "bp", X=X, T=T - 1e39, hidden=3, precision="float32")


def test_identify_with_float32_fitness_runs_and_lm_starts_at_its_best():
    g = np.random.default_rng(1)
    U = g.uniform(-1, 1, (400, 2))
    Y = np.c_[np.tanh(1.5 * U[:, 0]) + 0.3 * U[:, 1], U[:, 0] * U[:, 1]]
    cfg = IdentifyConfig(hidden=4, iterations=5, population=8, lm_epochs=10,
                         smoothing_passes=0, fitness_precision="float32", threads=1)
    a = identify("iboa", U, Y, seed=2, config=cfg)
    b = identify("iboa", U, Y, seed=2, config=IdentifyConfig(**{**cfg.to_dict(), "threads": 2,
                                                                 "narx": None,
                                                                 "bounds": (-1.0, 1.0)}))
    np.testing.assert_array_equal(a.curve, b.curve)
    np.testing.assert_array_equal(a.lm_mse, b.lm_mse)
    # LM (double) starts at the optimiser's best: its double MSE is the float32 one to rounding
    assert a.lm_mse[0] == pytest.approx(a.optimiser_mse, rel=1e-5)
    assert np.all(np.diff(a.lm_mse) <= 0)
