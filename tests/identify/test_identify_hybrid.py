"""The hybrid NARX model (linear ARX + network on the residual) and physics features.

Expected values: a simulated system whose linear part and nonlinear input term are known (the
least-squares coefficients are checked against numpy's on regressors built here), the X-mixer
formulas written out, and free-run simulation written out as a loop here."""
import numpy as np
import pytest

from cdam_core.evaluate import evaluate
from cdam_core.identify import IdentifyConfig, identify, select_structure
from cdam_core.models import ArxModel, physics_features


def _plant(n=1500, seed=0, noise=0.01):
    """y(t) = 0.8 y(t-1) - 0.1 y(t-2) + 0.5 u(t) + 0.6 tanh(3 u(t-1)) (two outputs)."""
    g = np.random.default_rng(seed)
    U = np.c_[np.convolve(g.uniform(-1, 1, n), np.ones(5) / 5, "same"), g.uniform(-1, 1, n)]
    Y = np.zeros((n, 2))
    for t in range(2, n):
        Y[t, 0] = 0.8 * Y[t - 1, 0] - 0.1 * Y[t - 2, 0] + 0.5 * U[t, 0] + 0.6 * np.tanh(3 * U[t - 1, 0])
        Y[t, 1] = 0.5 * Y[t - 1, 1] + 0.3 * U[t, 1] + 0.2 * U[t - 1, 0]
    return U, Y + noise * g.normal(size=Y.shape)


def test_physics_features_follow_the_x_mixer():
    U = np.array([[1.0, 2.0, 3.0, 4.0], [4.0, 0.0, 2.0, 1.0]])
    F, scale = physics_features(U)
    np.testing.assert_array_equal(scale, [4.0, 2.0, 3.0, 4.0])
    f = (U / scale) ** 2
    np.testing.assert_allclose(F[:, :4], U / scale)
    np.testing.assert_allclose(F[:, 4], f.sum(axis=1))
    np.testing.assert_allclose(F[:, 5], f[:, 0] + f[:, 3] - f[:, 1] - f[:, 2])
    np.testing.assert_allclose(F[:, 6], f[:, 0] + f[:, 1] - f[:, 2] - f[:, 3])
    np.testing.assert_allclose(F[:, 7], f[:, 0] - f[:, 1] + f[:, 2] - f[:, 3])
    with pytest.raises(ValueError, match="U"):
        physics_features(U[:, :3])
    with pytest.raises(ValueError, match="U"):
        physics_features(np.full((2, 4), np.nan))


