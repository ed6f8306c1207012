"""The direct multi-step predictor (kind arx_direct) against plain numpy least squares written
here: per step k, the regressors [y(t), .., y(t-na+1), f(t+1-nk-nb+1), .., f(t+k-nk), 1] of
every origin t whose target t + k lies in its segment, solved by np.linalg.lstsq."""
import numpy as np
import pytest

from cdam_core.models.arx import ArxModel
from cdam_core.models.arx_direct import ArxDirect


def _record(seed, n=400):
    """A stable two-output linear system driven by two inputs, with noise (independent of the
    model code)."""
    rng = np.random.default_rng(seed)
    U = rng.normal(size=(n, 2))
    Y = np.zeros((n, 2))
    for t in range(2, n):
        Y[t, 0] = 0.6 * Y[t - 1, 0] - 0.2 * Y[t - 2, 1] + 0.5 * U[t - 1, 0] + 0.1 * U[t - 2, 1]
        Y[t, 1] = 0.3 * Y[t - 1, 1] + 0.1 * Y[t - 1, 0] ** 2 + 0.4 * U[t - 1, 1]
    return U, Y + 0.05 * rng.normal(size=Y.shape)


def _numpy_direct(U, Y, lengths, orders, k):
    """(origins, coefficients) of step k by np.linalg.lstsq on the explicit design."""
    na, nb, nk = orders
    t0 = max(na, nk + nb - 1)
    rows, targets, origins = [], [], []
    a = 0
    for n in lengths:
        b = a + n
        for t in range(a + t0 - 1, b - k):
            reg = [Y[t - j] for j in range(na)]
            reg += [U[t + s] for s in range(2 - nk - nb, k - nk + 1)]
            rows.append(np.concatenate(reg + [[1.0]]))
            targets.append(Y[t + k])
            origins.append(t)
        a = b
    X, T = np.array(rows), np.array(targets)
    coef = np.linalg.lstsq(X, T, rcond=None)[0]
    return np.array(origins), X @ coef


@pytest.mark.parametrize("orders", [(2, 2, 1), (1, 3, 2)])
def test_each_step_is_the_least_squares_fit_of_that_step(orders):
    U1, Y1 = _record(0)
    U2, Y2 = _record(1, 300)
    U, Y, lengths = np.vstack([U1, U2]), np.vstack([Y1, Y2]), [400, 300]
    H = 12
    m = ArxDirect(orders, "raw", horizon=H).fit(U, Y, segments=lengths)
    got = {k: (rows, P) for k, rows, P in m.rollout(U, Y, H, segments=lengths)}
    for k in (1, 2, 5, H):
        origins, want = _numpy_direct(U, Y, lengths, orders, k)
        rows, P = got[k]
        np.testing.assert_array_equal(rows, origins + k)
        np.testing.assert_allclose(P, want, rtol=0, atol=1e-9 * np.abs(want).max())
        # predict(k_step) gives the same rows (the first t0 + k - 1 of each segment measured)
        Pk = m.predict(U, Y, mode="k_step", k=k, segments=lengths)
        np.testing.assert_allclose(Pk[rows], P, rtol=0, atol=1e-12)


def test_step_one_and_beyond_the_horizon_are_the_arx():
    U, Y = _record(2)
    m = ArxDirect((2, 2, 1), "raw", horizon=3).fit(U, Y)
    arx = ArxModel((2, 2, 1), "raw").fit(U, Y)
    np.testing.assert_allclose(m.predict(U, Y), arx.predict(U, Y), atol=1e-12)
    np.testing.assert_allclose(m.predict(U, Y, mode="free_run"),
                               arx.predict(U, Y, mode="free_run"), atol=1e-10)
    # step 5 = the ARX's recursion continued from the direct steps 2 and 3
    outs = {k: P for k, _, P in m.rollout(U, Y, 5)}
    origins = np.arange(1, len(Y) - 5)
    A, B = arx.coef_[:4], arx.coef_[4:8]
    Z = {0: Y[origins], -1: Y[origins - 1]}
    for k in range(1, 6):
        if k in (2, 3):
            Z[k] = outs[k][:len(origins)]
        else:
            Z[k] = (np.hstack([Z[k - 1], Z[k - 2]]) @ A
                    + np.hstack([U[origins + k - 1], U[origins + k - 2]]) @ B + arx.coef_[8])
    np.testing.assert_allclose(outs[5][:len(origins)], Z[5], atol=1e-10)


def test_file_round_trip_and_bad_input():
    from cdam_core.models.file import load_model, save_model
    U, Y = _record(3)
    m = ArxDirect((2, 1, 1), "raw", horizon=4).fit(U, Y)
    d = m.to_dict()
    m2 = ArxDirect.from_dict(d)
    np.testing.assert_array_equal(m2.predict(U, Y, mode="k_step", k=3),
                                  m.predict(U, Y, mode="k_step", k=3))
    with pytest.raises(ValueError, match="horizon"):
        ArxDirect((2, 1, 1), horizon=0)
    bad = dict(d, steps=d["steps"][:-1])
    with pytest.raises(ValueError, match="model.steps"):
        ArxDirect.from_dict(bad)
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        save_model(f"{tmp}/m.json", m)
        np.testing.assert_array_equal(load_model(f"{tmp}/m.json").predict(U, Y, mode="k_step",
                                                                           k=4),
                                      m.predict(U, Y, mode="k_step", k=4))


