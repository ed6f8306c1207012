"""C++ optimisers (BOA, IBOA, CABC) and BP fitness against the numpy twins and closed forms."""
import numpy as np
import pytest

from cdam_core import _core
from cdam_core.reference import optimisers as ref
from cdam_core.reference.rng import Rng


def _data(n=80, seed=0):
    g = np.random.default_rng(seed)
    X = g.uniform(-1, 1, (n, 3))
    T = np.c_[np.tanh(X @ [0.8, -0.5, 0.3]), X[:, 0] * X[:, 1]]
    return X, T


CASES = [("boa", {}), ("boa", {"form": "paper"}), ("iboa", {}),
         ("iboa", {"form": "paper", "chaos_form": "additive", "clusters": 2}),
         ("cabc", {}), ("cabc", {"limit": 1, "scout_candidates": 3})]


@pytest.mark.parametrize("algo,opts", CASES)
def test_core_curve_equals_numpy_twin_on_bp_fitness(algo, opts):
    X, T = _data()
    opts = dict(opts, iterations=15, n=10)
    a = _core.optimise(algo, "bp", X=X, T=T, hidden=4, seed=7, options=opts)
    f = ref.BpObjective(X, T, 4)
    b = getattr(ref, algo)(f, f.dim, seed=7, options=opts)
    np.testing.assert_allclose(a["curve"], b["curve"], rtol=1e-9, atol=0)
    assert a["evaluations"] == b["evaluations"]
    np.testing.assert_allclose(a["best"], b["best"], rtol=1e-9, atol=1e-12)
    # the reported best fitness is the MSE of the reported best, computed independently
    W1 = a["best"][:12].reshape(4, 3, order="F")
    b1 = a["best"][12:16]
    W2 = a["best"][16:24].reshape(2, 4, order="F")
    b2 = a["best"][24:26]
    Y = np.tanh(X @ W1.T + b1) @ W2.T + b2
    assert a["best_fitness"] == pytest.approx(np.mean((T - Y) ** 2), rel=1e-12)
    assert np.all(np.diff(a["curve"]) <= 0)


@pytest.mark.parametrize("algo", ["boa", "iboa", "cabc"])
def test_sphere_curves_match_exactly_and_descend(algo):
    sph = lambda x: float(np.sum(x ** 2))  # noqa: E731
    a = _core.optimise(algo, "sphere", dim=4, seed=3, options={"iterations": 40})
    b = getattr(ref, algo)(sph, 4, seed=3, options={"iterations": 40})
    np.testing.assert_allclose(a["curve"], b["curve"], rtol=1e-12)
    assert a["curve"][-1] < 0.2 * a["curve"][0]
    assert a["best_fitness"] == pytest.approx(np.sum(a["best"] ** 2), rel=1e-14)


def test_iboa_finds_the_sphere_minimum():
    res = _core.optimise("iboa", "sphere", dim=5, seed=1, options={"iterations": 100})
    assert res["best_fitness"] < 1e-3  # minimum 0 at the origin
    assert res["positions"].shape == (20, 5)


def test_same_seed_same_run_other_seed_other_run():
    X, T = _data()
    a = _core.optimise("iboa", "bp", X=X, T=T, hidden=3, seed=5, options={"iterations": 5})
    b = _core.optimise("iboa", "bp", X=X, T=T, hidden=3, seed=5, options={"iterations": 5},
                       threads=1)
    c = _core.optimise("iboa", "bp", X=X, T=T, hidden=3, seed=6, options={"iterations": 5})
    np.testing.assert_array_equal(a["curve"], b["curve"])
    assert not np.array_equal(a["best"], c["best"])


def test_bp_fitness_matches_numpy_and_is_thread_independent():
    g = np.random.default_rng(2)
    X = g.uniform(-1, 1, (5000, 6))
    T = g.uniform(-1, 1, (5000, 8))
    th = g.uniform(-1, 1, (5, 6 * 7 + 7 + 7 * 8 + 8))
    f1 = _core.bp_fitness(th, X, T, 7, threads=1)
    f2 = _core.bp_fitness(th, X, T, 7, threads=2)
    np.testing.assert_array_equal(f1, f2)
    for k in range(5):
        W1 = th[k, :42].reshape(7, 6, order="F")
        b1 = th[k, 42:49]
        W2 = th[k, 49:105].reshape(8, 7, order="F")
        b2 = th[k, 105:]
        Y = np.tanh(X @ W1.T + b1) @ W2.T + b2
        assert f1[k] == pytest.approx(np.mean((T - Y) ** 2), rel=1e-13)
    assert _core.bp_fitness(th[0], X, T, 7)[0] == f1[0]
    lg = _core.bp_fitness(th[:1], X, T, 7, activation="logsig")[0]
    Y = (1 / (1 + np.exp(-(X @ th[0, :42].reshape(7, 6, order="F").T + th[0, 42:49])))
         @ th[0, 49:105].reshape(8, 7, order="F").T + th[0, 105:])
    assert lg == pytest.approx(np.mean((T - Y) ** 2), rel=1e-13)


def test_reference_kmeans_separates_blobs():
    x = np.r_[np.full((5, 2), -5.0), np.full((5, 2), 5.0)] + np.arange(10)[:, None] * 0.01
    centres, label = ref.kmeans(x, 2, 10, Rng(4))
    assert len(set(label[:5])) == 1 and len(set(label[5:])) == 1 and label[0] != label[5]
    np.testing.assert_allclose(centres[label[0]], x[:5].mean(axis=0))


def test_logistic_map_twin():
    m = ref.LogisticMap(0.3)
    assert m.next() == pytest.approx(4 * 0.3 * 0.7)
    m.z = 0.75
    assert m.next() == ref.LogisticMap.FALLBACK  # 0.75 is a fixed point: guarded


@pytest.mark.parametrize("kwargs,match", [
    ({"algorithm": "pso"}, "algorithm"),
    ({"options": {"bogus": 1}}, "unknown key"),
    ({"options": {"n": 1}}, "options"),
    ({"options": {"lb": 1.0, "ub": -1.0}}, "options"),
    ({"options": {"form": "x"}}, "form"),
    ({"seed": -1}, "seed"),
    ({"X": np.full((10, 3), np.nan)}, "X"),
    ({"T": np.zeros((9, 2))}, "T"),
    ({"hidden": 0}, "hidden"),
])
def test_core_rejects_bad_input(kwargs, match):
    X, T = _data(10)
    args = {"algorithm": "boa", "X": X, "T": T, "hidden": 2, "options": {"iterations": 2}}
    args.update(kwargs)
    algo = args.pop("algorithm")
    with pytest.raises(ValueError, match=match):
        _core.optimise(algo, "bp", **args)


@pytest.mark.parametrize("algo,opts,match", [
    ("boa", {"bogus": 1}, "unknown key"), ("iboa", {"clusters": 50}, "clusters"),
    ("cabc", {"n": 2}, "n"), ("boa", {"form": "x"}, "form"), ("boa", {"n": 2.5}, "integer"),
])
def test_reference_rejects_bad_options(algo, opts, match):
    with pytest.raises(ValueError, match=match):
        getattr(ref, algo)(lambda x: 0.0, 2, options=opts)
    with pytest.raises(ValueError, match="objective"):
        ref.boa(3, 2)
