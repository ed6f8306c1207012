"""A bp_network with a monitor section on the board: exported one sample at a time (kind 5,
fw::StepModel, NARX or static) beside fw/monitor.hpp. Without the toolchain: the header's
numbers against the model file read as plain JSON, and a float32 numpy twin of the step on
those numbers against the Python model. Under QEMU (slow): the firmware's predictions and
monitor decisions against Python's, and the same decisions in PIL over SLCAN."""
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core import firmware as fw
from cdam_core.evaluate.monitor import calibrate
from cdam_core.models import BPNetwork, save_model

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "evaluate"))
from _monitor_plant import DT, plant  # noqa: E402


def _network_file(path, narx, monitor=True, hidden=5):
    U, Y = plant(4000, seed=1)
    m = BPNetwork(hidden=hidden, narx=narx, epochs=40).fit(U, Y)
    save_model(path, m, inputs=["u_secret", "u1"], outputs=["y_secret", "y1"],
               monitor=calibrate(m, U, Y, DT, paths=100, seed=0) if monitor else None)
    return path


def _array(text, name):
    m = re.search(rf"constexpr float {name}\[(\d+)\] = \{{(.*?)\}};", text, re.S)
    assert m, name
    return np.array([float(v.strip().rstrip("f")) for v in m.group(2).split(",")], np.float32)


def _int(text, name):
    return int(re.search(rf"constexpr int {name} = (-?\d+);", text).group(1))


@pytest.fixture(scope="module")
def network_files(tmp_path_factory):
    """The NARX and the static network with their monitor sections, written once."""
    d = tmp_path_factory.mktemp("nets")
    return {narx: _network_file(d / f"n{k}.json", narx) for k, narx in
            enumerate([(2, 2, 1), None])}


@pytest.mark.parametrize("narx", [(2, 2, 1), None])
def test_header_holds_the_file_numbers(tmp_path, network_files, narx):
    path = network_files[narx]
    doc = json.loads(path.read_text())
    text = fw.export_header(path, tmp_path / "model.hpp").read_text()
    assert "#define CDAM_MODEL_KIND 5" in text and "#define CDAM_MODEL_HAS_MONITOR 1" in text
    for word in ("u_secret", "y_secret", "tansig"):
        assert word not in text
    na, nb, nk = narx or (0, 1, 0)
    assert [_int(text, k) for k in ("kNa", "kNb", "kNk", "kHistory")] == \
        [na, nb, nk, max(na, nb + nk - 1) if narx else 0]
    d, f32 = doc["model"], lambda v: np.asarray(v, np.float32)
    np.testing.assert_array_equal(_array(text, "kNetTheta"), f32(d["theta"]))
    np.testing.assert_array_equal(_array(text, "kNetXMin"), f32(d["y_min"] * na + d["x_min"] * nb))
    np.testing.assert_array_equal(_array(text, "kNetXMax"), f32(d["y_max"] * na + d["x_max"] * nb))
    np.testing.assert_array_equal(_array(text, "kMonH"), f32(doc["monitor"]["h"]))
    # without a monitor section the network stays the kind-0 network of the joint loop
    plain = fw.load_firmware_model(_network_file(tmp_path / "p.json", narx, monitor=False))
    assert isinstance(plain, fw.FirmwareModel)


