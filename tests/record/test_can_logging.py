"""`cdam can-log` between two processes on udp_multicast (loopback only, TTL 0).

The logger runs as a subprocess (``python -m cdam_core can-log``); this test process sends frames
carrying a 64-bit sequence counter. Checked: no frame lost, duplicated or reordered; after a
SIGKILL the log is readable and complete up to at most 100 ms before the kill.
Figures are printed (run with -s to see them).
"""
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
import pytest

import cdam_core
from cdam_core.record.can import iter_log, open_bus
from cdam_core.cli.main import main

PKG_ROOT = str(Path(cdam_core.__file__).resolve().parents[1])


def _port() -> int:
    # one port per test process and call, so parallel runs of this file never share a bus
    _port.n = getattr(_port, "n", 0) + 1
    return 44000 + (os.getpid() * 7 + _port.n * 131) % 15000


def _start_logger(log: Path, port: int, extra=()):
    env = dict(os.environ, PYTHONPATH=PKG_ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen(
        [sys.executable, "-m", "cdam_core", "can-log", "--interface", "udp_multicast",
         "--port", str(port), "-o", str(log), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    line = proc.stderr.readline()       # printed once the socket has joined the group
    if "recording to" not in line:
        proc.kill()
        raise AssertionError(f"logger did not start: {line}{proc.stderr.read()}")
    return proc


def _send(bus, rate: float, seconds: float, stop_at=None):
    """Send frames with a sequence counter at ``rate`` for ``seconds``; returns send times."""
    n = int(rate * seconds)
    sent = np.empty(n)
    t0 = time.perf_counter()
    seq = 0
    while seq < n:
        due = min(n, int((time.perf_counter() - t0) * rate) + 1)
        while seq < due:
            sent[seq] = time.time()
            bus.send(can.Message(arbitration_id=0x123, data=struct.pack(">Q", seq),
                                 is_extended_id=False))
            seq += 1
        if stop_at is not None and seq >= stop_at:
            return sent[:seq]
        time.sleep(0.0002)
    return sent


def _wait_quiet(log: Path, settle=0.6, limit=60.0):
    """Wait until the log has stopped growing (the logger has drained its socket)."""
    last, since, end = -1, time.monotonic(), time.monotonic() + limit
    while time.monotonic() < end:
        size = log.stat().st_size if log.exists() else 0
        if size != last:
            last, since = size, time.monotonic()
        elif time.monotonic() - since > settle:
            return
        time.sleep(0.1)


def _seqs(log: Path):
    report = {}
    msgs = list(iter_log(log, report))
    return (np.array([struct.unpack(">Q", bytes(m.data))[0] for m in msgs], dtype=np.int64),
            np.array([m.timestamp for m in msgs]), report)


def _link(tmp_path, rate, seconds, suffix=".log"):
    log = tmp_path / f"link{suffix}"
    port = _port()
    proc = _start_logger(log, port)
    try:
        with open_bus("udp_multicast", port=port) as tx:
            t_start = time.perf_counter()
            sent = _send(tx, rate, seconds)
            t_send = time.perf_counter() - t_start
        _wait_quiet(log)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    seq, tstamp, report = _seqs(log)
    n = sent.size
    lost = n - np.unique(seq).size
    reordered = int(np.sum(np.diff(seq) <= 0)) if seq.size > 1 else 0
    latency = tstamp - sent[seq] if seq.size else np.array([np.nan])
    print(f"\nudp_multicast {suffix}: sent {n} frames in {t_send:.2f} s "
          f"({n / t_send:.0f} frame/s), logged {seq.size}, lost {lost}, "
          f"out of order {reordered}; receive latency median {np.median(latency) * 1e3:.2f} ms, "
          f"max {latency.max() * 1e3:.2f} ms")
    assert not report["truncated"]
    assert seq.size == n and lost == 0 and reordered == 0
    np.testing.assert_array_equal(seq, np.arange(n))


@pytest.mark.realtime
def test_link_10k_frames_per_second_short(tmp_path):
    _link(tmp_path, rate=10_000, seconds=2.0)


@pytest.mark.slow
@pytest.mark.realtime
def test_link_10k_frames_per_second_60s(tmp_path):
    _link(tmp_path, rate=10_000, seconds=60.0)


def _kill(tmp_path, suffix, rate):
    log = tmp_path / f"killed{suffix}"
    port = _port()
    proc = _start_logger(log, port)
    try:
        with open_bus("udp_multicast", port=port) as tx:
            sent = _send(tx, rate, 1.0)
            t_kill = time.time()
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
            sent = np.concatenate([sent, _send(tx, rate, 0.1)])   # traffic goes on after the kill
    finally:
        if proc.poll() is None:
            proc.kill()
    seq, tstamp, report = _seqs(log)
    assert seq.size > 0
    np.testing.assert_array_equal(seq, np.arange(seq.size))      # a clean prefix
    must_have = int(np.sum(sent < t_kill - 0.100))                # frames sent > 100 ms before
    lag = t_kill - sent[seq[-1]]
    print(f"\nSIGKILL {suffix} at {rate} frame/s: {seq.size} frames readable, last sent {lag * 1e3:.1f} ms before "
          f"the kill; {must_have} required; partial tail: {report['truncated']}")
    assert seq.size >= must_have


def test_can_log_virtual_with_duration_and_decoded(tmp_path, capsys):
    log, dec = tmp_path / "v.log", tmp_path / "v.csv"
    # nothing on the bus: the log is valid but empty, and --decoded says why it cannot decode
    assert main(["can-log", "--interface", "virtual", "--channel", "cdam-empty", "-o", str(log),
                 "--duration", "0.2", "--decoded", str(dec), "--quiet"]) == 2
    assert "fewer than 2 feedback frames" in capsys.readouterr().err
    assert list(iter_log(log)) == []


def test_can_log_rejects_bad_arguments(tmp_path, capsys):
    assert main(["can-log", "--interface", "virtual", "-o", str(tmp_path / "x.txt"),
                 "--duration", "0.1"]) == 2
    assert "suffix" in capsys.readouterr().err
    assert main(["can-log", "--interface", "virtual", "-o", str(tmp_path / "x.log"),
                 "--duration", "-1"]) == 2
    assert "duration" in capsys.readouterr().err
    assert main(["can-log", "--interface", "socketcan", "-o", str(tmp_path / "x.log")]) == 2


# The arm's bus carries 2 motors x 1 kHz feedback + 1 kHz commands = 3 kframe/s.
@pytest.mark.parametrize("suffix", [".log", ".blf"])
def test_sigkill_leaves_log_readable_to_100ms_before_kill(tmp_path, suffix):
    _kill(tmp_path, suffix, rate=3000)


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.parametrize("suffix", [".log", ".blf"])
def test_sigkill_at_10k_frames_per_second(tmp_path, suffix):
    _kill(tmp_path, suffix, rate=10_000)
