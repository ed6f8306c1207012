"""k-step (simulation) training in the core (cpp/include/cdam/host/kstep.hpp): the Jacobian of
a K-step rollout of "physics increment + network residual" by forward sensitivities, checked
against central finite differences and the numpy twin (reference.kstep); J'J / J'e against the
twin's J, bit-identical at 1, 2 and 3 threads; the LM against the twin's trainlm loop; bad
input named."""
import numpy as np
import pytest

from cdam_core import _core
from cdam_core.reference.kstep import (kstep_jacobian, kstep_lm, kstep_num_params,
                                       kstep_residuals)


def _problem(seed=0, N=400, ns=3, ne=4, H=5, K=6, windows=None):
    rng = np.random.default_rng(seed)
    S = np.cumsum(rng.normal(size=(N, ns)), 0) * 0.1
    E = rng.normal(size=(N, ne))
    Dr = rng.normal(size=(N, ns)) * 0.01
    starts = np.array([0, 10, 50, 200, N - 1 - K]) if windows is None else \
        np.sort(rng.choice(N - K - 1, windows, replace=False))
    theta = rng.normal(size=kstep_num_params(ns, ne, H)) * 0.5
    scales = (rng.normal(size=ns) * 0.2, rng.uniform(0.5, 2, ns), rng.uniform(0.05, 0.3, ns),
              rng.uniform(0.5, 2, ns))
    return theta, (S, E, Dr, starts, K, H) + scales


def _central_differences(theta, args, h=1e-6):
    """-d e / d theta of the twin's residuals (e = (y - y_hat) / q, so J = -de/dtheta)."""
    cols = []
    for p in range(theta.size):
        d = np.zeros(theta.size)
        d[p] = h
        cols.append(-(kstep_residuals(theta + d, *args) - kstep_residuals(theta - d, *args))
                    / (2 * h))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("weighted", [False, True])
def test_jacobian_equals_central_differences_and_the_numpy_twin(weighted):
    theta, args = _problem()
    if weighted:
        args = args + (np.linspace(0.5, 2.0, args[4]),)
    e, J = _core.kstep_jacobian(theta, *args)
    e2, J2 = kstep_jacobian(theta, *args)
    assert J.shape == (5 * 6 * 3, theta.size)
    np.testing.assert_allclose(e, e2, rtol=0, atol=1e-13)
    np.testing.assert_allclose(J, J2, rtol=0, atol=1e-12 * np.abs(J2).max())
    Jfd = _central_differences(theta, args)
    np.testing.assert_allclose(J, Jfd, rtol=0, atol=1e-7 * np.abs(Jfd).max())
    # the recurrence matters: a later step depends on the network through the state
    assert np.abs(J[-3:]).max() > 2 * np.abs(J[:3]).max()


def test_normal_equations_equal_the_twin_and_every_thread_count():
    theta, args = _problem(seed=1, N=3000, windows=300, K=8, H=7)
    args = args + (1.0 / np.arange(1, 9),)      # step weights
    e, J = kstep_jacobian(theta, *args)
    out = [_core.kstep_normal(theta, *args, threads=t) for t in (1, 2, 3)]
    jtj, jte, sse = out[0]
    np.testing.assert_allclose(jtj, J.T @ J, rtol=1e-11, atol=1e-11 * np.abs(J.T @ J).max())
    np.testing.assert_allclose(jte, J.T @ e, rtol=1e-11, atol=1e-11 * np.abs(J.T @ e).max())
    assert sse == pytest.approx(float(e @ e), rel=1e-12)
    for jtj2, jte2, sse2 in out[1:]:
        assert np.array_equal(jtj, jtj2) and np.array_equal(jte, jte2) and sse == sse2


