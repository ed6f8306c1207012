"""The residual monitor in the loop (PIL) over SLCAN with python-can: fw_monitor_pil.elf under
QEMU takes a simulated record row by row (the independent generator of
tests/evaluate/_monitor_plant.py, 1 kHz), runs the model beside it and sends an alarm frame
(0x3F2) naming the output. Three effects switching on at t = 10 s are alarmed within 0.5 s, 60 s
without an effect raise no alarm, and `cdam monitor MODEL RECORD` takes the firmware's decisions
sample for sample. The QEMU runs are slow (about 4 ms of wall time a row on two shared cores:
the 60 s record takes about 4-6 minutes), so the three effects are marked slow (CI runs them
once, about 1.5 minutes) and the 60 s soak is marked soak (run by hand: ``pytest -m soak
tests/firmware``; measured: 60,000 rows, no alarm, 351 s at load 8-18). CI still covers the 60 s
claim: the board's decisions equal `cdam monitor`'s row for row here, and `cdam monitor` raises
no alarm in 60 s of the same plant (tests/evaluate/test_monitor.py)."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core import firmware as fw
from cdam_core.cli.main import main
from cdam_core.evaluate.monitor import calibrate
from cdam_core.firmware.monitor_pil import (ROW_HISTORY, ROW_ID, ROW_MONITORED, monitor_pil,
                                            ring_bytes, row_frames, rows_in_flight)
from cdam_core.models import ArxModel, save_model

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "evaluate"))
from _monitor_plant import DT, EFFECTS, ONSET_S, plant  # noqa: E402

needs_toolchain = pytest.mark.skipif(fw.toolchain_available() is not None,
                                     reason=f"firmware toolchain: {fw.toolchain_available()}")
BITS = {"cusum_up": 1, "cusum_down": 2, "ewma": 4}
OUTPUTS = ["y0", "y1"]


def _model(path, paths):
    """ARX (2, 2, 1) on 60 s of the plant (seed 1), the thresholds for 5 % false-alarm
    probability per 60 s (as tests/evaluate/test_monitor.py)."""
    U, Y = plant(60_000, seed=1)
    m = ArxModel((2, 2, 1)).fit(U, Y)
    save_model(path, m, inputs=["u0", "u1"], outputs=OUTPUTS,
               monitor=calibrate(m, U, Y, DT, paths=paths, seed=0))
    return path


@pytest.fixture(scope="module")
def board(tmp_path_factory):
    path = _model(tmp_path_factory.mktemp("m") / "arx_monitor.json", 1000)
    bdir = tmp_path_factory.mktemp("fw_pil")
    sizes = fw.build(bdir, path)
    assert "fw_monitor_pil" in sizes
    return path, bdir


def _cdam_monitor_flags(tmp, model, U, Y):
    """`cdam monitor MODEL RECORD` on the record as the board got it (float32 values written
    exactly): its alarms as flags (N, m)."""
    csv = tmp / "record.csv"
    t = np.arange(len(U)) * DT
    np.savetxt(csv, np.column_stack([t, U.astype(np.float32), Y.astype(np.float32)]),
               delimiter=",", header="t,u0,u1,y0,y1", comments="", fmt="%.17g")
    assert main(["monitor", str(model), str(csv), "--json", str(tmp / "a.json")]) == 0
    flags = np.zeros(Y.shape, np.uint8)
    for a in json.loads((tmp / "a.json").read_text())["alarms"]:
        flags[a["row"], OUTPUTS.index(a["output"])] = sum(BITS[s] for s in a["statistics"])
    return flags


def _pil(board, tmp, U, Y):
    path, bdir = board
    r = monitor_pil(bdir, path, U, Y)
    print(f"PIL: {r['rows']} rows in {r['wall_s']} s ({r['wall_ms_per_row']} ms a row, "
          f"{r['in_flight']} in flight), alarms {r['alarms'][:3]}")
    assert r["ignored"] == 0
    assert np.all(r["status"][:2] == ROW_HISTORY) and np.all(r["status"][2:] == ROW_MONITORED)
    np.testing.assert_array_equal(r["flags"], _cdam_monitor_flags(tmp, path, U, Y))
    # the alarm frames name the outputs the flags name, in row order
    assert [(c, f, t) for c, f, _, t in r["alarm_frames"]] == \
        [(c, r["flags"][t, c], t) for t, c, _ in r["alarms"]]
    return r


@pytest.mark.slow
@needs_toolchain
@pytest.mark.parametrize("effect", EFFECTS)
def test_pil_alarms_an_effect_within_half_a_second(board, tmp_path, effect):
    U, Y = plant(int(round((ONSET_S + 0.5) / DT)) + 1, seed=10 + EFFECTS.index(effect),
                 effect=effect)
    r = _pil(board, tmp_path, U, Y)
    onset = int(round(ONSET_S / DT))
    assert r["alarms"], effect
    first = r["alarms"][0]
    print(f"{effect}: first alarm {first} delay {(first[0] - onset) * DT:.3f} s")
    assert onset <= first[0] <= onset + int(round(0.5 / DT))      # none before, within 0.5 s


@pytest.mark.soak
@needs_toolchain
def test_pil_60_s_without_an_effect_raise_no_alarm(board, tmp_path):
    U, Y = plant(60_000, seed=2)
    r = _pil(board, tmp_path, U, Y)
    assert r["alarms"] == [] and r["alarm_frames"] == []


def test_row_frames_and_flow_control():
    """Without QEMU: a row's frames carry its float32 values in order, and the rows kept in
    flight never exceed the image's receive ring."""
    u, y = np.array([1.5, -2.25, 3.0]), np.array([0.1, 7.0])
    frames = row_frames(u, y)
    assert [f.arbitration_id for f in frames] == [ROW_ID, ROW_ID + 1, ROW_ID + 2]
    got = np.frombuffer(b"".join(bytes(f.data) for f in frames), "<f4")
    np.testing.assert_array_equal(got, np.r_[u, y, 0.0].astype(np.float32))
    for values in (2, 4, 5, 17, 64):
        frames_per_row = (values + 1) // 2
        w = rows_in_flight(values)
        # room for the rows and the host's ack request ("r3F38\r": 6 bytes)
        assert w >= 1 and (w == 1 or w * frames_per_row * 22 + 6 <= ring_bytes())
        assert (w + 1) * frames_per_row * 22 + 6 > ring_bytes() - 2


