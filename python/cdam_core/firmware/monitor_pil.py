"""Processor in the loop for the residual monitor: fw_monitor_pil.elf (fw/monitor_pil.hpp) under
QEMU runs the model beside the measurements, which python-can sends over SLCAN on the emulated
USART1, one row [u, y] of float32 per sample in frames 0x310 + j; the firmware answers each row
with the alarm frames (0x3F2, :mod:`cdam_core.firmware.alarm`) of the outputs that alarmed and
acks (0x3F3: after a history, rejected or alarmed row, after every 8th row, and on request).

Flow control: at most :func:`rows_in_flight` rows are unacknowledged, so the bytes in flight
never exceed the image's 1 KiB USART receive ring (src/hal_stm32.cpp, its size set in
CMakeLists.txt) and no byte is dropped; when the rows in flight fill it, the host asks for an
ack. The emulated link is lock-step, not real time: a sample takes the wall time of its
round trip (measured in the report's ``wall_s``); on the board the rows would come at 1 kHz.
"""
from __future__ import annotations

import re
import struct
import time
from pathlib import Path

import numpy as np

from cdam_core.firmware.alarm import ALARM_ID, decode_alarm
from cdam_core.firmware.model import StepFirmwareModel, load_firmware_model
from cdam_core.firmware.paths import FIRMWARE_DIR
from cdam_core.firmware.pil import slcan_board
from cdam_core.firmware.qemu import step_record

__all__ = ["ROW_ID", "ACK_ID", "rows_in_flight", "row_frames", "monitor_pil"]

ROW_ID, ACK_ID = 0x310, 0x3F3
LINE_BYTES = 22           # an SLCAN line of a standard 8-byte frame: 't' + 3 + 1 + 16 + '\r'
REQUEST_BYTES = 8         # room for the host's ack request (r3F38 and a CR: 6 bytes)
MAX_ROW_FRAMES = 32       # fw/monitor_pil.hpp kMaxRowFrames
ROW_HISTORY, ROW_MONITORED, ROW_REJECTED = 0, 1, 2   # the ack's status byte
_ACK = struct.Struct("<IBBH")


def ring_bytes() -> int:
    """The receive ring of fw_monitor_pil (CDAM_FW_UART_RING in firmware_stubs/CMakeLists.txt)."""
    text = (FIRMWARE_DIR / "CMakeLists.txt").read_text()
    found = re.search(r"fw_monitor_pil\.elf PRIVATE CDAM_FW_UART_RING=(\d+)", text)
    if not found:
        raise RuntimeError("CMakeLists.txt: no CDAM_FW_UART_RING for fw_monitor_pil")
    return int(found.group(1))


def _frames_per_row(values: int) -> int:
    return (int(values) + 1) // 2


