"""Tests of the numpy reference trainers: Levenberg-Marquardt (trainlm semantics) and GD."""
import numpy as np
import pytest

from cdam_core.reference import (mlp_forward, mlp_jtj, mlp_mse_gradient, mlp_num_params,
                                 train_gd, train_lm)


def mse_of(theta, X, T, h, act="tansig"):
    e = T - mlp_forward(theta, X, h, T.shape[1], act)
    return float(np.mean(e**2))


def teacher_problem(seed=0, n=40, i=2, h=3, m=1, spread=0.3):
    rng = np.random.default_rng(seed)
    teacher = rng.normal(size=mlp_num_params(i, h, m))
    X = rng.uniform(-1, 1, (n, i))
    T = mlp_forward(teacher, X, h, m)
    return teacher + spread * rng.normal(size=teacher.size), X, T


def overfit_problem(seed):
    """A 10-hidden-node net on 15 noisy samples; validation on fresh samples."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, (15, 1))
    T = np.sin(3 * X) + 0.3 * rng.normal(size=(15, 1))
    Xv = rng.uniform(-1, 1, (30, 1))
    Tv = np.sin(3 * Xv) + 0.3 * rng.normal(size=(30, 1))
    return 0.5 * rng.normal(size=mlp_num_params(1, 10, 1)), X, T, Xv, Tv


def transcribed_lm(theta, X, T, h, act, epochs, mu, mu_max, max_fail, Xv, Tv):
    """The specification's loop written out with mlp_jtj and a dense solve (LU, not Cholesky)."""
    mse = mse_of(theta, X, T, h, act)
    vbest = mse_of(theta, Xv, Tv, h, act)
    v, fails, best = vbest, 0, theta
    mses, mus, vals = [], [], []
    for epoch in range(epochs + 1):
        JtJ, Jte, _ = mlp_jtj(theta, X, T, h, act)
        mses.append(mse)
        mus.append(mu)
        vals.append(v)
        if epoch == epochs or mu >= mu_max or fails >= max_fail:
            break
        while mu <= mu_max:
            d = np.linalg.solve(JtJ + mu * np.eye(theta.size), Jte)
            mse2 = mse_of(theta + d, X, T, h, act)
            if mse2 < mse:
                theta, mse, mu = theta + d, mse2, max(mu * 0.1, 1e-20)
                break
            mu *= 10
        v = mse_of(theta, Xv, Tv, h, act)
        if v < vbest:
            vbest, best, fails = v, theta, 0
        elif v > vbest:
            fails += 1
    return best, np.array(mses), np.array(mus), np.array(vals)


@pytest.mark.parametrize("act", ["tansig", "logsig"])
def test_lm_fits_a_known_network(act):
    rng = np.random.default_rng(1)
    i, h, m = 2, 3, 2
    teacher = rng.normal(size=mlp_num_params(i, h, m))
    X = rng.uniform(-1, 1, (60, i))
    T = mlp_forward(teacher, X, h, m, act)
    theta0 = teacher + 0.3 * rng.normal(size=teacher.size)
    assert mse_of(theta0, X, T, h, act) > 1e-3
    theta, hist = train_lm(theta0, X, T, h, act, goal=1e-10, epochs=300)
    assert hist["stop"] == "goal"
    assert mse_of(theta, X, T, h, act) <= 1e-10
    assert hist["mse"][-1] == pytest.approx(mse_of(theta, X, T, h, act), rel=1e-9)
    np.testing.assert_allclose(mlp_forward(theta, X, h, m, act), T, atol=1e-4)


