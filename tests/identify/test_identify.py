"""The identification pipelines, metrics, comparison, report and `cdam identify`."""
import json

import numpy as np
import pytest
from scipy import stats

from cdam_core.base.metrics import adaptation_value, output_metrics
from cdam_core.evaluate import compare, evaluate
from cdam_core.identify import IdentifyConfig, identify
from cdam_core.reference.pipeline import identify_reference


def _system(n=300, seed=0):
    g = np.random.default_rng(seed)
    U = np.c_[np.sin(np.arange(n) * 0.07) + 0.2 * g.normal(size=n), g.uniform(-1, 1, n)]
    Y = np.c_[np.tanh(1.5 * U[:, 0]) + 0.3 * U[:, 1], U[:, 0] * U[:, 1]]
    return U, Y


CFG = IdentifyConfig(hidden=4, iterations=6, population=10, lm_epochs=15, smoothing_passes=0)


def test_metrics_against_scipy_and_formulas():
    g = np.random.default_rng(1)
    y = g.normal(size=(50, 2))
    p = y + 0.3 * g.normal(size=(50, 2))
    m = output_metrics(y, p, ["a", "b"])
    assert m["a"]["r"] == pytest.approx(stats.pearsonr(y[:, 0], p[:, 0])[0], rel=1e-12)
    e = np.sqrt(np.mean((y[:, 1] - p[:, 1]) ** 2))
    assert m["b"]["rmse"] == pytest.approx(e, rel=1e-12)
    assert m["b"]["nrmse"] == pytest.approx(e / np.std(y[:, 1]), rel=1e-12)
    assert adaptation_value(0.0) == 1.0 and adaptation_value(1.0) == 0.5
    with pytest.raises(ValueError, match="predicted"):
        output_metrics(y, p[:10])
    with pytest.raises(ValueError, match="mse"):
        adaptation_value(-1.0)
    with pytest.raises(ValueError, match="measured"):
        output_metrics(np.full((3, 1), np.nan), np.zeros((3, 1)))


@pytest.mark.parametrize("algo", ["iboa", "boa", "cabc", "bp"])
def test_pipeline_runs_and_lm_only_improves(algo):
    U, Y = _system()
    run = identify(algo, U, Y, seed=2, config=CFG)
    assert run.final_mse <= run.lm_mse[0]
    assert np.all(np.diff(run.lm_mse) <= 0)
    if algo != "bp":
        assert run.lm_mse[0] == pytest.approx(run.optimiser_mse, rel=1e-10)  # LM starts at it
        assert len(run.curve) == CFG.iterations + 1
    assert run.fitness == pytest.approx(1 / (1 + run.final_mse))
    m = evaluate(run.model, U, Y, ["a", "b"])
    assert m["one_step"]["a"]["r"] > 0.9


def test_core_pipeline_equals_reference_pipeline():
    U, Y = _system(200)
    cfg = IdentifyConfig(hidden=3, iterations=4, population=6, lm_epochs=5, smoothing_passes=2)
    a = identify("iboa", U, Y, seed=1, config=cfg)
    b = identify_reference("iboa", U, Y, seed=1, hidden=3, smoothing_passes=2,
                           options=cfg.options("iboa"), lm_epochs=5, lm_goal=cfg.lm_goal)
    np.testing.assert_allclose(a.curve, b["curve"], rtol=1e-9)
    np.testing.assert_allclose(a.lm_mse, b["lm_mse"], rtol=1e-7)


def test_narx_pipeline_has_free_run_metrics():
    g = np.random.default_rng(3)
    u = g.uniform(-1, 1, (400, 1))
    y = np.zeros((400, 1))
    for t in range(1, 400):
        y[t] = 0.7 * y[t - 1] + 0.5 * np.tanh(2 * u[t - 1])
    cfg = IdentifyConfig(hidden=4, iterations=5, population=10, lm_epochs=30, lm_goal=0.0,
                         smoothing_passes=0, narx=(1, 1, 1))
    run = identify("iboa", u[:300], y[:300], seed=0, config=cfg)
    m = evaluate(run.model, u[300:], y[300:], ["y"])
    assert m["free_run"]["y"]["r"] > 0.95


