"""Export of the dynamic kinds (arx, hybrid, greybox incl. the aerial manipulator) for the
firmware, no toolchain needed:
numbers only (checked against the model file read as plain JSON), no text from the file, the
refusals, and the float32 twins against the Python models."""
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core import firmware as fw
from cdam_core.cli.main import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _kinds import (AERIAL, PENDULUM, QUAD, RIGID, aerial_file, arx_file, arx_twin32,  # noqa: E402
                    flexible_file, greybox_file, hybrid_file, quadrotor_file, rigid_record,
                    rigid_twin32, pendulum_file)

HOSTILE = '"); system("rm -rf /'


def _array(text, name):
    m = re.search(rf"constexpr float {name}\[(\d+)\] = \{{(.*?)\}};", text, re.S)
    assert m, name
    vals = np.array([float(v.strip().rstrip("f")) for v in m.group(2).split(",")])
    assert vals.size == int(m.group(1))
    return vals


def _int(text, name):
    return int(re.search(rf"constexpr int {name} = (-?\d+);", text).group(1))


def test_arx_header_holds_the_file_coefficients(tmp_path):
    path = arx_file(tmp_path / "arx.json")
    doc = json.loads(path.read_text())
    text = fw.export_header(path, tmp_path / "model.hpp").read_text()
    coef = np.asarray(doc["model"]["coef"])
    np.testing.assert_array_equal(_array(text, "kCoef").astype(np.float32),
                                  coef.ravel().astype(np.float32))
    assert "#define CDAM_MODEL_KIND 1" in text and "#define CDAM_MODEL_HAS_NET 0" in text
    assert (_int(text, "kNa"), _int(text, "kNb"), _int(text, "kNk")) == tuple(doc["model"]["narx"])
    assert _int(text, "kHistory") == 2 and _int(text, "kOutputs") == 2
    assert f'kSourceSha256[] = "{doc["checksum"]["sha256"]}"' in text
    # the checksum the firmware recomputes: FNV-1a of the float32 bytes, written out here
    h = 0x811C9DC5
    for b in coef.ravel().astype("<f4").tobytes():
        h = ((h ^ b) * 0x01000193) & 0xFFFFFFFF
    assert f"kParamsFnv1a = 0x{h:08X}u" in text


def test_hybrid_without_its_network_is_the_arx_part(tmp_path):
    from cdam_core.models.file import save_model
    _, h = hybrid_file(tmp_path / "hybrid.json")
    h.residual_weight_ = 0.0          # the network did not help: the file keeps it, unused
    save_model(tmp_path / "h0.json", h)
    text = fw.export_header(tmp_path / "h0.json", tmp_path / "model.hpp").read_text()
    assert "#define CDAM_MODEL_HAS_NET 0" in text and "kNetTheta" not in text
    np.testing.assert_array_equal(_array(text, "kCoef").astype(np.float32),
                                  h.coef_.ravel().astype(np.float32))


def test_hybrid_header_holds_the_network(tmp_path):
    path, h = hybrid_file(tmp_path / "hybrid.json")
    doc = json.loads(path.read_text())["model"]
    text = fw.export_header(path, tmp_path / "model.hpp").read_text()
    assert "#define CDAM_MODEL_KIND 2" in text
    if doc["residual_weight"] == 0.0:
        assert "#define CDAM_MODEL_HAS_NET 0" in text and "kNetTheta" not in text
        return
    net = doc["network"]
    assert "#define CDAM_MODEL_HAS_NET 1" in text
    for key, name in (("theta", "kNetTheta"), ("x_min", "kNetXMin"), ("y_max", "kNetYMax")):
        np.testing.assert_array_equal(_array(text, name).astype(np.float32),
                                      np.asarray(net[key], np.float32))
    assert _int(text, "kNetHidden") == net["hidden"]


def test_greybox_header_numbers_and_codes(tmp_path):
    path = greybox_file(tmp_path / "gb.json")
    text = fw.export_header(path, tmp_path / "model.hpp").read_text()
    p = RIGID
    # a file written before the gravity terms existed: G and Gc at 0
    np.testing.assert_array_equal(_array(text, "kBase"),
                                  np.float32([p["M"], p["Fv"], p["offset"], 0.0, 0.0]))
    # rigid axis: the accelerations enter as M q'', so the inverse inertia is 1 / M
    assert _array(text, "kInertia")[0] == pytest.approx(1 / p["M"], rel=1e-7)
    assert re.search(r"kEffectCode\[4\] = \{1, 2, 3, 4\}", text)
    par = _array(text, "kEffectParam").reshape(4, 4)
    assert par[0, 0] == np.float32(p["Fc"]) and par[1, 0] == np.float32(p["dFv"])
    assert par[2, 0] == np.float32(p["gain"])
    L = int(np.ceil(p["delay"] / p["dt"]))
    assert re.search(rf"kEffectLag\[4\] = \{{0, 0, 0, {L}\}}", text)
    assert par[3, 0] == pytest.approx(L * p["dt"] - p["delay"], rel=1e-6)
    assert _int(text, "kSubsteps") == p["substeps"] and _int(text, "kDelayLag") == L


