"""Every dynamic model kind on the emulated STM32F405 (qemu-system-arm -M netduinoplus2): arx
(raw and physics features), hybrid (ARX + residual network), greybox (rigid axis with Coulomb
and asymmetric friction, an external force and an actuator delay; a flexible joint with every
effect of its library; the quadrotor and the aerial manipulator with joint and flight effects; the joint the residual loop finds on a simulated arm with friction; and
the EMPS axis fitted by the residual loop when the shared data are there).

The firmware is compared with the Python model (float64) and, for arx and greybox, bit for bit
with a plain numpy float32 twin written from the equations (tests/firmware/_kinds.py). Skipped
only when arm-none-eabi-gcc / qemu-system-arm / cmake are absent. One build per kind (a few
seconds each: two small images), shared by the module's tests.
"""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core import firmware as fw
from cdam_core.models.file import load_model

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _kinds import (RIGID, aerial_file, arx_file, arx_twin32, flexible_file,  # noqa: E402
                    greybox_file, hybrid_file, pendulum_file, quadrotor_file, rigid_record,
                    rigid_twin32)

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(fw.toolchain_available() is not None,
                                 reason=f"firmware toolchain: {fw.toolchain_available()}")]

# One step of any kind, at most (the budget is 20,000 for the largest flight model;
# these small models are far below): the 1 kHz loop has 168,000 cycles.
STEP_BUDGET = 5000


def _built(tmp_path_factory, name, path):
    bdir = tmp_path_factory.mktemp(f"fw_{name}")
    return path, bdir, fw.build(bdir, path)


@pytest.fixture(scope="module")
def arx(tmp_path_factory):
    return _built(tmp_path_factory, "arx", arx_file(tmp_path_factory.mktemp("m") / "arx.json"))


@pytest.fixture(scope="module")
def arx_physics(tmp_path_factory):
    path = arx_file(tmp_path_factory.mktemp("m") / "arxp.json", physics=True)
    return _built(tmp_path_factory, "arxp", path)


@pytest.fixture(scope="module")
def hybrid(tmp_path_factory):
    path, _ = hybrid_file(tmp_path_factory.mktemp("m") / "hybrid.json")
    return _built(tmp_path_factory, "hybrid", path)


@pytest.fixture(scope="module")
def greybox(tmp_path_factory):
    path = greybox_file(tmp_path_factory.mktemp("m") / "gb.json")
    return _built(tmp_path_factory, "gb", path)


def _record(model, U, noise=1e-3, seed=4):
    """Outputs: the model's free run from rest plus measurement noise (so one-step and free
    run differ)."""
    Y = np.zeros((len(U), model.n_outputs_))
    Y[model.t0:] = model.predict(U, Y, mode="free_run")[model.t0:]
    return Y + noise * np.ptp(Y) * np.random.default_rng(seed).standard_normal(Y.shape)


def _common(res, sizes):
    assert res["instructions_per_step"] <= STEP_BUDGET
    img = sizes["fw_step"]
    assert img["text"] + img["data"] <= 16 * 1024 and img["data"] + img["bss"] <= 1024
    if fw.sandbox.available() is None:
        assert res["sandbox"].startswith("private root"), res["sandbox"]


@pytest.mark.parametrize("which", ["arx", "arx_physics"])
def test_arx_on_the_board_is_the_float32_twin(which, request):
    path, bdir, sizes = request.getfixturevalue(which)
    m = load_model(path)
    rng = np.random.default_rng(6)
    U = rng.uniform(0.2, 1.0, (800, m.n_inputs_)) * (400.0 if which == "arx_physics" else 1.0)
    Y = _record(m, U)
    span = np.ptp(Y, axis=0).max()
    for mode in ("one_step", "free_run"):
        res = fw.run_step_equivalence(bdir, path, U, Y, mode)
        twin = arx_twin32(m.coef_, *m.narx, U, Y, mode,
                          m.feature_scale_ if which == "arx_physics" else None)
        np.testing.assert_array_equal(res["outputs"], twin)     # same float32 operations
        assert res["max_abs_error"] <= (1e-5 if mode == "one_step" else 1e-4) * span
        _common(res, sizes)
        print(which, mode, {k: v for k, v in res.items() if k != "outputs"}, sizes["fw_step"])


