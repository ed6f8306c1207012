"""The aerial manipulator's arm_coupling on the board: a grey-box model fitted with the causal
columns (models/greybox/causal.py) on a simulated flight, exported (its numbers only: theta,
the Butterworth sections), run under QEMU (fw_step_check: every measured row reaches the model
through fw::StepModel::observe, in every mode) against the Python model on the same
float32-rounded record, with the residual monitor beside it. Zero-phase columns are refused
(test_firmware_kinds_export.py)."""
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core import firmware as fw

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _kinds import arm_coupling_file  # noqa: E402

needs_toolchain = pytest.mark.skipif(fw.toolchain_available() is not None,
                                     reason=f"firmware toolchain: {fw.toolchain_available()}")
ROWS = 1500     # 1.5 s of the 1 kHz flight on the board (the QEMU runs take a few seconds)


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    return arm_coupling_file(tmp_path_factory.mktemp("arm") / "arm.json", monitor=True)


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
