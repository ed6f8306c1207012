"""The residual monitor (evaluate.monitor, `cdam monitor`): the float32 recursion against a plain
scalar twin, the CUSUM threshold against Siegmund's closed form on a white residual, the model
file's monitor section, and the alarm test: three effects switching on at t = 10 s on an
independent generator, each alarmed within 0.5 s, and 60 s without any effect alarm-free."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core.cli.main import main
from cdam_core.evaluate.monitor import (CUSUM_DOWN, CUSUM_UP, EWMA, calibrate,
                                        one_step_residuals, run_monitor)
from cdam_core.models import ArxModel, save_model
from cdam_core.models.file import read_model_file

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _monitor_plant import DT, EFFECTS, ONSET_S, plant  # noqa: E402


@pytest.fixture(scope="module")
def trained():
    U, Y = plant(60_000, seed=1)
    m = ArxModel((2, 2, 1)).fit(U, Y)
    return m, calibrate(m, U, Y, DT, paths=1000, seed=0)


def _twin(sec, R, valid):
    """Plain scalar float32 loop of the module doc's recursion, restart after an alarm."""
    f = np.float32
    n, m = R.shape
    flags = np.zeros((n, m), np.uint8)
    for c in range(m):
        e = up = dn = f(0)
        mu, sd, h, L = (f(sec[k][c]) for k in ("mean", "std", "h", "ewma_limit"))
        k, lam = f(sec["k"]), f(sec["lambda"])
        for t in range(n):
            if not valid[t]:
                continue
            z = f(f(R[t, c]) - mu) / sd
            e = f(e + f(lam * f(z - e)))
            up = max(f(f(up + z) - k), f(0))
            dn = max(f(f(dn - z) - k), f(0))
            fl = (CUSUM_UP if up > h else 0) | (CUSUM_DOWN if dn > h else 0) | \
                 (EWMA if abs(e) > L else 0)
            if fl:
                flags[t, c] = fl
                e = up = dn = f(0)
    return flags


def test_recursion_equals_a_scalar_float32_twin(trained):
    m, sec = trained
    U, Y = plant(15_000, seed=5, effect="friction")
    R, valid = one_step_residuals(m, U, Y)
    res = run_monitor(sec, R, valid)
    assert res.flags.any()                     # the comparison covers alarms and restarts
    np.testing.assert_array_equal(res.flags, _twin(sec, R, valid))


def _siegmund_arl(h, k):
    """One-sided CUSUM on iid N(0, 1): Siegmund's approximation, drift -k, b = h + 1.166."""
    d, b = -k, h + 1.166
    return (np.exp(-2 * d * b) + 2 * d * b - 1) / (2 * d * d)


def test_threshold_on_a_white_residual_matches_siegmund():
    rng = np.random.default_rng(3)
    n = 40_000
    U = rng.uniform(-1, 1, (n, 1))
    Y = np.zeros((n, 1))
    w = 0.01 * rng.standard_normal(n)
    for t in range(1, n):
        Y[t, 0] = 0.5 * Y[t - 1, 0] + U[t - 1, 0] + w[t]
    m = ArxModel((1, 1, 1)).fit(U, Y)
    sec = calibrate(m, U, Y, DT, paths=1000, seed=1)
    assert sec["ar_order"][0] <= 2                  # white: (almost) no AR structure
    # Siegmund: either side alarms within T samples with probability ~ 2 (1 - exp(-T / ARL));
    # the calibration's target for one output is 0.05 / 3
    T, target = int(sec["window_s"] / DT), 0.05 / 3
    hs = np.linspace(3, 15, 2401)
    p = 2 * (1 - np.exp(-T / _siegmund_arl(hs, 0.5)))
    h_siegmund = hs[np.argmax(p <= target)]
    assert sec["h"][0] == pytest.approx(h_siegmund, rel=0.08)
    # EWMA: a white z gives the stationary std sqrt(lam / (2 - lam)); the limit is a few of them
    s_e = np.sqrt(sec["lambda"] / (2 - sec["lambda"]))
    assert 3.0 < sec["ewma_limit"][0] / s_e < 5.0


def test_model_file_monitor_section(tmp_path, trained):
    m, sec = trained
    p = tmp_path / "m.json"
    save_model(p, m, inputs=["u0", "u1"], outputs=["y0", "y1"], monitor=sec)
    mf = read_model_file(p)
    assert mf.monitor == json.loads(json.dumps(sec))
    bad = dict(sec, h=sec["h"][:1])
    with pytest.raises(ValueError, match="monitor.h"):
        save_model(tmp_path / "b.json", m, monitor=bad)
    with pytest.raises(ValueError, match="monitor"):
        save_model(tmp_path / "b.json", m, monitor=dict(sec, version=2))
    doc = json.loads(p.read_text())
    doc["monitor"]["std"][0] = -1.0
    p.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"monitor\.std"):
        read_model_file(p)


