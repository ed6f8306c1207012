"""A python-can Listener that decodes C610 feedback into a growing per-motor record."""
from __future__ import annotations

import bisect
import threading
from collections import Counter

import can
import numpy as np

from cdam_core.record.can.codec import (COMMAND_IDS, DEFAULT_KT_OUTPUT, GEAR_RATIO, MalformedFrame,
                                 MotorState, decode_current_command, decode_feedback)
from cdam_core.record.dataset import Dataset
from cdam_core.record.resample import find_gaps, resample, segmented_grid

__all__ = ["C610Recorder", "MALFORMED_KINDS"]

MALFORMED_KINDS = ("wrong_dlc", "unknown_id", "out_of_range", "error_frame", "remote_frame",
                   "non_finite_time", "non_increasing_time", "decode_error")
_FIELDS = ("t", "theta", "omega", "current", "tau")
_RAW = ("t", "angle", "rpm", "current")


def increasing_subset(t: np.ndarray) -> np.ndarray:
    """Boolean mask of the largest set of samples whose times strictly increase in arrival
    order (longest increasing subsequence, O(n log n)). One frame stamped far in the future or
    the past is the one left out, not every frame after it."""
    t = np.asarray(t, dtype=np.float64)
    keep = np.ones(t.size, dtype=bool)
    if t.size < 2 or np.all(np.diff(t) > 0):
        return keep
    tails: list[float] = []          # smallest last time of an increasing run of each length
    tail_idx: list[int] = []
    prev = np.full(t.size, -1, dtype=np.int64)
    for i, v in enumerate(t.tolist()):
        k = bisect.bisect_left(tails, v)
        if k == len(tails):
            tails.append(v)
            tail_idx.append(i)
        else:
            tails[k], tail_idx[k] = v, i
        prev[i] = tail_idx[k - 1] if k else -1
    keep[:] = False
    i = tail_idx[-1]
    while i >= 0:
        keep[i] = True
        i = prev[i]
    return keep


