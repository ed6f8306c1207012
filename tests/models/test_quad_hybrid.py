"""The physics + network flight model (kind quad_hybrid, models/flight/hybrid.py) on flights of
the independent generator (tests/models/quad_generator.py): with the network's weights at zero
it is the physics (QuadPhysics without the coupling, separate code); its numpy prediction is the
rollout the core trained (_core.kstep_jacobian's residuals); trained on the k-step error it
learns an actuation lag the physics lacks (held-out flight; measured when written: rate RMSE
0.042 / 0.099 / 0.175 rad/s at k = 1 / 5 / 20 against the physics' 0.051 / 0.173 / 0.435); same
result at 1 and 2 threads; bad input named."""
from functools import lru_cache

import numpy as np
import pytest

from cdam_core import _core
from cdam_core.models import QuadHybrid, QuadPhysics

from quad_generator import flight


@lru_cache(maxsize=None)
def _flights():
    train = flight(20.0, seed=1, lag=0.04)
    test = flight(10.0, seed=2, lag=0.04)
    return train[:2], test[:2]


def _fit(**kw):
    (U, Y), _ = _flights()
    args = dict(hidden=6, horizon=20, lags=4, epochs=12, stride=5)
    args.update(kw)
    return QuadHybrid(**args).fit(U, Y)


@lru_cache(maxsize=None)
def _fitted():
    return _fit()


def _rate_rmse(model, U, Y, k):
    P = model.predict(U, Y, mode="k_step", k=k)
    skip = max(model.t0, 6) + k
    return float(np.sqrt(np.mean((P[skip:, 10:13] - Y[skip:, 10:13]) ** 2)))


def test_zero_network_is_the_physics():
    (U, Y), _ = _flights()
    m = _fit(epochs=0)
    m.theta_ = np.zeros_like(m.theta_)
    ref = QuadPhysics(gyro=False).fit(U, Y)
    for k in (1, 7):
        P, R = m.predict(U, Y, mode="k_step", k=k), ref.predict(U, Y, mode="k_step", k=k)
        rows = slice(m.t0 + k, None)
        np.testing.assert_allclose(P[rows], R[rows], rtol=0, atol=1e-9)


def test_prediction_is_the_rollout_the_core_trained():
    (U, Y), _ = _flights()
    m = _fitted()
    K, starts = 8, np.array([40, 333, 1200])
    rows = np.arange(m.t0 - 1, len(U) - 1)
    E, Dr = np.zeros((len(U), 3 * m.lags)), np.zeros((len(U), 3))
    E[rows], Dr[rows] = m._features(U, rows), m._drift(U, rows)
    e, _ = _core.kstep_jacobian(m.theta_, np.ascontiguousarray(Y[:, 10:13]), E, Dr, starts, K,
                                m.hidden, m.in_mean_, m.in_scale_, m.out_scale_, m.err_scale_)
    e = e.reshape(len(starts), K, 3) * m.err_scale_
    for w, a in enumerate(starts):
        for j in (0, K - 1):
            P = m.predict(U, Y, mode="k_step", k=j + 1)
            np.testing.assert_allclose(Y[a + j + 1, 10:13] - P[a + j + 1, 10:13], e[w, j],
                                       rtol=0, atol=1e-10)


def test_k_step_training_learns_the_actuation_lag_on_a_held_out_flight():
    _, (U, Y) = _flights()
    m = _fitted()
    prior = QuadPhysics(gyro=False).fit(*_flights()[0])
    for k in (5, 20):
        ours, phys = _rate_rmse(m, U, Y, k), _rate_rmse(prior, U, Y, k)
        assert ours < 0.8 * phys, (k, ours, phys)
    assert m.history_["mse"][-1] < 0.5 * m.history_["mse"][0]


def test_same_seed_same_result_at_one_and_two_threads():
    a, b = _fit(epochs=3, threads=1), _fit(epochs=3, threads=2)
    assert np.array_equal(a.theta_, b.theta_)


@pytest.mark.parametrize("kw, message", [
    (dict(hidden=0), "hidden: must be"), (dict(prior="free"), "prior: unknown 'free'"),
    (dict(lags=1.5), "lags: must be an integer"), (dict(stride=0), "stride: must be"),
])
def test_bad_arguments_are_named(kw, message):
    with pytest.raises(ValueError, match=message):
        QuadHybrid(**kw)


def test_bad_data_is_named():
    (U, Y), _ = _flights()
    with pytest.raises(ValueError, match="the 4 rotor speeds and the 13 states"):
        QuadHybrid().fit(U[:, :3], Y)
    with pytest.raises(ValueError, match="too few samples for windows of 500 steps"):
        QuadHybrid(horizon=500).fit(U[:400], Y[:400])