def test_lm_follows_the_twins_trainlm_loop_and_recovers_a_known_network():
    # data from a known network run recurrently (the twin's rollout): the k-step LM from a
    # perturbed start brings the k-step error down to the noise-free floor
    rng = np.random.default_rng(4)
    N, ns, ne, H, K = 600, 2, 2, 3, 5
    E = np.sin(np.arange(N)[:, None] * np.array([0.05, 0.13])) + 0.1 * rng.normal(size=(N, ne))
    Dr = 0.02 * np.cos(np.arange(N)[:, None] * np.array([0.07, 0.03]))
    true = rng.normal(size=kstep_num_params(ns, ne, H)) * 0.6
    scales = (np.zeros(ns), np.ones(ns), np.full(ns, 0.1), np.ones(ns))
    S = np.zeros((N, ns))
    for t in range(N - 1):     # one-window rollouts of length 1 give the recurrence
        e1, _ = kstep_jacobian(true, S, E, Dr, [t], 1, H, *scales, jacobian=False)
        S[t + 1] = S[t + 1] - e1 * scales[3]   # e = (S[t+1] - s_hat) / q with S[t+1] = 0
    starts = np.arange(0, N - K - 1, 7)
    args = (S, E, Dr, starts, K, H) + scales
    theta0 = true + 0.3 * rng.normal(size=true.size)
    th_c, hist = _core.kstep_train_lm(theta0, *args, epochs=8, threads=2)
    th_n, hist_n = kstep_lm(theta0, args, epochs=8)
    np.testing.assert_allclose(hist["mse"], hist_n, rtol=1e-6)
    np.testing.assert_allclose(th_c, th_n, rtol=0, atol=1e-6 * np.abs(th_n).max())
    th_long, hist_long = _core.kstep_train_lm(theta0, *args, epochs=60, threads=1)
    assert hist_long["mse"][-1] < 1e-6 * hist_long["mse"][0]
    th_2, hist_2 = _core.kstep_train_lm(theta0, *args, epochs=60, threads=2)
    assert np.array_equal(th_long, th_2)


def test_validation_windows_return_the_best_weights():
    theta, args = _problem(seed=2, N=1500, windows=120, K=5, H=4)
    S, E, Dr, starts = args[:4]
    val = (S, E, Dr, starts[::3])
    th, hist = _core.kstep_train_lm(theta, *args, epochs=15, val=val, max_fail=2)
    assert np.all(np.isfinite(hist["val_mse"]))
    best = int(hist["best_epoch"])
    assert hist["val_mse"][best] == np.min(hist["val_mse"])


@pytest.mark.parametrize("change, message", [
    (lambda a: (a[0][:-1],) + a[1:], "theta: expected length"),
    (lambda a: a[:4] + (np.array([0, 395]),) + a[5:], r"starts\[1\]: row 395 leaves no 6 steps"),
    (lambda a: a[:10] + (np.array([1.0, 0.0, 1.0]),) + a[11:], "scales: every"),
    (lambda a: a[:2] + (a[2][:-1],) + a[3:], "E: expected 400 rows"),
    (lambda a: a[:1] + (np.full_like(a[1], np.nan),) + a[2:], "S: contains NaN"),
    (lambda a: a[:4] + (np.array([0.5]),) + a[5:], "starts: expected integers"),
    (lambda a: a + (np.ones(5),), "step_weight: expected length 6"),
    (lambda a: a + (np.array([1, 1, 1, 0, 1, 1.0]),), "step_weight: every weight"),
])
def test_bad_input_is_named(change, message):
    theta, args = _problem()
    with pytest.raises(ValueError, match=message):
        _core.kstep_jacobian(*change((theta,) + args))


def test_parameter_count():
    assert _core.kstep_num_params(3, 18, 8) == kstep_num_params(3, 18, 8) == 8 * 21 + 8 + 27
    with pytest.raises(ValueError, match="hidden: must be in 1"):
        _core.kstep_num_params(3, 4, 0)
    with pytest.raises(ValueError, match="states: must be in 1"):
        _core.kstep_num_params(-1, 4, 2)


def _linear_problem(seed=5, N=500, ns=3, ne=2, H=4, K=7, na=2):
    """A problem with a linear part of na lags, stable (spectral radius < 1 of the companion)."""
    theta, args = _problem(seed=seed, N=N, ns=ns, ne=ne, H=H, K=K)
    rng = np.random.default_rng(seed + 100)
    A = [0.5 * np.eye(ns) + 0.1 * rng.normal(size=(ns, ns))] + \
        [0.2 * rng.normal(size=(ns, ns)) for _ in range(na - 1)]
    lin = np.hstack([A[0] - np.eye(ns)] + A[1:])
    S, E, Dr = args[:3]
    starts = np.array([na - 1, 10, 50, 200, N - 1 - K])
    return theta, (S, E, Dr, starts) + args[4:] + (None, lin), A


