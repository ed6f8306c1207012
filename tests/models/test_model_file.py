"""One model protocol and one model file for every kind: round trips, checked fields,
segments, k-step. Expected values come from numpy/statsmodels computations or from the
model's own other mode (k = 1 is one-step, k >= N is free run: definitions, not outputs)."""
import hashlib
import json

import numpy as np
import pytest

from cdam_core.models import (ArxDirect, ArxKStep, ArxModel, BPNetwork, HybridNarx, KStepBlend, QuadHybrid,
                              QuadPhysics, load_model, read_model_file, save_model)
from cdam_core.models.file import KINDS as FILE_KINDS
from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.models.greybox.effects import CoulombFriction


def _plant(n=500, seed=0):
    rng = np.random.default_rng(seed)
    U = rng.uniform(-1, 1, (n, 2))
    Y = np.zeros((n, 2))
    for t in range(2, n):
        Y[t, 0] = 0.6 * Y[t - 1, 0] - 0.1 * Y[t - 2, 0] + 0.5 * U[t - 1, 0] + 0.2 * np.tanh(2 * U[t - 1, 1])
        Y[t, 1] = 0.8 * Y[t - 1, 1] + 0.3 * U[t, 1] ** 2
    return U, Y + 0.01 * rng.standard_normal(Y.shape)


def _motors(n=500, seed=1):
    rng = np.random.default_rng(seed)
    U = 1 + 0.3 * rng.uniform(-1, 1, (n, 4))
    Y = np.zeros((n, 1))
    for t in range(1, n):
        Y[t] = 0.9 * Y[t - 1] + 0.1 * (U[t - 1] ** 2).sum()
    return U, Y


def _axis(n=3000, dt=1e-3):
    """A rigid axis with dry friction, closed forms in plain numpy (q a sum of sines)."""
    t = np.arange(n) * dt
    q = 0.2 * np.sin(2 * np.pi * 0.7 * t) + 0.05 * np.sin(2 * np.pi * 2.3 * t)
    qd = 2 * np.pi * (0.14 * np.cos(2 * np.pi * 0.7 * t) + 0.115 * np.cos(2 * np.pi * 2.3 * t))
    qdd = -(2 * np.pi) ** 2 * (0.098 * np.sin(2 * np.pi * 0.7 * t)
                               + 0.2645 * np.sin(2 * np.pi * 2.3 * t))
    tau = 0.5 * qdd + 2.0 * qd + 1.0 * np.tanh(qd / 1e-3)
    return tau[:, None], q[:, None]


def _quad():
    from quad_generator import flight
    U, Y, _ = flight(6.0, seed=3)
    return U, Y


KINDS = {
    "bp_static": lambda: (BPNetwork(hidden=4, epochs=15, seed=2), _plant()),
    "bp_narx": lambda: (BPNetwork(hidden=4, epochs=15, seed=2, narx=(2, 2, 1)), _plant()),
    "arx_raw": lambda: (ArxModel((2, 2, 0)), _plant()),
    "arx_physics": lambda: (ArxModel((1, 2, 1), "physics"), _motors()),
    "hybrid": lambda: (HybridNarx((2, 2, 0), seed=3), _plant()),
    "greybox": lambda: (GreyBox("rigid_axis", dt=1e-3, cutoff_hz=40.0,
                                effects=(CoulombFriction("tau"),)), _axis()),
    "quad_physics": lambda: (QuadPhysics(), _quad()),
    "quad_hybrid": lambda: (QuadHybrid(hidden=3, horizon=5, lags=2, epochs=3, stride=10),
                            _quad()),
    "arx_kstep": lambda: (ArxKStep((2, 2, 1), hidden=3, horizon=5, lags=2, epochs=3, stride=10,
                                   net_features="physics", blind=[0, 1, 2],
                                   groups=[0, 0, 0, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3]), _quad()),
    "arx_direct": lambda: (ArxDirect((2, 2, 1), horizon=6), _plant()),
    "kstep_blend": lambda: _blend(),
}


