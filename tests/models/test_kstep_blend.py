"""Models blended per prediction step and group (kind kstep_blend, models/kstep_blend.py): the
weights against scipy's constrained solver and a closed form, the blend of two ARX models
against a plain numpy ARX (its own least squares and k-step loop), the validation guarantee,
the protocol's modes agreeing, bad input named."""
import numpy as np
import pytest
from scipy.optimize import minimize

from cdam_core.models import ArxModel, KStepBlend
from cdam_core.models.kstep_blend import blend_sums, minimax_weights, simplex_weights


def _qp_reference(G, b):
    """min w'Gw - 2b'w on w >= 0, sum w <= 1 by scipy's SLSQP from every vertex."""
    n = b.size
    cons = [{"type": "ineq", "fun": lambda w: 1 - w.sum(), "jac": lambda w: -np.ones(n)}]
    best = None
    for w0 in [np.zeros(n)] + list(np.eye(n)) + [np.full(n, 1.0 / (n + 1))]:
        r = minimize(lambda w: w @ G @ w - 2 * b @ w, w0, jac=lambda w: 2 * G @ w - 2 * b,
                     bounds=[(0, 1)] * n, constraints=cons, method="SLSQP",
                     options={"ftol": 1e-14, "maxiter": 500})
        # SLSQP's point may break the constraints by its tolerance (scipy 1.17: sum w =
        # 1 + 4.4e-9, an objective 5e-7 below the feasible optimum): scored where it is feasible
        x = np.clip(r.x, 0.0, None)
        x = x / x.sum() if x.sum() > 1 else x
        f = float(x @ G @ x - 2 * b @ x)
        if best is None or f < best[1]:
            best = (x, f)
    return best


@pytest.mark.parametrize("J", [1, 2, 3])
def test_simplex_weights_are_the_constrained_least_squares(J):
    rng = np.random.default_rng(J)
    for trial in range(12):
        # J + 1 predictors of 2 outputs (one group) on 200 rows; the errors e of the reference
        P = rng.normal(size=(J + 1, 200, 2)) * rng.uniform(0.2, 2, size=(J + 1, 1, 1))
        Y = rng.normal(size=(200, 2)) + (trial % 3) * P[-1]
        G, b = blend_sums(P, Y)
        W = simplex_weights(G[None], b[None], [0, 0])[0]        # (2 outputs, J + 1)
        assert np.allclose(W[0], W[1]) and np.all(W >= 0) and np.isclose(W[0].sum(), 1)
        D = P[1:] - P[0]
        e = Y - P[0]
        Gd = np.einsum("jri,lri->jl", D, D)                    # plain sums, independent
        bd = np.einsum("jri,ri->j", D, e)
        if J == 1:
            w = np.clip(bd[0] / Gd[0, 0], 0, 1)
            assert W[0, 1] == pytest.approx(w, abs=1e-12)
        x, f = _qp_reference(Gd, bd)
        mine = W[0, 1:]
        assert mine @ Gd @ mine - 2 * bd @ mine <= f + 1e-9 * max(1, abs(f))
        np.testing.assert_allclose(mine, x, atol=1e-5)


@pytest.mark.parametrize("J", [1, 2])
def test_minimax_weights_are_the_grid_point_of_least_worst_unit(J):
    rng = np.random.default_rng(10 + J)
    units = [rng.normal(size=(J + 1, 150, 3)) * rng.uniform(0.3, 2, size=(J + 1, 1, 1))
             for _ in range(3)]
    Ys = [rng.normal(size=(150, 3)) + u[-1] * s for u, s in zip(units, (1.0, 0.2, -0.5))]
    sums = [blend_sums(P, Y) for P, Y in zip(units, Ys)]
    G = np.stack([g for g, _ in sums])[:, None]          # (units, 1 step, m, J, J)
    b = np.stack([v for _, v in sums])[:, None]
    c = np.stack([np.sum((Y - P[0]) ** 2, axis=0) for P, Y in zip(units, Ys)])[:, None]
    W = minimax_weights(G, b, c, [0, 0, 1], resolution=20)[0]
    # plain numpy: every grid point's blended predictions, each unit's squared error over
    # the reference's, per group (outputs 0-1 and 2)
    grid = [np.array(p) / 20 for p in np.ndindex(*(21,) * J) if sum(p) <= 20]
    for cols in ([0, 1], [2]):
        def worst(w):
            lam = np.concatenate([[1 - w.sum()], w])
            return max(np.sum((np.einsum("j,jri->ri", lam, P) - Y)[:, cols] ** 2)
                       / np.sum((P[0] - Y)[:, cols] ** 2) for P, Y in zip(units, Ys))
        scores = [worst(w) for w in grid]
        best = grid[int(np.argmin(scores))]
        np.testing.assert_allclose(W[cols[0], 1:], best, atol=1e-12)
        assert worst(W[cols[0], 1:]) <= 1 + 1e-12 and np.allclose(W[cols, 0], W[cols[0], 0])


