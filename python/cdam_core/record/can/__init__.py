"""The arm's CAN bus: C610/M2006 codec (DBC + cantools), a python-can recorder, log files."""
from cdam_core.record.can.codec import (AMPS_PER_COUNT, COUNTS_PER_REV, DEFAULT_KT_OUTPUT, GEAR_RATIO,
                                 Feedback, MalformedFrame, MotorState, decode_current_command,
                                 decode_feedback, encode_current_command, encode_feedback,
                                 load_dbc)
from cdam_core.record.can.listener import MALFORMED_KINDS, C610Recorder
from cdam_core.record.can.logfiles import iter_log, log_bus, open_bus

__all__ = [
    "AMPS_PER_COUNT", "COUNTS_PER_REV", "DEFAULT_KT_OUTPUT", "GEAR_RATIO", "Feedback",
    "MalformedFrame", "MotorState", "decode_current_command", "decode_feedback",
    "encode_current_command", "encode_feedback", "load_dbc", "MALFORMED_KINDS", "C610Recorder",
    "iter_log", "log_bus", "open_bus",
]