def test_alarms_within_half_a_second_and_none_in_60_s(trained):
    m, sec = trained
    U, Y = plant(60_000, seed=2)
    R, valid = one_step_residuals(m, U, Y)
    assert run_monitor(sec, R, valid).alarms == []        # 60 s in control: no alarm
    onset = int(round(ONSET_S / DT))
    for k, effect in enumerate(EFFECTS):
        U, Y = plant(12_000, seed=10 + k, effect=effect)
        R, valid = one_step_residuals(m, U, Y)
        alarms = run_monitor(sec, R, valid).alarms
        assert alarms, effect
        assert alarms[0][0] >= onset, (effect, alarms[0])  # nothing before the onset
        assert (alarms[0][0] - onset) * DT <= 0.5, (effect, alarms[0])


def _csv(path, U, Y):
    t = np.arange(len(U)) * DT
    np.savetxt(path, np.column_stack([t, U, Y]), delimiter=",", header="t,u0,u1,y0,y1",
               comments="", fmt="%.17g")


def test_cli_calibrate_then_monitor(tmp_path, capsys):
    U, Y = plant(20_000, seed=1)
    _csv(tmp_path / "train.csv", U, Y)
    U2, Y2 = plant(11_000, seed=4, effect="bias")
    _csv(tmp_path / "run.csv", U2, Y2)
    save_model(tmp_path / "m.json", ArxModel((2, 2, 1)).fit(U, Y), inputs=["u0", "u1"],
               outputs=["y0", "y1"])
    assert main(["monitor", str(tmp_path / "m.json"), str(tmp_path / "run.csv")]) == 2
    assert "no monitor section" in capsys.readouterr().err
    assert main(["monitor", str(tmp_path / "m.json"), str(tmp_path / "train.csv"), "--paths",
                 "200", "--calibrate", str(tmp_path / "mm.json"), "--quiet"]) == 0
    assert main(["monitor", str(tmp_path / "mm.json"), str(tmp_path / "run.csv"), "--json",
                 str(tmp_path / "a.json")]) == 0
    js = json.loads((tmp_path / "a.json").read_text())
    first = js["alarms"][0]
    assert 10.0 <= first["t"] <= 10.5 and first["output"] in ("y0", "y1")
    assert main(["monitor", str(tmp_path / "mm.json"), str(tmp_path / "run.csv"), "--json",
                 str(tmp_path / "run.csv")]) == 2             # never overwrites an input
    assert main(["monitor", str(tmp_path / "mm.json"), str(tmp_path / "nope.csv")]) == 2


@pytest.mark.parametrize("kind", ["bp_network", "hybrid", "greybox"])
def test_every_kind_with_a_one_step_predictor(tmp_path, kind):
    """The monitor takes any kind's one-step prediction: the residual equals Y - predict
    (one_step) rounded to float32, and an offset added to the measured output from row 1,500
    on is alarmed after it and not before."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "firmware"))
    from _kinds import greybox_file, rigid_record
    if kind == "greybox":
        m = read_model_file(greybox_file(tmp_path / "g.json",
                                         effects=("coulomb", "asymmetric"))).model
        U = rigid_record(3000, seed=3, extra=False)
        Y = np.zeros((3000, 1))
        Y[m.t0:] = m.predict(U, Y, mode="free_run").reshape(-1, 1)[m.t0:]
        Y = Y + 1e-4 * np.random.default_rng(0).standard_normal(Y.shape)
    else:
        U, Y = plant(3000, seed=7)
        if kind == "hybrid":
            from cdam_core.models import HybridNarx
            m = HybridNarx(narx=(2, 2, 1)).fit(U, Y)
        else:
            from cdam_core.models import BPNetwork
            m = BPNetwork(hidden=4, narx=(2, 2, 1), epochs=30).fit(U, Y)
    n = Y.shape[0] // 2
    sec = calibrate(m, U[:n], Y[:n], DT, paths=100, seed=0)
    R, valid = one_step_residuals(m, U, Y)
    P = np.asarray(m.predict(U, Y, mode="one_step")).reshape(Y.shape)
    np.testing.assert_array_equal(R[valid], (Y.astype(np.float32) - P.astype(np.float32))[valid])
    Y2 = Y.copy()
    Y2[n:] += 10 * np.asarray(sec["std"])                  # a sensor offset of 10 std
    R2, valid2 = one_step_residuals(m, U, Y2)
    alarms = run_monitor(sec, R2, valid2).alarms
    assert alarms and alarms[0][0] >= n, (kind, alarms[:3])
