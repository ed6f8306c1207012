"""The simulated flights of the paper run and how they become training, test and validation data.

Data design (see :data:`DATA_DESIGN`): experiments (i) and (ii) are simulated as separate
records of ``duration`` seconds (the paper's 20 s at 1 kHz) plus, for each, a separate
validation record of ``duration / 2`` seconds (the paper's 10 s) with its own seed. Each record
is smoothed at 1 kHz (five-point cubic, ``smoothing`` passes), then decimated to ``rate`` Hz with
``scipy.signal.decimate`` (zero-phase FIR anti-aliasing) when ``rate`` < 1000. The first half of
each experiment trains, the last half tests (Table 2), the validation records validate
(Table 3). Training data is (i) then (ii) stacked; test and validation records keep their
segments so that NARX models restart at each segment from its first measured samples.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import decimate

from cdam_core.preprocess import smooth_pair

__all__ = ["DATA_DESIGN", "Segment", "PaperData", "simulate_records", "prepare_data"]

DATA_DESIGN = (
    "Training data: the first half of experiment (i) followed by the first half of experiment "
    "(ii), one 6-input, 8-output network for both. Reason: each experiment excites only part of "
    "the outputs (the operator excites roll, pitch, yaw and altitude in (i) while the arm is "
    "held; the joints move only in (ii)), and the paper identifies one model of all eight "
    "outputs from these two experiments, so the training set must hold both; stacking keeps "
    "each experiment as flown, whereas the simulator's 'both' (everything excited at once) is "
    "a flight the paper did not make. Test: the last halves of (i) and (ii); validation: the "
    "separate validation record of each experiment. Metrics pool the segments of a record; a "
    "NARX model restarts at each segment (one-step and free-run) from its first measured "
    "samples, so no prediction crosses the seam between two experiments.")


@dataclass
class Segment:
    """One contiguous piece of a record: time (s), inputs U (N, 6) and outputs Y (N, 8),
    already smoothed (and decimated)."""

    name: str
    t: np.ndarray
    U: np.ndarray
    Y: np.ndarray


@dataclass
class PaperData:
    """Training arrays and the segmented test and validation records."""

    inputs: list
    outputs: list
    rate: float
    train: list       # [Segment] (stacked for training)
    test: list        # [Segment]
    validation: list  # [Segment]

    def train_arrays(self):
        """(U, Y) of the training segments stacked in order."""
        return (np.vstack([s.U for s in self.train]), np.vstack([s.Y for s in self.train]))


def simulate_records(seed: int = 0, duration: float = 20.0, effects=None) -> dict:
    """Simulate experiments (i) and (ii) (``duration`` s) and their validation records
    (``duration / 2`` s) at 1 kHz; returns {"exp_i", "exp_ii", "val_i", "val_ii"} Datasets."""
    from cdam_core.sim import simulate_flight
    duration = float(duration)
    if not np.isfinite(duration) or duration <= 0:
        raise ValueError(f"duration: must be positive and finite, got {duration}")
    out = {}
    for exp in ("i", "ii"):
        out[f"exp_{exp}"] = simulate_flight(exp, duration=duration, seed=seed, effects=effects)
        out[f"val_{exp}"] = simulate_flight(exp, duration=duration / 2, seed=seed,
                                            effects=effects, validation=True)
    return out


def decimation_factor(source_rate: float, rate: float) -> int:
    """Integer factor q = source_rate / rate; ValueError if ``rate`` does not divide it."""
    rate = float(rate)
    if not np.isfinite(rate) or rate <= 0 or rate > source_rate:
        raise ValueError(f"rate: must be in (0, {source_rate:g}] Hz, got {rate:g}")
    q = source_rate / rate
    if abs(q - round(q)) > 1e-9:
        raise ValueError(f"rate: {rate:g} Hz does not divide the {source_rate:g} Hz logging rate")
    return int(round(q))


def _smooth_decimate(ds, smoothing: int, q: int):
    U, Y = smooth_pair(ds.select(ds.inputs), ds.select(ds.outputs), smoothing)
    t = ds.t
    if q > 1:
        U = decimate(U, q, ftype="fir", axis=0, zero_phase=True)
        Y = decimate(Y, q, ftype="fir", axis=0, zero_phase=True)
        t = t[::q][:len(U)]
    return t, U, Y


def smoothed(ds, smoothing: int) -> tuple:
    """(raw U, raw Y, smoothed U, smoothed Y) of a Dataset at its own rate (for Figs. 8-10)."""
    U, Y = ds.select(ds.inputs), ds.select(ds.outputs)
    Us, Ys = smooth_pair(U, Y, smoothing)
    return U, Y, Us, Ys


def prepare_data(records: dict, smoothing: int = 5, rate: float = 200.0) -> PaperData:
    """Smooth, decimate and split the records of :func:`simulate_records` (see module doc)."""
    missing = [k for k in ("exp_i", "exp_ii", "val_i", "val_ii") if k not in records]
    if missing:
        raise ValueError(f"records: missing {', '.join(missing)}")
    src = float(records["exp_i"].rate)
    q = decimation_factor(src, rate)
    train, test, val = [], [], []
    for exp in ("i", "ii"):
        t, U, Y = _smooth_decimate(records[f"exp_{exp}"], smoothing, q)
        n = len(t) // 2
        if n < 10:
            raise ValueError(f"duration: too short, {len(t)} samples at {rate:g} Hz")
        train.append(Segment(f"({exp}) first half", t[:n], U[:n], Y[:n]))
        test.append(Segment(f"({exp}) last half", t[n:], U[n:], Y[n:]))
        t, U, Y = _smooth_decimate(records[f"val_{exp}"], smoothing, q)
        val.append(Segment(f"({exp}) validation", t, U, Y))
    ds = records["exp_i"]
    return PaperData(inputs=list(ds.inputs), outputs=list(ds.outputs), rate=src / q,
                     train=train, test=test, validation=val)
