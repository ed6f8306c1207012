"""C610/M2006 codec: DBC frames against struct-packed bytes, unwrapping against the true angle."""
import math
import struct

import can
import numpy as np
import pytest

from cdam_core.record.can import (MalformedFrame, MotorState, decode_current_command, decode_feedback,
                           encode_current_command, encode_feedback, load_dbc)


def _fb(motor, angle, rpm, current, dlc=8, ext=False, raw=None):
    data = raw if raw is not None else struct.pack(">HhhH", angle, rpm, current, 0)
    return can.Message(arbitration_id=0x200 + motor, data=data[:dlc], is_extended_id=ext)


def test_dbc_describes_all_frames():
    db = load_dbc()
    ids = sorted(m.frame_id for m in db.messages)
    assert ids == [0x1FF, 0x200] + list(range(0x201, 0x209))
    assert all(m.length == 8 for m in db.messages)


@pytest.mark.parametrize("bank, fid", [(1, 0x200), (2, 0x1FF)])
def test_command_bytes_match_big_endian_int16(bank, fid):
    amps = [1.234, -10.0, 0.0, 9.999]
    msg = encode_current_command(amps, bank=bank)
    assert msg.arbitration_id == fid and not msg.is_extended_id
    assert bytes(msg.data) == struct.pack(">hhhh", 1234, -10000, 0, 9999)
    first = 1 if bank == 1 else 5
    back = decode_current_command(msg)
    assert back == pytest.approx({first + k: a for k, a in enumerate(amps)})


def test_command_rejects_bad_input():
    with pytest.raises(ValueError, match="currents_a: element 1 is NaN"):
        encode_current_command([0.0, math.nan])
    with pytest.raises(ValueError, match="outside"):
        encode_current_command([10.5])
    with pytest.raises(ValueError, match="bank"):
        encode_current_command([1.0], bank=3)
    with pytest.raises(ValueError, match="1 to 4"):
        encode_current_command([0.0] * 5)
    # fewer than four currents: the rest are zero
    assert bytes(encode_current_command([0.5]).data) == struct.pack(">hhhh", 500, 0, 0, 0)


@pytest.mark.parametrize("motor, angle, rpm, cur", [(1, 0, 0, 0), (2, 8191, -18000, 10000),
                                                    (8, 4096, 17999, -10000), (5, 1, -1, -1)])
def test_feedback_decodes_struct_packed_bytes(motor, angle, rpm, cur):
    fb = decode_feedback(_fb(motor, angle, rpm, cur))
    assert (fb.motor_id, fb.angle, fb.speed_rpm, fb.current) == (motor, angle, rpm, cur)
    assert bytes(encode_feedback(motor, angle, rpm, cur).data) == struct.pack(">HhhH", angle, rpm,
                                                                              cur, 0)


@pytest.mark.parametrize("msg, kind", [
    (_fb(1, 10, 0, 0, dlc=6), "wrong_dlc"),
    (can.Message(arbitration_id=0x301, data=bytes(8), is_extended_id=False), "unknown_id"),
    (_fb(1, 10, 0, 0, ext=True), "unknown_id"),
    (_fb(1, 0, 0, 0, raw=struct.pack(">HhhH", 8192, 0, 0, 0)), "out_of_range"),
    (_fb(1, 0, 0, 0, raw=struct.pack(">HhhH", 0, 0, 12000, 0)), "out_of_range"),
    (_fb(1, 0, 0, 0, raw=struct.pack(">HhhH", 0, 30000, 0, 0)), "out_of_range"),
    (can.Message(arbitration_id=0x201, is_error_frame=True), "error_frame"),
    (can.Message(arbitration_id=0x201, is_remote_frame=True, dlc=8), "remote_frame"),
])
def test_malformed_feedback_names_its_kind(msg, kind):
    with pytest.raises(MalformedFrame) as exc:
        decode_feedback(msg)
    assert exc.value.kind == kind and isinstance(exc.value, ValueError)


def _rotor_trajectory(n, dt, seed=3):
    """True rotor angle (counts, float), sampled frames: (t, counts 0..8191, rpm)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    # several turns each way, peak speed below the M2006's 18000 rpm
    w = 2 * np.pi * np.array([0.3, 1.1, 2.7])
    amp_rev = np.array([20.0, 5.0, 1.0]) * rng.uniform(0.8, 1.2, 3)
    rev = (amp_rev[:, None] * np.sin(w[:, None] * t)).sum(0) + 0.37
    rpm = (amp_rev[:, None] * w[:, None] * np.cos(w[:, None] * t)).sum(0) * 60
    assert np.abs(rpm).max() < 18000
    counts_true = np.floor(rev * 8192).astype(np.int64)
    return t, counts_true, np.round(rpm).astype(int)


def test_unwrap_matches_true_multiturn_angle_and_gearbox():
    t, counts_true, rpm = _rotor_trajectory(5000, 1e-3)
    st = MotorState()
    theta = np.array([st.update(int(c % 8192), r, 0, tt)[0] for tt, c, r in zip(t, counts_true, rpm)])
    expected = (counts_true - counts_true[0] + counts_true[0] % 8192) * 2 * np.pi / 8192 / 36
    np.testing.assert_allclose(theta, expected, rtol=0, atol=1e-12)


def test_unwrap_survives_lost_frames_using_speed():
    t, counts_true, rpm = _rotor_trajectory(5000, 1e-3)
    keep = np.ones(t.size, bool)
    fast = 100 + int(np.argmax(np.abs(rpm[100:4000])))
    keep[fast:fast + 8] = False    # 8 ms lost at top speed: more than half a rotor turn
    keep[3000:3005] = False
    moved = np.abs(counts_true[fast + 8] - counts_true[fast - 1])
    assert moved > 4096            # nearest-wrap would be wrong here
    st = MotorState()
    theta = np.array([st.update(int(c % 8192), r, 0, tt)[0]
                      for tt, c, r in zip(t[keep], counts_true[keep], rpm[keep])])
    c = counts_true[keep]
    expected = (c - c[0] + c[0] % 8192) * 2 * np.pi / 8192 / 36
    np.testing.assert_allclose(theta, expected, rtol=0, atol=1e-12)
    # without times, the nearest wrap cannot follow the same gap
    st2 = MotorState()
    theta2 = np.array([st2.update(int(c % 8192), r, 0)[0]
                       for c, r in zip(counts_true[keep], rpm[keep])])
    assert np.abs(theta2 - expected).max() > 0.1


def test_speed_current_torque_units():
    st = MotorState(kt=0.2)
    theta, omega, amps, tau = st.update(100, 3600, -2500)
    assert omega == pytest.approx(3600 / 60 * 2 * np.pi / 36)   # 60 rev/s rotor
    assert amps == pytest.approx(-2.5) and tau == pytest.approx(-0.5)
    assert MotorState().update(0, 0, 1000)[3] == pytest.approx(0.18)
    with pytest.raises(ValueError, match="angle"):
        st.update(9000, 0, 0)
