"""C610Recorder (python-can Listener) and `cdam import-can`."""
import struct

import can
import numpy as np
import pytest

from cdam_core.record.can import C610Recorder, encode_current_command
from cdam_core.cli.main import main
from cdam_core.record.dataset import read_dataset

RATE = 1000.0


def _frames(n=600, t0=1000.0, seed=0):
    """Two motors at 1 kHz (motor 2 0.4 ms after motor 1); true output angle, current."""
    rng = np.random.default_rng(seed)
    msgs, truth = [], {}
    for m, phase in ((1, 0.0), (2, 0.0004)):
        t = t0 + phase + np.arange(n) / RATE
        rev = 3.0 * np.sin(2 * np.pi * 2.0 * (t - t0)) + 0.1 * m     # rotor revolutions
        rpm = np.round(3.0 * 2 * np.pi * 2.0 * np.cos(2 * np.pi * 2.0 * (t - t0)) * 60)
        counts = np.floor(rev * 8192).astype(int)
        cur = rng.integers(-9000, 9000, n)
        truth[m] = dict(t=t, theta=counts * 2 * np.pi / 8192 / 36, cur=cur / 1000.0, rpm=rpm)
        for k in range(n):
            data = struct.pack(">HhhH", counts[k] % 8192, int(rpm[k]), int(cur[k]), 0)
            msgs.append(can.Message(timestamp=float(t[k]), arbitration_id=0x200 + m, data=data,
                                    is_extended_id=False))
    msgs.sort(key=lambda m: m.timestamp)
    return msgs, truth


BAD = [
    can.Message(timestamp=1000.1001, arbitration_id=0x201, data=bytes(6),
                is_extended_id=False),              # dlc
    can.Message(timestamp=1000.1002, arbitration_id=0x555, data=bytes(8),
                is_extended_id=False),              # id
    can.Message(timestamp=1000.1003, arbitration_id=0x202,
                data=struct.pack(">HhhH", 9000, 0, 0, 0), is_extended_id=False),                              # range
    can.Message(timestamp=1000.1004, arbitration_id=0x201, is_error_frame=True),
]


def test_recorder_decodes_and_counts_every_malformed_frame():
    msgs, truth = _frames()
    rec = C610Recorder()
    for m in msgs[:300] + BAD + msgs[300:]:
        rec.on_message_received(m)
    rec.on_message_received(encode_current_command([1.5, -0.5]))
    assert rec.counts["feedback"] == len(msgs) and rec.counts["command"] == 1
    assert rec.malformed == {"wrong_dlc": 1, "unknown_id": 1, "out_of_range": 1,
                             "error_frame": 1, "remote_frame": 0, "non_finite_time": 0,
                             "non_increasing_time": 0, "decode_error": 0}
    for m in (1, 2):
        r = rec.motor_record(m)
        tr = truth[m]
        np.testing.assert_array_equal(r["t"], tr["t"])
        # unwrapped angle is the true one up to the first frame's whole rotor turns
        off = tr["theta"][0] - r["theta"][0]
        assert off == pytest.approx(round(off / (2 * np.pi / 36)) * 2 * np.pi / 36, abs=1e-12)
        np.testing.assert_allclose(r["theta"] + off, tr["theta"], atol=1e-12)
        np.testing.assert_allclose(r["tau"], 0.18 * tr["cur"], atol=1e-12)
        np.testing.assert_allclose(r["omega"], tr["rpm"] * 2 * np.pi / 60 / 36)
    assert rec.commands(1)[1].tolist() == [1.5] and rec.commands(2)[1].tolist() == [-0.5]


def test_recorder_through_notifier_on_virtual_bus():
    msgs, _ = _frames(n=200)
    rec = C610Recorder()
    with can.Bus(interface="virtual", channel="cdam-test-rec") as rx, \
            can.Bus(interface="virtual", channel="cdam-test-rec") as tx:
        notifier = can.Notifier(rx, [rec])
        for m in msgs + BAD:
            tx.send(m)
        deadline = __import__("time").monotonic() + 5
        while sum(rec.counts.values()) < len(msgs) + len(BAD) and \
                __import__("time").monotonic() < deadline:
            __import__("time").sleep(0.01)
        notifier.stop()
    # the virtual bus stamps frames on send; a bad timestamp never raises
    assert sum(rec.counts.values()) == len(msgs) + len(BAD)
    assert rec.malformed["wrong_dlc"] == 1 and rec.malformed["unknown_id"] == 1