def _blend():
    """An ARX and an ARX on physics features blended with fixed weights over 4 steps (fit
    refits both, the weights kept)."""
    U, Y = _quad()
    comps = [ArxModel((1, 1, 1)).fit(U, Y), ArxModel((2, 1, 1), "physics").fit(U, Y)]
    w = np.random.default_rng(0).uniform(size=(4, Y.shape[1], 1))
    return KStepBlend(comps, weights=np.concatenate([w, 1 - w], axis=2),
                      groups=[0, 0, 0, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3]), (U, Y)


def test_every_registered_kind_has_a_round_trip_case():
    """A new kind added to the model file without a case here fails ([package] item 1)."""
    covered = {type(KINDS[name]()[0]).kind for name in KINDS}
    assert covered == set(FILE_KINDS), sorted(set(FILE_KINDS) - covered)


@pytest.mark.parametrize("name", list(KINDS))
def test_fit_save_load_predict_round_trip(tmp_path, name):
    model, (U, Y) = KINDS[name]()
    model.fit(U, Y)
    path = tmp_path / f"{name}.json"
    save_model(path, model, inputs=[f"in{k}" for k in range(U.shape[1])],
               outputs=[f"out{k}" for k in range(Y.shape[1])], meta={"note": "test"})
    loaded = load_model(path)
    assert type(loaded) is type(model)
    modes = [("one_step", 1)] + ([("free_run", 1), ("k_step", 5)] if model.dynamic else [])
    for mode, k in modes:
        a = model.predict(U, Y, mode=mode, k=k)
        b = loaded.predict(U, Y, mode=mode, k=k)
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)
    assert loaded.meta_ == {"note": "test"}
    assert loaded.parameters().keys() == model.parameters().keys()


def _saved(tmp_path):
    U, Y = _plant()
    m = HybridNarx((2, 2, 0), seed=3).fit(U, Y)
    path = tmp_path / "m.json"
    save_model(path, m)
    return path, json.loads(path.read_text())


def _rewrite(path, doc, rehash=True):
    if rehash:
        body = {k: v for k, v in doc.items() if k != "checksum"}
        doc["checksum"] = {"sha256": hashlib.sha256(json.dumps(
            body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()}
    path.write_text(json.dumps(doc))


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d["model"]["network"].__setitem__("theta", d["model"]["network"]["theta"][:-1]),
     "model.network.theta"),
    (lambda d: d["model"].__setitem__("coef", [[1.0]]), "model.coef"),
    (lambda d: d["model"].pop("narx"), "narx"),
    (lambda d: d["model"].__setitem__("features", "magic"), "model.features"),
    (lambda d: d.__setitem__("kind", "forest"), "kind"),
    (lambda d: d["inputs"].__setitem__(0, "u0\n#include <cstdio>"), "inputs[0]"),
    (lambda d: d["model"]["network"].__setitem__("activation", "relu"), "model.network.activation"),
    (lambda d: d["preprocessing"].__setitem__("smoothing_passes", -1), "preprocessing.smoothing_passes"),
    (lambda d: d["model"].__setitem__("narx", [2, 2, 2**40]), "model.narx[2]"),
    (lambda d: d["model"].__setitem__("residual_weight", 1.5), "model.residual_weight"),
])
def test_bad_fields_are_named(tmp_path, mutate, field):
    path, doc = _saved(tmp_path)
    mutate(doc)
    _rewrite(path, doc)
    with pytest.raises(ValueError) as err:
        read_model_file(path)
    assert field in str(err.value), str(err.value)


