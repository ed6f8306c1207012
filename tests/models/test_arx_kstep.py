"""The ARX-anchored k-step model (kind arx_kstep, models/arx_kstep.py) on an independent
two-output plant with input and state nonlinearities a linear ARX lacks (generated here in plain
numpy): it starts exactly at the ARX, LM only lowers its training error, its k-step predictions
are the core's rollout, it learns what the ARX misses on held-out data; bad input named."""
import numpy as np
import pytest

from cdam_core import _core
from cdam_core.models import ArxKStep, ArxModel


def _inputs(n, seed):
    """(rng, U): two smooth random inputs (first-order filtered white noise)."""
    rng = np.random.default_rng(seed)
    U = np.zeros((n, 2))
    for t in range(1, n):
        U[t] = 0.9 * U[t - 1] + 0.3 * rng.normal(size=2)
    return rng, U


def _plant(n, seed):
    """y1' = 0.85 y1 + 0.1 y2 + 0.4 tanh(2 u1(t-1)); y2' = 0.8 y2 + 0.3 u2(t-1) - 0.3 y1 |y1|,
    smooth random inputs, small output noise."""
    rng, U = _inputs(n, seed)
    Y = np.zeros((n, 2))
    for t in range(1, n):
        y1, y2 = Y[t - 1]
        Y[t] = [0.85 * y1 + 0.1 * y2 + 0.4 * np.tanh(2 * U[t - 1, 0]),
                0.8 * y2 + 0.3 * U[t - 1, 1] - 0.3 * y1 * abs(y1)]
    return U, Y + 0.002 * rng.normal(size=Y.shape)


def _kstep_rmse(model, U, Y, k):
    P = model.predict(U, Y, mode="k_step", k=k)
    first = 10
    return np.sqrt(np.mean((P[first:] - Y[first:]) ** 2, axis=0))


@pytest.fixture(scope="module")
def trained():
    U, Y = _plant(3000, 1)
    m = ArxKStep((1, 1, 1), hidden=6, lags=1, horizon=10, epochs=25, seed=2).fit(U, Y)
    return m, U, Y


def test_starts_at_the_arx_and_only_lowers_the_training_error(trained):
    U, Y = _plant(3000, 1)
    zero = ArxKStep((1, 1, 1), hidden=6, lags=1, horizon=10, epochs=0).fit(U, Y)
    arx = ArxModel((1, 1, 1)).fit(U, Y)
    for k in (1, 5):
        np.testing.assert_allclose(zero.predict(U, Y, mode="k_step", k=k),
                                   arx.predict(U, Y, mode="k_step", k=k), rtol=0, atol=1e-12)
    # error scales: the ARX's own RMS error per step and output, so its mse is 1 exactly
    assert zero.history_["mse"][0] == pytest.approx(1.0, rel=1e-12)
    mse = np.array(trained[0].history_["mse"])
    assert mse[0] == pytest.approx(1.0, rel=1e-12)
    assert np.all(np.diff(mse) <= 0) and mse[-1] < 0.5


def test_learns_what_the_arx_lacks_on_held_out_data(trained):
    m = trained[0]
    U, Y = _plant(2000, 7)                       # another record of the plant
    arx = ArxModel((1, 1, 1)).fit(*trained[1:])
    for k in (1, 10, 30):
        mine, base = _kstep_rmse(m, U, Y, k), _kstep_rmse(arx, U, Y, k)
        assert np.all(mine < 0.7 * base), (k, mine, base)


def test_predictions_are_the_cores_rollout(trained):
    # the core's k-step error of a few windows (the training problem rebuilt from the fitted
    # model) against the protocol's k-step prediction at the window ends
    m, U, Y = trained
    S, E, Dr, _, _ = m._windows(U, Y, [(0, len(U))])
    starts = np.array([5, 400, 2500])
    K = 10
    e, _ = _core.kstep_jacobian(m.theta_, S, E, Dr, starts, K, m.hidden, m.in_mean_,
                                m.in_scale_, m.out_scale_, np.ones(2), lin=m._lin())
    P = m.predict(U, Y, mode="k_step", k=K)
    last = e.reshape(len(starts), K, 2)[:, -1]
    np.testing.assert_allclose(Y[starts + K] - last, P[starts + K], rtol=0, atol=1e-10)