def test_identify_rejects_bad_input():
    U, Y = _system(50)
    with pytest.raises(ValueError, match="algo"):
        identify("pso", U, Y)
    with pytest.raises(ValueError, match="U, Y"):
        identify("bp", U, Y[:10])
    with pytest.raises(ValueError, match="seed"):
        identify("bp", U, Y, seed=-1)
    with pytest.raises(ValueError, match="narx"):
        IdentifyConfig(narx=(0, 0, 0))
    with pytest.raises(ValueError, match="NaN"):
        identify("bp", np.full_like(U, np.nan), Y)


def test_compare_summary_and_rank_sum():
    U, Y = _system()
    res = compare(["iboa", "boa", "bp"], U[:200], Y[:200], records={"test": (U[200:], Y[200:])},
                  seeds=range(3), config=CFG, names=["a", "b"]).result
    s = res["summary"]["boa"]["records"]["test"]["one_step"]["a"]["r"]
    rs = [r["metrics"]["test"]["one_step"]["a"]["r"] for r in res["algorithms"]["boa"]["runs"]]
    assert s["mean"] == pytest.approx(np.mean(rs)) and s["std"] == pytest.approx(np.std(rs, ddof=1))
    p = res["rank_sum"]["boa"]["fitness"]["p_value"]
    a = [r["fitness"] for r in res["algorithms"]["iboa"]["runs"]]
    b = [r["fitness"] for r in res["algorithms"]["boa"]["runs"]]
    assert p == pytest.approx(stats.mannwhitneyu(a, b, alternative="greater").pvalue)


def _write_csv(path, n=240):
    U, Y = _system(n)
    t = np.arange(n) * 0.01
    np.savetxt(path, np.c_[t, U, Y], delimiter=",", header="t,u1,u2,y1,y2", comments="")


def test_cli_identify_json_report_and_model(tmp_path):
    from cdam_core import load_model
    from cdam_core.cli.main import main
    csv = tmp_path / "d.csv"
    _write_csv(csv)
    out = tmp_path / "o.json"
    rc = main(["identify", str(csv), "--inputs", "u1,u2", "--outputs", "y1,y2", "--algo", "all",
               "--seeds", "2", "--hidden", "3", "--iterations", "3", "--population", "6",
               "--epochs", "5", "--smoothing", "1", "--json", str(out), "--report",
               str(tmp_path / "rep"), "--save", str(tmp_path / "m.json"), "--quiet"])
    assert rc == 0
    res = json.loads(out.read_text())
    assert set(res["algorithms"]) == {"iboa", "boa", "cabc", "bp"}
    run = res["algorithms"]["cabc"]["runs"][0]
    assert {"seconds", "fitness", "metrics"} <= set(run)
    assert set(run["metrics"]["test"]["one_step"]["y2"]) >= {"r", "rmse", "nrmse"}
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "IBOA-BP" in md and (tmp_path / "rep" / "convergence.png").stat().st_size > 1000
    model = load_model(tmp_path / "m.json")
    assert model.n_inputs_ == 2 and model.n_outputs_ == 2


def test_cli_identify_errors(tmp_path, capsys):
    from cdam_core.cli.main import main
    csv = tmp_path / "d.csv"
    _write_csv(csv, 60)
    assert main(["identify", str(csv), "--inputs", "u1", "--outputs", "nope", "--quiet"]) == 2
    assert "nope" in capsys.readouterr().err
    assert main(["identify", str(csv), "--inputs", "u1", "--outputs", "y1", "--split", "1.5"]) == 2
    assert main(["identify", str(csv), "--inputs", "u1", "--outputs", "y1", "--narx", "a"]) == 2
