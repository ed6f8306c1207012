"""The Parrot AR.Drone 2.0 flight with OptiTrack (data/ardrone2) as a Dataset.

Source: tud-cor/ardrone2_dem_filter (Apache-2.0), matlab/expData10_29_25.mat; see
data/ardrone2/PROVENANCE.md. We use ``origData`` (the raw, irregular streams), not the 20 s
pre-resampled ``output``/``input``:
- inputs ``motor1..motor4``: ``navMotor`` (PWM 0..255, about 198 Hz, irregular), zero-order hold;
- outputs ``phi, theta, psi`` (``otOrient``, Z-Y-X Euler from OptiTrack, rad; unwrapped then
  linear) and ``X, Y, Z`` (``otPos``, m, linear), OptiTrack at a nominal 120 Hz.
The grid covers the span both streams have (navdata starts about 6.6 s after OptiTrack).
The OptiTrack and navdata times are taken to share one clock, as the source's own resampling
does. Frames are OptiTrack's as recorded (not converted).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cdam_core.record.dataset import Dataset
from cdam_core.record.realdata import real_record
from cdam_core.record.resample import find_gaps, resample_signals

__all__ = ["load_ardrone2", "ARDRONE2_FILE"]

ARDRONE2_FILE = "ardrone2/expData10_29_25.mat"


def _strictly_increasing(t, x):
    keep = np.r_[True, np.diff(t) > 0]
    return t[keep], x[keep], int((~keep).sum())


def load_ardrone2(path: str | Path | None = None, rate: float = 120.0) -> Dataset:
    """Load the AR.Drone 2.0 flight resampled onto a uniform grid at ``rate`` Hz.

    Args:
        path: the .mat file; default ``real_record(ARDRONE2_FILE)`` (data/ first).
        rate: grid rate in Hz (default 120, OptiTrack's nominal rate).

    Returns:
        Dataset with inputs motor1..motor4 and outputs phi, theta, psi, X, Y, Z; ``t`` in the
        recording's seconds.
    """
    from scipy.io import loadmat

    path = Path(path) if path is not None else real_record(ARDRONE2_FILE)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (see data/README.md)")
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate: expected a positive rate in Hz, got {rate!r}")
    try:
        exp = loadmat(str(path), squeeze_me=True, struct_as_record=False)["expData"]
        o = exp.origData
        t_ot = np.asarray(o.otTime, np.float64)
        pos = np.asarray(o.otPos, np.float64).T
        ori = np.asarray(o.otOrient, np.float64).T
        t_nav = np.asarray(o.navTime, np.float64)
        mot = np.asarray(o.navMotor, np.float64).T
    except (KeyError, AttributeError, ValueError, TypeError) as exc:
        raise ValueError(f"{path}: not the expected AR.Drone record ({exc})") from None
    if pos.shape != (t_ot.size, 3) or ori.shape != (t_ot.size, 3) or mot.shape != (t_nav.size, 4):
        raise ValueError(f"{path}: unexpected array shapes {pos.shape}, {ori.shape}, {mot.shape}")
    t_ot, otx, d_ot = _strictly_increasing(t_ot, np.column_stack([ori, pos]))
    t_nav, mot, d_nav = _strictly_increasing(t_nav, mot)
    signals = {}
    for j, name in enumerate(["phi", "theta", "psi"]):
        signals[name] = (t_ot, otx[:, j], "angle")
    for j, name in enumerate(["X", "Y", "Z"]):
        signals[name] = (t_ot, otx[:, 3 + j], "linear")
    for j in range(4):
        signals[f"motor{j + 1}"] = (t_nav, mot[:, j], "hold")
    grid, out = resample_signals(signals, rate)
    cols = [f"motor{j}" for j in range(1, 5)] + ["phi", "theta", "psi", "X", "Y", "Z"]
    meta = {
        "source": "Parrot AR.Drone 2.0 + OptiTrack, tud-cor/ardrone2_dem_filter (Apache-2.0), "
                  "matlab/expData10_29_25.mat, origData",
        "rate": float(rate),
        "units": {**{f"motor{j}": "PWM 0..255" for j in range(1, 5)},
                  "phi": "rad", "theta": "rad", "psi": "rad", "X": "m", "Y": "m", "Z": "m"},
        "interpolation": {c: signals[c][2] for c in cols},
        "inputs": cols[:4],
        "outputs": cols[4:],
        "gaps": {"optitrack": find_gaps(t_ot, 5 / 120.0), "navdata": find_gaps(t_nav, 0.05)},
        "repeated_times_dropped": {"optitrack": d_ot, "navdata": d_nav},
    }
    return Dataset(t=grid, columns=cols, data=np.column_stack([out[c] for c in cols]), meta=meta)