def test_greybox_on_the_board_is_the_float32_twin(greybox):
    path, bdir, sizes = greybox
    g = load_model(path)
    U = rigid_record()
    Y = _record(g, U)
    span = np.ptp(Y)
    for mode in ("one_step", "free_run"):
        res = fw.run_step_equivalence(bdir, path, U, Y, mode)
        twin = rigid_twin32(RIGID, U, Y, mode, inertia=g._inertia[0, 0])
        np.testing.assert_array_equal(res["outputs"], twin)
        assert res["max_abs_error"] <= 1e-5 * span
        _common(res, sizes)
        print("greybox", mode, {k: v for k, v in res.items() if k != "outputs"}, sizes["fw_step"])


def test_hybrid_on_the_board_matches_python(hybrid):
    path, bdir, sizes = hybrid
    h = load_model(path)
    U = np.random.default_rng(7).uniform(-1, 1, (800, 2))
    Y = _record(h, U)
    span = np.ptp(Y, axis=0).max()
    for mode in ("one_step", "free_run"):
        res = fw.run_step_equivalence(bdir, path, U, Y, mode)
        # the network runs the fast tanh (within 1e-6 of tanh, cdam/fast_math.hpp)
        assert res["max_abs_error"] <= (1e-5 if mode == "one_step" else 1e-4) * span
        _common(res, sizes)
        print("hybrid", mode, {k: v for k, v in res.items() if k != "outputs"}, sizes["fw_step"])


def test_flexible_joint_with_every_effect_matches_python(tmp_path):
    path = flexible_file(tmp_path / "fj.json")
    g = load_model(path)
    rng = np.random.default_rng(8)
    U = np.repeat(rng.uniform(-1.5, 1.5, (40, 1)), 20, axis=0)
    Y = _record(g, U)
    res = fw.check(path, build_dir=tmp_path / "b", record=(U, Y))
    print("flexible", res)
    # sin and tanh of newlib (float) against numpy's (double): rounding level
    assert res["max_rel_error"] <= 1e-5 and res["max_rel_error_free_run"] <= 1e-4
    assert res["heap_free"] and res["instructions_per_step"] <= STEP_BUDGET


def test_rotary_axis_with_gravity_matches_python(tmp_path):
    """A pendulum (rigid_axis with G sin q + Gc cos q): the firmware's step evaluates the
    gravity columns (before they existed it read the file's first three numbers only)."""
    path = pendulum_file(tmp_path / "p.json")
    g = load_model(path)
    U = 4.0 * np.sin(2 * np.pi * 0.5 * np.arange(2000) * 1e-3)[:, None]   # N m, 2 s
    Y = _record(g, U)
    assert np.ptp(Y) > 0.5          # a swing over which sin and cos are far from linear
    res = fw.check(path, build_dir=tmp_path / "b", record=(U, Y))
    print("pendulum", res)
    assert res["max_rel_error"] <= 1e-5 and res["max_rel_error_free_run"] <= 1e-4
    assert res["heap_free"] and res["instructions_per_step"] <= STEP_BUDGET


def test_quadrotor_with_flight_effects_matches_python(tmp_path):
    path = quadrotor_file(tmp_path / "q.json")
    res = fw.check(path, build_dir=tmp_path / "b")      # the default synthetic record
    print("quadrotor", res)
    # each output (angles and positions) against its own span
    assert res["max_rel_error"] <= 1e-5 and res["max_rel_error_free_run"] <= 1e-4
    assert res["heap_free"] and res["instructions_per_step"] <= STEP_BUDGET


def test_aerial_manipulator_with_joint_effects_matches_python(tmp_path):
    """The body and both cable-driven joints at 1 kHz with a rotor delay, Coulomb friction on
    motor 1, backlash and a hardening spring in cable 2, asymmetric friction on link 1 and a
    payload, on the synthetic record (thrust near hover, joint torques up to the links'
    gravity torques); the effects change the free run far beyond the firmware's error."""
    path = aerial_file(tmp_path / "am.json")
    U, Y = fw.default_record(fw.load_firmware_model(path))
    res = fw.check(path, build_dir=tmp_path / "b", record=(U, Y))
    print("aerial_manipulator", res)
    assert res["max_rel_error"] <= 1e-5 and res["max_rel_error_free_run"] <= 1e-4
    assert res["k"] == 10 and res["max_rel_error_k_step"] <= 1e-5
    assert res["heap_free"] and res["instructions_per_step"] <= STEP_BUDGET
    bare = load_model(aerial_file(tmp_path / "bare.json", effects=False))
    t0 = bare.t0
    moved = np.max(np.abs(bare.predict(U, Y, mode="free_run")[t0:, 6:] - Y[t0:, 6:]))
    assert moved >= 1000 * res["max_abs_error_free_run"]


