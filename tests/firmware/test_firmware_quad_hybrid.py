"""The quad_hybrid flight model (physics + a recurrent tanh network on the body rates) on the
firmware: export (numbers only, no toolchain needed), and the run on the emulated STM32F405
against the Python model with its residual monitor (QEMU, skipped without the toolchain).

The model is a small quad_hybrid (4 tanh units, 3 rotor lags, 10-step windows, 5 LM epochs:
a 0.1 s fit; tests/firmware/_kinds.py) on the first 6 s of an 8 s flight of the independent
numpy generator (tests/models/quad_generator.py) with a 30 ms rotor lag the physics lacks; the
last 2 s are held out. The nano-drone case fits the documented structure (8 units, 6 lags, K = 50) on a
stretch of a real flight and runs a square flight it never saw.

Tolerance of one step against the Python model (float64), derived a priori from the model's own
numbers along the record (standard rounding bounds, gamma_n = n eps / (1 - n eps), eps = 2^-23,
first order): every dot product of n terms is off by at most gamma_n times the sum of the
terms' absolute values; an input's error passes through tanh with gain <= 1; libm's tanhf adds
at most 4 ulp. The rates' bound (network inputs -> pre-activations -> tanh -> outputs ->
w + d + out, the drift's torque combinations with their cancellation) is computed row by row;
the other states move by one RK4 step whose rounding is a few ulp of each state and of dt times
its derivative's terms, and the quaternion takes dt/2 of the rates' error. k-step and free run:
the recurrence compounds the rounding, so these are held to 1e-4 of each state's span, the
level the other kinds' free runs are held to (tests/firmware/test_firmware_kinds_qemu.py), the
free run over 2 s of the generator (1 s of the nano-drone flight and of the prior "hold"
model: measured, their 2-3 s free runs reach 1.1-1.3e-4 of the smallest span, z and qw, as the
float32 rounding grows along the open-loop trajectory).
"""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core import firmware as fw
from cdam_core.cli.main import main
from cdam_core.models.file import load_model, save_model
from cdam_core.models.flight.hybrid import QuadHybrid
from cdam_core.record.realdata import shared_data_dir

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "models"))
from quad_generator import TRUTH, flight  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _kinds import header_array as _array, header_int as _int  # noqa: E402
from _kinds import QUAD_HYBRID_N_FIT as N_FIT, nanodrone_flight, quad_hybrid_file  # noqa: E402
from _kinds import assert_float32_overflow_refused, cli_check_report  # noqa: E402

EPS = 2.0 ** -23
HOSTILE = '"); system("rm -rf /'
FLIGHTS = shared_data_dir() / "nanodrone"

needs_toolchain = pytest.mark.skipif(fw.toolchain_available() is not None,
                                     reason=f"firmware toolchain: {fw.toolchain_available()}")


def _gamma(n):
    return n * EPS / (1 - n * EPS)


@pytest.fixture(scope="module")
def hybrid(tmp_path_factory):
    """(path, U, Y, monitored path): the small quad_hybrid, and the same with a monitor."""
    folder = tmp_path_factory.mktemp("qh")
    path, U, Y = quad_hybrid_file(folder / "qh.json", meta={"note": HOSTILE})
    mon = quad_hybrid_file(folder / "qh_mon.json", monitor=True)[0]
    return path, U, Y, mon


def test_header_holds_the_file_numbers_only(hybrid, tmp_path):
    path = hybrid[0]
    doc = json.loads(path.read_text())["model"]
    out = tmp_path / "model.hpp"
    assert main(["export-firmware", str(path), "-o", str(out)]) == 0
    text = out.read_text()
    assert "#define CDAM_MODEL_KIND 6" in text
    f32 = lambda v: np.asarray(v, np.float32)  # noqa: E731
    np.testing.assert_array_equal(_array(text, "kNetTheta").astype(np.float32), f32(doc["theta"]))
    np.testing.assert_array_equal(
        _array(text, "kNetScale").astype(np.float32),
        f32(doc["in_mean"] + doc["in_scale"] + doc["out_scale"] + doc["feature_scale"]))
    rot = doc["physics"]["rotation"]       # b (slots 0..2) and e (6..8): the rate increment
    np.testing.assert_array_equal(_array(text, "kDrift").astype(np.float32),
                                  f32(rot[0:3] + rot[6:9]))
    np.testing.assert_array_equal(_array(text, "kTrans").astype(np.float32),
                                  f32(doc["physics"]["translation"]))
    assert (_int(text, "kDelayTrans"), _int(text, "kDelayRot")) == tuple(doc["physics"]["delays"])
    # t0: the physics' 1 + the larger delay (no lag, no reaction), then lags - 1 more rows
    assert doc["physics"]["lag"] == 0 and not doc["physics"]["reaction"]
    assert _int(text, "kHistory") == 1 + max(doc["physics"]["delays"]) + doc["lags"] - 1
    assert (_int(text, "kLags"), _int(text, "kNetHidden")) == (doc["lags"], doc["hidden"])
    assert "system" not in text and "rotor_speed" not in text and "state_" not in text