def test_rotary_axis_header_holds_its_gravity(tmp_path):
    text = fw.export_header(pendulum_file(tmp_path / "p.json"), tmp_path / "model.hpp").read_text()
    p = PENDULUM
    np.testing.assert_array_equal(np.float32(_array(text, "kBase")),
                                  np.float32([p[k] for k in ("M", "Fv", "offset", "G", "Gc")]))
    assert re.search(r"CDAM_MODEL_DECLARED 0\b", text)


def test_no_text_from_the_file_reaches_the_header(tmp_path):
    # names the schema admits, and hostile text where the file allows free text (meta)
    path = greybox_file(tmp_path / "gb.json", inputs=("system", "rm_rf"), outputs=("__asm__",),
                        extra_column="rm_rf", meta={"note": HOSTILE, "source": "#include <x>"})
    text = fw.export_header(path, tmp_path / "model.hpp").read_text()
    for word in ("system", "rm_rf", "__asm__", HOSTILE, "#include <x>", "tau", "coulomb",
                 "rigid_axis", "load"):
        assert word not in text, word
    # every line is a comment, a preprocessor line with a number, or a declaration of numbers
    code = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("//")]
    allowed = re.compile(r'^(#pragma once|#include <cstdint>|#define CDAM_MODEL_[A-Z_]+ \d+|'
                         r'namespace cdam_model \{|\}  // namespace cdam_model|'
                         r'constexpr (int|bool|float) k\w+ = [-0-9.e+a-z]+;|'
                         r'constexpr char kSourceSha256\[\] = "[0-9a-f]{64}";|'
                         r'constexpr std::uint32_t kParamsFnv1a = 0x[0-9A-F]{8}u;|'
                         r'(alignas\(4\) )?constexpr (float|int) k\w+\[\d+\] = \{.*|'
                         r'\s+[-0-9., e+f]+(\};)?)$')
    assert [ln for ln in code if not allowed.match(ln)] == []


def test_a_hostile_name_is_refused_before_any_header(tmp_path):
    path = arx_file(tmp_path / "arx.json")
    doc = json.loads(path.read_text())
    doc["inputs"][0] = HOSTILE
    bad = tmp_path / "hostile.json"
    bad.write_text(json.dumps(doc))
    out = tmp_path / "model.hpp"
    assert main(["export-firmware", str(bad), "-o", str(out)]) == 2
    assert not out.exists()


def test_flexible_joint_header(tmp_path):
    from cdam_core.firmware.step import G0
    from cdam_core.models.greybox.effects import G0 as LIBRARY_G0
    assert G0 == LIBRARY_G0
    text = fw.export_header(flexible_file(tmp_path / "fj.json"), tmp_path / "m.hpp").read_text()
    assert "#define CDAM_MODEL_DECLARED 1" in text
    # Im, Dm, Ks, Kd, I, Dl, G, Gc, offset_m, offset_l in the declared model's order (the file
    # predates the last three: the model it holds has them at 0)
    np.testing.assert_array_equal(_array(text, "kBase").astype(np.float32),
                                  np.float32([0.01, 0.1, 20.0, 0.05, 0.02, 0.05, 0.5, 0, 0, 0]))
    # backlash, hardening, coulomb (motor), asymmetric (link), payload, delay (motor input)
    assert re.search(r"kEffectCode\[6\] = \{5, 6, 1, 2, 7, 4\}", text)
    assert re.search(r"kEffectEq\[6\] = \{1, 1, 0, 1, 1, 0\}", text)
    # the velocity of each channel's viscous term: theta_m for tau_m, q for tau_l
    assert re.search(r"kEffectVel\[6\] = \{1, 1, 0, 1, 1, 0\}", text)
    par = _array(text, "kEffectParam").astype(np.float32).reshape(6, 4)
    assert par[0, 0] == np.float32(0.01)                       # half the backlash width
    assert par[2, :2].tolist() == [np.float32(0.05), np.float32(0.01)]   # Fc, tanh width
    assert par[3, 2] == 1.0                                    # no offset: dFc column
    assert par[4, 1] == np.float32(9.81 * 0.3)                # g l of the payload
    # how the accelerations enter: diag(1 / Im, 1 / (I + m l^2)) for this model
    np.testing.assert_allclose(_array(text, "kInertia"),
                               [1 / 0.01, 0, 0, 1 / (0.02 + 0.2 * 0.09)], rtol=1e-7)