def test_truncated_altered_and_foreign_files(tmp_path):
    path, doc = _saved(tmp_path)
    text = path.read_text()
    path.write_text(text[: len(text) // 2])
    with pytest.raises(ValueError, match="corrupt or truncated"):
        read_model_file(path)
    doc["model"]["coef"][0][0] += 1.0
    _rewrite(path, doc, rehash=False)
    with pytest.raises(ValueError, match="checksum"):
        read_model_file(path)
    path.write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(ValueError, match="format"):
        read_model_file(path)
    path.write_text(text.replace('"version": 2', '"version": 9'))
    with pytest.raises(ValueError, match="version"):
        read_model_file(path)
    path.write_text('{"format": "cdam-model", "version": 2, "x": NaN}')
    with pytest.raises(ValueError, match="NaN"):
        read_model_file(path)
    with pytest.raises(FileNotFoundError):
        read_model_file(tmp_path / "absent.json")


def test_save_refuses_what_it_cannot_write(tmp_path):
    with pytest.raises(ValueError, match="not fitted"):
        save_model(tmp_path / "a.json", ArxModel((1, 1, 0)))
    U, Y = _plant()
    m = ArxModel((1, 1, 0)).fit(U, Y)
    with pytest.raises(ValueError, match="names"):
        save_model(tmp_path / "a.json", m, inputs=["a"])
    with pytest.raises(ValueError, match=r"inputs\[0\]"):
        save_model(tmp_path / "a.json", m, inputs=["bad name", "b"])
    with pytest.raises(ValueError, match="model"):
        save_model(tmp_path / "a.json", object())
    assert not (tmp_path / "a.json").exists()


def test_arx_coefficients_and_sigma_equal_ordinary_least_squares():
    import statsmodels.api as sm
    U, Y = _plant()
    m = ArxModel((2, 1, 1)).fit(U, Y)
    t0 = 2
    X = np.column_stack([Y[t0 - 1:-1], Y[t0 - 2:-2], U[t0 - 1:-1], np.ones(len(Y) - t0)])
    for o in range(2):
        res = sm.OLS(Y[t0:, o], X).fit()
        np.testing.assert_allclose(m.coef_[:, o], res.params, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(m.coef_std_[:, o], res.bse, rtol=1e-6)
    p = m.parameters()
    assert p["A[0,1,0]"][0] == pytest.approx(m.coef_[0, 0])


@pytest.mark.parametrize("name", ["bp_narx", "arx_raw", "hybrid"])
def test_segments_never_cross_a_seam(name):
    model, (U, Y) = KINDS[name]()
    model.fit(U, Y)
    cuts = [0, 170, 330, len(U)]
    for mode, k in (("one_step", 1), ("free_run", 1), ("k_step", 4)):
        joint = model.predict(U, Y, mode=mode, k=k, segments=np.diff(cuts).tolist())
        apart = np.vstack([model.predict(U[a:b], Y[a:b], mode=mode, k=k)
                           for a, b in zip(cuts[:-1], cuts[1:])])
        np.testing.assert_array_equal(joint, apart)
        # each segment starts from its own measured rows
        for a in cuts[:-1]:
            np.testing.assert_array_equal(joint[a:a + model.t0], Y[a:a + model.t0])


@pytest.mark.parametrize("name", ["bp_narx", "arx_raw", "hybrid"])
def test_k_step_spans_one_step_to_free_run(name):
    model, (U, Y) = KINDS[name]()
    model.fit(U, Y)
    U, Y = U[:120], Y[:120]
    np.testing.assert_allclose(model.predict(U, Y, mode="k_step", k=1),
                               model.predict(U, Y, mode="one_step"), rtol=1e-12, atol=1e-12)
    # k = N - t0: the last row is predicted from the first t0 rows alone, as in free run
    k = len(U) - model.t0
    np.testing.assert_allclose(model.predict(U, Y, mode="k_step", k=k)[-1],
                               model.predict(U, Y, mode="free_run")[-1], rtol=1e-9, atol=1e-12)


def test_segments_are_checked():
    U, Y = _plant()
    m = ArxModel((1, 1, 0)).fit(U, Y)
    with pytest.raises(ValueError, match="segments"):
        m.predict(U, Y, segments=[100, 100])
    with pytest.raises(ValueError, match=r"segments\[1\]"):
        m.predict(U, Y, segments=[(0, 100), (120, 500)])
    with pytest.raises(ValueError, match="k"):
        m.predict(U, Y, mode="k_step", k=0)
