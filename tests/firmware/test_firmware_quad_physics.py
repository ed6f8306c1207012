"""The quad_physics flight model on the firmware: export (numbers only, no toolchain needed) and
the run on the emulated STM32F405 against the Python model (QEMU, skipped without the
toolchain).

The model is fitted on a short flight of the independent numpy generator
(tests/models/quad_generator.py: rotation-matrix attitude, Euler's equation, RK4 sub-steps, a
first-order rotor lag of 30 ms) with the lag, rate damping and yaw reaction switched on (the
largest step the kind has: a 15-tap kernel), and checked on the held-out part of that flight.

The firmware's outputs equal, bit for bit, a plain numpy float32 twin of the equations
(tests/firmware/_kinds.py, written from the model's module doc). Against the Python model
(float64), the tolerance (float32 rounding, derived here, not measured): the largest rounding
error of one step is in the torque combinations, sums of four squared rotor speeds that cancel, so the
angular acceleration is off by up to a = eps32 |b|max sum(f)max per step (eps32 = 2^-23) and
the thrust acceleration by eps32 g. Over a horizon T these integrate, to first order, into
rates a T, attitude (quaternion) a T^2 / 2, velocity g a T^3 / 6 + eps32 g T, position
g a T^4 / 24 + eps32 g T^2 / 2, each grown by exp(L T) (Gronwall) with L = max|k| +
2 max|c| max|w| the row-sum bound of the rate dynamics' Jacobian along the record, plus a few
ulp of each state's own size (the float32 state). One step is T = dt (tight: the errors
measured are within a third of it); the free run T = its length (loose: a guarantee, not an
estimate), so the free run must also stay within 1e-4 of each state's span, the level the
other kinds' free runs are held to (tests/firmware/test_firmware_kinds_qemu.py).
"""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core import firmware as fw
from cdam_core.cli.main import main
from cdam_core.models.file import load_model, save_model
from cdam_core.models.flight.physics import QuadPhysics
from cdam_core.record.realdata import shared_data_dir

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _kinds import QUAD_N_FIT as N_FIT, quad_physics_file, quad_twin32  # noqa: E402
from _kinds import header_array as _array, header_int as _int  # noqa: E402
from _kinds import assert_float32_overflow_refused, cli_check_report, nanodrone_flight  # noqa: E402,E501

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "models"))

EPS32 = 2.0 ** -23
HOSTILE = '"); system("rm -rf /'
FLIGHTS = shared_data_dir() / "nanodrone"

needs_toolchain = pytest.mark.skipif(fw.toolchain_available() is not None,
                                     reason=f"firmware toolchain: {fw.toolchain_available()}")


@pytest.fixture(scope="module")
def quad(tmp_path_factory):
    return quad_physics_file(tmp_path_factory.mktemp("m") / "quad.json", meta={"note": HOSTILE})


@pytest.fixture(scope="module")
def bdir(tmp_path_factory):
    """One build folder for the quad model's tests (a rebuild there is incremental)."""
    return tmp_path_factory.mktemp("fw_quad")


def test_header_holds_the_file_numbers_only(quad, tmp_path):
    path, _, _ = quad
    doc = json.loads(path.read_text())["model"]
    out = tmp_path / "model.hpp"
    assert main(["export-firmware", str(path), "-o", str(out)]) == 0
    text = out.read_text()
    assert "#define CDAM_MODEL_KIND 4" in text
    for key, name in (("translation", "kTrans"), ("rotation", "kRot")):
        np.testing.assert_array_equal(_array(text, name).astype(np.float32),
                                      np.asarray(doc[key], np.float32))
    # the lag kernel from the module doc: (1 - a) a^j, j < ceil(5 T / dt), normalised
    a = np.exp(-doc["dt"] / doc["lag"])
    w = (1 - a) * a ** np.arange(int(np.ceil(5 * doc["lag"] / doc["dt"])))
    np.testing.assert_allclose(_array(text, "kKernelW"), w / w.sum(), rtol=1e-7)
    assert (_int(text, "kDelayTrans"), _int(text, "kDelayRot")) == tuple(doc["delays"])
    # t0 = 1 + (taps - 1) + 1 (reaction) + the larger delay
    assert _int(text, "kHistory") == 1 + (w.size - 1) + 1 + max(doc["delays"])
    assert "constexpr bool kReaction = true;" in text
    assert "constexpr bool kRatesDynamic = true;" in text
    assert "system" not in text and "rotor_speed" not in text and "state_" not in text