def test_simulated_arm_found_effect(tmp_path):
    """cdam simulate (joint excitation, Coulomb friction on motor 1) -> cdam residual
    --model flexible_joint --save -> the saved model on the board, on the simulated record."""
    from cdam_core.cli.main import main
    from cdam_core.record.dataset import read_dataset
    rec, model = tmp_path / "arm.csv", tmp_path / "arm_model.json"
    assert main(["simulate", "--experiment", "ii", "--duration", "6", "--seed", "1",
                 "--effect", "coulomb_friction:Fc1=0.05", "-o", str(rec)]) == 0
    assert main(["residual", str(rec), "--model", "flexible_joint", "--no-free-run",
                 "--estimator", "idim-ls", "--save", str(model)]) == 0
    doc = json.loads(model.read_text())
    assert "coulomb_friction" in [e["name"] for e in doc["model"]["effects"]]
    out = tmp_path / "check.json"
    assert main(["firmware", "check", str(model), "--data", str(rec), "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    print("simulated arm", res)
    assert res["steps"] == len(read_dataset(rec)) - 2     # the whole record, after 2 rows
    assert res["max_rel_error"] <= 1e-5
    assert res["heap_free"] and res["instructions_per_step"] <= STEP_BUDGET


def test_cli_check_reports_every_figure(greybox, tmp_path, capsys):
    from cdam_core.cli.main import main
    path, bdir, _ = greybox
    out = tmp_path / "report.json"
    capsys.readouterr()
    assert main(["firmware", "check", str(path), "--json", str(out), "--quiet",
                 "--report", str(tmp_path / "rep"), "--build-dir", str(bdir)]) == 0
    assert capsys.readouterr().err == ""                   # --quiet: no notes
    rep = json.loads(out.read_text())
    # --report: the same figures as a page (Markdown and HTML) and results.json
    page = (tmp_path / "rep" / "index.md").read_text()
    assert f"instructions_per_step        {rep['instructions_per_step']}" in page
    assert json.loads((tmp_path / "rep" / "results.json").read_text()) == rep
    assert "<table>" not in page and "instructions_per_step" in \
        (tmp_path / "rep" / "index.html").read_text()
    assert rep["kind"] == "greybox" and rep["heap_free"] is True
    assert {"flash_bytes", "static_ram_bytes", "instructions_per_step", "microseconds_168mhz",
            "max_abs_error", "max_abs_error_free_run", "output_span", "max_rel_error",
            "max_rel_error_free_run", "max_abs_error_k_step", "max_rel_error_k_step"} <= rep.keys()
    assert rep["k"] == 10 and rep["max_abs_error_k_step"] <= 1e-5 * rep["output_span"]
    assert rep["max_abs_error"] <= 1e-5 * rep["output_span"]
    assert rep["microseconds_168mhz"] == pytest.approx(rep["instructions_per_step"] / 168, abs=0.01)
    assert "load" not in json.dumps(rep)    # no name from the file in the report either


def test_emps_axis_found_by_the_residual_loop(tmp_path, bundled_record):
    """The model `cdam residual --save` writes for DATA_EMPS, checked on DATA_EMPS_PULSES
    (both ship in data/: missing is a failure)."""
    from cdam_core.models.file import save_model
    from cdam_core.record.realdata.emps import EMPS_UNITS, load_emps
    from cdam_core.residual.analyse import analyse
    from cdam_core.residual.benchmark import greybox_of
    bundled_record("emps/DATA_EMPS.mat")
    bundled_record("emps/DATA_EMPS_PULSES.mat")
    d = load_emps("DATA_EMPS")
    sel = analyse("rigid_axis", d["t"], {"tau": d["force"], "q": d["qm"]}, free_run=False,
                  units=EMPS_UNITS)
    g = greybox_of(sel.final, float(np.mean(np.diff(d["t"]))))
    path = tmp_path / "emps.json"
    save_model(path, g, inputs=["force"], outputs=["qm"])
    assert [e.name for e in g.effects][:1] == ["coulomb_friction"]
    p = load_emps("DATA_EMPS_PULSES")
    n = 3000
    rep = fw.check(path, build_dir=tmp_path / "b",
                   record=(p["force"][:n, None], p["qm"][:n, None]))
    print("emps", rep)
    assert rep["heap_free"] and rep["max_abs_error"] <= 1e-5 * rep["output_span"]
    assert rep["max_abs_error_free_run"] <= 1e-4 * rep["output_span"]
    assert rep["instructions_per_step"] <= STEP_BUDGET
