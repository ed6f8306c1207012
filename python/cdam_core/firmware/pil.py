"""Processor in the loop: the 1 kHz joint loop over SLCAN against a Python joint plant."""
from __future__ import annotations

import math
import re
import struct
import subprocess
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cdam_core.firmware.model import FirmwareModel, load_firmware_model
from cdam_core.firmware.paths import FIRMWARE_DIR, QEMU

REFERENCE_ID, DIAGNOSTIC_ID = 0x300, 0x3F0   # joint references in; loop diagnostics out


def pid_config() -> dict:
    """The loop constants of firmware_stubs/include/fw/config.hpp (kDt, kKp, kKi, kKd, ...)."""
    text = (FIRMWARE_DIR / "include" / "fw" / "config.hpp").read_text()
    vals = dict(re.findall(r"constexpr float (k\w+) = ([-+0-9.eE]+)f;", text))
    need = {"kDt", "kKp", "kKi", "kKd", "kIntegralLimit", "kCurrentLimitA"}
    if not need <= vals.keys():
        raise ValueError(f"config.hpp: missing constants {sorted(need - vals.keys())}")
    return {k: float(v) for k, v in vals.items()}


@dataclass
class JointPlant:
    """Two independent geared joints driven by C610/M2006 currents: J dw/dt = kt I - b w.

    State per joint: output angle q (rad) and speed w (rad/s); integrated exactly over one
    period for constant current (first-order speed response). The C610 is taken to track its
    current command within the period and reports it as the feedback current.
    """

    inertia: float = 0.01      # kg m^2 at the output
    damping: float = 0.05      # N m s/rad
    kt: float = 0.18           # N m/A (cdam_core.record.can.codec.DEFAULT_KT_OUTPUT)
    q: np.ndarray = field(default_factory=lambda: np.zeros(2))
    w: np.ndarray = field(default_factory=lambda: np.zeros(2))
    counts: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=int))

    def step(self, current_counts, dt: float) -> None:
        """Advance by dt with the currents (C610 counts) held."""
        self.counts = np.asarray(current_counts, dtype=int)[:2].copy()
        tau = self.kt * self.counts * 1e-3
        a = self.damping / self.inertia
        w_inf = tau / self.damping
        e = math.exp(-a * dt)
        self.q = self.q + w_inf * dt + (self.w - w_inf) * (1 - e) / a
        self.w = w_inf + (self.w - w_inf) * e

    def feedback_frames(self):
        """The two C610 feedback frames (0x201, 0x202) of the present state."""
        from cdam_core.record.can.codec import COUNTS_PER_REV, GEAR_RATIO, encode_feedback
        frames = []
        for j in range(2):
            rotor = self.q[j] * GEAR_RATIO / (2 * math.pi) * COUNTS_PER_REV
            angle = int(math.floor(rotor)) % COUNTS_PER_REV
            rpm = int(round(self.w[j] * GEAR_RATIO * 60 / (2 * math.pi)))
            frames.append(encode_feedback(j + 1, angle, rpm, int(self.counts[j])))
        return frames


def default_reference(t: float) -> tuple[float, float]:
    """Joint references (rad): 0.5 rad from 0.01 s and -0.3 rad from 0.05 s (steps; the PIL
    loop sends a 0x300 frame only when the reference changes, which saves 22 bytes a cycle on
    the emulated UART)."""
    return (0.5 if t >= 0.01 else 0.0), (-0.3 if t >= 0.05 else 0.0)


def _reference_frame(r):
    import can
    return can.Message(arbitration_id=REFERENCE_ID, is_extended_id=False,
                       data=struct.pack("<2f", float(r[0]), float(r[1])))


def closed_loop_python(duration: float = 2.0, reference=default_reference,
                       plant: JointPlant | None = None, model=None) -> dict:
    """The loop of fw/controller.hpp in plain Python (float64) on the same plant and frames.

    Returns t, r (N, 2), q (N, 2) plant angles before each step, u (N, 2) current counts and,
    with ``model``, y0 (N,) the model's first output on the features.
    """
    from cdam_core.record.can.codec import (MotorState, decode_current_command, decode_feedback,
                                     encode_current_command)
    cfg = pid_config()
    dt, n = cfg["kDt"], int(round(float(duration) / cfg["kDt"]))
    if n < 1:
        raise ValueError(f"duration: must be at least one period, got {duration}")
    plant = plant or JointPlant()
    fm = None if model is None else (model if isinstance(model, FirmwareModel)
                                     else load_firmware_model(model))
    motors, integ = [MotorState(), MotorState()], np.zeros(2)
    out = {k: [] for k in ("t", "r", "q", "u", "y0")}
    for k in range(n):
        t = k * dt
        r = np.asarray(reference(t), dtype=float)
        feats = []
        for j, msg in enumerate(plant.feedback_frames()):
            fb = decode_feedback(msg)
            th, om, amps, _ = motors[j].update(fb.angle, fb.speed_rpm, fb.current, t=t)
            feats += [th, om, amps]
        f = np.asarray(feats)
        e = r - f[[0, 3]]
        integ = np.clip(integ + e * dt, -cfg["kIntegralLimit"], cfg["kIntegralLimit"])
        u = np.clip(cfg["kKp"] * e + cfg["kKi"] * integ - cfg["kKd"] * f[[1, 4]],
                    -cfg["kCurrentLimitA"], cfg["kCurrentLimitA"])
        counts = np.clip(np.round(u * 1000), -10000, 10000).astype(int)
        cmd = decode_current_command(encode_current_command(counts[:2] * 1e-3))
        out["t"].append(t)
        out["r"].append(r)
        out["q"].append(plant.q.copy())
        out["u"].append(counts)
        if fm is not None:
            x = np.resize(f, fm.n_inputs)
            out["y0"].append(float(fm.predict(x[None, :])[0, 0]))
        plant.step([round(cmd[1] * 1000), round(cmd[2] * 1000)], dt)
    return {k: np.asarray(v) for k, v in out.items()}


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _set_nodelay(bus) -> None:
    """TCP_NODELAY on python-can's slcan socket (pyserial's ``socket://`` keeps it in
    ``_socket``); without it every frame written waits for the previous one's delayed ACK."""
    import socket
    sock = getattr(getattr(bus, "serialPortOrig", None), "_socket", None)
    if sock is not None:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