def test_refusals_are_named(quad, tmp_path):
    path, _, _ = quad
    m = load_model(path)
    m.rot_ = np.array(m.rot_)
    m.rot_[4] = 1e39                    # finite in the file, not in float32
    assert_float32_overflow_refused(m, tmp_path, "kRot")


def test_an_option_the_firmware_does_not_know_is_named(quad, tmp_path, monkeypatch):
    path, _, _ = quad
    to_dict = QuadPhysics.to_dict
    monkeypatch.setattr(QuadPhysics, "to_dict",
                        lambda self: {**to_dict(self), "residual_network": {}})
    with pytest.raises(ValueError, match="model.residual_network: a quad_physics option the "
                                         "firmware does not run yet"):
        fw.load_firmware_model(path)


def _tolerance(m, U, Y, T):
    """Per state, the float32 rounding bound of the module doc over a horizon T (s)."""
    rot = np.asarray(m.rot_)
    f = U.astype(np.float64) ** 2
    a = EPS32 * np.max(np.abs(rot[0:3])) * np.max(f.sum(axis=1))
    g = float(m.gravity)
    L = np.max(np.abs(rot[9:12])) + 2 * np.max(np.abs(rot[3:6])) * np.max(np.abs(Y[:, 10:13]))
    grow = np.exp(L * T)
    per = np.r_[[g * a * T ** 4 / 24 + EPS32 * g * T ** 2 / 2] * 3,
                [g * a * T ** 3 / 6 + EPS32 * g * T] * 3, [a * T ** 2 / 2] * 4, [a * T] * 3]
    return per * grow + 8 * EPS32 * np.max(np.abs(Y), axis=0)


@pytest.mark.slow
@needs_toolchain

def _board_against_model(bdir, path, m, u, y, mode, T, rel, k=None):
    """Run the record on the board in ``mode`` and check it against the float64 model: within
    the float32 bound derived in ``_tolerance`` over ``T`` seconds, and within ``rel`` of each
    state's span. Returns the board's run."""
    r = fw.run_step_equivalence(bdir, path, u, y, mode, k=k)
    want = m.predict(u.astype(np.float32).astype(float), y.astype(np.float32).astype(float),
                     mode=mode, k=k or 1)[m.t0:]
    err = np.max(np.abs(r["outputs"] - want), axis=0)
    tol = _tolerance(m, u, np.r_[y, want], T)
    print(mode, "error / bound per state", np.round(err / tol, 4))
    assert np.all(err <= tol), (mode, err, tol)
    span = np.ptp(y.astype(np.float32).astype(float), axis=0)
    print(mode, "error / span per state", np.round(err / span, 8))
    assert np.all(err <= rel * span)
    return r

def test_quad_physics_on_the_board_matches_python(quad, bdir):
    path, U, Y = quad
    m = load_model(path)
    u, y = U[N_FIT:N_FIT + 200], Y[N_FIT:N_FIT + 200]      # 2 s held out
    rep = fw.check(path, build_dir=bdir, record=(u, y))
    print("quad_physics", rep)
    assert rep["kind"] == "quad_physics" and rep["heap_free"] is True
    assert rep["steps"] == len(u) - m.t0
    dt = float(m.dt)
    for mode, T in (("one_step", dt), ("k_step", 10 * dt), ("free_run", (len(u) - m.t0) * dt)):
        r = _board_against_model(bdir, path, m, u, y, mode, T,
                                 1e-4 if mode == "free_run" else 1e-5, k=10)
        if mode == "k_step":   # rows t0 .. t0 + k - 2 have no origin k rows back: measured
            np.testing.assert_array_equal(r["outputs"][:9], y[m.t0:m.t0 + 9].astype(np.float32))
        else:                  # the same float32 operations as a numpy twin of the equations
            np.testing.assert_array_equal(r["outputs"], quad_twin32(m, u, y, mode))
    # the budget for the largest flight model is 20,000 instructions per step
    assert rep["instructions_per_step"] <= 20000
    assert rep["flash_bytes"] <= 16 * 1024 and rep["static_ram_bytes"] <= 2048


