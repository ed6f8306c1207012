"""The aerial manipulator's arm_coupling on the board: a grey-box model fitted with the causal
columns (models/greybox/causal.py) on a simulated flight, exported (its numbers only: theta,
the Butterworth sections), run under QEMU (fw_step_check: every measured row reaches the model
through fw::StepModel::observe, in every mode) against the Python model on the same
float32-rounded record, with the residual monitor beside it. Zero-phase columns are refused
(test_firmware_kinds_export.py)."""
import re

import numpy as np
import pytest

from cdam_core import firmware as fw
from cdam_core.models.file import save_model
from cdam_core.models.greybox import effects as eff
from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.models.greybox.registry import get_model
from cdam_core.sim import simulate_flight
from cdam_core.sim.parameters import plant_dict, plant_vector, total_mass

needs_toolchain = pytest.mark.skipif(fw.toolchain_available() is not None,
                                     reason=f"firmware toolchain: {fw.toolchain_available()}")
CHANNELS = ("X", "Y", "Z", "tau_phi", "tau_theta")
ROWS = 1500     # 1.5 s of the 1 kHz flight on the board (the QEMU runs take a few seconds)


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    ds = simulate_flight("both", duration=10.0, seed=3, declare=["arm_coupling"])
    m = get_model("aerial_manipulator")
    U = np.column_stack([ds.column(k) for k in m.inputs])
    Y = np.column_stack([ds.column(k) for k in m.positions])
    dt = float(np.median(np.diff(ds.t)))
    fixed = {"m": total_mass(plant_dict(plant_vector()), with_payload=False)}
    g = GreyBox("aerial_manipulator", dt, fixed=fixed,
                effects=[eff.ArmCoupling(c, causal=True) for c in CHANNELS]).fit(U, Y)
    from cdam_core.evaluate.monitor import calibrate
    path = tmp_path_factory.mktemp("arm") / "arm.json"
    save_model(path, g, inputs=list(m.inputs), outputs=list(m.positions),
               monitor=calibrate(g, U[:4000], Y[:4000], dt, paths=100, seed=0))
    return path, U, Y


def test_header_holds_the_causal_columns_numbers(arm, tmp_path):
    path, _, _ = arm
    g = fw.load_firmware_model(path).model
    text = fw.export_header(path, tmp_path / "m.hpp").read_text()
    assert "#define CDAM_MODEL_ARM 1" in text
    # channels in the firmware's order X Y Z tau_theta tau_phi; equations in the error
    # vector's order (the body's six first: X Y Z tau_phi tau_theta tau_psi)
    assert re.search(r"kArmEq\[5\] = \{0, 1, 2, 4, 3\}", text)
    assert re.search(r"kArmCols\[5\] = \{3, 3, 3, 8, 6\}", text)
    got = np.array([float(v.rstrip("f")) for v in re.search(
        r"kArmTheta\[40\] = \{(.*?)\}", text, re.S).group(1).split(",")])
    want = np.zeros((5, 8))
    names = {"X": "c0 c1 c2", "Y": "c0 c1 c2", "Z": "c0 c1 c2",
             "tau_theta": "c0 c1 c2 dc1 dc2 p2 I1 I12", "tau_phi": "c0 c1 c2 dc1 dc2 p2"}
    for i, (ch, ns) in enumerate(names.items()):
        for j, n in enumerate(ns.split()):
            want[i, j] = g.theta_[f"arm_coupling@{ch}.{n}"]
    np.testing.assert_allclose(got, want.ravel().astype(np.float32), rtol=1e-7, atol=0)


@needs_toolchain
@pytest.mark.slow
def test_arm_coupling_on_the_board_matches_python(arm, tmp_path):
    path, U, Y = arm
    r = fw.check(path, build_dir=tmp_path / "b", record=(U[:ROWS], Y[:ROWS]))
    print({k: r[k] for k in ("instructions_per_step", "instructions_per_observe",
                             "instructions_per_monitor", "flash_bytes", "static_ram_bytes",
                             "max_rel_error", "max_rel_error_k_step", "max_rel_error_free_run",
                             "monitor_alarms", "monitor_mismatches") if k in r})
    assert r["heap_free"]
    assert r["instructions_per_observe"] > 0          # the columns are computed on the board
    # one-step and 10-step at float32 rounding of the positions' spans (the aerial
    # manipulator without the effect: 6.3e-7 and 6.0e-6 on this record)
    assert r["max_rel_error"] < 2e-6
    assert r["max_rel_error_k_step"] < 2e-5
    assert np.isfinite(r["max_rel_error_free_run"])
    # the monitor beside it decides as Python does, sample for sample
    assert r["monitor_mismatches"] == 0 and r["alarm_frames_equal"]
