"""The nano-drone benchmark's flights (../shared/data/nanodrone/*.parquet) as Datasets.

Source: idsia-robotics/nanodrone-sysid-benchmark (Busetto, Cereda, Forgione, Maroni, Piga,
Palossi, "Nonlinear system identification for a nano-drone benchmark", Control Engineering
Practice 172 (2026) 106871, arXiv 2512.14450); Crazyflie 2.1 Brushless, 100 Hz. See the README
beside the files.

Inputs ``w1..w4``: the four motor speeds in rad/s = eRPM x 2 pi / 360 (the benchmark
repository's conversion, ``m * 2 pi / (6 * 60)``), Crazyflie numbering (M1 front-right, M2
rear-right, M3 rear-left, M4 front-left). Outputs: the 13 states ``x y z`` (m, world, z up),
``vx vy vz`` (m/s, world), ``qx qy qz qw`` (attitude quaternion), ``wx wy wz`` (rad/s, body).
``Vbat`` (V) is kept as an extra column. Everything is read through the one dataset path
(``read_dataset`` with a column map and ``nan="split"``).

Samples left out (``meta["excluded"]``: reason, first and last time, samples; the record is cut
into segments there, so nothing trains or scores across them). Every rule is a physical or
kinematic fact with its threshold in physical units, the same for every record:

- **NaN motor speed**: a real telemetry gap; the row is dropped (never filled in).
- **implausible motor speed**: a reading below 0 or above ``MAX_MOTOR_SPEED`` = 4,400 rad/s,
  the no-load speed of the vehicle's 10,000 rpm/V motors on a full 1S battery (4.2 V); the
  flights reach about 2,500 rad/s, and the five telemetry glitches in them read 33,000 and
  105,000 rad/s (multisine runs 1 and 4): corrupted telemetry, not a rotor.
- **not flying (flags)**: ``is_armed`` false, ``is_flying`` false or ``is_tumbled`` true
  (where the file has the flags; a flight without them is read, ``meta["flags"]`` says so, and
  the rules below still apply).
- **ground contact** (takeoff, landing, crash): height within ``GROUND_MARGIN`` = 0.05 m (about
  one rotor diameter) of the record's lowest height (the vehicle resting on the floor). Within
  one rotor diameter the ground reaction and ground effect act (the Cheeseman-Bennett ground
  effect falls below 2 % of thrust above it), which a free-flight model does not describe.
  The lowest height is the floor only when the record starts or ends there (a logged takeoff,
  landing or crash; all 17 flights here): a flight cut to its airborne part (as the
  benchmark's own processed files may be) has no floor in it, and its lowest stretch of flight
  is kept (``_floor``).
- **diverging state estimate**: position and velocity are one estimate, so the position change
  over ``CONSISTENCY_WINDOW`` = 0.25 s must match the integral of the velocity; a mean
  disagreement above ``CONSISTENCY_LIMIT`` = 0.5 m/s (12.5 cm in 0.25 s, far above the
  motion-capture and filter noise) sustained for at least ``SUSTAINED`` = 0.5 s (the benchmark's
  50-step horizon; shorter spikes are the filter's lag at sharp turns) marks a divergence;
  its windows are left out. The rule is not fitted to the flight it finds: with the limit
  anywhere in 0.25-1.0 m/s at 0.5 s, or the duration anywhere in 0.25-1.0 s at 0.5 m/s, the
  flight flagged is multisine run 4 (halving the limit adds multisine run 2 and random1 run 2;
  halving the duration adds the 0.25 s crash spike of square run 1, already on the ground).
- Kept pieces shorter than ``SUSTAINED`` between two flight-state exclusions (bounces on
  landing) are left out with them: no 50-step prediction fits in them.

A file without the time column ``t`` is read as the benchmark's 100 Hz samples from t = 0
(``meta["time"]`` says so); every other column is read as named above.

On the 17 flights these rules leave out takeoff and landing of every flight, the crash and
ground time of square run 1 (flags and ground), five motor-telemetry glitches, and one
diverging estimate: the last 1.5 s of multisine run 4 (where the vehicle hits the floor and the
position keeps drifting with idle motors); ``python -m cdam_core.record.realdata.nanodrone``
prints them.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cdam_core.record.dataset import Dataset, read_dataset
from cdam_core.record.parquet import read_parquet_frame
from cdam_core.record.realdata import shared_data_dir

__all__ = ["load_nanodrone", "nanodrone_files", "trajectory_type", "flight_exclusions",
           "exclusion_report", "INPUTS", "STATES", "GROUPS", "ERPM_TO_RAD_S", "NANODRONE_DIR"]

NANODRONE_DIR = "nanodrone"
ERPM_TO_RAD_S = 2.0 * math.pi / 360.0
INPUTS = ["w1", "w2", "w3", "w4"]
STATES = ["x", "y", "z", "vx", "vy", "vz", "qx", "qy", "qz", "qw", "wx", "wy", "wz"]
GROUPS = {"position": ["x", "y", "z"], "velocity": ["vx", "vy", "vz"],
          "attitude": ["qx", "qy", "qz", "qw"], "rates": ["wx", "wy", "wz"]}
FLAGS = ("is_armed", "is_flying", "is_tumbled")
GROUND_MARGIN = 0.05        # m, about one rotor diameter
CONSISTENCY_WINDOW = 0.25   # s
CONSISTENCY_LIMIT = 0.5     # m/s
SUSTAINED = 0.5             # s, the benchmark's horizon
MAX_MOTOR_SPEED = 4400.0    # rad/s: 10,000 rpm/V x 4.2 V no-load
RATE = 100.0                # Hz, the benchmark's sampling rate

UNITS = {**{w: "rad/s" for w in INPUTS}, "x": "m", "y": "m", "z": "m", "vx": "m/s",
         "vy": "m/s", "vz": "m/s", "qx": "1", "qy": "1", "qz": "1", "qw": "1",
         "wx": "rad/s", "wy": "rad/s", "wz": "rad/s", "Vbat": "V"}


def nanodrone_files(folder=None, types=None) -> list[Path]:
    """The flights' Parquet files (sorted), optionally only those of the trajectory ``types``."""
    folder = Path(folder) if folder is not None else shared_data_dir() / NANODRONE_DIR
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no such folder (set CDAM_SHARED_DATA?)")
    files = sorted(folder.glob("*.parquet"))
    if types is not None:
        types = set(types)
        files = [f for f in files if trajectory_type(f) in types]
    return files