@contextmanager
def slcan_board(elf, timeout: float):
    """QEMU running ``elf`` (an SLCAN image: fw_loop, fw_monitor_pil) with its USART1 on a
    local TCP port, and python-can's ``slcan`` bus opened on it; QEMU ends with the block.

    Both ends of the TCP link run with TCP_NODELAY (QEMU's ``nodelay=on`` and the client
    socket): with Nagle's algorithm each of the many small writes of a cycle waited for a
    delayed ACK, about 40 ms a write. ``timeout``: seconds of wall time for QEMU.
    """
    import time

    import can
    elf = Path(elf).resolve()
    if not elf.is_file():
        raise FileNotFoundError(f"build_dir: no {elf.name} in {elf.parent}")
    port = _free_port()
    proc = subprocess.Popen(
        ["timeout", "--kill-after=5", str(float(timeout)), QEMU, "-M", "netduinoplus2",
         "-display", "none", "-monitor", "none",
         "-serial", f"tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on", "-kernel", str(elf)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    bus = None
    try:
        deadline = time.monotonic() + 10
        while True:
            try:
                bus = can.Bus(interface="slcan", channel=f"socket://127.0.0.1:{port}",
                              bitrate=1000000, sleep_after_open=0)
                break
            except Exception:
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise
                time.sleep(0.05)
        _set_nodelay(bus)
        # The emulated USART drops bytes that arrive before the firmware enables it, so the
        # open sequence python-can sent may be lost: wait for an answer to "V", then open.
        while bus.get_version(0.5)[0] is None:
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError("the firmware does not answer on the SLCAN port")
        bus.open()
        yield bus
    finally:
        if bus is not None:
            bus.shutdown()
        if proc.poll() is None:
            proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()


def closed_loop_pil(build_dir, duration: float = 2.0, reference=default_reference,
                    plant: JointPlant | None = None, *, timeout: float | None = None) -> dict:
    """Check (4): fw_loop.elf under QEMU, the plant in Python, python-can over SLCAN on the
    emulated USART1 (``-serial tcp:127.0.0.1:PORT,server=on,wait=on``).

    ``timeout`` (seconds of wall time for QEMU) defaults to 60 + 0.1 s per cycle.
    With TCP_NODELAY (:func:`slcan_board`) a cycle takes about 5 ms of wall time instead of
    about 0.1 s.
    Lock-step: each period sends the reference (0x300) and both feedback frames, waits for the
    0x200 command and the 0x3F0 diagnostic, then advances the plant one period. Returns the
    same arrays as closed_loop_python plus frames_sent, frames_received, cycles (the
    firmware's counter) and rejected (frames the firmware refused).
    """
    from cdam_core.record.can.codec import decode_current_command
    cfg = pid_config()
    dt, n = cfg["kDt"], int(round(float(duration) / cfg["kDt"]))
    if n < 1:
        raise ValueError(f"duration: must be at least one period, got {duration}")
    plant = plant or JointPlant()
    if timeout is None:  # about 5 ms of wall time per cycle with TCP_NODELAY
        timeout = 60.0 + 0.1 * n
    out = {k: [] for k in ("t", "r", "q", "u", "y0")}
    sent = received = 0
    cycles = rejected = 0
    last_ref = None
    with slcan_board(Path(build_dir) / "fw_loop.elf", timeout) as bus:
        for k in range(n):
            t = k * dt
            r = np.asarray(reference(t), dtype=float)
            q_before = plant.q.copy()
            changed = last_ref is None or not np.array_equal(r, last_ref)
            last_ref = r
            for msg in ([_reference_frame(r)] if changed else []) + plant.feedback_frames():
                bus.send(msg)
                sent += 1
            cmd = diag = None
            while cmd is None or diag is None:
                msg = bus.recv(timeout=5.0)
                if msg is None:
                    raise RuntimeError(f"no answer from the firmware at cycle {k}")
                received += 1
                if msg.arbitration_id == 0x200:
                    cmd = decode_current_command(msg)
                elif msg.arbitration_id == DIAGNOSTIC_ID:
                    diag = bytes(msg.data)
            y0, cyc, rej = struct.unpack("<fHH", diag)
            if cyc != (k + 1) & 0xFFFF:
                raise RuntimeError(f"cycle counter {cyc} at step {k}: a frame was lost")
            cycles, rejected = k + 1, rej
            counts = [int(round(cmd[1] * 1000)), int(round(cmd[2] * 1000))]
            out["t"].append(t)
            out["r"].append(r)
            out["q"].append(q_before)
            out["u"].append(counts)
            out["y0"].append(y0)
            plant.step(counts, dt)
    res = {k: np.asarray(v) for k, v in out.items()}
    res.update(frames_sent=sent, frames_received=received, cycles=cycles, rejected=rejected)
    return res