def test_refusals_are_named(hybrid, tmp_path, monkeypatch):
    m = load_model(hybrid[0])
    m.theta_ = np.array(m.theta_)
    m.theta_[3] = 1e39                      # finite in the file, not in float32
    assert_float32_overflow_refused(m, tmp_path, "kNetTheta")
    to_dict = QuadHybrid.to_dict
    monkeypatch.setattr(QuadHybrid, "to_dict", lambda self: {**to_dict(self), "attitude": 1})
    with pytest.raises(ValueError, match="model.attitude: a quad_hybrid option the firmware "
                                         "does not run yet"):
        fw.load_firmware_model(hybrid[0])


def _one_step_bound(m, U, Y):
    """Per row t0.. and state, the first-order float32 bound of one step (module doc), from the
    model file's numbers (plain numpy, float64)."""
    d = m.to_dict()
    ph = d["physics"]
    H, L = d["hidden"], d["lags"]
    ni = 3 + 3 * L
    th = np.asarray(d["theta"])
    W1 = np.abs(th[:ni * H].reshape(ni, H).T)            # W1(h, i) = theta[i H + h]
    b1 = np.abs(th[ni * H:ni * H + H])
    W2 = np.abs(th[ni * H + H:ni * H + 4 * H].reshape(H, 3).T)
    b2 = np.abs(th[ni * H + 4 * H:])
    dT, dR = ph["delays"]
    n = len(U)
    t = np.arange(m.t0, n)
    f2 = U.astype(np.float64) ** 2
    S = np.array([[-1, -1, 1, 1], [-1, 1, 1, -1], [-1, 1, -1, 1]], float)
    fsc = np.asarray(d["feature_scale"])
    w = Y[t - 1, 10:13]
    x = [np.abs((w - d["in_mean"]) / d["in_scale"])]
    dx = [3 * EPS * x[0]]
    for j in range(L):                        # tau at delay dR + j, its cancellation error
        f = f2[t - 1 - dR - j]
        x.append(np.abs(f @ S.T) / fsc[3 * j:3 * j + 3])
        dx.append((_gamma(5) * f.sum(axis=1)[:, None] + EPS * np.abs(f @ S.T))
                  / fsc[3 * j:3 * j + 3])
    x, dx = np.hstack(x), np.hstack(dx)
    dn = dx @ W1.T + _gamma(ni + 1) * (x @ W1.T + b1)
    a = np.tanh(x @ W1.T + b1)                # |a| bound: tanh of the largest |n|
    da = dn + 4 * EPS * a
    do = da @ W2.T + _gamma(H + 1) * (a @ W2.T + b2)
    osc = np.asarray(d["out_scale"])
    out = osc * (a @ W2.T + b2)
    dout = osc * do + EPS * out
    dt = float(d["dt"])
    rot = np.abs(np.asarray(ph["rotation"]))
    f = f2[t - 1 - dR]
    tau = np.abs(f @ S.T)
    drift = dt * (rot[0:3] * tau + rot[6:9])
    ddrift = dt * (rot[0:3] * (_gamma(5) * f.sum(axis=1)[:, None]) + _gamma(3) * drift / dt) \
        + EPS * drift
    dnext = ddrift + dout + _gamma(3) * (np.abs(w) + drift + out)
    thrust = abs(ph["translation"][0]) * f2[t - 1 - dT].sum(axis=1)
    vmag = np.abs(Y[t - 1, 3:6]).sum(axis=1)
    drag = abs(ph["translation"][1]) + abs(ph["translation"][2])
    deriv = np.column_stack([np.abs(Y[t - 1, 3:6]),
                             np.repeat((thrust + ph["gravity"] + 3 * drag * vmag)[:, None], 3, 1),
                             np.repeat(np.abs(w).sum(axis=1)[:, None] + np.abs(dnext).max(axis=1)
                                       [:, None] / dt, 4, 1)])
    other = 16 * EPS * (np.abs(Y[t - 1, :10]) + np.abs(Y[t, :10]) + dt * deriv)
    other[:, 6:10] += 0.5 * dt * dnext.sum(axis=1)[:, None]          # q' = 1/2 q (x) w
    other[:, 3:6] += 2 * dt * dt * thrust[:, None] * dnext.sum(axis=1)[:, None]
    return np.hstack([other, dnext + 4 * EPS * np.abs(Y[t, 10:13])])


def _against_python(bdir, path, m, U, Y, k=10, free_rows=None):
    """One-step within the derived bound, k-step and free run (its first ``free_rows`` rows)
    within 1e-4 of each state's span."""
    runs = {}
    for mode in ("one_step", "k_step", "free_run"):
        u, y = (U[:free_rows], Y[:free_rows]) if mode == "free_run" else (U, Y)
        u32, y32 = u.astype(np.float32).astype(float), y.astype(np.float32).astype(float)
        span = np.ptp(y32, axis=0)
        r = fw.run_step_equivalence(bdir, path, u, y, mode, k=k)
        want = m.predict(u32, y32, mode=mode, k=k)[m.t0:]
        err = np.abs(r["outputs"] - want)
        if mode == "one_step":
            bound = _one_step_bound(m, u32, y32)
            print(mode, "largest error / bound per state",
                  np.round(np.max(err / bound, axis=0), 4))
            assert np.all(err <= bound), mode
        print(mode, "error / span per state", np.round(err.max(axis=0) / span, 8))
        assert np.all(err.max(axis=0) <= 1e-4 * span), mode
        runs[mode] = r
    return runs