class C610Recorder(can.Listener):
    """Decode C610/M2006 feedback frames into a record, counting every frame it cannot use.

    Per motor id (1..8) it keeps ``t`` (frame timestamp, s), ``theta`` (unwrapped output-shaft
    angle, rad), ``omega`` (output speed, rad/s), ``current`` (A) and ``tau`` (N m, ``kt`` times
    current). Command frames (0x200, 0x1FF) are recorded as commanded currents. Every other frame
    is counted in ``counts`` under its kind (see MALFORMED_KINDS) and never raises: a listener
    that raised would stop python-can's Notifier. A frame with a NaN/Inf timestamp is counted as
    ``non_finite_time``. Frames out of time order (a clock glitch, one frame stamped in the
    future) are excluded when the record is read (``increasing_subset``), counted as
    ``non_increasing_time`` and listed by ``excluded_times``; the others are kept.

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
        self._raw: dict[int, dict[str, list]] = {}
        self._cache: dict[int, tuple[int, dict, np.ndarray]] = {}
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
        t = float(msg.timestamp)
        if not np.isfinite(t):
            raise MalformedFrame("non_finite_time", f"motor {fb.motor_id}: timestamp {t}")
        raw = self._raw.setdefault(fb.motor_id, {k: [] for k in _RAW})
        for k, v in zip(_RAW, (t, fb.angle, fb.speed_rpm, fb.current)):
            raw[k].append(v)
        self.counts["feedback"] += 1

    # -- results ----------------------------------------------------------------------------
    @property
    def malformed(self) -> dict[str, int]:
        """Counts of frames not used, by kind (zeros included, so a report lists every kind)."""
        out = {k: int(self.counts.get(k, 0)) for k in MALFORMED_KINDS}
        out["non_increasing_time"] = sum(v.size for v in self.excluded_times().values())
        return out

    def motors(self) -> list[int]:
        """Motor ids seen in feedback."""
        with self._lock:
            return sorted(self._raw)

    def _decoded(self, motor_id: int) -> tuple[dict, np.ndarray]:
        """(decoded record of the frames in time order, timestamps of the excluded ones)."""
        with self._lock:
            if motor_id not in self._raw:
                raise ValueError(f"motor_id: no feedback from motor {motor_id}")
            raw = {k: np.asarray(v, dtype=np.float64) for k, v in self._raw[motor_id].items()}
        n = raw["t"].size
        hit = self._cache.get(motor_id)
        if hit is not None and hit[0] == n:
            return hit[1], hit[2]
        keep = increasing_subset(raw["t"])
        state = MotorState(self.kt, self.gear_ratio)
        rows = [state.update(int(a), s, int(c), t) for t, a, s, c in
                zip(*(raw[k][keep].tolist() for k in _RAW))]
        arr = np.asarray(rows, dtype=np.float64).reshape(-1, 4)
        rec = {"t": raw["t"][keep], "theta": arr[:, 0], "omega": arr[:, 1],
               "current": arr[:, 2], "tau": arr[:, 3]}
        self._cache[motor_id] = (n, rec, raw["t"][~keep])
        return rec, raw["t"][~keep]

    def motor_record(self, motor_id: int) -> dict[str, np.ndarray]:
        """The decoded record of one motor, frames in time order: arrays ``t, theta, omega,
        current, tau`` (out-of-order frames excluded, see ``excluded_times``)."""
        rec, _ = self._decoded(motor_id)
        return {k: v.copy() for k, v in rec.items()}

    def excluded_times(self) -> dict[int, np.ndarray]:
        """Motor id -> timestamps of the feedback frames excluded for breaking time order."""
        return {m: self._decoded(m)[1] for m in self.motors()}

    def commands(self, motor_id: int) -> tuple[np.ndarray, np.ndarray]:
        """(t, commanded current A) of one motor."""
        with self._lock:
            arr = np.asarray(self._cmd.get(motor_id, []), dtype=np.float64).reshape(-1, 2)
        return arr[:, 0], arr[:, 1]

    def to_dataset(self, rate: float = 1000.0, gap_threshold: float = 0.01) -> Dataset:
        """The mapped joints resampled onto one grid at ``rate`` Hz, in the dataset format.

        Columns per joint J: ``theta_J`` (output-shaft angle, rad), ``omega_J`` (rad/s),
        ``i_J`` (A) and ``tau_J`` (N m); linear interpolation between frames at most
        ``gap_threshold`` s apart. A longer feedback gap stays a gap: no grid sample falls in
        it, ``t`` jumps over it (grid times stay on one k / rate lattice) and ``meta`` lists
        the row ranges without a gap (``gapless_rows``, also ``segments``), the gaps per joint (``gaps``) and the grid
        samples left out (``gap_samples``). A frame with a gap on both sides has nothing to
        interpolate with and is excluded (``excluded``, with the out-of-order ones). Across a gap
        the rotor turns are estimated from the speeds at its ends, so ``theta`` of a later
        segment may be off by whole rotor turns (2 pi / gear_ratio rad). ``t`` is seconds from
        the first grid point; the absolute start is ``meta["t0"]``.
        """
        missing = [f"motor {m} ({j})" for m, j in self.joints.items()
                   if m not in self._raw or len(self._raw[m]["t"]) < 2]
        if missing:
            raise ValueError(f"record: fewer than 2 feedback frames from {', '.join(missing)} "
                             f"(frames counted: {dict(self.counts)})")
        recs, gaps, spans, excluded = {}, {}, [], {}
        for mid, name in self.joints.items():
            r, out_of_order = self._decoded(mid)
            runs = _runs(r["t"], gap_threshold)
            isolated = [r["t"][a] for a, b in runs if b - a < 2]
            spans.append([(r["t"][a], r["t"][b - 1]) for a, b in runs if b - a >= 2])
            recs[name] = r
            gaps[name] = find_gaps(r["t"], gap_threshold) if r["t"].size >= 2 else []
            excluded[name] = {"out_of_order": _listed(out_of_order),
                              "isolated": _listed(np.asarray(isolated))}
        common = spans[0]
        for other in spans[1:]:
            common = _intersect(common, other)
        if not common:
            raise ValueError(f"record: no stretch where every joint ({', '.join(recs)}) has "
                             f"feedback without a gap longer than {gap_threshold:g} s")
        grid, rows = segmented_grid(common, rate, origin=common[0][0])
        if not rows:
            raise ValueError(f"record: no stretch of 2 samples at {rate:g} Hz where every joint "
                             "has feedback without a gap")
        t0 = float(grid[0])
        full = int(round((grid[-1] - t0) * rate)) + 1
        out = {}
        for name, r in recs.items():
            for field, col in (("theta", "theta"), ("omega", "omega"), ("current", "i"),
                               ("tau", "tau")):
                out[f"{col}_{name}"] = resample(r["t"], r[field], grid, "linear")
        order = sorted(out, key=lambda c: (c.split("_")[0] != "theta", c))
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
            "gap_threshold": float(gap_threshold),
            "gapless_rows": [list(rw) for rw in rows],
            "gapless_rows_note": "row ranges without a feedback gap; across a gap theta may be off "
                             "by whole rotor turns (2 pi / gear_ratio rad)",
            "gap_samples": full - int(grid.size),
            "excluded": excluded,
            "interpolation": {c: "linear" for c in order},
            "inputs": [c for c in order if c.startswith("tau_")],
            "outputs": [c for c in order if c.startswith("theta_")],
        }
        if len(rows) > 1:                   # no model predicts across a gap
            meta["segments"] = [list(rw) for rw in rows]
        return Dataset(t=grid - t0, columns=order, data=np.column_stack([out[c] for c in order]),
                       meta=meta)


MAX_LISTED_TIMES = 20


def _listed(times: np.ndarray) -> dict:
    """{"count": n, "times": the first MAX_LISTED_TIMES timestamps} (JSON-ready)."""
    return {"count": int(times.size), "times": [float(x) for x in times[:MAX_LISTED_TIMES]]}


def _runs(t: np.ndarray, gap: float) -> list[tuple[int, int]]:
    """(start, end) index ranges of frames with no step longer than ``gap``."""
    cut = np.flatnonzero(np.diff(t) > gap) + 1
    edges = [0, *cut.tolist(), t.size]
    return list(zip(edges[:-1], edges[1:]))


def _intersect(a: list, b: list) -> list:
    """Intersection of two sorted lists of disjoint (start, stop) intervals."""
    out, i, j = [], 0, 0
    while i < len(a) and j < len(b):
        s, e = max(a[i][0], b[j][0]), min(a[i][1], b[j][1])
        if s < e:
            out.append((s, e))
        if a[i][1] < b[j][1]:
            i += 1
        else:
            j += 1
    return out
