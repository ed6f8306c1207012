"""BPNetwork behaviour: trainlm semantics seen from the estimator, NARX, hidden-node rule."""
import math

import numpy as np
import pytest

import cdam_core
from cdam_core import BPNetwork, hidden_node_candidates


def linear_system(n, seed):
    """y(t) = 0.7 y(t-1) + 0.2 u(t-1): a NARX(1,1,1) network with tanh can represent it closely."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n // 10 + 1), 10)[:n]
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.7 * y[t - 1] + 0.2 * u[t - 1]
    return u[:, None], y[:, None]


def test_hidden_node_rule_closed_form():
    # h = sqrt(i + m) + a rounded: i = 6, m = 8 -> sqrt(14) = 3.742
    assert hidden_node_candidates(6, 8, [1, 2, 10]) == [5, 6, 14]
    assert hidden_node_candidates(1, 3, [1]) == [3]  # sqrt(4) + 1


def test_hidden_auto_keeps_the_lowest_training_mse():
    rng = np.random.default_rng(0)
    U = rng.uniform(-1, 1, (300, 2))
    Y = np.sin(3 * U[:, :1]) * U[:, 1:]
    net = BPNetwork(hidden="auto", epochs=20).fit(U, Y)
    finals = {h: BPNetwork(hidden=h, epochs=20).fit(U, Y).history_["mse"][-1]
              for h in hidden_node_candidates(2, 1)}
    assert net.hidden_ == min(finals, key=finals.get)


def test_validation_returns_best_validation_weights():
    rng = np.random.default_rng(1)
    U = rng.uniform(-1, 1, (60, 3))
    Y = U[:, :1] + 0.3 * rng.standard_normal((60, 1))  # noisy: a 15-node net overfits
    Uv = rng.uniform(-1, 1, (200, 3))
    Yv = Uv[:, :1] + 0.3 * rng.standard_normal((200, 1))
    net = BPNetwork(hidden=15, epochs=200, max_fail=4).fit(U, Y, validation=(Uv, Yv))
    h = net.history_
    assert h["stop"] == "max_fail"
    best = h["best_epoch"]
    assert h["val_mse"][best] == pytest.approx(np.nanmin(h["val_mse"]))
    # the returned weights give the best validation MSE (recomputed independently in numpy)
    P = net.predict(Uv)
    lo, hi = Yv.min(), Yv.max()
    scaled_err = 2 * (Yv - P) / (Y.max() - Y.min())
    assert np.mean(scaled_err**2) == pytest.approx(h["val_mse"][best], rel=1e-6)
    assert lo < hi


def test_lm_goal_stop_and_mu_schedule():
    rng = np.random.default_rng(2)
    U = rng.uniform(-1, 1, (200, 2))
    Y = np.tanh(U @ [[0.8], [-0.4]])
    net = BPNetwork(hidden=3, epochs=100, goal=1e-6).fit(U, Y)
    h = net.history_
    assert h["stop"] == "goal" and h["mse"][-1] <= 1e-6
    mu = h["mu"]
    # trainlm: after each epoch mu is either divided by 10 (first trial accepted) or went up by
    # factors of 10 and then down once: always a power of 10 times the start
    k = np.log10(mu / 1e-3)
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)


def test_gradient_descent_baseline_is_slower_than_lm():
    rng = np.random.default_rng(3)
    U = rng.uniform(-1, 1, (300, 2))
    Y = np.sin(2 * U[:, :1]) + U[:, 1:] ** 2
    lm = BPNetwork(hidden=6, epochs=30, seed=1).fit(U, Y)
    gd = BPNetwork(hidden=6, epochs=30, trainer="gd", lr=0.05, seed=1).fit(U, Y)
    assert gd.history_["mse"][-1] < gd.history_["mse"][0]
    assert lm.history_["mse"][-1] < gd.history_["mse"][-1]


def test_narx_free_run_reproduces_a_linear_system():
    U, Y = linear_system(3000, 0)
    Ut, Yt = linear_system(1000, 1)
    net = BPNetwork(hidden=3, epochs=100, narx=(1, 1, 1)).fit(U, Y)
    P = net.predict(Ut, Yt, mode="free_run")
    rmse = math.sqrt(np.mean((P - Yt) ** 2))
    assert rmse < 0.01 * np.std(Yt) * 10
    # the free run only used Yt[:t0]: changing later measurements changes nothing
    Y2 = Yt.copy()
    Y2[5:] = 0
    np.testing.assert_array_equal(net.predict(Ut, Y2, mode="free_run"), P)


def test_static_network_cannot_represent_dynamics_but_narx_can():
    U, Y = linear_system(3000, 0)
    static = BPNetwork(hidden=5, epochs=50).fit(U, Y)
    narx = BPNetwork(hidden=5, epochs=50, narx=(1, 1, 1)).fit(U, Y)
    assert narx.score(U, Y, mode="free_run") > static.score(U, Y) + 0.05


def test_float32_stays_float32():
    rng = np.random.default_rng(5)
    U = rng.uniform(-1, 1, (100, 2)).astype(np.float32)
    Y = (U[:, :1] * 2).astype(np.float32)
    net = BPNetwork(hidden=3, epochs=5).fit(U, Y)
    assert net.theta_.dtype == np.float32
    assert net.predict(U).dtype == np.float32


def test_same_seed_same_result():
    rng = np.random.default_rng(6)
    U = rng.uniform(-1, 1, (500, 3))
    Y = np.sin(U.sum(1, keepdims=True))
    a = BPNetwork(hidden=6, epochs=10, seed=4).fit(U, Y)
    b = BPNetwork(hidden=6, epochs=10, seed=4).fit(U, Y)
    np.testing.assert_array_equal(a.theta_, b.theta_)
    c = BPNetwork(hidden=6, epochs=10, seed=5).fit(U, Y)
    assert not np.array_equal(a.theta_, c.theta_)


def test_callback_can_stop_training():
    rng = np.random.default_rng(7)
    U = rng.uniform(-1, 1, (100, 2))
    seen = []
    net = BPNetwork(hidden=3, epochs=50).fit(U, U[:, :1], callback=lambda e, m: seen.append(e) or e < 3)
    assert net.history_["stop"] == "cancelled" and seen == [0, 1, 2, 3]


def test_reference_names_exist():
    from cdam_core import reference
    for name in ("five_point_cubic_smooth", "MinMaxScaler"):
        assert hasattr(reference, name) and hasattr(cdam_core, name)