@pytest.mark.slow
@needs_toolchain
def test_quad_hybrid_on_the_board_with_its_monitor(hybrid, tmp_path):
    """The check on 2 s held out, then the monitor: on the held-out flight and on one whose
    rotors give 10 % less thrust (the generator's kT), the firmware's decisions and alarm
    frames equal Python's sample for sample, and the thrust loss alarms."""
    _, U, Y, mon = hybrid
    m = load_model(mon)
    bdir = tmp_path / "b"
    u, y = U[N_FIT:], Y[N_FIT:]
    rep = fw.check(mon, build_dir=bdir, record=(u, y))
    print("quad_hybrid", {k: v for k, v in rep.items() if k != "check_image"})
    assert rep["kind"] == "quad_hybrid" and rep["heap_free"] is True
    assert rep["steps"] == len(u) - m.t0
    assert rep["monitor_mismatches"] == 0 and rep["alarm_frames_equal"]
    _against_python(bdir, mon, m, u, y)
    # the budget for the largest flight model: 20,000 instructions per step (model +
    # monitor); flash and static RAM far below the M4F's 1 MiB / 192 KiB
    assert rep["instructions_per_step"] + rep["instructions_per_monitor"] <= 20000
    assert rep["flash_bytes"] <= 16 * 1024 and rep["static_ram_bytes"] <= 2048
    U2, Y2, _ = flight(seconds=4.0, seed=9, lag=0.03, truth=dict(TRUTH, kT=0.9 * TRUTH["kT"]))
    r = fw.run_step_equivalence(bdir, mon, U2, Y2, "one_step")
    print({k: r[k] for k in ("monitor_alarms", "monitor_mismatches", "instructions_per_monitor")})
    assert r["monitor_alarms"] > 0 and r["monitor_mismatches"] == 0 and r["alarm_frames_equal"]


@pytest.mark.slow
@needs_toolchain
def test_prior_hold_on_the_board(hybrid, tmp_path):
    """prior="hold" (no physics increment: the network supplies every change of the rates),
    with a 20 ms actuation lag in the physics (a 10-tap kernel) on the held-out rows."""
    _, U, Y, _ = hybrid
    m = QuadHybrid(hidden=4, lags=2, horizon=10, epochs=3, prior="hold", threads=1)
    m.fit(U[:N_FIT], Y[:N_FIT])
    m.physics_.lag = 0.02                 # the kernel the physics' drive then uses
    path = tmp_path / "hold.json"
    save_model(path, m)
    m = load_model(path)
    assert "prior hold" in fw.load_firmware_model(path).describe()
    fw.build(tmp_path / "b", path)
    _against_python(tmp_path / "b", path, m, U[N_FIT:], Y[N_FIT:], free_rows=100)   # 1 s


@pytest.mark.slow
@needs_toolchain
def test_cli_check_on_the_default_record(hybrid, tmp_path):
    path = hybrid[0]
    out = tmp_path / "rep.json"
    rep = cli_check_report(path, out, tmp_path / "b", "quad_hybrid", HOSTILE)
    assert rep["max_rel_error"] <= 1e-5 and rep["max_rel_error_free_run"] <= 1e-4


@pytest.mark.slow
@needs_toolchain
@pytest.mark.skipif(not (FLIGHTS / "square_20251017_run2.parquet").is_file(),
                    reason=f"nano-drone flights not found at {FLIGHTS} (set CDAM_SHARED_DATA)")
def test_nanodrone_flight_model_on_the_board(tmp_path):
    """The issue's case: the documented structure (8 units, 6 lags, K = 50, dynamic prior)
    fitted on the longest clean stretch of random1 run 1, checked with its monitor on 3 s of a
    square flight it never saw; its step and monitor within the 20,000-instruction budget."""
    from cdam_core.evaluate.monitor import calibrate
    U, Y = nanodrone_flight(FLIGHTS, "random1_20251017_run1")
    m = QuadHybrid(dt=0.01, threads=1, epochs=5).fit(U, Y)
    path = tmp_path / "nano.json"
    save_model(path, m, monitor=calibrate(m, U, Y, 0.01, paths=200, seed=0))
    Ut, Yt = nanodrone_flight(FLIGHTS, "square_20251017_run2")
    u, y = Ut[:300], Yt[:300]
    rep = fw.check(path, build_dir=tmp_path / "b", record=(u, y))
    print("nano-drone quad_hybrid", {k: v for k, v in rep.items() if k != "check_image"})
    assert rep["heap_free"] and rep["steps"] == 300 - m.t0
    assert rep["monitor_mismatches"] == 0 and rep["alarm_frames_equal"]
    assert rep["instructions_per_step"] + rep["instructions_per_monitor"] <= 20000
    _against_python(tmp_path / "b", path, m, u, y, free_rows=100)    # free run: 1 s