def test_lm_history_obeys_the_semantics():
    theta0, X, T = teacher_problem()
    mu0, mu_max = 1e-3, 1e10
    theta, hist = train_lm(theta0, X, T, 3, epochs=30, mu=mu0)
    mse, mu, g = hist["mse"], hist["mu"], hist["grad_norm"]
    assert hist["stop"] == "epochs" and len(mse) == 31 and hist["best_epoch"] == 30
    assert np.all(np.isnan(hist["val_mse"]))
    assert mse[0] == pytest.approx(mse_of(theta0, X, T, 3), rel=1e-12)
    assert mu[0] == mu0
    assert g[0] == pytest.approx(np.linalg.norm(mlp_jtj(theta0, X, T, 3)[1]), rel=1e-12)
    assert np.all(np.diff(mse) <= 0)
    for k in range(len(mse) - 1):
        if mse[k + 1] < mse[k]:
            # accepted after r >= 0 rejections: mu * 10**r * 0.1
            r = np.log10(mu[k + 1] / mu[k]) + 1
            assert r >= -1e-9 and abs(r - round(r)) < 1e-9
        else:
            assert mu[k + 1] > mu_max
    assert np.sum(np.diff(mse) < 0) >= 5
    assert mse[-1] == pytest.approx(mse_of(theta, X, T, 3), rel=1e-12)
    assert hist["mse"].dtype == np.float64 and hist["mu"].dtype == np.float64


def test_lm_mu_is_divided_by_ten_after_a_first_try_success():
    theta0, X, T = teacher_problem()
    _, hist = train_lm(theta0, X, T, 3, epochs=3, mu=1e-3)
    # near the teacher the first Gauss-Newton-like step succeeds at once
    np.testing.assert_allclose(hist["mu"], [1e-3, 1e-4, 1e-5, 1e-6], rtol=1e-12)