def test_one_step_on_physics_features_is_the_least_squares_fit():
    """horizon 1 with physics features (a fit that once failed: no window is cut by a
    segment's end): step 1 is the least-squares fit on the features written here from their
    definition (f_i = u_i^2, their sum and the three X-mixer torque combinations, the scaled
    commands; a least-squares fit with an intercept does not depend on the columns' scales)."""
    rng = np.random.default_rng(7)
    lengths = [300, 250]
    U = 1.0 + 0.3 * rng.uniform(size=(sum(lengths), 4))
    f = U ** 2
    F = np.column_stack([U, f.sum(1), f[:, 0] + f[:, 3] - f[:, 1] - f[:, 2],
                         f[:, 0] + f[:, 1] - f[:, 2] - f[:, 3],
                         f[:, 0] - f[:, 1] + f[:, 2] - f[:, 3]])
    Y = np.zeros((sum(lengths), 2))
    for t in range(1, len(Y)):
        Y[t] = 0.7 * Y[t - 1] + [0.3 * F[t - 1, 4], 0.2 * F[t - 1, 5]]
    Y += 0.01 * rng.normal(size=Y.shape)
    orders = (2, 2, 1)
    m = ArxDirect(orders, "physics", horizon=1).fit(U, Y, segments=lengths)
    (k, rows, P), = list(m.rollout(U, Y, 1, segments=lengths))
    origins, want = _numpy_direct(F, Y, lengths, orders, 1)
    np.testing.assert_array_equal(rows, origins + 1)
    np.testing.assert_allclose(P, want, rtol=0, atol=1e-8 * np.abs(want).max())


def _record3(seed, n=400):
    """Three outputs, the third driven by the newest input (delay 1), the others by older
    ones (independent of the model code)."""
    rng = np.random.default_rng(seed)
    U = rng.normal(size=(n, 2))
    Y = np.zeros((n, 3))
    for t in range(3, n):
        Y[t, 0] = 0.6 * Y[t - 1, 0] + 0.4 * U[t - 2, 0]
        Y[t, 1] = 0.5 * Y[t - 1, 1] - 0.2 * Y[t - 2, 0] + 0.3 * U[t - 3, 1]
        Y[t, 2] = 0.7 * Y[t - 1, 2] + 0.5 * U[t - 1, 1] + 0.2 * U[t - 1, 0] ** 2
    return U, Y + 0.02 * rng.normal(size=Y.shape)


def _numpy_one_step(U, Y, lengths, orders, t0):
    """One-step predictions of the rows t >= t0 of each segment by np.linalg.lstsq on the ARX
    regressors [y(t-1..t-na), u(t-nk..t-nk-nb+1), 1] of (na, nb, nk), fitted on the rows
    t >= the orders' own t0."""
    na, nb, nk = orders
    own = max(na, nk + nb - 1)

    def design(first):
        rows, targets, at = [], [], []
        a = 0
        for n in lengths:
            for t in range(a + first, a + n):
                rows.append(np.concatenate([Y[t - j] for j in range(1, na + 1)]
                                           + [U[t - nk - j] for j in range(nb)] + [[1.0]]))
                targets.append(Y[t])
                at.append(t)
            a += n
        return np.array(rows), np.array(targets), np.array(at)

    X, T, _ = design(own)
    coef = np.linalg.lstsq(X, T, rcond=None)[0]
    X, _, at = design(t0)
    return at, X @ coef