def _plant(n, seed):
    """Two outputs, two smooth inputs, a cubic term an ARX(1, 1, 1) lacks."""
    rng = np.random.default_rng(seed)
    U = np.zeros((n, 2))
    Y = np.zeros((n, 2))
    for t in range(1, n):
        U[t] = 0.9 * U[t - 1] + 0.3 * rng.normal(size=2)
        y1, y2 = Y[t - 1]
        Y[t] = [0.9 * y1 + 0.1 * y2 + 0.3 * U[t - 1, 0] - 0.2 * y2 ** 3,
                0.7 * y2 + 0.4 * U[t - 1, 1] + 0.1 * U[t - 1, 0] ** 2]
    return U, Y + 0.01 * rng.normal(size=Y.shape)


def _numpy_arx_kstep(U, Y, Ut, Yt, k, na, nb):
    """ARX(na, nb, 1) by numpy least squares on (U, Y), k-step predictions on (Ut, Yt): row t
    from the measured rows up to t - k, its own predictions after (rows before t0 + k - 1
    measured)."""
    t0 = max(na, nb)

    def reg(Uc, Yc, t):
        return np.concatenate([Yc[t - j] for j in range(1, na + 1)]
                              + [Uc[t - 1 - j] for j in range(nb)] + [[1.0]])

    A = np.array([reg(U, Y, t) for t in range(t0, len(U))])
    W = np.linalg.lstsq(A, Y[t0:], rcond=None)[0]
    P = Yt.copy()
    for t in range(t0 + k - 1, len(Ut)):
        Z = Yt[:t + 1].copy()
        for s in range(t - k + 1, t + 1):
            Z[s] = reg(Ut, Z, s) @ W
        P[t] = Z[t]
    return P


@pytest.fixture(scope="module")
def blend():
    U, Y = _plant(2000, 1)
    Uv, Yv = _plant(800, 2)
    comps = [ArxModel((1, 1, 1)).fit(U, Y), ArxModel((2, 2, 1)).fit(U, Y)]
    return KStepBlend(comps, groups=[0, 1]).choose(Uv, Yv, horizon=6), (U, Y), (Uv, Yv)


def test_blend_of_two_arx_models_against_numpy(blend):
    model, (U, Y), (Uv, Yv) = blend
    t0 = 2
    for k in (1, 3, 6):
        a = _numpy_arx_kstep(U, Y, Uv, Yv, k, 1, 1)
        c = _numpy_arx_kstep(U, Y, Uv, Yv, k, 2, 2)
        rows = np.arange(t0 + k - 1, len(Yv))        # the rows both predict (the blend's t0)
        d, e = (c - a)[rows], (Yv - a)[rows]
        w = np.clip(np.sum(d * e, axis=0) / np.sum(d * d, axis=0), 0, 1)   # one output a group
        np.testing.assert_allclose(model.weights_[k - 1, :, 1], w, rtol=1e-9, atol=1e-12)
        P = model.predict(Uv, Yv, mode="k_step", k=k)
        np.testing.assert_allclose(P[rows], a[rows] + w * (c - a)[rows], rtol=0, atol=1e-10)


def test_on_the_choosing_records_no_step_is_worse_than_a_component(blend):
    model, _, (Uv, Yv) = blend
    for k in range(1, 7):
        rows = np.arange(model.t0 + k - 1, len(Yv))
        sse = lambda m: np.sum((m.predict(Uv, Yv, mode="k_step", k=k)[rows]  # noqa: E731
                                - Yv[rows]) ** 2, axis=0)
        mine = sse(model)
        for c in model.components_:
            assert np.all(mine <= sse(c) * (1 + 1e-12)), k