def test_lm_matches_the_transcribed_specification():
    theta0, X, T, Xv, Tv = overfit_problem(1)
    theta, hist = train_lm(theta0, X, T, 10, epochs=8, max_fail=4, X_val=Xv, T_val=Tv)
    best, mses, mus, vals = transcribed_lm(theta0, X, T, 10, "tansig", 8, 1e-3, 1e10, 4, Xv, Tv)
    assert len(hist["mse"]) == len(mses)
    np.testing.assert_allclose(hist["mse"], mses, rtol=1e-8)
    np.testing.assert_allclose(hist["mu"], mus, rtol=1e-12)
    np.testing.assert_allclose(hist["val_mse"], vals, rtol=1e-8)
    np.testing.assert_allclose(theta, best, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lm_max_fail_returns_best_validation_weights(seed):
    theta0, X, T, Xv, Tv = overfit_problem(seed)
    theta, hist = train_lm(theta0, X, T, 10, epochs=500, max_fail=4, X_val=Xv, T_val=Tv)
    assert hist["stop"] == "max_fail"
    vals = hist["val_mse"]
    b = hist["best_epoch"]
    v_returned = mse_of(theta, Xv, Tv, 10)
    assert v_returned == pytest.approx(vals.min(), rel=1e-12)
    assert vals[b] == vals.min() and np.argmin(vals) == b
    # after the best epoch, exactly max_fail recorded values rose above the best
    assert np.sum(vals[b + 1:] > vals[b]) == 4 and np.all(vals[b + 1:] >= vals[b])
    # the weights are not the last ones: training went on past the best epoch
    assert len(vals) - 1 > b
    assert mse_of(theta, X, T, 10) >= hist["mse"][-1]


def test_lm_stops_on_goal_min_grad_and_mu_max_at_once():
    theta0, X, T = teacher_problem()
    th, hist = train_lm(theta0, X, T, 3, goal=1e6)
    assert hist["stop"] == "goal" and len(hist["mse"]) == 1
    np.testing.assert_array_equal(th, theta0)
    _, hist = train_lm(theta0, X, T, 3, min_grad=1e6)
    assert hist["stop"] == "min_grad"
    _, hist = train_lm(theta0, X, T, 3, mu=1e3, mu_max=1e3)
    assert hist["stop"] == "mu_max"
    _, hist = train_lm(theta0, X, T, 3, epochs=0)
    assert hist["stop"] == "epochs" and hist["best_epoch"] == 0
    # goal is checked before epochs
    _, hist = train_lm(theta0, X, T, 3, epochs=0, goal=1e6)
    assert hist["stop"] == "goal"


def test_lm_float32_runs_in_float32():
    theta0, X, T = teacher_problem()
    th32, hist = train_lm(theta0.astype(np.float32), X.astype(np.float32),
                          T.astype(np.float32), 3, epochs=5)
    assert th32.dtype == np.float32 and hist["mse"].dtype == np.float64
    assert hist["mse"][-1] < hist["mse"][0]


@pytest.mark.parametrize("kw, match", [
    (dict(epochs=-1), "epochs: must be >= 0"),
    (dict(goal=-1.0), "goal: must be >= 0"),
    (dict(mu=0.0), "mu: must be > 0"),
    (dict(mu_dec=1.0), "mu_dec: must be < 1"),
    (dict(mu_inc=1.0), "mu_inc: must be > 1"),
    (dict(mu_max=float("nan")), "mu_max: must be finite"),
    (dict(min_grad=-1.0), "min_grad: must be >= 0"),
    (dict(max_fail=0), "max_fail: must be >= 1"),
    (dict(X_val=np.ones((3, 2))), "T_val: X_val and T_val must be given together"),
    (dict(X_val=np.ones((3, 3)), T_val=np.ones((3, 1))), "X_val: has 3 columns"),
    (dict(X_val=np.ones((3, 2)), T_val=np.ones((4, 1))), "T_val: has 4 samples"),
    (dict(X_val=np.ones((3, 2)), T_val=np.full((3, 1), np.nan)), "T_val: contains NaN"),
    (dict(hidden=0), "hidden: must be >= 1"),
    (dict(T=np.ones((5, 1))), "T: has 5 samples but X has 40"),
])
def test_lm_bad_input(kw, match):
    theta0, X, T = teacher_problem()
    args = dict(hidden=3, X=X, T=T)
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        train_lm(theta0, **args)


def test_gd_lowers_the_mse_and_steps_as_specified():
    theta0, X, T = teacher_problem(spread=1.0)
    lr = 0.05
    th1, h1 = train_gd(theta0, X, T, 3, lr=lr, epochs=1)
    _, grad = mlp_mse_gradient(theta0, X, T, 3)
    np.testing.assert_allclose(th1, theta0 - lr * grad, rtol=1e-14, atol=1e-15)
    assert h1["stop"] == "epochs" and len(h1["mse"]) == 2
    th, hist = train_gd(theta0, X, T, 3, lr=lr, epochs=300)
    assert len(hist["mse"]) == 301 and hist["best_epoch"] == 300
    assert hist["mse"][-1] < 0.5 * hist["mse"][0]
    assert np.all(np.diff(hist["mse"]) <= 1e-15)   # small step: monotone
    assert hist["mse"][-1] == pytest.approx(mse_of(th, X, T, 3), rel=1e-12)
    _, hist = train_gd(theta0, X, T, 3, goal=1e6)
    assert hist["stop"] == "goal" and len(hist["mse"]) == 1


@pytest.mark.parametrize("kw, match", [
    (dict(lr=0.0), "lr: must be > 0"),
    (dict(epochs=1.5), "epochs: must be an integer"),
    (dict(goal=float("inf")), "goal: must be finite"),
    (dict(activation="relu"), "activation: must be one of"),
])
def test_gd_bad_input(kw, match):
    theta0, X, T = teacher_problem()
    with pytest.raises(ValueError, match=match):
        train_gd(theta0, X, T, 3, **kw)


def test_lm_callback_cancels_after_the_stop_tests():
    theta0, X, T = teacher_problem()
    seen = []

    def cb(epoch, mse):
        seen.append((epoch, mse))
        return None if epoch < 2 else False

    _, hist = train_lm(theta0, X, T, 3, epochs=10, callback=cb)
    assert hist["stop"] == "cancelled" and len(hist["mse"]) == 3
    assert [e for e, _ in seen] == [0, 1, 2]
    np.testing.assert_array_equal([v for _, v in seen], hist["mse"])
    # the epoch limit is tested before the callback
    seen.clear()
    _, hist = train_lm(theta0, X, T, 3, epochs=0, callback=cb)
    assert hist["stop"] == "epochs" and seen == []
    with pytest.raises(ValueError, match="callback: must be callable"):
        train_lm(theta0, X, T, 3, callback=3)


def test_gd_callback_and_history_shape():
    theta0, X, T = teacher_problem()
    _, hist = train_gd(theta0, X, T, 3, epochs=10, callback=lambda e, m: e < 4)
    assert hist["stop"] == "cancelled" and len(hist["mse"]) == 5 and hist["best_epoch"] == 4
    for key in ("mu", "grad_norm", "val_mse"):
        assert hist[key].dtype == np.float64 and hist[key].size == 0
