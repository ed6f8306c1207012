"""The residual monitor's alarm frame on the CAN bus (fw/monitor.hpp): id 0x3F2, standard, 8
bytes little-endian: output index (uint8), flags (uint8: bit 0 CUSUM up, bit 1 CUSUM down,
bit 2 EWMA), alarms so far (uint16, saturating), sample counter (uint32). 0x3F2 is free: the
C610 uses 0x1FF, 0x200 and 0x201..0x208, the loop 0x300, 0x3F0 and 0x3F1."""
from __future__ import annotations

import struct

ALARM_ID = 0x3F2
_LAYOUT = struct.Struct("<BBHI")

__all__ = ["ALARM_ID", "decode_alarm", "decode_alarm_frames"]


def decode_alarm(data: bytes) -> tuple[int, int, int, int]:
    """(output, flags, count, sample) of an alarm frame's 8 data bytes."""
    data = bytes(data)
    if len(data) != 8:
        raise ValueError(f"data: an alarm frame has 8 bytes, got {len(data)}")
    return _LAYOUT.unpack(data)


def decode_alarm_frames(raw: bytes) -> list[tuple[int, int, int, int, int]]:
    """(id, output, flags, count, sample) of each 12-byte record (uint32 id, 8 data bytes)
    the step-check image writes."""
    if len(raw) % 12:
        raise ValueError(f"raw: {len(raw)} bytes is not a whole number of 12-byte frames")
    out = []
    for k in range(0, len(raw), 12):
        (fid,) = struct.unpack_from("<I", raw, k)
        out.append((fid, *decode_alarm(raw[k + 4:k + 12])))
    return out