def test_quadrotor_header(tmp_path):
    from cdam_core.firmware.step import G0
    from cdam_core.models.greybox.flight import G0 as FLIGHT_G0
    assert G0 == FLIGHT_G0
    text = fw.export_header(quadrotor_file(tmp_path / "q.json"), tmp_path / "m.hpp").read_text()
    assert "#define CDAM_MODEL_DECLARED 2" in text
    np.testing.assert_array_equal(_array(text, "kBase").astype(np.float32),
                                  np.float32(QUAD["values"][:10]))
    # the shared rotor delay on each of the four commands, then ground effect, thrust loss,
    # payload, all on Z (equation 2)
    assert re.search(r"kEffectCode\[7\] = \{4, 4, 4, 4, 8, 9, 7\}", text)
    assert re.search(r"kEffectIndex\[7\] = \{0, 1, 2, 3, 0, 0, 0\}", text)
    assert re.search(r"kEffectEq\[7\] = \{0, 0, 0, 0, 2, 2, 2\}", text)
    assert re.search(r"kEffectLag\[7\] = \{3, 3, 3, 3, 0, 0, 0\}", text)
    par = _array(text, "kEffectParam").astype(np.float32).reshape(7, 4)
    assert par[4, :2].tolist() == [1.0, np.float32(0.127)]   # k, the rotor radius
    # accelerations: X, Y, Z by m (+ the payload on Z), the moments by Jx, Jy, Jz
    inv = _array(text, "kInertia").reshape(6, 6)
    want = np.zeros((6, 6))
    for pos, eq, mass in ((3, 0, 1.8), (4, 1, 1.8), (5, 2, 2.0), (0, 3, 0.02), (1, 4, 0.02),
                          (2, 5, 0.04)):
        want[pos, eq] = 1 / mass
    np.testing.assert_allclose(inv, want, rtol=1e-7, atol=1e-12)


def test_aerial_manipulator_header_numbers_and_codes(tmp_path):
    """The body's and both joints' parameters in the declared order, the joint depth, and each
    effect's code, equation row (the error vector's order: the body's six, tau_m1, tau_m2,
    tau_l1, tau_l2), velocity and cable."""
    from cdam_core.models.greybox.registry import get_model
    path = aerial_file(tmp_path / "am.json")
    text = fw.export_header(path, tmp_path / "model.hpp").read_text()
    assert "#define CDAM_MODEL_DECLARED 3" in text
    names = get_model("aerial_manipulator").parameter_names
    np.testing.assert_array_equal(_array(text, "kBase").astype(np.float32),
                                  np.array([AERIAL[n] for n in names], np.float32))
    assert "constexpr float kJointDepth = 0.0799999982f;" in text      # float32 of 0.08 m
    codes = re.search(r"kEffectCode\[\d+\] = \{(.*?)\}", text).group(1)
    eqs = re.search(r"kEffectEq\[\d+\] = \{(.*?)\}", text).group(1)
    idx = re.search(r"kEffectIndex\[\d+\] = \{(.*?)\}", text).group(1)
    # delay x 4 rotor commands, Coulomb on tau_m1 (row 6), backlash and hardening on cable 2
    # (tau_l2, row 9, index 1), asymmetric friction on tau_l1 (row 8), payload on Z (row 2)
    assert codes == "4, 4, 4, 4, 1, 5, 6, 2, 7"
    assert eqs == "0, 0, 0, 0, 6, 9, 9, 8, 2"
    assert idx == "0, 1, 2, 3, 0, 1, 1, 0, 0"


