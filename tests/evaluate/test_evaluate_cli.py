"""`cdam evaluate` on saved models of two kinds: multi-step RMSE against a numpy computation of
the ARX h-step predictor, the naive predictor, segments, and named errors."""
import json

import numpy as np
import pytest

from cdam_core.cli.main import main
from cdam_core.models import ArxModel, save_model


def _record(path, n, seed, dt=0.01):
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1] + 0.05 * rng.standard_normal()
    np.savetxt(path, np.column_stack([np.arange(n) * dt, u, y]), delimiter=",",
               header="t,u,y", comments="", fmt="%.17g")
    return u, y


def _h_step(a, b, c, u, y, h):
    """y(t|t-h) of y(t) = a y(t-1) + b u(t-1) + c, for t >= h (closed form)."""
    t = np.arange(h, len(y))
    p = a ** h * y[t - h]
    for j in range(1, h + 1):
        p = p + a ** (j - 1) * (b * u[t - j] + c)
    return t, p


def test_arx_horizons_match_numpy(tmp_path):
    u1, y1 = _record(tmp_path / "a.csv", 400, 0)
    u2, y2 = _record(tmp_path / "b.csv", 300, 1)
    m = ArxModel((1, 1, 1)).fit(u1[:, None], y1[:, None])
    save_model(tmp_path / "m.json", m, inputs=["u"], outputs=["y"])
    doc = json.loads((tmp_path / "m.json").read_text())["model"]
    (a,), (b,), (c,) = doc["coef"]      # rows: y lag, u lag, constant (docs/MODEL_FILE.md)
    assert main(["evaluate", str(tmp_path / "m.json"), str(tmp_path / "a.csv"),
                 str(tmp_path / "b.csv"), "--horizon", "8", "--json", str(tmp_path / "e.json"),
                 "--report", str(tmp_path / "rep"), "--quiet"]) == 0
    js = json.loads((tmp_path / "e.json").read_text())
    assert js["horizons"] == list(range(1, 9))
    for i, h in enumerate(js["horizons"]):
        errs, naive = [], []
        for u, y in ((u1, y1), (u2, y2)):      # each record its own segment
            t, p = _h_step(a, b, c, u, y, h)
            errs.append(p - y[t])
            naive.append(y[t - h] - y[t])
        want = np.sqrt(np.mean(np.concatenate(errs) ** 2))
        assert js["rmse"]["model"]["y"][i] == pytest.approx(want, rel=1e-9)
        assert js["rmse"]["naive"]["y"][i] == pytest.approx(
            np.sqrt(np.mean(np.concatenate(naive) ** 2)), rel=1e-12)
    assert js["rmse"]["model"]["y"][-1] < js["rmse"]["naive"]["y"][-1]
    assert (tmp_path / "rep" / "rmse_vs_horizon.png").is_file()


def test_greybox_model_is_evaluated(tmp_path):
    """The residual loop's saved model (kind greybox) goes through the same command."""
    import sys
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parents[1] / "residual"))
    from test_residual_synth_data import rigid_axis_record
    rec = rigid_axis_record(seed=2, Fc=1.5, duration=4.0)
    np.savetxt(tmp_path / "r.csv", np.column_stack([rec["t"], rec["tau"], rec["q"]]),
               delimiter=",", header="t,force,pos", comments="", fmt="%.12g")
    assert main(["residual", str(tmp_path / "r.csv"), "--model", "rigid_axis", "--map",
                 "tau=force,q=pos", "--no-free-run", "--estimator", "idim-ls", "--json",
                 str(tmp_path / "o.json"), "--save", str(tmp_path / "g.json")]) == 0
    assert main(["evaluate", str(tmp_path / "g.json"), str(tmp_path / "r.csv"), "--horizon",
                 "100", "--json", str(tmp_path / "e.json"), "--quiet"]) == 0
    js = json.loads((tmp_path / "e.json").read_text())
    assert js["model"]["kind"] == "greybox"
    assert js["horizons"][-1] == 100
    assert js["rmse"]["model"]["pos"][-1] < 0.2 * js["rmse"]["naive"]["pos"][-1]
    assert js["free_run"]["model"]["pos"]["rmse"] < np.std(rec["q"])


def test_named_errors(tmp_path, capsys):
    u, y = _record(tmp_path / "a.csv", 200, 0)
    m = ArxModel((1, 1, 1)).fit(u[:, None], y[:, None])
    save_model(tmp_path / "m.json", m, inputs=["u"], outputs=["speed"])
    assert main(["evaluate", str(tmp_path / "m.json"), str(tmp_path / "a.csv")]) == 2
    assert "speed" in capsys.readouterr().err
    save_model(tmp_path / "m.json", m, inputs=["u"], outputs=["y"])
    assert main(["evaluate", str(tmp_path / "m.json"), str(tmp_path / "a.csv"),
                 "--horizon", "500"]) == 2
    assert "--horizon" in capsys.readouterr().err
    (tmp_path / "bad.json").write_text("{\"format\": \"cdam-model\"")
    assert main(["evaluate", str(tmp_path / "bad.json"), str(tmp_path / "a.csv")]) == 2
    assert "corrupt" in capsys.readouterr().err


def test_outputs_never_overwrite_inputs(tmp_path, capsys):
    u, y = _record(tmp_path / "a.csv", 200, 0)
    m = ArxModel((1, 1, 1)).fit(u[:, None], y[:, None])
    save_model(tmp_path / "m.json", m, inputs=["u"], outputs=["y"])
    before = (tmp_path / "m.json").read_bytes()
    assert main(["evaluate", str(tmp_path / "m.json"), str(tmp_path / "a.csv"),
                 "--json", str(tmp_path / "m.json")]) == 2
    assert "refusing" in capsys.readouterr().err
    assert (tmp_path / "m.json").read_bytes() == before
