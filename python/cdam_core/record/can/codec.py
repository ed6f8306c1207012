"""C610/M2006 (DJI RoboMaster) CAN codec, from the shipped DBC ``cdam_core/data/c610.dbc``.

Protocol (ALGORITHMS.md, section C610): 1 Mbit/s, standard 11-bit ids.
- Command 0x200 (motors 1-4) and 0x1FF (motors 5-8): four big-endian int16 currents,
  -10000..10000 counts = -10..10 A (1 mA per count).
- Feedback 0x200 + id (0x201..0x208), 1 kHz: bytes 0-1 rotor angle 0..8191 (one rotor turn,
  big-endian unsigned), 2-3 rotor speed in rpm (int16), 4-5 torque current (int16, same scale
  as the command), 6-7 unused on the C610.
- M2006 P36 gearbox 36:1.

Torque: ``tau = kt * I`` at the output shaft with ``kt`` a parameter, default
``DEFAULT_KT_OUTPUT = 0.18`` N m/A. Source: the torque constant DJI lists for the M2006 P36
(0.18 N m/A, referred to the gearbox output), inside the 0.18-0.2 N m/A that ALGORITHMS.md reads
off the C610 manual's M2006 performance curve. Gearbox losses and friction are not included: it
is the motor's electromagnetic torque referred to the output, not a measured joint torque.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from typing import NamedTuple, Sequence

import can
import cantools

__all__ = [
    "COUNTS_PER_REV", "GEAR_RATIO", "AMPS_PER_COUNT", "CURRENT_LIMIT_COUNTS", "SPEED_LIMIT_RPM",
    "DEFAULT_KT_OUTPUT", "COMMAND_IDS", "FEEDBACK_IDS", "MalformedFrame", "Feedback",
    "load_dbc", "encode_current_command", "decode_current_command", "encode_feedback",
    "decode_feedback", "MotorState",
]

COUNTS_PER_REV = 8192          # rotor angle counts per rotor turn
GEAR_RATIO = 36.0              # M2006 P36: rotor turns per output turn
AMPS_PER_COUNT = 0.001         # 10000 counts = 10 A
CURRENT_LIMIT_COUNTS = 10000   # C610 command and feedback range
SPEED_LIMIT_RPM = 20000        # rotor; M2006 P36 no-load 500 rpm output = 18000 rpm rotor
DEFAULT_KT_OUTPUT = 0.18       # N m/A at the output shaft (see module docstring)
COMMAND_IDS = {0x200: 1, 0x1FF: 5}          # id -> first motor of the frame
FEEDBACK_IDS = range(0x201, 0x209)


class MalformedFrame(ValueError):
    """A frame that cannot be decoded as C610 traffic; ``kind`` names the reason.

    Kinds: ``wrong_dlc``, ``unknown_id``, ``out_of_range``, ``error_frame``, ``remote_frame``.
    """

    def __init__(self, kind: str, message: str):
        super().__init__(f"{kind}: {message}")
        self.kind = kind


class Feedback(NamedTuple):
    """Raw feedback of one C610 (counts, as on the wire)."""

    motor_id: int           # 1..8
    angle: int              # rotor angle 0..8191
    speed_rpm: int          # rotor speed
    current: int            # torque current counts (1 mA)
    reserved: int           # bytes 6-7 (0 on the C610; the C620 puts the temperature in byte 6)


@lru_cache(maxsize=1)
def load_dbc() -> cantools.database.can.Database:
    """The shipped C610/M2006 DBC, parsed with cantools (cached)."""
    text = resources.files("cdam_core").joinpath("data", "c610.dbc").read_text(encoding="utf-8")
    return cantools.database.load_string(text, database_format="dbc")


def encode_current_command(currents_a: Sequence[float], bank: int = 1) -> can.Message:
    """Current command frame for four motors.

    Args:
        currents_a: 1 to 4 currents in amperes (missing ones are 0), each within -10..10 A.
        bank: 1 for motors 1-4 (id 0x200), 2 for motors 5-8 (id 0x1FF).
    """
    if bank not in (1, 2):
        raise ValueError(f"bank: expected 1 (motors 1-4) or 2 (motors 5-8), got {bank!r}")
    vals = [float(c) for c in currents_a]
    if not 1 <= len(vals) <= 4:
        raise ValueError(f"currents_a: expected 1 to 4 currents, got {len(vals)}")
    limit = CURRENT_LIMIT_COUNTS * AMPS_PER_COUNT
    for k, v in enumerate(vals):
        if not math.isfinite(v):
            raise ValueError(f"currents_a: element {k} is NaN or Inf")
        if abs(v) > limit:
            raise ValueError(f"currents_a: element {k} = {v} A outside -{limit}..{limit} A")
    vals += [0.0] * (4 - len(vals))
    first = 1 if bank == 1 else 5
    msg_def = load_dbc().get_message_by_frame_id(0x200 if bank == 1 else 0x1FF)
    data = msg_def.encode({f"current_{first + k}": vals[k] for k in range(4)})
    return can.Message(arbitration_id=msg_def.frame_id, data=data, is_extended_id=False)


def decode_current_command(msg: can.Message) -> dict[int, float]:
    """Motor id -> commanded current (A) of a 0x200/0x1FF frame."""
    if msg.arbitration_id not in COMMAND_IDS or msg.is_extended_id:
        raise MalformedFrame("unknown_id", f"0x{msg.arbitration_id:X} is not a C610 command")
    if msg.dlc != 8 or len(msg.data) != 8:
        raise MalformedFrame("wrong_dlc", f"command 0x{msg.arbitration_id:X} has DLC {msg.dlc}")
    raw = load_dbc().get_message_by_frame_id(msg.arbitration_id).decode(
        bytes(msg.data), scaling=False)
    first = COMMAND_IDS[msg.arbitration_id]
    return {first + k: raw[f"current_{first + k}"] * AMPS_PER_COUNT for k in range(4)}


def encode_feedback(motor_id: int, angle: int, speed_rpm: int, current: int,
                    timestamp: float = 0.0) -> can.Message:
    """A feedback frame as a C610 sends it (for simulators and tests); raw counts in."""
    if motor_id not in range(1, 9):
        raise ValueError(f"motor_id: expected 1..8, got {motor_id!r}")
    msg_def = load_dbc().get_message_by_frame_id(0x200 + motor_id)
    data = msg_def.encode({"angle": int(angle), "speed": int(speed_rpm),
                           "current": int(current) * AMPS_PER_COUNT, "reserved": 0})
    return can.Message(timestamp=timestamp, arbitration_id=0x200 + motor_id, data=data,
                       is_extended_id=False)


def decode_feedback(msg: can.Message) -> Feedback:
    """Decode a 0x201..0x208 feedback frame; MalformedFrame (a ValueError) if it is not one."""
    if msg.is_error_frame:
        raise MalformedFrame("error_frame", "CAN error frame")
    if msg.is_remote_frame:
        raise MalformedFrame("remote_frame", f"remote frame 0x{msg.arbitration_id:X}")
    if msg.is_extended_id or msg.arbitration_id not in FEEDBACK_IDS:
        raise MalformedFrame("unknown_id", f"0x{msg.arbitration_id:X} is not a C610 feedback id")
    if msg.dlc != 8 or len(msg.data) != 8:
        raise MalformedFrame("wrong_dlc", f"0x{msg.arbitration_id:X} has DLC {len(msg.data)}, "
                                          "expected 8")
    raw = load_dbc().get_message_by_frame_id(msg.arbitration_id).decode(
        bytes(msg.data), scaling=False)
    fb = Feedback(msg.arbitration_id - 0x200, raw["angle"], raw["speed"], raw["current"],
                  raw["reserved"])
    if fb.angle >= COUNTS_PER_REV:
        raise MalformedFrame("out_of_range", f"motor {fb.motor_id}: angle {fb.angle} > 8191")
    if abs(fb.speed_rpm) > SPEED_LIMIT_RPM:
        raise MalformedFrame("out_of_range", f"motor {fb.motor_id}: speed {fb.speed_rpm} rpm")
    if abs(fb.current) > CURRENT_LIMIT_COUNTS:
        raise MalformedFrame("out_of_range", f"motor {fb.motor_id}: current {fb.current} counts")
    return fb


@dataclass
class MotorState:
    """Multi-turn state of one M2006 built from successive feedback frames.

    The rotor angle (0..8191 per rotor turn) is unwrapped into a multi-turn count. The wrap is
    chosen so that the angle step best matches the step predicted from the reported speeds
    (mean of the two frames' rpm over the time between them); with no time step it is the
    nearest wrap. At 1 kHz and the M2006's 18000 rpm no-load rotor speed the rotor turns 0.3 of
    a turn between frames, so either rule is unambiguous; the speed rule also survives lost
    frames. The output angle is known up to the rotor's position at the first frame: it starts
    in [0, 2 pi / 36) and is relative to the gearbox's unknown initial turn -- zero it at a
    known pose.

    Args:
        kt: torque constant at the output shaft, N m/A (default DEFAULT_KT_OUTPUT).
        gear_ratio: rotor turns per output turn (36 for the M2006 P36).
    """

    kt: float = DEFAULT_KT_OUTPUT
    gear_ratio: float = GEAR_RATIO
    turns_counts: int | None = field(default=None, init=False)   # unwrapped rotor counts
    _last_angle: int = field(default=0, init=False, repr=False)
    _last_rpm: float = field(default=0.0, init=False, repr=False)
    _last_t: float | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        if not (math.isfinite(self.kt) and math.isfinite(self.gear_ratio) and self.gear_ratio > 0):
            raise ValueError("kt, gear_ratio: expected finite numbers, gear_ratio > 0")

    def update(self, angle: int, speed_rpm: float, current: int,
               t: float | None = None) -> tuple[float, float, float, float]:
        """Feed one frame; returns (theta_out rad, omega_out rad/s, current A, tau N m)."""
        if not 0 <= angle < COUNTS_PER_REV:
            raise ValueError(f"angle: expected 0..8191, got {angle}")
        if self.turns_counts is None:
            self.turns_counts = int(angle)
        else:
            step = int(angle) - self._last_angle
            predicted = 0.0
            if t is not None and self._last_t is not None:
                dt = t - self._last_t
                predicted = 0.5 * (speed_rpm + self._last_rpm) / 60.0 * dt * COUNTS_PER_REV
            step += COUNTS_PER_REV * round((predicted - step) / COUNTS_PER_REV)
            self.turns_counts += step
        self._last_angle, self._last_rpm, self._last_t = int(angle), float(speed_rpm), t
        theta = 2.0 * math.pi * self.turns_counts / COUNTS_PER_REV / self.gear_ratio
        omega = speed_rpm * 2.0 * math.pi / 60.0 / self.gear_ratio
        amps = current * AMPS_PER_COUNT
        return theta, omega, amps, self.kt * amps