def test_unsupported_greybox_effect_is_named(tmp_path):
    from cdam_core.models.file import save_model
    from cdam_core.models.greybox.augmented import GreyBox
    g = GreyBox.from_dict(json.loads(aerial_file(tmp_path / "a.json", effects=False)
                                     .read_text())["model"])
    d = g.to_dict()
    d["effects"] = [{"name": "arm_coupling", "channel": "X"}]
    extra = [f"arm_coupling@X.{n}" for n in ("c0", "c1", "c2")]
    d["parameters"] = {k: list(v) + ([0.01] * 3 if k == "values" else
                                     [None] * 3 if k == "std" else extra)
                       for k, v in d["parameters"].items()}
    save_model(tmp_path / "am.json", GreyBox.from_dict(d))
    # zero-phase columns (the file's default): refused, the remedy named
    with pytest.raises(ValueError, match="effect 'arm_coupling' cannot run on the firmware "
                                         r"with zero-phase columns.*--firmware"):
        fw.load_firmware_model(tmp_path / "am.json")
    assert main(["export-firmware", str(tmp_path / "am.json"), "-o",
                 str(tmp_path / "m.hpp")]) == 2
    assert not (tmp_path / "m.hpp").exists()


def test_cli_export_every_kind(tmp_path, capsys):
    for name, path in (("arx", arx_file(tmp_path / "a.json")),
                       ("greybox", greybox_file(tmp_path / "g.json"))):
        out = tmp_path / f"{name}.hpp"
        assert main(["export-firmware", str(path), "-o", str(out)]) == 0
        assert out.is_file() and name in capsys.readouterr().out


# ---- the float32 twins against the Python models (float64): the twins are what the QEMU
# test compares the firmware with bit for bit, so they must be the models' equations ----

def test_arx_twin_is_the_python_model(tmp_path):
    from cdam_core.models.file import load_model
    for physics in (False, True):
        path = arx_file(tmp_path / f"arx{physics}.json", physics=physics)
        m = load_model(path)
        rng = np.random.default_rng(5)
        U = rng.uniform(0.2, 1.0, (300, m.n_inputs_)) * (400 if physics else 1)
        Y = np.zeros((300, m.n_outputs_))
        Y[m.t0:] = m.predict(U, Y, mode="free_run")[m.t0:]
        Y += 1e-3 * rng.standard_normal(Y.shape)
        na, nb, nk = m.narx
        for mode in ("one_step", "free_run"):
            twin = arx_twin32(m.coef_, na, nb, nk, U, Y, mode,
                              m.feature_scale_ if physics else None)
            want = m.predict(U.astype(np.float32).astype(float), Y.astype(np.float32).astype(float),
                             mode=mode)[m.t0:]
            span = np.ptp(Y, axis=0).max()
            assert np.max(np.abs(twin - want)) <= 1e-5 * span, mode


def test_rigid_twin_is_the_python_greybox(tmp_path):
    from cdam_core.models.file import load_model
    g = load_model(greybox_file(tmp_path / "gb.json"))
    U = rigid_record()
    Y = np.zeros((len(U), 1))
    Y[2:] = g.predict(U, Y, mode="free_run")[2:]
    dY = np.diff(Y[2:, 0])                  # the axis moves both ways: every friction branch
    assert np.sum(dY > 0) > 50 and np.sum(dY < 0) > 50
    for mode in ("one_step", "free_run"):
        want = g.predict(U.astype(np.float32).astype(float), Y.astype(np.float32).astype(float),
                         mode=mode)[2:]
        twin = rigid_twin32(RIGID, U, Y, mode)
        assert np.max(np.abs(twin - want)) <= 1e-5 * np.ptp(Y), mode


def test_default_record_moves_the_model(tmp_path):
    fm = fw.load_firmware_model(greybox_file(tmp_path / "gb.json"))
    U, Y = fw.default_record(fm, n=400)
    assert U.shape == (400, 2) and Y.shape == (400, 1) and np.all(np.isfinite(Y))
    assert np.ptp(Y) > 0 and len(np.unique(U[:, 0])) > 10


def test_a_delay_beyond_the_firmware_buffer_is_refused(tmp_path):
    from cdam_core.firmware.step import MAX_DELAY_ROWS
    from cdam_core.models.file import load_model, save_model
    g = load_model(greybox_file(tmp_path / "gb.json"))
    e = g.effects[-1]
    assert e.name == "actuator_delay"
    g.effects = g.effects[:-1] + (e.with_value((MAX_DELAY_ROWS + 1) * RIGID["dt"]),)
    save_model(tmp_path / "long.json", g, inputs=["tau", "load"], outputs=["q"])
    with pytest.raises(ValueError, match=f"delay: {MAX_DELAY_ROWS + 1} samples exceed"):
        fw.load_firmware_model(tmp_path / "long.json")