def test_bad_input_is_refused_by_name(tmp_path):
    U, Y = plant(3000, seed=1)
    save_model(tmp_path / "m.json", ArxModel((2, 2, 1)).fit(U, Y), inputs=["u0", "u1"],
               outputs=OUTPUTS)
    with pytest.raises(ValueError, match="monitor"):
        monitor_pil(tmp_path, tmp_path / "m.json", U, Y)
    with pytest.raises(FileNotFoundError, match="MODEL"):
        monitor_pil(tmp_path, tmp_path / "none.json", U, Y)
    m = ArxModel((2, 2, 1)).fit(U, Y)
    save_model(tmp_path / "mm.json", m, monitor=calibrate(m, U, Y, DT, paths=100, seed=0))
    with pytest.raises(ValueError, match=r"Y: expected shape \(N, 2\)"):
        monitor_pil(tmp_path, tmp_path / "mm.json", U, Y[:, :1])
    Y[5, 1] = np.nan
    with pytest.raises(ValueError, match="Y: contains NaN"):
        monitor_pil(tmp_path, tmp_path / "mm.json", U, Y)
    with pytest.raises(FileNotFoundError, match="fw_monitor_pil.elf"):
        monitor_pil(tmp_path, tmp_path / "mm.json", U, np.nan_to_num(Y))


@pytest.mark.slow
@needs_toolchain
def test_pil_counts_foreign_frames_and_rejects_a_row_not_finite(board):
    """Raw frames on the bus: a foreign id and a short row frame are ignored and counted, a row
    with a NaN is taken but not run (status 2, acknowledged at once), and a remote frame 0x3F3
    asks for an ack."""
    import can
    from cdam_core.firmware.monitor_pil import ACK_ID, ROW_REJECTED
    from cdam_core.firmware.pil import slcan_board
    _, bdir = board

    def ack(bus):
        while True:
            msg = bus.recv(timeout=5.0)
            assert msg is not None
            if msg.arbitration_id == ACK_ID:
                return np.frombuffer(bytes(msg.data)[:4], "<u4")[0], msg.data[4], \
                    int.from_bytes(bytes(msg.data)[6:8], "little")

    with slcan_board(bdir / "fw_monitor_pil.elf", 60) as bus:
        bus.send(can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\0" * 8))
        bus.send(can.Message(arbitration_id=ROW_ID, is_extended_id=False, data=b"\0" * 4))
        for msg in row_frames([0.1, 0.2], [np.nan, 0.0]):
            bus.send(msg)
        assert ack(bus) == (1, ROW_REJECTED, 2)
        for msg in row_frames([0.1, 0.2], [0.0, 0.0]):       # a history row: acknowledged
            bus.send(msg)
        assert ack(bus) == (2, ROW_HISTORY, 2)
        bus.send(can.Message(arbitration_id=ACK_ID, is_extended_id=False, is_remote_frame=True,
                             dlc=8))
        assert ack(bus) == (2, ROW_HISTORY, 2)