def test_same_seed_same_result_at_any_thread_count():
    U, Y = _plant(1200, 3)
    a = ArxKStep((1, 1, 1), hidden=4, lags=1, horizon=8, epochs=4, threads=1).fit(U, Y)
    b = ArxKStep((1, 1, 1), hidden=4, lags=1, horizon=8, epochs=4, threads=2).fit(U, Y)
    assert np.array_equal(a.theta_, b.theta_)


def test_validation_keeps_the_best_epoch():
    U, Y = _plant(1500, 4)
    Uv, Yv = _plant(800, 5)
    m = ArxKStep((1, 1, 1), hidden=4, lags=1, horizon=8, epochs=6).fit(
        U, Y, validation=(Uv, Yv, None))
    h = m.history_
    assert h["best_epoch"] == int(np.argmin(h["val_mse"]))


@pytest.mark.parametrize("kw, message", [
    ({"narx": (1, 1, 0)}, "narx: the delay nk must be >= 1"),
    ({"weighting": "naive"}, "weighting: unknown 'naive'"),
    ({"net_features": "cubic"}, "net_features: unknown 'cubic'"),
    ({"hidden": 0}, "hidden: must be"),
    ({"mu": -1.0}, "mu: must be"),
])
def test_bad_parameters_are_named(kw, message):
    with pytest.raises(ValueError, match=message):
        ArxKStep(**{"narx": (1, 1, 1), **kw})


@pytest.mark.parametrize("kw, message", [
    ({"blind": [5]}, r"blind: output indices must be in 0\.\.1"),
    ({"groups": [0, 1, 2]}, "groups: 3 labels for 2 outputs"),
    ({"net_features": "physics"}, "U: physics features need 4 motor commands"),
])
def test_bad_fit_input_is_named(kw, message):
    U, Y = _plant(600, 6)
    with pytest.raises(ValueError, match=message):
        ArxKStep((1, 1, 1), hidden=2, horizon=5, epochs=1, **kw).fit(U, Y)


def _stack(parts):
    """A record.stack.Stack of (U, Y) records laid end to end (outputs y0, y1)."""
    from cdam_core.record.stack import Stack
    U = np.vstack([u for u, _ in parts])
    Y = np.vstack([y for _, y in parts])
    n = [len(u) for u, _ in parts]
    return Stack([f"r{k}" for k in range(len(parts))], ["u0", "u1"], ["y0", "y1"], U, Y,
                 np.arange(len(U)) * 0.01, n, np.repeat(np.arange(len(parts)), n),
                 np.concatenate([np.arange(k) for k in n]))


def _linear(n, seed):
    """y' = A y + B u(t-1) exactly (an ARX(1, 1, 1)), small output noise."""
    rng, U = _inputs(n, seed)
    Y = np.zeros((n, 2))
    for t in range(1, n):
        Y[t] = [[0.85, 0.1], [-0.2, 0.8]] @ Y[t - 1] + [0.4, 0.3] * U[t - 1]
    return U, Y + 0.002 * rng.normal(size=Y.shape)


@pytest.mark.parametrize("plant, kept, blend", [(_plant, True, "none"),
                                                (_plant, True, "validation"),
                                                (_linear, False, "validation")])
def test_anchored_fitter_keeps_the_network_only_where_validation_says_so(plant, kept, blend):
    from cdam_core.evaluate.crossfold import AnchoredFitter
    from cdam_core.models.kstep_blend import KStepBlend
    fit_parts, valid_parts = [plant(1500, 11), plant(1500, 12)], [plant(1000, 13)]
    fit, valid = _stack(fit_parts), _stack(valid_parts)
    train = _stack(fit_parts + valid_parts)
    fitter = AnchoredFitter(grid={"small": {"hidden": 4, "lags": 1, "horizon": 10}},
                            fixed={"epochs": 8, "weighting": "base"},
                            arx_grid=((1, 1, 1), (2, 1, 1)), groups=(), blind=(),
                            blend=blend)
    model = fitter(train, fit, valid)
    c = fitter.choices[-1]
    # two inputs: physics features are no candidate, the anchor is the raw-input ARX
    assert c["anchor_features"] == "raw" and all(k.startswith("raw ")
                                                 for k in c["anchor_validation"])
    if kept:
        assert c["chosen"] == "small" and c["validation"]["small"] < c["validation"]["arx"]
        net = model
        if blend == "validation":         # the raw ARX (the anchor) and the network, blended
            assert isinstance(model, KStepBlend) and len(model.components_) == 2
            assert type(model.components_[0]) is ArxModel
            assert np.array_equal(model.weights_, np.asarray(c["blend_weights"]))
            assert model.weights_.shape == (50, 2, 2)    # steps: max(select_horizons, K)
            net = model.components_[-1]
        assert isinstance(net, ArxKStep)
        assert list(net.arx_.orders) == c["arx_orders"]
        assert net.epochs == c["epochs"] >= 1 and net.n_outputs_ == 2
    else:
        assert c["chosen"] == "arx" and type(model) is ArxModel