def test_to_dataset_grid_and_columns():
    msgs, truth = _frames()
    rec = C610Recorder()
    for m in msgs:
        rec.on_message_received(m)
    ds = rec.to_dataset(rate=500.0)
    assert ds.columns[:2] == ["theta_m1", "theta_m2"]
    assert set(ds.columns) == {f"{p}_{j}" for p in ("theta", "omega", "i", "tau")
                               for j in ("m1", "m2")}
    assert ds.inputs == ["tau_m1", "tau_m2"] and ds.outputs == ["theta_m1", "theta_m2"]
    assert ds.rate == 500.0
    np.testing.assert_allclose(np.diff(ds.t), 1 / 500.0, atol=1e-9)
    # grid inside both motors' spans; tau linear in time between frames
    tabs = ds.t + ds.meta["t0"]
    assert tabs[0] >= truth[2]["t"][0] and tabs[-1] <= truth[1]["t"][-1]
    exp = np.interp(tabs, truth[2]["t"], 0.18 * truth[2]["cur"])
    np.testing.assert_allclose(ds.column("tau_m2"), exp, atol=1e-9)
    assert ds.meta["gaps"] == {"m1": [], "m2": []}


def test_to_dataset_without_data_is_a_clear_error():
    rec = C610Recorder()
    rec.on_message_received(BAD[0])
    with pytest.raises(ValueError, match=r"motor 1 \(m1\).*wrong_dlc"):
        rec.to_dataset()


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".csv"])
def test_import_can_cli_all_formats(tmp_path, suffix, capsys):
    msgs, truth = _frames(n=300)
    log = tmp_path / f"bus{suffix}"
    with can.Logger(str(log)) as w:
        for m in msgs[:100] + BAD[:3] + msgs[100:]:
            w(m)
    out = tmp_path / "joints.csv"
    assert main(["import-can", str(log), "-o", str(out), "--rate", "1000"]) == 0
    printed = capsys.readouterr().out
    assert "'wrong_dlc': 1" in printed and "'unknown_id': 1" in printed
    ds = read_dataset(out)
    assert ds.meta["malformed"]["out_of_range"] == 1
    # .asc and .blf store times relative to the first frame: shift back to the source clock
    reader = can.LogReader(str(log))
    shift = msgs[0].timestamp - next(iter(reader)).timestamp
    getattr(reader, "stop", lambda: None)()
    tabs = ds.t + ds.meta["t0"] + shift
    # formats keep microseconds (or less): the tolerance covers 1 us of current slope
    exp = np.interp(tabs, truth[1]["t"], 0.18 * truth[1]["cur"])
    np.testing.assert_allclose(ds.column("tau_m1"), exp, atol=2e-3)


def test_import_can_cli_errors(tmp_path, capsys):
    assert main(["import-can", str(tmp_path / "none.log"), "-o", str(tmp_path / "o.csv")]) == 2
    assert "no such file" in capsys.readouterr().err
    bad = tmp_path / "x.txt"
    bad.write_text("")
    assert main(["import-can", str(bad), "-o", str(tmp_path / "o.csv")]) == 2
    assert "suffix" in capsys.readouterr().err
    assert main(["import-can", str(bad), "-o", "o.csv", "--joints", "1-m1"]) == 2


def test_import_can_reports_a_log_cut_by_a_kill(tmp_path, capsys):
    msgs, _ = _frames(n=50)
    log = tmp_path / "cut.log"
    with can.Logger(str(log)) as w:
        for m in msgs:
            w(m)
    with open(log, "a") as f:
        f.write("(1000.06")                       # a line cut mid-write
    assert main(["import-can", str(log), "-o", str(tmp_path / "j.csv")]) == 0
    cap = capsys.readouterr()
    assert "partial record" in cap.err and f"{len(msgs)} frames" in cap.out
    ds = read_dataset(tmp_path / "j.csv")
    assert ds.meta["log_truncated"]