@pytest.mark.parametrize("na", [1, 3])
def test_linear_part_jacobian_equals_differences_and_the_twin(na):
    theta, args, _ = _linear_problem(na=na)
    e, J = _core.kstep_jacobian(theta, *args)
    e2, J2 = kstep_jacobian(theta, *args)
    np.testing.assert_allclose(e, e2, rtol=0, atol=1e-12 * np.abs(e2).max())
    np.testing.assert_allclose(J, J2, rtol=0, atol=1e-12 * np.abs(J2).max())
    Jfd = _central_differences(theta, args)
    np.testing.assert_allclose(J, Jfd, rtol=0, atol=1e-7 * np.abs(Jfd).max())
    # J'J / J'e of the core against the twin's J, any thread count alike
    jtj, jte, sse = _core.kstep_normal(theta, *args[:11], threads=1, lin=args[11])
    np.testing.assert_allclose(jtj, J2.T @ J2, rtol=1e-11, atol=1e-11 * np.abs(J2.T @ J2).max())
    np.testing.assert_allclose(jte, J2.T @ e2, rtol=1e-11, atol=1e-11 * np.abs(J2.T @ e2).max())
    jtj3, jte3, sse3 = _core.kstep_normal(theta, *args[:11], threads=3, lin=args[11])
    assert np.array_equal(jtj, jtj3) and np.array_equal(jte, jte3) and sse == sse3


def test_linear_part_with_a_silent_network_is_the_linear_model():
    # network output zero (W2 = b2 = 0): the rollout is the linear recursion
    # s_{t+1} = sum_l A_l s_{t-l} + D_t, simulated here in plain numpy from the measured past
    theta, args, A = _linear_problem(na=3)
    S, E, Dr, starts, K, H = args[:6]
    ns, ni = S.shape[1], S.shape[1] + E.shape[1]
    theta = theta.copy()
    theta[H * ni + H:] = 0.0
    q = args[9]
    e, _ = _core.kstep_jacobian(theta, *args)
    e = e.reshape(len(starts), K, ns)
    for w, a in enumerate(starts):
        hist = [S[a - 2], S[a - 1], S[a]]
        for j in range(K):
            t = a + j
            nxt = A[0] @ hist[-1] + A[1] @ hist[-2] + A[2] @ hist[-3] + Dr[t]
            hist.append(nxt)
            np.testing.assert_allclose(e[w, j], (S[t + 1] - nxt) / q, rtol=1e-12, atol=1e-12)


def test_linear_part_bad_input_is_named():
    theta, args, _ = _linear_problem(na=2)
    S = args[0]
    with pytest.raises(ValueError, match="lin: expected an"):
        _core.kstep_jacobian(theta, *args[:11], lin=np.zeros((S.shape[1], 4)))
    starts = np.array([0, 10])
    with pytest.raises(ValueError, match=r"starts\[0\]: row 0 has not the 1 earlier rows"):
        _core.kstep_jacobian(theta, *args[:3], starts, *args[4:])
    with pytest.raises(ValueError, match="lin: contains NaN"):
        _core.kstep_jacobian(theta, *args[:11], lin=np.full((S.shape[1], 6), np.nan))


def test_per_step_error_scales_divide_the_unscaled_errors():
    # err_scale (K, ns): each step's error of each state over its own scale; the unscaled
    # errors (err_scale 1) divided here in numpy, the Jacobian against the twin
    theta, args, _ = _linear_problem(na=2)
    S, K = args[0], args[4]
    ns = S.shape[1]
    qk = np.random.default_rng(9).uniform(0.2, 3.0, (K, ns))
    plain = args[:9] + (np.ones(ns), None, args[11])
    e1, J1 = _core.kstep_jacobian(theta, *plain)
    scaled = args[:9] + (qk, None, args[11])
    e, J = _core.kstep_jacobian(theta, *scaled)
    div = np.tile(qk.reshape(-1), len(args[3]))
    np.testing.assert_allclose(e, e1 / div, rtol=1e-13, atol=0)
    np.testing.assert_allclose(J, J1 / div[:, None], rtol=1e-13, atol=0)
    e2, J2 = kstep_jacobian(theta, *scaled)
    np.testing.assert_allclose(e, e2, rtol=0, atol=1e-12 * np.abs(e2).max())
    np.testing.assert_allclose(J, J2, rtol=0, atol=1e-12 * np.abs(J2).max())
    with pytest.raises(ValueError, match="step_weight: not with a per-step err_scale"):
        _core.kstep_jacobian(theta, *args[:9], qk, np.ones(K), args[11])
    with pytest.raises(ValueError, match="err_scale: expected 3 columns"):
        _core.kstep_jacobian(theta, *args[:9], np.ones((K, ns + 1)), None, args[11])
