"""`cdam import-can` never drops data silently (issue 24 item 4): a bad line is skipped and named,
a frame stamped out of time order is excluded alone, a gap stays a gap, a NaN timestamp is named.
Logs are written here with plain Python (struct, base64), not with the code under test."""
import base64
import json
import struct

import numpy as np
import pytest

from cdam_core.cli.main import main

RATE = 1000.0
T0 = 1000.0
N = 1000          # frames per motor


def _truth(n=N):
    """Per motor: timestamps (us resolution, as candump writes), wire counts, true theta."""
    out = {}
    for m, phase in ((1, 0.0), (2, 0.0004)):
        t = np.round(T0 + phase + np.arange(n) / RATE, 6)
        rev = 2.0 * np.sin(2 * np.pi * 1.5 * (t - T0)) + 0.3 * m           # rotor revolutions
        rpm = np.round(2.0 * 2 * np.pi * 1.5 * np.cos(2 * np.pi * 1.5 * (t - T0)) * 60)
        counts = np.floor(rev * 8192).astype(int)
        cur = (np.arange(n) * 37 % 4000 - 2000).astype(int)
        out[m] = dict(t=t, counts=counts, rpm=rpm.astype(int), cur=cur,
                      theta=counts * 2 * np.pi / 8192 / 36)
    return out


def _frames(truth, stamp=None, drop=None):
    """[(timestamp, motor, 8 data bytes)] in arrival order; ``stamp`` {(m, k): t} changes one
    frame's timestamp (not its place), ``drop`` {m: slice} removes frames."""
    rows = []
    for m, tr in truth.items():
        for k in range(tr["t"].size):
            if drop and m in drop and k in range(*drop[m].indices(tr["t"].size)):
                continue
            data = struct.pack(">HhhH", tr["counts"][k] % 8192, tr["rpm"][k], tr["cur"][k], 0)
            rows.append((tr["t"][k], m, data, (stamp or {}).get((m, k), tr["t"][k])))
    rows.sort(key=lambda r: (r[0], r[1]))          # arrival order = true time order
    return [(r[3], r[1], r[2]) for r in rows]


def _write_candump(path, frames):
    with open(path, "w") as f:
        for t, m, data in frames:
            f.write(f"({t:.6f}) can0 {0x200 + m:03X}#{data.hex().upper()}\n")


def _write_csv(path, frames):
    with open(path, "w") as f:
        f.write("timestamp,arbitration_id,extended,remote,error,dlc,data\n")
        for t, m, data in frames:
            f.write(f"{float(t)!r},0x{0x200 + m:03X},0,0,0,8,{base64.b64encode(data).decode()}\n")


def _import(tmp_path, log, capsys, *extra):
    out = tmp_path / "joints.csv"
    code = main(["import-can", str(log), "-o", str(out), *extra])
    cap = capsys.readouterr()
    return code, cap.out, cap.err, out


def _read(out):
    """The written record, read with csv/json only."""
    arr = np.loadtxt(out, delimiter=",", skiprows=1)
    cols = out.read_text().splitlines()[0].split(",")
    meta = json.loads(out.with_suffix(".json").read_text())
    return {c: arr[:, j] for j, c in enumerate(cols)}, meta


def _check_theta(rec, meta, truth, m, keep=None):
    """theta_m matches linear interpolation of the kept true frames, up to whole rotor turns
    per segment (the turns made inside a gap are estimated from the speeds)."""
    tr = truth[m]
    t, th = (tr["t"], tr["theta"]) if keep is None else (tr["t"][keep], tr["theta"][keep])
    tabs = rec["t"] + meta["t0"]
    for a, b in meta["gapless_rows"]:
        exp = np.interp(tabs[a:b], t, th)
        got = rec[f"theta_m{m}"][a:b]
        off = exp[0] - got[0]
        turn = 2 * np.pi / 36
        assert off == pytest.approx(round(off / turn) * turn, abs=1e-9)
        np.testing.assert_allclose(got + off, exp, atol=1e-9)


BAD_LINES = {
    "bad hex": (".log", lambda line: line.replace("#", "#ZZ", 1)),
    "stray text": (".log", lambda line: "logger restarted by operator\n"),
    "bad base64": (".csv", lambda line: line.rsplit(",", 1)[0] + ",A!B=\n"),
    "csv stray text": (".csv", lambda line: "# comment in the middle\n"),
}