def _rotors(n, seed):
    """Four positive smooth 'rotor speeds' and two outputs driven by their squares (a roll-like
    difference and a thrust-like sum): physics features fit, raw inputs do not."""
    rng = np.random.default_rng(seed)
    U = np.ones((n, 4))
    Y = np.zeros((n, 2))
    for t in range(1, n):
        U[t] = 1 + 0.9 * (U[t - 1] - 1) + 0.12 * rng.normal(size=4)
        f = U[t - 1] ** 2
        Y[t] = [0.8 * Y[t - 1, 0] + 0.3 * (f[0] + f[3] - f[1] - f[2]),
                0.7 * Y[t - 1, 1] + 0.2 * (f.sum() - 4)]
    return U, Y + 0.003 * rng.normal(size=Y.shape)


def _numpy_relative_error(parts_fit, U, Y, na, nb, physics, horizons):
    """Independent of the package: ARX(na, nb, 1) on raw inputs or on [u/s, T, roll, pitch,
    yaw] (f = (u/s)^2, s = the fit records' max |u|) by numpy least squares over the fit records
    (no regressor across records), k-step from each origin on (U, Y); the mean over horizons
    and outputs of its MAE over the naive MAE on the rows t >= t0 + k - 1."""
    s = np.max(np.abs(np.vstack([u for u, _ in parts_fit])), axis=0)

    def feats(u):
        if not physics:
            return u
        f = (u / s) ** 2
        return np.c_[u / s, f.sum(1), f[:, 0] + f[:, 3] - f[:, 1] - f[:, 2],
                     f[:, 0] + f[:, 1] - f[:, 2] - f[:, 3], f[:, 0] - f[:, 1] + f[:, 2] - f[:, 3]]

    t0 = max(na, nb)

    def reg(F, Z, t):
        return np.concatenate([Z[t - j] for j in range(1, na + 1)]
                              + [F[t - 1 - j] for j in range(nb)] + [[1.0]])

    A, T = [], []
    for u, y in parts_fit:
        F = feats(u)
        A += [reg(F, y, t) for t in range(t0, len(u))]
        T += [y[t] for t in range(t0, len(u))]
    W = np.linalg.lstsq(np.array(A), np.array(T), rcond=None)[0]
    F = feats(U)
    ratios = []
    for k in horizons:
        rows = np.arange(t0 + k - 1, len(Y))
        P = np.empty((rows.size, Y.shape[1]))
        for i, t in enumerate(rows):
            Z = Y[:t + 1].copy()
            for s_ in range(t - k + 1, t + 1):
                Z[s_] = reg(F, Z, s_) @ W
            P[i] = Z[t]
        ratios.append(np.mean(np.abs(P - Y[rows]), 0) / np.mean(np.abs(Y[rows - k] - Y[rows]), 0))
    return float(np.mean(ratios))