def trajectory_type(path) -> str:
    """The trajectory type of a flight: its file name's prefix (``square_20251017_run1`` ->
    ``square``)."""
    return Path(path).stem.split("_")[0]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    b = np.r_[0, mask.astype(np.int8), 0]
    d = np.diff(b)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def _diverging(t, pos, vel) -> np.ndarray:
    """Rows inside a sustained position/velocity disagreement (module doc)."""
    n = len(t)
    out = np.zeros(n, bool)
    dt = float(np.median(np.diff(t)))
    w = max(1, int(round(CONSISTENCY_WINDOW / dt)))
    if n <= w:
        return out
    ip = np.vstack([np.zeros(3), np.cumsum((vel[1:] + vel[:-1]) / 2 * np.diff(t)[:, None],
                                           axis=0)])
    span = t[w:] - t[:-w]
    mis = np.linalg.norm((pos[w:] - pos[:-w]) - (ip[w:] - ip[:-w]), axis=1) / span
    for a, b in _runs(mis > CONSISTENCY_LIMIT):
        if t[b - 1] - t[a] + dt >= SUSTAINED:
            out[a:b + w] = True
    return out


def _implausible(ds: Dataset) -> np.ndarray:
    if not all(w in ds.columns for w in INPUTS):
        return np.zeros(len(ds), bool)
    w = ds.select(INPUTS)
    return np.any((w < 0) | (w > MAX_MOTOR_SPEED), axis=1)


def _floor(z: np.ndarray) -> np.ndarray:
    """Rows within ``GROUND_MARGIN`` of the lowest height, where the record starts or ends
    there (it holds the floor); none otherwise (module doc)."""
    low = z < z.min() + GROUND_MARGIN
    return low if (low[0] or low[-1]) else np.zeros(len(z), bool)


def flight_exclusions(ds: Dataset) -> tuple[np.ndarray, list[dict]]:
    """(rows to leave out, bool (N,); [{"reason", "t_start", "t_stop", "samples"}]) of a
    loaded flight (flags, ground contact, diverging estimate; module doc)."""
    t = ds.t
    flags = {f: ds.column(f) for f in FLAGS if f in ds.columns}
    reasons = {
        "not flying (flags)": (
            (flags["is_armed"] < 0.5 if "is_armed" in flags else False) |
            (flags["is_flying"] < 0.5 if "is_flying" in flags else False) |
            (flags["is_tumbled"] > 0.5 if "is_tumbled" in flags else False)) &
        np.ones(len(t), bool),
        "implausible motor speed": _implausible(ds),
        "ground contact": _floor(ds.column("z")),
        "diverging state estimate": _diverging(t, ds.select(["x", "y", "z"]),
                                               ds.select(["vx", "vy", "vz"])),
    }
    drop = np.zeros(len(t), bool)
    for m in reasons.values():
        drop |= m
    # short kept pieces between two exclusions go with them
    for a, b in _runs(~drop):
        if a > 0 and b < len(t) and t[b - 1] - t[a] < SUSTAINED:
            drop[a:b] = True
    spans = []
    for a, b in _runs(drop):
        why = [r for r, m in reasons.items() if m[a:b].any()] or ["short piece between "
                                                                   "exclusions"]
        spans.append({"reason": ", ".join(why), "t_start": float(t[a]),
                      "t_stop": float(t[b - 1]), "samples": int(b - a)})
    return drop, spans


