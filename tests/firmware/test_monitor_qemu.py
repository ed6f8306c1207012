"""The residual monitor on the emulated STM32F405: fw/monitor.hpp beside the model step takes
the decisions cdam_core.evaluate.monitor takes, sample for sample, on a record where an effect
switches on at t = 10 s (the independent generator of tests/evaluate/_monitor_plant.py), and
its alarm frames (id 0x3F2) name the outputs Python names. Skipped without the toolchain."""
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core import firmware as fw
from cdam_core.evaluate.monitor import calibrate
from cdam_core.firmware.alarm import ALARM_ID
from cdam_core.models import ArxModel, save_model

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "evaluate"))
from _monitor_plant import DT, ONSET_S, plant  # noqa: E402

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(fw.toolchain_available() is not None,
                                 reason=f"firmware toolchain: {fw.toolchain_available()}")]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    U, Y = plant(20_000, seed=1)
    m = ArxModel((2, 2, 1)).fit(U, Y)
    path = tmp_path_factory.mktemp("m") / "arx_monitor.json"
    save_model(path, m, inputs=["u0", "u1"], outputs=["y0", "y1"],
               monitor=calibrate(m, U, Y, DT, paths=200, seed=0))
    bdir = tmp_path_factory.mktemp("fw_monitor")
    return path, bdir, fw.build(bdir, path)


def test_firmware_monitor_equals_python_sample_for_sample(built):
    path, bdir, sizes = built
    U, Y = plant(11_000, seed=11, effect="friction")
    r = fw.run_step_equivalence(bdir, path, U, Y, "one_step", timeout=240)
    assert r["monitor_alarms"] > 0                          # the comparison covers alarms
    assert r["monitor_mismatches"] == 0
    np.testing.assert_array_equal(r["monitor_flags"], r["monitor_flags_python"])
    assert r["alarm_frames_equal"]
    frames = r["alarm_frames"]
    assert {f[0] for f in frames} == {ALARM_ID}
    first = frames[0]
    onset = int(round(ONSET_S / DT))
    assert onset <= first[4] <= onset + int(0.5 / DT)        # within 0.5 s of the onset
    assert first[1] in (0, 1) and first[2] in (1, 2, 3, 4, 5, 6, 7)
    assert r["instructions_per_monitor"] < 500


def test_image_sizes_include_the_monitor(built):
    _, _, sizes = built
    # the monitor's four per-output arrays and its state (3 floats per output) are there
    assert sizes["fw_step"]["bss"] >= 2 * 3 * 4