def test_anchored_fitter_chooses_the_anchors_features_and_orders_on_validation():
    from cdam_core.evaluate.crossfold import AnchoredFitter
    fit_parts, valid_parts = [_rotors(700, 21), _rotors(700, 22)], [_rotors(400, 23)]
    fit, valid = _stack(fit_parts), _stack(valid_parts)
    fit.inputs = valid.inputs = ["u0", "u1", "u2", "u3"]
    train = _stack(fit_parts + valid_parts)
    train.inputs = fit.inputs
    grid = ((1, 1, 1), (2, 2, 1))
    fitter = AnchoredFitter(grid={"tiny": {"hidden": 2, "lags": 1, "horizon": 5}},
                            fixed={"epochs": 2, "net_features": "raw"}, arx_grid=grid,
                            select_horizons=(1, 5), groups=(), blind=())
    fitter(train, fit, valid)
    c = fitter.choices[-1]
    Uv, Yv = valid_parts[0]
    mine = {f"{'physics' if ph else 'raw'} {na},{nb},1":
            _numpy_relative_error(fit_parts, Uv, Yv, na, nb, ph, (1, 5))
            for ph in (False, True) for na, nb, _ in grid}
    assert c["anchor_validation"].keys() == mine.keys()
    for k, v in mine.items():
        assert c["anchor_validation"][k] == pytest.approx(v, rel=1e-9), k
    best = min(mine, key=mine.get)
    assert best.startswith("physics") and mine[best] < 0.8 * min(
        v for k, v in mine.items() if k.startswith("raw"))
    assert f"{c['anchor_features']} {','.join(map(str, c['arx_orders']))}" == best
    assert fitter.anchor_.features == "physics" and list(fitter.anchor_.orders) == \
        c["arx_orders"]


def test_anchored_fitter_type_out_design_and_the_direct_predictor():
    """blend_design='types': one unit per training type (the file-name prefix), the direct
    predictor kept exactly when its held-out score is the lower, the final blend's components
    and weights those the choice names; bad option combinations rejected by name."""
    from cdam_core.evaluate.crossfold import AnchoredFitter
    from cdam_core.models.arx_direct import ArxDirect
    from cdam_core.models.kstep_blend import KStepBlend
    parts = [_plant(1200, s) for s in (31, 32, 33, 34, 35, 36)]
    train = _stack(parts)
    train.names = ["a_1", "a_2", "b_1", "b_2", "c_1", "c_2"]
    fit, valid = _stack([parts[0], parts[2], parts[4]]), _stack([parts[1], parts[3], parts[5]])
    fitter = AnchoredFitter(grid={"small": {"hidden": 4, "lags": 1, "horizon": 10}},
                            fixed={"epochs": 8, "weighting": "base"},
                            arx_grid=((1, 1, 1), (2, 1, 1)), groups=(), blind=(),
                            blend_design="types", direct=True)
    model = fitter(train, fit, valid)
    c = fitter.choices[-1]
    assert c["chosen"] == "small" and isinstance(model, KStepBlend)
    t = c["type_out"]
    assert t["types"] == ["a", "b", "c"]
    s = t["scores"]
    assert np.isfinite(s["with_direct"]) and np.isfinite(s["without_direct"])
    assert t["keep_direct"] == (s["with_direct"] < s["without_direct"])
    kinds = [type(p) for p in model.components_]
    assert (ArxDirect in kinds) == t["keep_direct"]
    # step 1's own regressors: the final direct predictor carries the type-out choice
    first = c["direct"]["first"]
    assert set(first["chosen"]) == {0, 1}
    for p in model.components_:
        if isinstance(p, ArxDirect):
            assert [[o, list(m.orders), m.features] for o, m in
                    zip(p.first_outputs_, p.first_)] == first["parts"]
            # the default (mix): mixed with the raw ARX where a group has a step 1 of its own
            assert (p.mix_ is not None) == bool(first["parts"])
            if first["parts"]:
                assert list(p.mix_.orders) == list(model.components_[0].orders)
    assert model.weights_.shape == (50, 2, len(model.components_))
    assert np.array_equal(model.weights_, np.asarray(c["blend_weights"]))
    # the gate: per step and group the ungated weights, or the raw ARX's alone where closed
    ungated, gate = fitter.blends_["types_worst"].weights_, t["gate"]
    assert np.shape(gate["kept"]) == (50, 2)
    for j in range(2):
        closed = np.asarray(gate["closed"][j], int) - 1
        assert np.array_equal(np.flatnonzero(~np.asarray(gate["kept"], bool)[:, j]), closed)
        keep = np.setdiff1d(np.arange(50), closed)
        assert np.array_equal(model.weights_[keep, j], ungated[keep, j])
        assert np.all(model.weights_[closed, j, 0] == 1.0)
    assert np.array_equal(fitter.blends_["types_pooled"].weights_,
                          np.asarray(t["other_rule_weights"]["pooled"]))
    assert set(fitter.blends_) == {"flights", "types_worst", "types_pooled",
                                   "types_worst_every", "types_worst_mean"}
    assert gate["need"] == "mean" and np.array_equal(
        fitter.blends_["types_worst_mean"].weights_, model.weights_)
    assert c["direct"]["orders"][2] == c["arx_orders"][2]       # the anchor's delay
    with pytest.raises(ValueError, match="direct"):
        AnchoredFitter(direct=True)
    with pytest.raises(ValueError, match="blend_design"):
        AnchoredFitter(blend_design="folds")
    with pytest.raises(ValueError, match="gate"):
        AnchoredFitter(gate="median")
    train.names = ["a_1"] * 6
    with pytest.raises(ValueError, match="type"):
        fitter(train, fit, valid)
    # auto: the type-out design with two or more types, else the validation flights'
    auto = AnchoredFitter(grid=fitter.grid, fixed=fitter.fixed, arx_grid=((1, 1, 1),),
                          groups=(), blind=(), blend_design="auto", direct=True)
    m = auto(train, fit, valid)
    a = auto.choices[-1]
    assert (a["blend_design"], a["blend_design_asked"], a["type_out"], a["direct"]) == \
        ("flights", "auto", None, None)
    assert ArxDirect not in [type(p) for p in getattr(m, "components_", [m])]


