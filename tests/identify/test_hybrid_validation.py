"""HybridNarx chooses its network's weight held out: the ARX and the residual network of the
comparison are fitted on the first 80 % of the training record only, and both are scored in
free run on the last 20 %; the kept model is then refitted on the whole record.

Expected values are computed here with plain numpy from an independent generator (a
four-command plant with a squared-command term the linear part cannot represent): the physics
features written out from the X-mixer formulas, least squares by ``np.linalg.lstsq`` on
regressors built in a loop, the free runs as loops, Pearson r by ``np.corrcoef``. Only the
residual networks come from the code under test (a spy records what they are fitted on)."""
import numpy as np
import pytest

from cdam_core.models import BPNetwork, HybridNarx


def _plant(n=900, seed=3, noise=0.005):
    """Four motor commands -> two outputs; output 0 has a saturating term. The
    largest command of input 2 falls in the last tenth (so the fit rows' maximum differs from
    the record's)."""
    g = np.random.default_rng(seed)
    U = np.abs(np.c_[[np.convolve(g.normal(size=n), np.ones(7) / 7, "same") for _ in range(4)]].T)
    U[int(0.95 * n), 2] = 3.0 * U[:, 2].max()
    Y = np.zeros((n, 2))
    for t in range(1, n):
        Y[t, 0] = (0.7 * Y[t - 1, 0] + 0.4 * U[t, 0] - 0.2 * U[t, 1]
                   + np.tanh(8 * (U[t, 0] - U[t, 3])))
        Y[t, 1] = 0.5 * Y[t - 1, 1] + 0.3 * U[t, 2] + 0.1 * U[t - 1, 3]
    return U, Y + noise * g.normal(size=Y.shape)


def _features(U, scale):
    u = U / scale
    f = u * u
    return np.c_[u, f.sum(1), f[:, 0] + f[:, 3] - f[:, 1] - f[:, 2],
                 f[:, 0] + f[:, 1] - f[:, 2] - f[:, 3], f[:, 0] - f[:, 1] + f[:, 2] - f[:, 3]]


def _design(F, Y, t0=2):
    """ARX (2, 2, 0) rows: y(t-1), y(t-2), f(t), f(t-1), 1 for t = t0 .. N-1."""
    return np.array([np.r_[Y[t - 1], Y[t - 2], F[t], F[t - 1], 1.0] for t in range(t0, len(F))])


def _free_run(W, F, Y0, extra, t0=2):
    """The ARX recursion from the first t0 measured rows, plus ``extra`` (rows t0..)."""
    P = np.zeros((len(F), W.shape[1]))
    P[:t0] = Y0
    for t in range(t0, len(F)):
        P[t] = np.r_[P[t - 1], P[t - 2], F[t], F[t - 1], 1.0] @ W + extra[t - t0]
    return P[t0:]


def _r(Y, P):
    return np.mean([np.corrcoef(Y[:, k], P[:, k])[0, 1] for k in range(Y.shape[1])])