def load_nanodrone(path, exclude: bool = True) -> Dataset:
    """One flight: inputs ``w1..w4`` (rad/s), outputs the 13 states, ``Vbat`` and the flags as
    extra columns; rows with a NaN motor speed dropped and, with ``exclude``, the flight-state
    exclusions too (module doc), the record cut into segments there. ``meta["excluded"]`` lists
    every span left out with its reason."""
    path = Path(path)
    mapping = {w: f"m{k + 1}_erpm*{ERPM_TO_RAD_S!r}" for k, w in enumerate(INPUTS)}
    ds, t_all, timed = _read(path, mapping)
    missing = [c for c in STATES if c not in ds.columns]
    if missing:
        raise ValueError(f"{path}: not a nano-drone flight: no column {', '.join(missing)}")
    gone = np.setdiff1d(t_all, ds.t)
    excluded = [{"reason": "NaN motor speed", "t_start": float(x), "t_stop": float(x),
                 "samples": 1} for x in gone]
    if exclude:
        drop, spans = flight_exclusions(ds)
        if drop.any():
            ds = ds.without_rows(drop)
        excluded += spans
    keep = INPUTS + STATES + [c for c in ("Vbat",) + FLAGS if c in ds.columns]
    meta = {k: v for k, v in ds.meta.items() if k not in ("map", "units")}
    meta.update({
        "source": f"nano-drone benchmark flight {path.name} (idsia-robotics/"
                  f"nanodrone-sysid-benchmark; Busetto et al., Control Eng. Practice 172 (2026) "
                  f"106871)",
        "path": str(path), "rate": 100.0, "units": {c: UNITS[c] for c in keep if c in UNITS},
        "trajectory": trajectory_type(path),
        "conversion": "w_i = m{i}_erpm * 2 pi / 360 (rad/s)",
        "flags": ("status flags read: " + ", ".join(f for f in FLAGS if f in ds.columns))
        if any(f in ds.columns for f in FLAGS) else
        "no status flags in the file: flight state from ground contact and the estimate only",
        "excluded": sorted(excluded, key=lambda e: e["t_start"]),
    })
    if not timed:
        meta["time"] = f"no column t in the file: rows taken as {RATE:g} Hz samples from t = 0"
    return Dataset(t=ds.t, columns=keep, data=ds.select(keep), meta=meta,
                   input_names=INPUTS, output_names=STATES)


def _read(path: Path, mapping: dict) -> tuple[Dataset, np.ndarray, bool]:
    """(the flight through the dataset path, every row's time, whether the file had ``t``):
    ``read_dataset``, or for a file without a time column the same path from a DataFrame with
    ``t`` at the benchmark's rate (module doc)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    try:
        names = pq.read_schema(path).names
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise ValueError(f"{path}: corrupt or unreadable Parquet file ({exc})") from None
    if "t" in names or "__time" in names:
        ds = read_dataset(path, inputs=INPUTS, outputs=STATES, mapping=mapping, nan="split")
        tname = "t" if "t" in names else "__time"
        return ds, pq.read_table(path, columns=[tname]).column(tname).to_numpy(), True
    df = read_parquet_frame(path)
    df.insert(0, "t", np.arange(len(df)) / RATE)
    try:
        ds = Dataset.from_dataframe(df, INPUTS, STATES, mapping=mapping, nan="split")
    except ValueError as exc:
        raise ValueError(f"{path}: {str(exc).removeprefix('dataframe: ')}") from None
    return ds, df["t"].to_numpy(), False


def exclusion_report(files=None) -> str:
    """A plain-text table of every span the loader leaves out of each flight."""
    lines = []
    for f in (files if files is not None else nanodrone_files()):
        ds = load_nanodrone(f)
        ex = ds.meta["excluded"]
        nan = sum(e["samples"] for e in ex if e["reason"] == "NaN motor speed")
        lines.append(f"{Path(f).stem}: {len(ds)} samples kept in {len(ds.segments)} segments; "
                     f"{nan} NaN motor samples")
        for e in ex:
            if e["reason"] != "NaN motor speed":
                lines.append(f"  {e['t_start']:7.2f} .. {e['t_stop']:7.2f} s  "
                             f"{e['samples']:5d} samples  {e['reason']}")
    return "\n".join(lines)


if __name__ == "__main__":   # pragma: no cover
    print(exclusion_report())