def test_modes_agree_and_the_file_round_trips(blend):
    model, _, _ = blend
    Ut, Yt = _plant(300, 3)
    for k, rows, P in model.rollout(Ut, Yt, 9):      # beyond the weights' 6 steps: the last
        np.testing.assert_allclose(P, model.predict(Ut, Yt, mode="k_step", k=k)[rows],
                                   rtol=0, atol=1e-12)
    np.testing.assert_allclose(model.predict(Ut, Yt, mode="one_step"),
                               model.predict(Ut, Yt, mode="k_step", k=1), rtol=0, atol=1e-12)
    free = model.predict(Ut, Yt, mode="free_run")
    np.testing.assert_allclose(free[-1], model.predict(Ut, Yt, mode="k_step", k=298)[-1],
                               rtol=0, atol=1e-10)
    again = KStepBlend.from_dict(model.to_dict())
    np.testing.assert_array_equal(again.predict(Ut, Yt, mode="k_step", k=4),
                                  model.predict(Ut, Yt, mode="k_step", k=4))


def test_bad_input_is_named(blend):
    model, (U, Y), _ = blend
    comps = model.components_
    w = np.full((3, 2, 2), 0.5)
    with pytest.raises(ValueError, match="components: none given"):
        KStepBlend([])
    with pytest.raises(ValueError, match="weights: each step's and output's weights"):
        KStepBlend(comps, weights=np.full((3, 2, 2), 0.6))
    with pytest.raises(ValueError, match=r"weights: expected \(steps, outputs, 2\)"):
        KStepBlend(comps, weights=np.full((3, 2), 0.5))
    with pytest.raises(ValueError, match="weights: 2 outputs, the components have 1"):
        KStepBlend([ArxModel((1, 1, 1)).fit(U, Y[:, :1])] * 2, weights=w)
    with pytest.raises(ValueError, match=r"components\[1\]: other inputs or outputs"):
        KStepBlend([comps[0], ArxModel((1, 1, 1)).fit(U, Y[:, :1])])
    with pytest.raises(ValueError, match="components: fit every component"):
        KStepBlend([comps[0], ArxModel((1, 1, 1))]).choose(U, Y)
    with pytest.raises(ValueError, match="weights: none"):
        KStepBlend([ArxModel((1, 1, 1)), ArxModel((2, 1, 1))]).fit(U, Y)
    with pytest.raises(ValueError, match=r"units: expected one label per row \(2000\)"):
        KStepBlend(comps, groups=[0, 1]).choose(U, Y, units=[0, 1])
    with pytest.raises(ValueError, match="groups: 3 labels for 2 outputs"):
        KStepBlend(comps, weights=w, groups=[0, 1, 2])


def test_unit_errors_and_held_out_score_against_explicit_predictions():
    """Three units, one extra component (J = 1): the pooled weight of a unit set is the
    closed form clip(sum d e / sum d d, 0, 1) per step and output (one output per group);
    the held-out score is then each unit's blended RMSE over the reference's, averaged,
    computed here from the predictions themselves."""
    from cdam_core.models.kstep_blend import held_out_score, unit_errors
    rng = np.random.default_rng(5)
    steps, m, rows = 3, 2, 40
    P = rng.normal(size=(3, 2, steps, rows, m))        # unit, component, step, row, output
    Y = P[:, 0] + 0.5 * rng.normal(size=(3, steps, rows, m))
    Y += 0.6 * (P[:, 1] - P[:, 0]) * np.array([1.0, 0.5, 1.5])[:, None, None, None]
    D, E = P[:, 1] - P[:, 0], Y - P[:, 0]
    G = np.einsum("uhri,uhri->uhi", D, D)[..., None, None]
    b = np.einsum("uhri,uhri->uhi", D, E)[..., None]
    c = np.einsum("uhri,uhri->uhi", E, E)
    # unit_errors: against the blended predictions' squared error
    W = rng.uniform(size=(steps, m, 1))
    W = np.concatenate([1 - W, W], axis=2)
    blended = W[None, :, None, :, 0] * P[:, 0] + W[None, :, None, :, 1] * P[:, 1]
    np.testing.assert_allclose(unit_errors(W, G, b, c), np.sum((Y - blended) ** 2, axis=2),
                               rtol=1e-10)
    ratios = []
    for u in range(3):
        rest = [v for v in range(3) if v != u]
        w = np.clip(np.sum(D[rest] * E[rest], axis=(0, 2)) / np.sum(D[rest] ** 2, axis=(0, 2)),
                    0, 1)                                                  # (steps, m)
        pred = (1 - w)[:, None, :] * P[u, 0] + w[:, None, :] * P[u, 1]
        ratios.append(np.sqrt(np.sum((Y[u] - pred) ** 2, axis=1) / np.sum(E[u] ** 2, axis=1)))
    assert held_out_score(G, b, c, [0, 1], "pooled") == pytest.approx(np.mean(ratios),
                                                                       rel=1e-10)
    with pytest.raises(ValueError, match="units"):
        held_out_score(G[:1], b[:1], c[:1], [0, 1], "pooled")
    with pytest.raises(ValueError, match="rule"):
        held_out_score(G, b, c, [0, 1], "median")


