"""Model export for the firmware (no toolchain needed): header contents, checks on bad input."""
import json
import re
import struct

import numpy as np
import pytest

from cdam_core import firmware as fw
from cdam_core.models.file import save_model

DEMO = fw.FIRMWARE_DIR / "generated" / "demo_model.json"


def test_header_holds_exact_float32_weights_and_checksum(tmp_path):
    out = fw.export_header(DEMO, tmp_path / "model.hpp")
    text = out.read_text()
    doc = json.loads(DEMO.read_text())
    theta = np.asarray(doc["model"]["theta"])
    body = re.search(r"kTheta\[(\d+)\] = \{(.*?)\};", text, re.S)
    assert int(body.group(1)) == theta.size == 6 * 20 + 20 + 20 * 8 + 8
    vals = np.array([float(v.rstrip("f")) for v in body.group(2).replace("\n", "").split(",")])
    np.testing.assert_array_equal(vals.astype(np.float32), theta.astype(np.float32))
    assert f'kSourceSha256[] = "{doc["sha256"]}"' in text
    # FNV-1a written out independently with struct
    h = 0x811C9DC5
    for b in struct.pack(f"<{theta.size}f", *theta.astype(np.float32)):
        h = ((h ^ b) * 0x01000193) & 0xFFFFFFFF
    assert f"kThetaFnv1a = 0x{h:08X}u" in text
    assert "constexpr int kInputs = 6;" in text and "constexpr int kOutputs = 8;" in text


def test_checked_in_header_is_the_demo_export(tmp_path):
    out = fw.export_header(DEMO, tmp_path / "model.hpp")
    assert out.read_text() == (fw.FIRMWARE_DIR / "generated" / "model.hpp").read_text()


def test_predict_matches_plain_numpy():
    fm = fw.load_firmware_model(DEMO)
    rng = np.random.default_rng(0)
    X = rng.uniform(fm.x_min, fm.x_max, size=(20, fm.n_inputs))
    W1 = fm.theta[:120].reshape(20, 6, order="F")
    b1 = fm.theta[120:140]
    W2 = fm.theta[140:300].reshape(8, 20, order="F")
    b2 = fm.theta[300:]
    xn = 2 * (X - fm.x_min) / (fm.x_max - fm.x_min) - 1
    yn = np.tanh(xn @ W1.T + b1) @ W2.T + b2
    y = (yn + 1) * (fm.y_max - fm.y_min) / 2 + fm.y_min
    np.testing.assert_allclose(fm.predict(X), y, rtol=1e-12, atol=1e-12)


def test_narx_model_gets_one_scale_per_regressor_element(tmp_path):
    from cdam_core.models import BPNetwork
    i, m, h, na, nb = 2, 1, 3, 2, 1
    n_in = na * m + nb * i
    net = BPNetwork.from_dict({
        "theta": np.linspace(-1, 1, n_in * h + h + h * m + m).tolist(), "n_inputs": i,
        "n_outputs": m, "hidden": h, "activation": "logsig", "narx": [na, nb, 1],
        "x_min": [0.0, 1.0], "x_max": [2.0, 3.0], "y_min": [-5.0], "y_max": [5.0]})
    save_model(tmp_path / "narx.json", net, inputs=["a", "b"], outputs=["y"])
    fm = fw.load_firmware_model(tmp_path / "narx.json")
    assert fm.inputs == ["y[t-1]", "y[t-2]", "a[t-nk-0]", "b[t-nk-0]"]
    np.testing.assert_array_equal(fm.x_min, [-5, -5, 0, 1])
    text = fw.export_header(fm, tmp_path / "m.hpp").read_text()
    assert "kTansig = false" in text and "constexpr int kInputs = 4;" in text


def test_bad_model_files_are_rejected(tmp_path):
    with pytest.raises(FileNotFoundError, match="MODEL"):
        fw.load_firmware_model(tmp_path / "missing.json")
    broken = tmp_path / "broken.json"
    broken.write_text(DEMO.read_text()[:200])
    with pytest.raises(ValueError):
        fw.load_firmware_model(broken)
    doc = json.loads(DEMO.read_text())
    doc["model"]["theta"][0] += 1.0  # altered: checksum no longer matches
    altered = tmp_path / "altered.json"
    altered.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="checksum"):
        fw.load_firmware_model(altered)
    with pytest.raises(ValueError, match="-o"):
        fw.export_header(DEMO, tmp_path / "no" / "such" / "model.hpp")


def test_pid_config_is_read_from_the_firmware_header():
    cfg = fw.pid_config()
    assert cfg["kDt"] == pytest.approx(0.001)
    assert cfg["kKp"] > 0 and cfg["kCurrentLimitA"] == pytest.approx(10.0)


def test_plant_feedback_frames_encode_the_state():
    from cdam_core.record.can.codec import decode_feedback
    p = fw.JointPlant()
    p.q = np.array([2 * np.pi / 36 * 1.25, -0.001])  # 1.25 rotor turns; slightly negative
    p.w = np.array([1.0, 0.0])
    f1, f2 = (decode_feedback(m) for m in p.feedback_frames())
    assert f1.angle == 2048 and f2.angle == 8192 - int(np.ceil(0.001 * 36 / (2 * np.pi) * 8192))
    assert f1.speed_rpm == round(36 * 60 / (2 * np.pi))
    # exact first-order response: dw/dt = (kt I - b w) / J from rest with 1 A
    p2 = fw.JointPlant()
    p2.step([1000, 0], 0.01)
    a, w_inf = p2.damping / p2.inertia, p2.kt / p2.damping
    assert p2.w[0] == pytest.approx(w_inf * (1 - np.exp(-a * 0.01)), rel=1e-12)


def test_checked_in_optim_data_is_a_fresh_export(tmp_path):
    out = fw.export_optim_data(tmp_path / "optim_data.hpp")
    assert out.read_text() == (fw.FIRMWARE_DIR / "generated" / "optim_data.hpp").read_text()


def test_optim_data_is_the_teacher_network_on_uniform_inputs():
    X, T, teacher = fw.optim_data()
    assert X.shape == (200, 4) and T.shape == (200, 2) and teacher.shape == (58,)
    assert X.dtype == np.float32 and T.dtype == np.float32
    assert np.all(np.abs(X) <= 1) and np.all(np.abs(teacher) <= 1.5)
    # independent forward pass: W1 (8x4), b1, W2 (2x8), b2 in MATLAB column-major order
    W1 = teacher[:32].reshape(4, 8).T
    b1 = teacher[32:40]
    W2 = teacher[40:56].reshape(8, 2).T
    b2 = teacher[56:]
    want = (np.tanh(X.astype(float) @ W1.T + b1) @ W2.T + b2).astype(np.float32)
    np.testing.assert_allclose(T, want, rtol=0, atol=1e-6)
    X2, _, _ = fw.optim_data(seed=43)
    assert not np.array_equal(X, X2)
    with pytest.raises(ValueError, match="n"):
        fw.optim_data(n=0)