@pytest.mark.slow
@needs_toolchain
def test_rates_held_as_the_benchmark_paper(quad, tmp_path):
    """rates="hold" (the benchmark paper's physics model: w' = 0, no lag): the step without
    the rotational dynamics, on the held-out rows."""
    _, U, Y = quad
    m = QuadPhysics(rates="hold").fit(U[:N_FIT], Y[:N_FIT])
    save_model(tmp_path / "hold.json", m)
    u, y = U[N_FIT:N_FIT + 200], Y[N_FIT:N_FIT + 200]
    rep = fw.check(tmp_path / "hold.json", build_dir=tmp_path / "b", record=(u, y))
    print("quad_physics hold", rep)
    assert "rates held" in rep["model"] and rep["heap_free"]
    assert rep["max_rel_error"] <= 1e-5 and rep["max_rel_error_k_step"] <= 1e-5
    assert rep["max_rel_error_free_run"] <= 1e-4
    # held rates: the free run keeps the first predicted row's rates to the last bit
    r = fw.run_step_equivalence(tmp_path / "b", tmp_path / "hold.json", u, y, "free_run")
    assert np.all(r["outputs"][:, 10:13] == y[m.t0 - 1, 10:13].astype(np.float32))


@pytest.mark.slow
@needs_toolchain
def test_cli_check_on_the_default_record(quad, bdir, tmp_path):
    path, _, _ = quad
    out = tmp_path / "rep.json"
    rep = cli_check_report(path, out, bdir, "quad_physics", HOSTILE)
    # one step from the model's own trajectory near hover: rounding level of each state
    assert rep["max_rel_error"] <= 1e-5


@pytest.mark.slow
@needs_toolchain
@pytest.mark.skipif(not (FLIGHTS / "square_20251017_run2.parquet").is_file(),
                    reason=f"nano-drone flights not found at {FLIGHTS} (set CDAM_SHARED_DATA)")
def test_nanodrone_flight_model_on_the_board(tmp_path):
    """Fitted on the longest clean stretch of random1 run 1 (the documented defaults: rates
    dynamic, delays chosen), checked on 3 s of a square flight it never saw."""
    U, Y = nanodrone_flight(FLIGHTS, "random1_20251017_run1")
    m = QuadPhysics(dt=0.01).fit(U, Y)
    path = tmp_path / "nano.json"
    save_model(path, m)
    Ut, Yt = nanodrone_flight(FLIGHTS, "square_20251017_run2")
    u, y = Ut[:300], Yt[:300]
    rep = fw.check(path, build_dir=tmp_path / "b", record=(u, y))
    print("nano-drone", rep)
    assert rep["heap_free"] and rep["steps"] == 300 - m.t0
    for mode, n in (("one_step", 300), ("free_run", 100)):      # free run: 1 s
        u, y = Ut[:n], Yt[:n]
        T = 0.01 if mode == "one_step" else (n - m.t0) * 0.01
        r = _board_against_model(tmp_path / "b", path, m, u, y, mode, T,
                                 1e-5 if mode == "one_step" else 1e-4)
        np.testing.assert_array_equal(r["outputs"], quad_twin32(m, u, y, mode))


def test_bad_horizon_is_named(quad, capsys):
    path, U, Y = quad
    assert main(["firmware", "check", str(path), "--horizon", "0"]) == 2
    assert "--horizon: expected 1..64, got 0" in capsys.readouterr().err
    with pytest.raises(ValueError, match="k: expected an integer in 1..64"):
        fw.check(path, k=65)
    with pytest.raises(ValueError, match="k: expected an integer in 1..64 for mode 'k_step'"):
        fw.run_step_equivalence("nowhere", path, U[:50], Y[:50], "k_step")


@pytest.mark.slow
@needs_toolchain
def test_residual_monitor_beside_the_flight_model(tmp_path):
    """The monitor section (cdam_core.evaluate.monitor.calibrate on the 20 s training flight)
    runs beside the quad_physics step: on a flight whose rotors give 10 % less thrust (the
    generator's kT) the firmware's decisions and alarm frames are Python's, sample for
    sample."""
    from cdam_core.evaluate.monitor import calibrate
    from quad_generator import TRUTH, flight
    U, Y, _ = flight(seconds=20.0, seed=3)
    m = QuadPhysics().fit(U, Y)
    save_model(tmp_path / "qmon.json", m, monitor=calibrate(m, U, Y, 0.01, paths=200, seed=0))
    fw.build(tmp_path / "b", tmp_path / "qmon.json")
    U2, Y2, _ = flight(seconds=8.0, seed=9, truth=dict(TRUTH, kT=0.9 * TRUTH["kT"]))
    r = fw.run_step_equivalence(tmp_path / "b", tmp_path / "qmon.json", U2, Y2, "one_step")
    print({k: r[k] for k in ("monitor_alarms", "monitor_mismatches", "instructions_per_monitor",
                             "instructions_per_step")})
    assert r["monitor_alarms"] > 0 and r["monitor_mismatches"] == 0
    assert r["alarm_frames_equal"]
    np.testing.assert_array_equal(r["monitor_flags"], r["monitor_flags_python"])
