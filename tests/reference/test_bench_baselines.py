"""The benchmarks' numpy baselines (benchmarks/numpy_baselines.py) against the reference.

The structured J'J (J never formed) and its LM are new implementations that the speed ratios
divide by, so they must compute the same thing as the plain reference, which forms J."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from cdam_core.reference import mlp_jtj, mlp_num_params, train_lm
from cdam_core.reference.optimisers import BpObjective

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "numpy_baselines.py"


@pytest.fixture(scope="module")
def nb():
    spec = importlib.util.spec_from_file_location("numpy_baselines", _PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _problem(seed, n=60, i=3, h=5, m=4):
    g = np.random.default_rng(seed)
    X = g.uniform(-1, 1, (n, i))
    T = np.tanh(X @ g.normal(size=(i, m))) + 0.05 * g.normal(size=(n, m))
    return g.uniform(-1, 1, mlp_num_params(i, h, m)), X, T, h


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_structured_jtj_equals_jtj_from_explicit_j(nb, seed):
    theta, X, T, h = _problem(seed)
    JtJ, Jte, sse = mlp_jtj(theta, X, T, h)
    S, Se, ssse = nb.jtj_structured(theta, X, T, h)
    np.testing.assert_allclose(S, JtJ, rtol=1e-10, atol=1e-12 * np.abs(JtJ).max())
    np.testing.assert_allclose(Se, Jte, rtol=1e-10, atol=1e-12 * np.abs(Jte).max())
    assert ssse == pytest.approx(sse, rel=1e-12)


@pytest.mark.parametrize("seed,epochs", [(0, 1), (1, 1), (2, 6)])
def test_structured_lm_takes_the_reference_steps(nb, seed, epochs):
    theta, X, T, h = _problem(seed)
    want, hist = train_lm(theta, X, T, h, epochs=epochs)
    got, ghist = nb.train_lm_structured(theta, X, T, h, epochs=epochs)
    assert hist["stop"] == ghist["stop"] == "epochs"
    assert not np.allclose(want, theta)          # the step moved theta: the check has teeth
    # one step to rtol 1e-10; over several epochs the rounding is amplified by J'J's condition,
    # so there the tolerance is 1e-10 of the largest weight
    atol = 1e-12 if epochs == 1 else 1e-10 * np.abs(want).max()
    np.testing.assert_allclose(got - theta, want - theta, rtol=1e-10, atol=atol)
    np.testing.assert_allclose(ghist["mse"], hist["mse"], rtol=1e-10)
    np.testing.assert_allclose(ghist["mu"], hist["mu"], rtol=0)


def test_batched_fitness_equals_one_network_at_a_time(nb):
    theta, X, T, h = _problem(3)
    thetas = np.random.default_rng(4).uniform(-1, 1, (7, theta.size))
    f = BpObjective(X, T, h)
    want = np.array([f(t) for t in thetas])
    np.testing.assert_allclose(nb.fitness_batched(thetas, X, T, h), want, rtol=1e-12)
    np.testing.assert_allclose(nb.fitness_loop(thetas, X, T, h), want, rtol=1e-12)
