"""A python-can Listener that decodes C610 feedback into a growing per-motor record."""
from __future__ import annotations

import threading
from collections import Counter

import can
import numpy as np

from cdam_core.record.can.codec import (COMMAND_IDS, DEFAULT_KT_OUTPUT, GEAR_RATIO, MalformedFrame,
                                 MotorState, decode_current_command, decode_feedback)
from cdam_core.record.dataset import Dataset
from cdam_core.record.resample import find_gaps, resample_signals

__all__ = ["C610Recorder", "MALFORMED_KINDS"]

MALFORMED_KINDS = ("wrong_dlc", "unknown_id", "out_of_range", "error_frame", "remote_frame",
                   "non_increasing_time", "decode_error")
_FIELDS = ("t", "theta", "omega", "current", "tau")


class C610Recorder(can.Listener):
    """Decode C610/M2006 feedback frames into a record, counting every frame it cannot use.

    Per motor id (1..8) it keeps ``t`` (frame timestamp, s), ``theta`` (unwrapped output-shaft
    angle, rad), ``omega`` (output speed, rad/s), ``current`` (A) and ``tau`` (N m, ``kt`` times
    current). Command frames (0x200, 0x1FF) are recorded as commanded currents. Every other frame
    is counted in ``counts`` under its kind (see MALFORMED_KINDS) and never raises: a listener
    that raised would stop python-can's Notifier.

    Args:
        joints: motor id -> joint suffix used by ``to_dataset`` (default {1: "m1", 2: "m2"}).
        kt: torque constant at the output shaft, N m/A.
        gear_ratio: rotor turns per output turn.
    """

    def __init__(self, joints: dict[int, str] | None = None, kt: float = DEFAULT_KT_OUTPUT,
                 gear_ratio: float = GEAR_RATIO):
        self.joints = dict(joints if joints is not None else {1: "m1", 2: "m2"})
        for mid in self.joints:
            if mid not in range(1, 9):
                raise ValueError(f"joints: motor id {mid!r} outside 1..8")
        self.kt, self.gear_ratio = float(kt), float(gear_ratio)
        MotorState(kt=self.kt, gear_ratio=self.gear_ratio)  # validates
        self.counts: Counter = Counter()
        self._states: dict[int, MotorState] = {}
        self._rec: dict[int, dict[str, list]] = {}
        self._cmd: dict[int, list] = {}
        self._lock = threading.Lock()

    # -- python-can Listener ---------------------------------------------------------------
    def on_message_received(self, msg: can.Message) -> None:
        try:
            with self._lock:
                self._handle(msg)
        except MalformedFrame as exc:
            self.counts[exc.kind] += 1
        except Exception:  # never let a bad frame stop the Notifier; count it instead
            self.counts["decode_error"] += 1

    def on_error(self, exc: Exception) -> None:
        self.counts["bus_error"] += 1

    def stop(self) -> None:
        pass

    def _handle(self, msg: can.Message) -> None:
        if (not msg.is_extended_id and not msg.is_error_frame and not msg.is_remote_frame
                and msg.arbitration_id in COMMAND_IDS):
            for mid, amps in decode_current_command(msg).items():
                self._cmd.setdefault(mid, []).append((msg.timestamp, amps))
            self.counts["command"] += 1
            return
        fb = decode_feedback(msg)
        rec = self._rec.setdefault(fb.motor_id, {k: [] for k in _FIELDS})
        if rec["t"] and msg.timestamp <= rec["t"][-1]:
            raise MalformedFrame("non_increasing_time", f"motor {fb.motor_id}")
        state = self._states.setdefault(fb.motor_id, MotorState(self.kt, self.gear_ratio))
        theta, omega, amps, tau = state.update(fb.angle, fb.speed_rpm, fb.current, msg.timestamp)
        for k, v in zip(_FIELDS, (msg.timestamp, theta, omega, amps, tau)):
            rec[k].append(v)
        self.counts["feedback"] += 1

    # -- results ----------------------------------------------------------------------------
    @property
    def malformed(self) -> dict[str, int]:
        """Counts of frames not used, by kind (zeros included, so a report lists every kind)."""
        return {k: int(self.counts.get(k, 0)) for k in MALFORMED_KINDS}

    def motors(self) -> list[int]:
        """Motor ids seen in feedback."""
        with self._lock:
            return sorted(self._rec)

    def motor_record(self, motor_id: int) -> dict[str, np.ndarray]:
        """The raw decoded record of one motor: arrays ``t, theta, omega, current, tau``."""
        with self._lock:
            if motor_id not in self._rec:
                raise ValueError(f"motor_id: no feedback from motor {motor_id}")
            return {k: np.asarray(v, dtype=np.float64) for k, v in self._rec[motor_id].items()}

    def commands(self, motor_id: int) -> tuple[np.ndarray, np.ndarray]:
        """(t, commanded current A) of one motor."""
        with self._lock:
            arr = np.asarray(self._cmd.get(motor_id, []), dtype=np.float64).reshape(-1, 2)
        return arr[:, 0], arr[:, 1]

    def to_dataset(self, rate: float = 1000.0, gap_threshold: float = 0.01) -> Dataset:
        """The mapped joints resampled onto one grid at ``rate`` Hz, in the dataset format.

        Columns per joint J: ``theta_J`` (output-shaft angle, rad), ``omega_J`` (rad/s),
        ``i_J`` (A) and ``tau_J`` (N m); all linear interpolation. ``t`` is seconds from the
        first grid point; the absolute start (frame timestamps' clock) is ``meta["t0"]``.
        Feedback gaps longer than ``gap_threshold`` seconds are listed in ``meta["gaps"]``.
        """
        signals, gaps = {}, {}
        missing = [f"motor {m} ({j})" for m, j in self.joints.items()
                   if len(self._rec.get(m, {"t": []})["t"]) < 2]
        if missing:
            raise ValueError(f"record: fewer than 2 feedback frames from {', '.join(missing)} "
                             f"(frames counted: {dict(self.counts)})")
        for mid, name in self.joints.items():
            r = self.motor_record(mid)
            for field, col in (("theta", "theta"), ("omega", "omega"), ("current", "i"),
                               ("tau", "tau")):
                signals[f"{col}_{name}"] = (r["t"], r[field], "linear")
            gaps[name] = find_gaps(r["t"], gap_threshold)
        grid, out = resample_signals(signals, rate)
        order = sorted(signals, key=lambda c: (c.split("_")[0] != "theta", c))
        t0 = float(grid[0])
        meta = {
            "rate": float(rate),
            "source": "C610/M2006 CAN feedback (cdam_core.record.can.C610Recorder)",
            "t0": t0,
            "units": {**{c: u for c in order for p, u in (("theta", "rad"), ("omega", "rad/s"),
                                                          ("i", "A"), ("tau", "N m"))
                         if c.startswith(p + "_")}},
            "kt_output_N_m_per_A": self.kt,
            "gear_ratio": self.gear_ratio,
            "joints": {str(k): v for k, v in self.joints.items()},
            "frames": dict(self.counts),
            "malformed": self.malformed,
            "gaps": {k: [{**g, "start": g["start"] - t0, "end": g["end"] - t0} for g in v]
                     for k, v in gaps.items()},
            "interpolation": {c: "linear" for c in order},
            "inputs": [c for c in order if c.startswith("tau_")],
            "outputs": [c for c in order if c.startswith("theta_")],
        }
        return Dataset(t=grid - t0, columns=order, data=np.column_stack([out[c] for c in order]),
                       meta=meta)
