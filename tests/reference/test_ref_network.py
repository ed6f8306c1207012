"""The reference BPNetwork (package estimator on the numpy kernels): end-to-end smoke tests."""
import subprocess
import sys

import numpy as np
import pytest

from cdam_core import reference as ref


def test_static_fit_of_a_smooth_map_and_same_seed_same_result():
    rng = np.random.default_rng(0)
    U = rng.uniform(-1, 1, (150, 2))
    Y = np.sin(U @ [[1.0], [2.0]])
    a = ref.BPNetwork(hidden=4, epochs=40, seed=3).fit(U, Y)
    b = ref.BPNetwork(hidden=4, epochs=40, seed=3).fit(U, Y)
    assert a.score(U, Y) > 0.999
    np.testing.assert_array_equal(a.theta_, b.theta_)
    np.testing.assert_array_equal(a.history_["mse"], b.history_["mse"])
    # initial weights are Rng(seed).uniform_array(D, -1, 1) (DESIGN.md draw order)
    _, hist0 = ref.train_lm(ref.Rng(3).uniform_array(17, -1.0, 1.0),
                            a.scaler_x_.transform(U), a.scaler_y_.transform(Y), 4, epochs=0)
    assert a.history_["mse"][0] == pytest.approx(hist0["mse"][0], rel=1e-12)


def test_narx_free_run_of_a_known_first_order_system():
    rng = np.random.default_rng(1)
    u = rng.uniform(-1, 1, (300, 1))
    y = np.zeros((300, 1))
    for t in range(1, 300):
        y[t] = 0.8 * y[t - 1] + 0.5 * np.tanh(u[t - 1])
    net = ref.BPNetwork(hidden=3, epochs=60, narx=(1, 1, 1)).fit(u, y)
    assert net.score(u, y, mode="free_run") > 0.99


def test_reference_never_loads_the_compiled_core():
    code = ("import sys, numpy as np\n"
            "from cdam_core import reference as ref\n"
            "U = np.linspace(-1, 1, 40)[:, None]\n"
            "ref.BPNetwork(hidden=2, epochs=3).fit(U, U**2).predict(U)\n"
            "ref.five_point_cubic_smooth(U)\n"
            "assert 'cdam_core._core' not in sys.modules, 'reference loaded _core'\n")
    env = {"PYTHONPATH": ":".join(p for p in sys.path if p)}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       timeout=60)
    assert r.returncode == 0, r.stderr