@pytest.mark.parametrize("case", sorted(BAD_LINES))
def test_one_bad_line_in_the_middle_is_skipped_and_named(tmp_path, capsys, case):
    suffix, spoil = BAD_LINES[case]
    truth = _truth()
    log = tmp_path / f"bus{suffix}"
    (_write_candump if suffix == ".log" else _write_csv)(log, _frames(truth))
    lines = log.read_text().splitlines(keepends=True)
    bad = len(lines) // 2                                    # 0-based; line number bad + 1
    lines[bad] = spoil(lines[bad])
    log.write_text("".join(lines))
    code, out, err, csv = _import(tmp_path, log, capsys)
    assert code == 1, err                                    # written, but incomplete
    assert f"warning: skipped lines: 1 (line {bad + 1})" in err   # warnings: stderr
    rec, meta = _read(csv)
    assert meta["skipped_lines"]["count"] == 1
    assert meta["skipped_lines"]["lines"][0]["line"] == bad + 1
    assert meta["frames"]["feedback"] >= 0.99 * 2 * N
    # the record goes on to the end of the log
    assert rec["t"][-1] + meta["t0"] >= truth[1]["t"][-1] - 2 / RATE
    for m in (1, 2):
        _check_theta(rec, meta, truth, m, keep=_kept(truth, m, lines, bad))


def _kept(truth, m, lines, bad):
    """Frames of motor m still in the log (the spoiled line held at most one)."""
    tr = truth[m]
    keep = np.ones(tr["t"].size, bool)
    orig = _frames(truth)
    # header line in CSV shifts the frame index by one
    k = bad - (1 if lines[0].startswith("timestamp") else 0)
    t, mm, _ = orig[k]
    if mm == m:
        keep[np.flatnonzero(tr["t"] == t)] = False
    return keep


@pytest.mark.parametrize("shift", [1000.0, -1000.0])
def test_one_frame_stamped_far_off_is_excluded_alone(tmp_path, capsys, shift):
    truth = _truth()
    k = N // 3
    log = tmp_path / "bus.log"
    _write_candump(log, _frames(truth, stamp={(1, k): float(truth[1]["t"][k] + shift)}))
    code, out, err, csv = _import(tmp_path, log, capsys)
    assert code == 1, err
    assert "excluded frames: m1: 1 out of order" in err
    rec, meta = _read(csv)
    assert meta["excluded"]["m1"]["out_of_order"]["count"] == 1
    keep = np.ones(N, bool)
    keep[k] = False
    _check_theta(rec, meta, truth, 1, keep=keep)     # nothing else of motor 1 changes
    _check_theta(rec, meta, truth, 2)
    assert rec["t"][-1] + meta["t0"] >= truth[1]["t"][-1] - 1 / RATE   # not cut at the frame


def test_a_gap_stays_a_gap(tmp_path, capsys):
    truth = _truth()
    a, b = 300, 600                                   # motor 1 silent for 0.3 s
    log = tmp_path / "bus.log"
    _write_candump(log, _frames(truth, drop={1: slice(a, b)}))
    code, out, err, csv = _import(tmp_path, log, capsys)
    assert code == 1, err
    rec, meta = _read(csv)
    tabs = rec["t"] + meta["t0"]
    t1 = truth[1]["t"]
    inside = (tabs > t1[a - 1] + 1e-9) & (tabs < t1[b] - 1e-9)
    assert not inside.any(), "grid samples fabricated inside the gap"
    assert 0.3 * RATE - 2 <= meta["gap_samples"] <= 0.3 * RATE + 2
    assert f"gap samples left out: {meta['gap_samples']}" in out
    assert len(meta["gapless_rows"]) == 2
    keep = np.ones(N, bool)
    keep[a:b] = False
    _check_theta(rec, meta, truth, 1, keep=keep)
    # on the 1/rate lattice on both sides of the gap
    steps = np.diff(rec["t"]) * RATE
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)


@pytest.mark.parametrize("writer", [_write_candump, _write_csv])
def test_a_nan_first_timestamp_is_named_and_the_rest_kept(tmp_path, capsys, writer):
    truth = _truth()
    log = tmp_path / ("bus.log" if writer is _write_candump else "bus.csv")
    frames = _frames(truth)
    assert frames[0][1] == 1
    frames[0] = (float("nan"), 1, frames[0][2])
    writer(log, frames)
    code, out, err, csv = _import(tmp_path, log, capsys)
    assert code == 1, err
    assert "excluded frames: 1 with a NaN/Inf timestamp" in err
    rec, meta = _read(csv)
    assert meta["malformed"]["non_finite_time"] == 1
    keep = np.ones(N, bool)
    keep[0] = False
    _check_theta(rec, meta, truth, 1, keep=keep)