def test_first_step_regressors_of_their_own(tmp_path):
    """``first``: the listed outputs' step 1 is the one-step least squares of their own orders
    (numpy), the others' the ARX's; steps 2.. equal the direct predictor without it (the same
    numbers), the free run the ARX's; the model file keeps it."""
    from cdam_core.models.file import load_model, save_model

    U1, Y1 = _record3(3)
    U2, Y2 = _record3(4, 300)
    U, Y, lengths = np.vstack([U1, U2]), np.vstack([Y1, Y2]), [400, 300]
    H = 6
    plain = ArxDirect((2, 2, 2), "raw", horizon=H).fit(U, Y, segments=lengths)
    m = ArxDirect((2, 2, 2), "raw", horizon=H, first=[([2], (1, 2, 1), "raw")]).fit(
        U, Y, segments=lengths)
    assert m.t0 == 3
    got = {k: (rows, P) for k, rows, P in m.rollout(U, Y, H + 2, segments=lengths)}
    ref = {k: (rows, P) for k, rows, P in plain.rollout(U, Y, H + 2, segments=lengths)}
    at, want2 = _numpy_one_step(U, Y, lengths, (1, 2, 1), 3)
    _, want01 = _numpy_one_step(U, Y, lengths, (2, 2, 2), 3)
    rows, P = got[1]
    np.testing.assert_array_equal(rows, at)
    np.testing.assert_allclose(P[:, 2], want2[:, 2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(P[:, :2], want01[:, :2], rtol=0, atol=1e-9)
    # the newest input predicts output 2 better one step ahead than the delay-2 ARX
    e_new = np.sqrt(np.mean((Y[at, 2] - want2[:, 2]) ** 2))
    e_arx = np.sqrt(np.mean((Y[at, 2] - want01[:, 2]) ** 2))
    assert e_new < 0.7 * e_arx
    for k in range(2, H + 3):
        np.testing.assert_array_equal(got[k][0], ref[k][0])
        np.testing.assert_array_equal(got[k][1], ref[k][1])
    # predict's one-step and k-step (k = 1) modes give the same step 1
    for mode in ("one_step", "k_step"):
        np.testing.assert_allclose(m.predict(U, Y, mode=mode, k=1, segments=lengths)[rows], P,
                                   rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.predict(U, Y, mode="free_run", segments=lengths)[3:400],
                               plain.predict(U, Y, mode="free_run", segments=lengths)[3:400],
                               rtol=0, atol=1e-9)
    save_model(tmp_path / "m.json", m, inputs=["a", "b"], outputs=["p", "q", "r"])
    back = load_model(tmp_path / "m.json")
    np.testing.assert_array_equal(back.predict(U, Y, segments=lengths),
                                  m.predict(U, Y, segments=lengths))


@pytest.mark.parametrize("first, what", [([([3], (1, 1, 1), "raw")], "output 3 of 3"),
                                         ([([0], (1, 1, 1), "raw"), ([0], (2, 1, 1), "raw")],
                                          "already listed"),
                                         ([([0], (1, 1, 1), "cubic")], "features"),
                                         (5, "expected a list")])
def test_first_rejects_bad_entries(first, what):
    U, Y = _record3(5)
    with pytest.raises(ValueError, match=what):
        ArxDirect((2, 2, 1), horizon=3, first=first).fit(U, Y)


def test_first_mix_weights_each_row_by_the_past_errors(tmp_path):
    """``first_mix``: step 1 of the ``first`` outputs is lambda p1 + (1 - lambda) p2 per row,
    lambda the least-squares weight (clipped to [0, 1]) of the two one-step predictors' errors
    on the ``window`` rows before it in its segment: numpy loops written here; steps 2.. as
    without it; the file keeps it."""
    U1, Y1 = _record3(6)
    U2, Y2 = _record3(7, 300)
    U, Y, lengths = np.vstack([U1, U2]), np.vstack([Y1, Y2]), [400, 300]
    W = 7
    m = ArxDirect((2, 2, 2), "raw", horizon=4, first=[([1, 2], (1, 2, 1), "raw")],
                  first_mix=((2, 2, 2), "raw", W)).fit(U, Y, segments=lengths)
    plain = ArxDirect((2, 2, 2), "raw", horizon=4).fit(U, Y, segments=lengths)
    at, p1 = _numpy_one_step(U, Y, lengths, (1, 2, 1), 3)
    _, p2 = _numpy_one_step(U, Y, lengths, (2, 2, 2), 3)
    want = p2.copy()
    seg = np.repeat([0, 1], [397, 297])            # the rows t >= 3 of each segment
    outs = [1, 2]
    for i in range(len(at)):
        past = [j for j in range(max(i - W, 0), i) if seg[j] == seg[i]]
        e1 = Y[at[past]][:, outs] - p1[past][:, outs]
        e2 = Y[at[past]][:, outs] - p2[past][:, outs]
        den = np.sum((e1 - e2) ** 2)
        lam = 0.0 if den == 0 else float(np.clip(np.sum((e2 - e1) * e2) / den, 0, 1))
        want[i, outs] = lam * p1[i, outs] + (1 - lam) * p2[i, outs]
    got = {k: (rows, P) for k, rows, P in m.rollout(U, Y, 4, segments=lengths)}
    ref = {k: (rows, P) for k, rows, P in plain.rollout(U, Y, 4, segments=lengths)}
    rows, P = got[1]
    np.testing.assert_array_equal(rows, at)
    np.testing.assert_allclose(P, want, rtol=0, atol=1e-9)
    np.testing.assert_allclose(m.predict(U, Y, segments=lengths)[rows], P, rtol=0, atol=1e-12)
    for k in (2, 3, 4):
        np.testing.assert_array_equal(got[k][1], ref[k][1])
    from cdam_core.models.file import load_model, save_model
    save_model(tmp_path / "m.json", m, inputs=["a", "b"], outputs=["p", "q", "r"])
    back = load_model(tmp_path / "m.json")
    np.testing.assert_array_equal(back.predict(U, Y, segments=lengths),
                                  m.predict(U, Y, segments=lengths))
    with pytest.raises(ValueError, match="first_mix"):
        ArxDirect((2, 2, 1), first_mix=((1, 1, 1), "raw", 5))
    with pytest.raises(ValueError, match="window"):
        ArxDirect((2, 2, 1), first=[([0], (1, 1, 1), "raw")], first_mix=((1, 1, 1), "raw", 0))