def rows_in_flight(values: int) -> int:
    """Rows of ``values`` float32 that fit the firmware's receive ring at once (at least 1)."""
    return max(1, (ring_bytes() - REQUEST_BYTES) // (LINE_BYTES * _frames_per_row(values)))


def row_frames(u, y) -> list:
    """The CAN frames (python-can messages) of one row: [u, y] as float32 pairs in 0x310 + j."""
    import can
    v = np.concatenate([np.asarray(u, np.float32).ravel(), np.asarray(y, np.float32).ravel()])
    if v.size % 2:
        v = np.r_[v, np.float32(0)]
    return [can.Message(arbitration_id=ROW_ID + j, is_extended_id=False,
                        data=v[2 * j:2 * j + 2].astype("<f4").tobytes())
            for j in range(v.size // 2)]


def _ack_request():
    import can
    return can.Message(arbitration_id=ACK_ID, is_extended_id=False, is_remote_frame=True, dlc=8)


def monitor_pil(build_dir, model, U, Y, *, timeout: float | None = None) -> dict:
    """Run the record (U (N, I), Y (N, m), rounded to float32) through fw_monitor_pil.elf of
    ``build_dir`` (built for ``model``, a model file with a monitor section) over SLCAN.

    Returns ``flags`` (N, m) uint8, the firmware's decisions per row and output (0 on the first
    t0 rows, the history), ``alarms`` [(row, output, flags)], ``alarm_frames`` [(output, flags,
    count, sample)] as received, ``status`` (N,) per row (the acks name every row that is not
    a plain monitored one), ``ignored`` (frames
    the firmware ignored), ``rows``, ``in_flight`` and ``wall_s`` (wall time of the rows).
    Raises ValueError for a bad model or record, RuntimeError when the firmware does not
    answer or an ack is out of order.
    """
    fm = model if isinstance(model, StepFirmwareModel) else load_firmware_model(model)
    if not isinstance(fm, StepFirmwareModel) or fm.monitor is None:
        raise ValueError("model: the monitor in the loop needs a model file with a 'monitor' "
                         "section (cdam monitor MODEL TRAIN --calibrate OUT)")
    U, Y = step_record(fm, U, Y)
    if _frames_per_row(fm.n_inputs + fm.n_outputs) > MAX_ROW_FRAMES:
        raise ValueError(f"model: a row of {fm.n_inputs + fm.n_outputs} values does not fit "
                         f"{MAX_ROW_FRAMES} frames")
    n, m = Y.shape
    window = rows_in_flight(fm.n_inputs + fm.n_outputs)
    if timeout is None:   # generous: measured about 2-5 ms of wall time a row
        timeout = 60.0 + 0.05 * n
    U32, Y32 = U.astype(np.float32), Y.astype(np.float32)
    flags = np.zeros((n, m), np.uint8)
    status = np.full(n, ROW_MONITORED, np.uint8)   # rows between two acks: monitored, no alarm
    frames, alarms = [], []
    ignored = 0
    with slcan_board(Path(build_dir) / "fw_monitor_pil.elf", timeout) as bus:
        t_start = time.monotonic()
        sent = acked = 0
        pending = 0                       # alarm frames since the last ack
        asked = -1                        # rows sent when an ack was last asked for
        while acked < n:
            while sent < n and sent - acked < window:
                for msg in row_frames(U32[sent], Y32[sent]):
                    bus.send(msg)
                sent += 1
            if (sent == n or sent - acked >= window) and asked != sent:
                bus.send(_ack_request())  # the rows in flight may fall between two acks
                asked = sent
            msg = bus.recv(timeout=5.0)
            if msg is None:
                raise RuntimeError(f"no answer from the firmware after row {acked}")
            if msg.arbitration_id == ALARM_ID:
                c, f, count, sample = decode_alarm(msg.data)
                last = alarms[-1][0] if alarms else -1
                if not acked <= sample < sent or sample < last or c >= m:
                    raise RuntimeError(f"alarm frame for row {sample}, output {c}: rows {acked}.."
                                       f"{sent - 1} are in flight")
                flags[sample, c] = f
                frames.append((c, f, count, sample))
                alarms.append((sample, c, f))
                pending += 1
            elif msg.arbitration_id == ACK_ID:
                rows, st, n_alarm, ignored = _ACK.unpack(bytes(msg.data))
                if rows == acked and n_alarm == 0:   # asked for after an ack: nothing new
                    continue
                if not acked < rows <= sent or n_alarm != pending:
                    raise RuntimeError(f"ack of {rows} rows ({n_alarm} alarm frame(s)) after "
                                       f"{acked} ({pending}), {sent} sent: a frame was lost")
                status[rows - 1] = st
                acked = rows
                pending = 0
        wall = time.monotonic() - t_start
    return {"flags": flags, "alarms": alarms, "alarm_frames": frames, "status": status,
            "ignored": int(ignored), "rows": n, "in_flight": window, "wall_s": round(wall, 3),
            "wall_ms_per_row": round(1e3 * wall / n, 3)}