def test_a_clean_log_exits_0_and_loses_nothing(tmp_path, capsys):
    truth = _truth()
    log = tmp_path / "bus.log"
    _write_candump(log, _frames(truth))
    code, out, err, csv = _import(tmp_path, log, capsys)
    assert code == 0, err
    assert "incomplete" not in out + err and "warning" not in err
    rec, meta = _read(csv)
    assert meta["gap_samples"] == 0 and meta["skipped_lines"]["count"] == 0
    _check_theta(rec, meta, truth, 1)


def test_a_grid_above_the_limit_is_refused_before_allocating(tmp_path, capsys):
    from cdam_core.record.resample import MAX_GRID_SAMPLES
    truth = _truth()
    log = tmp_path / "bus.log"
    _write_candump(log, _frames(truth))
    rate = 2.0 * MAX_GRID_SAMPLES / (N / RATE)           # twice the limit over the record
    code, out, err, csv = _import(tmp_path, log, capsys, "--rate", repr(rate))
    assert code == 2
    assert "MAX_GRID_SAMPLES" in err and err.count("\n") == 1
    assert not csv.exists()


def _write_blf(path, frames, level):
    """python-can's BLFWriter, 100 frames per container (48-byte objects, 4,800-byte
    containers), zlib (``level`` -1) or uncompressed (0)."""
    import can
    w = can.BLFWriter(str(path), compression_level=level)
    w.max_container_size = 100 * 48
    for t, m, data in frames:
        w.on_message_received(can.Message(timestamp=float(t), arbitration_id=0x200 + m,
                                          is_extended_id=False, data=data))
    w.stop()


def _containers(blob):
    """(offset, size) of the top-level objects, walked with struct (file header size at byte 4,
    then b"LOBJ" headers: signature, header size, version, object size, type)."""
    pos = struct.unpack_from("<L", blob, 4)[0]
    out = []
    while pos < len(blob):
        sig, _, _, size, _ = struct.unpack_from("<4sHHLL", blob, pos)
        assert sig == b"LOBJ"
        out.append((pos, size))
        pos += size + size % 4
    return out


@pytest.mark.parametrize("where", ["zlib container", "object header"])
def test_blf_a_bad_object_in_the_middle_is_skipped_and_counted(tmp_path, capsys, where):
    truth = _truth()
    frames = _frames(truth)
    log = tmp_path / "bus.blf"
    _write_blf(log, frames, -1 if where == "zlib container" else 0)
    blob = bytearray(log.read_bytes())
    cons = _containers(blob)
    c = len(cons) // 2
    off, size = cons[c]
    if where == "zlib container":         # a flipped byte inside the compressed stream
        blob[off + 32 + (size - 32) // 2] ^= 0xFF
        lost = list(range(100 * c, 100 * (c + 1)))
    else:                                 # the signature of the 51st object of the container
        k = 50
        blob[off + 32 + 48 * k] ^= 0xFF
        lost = [100 * c + k]
    log.write_bytes(bytes(blob))
    code, out, err, csv = _import(tmp_path, log, capsys)
    assert code == 1, err
    assert "warning: skipped objects: 1," in err
    rec, meta = _read(csv)
    assert meta["skipped_objects"]["count"] == 1
    if where == "zlib container":
        assert meta["skipped_objects"]["bytes"] == size + size % 4
    assert meta["frames"]["feedback"] == 2 * N - len(lost)
    assert not meta["log_truncated"]
    # the record goes on to the end of the log, and theta follows the frames kept
    assert rec["t"][-1] + meta["t0"] >= truth[1]["t"][-1] - T0 - 2 / RATE
    gone = {(frames[i][0], frames[i][1]) for i in lost}
    tabs = rec["t"] + meta["t0"] + T0           # BLF keeps times from the first frame
    for m in (1, 2):
        tr = truth[m]
        keep = np.array([(t, m) not in gone for t in tr["t"]])
        for a, b in meta["gapless_rows"]:
            exp = np.interp(tabs[a:b], tr["t"][keep], tr["theta"][keep])
            got = rec[f"theta_m{m}"][a:b]
            turn = 2 * np.pi / 36
            off_ = exp[0] - got[0]
            assert off_ == pytest.approx(round(off_ / turn) * turn, abs=1e-6)
            np.testing.assert_allclose(got + round(off_ / turn) * turn, exp, atol=1e-6)