def _delays(n, seed):
    """y0 driven by u0 one sample back, y1 by u1 two samples back (an ARX of each), noise."""
    rng, U = _inputs(n, seed)
    Y = np.zeros((n, 2))
    for t in range(2, n):
        Y[t] = [0.8 * Y[t - 1, 0] + 0.5 * U[t - 1, 0], 0.7 * Y[t - 1, 1] + 0.4 * U[t - 2, 1]]
    return U, Y + 0.01 * rng.normal(size=Y.shape)


def test_first_step_chosen_type_out_per_group():
    """``AnchoredFitter._first_step``: per group (here each output), the candidate of least
    mean held-out one-step RMSE ratio to the reference ARX; its scores equal numpy least
    squares written here (fit on the other types' records, rows t >= 2 of the held-out
    type's); the newest input wins for y0, the direct's own delay-2 step for y1 (no entry)."""
    from cdam_core.evaluate.crossfold import AnchoredFitter
    parts = [_delays(600, s) for s in (41, 42, 43, 44, 45, 46)]
    train = _stack(parts)
    train.names = ["a_1", "a_2", "b_1", "b_2", "c_1", "c_2"]
    fitter = AnchoredFitter(arx_grid=((1, 1, 1), (1, 1, 2)), anchor_features=("raw",),
                            groups=(), blind=(), blend_design="types", direct=True)
    ref = ("raw", (1, 1, 2))
    got = fitter._first_step(train, ref, {"orders": [1, 1, 2]}, "raw", [0, 1])

    def one_step(fit_parts, held_parts, nk):
        X, T = [], []
        for u, y in fit_parts:
            for t in range(max(1, nk), len(y)):
                X.append([y[t - 1, 0], y[t - 1, 1], u[t - nk, 0], u[t - nk, 1], 1.0])
                T.append(y[t])
        coef = np.linalg.lstsq(np.array(X), np.array(T), rcond=None)[0]
        sse = np.zeros(2)
        for u, y in held_parts:
            R = np.array([[y[t - 1, 0], y[t - 1, 1], u[t - nk, 0], u[t - nk, 1], 1.0]
                          for t in range(2, len(y))])
            sse += np.sum((y[2:] - R @ coef) ** 2, axis=0)
        return sse

    ratios = []
    for held in range(3):
        out = parts[2 * held:2 * held + 2]
        rest = [p for k, p in enumerate(parts) if k // 2 != held]
        ratios.append(np.sqrt(one_step(rest, out, 1) / one_step(rest, out, 2)))
    mean = np.mean(ratios, axis=0)
    for g in (0, 1):
        assert got["scores"][g]["raw 1,1,1"] == pytest.approx(mean[g], rel=1e-9)
        assert got["scores"][g]["raw 1,1,2"] == pytest.approx(1.0, rel=1e-12)
    assert mean[0] < 0.9 and mean[1] > 1.0
    assert got["chosen"] == {0: "raw 1,1,1", 1: "raw 1,1,2"}
    assert got["parts"] == [[[0], [1, 1, 1], "raw"]]