def test_held_out_gate_against_explicit_predictions():
    """Three units, one extra component (J = 1), one output per group: the blend is kept at a
    step and output only where, for every unit (need "every"), or on the mean over the units
    of the RMSE ratios (need "mean"), the weight chosen on the two others (pooled:
    the closed form clip(sum d e / sum d d, 0, 1); worst: the point of {0, 0.01, .., 1} whose
    larger ratio over the two others of its squared error to the reference's is least, the
    first such point) gives that unit a lower error than the reference; elsewhere the weights
    are the reference's alone. All computed here from the predictions themselves; the data
    make the extra component help every unit on output 0 (but one at step 4) and hurt one
    unit on output 1 (a little at step 1, where the mean keeps the blend)."""
    from cdam_core.models.kstep_blend import held_out_gate
    rng = np.random.default_rng(11)
    steps, m, rows = 4, 2, 60
    P = rng.normal(size=(3, 2, steps, rows, m))        # unit, component, step, row, output
    D = P[:, 1] - P[:, 0]
    gain = np.ones((3, steps, m))
    gain[:, :, 1] = [[0.9], [0.8], [-0.6]]              # unit 2: the component hurts output 1
    gain[:, 3, 0] = [0.05, 0.9, 0.9]                    # step 4, output 0: unit 0 barely
    gain[2, 0, 1] = 0.3                                 # step 1, output 1: unit 2 a little
    Y = P[:, 0] + gain[:, :, None, :] * D + 0.3 * rng.normal(size=(3, steps, rows, m))
    E = Y - P[:, 0]
    G = np.einsum("uhri,uhri->uhi", D, D)[..., None, None]
    b = np.einsum("uhri,uhri->uhi", D, E)[..., None]
    c = np.einsum("uhri,uhri->uhi", E, E)
    grid = np.linspace(0.0, 1.0, 101)

    def sse(u, w):                                      # (steps, m) at weight w (steps, m)
        pred = (1 - w)[:, None, :] * P[u, 0] + w[:, None, :] * P[u, 1]
        return np.sum((Y[u] - pred) ** 2, axis=1)

    def choose(units, rule):
        if rule == "pooled":
            return np.clip(np.sum(D[units] * E[units], axis=(0, 2))
                           / np.sum(D[units] ** 2, axis=(0, 2)), 0, 1)
        w = np.zeros((steps, m))
        for k in range(steps):
            for i in range(m):
                worst = [max(np.sum((E[u, k, :, i] - g * D[u, k, :, i]) ** 2)
                             / np.sum(E[u, k, :, i] ** 2) for u in units) for g in grid]
                w[k, i] = grid[int(np.argmin(worst))]
        return w

    for rule in ("pooled", "worst"):
        ratio = np.zeros((3, steps, m))
        for u in range(3):
            w = choose([v for v in range(3) if v != u], rule)
            ratio[u] = np.sqrt(sse(u, w) / np.sum(E[u] ** 2, axis=1))
        kept = {"every": np.all(ratio < 1, axis=0), "mean": np.mean(ratio, axis=0) < 1}
        # every: kept on output 0 but at step 4 (unit 0), closed on output 1 (unit 2)
        assert kept["every"][:3, 0].all() and not kept["every"][3, 0]
        assert not kept["every"][:, 1].any()
        assert kept["mean"][0, 1] and (kept["mean"] != kept["every"]).sum() == 1
        full = choose([0, 1, 2], rule)
        W = np.stack([1 - full, full], axis=2)
        for need in ("every", "mean"):
            gated, got = held_out_gate(W, G, b, c, [0, 1], rule, need=need)
            np.testing.assert_array_equal(got, kept[need])
            expect = np.where(kept[need][..., None], W, np.array([1.0, 0.0]))
            np.testing.assert_allclose(gated, expect, atol=1e-12)
    with pytest.raises(ValueError, match="need"):
        held_out_gate(W, G, b, c, [0, 1], "worst", need="median")