def test_linear_part_is_numpy_least_squares_and_free_run_is_the_recursion():
    U, Y = _plant()
    m = ArxModel((2, 2, 0), "raw").fit(U, Y)
    # regressors built here: y(t-1), y(t-2), u(t), u(t-1), 1
    t0 = 2
    A = np.array([np.r_[Y[t - 1], Y[t - 2], U[t], U[t - 1], 1.0] for t in range(t0, len(U))])
    W = np.linalg.lstsq(A, Y[t0:], rcond=None)[0]
    np.testing.assert_allclose(m.coef_, W, rtol=1e-9, atol=1e-12)
    P = Y.copy()
    for t in range(t0, len(U)):
        P[t] = np.r_[P[t - 1], P[t - 2], U[t], U[t - 1], 1.0] @ W
    np.testing.assert_allclose(m.predict(U, Y, mode="free_run"), P, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(m.predict(U, Y)[t0:], A @ W, rtol=1e-9, atol=1e-12)


def test_residual_network_is_kept_where_it_helps_and_improves_the_free_run():
    U, Y = _plant()
    Ut, Yt = _plant(seed=1)
    cfg = IdentifyConfig(hidden=5, iterations=10, population=10, lm_epochs=30,
                         smoothing_passes=0, model="hybrid", narx=(2, 2, 0))
    run = identify("iboa", U, Y, seed=0, config=cfg)
    lin = ArxModel((2, 2, 0), "raw").fit(U, Y)
    assert run.model.residual_weight_ == 1.0
    e_h = np.sqrt(np.mean((run.model.predict(Ut, Yt, mode="free_run") - Yt)[2:, 0] ** 2))
    e_l = np.sqrt(np.mean((lin.predict(Ut, Yt, mode="free_run") - Yt)[2:, 0] ** 2))
    assert e_h < 0.7 * e_l  # the tanh term is what the linear part cannot represent
    m = evaluate(run.model, Ut, Yt, ["a", "b"])
    assert set(m) == {"one_step", "free_run"}
    assert run.curve is not None and run.evaluations > 0 and 0 < run.fitness <= 1


def test_select_structure_finds_the_direct_term_and_orders():
    U, Y = _plant(noise=0.002)
    sel = select_structure(U, Y, orders=(1, 2), delays=(0, 1), features=("raw",),
                           decimations=(1, 3))
    assert sel["narx"][2] == 0  # the plant has a direct u(t) term
    assert sel["table"][0][0] == sel["validation_r"] == max(r[0] for r in sel["table"])
    assert sel["decimation"] == 1  # the plant's own rate; decimating by 3 breaks its dynamics
    assert len(sel["table"]) == 2 * 2 * 2


def test_bad_input_is_rejected_with_the_argument_named():
    U, Y = _plant(n=200)
    with pytest.raises(ValueError, match="narx"):
        ArxModel((0, 0, 1))
    with pytest.raises(ValueError, match="features"):
        ArxModel((2, 2, 0), "magic")
    with pytest.raises(ValueError, match="U, Y"):
        ArxModel((2, 2, 0)).fit(U, Y[:-1])
    with pytest.raises(ValueError, match="Y"):
        ArxModel((2, 2, 0)).fit(U, np.full_like(Y, np.nan))
    with pytest.raises(ValueError, match="not fitted"):
        ArxModel((2, 2, 0)).predict(U, Y)
    m = ArxModel((2, 2, 0)).fit(U, Y)
    with pytest.raises(ValueError, match="mode"):
        m.predict(U, Y, mode="sideways")
    with pytest.raises(ValueError, match="U: expected 2 columns"):
        m.predict(U[:, :1], Y)
    with pytest.raises(ValueError, match="narx"):
        IdentifyConfig(model="hybrid")
    with pytest.raises(ValueError, match="features"):
        IdentifyConfig(features="physics")
    with pytest.raises(ValueError, match="model"):
        IdentifyConfig(model="forest")


def test_cli_identify_hybrid(tmp_path, capsys):
    import json

    from cdam_core.cli.main import main
    U, Y = _plant(n=600)
    csv = tmp_path / "d.csv"
    np.savetxt(csv, np.c_[np.arange(600) * 0.01, U, Y], delimiter=",",
               header="t,u1,u2,y1,y2", comments="")
    out = tmp_path / "o.json"
    args = ["identify", str(csv), "--inputs", "u1,u2", "--outputs", "y1,y2", "--split", "0.7",
            "--algo", "iboa", "--seeds", "1", "--hidden", "3", "--iterations", "3",
            "--population", "6", "--epochs", "5", "--smoothing", "0", "--quiet"]
    assert main(args + ["--model", "hybrid", "--narx", "2,2,0", "--json", str(out),
                        "--report", str(tmp_path / "rep")]) == 0
    res = json.loads(out.read_text())
    assert res["config"]["model"] == "hybrid"
    fr = res["algorithms"]["iboa"]["runs"][0]["metrics"]["test"]["free_run"]
    assert fr["y2"]["r"] > 0.9  # a nearly linear output: the ARX part alone follows it
    assert "hybrid" in (tmp_path / "rep" / "report.md").read_text()
    capsys.readouterr()
    assert main(args + ["--model", "hybrid"]) == 2
    assert "--narx" in capsys.readouterr().err
    assert main(args + ["--features", "physics"]) == 2
    assert main(args + ["--model", "hybrid", "--narx", "2,2,0", "--features", "physics"]) == 2
    assert "4 motor" in capsys.readouterr().err
    # every kind has a model file now: the saved hybrid predicts as the fitted one
    assert main(args + ["--model", "hybrid", "--narx", "2,2,0", "--save",
                        str(tmp_path / "m.json")]) == 0
    from cdam_core import load_model
    loaded = load_model(tmp_path / "m.json")
    assert loaded.kind == "hybrid" and loaded.input_names_ == ["u1", "u2"]
    P = loaded.predict(U, Y, mode="free_run")
    assert P.shape == Y.shape and np.all(np.isfinite(P))


def test_cli_identify_hybrid_ensemble_and_weights(tmp_path, capsys):
    """--ensemble, --residual-weights, --validation-blocks reach the model (K networks' mean,
    a weight from the list or 0, chosen on the blocks) and are refused by name when bad."""
    import json

    from cdam_core import load_model
    from cdam_core.cli.main import main
    U, Y = _plant(n=600)
    csv = tmp_path / "d.csv"
    np.savetxt(csv, np.c_[np.arange(600) * 0.01, U, Y], delimiter=",",
               header="t,u1,u2,y1,y2", comments="")
    args = ["identify", str(csv), "--inputs", "u1,u2", "--outputs", "y1,y2", "--split", "0.7",
            "--algo", "iboa", "--hidden", "3", "--iterations", "2", "--population", "6",
            "--epochs", "5", "--smoothing", "0", "--quiet", "--model", "hybrid",
            "--narx", "2,2,0"]
    m = tmp_path / "m.json"
    assert main(args + ["--ensemble", "2", "--residual-weights", "0.5,1",
                        "--validation-blocks", "3", "--residual-training", "free_run",
                        "--save", str(m), "--json", str(tmp_path / "o.json")]) == 0
    cfg = json.loads((tmp_path / "o.json").read_text())["config"]
    assert (cfg["ensemble"], cfg["residual_weights"], cfg["validation_blocks"],
            cfg["residual_training"]) == (2, [0.5, 1.0], 3, "free_run")
    loaded = load_model(m)
    assert loaded.residual_weight_ in (0.0, 0.5, 1.0) and loaded.net_.hidden_ == 6
    # a weight between 0 and 1 is a valid model file (schema and reader)
    from cdam_core.models.file import save_model
    loaded.residual_weight_ = 0.5
    save_model(tmp_path / "m2.json", loaded, inputs=["u1", "u2"], outputs=["y1", "y2"])
    again = load_model(tmp_path / "m2.json")
    assert again.residual_weight_ == 0.5
    np.testing.assert_array_equal(again.predict(U, Y, mode="free_run"),
                                  loaded.predict(U, Y, mode="free_run"))
    capsys.readouterr()
    for extra, msg in ((["--ensemble", "0"], "--ensemble: must be >= 1"),
                       (["--residual-weights", "0,2"], "--residual-weights: must be in [0, 1]"),
                       (["--residual-weights", "x"], "--residual-weights: expected numbers"),
                       (["--validation-blocks", "1"], "--validation-blocks: must be 0")):
        assert main(args + extra) == 2
        err = capsys.readouterr().err
        assert err.startswith("cdam identify: error: " + msg) and err.count("\n") == 1, err
    assert main(args[:-4] + ["--ensemble", "2"]) == 2
    assert "--ensemble: needs --model hybrid" in capsys.readouterr().err