@pytest.mark.parametrize("useful", [True, False])
def test_the_network_weight_is_chosen_on_rows_neither_fit_saw(useful):
    U, Y = _plant()
    calls = []

    def spy(X, R):
        calls.append((X.copy(), R.copy()))
        return BPNetwork(hidden=4, epochs=20, seed=0, threads=1).fit(
            X, R if useful else R[::-1])      # time-reversed: a residual the inputs do not explain
    m = HybridNarx((2, 2, 0), "physics", fit_residual=spy).fit(U, Y)

    n, t0 = len(U), 2
    n_fit = int(round((n - t0) * 0.8))
    e = t0 + n_fit
    scale = np.abs(U).max(axis=0)                # the whole record's, in both fits
    F = _features(U, scale)
    A = _design(F, Y)
    # the held-out stage: least squares on the rows before e only
    W_a = np.linalg.lstsq(A[:n_fit], Y[t0:e], rcond=None)[0]
    X1, R1 = calls[0]
    np.testing.assert_allclose(X1, np.c_[F[t0:e], F[t0 - 1:e - 1]], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(R1, Y[t0:e] - A[:n_fit] @ W_a, rtol=1e-8, atol=1e-10)
    # both arms of the comparison run free on rows e.. from the rows before them
    net1 = BPNetwork(hidden=4, epochs=20, seed=0, threads=1).fit(X1, R1 if useful else R1[::-1])
    Fv, Yv = F[n_fit:], Y[n_fit:]
    Xv = np.c_[Fv[t0:], Fv[t0 - 1:-1]]
    r0 = _r(Yv[t0:], _free_run(W_a, Fv, Yv[:t0], np.zeros((len(Xv), 2))))
    r1 = _r(Yv[t0:], _free_run(W_a, Fv, Yv[:t0], net1.predict(Xv)))
    assert m.validation_r_[0.0] == pytest.approx(r0, abs=1e-9)
    assert m.validation_r_[1.0] == pytest.approx(r1, abs=1e-9)
    # the ARX scored on the tail it was fitted on (the old comparison) looks better than held out
    W_all = np.linalg.lstsq(A, Y[t0:], rcond=None)[0]
    r_in = _r(Yv[t0:], _free_run(W_all, Fv, Yv[:t0], np.zeros((len(Xv), 2))))
    assert r_in > r0
    # the model: the ARX refitted on every row; the network refitted on its residual if kept
    kept = r1 > r0
    assert m.residual_weight_ == (1.0 if kept else 0.0)
    np.testing.assert_allclose(m.coef_, W_all, rtol=1e-8, atol=1e-10)
    assert len(calls) == (2 if kept else 1)
    if kept:
        X2, R2 = calls[1]
        np.testing.assert_allclose(X2, np.c_[F[t0:], F[t0 - 1:-1]], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(R2, Y[t0:] - A @ W_all, rtol=1e-8, atol=1e-10)
    P = m.predict(U, Y, mode="free_run")[t0:]
    extra = m.net_.predict(np.c_[F[t0:], F[t0 - 1:-1]]) * m.residual_weight_
    np.testing.assert_allclose(P, _free_run(W_all, F, Y[:t0], extra), rtol=1e-8, atol=1e-9)
    # the saturation is what the network adds; fitted to a scrambled residual it harms
    assert kept == useful


def test_a_record_too_short_for_the_held_out_fit_is_refused_by_name():
    U, Y = _plant(n=21)
    with pytest.raises(ValueError, match=r"U: 21 samples leave 17 before the validation tail"):
        HybridNarx((1, 1, 1)).fit(U, Y)
    with pytest.raises(ValueError, match=r"weight: must be in \[0, 1\]"):
        HybridNarx((1, 1, 1)).fit_with_weight(U, Y, 1.5)


def _numpy_net(net, X):
    """A static network's output written out: min-max scaling to [-1, 1], tanh hidden layer
    (MATLAB column-major theta), linear output, back-scaling."""
    i, h, m = net.n_inputs_, net.hidden_, net.n_outputs_
    th = np.asarray(net.theta_, float)
    W1 = th[:i * h].reshape(h, i, order="F")
    b1 = th[i * h:i * h + h]
    W2 = th[i * h + h:i * h + h + h * m].reshape(m, h, order="F")
    b2 = th[i * h + h + h * m:]
    lo, hi = net.scaler_x_.data_min_, net.scaler_x_.data_max_
    Z = np.tanh((2 * (X - lo) / (hi - lo) - 1) @ W1.T + b1) @ W2.T + b2
    lo, hi = net.scaler_y_.data_min_, net.scaler_y_.data_max_
    return lo + (Z + 1) * (hi - lo) / 2


def test_mean_network_is_the_numpy_mean_of_its_members():
    from cdam_core.models.network import mean_network
    g = np.random.default_rng(5)
    X = g.normal(size=(150, 3))
    T = np.c_[np.sin(2 * X[:, 0]), X[:, 1] * X[:, 2]]
    nets = [BPNetwork(hidden=h, epochs=4, seed=s, threads=1).fit(X, T)
            for h, s in ((3, 0), (4, 1), (2, 2))]
    Xt = g.normal(size=(40, 3))
    want = np.mean([_numpy_net(n, Xt) for n in nets], axis=0)
    m = mean_network(nets)
    assert m.hidden_ == 9
    np.testing.assert_allclose(m.predict(Xt), want, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(BPNetwork.from_dict(m.to_dict()).predict(Xt), want,
                               rtol=1e-10, atol=1e-12)
    other = BPNetwork(hidden=2, epochs=1, threads=1).fit(X[:100], T[:100])
    with pytest.raises(ValueError, match=r"nets\[1\]: scaler_x differs"):
        mean_network([nets[0], other])


def test_ensemble_weights_chosen_on_blocks_against_numpy():
    """ensemble=2, weights {0, 0.5, 1}, 3 validation blocks: on each block the ARX (numpy least
    squares on the rest, two records) and two networks on its residual (a spy records what
    they are given) run free on the block with w x (the networks' mean) added; the mean r
    over blocks per weight, the weight chosen, and the refitted model, all recomputed here."""
    U, Y = _plant(n=600)
    calls = []

    def spy(X, R, member):
        calls.append((X.copy(), R.copy(), BPNetwork(hidden=3, epochs=8, seed=member,
                                                    threads=1).fit(X, R)))
        return calls[-1][2]
    m = HybridNarx((2, 2, 0), "physics", fit_residual=spy, ensemble=2, weights=(0.5, 1.0),
                   validation_blocks=3).fit(U, Y)
    n, t0 = len(U), 2
    F = _features(U, np.abs(U).max(axis=0))
    rs = {0.0: [], 0.5: [], 1.0: []}
    for k in range(3):
        a, b = n * k // 3, n * (k + 1) // 3
        segs = [(lo, hi) for lo, hi in ((0, a), (b, n)) if hi > lo]
        A = np.vstack([_design(F[lo:hi], Y[lo:hi]) for lo, hi in segs])
        T = np.vstack([Y[lo + t0:hi] for lo, hi in segs])
        Xr = np.vstack([np.c_[F[lo + t0:hi], F[lo + t0 - 1:hi - 1]] for lo, hi in segs])
        W = np.linalg.lstsq(A, T, rcond=None)[0]
        for j in (0, 1):
            Xs, Rs, _ = calls[2 * k + j]
            np.testing.assert_allclose(Xs, Xr, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(Rs, T - A @ W, rtol=1e-8, atol=1e-10)
        Xb = np.c_[F[a + t0:b], F[a + t0 - 1:b - 1]]
        mean = np.mean([_numpy_net(calls[2 * k + j][2], Xb) for j in (0, 1)], axis=0)
        for w in rs:
            rs[w].append(_r(Y[a + t0:b], _free_run(W, F[a:b], Y[a:a + t0], w * mean)))
    want = {w: np.mean(v) for w, v in rs.items()}
    assert m.validation_r_ == pytest.approx(want, abs=1e-9)
    best = max(want, key=want.get)
    kept = best > 0 and want[best] > want[0.0]
    assert m.residual_weight_ == (best if kept else 0.0)
    assert len(calls) == 6 + (2 if kept else 0)
    W_all = np.linalg.lstsq(_design(F, Y), Y[t0:], rcond=None)[0]
    X_all = np.c_[F[t0:], F[t0 - 1:-1]]
    extra = m.residual_weight_ * np.mean([_numpy_net(c[2], X_all) for c in calls[-2:]], axis=0)
    np.testing.assert_allclose(m.predict(U, Y, mode="free_run")[t0:],
                               _free_run(W_all, F, Y[:t0], extra), rtol=1e-8, atol=1e-9)
    # weight 0 is the ARX exactly, the networks beside it unused
    from cdam_core.models.arx import ArxModel
    m.residual_weight_ = 0.0
    np.testing.assert_array_equal(m.predict(U, Y, mode="free_run"),
                                  ArxModel((2, 2, 0), "physics").fit(U, Y).predict(
                                      U, Y, mode="free_run"))


def test_free_run_training_lowers_the_numpy_free_run_error():
    """training="free_run": the one-step network refined by LM on the hybrid's free-run error.
    The cost it reports before and after, recomputed here: the ARX (numpy least squares) run
    free with the network's term added (the recursion written out), its error over the std of
    the ARX's own free-run error per output; the refined network's is lower."""
    U, Y = _plant(n=400)
    calls = []

    def spy(X, R):
        calls.append(BPNetwork(hidden=3, epochs=10, seed=0, threads=1).fit(X, R))
        return calls[-1]
    m = HybridNarx((2, 2, 0), "physics", fit_residual=spy, training="free_run",
                   refine_epochs=4).fit_with_weight(U, Y, 1)
    t0 = 2
    F = _features(U, np.abs(U).max(axis=0))
    W = np.linalg.lstsq(_design(F, Y), Y[t0:], rcond=None)[0]
    X = np.c_[F[t0:], F[t0 - 1:-1]]
    E = Y[t0:] - _free_run(W, F, Y[:t0], np.zeros((len(X), 2)))
    s = E.std(axis=0)

    def cost(net):
        return np.mean(((Y[t0:] - _free_run(W, F, Y[:t0], _numpy_net(net, X))) / s) ** 2)
    hist = m.net_.history_["mse"]
    assert hist[0] == pytest.approx(cost(calls[0]), rel=1e-9)
    assert hist[-1] == pytest.approx(cost(m.net_), rel=1e-9)
    assert len(hist) > 1 and cost(m.net_) < cost(calls[0])
    np.testing.assert_allclose(m.predict(U, Y, mode="free_run")[t0:],
                               _free_run(W, F, Y[:t0], _numpy_net(m.net_, X)),
                               rtol=1e-8, atol=1e-9)
    with pytest.raises(ValueError, match="training: unknown 'k_step'"):
        HybridNarx((2, 2, 0), training="k_step").fit(U, Y)


def test_free_run_error_and_its_jacobian_against_numpy_and_finite_differences():
    """The refinement's cost terms: e = (E - G N(X)) / s with G the output recursion
    Z(t) = A1' Z(t-1) + A2' Z(t-2) + N(t) written out here, per record; its Jacobian against
    central differences of e."""
    from cdam_core.models.hybrid import free_run_error
    g = np.random.default_rng(7)
    X = g.normal(size=(60, 3))
    net = BPNetwork(hidden=2, epochs=3, seed=1, threads=1).fit(X, g.normal(size=(60, 2)))
    Wy = np.r_[[[0.5, 0.1], [-0.2, 0.4]], [[0.2, 0.0], [0.05, -0.1]]]   # rows: lag 1, lag 2
    parts = [(X[:35], g.normal(size=(35, 2))), (X[35:], g.normal(size=(25, 2)))]
    s = np.array([0.7, 1.3])
    theta = np.asarray(net.theta_, float)
    e, J = free_run_error(net, theta, Wy, 2, parts, s)
    want = []
    for Xk, E in parts:
        N = _numpy_net(net, Xk)
        Z = np.zeros_like(N)
        for t in range(len(N)):
            Z[t] = N[t] + (Z[t - 1] @ Wy[:2] if t >= 1 else 0) + (Z[t - 2] @ Wy[2:] if t >= 2 else 0)
        want.append(((E - Z) / s).ravel())
    np.testing.assert_allclose(e, np.concatenate(want), rtol=1e-10, atol=1e-12)
    h = 1e-6
    fd = np.column_stack([
        (free_run_error(net, theta - h * d, Wy, 2, parts, s, False)[0]
         - free_run_error(net, theta + h * d, Wy, 2, parts, s, False)[0]) / (2 * h)
        for d in np.eye(theta.size)])
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-7)