def _twin32(text, U, Y):
    """The kind-5 step in plain numpy float32 on the header's numbers (exact tanh), one-step:
    regressor [y(t-1..t-na), u(t-nk..t-nk-nb+1)], min-max to [-1, 1], W1 x + b1, tanh,
    W2 h + b2, back-scaled (theta column-major: W1 h x i, b1, W2 m x h, b2)."""
    f = np.float32
    na, nb, nk, h = (_int(text, k) for k in ("kNa", "kNb", "kNk", "kNetHidden"))
    th = _array(text, "kNetTheta").astype(f)
    lo, hi = _array(text, "kNetXMin").astype(f), _array(text, "kNetXMax").astype(f)
    ylo, yhi = _array(text, "kNetYMin").astype(f), _array(text, "kNetYMax").astype(f)
    m, i = Y.shape[1], lo.size
    W1 = th[:h * i].reshape(i, h).T
    b1 = th[h * i:h * i + h]
    W2 = th[h * i + h:h * i + h + m * h].reshape(h, m).T
    b2 = th[h * i + h + m * h:]
    U, Y = U.astype(f), Y.astype(f)
    t0 = max(na, nb + nk - 1) if na else nk + nb - 1
    out = []
    for t in range(t0, len(U)):
        r = np.concatenate([Y[t - a] for a in range(1, na + 1)] +
                           [U[t - nk - b] for b in range(nb)]).astype(f)
        x = f(2) * (r - lo) / (hi - lo) - f(1)
        yn = W2 @ np.tanh(W1 @ x + b1) + b2
        out.append((yn + f(1)) * (yhi - ylo) / f(2) + ylo)
    return np.array(out, np.float64)


@pytest.mark.parametrize("narx", [(2, 2, 1), None])
def test_float32_twin_of_the_step_is_the_python_model(tmp_path, network_files, narx):
    path = network_files[narx]
    text = fw.export_header(path, tmp_path / "model.hpp").read_text()
    fm = fw.load_firmware_model(path)
    U, Y = plant(400, seed=3)
    want = fm.predict(U.astype(np.float32).astype(float), Y.astype(np.float32).astype(float),
                      "one_step")
    twin = _twin32(text, U, Y)
    assert twin.shape == want.shape
    # float32 rounding of a 5-unit network and its scaling: a few ulp of the outputs' span
    span = np.ptp(Y, axis=0).max()
    assert np.max(np.abs(twin - want)) <= 50 * np.finfo(np.float32).eps * span


@pytest.mark.slow
@pytest.mark.skipif(fw.toolchain_available() is not None,
                    reason=f"firmware toolchain: {fw.toolchain_available()}")
@pytest.mark.parametrize("narx", [(2, 2, 1), None])
def test_network_and_monitor_on_the_board(tmp_path, network_files, narx):
    from cdam_core.firmware.monitor_pil import monitor_pil
    path = network_files[narx]
    sizes = fw.build(tmp_path / "b", path)
    U, Y = plant(3000, seed=12, effect="bias", onset_s=1.5)
    Y[1500:, 0] += 0.0 if narx else 0.3      # a static map sees a sensor offset, not the force
    r = fw.run_step_equivalence(tmp_path / "b", path, U, Y, "one_step", timeout=240)
    assert r["max_rel_error"] < 1e-5          # float32 and the fast tanh (about 1e-6 of it)
    assert r["monitor_alarms"] > 0 and r["monitor_mismatches"] == 0 and r["alarm_frames_equal"]
    # k = 10 steps on its own predictions: the fast tanh's 1e-6 grows through the feedback
    # (a free run of 3,000 rows of the NARX network: measured 1.2e-3 of the span)
    free = fw.run_step_equivalence(tmp_path / "b", path, U, Y, "k_step", k=10, timeout=240)
    assert free["max_rel_error"] < 1e-4
    print(f"bp_network narx={narx}: {r['instructions_per_step']} + "
          f"{r['instructions_per_monitor']} instructions, flash "
          f"{sizes['fw_step']['text'] + sizes['fw_step']['data']} B, RAM "
          f"{sizes['fw_step']['data'] + sizes['fw_step']['bss']} B, errors (one-step / k = 10) "
          f"{r['max_rel_error']:.2g} / {free['max_rel_error']:.2g}")
    if narx:   # the same decisions in PIL over SLCAN
        p = monitor_pil(tmp_path / "b", path, U, Y)
        np.testing.assert_array_equal(p["flags"][len(U) - r["steps"]:], r["monitor_flags"])
        assert math.isfinite(p["wall_s"])
