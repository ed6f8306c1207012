"""The EMPS benchmark records (Janot, Gautier, Brunot 2019; see data/emps/PROVENANCE.md).

``load_emps("DATA_EMPS")`` or ``load_emps("DATA_EMPS_PULSES")`` reads the MATLAB file with
``scipy.io.loadmat`` and returns the signals as 1-D float arrays: ``t`` (s), ``qm`` (motor
position, m), ``vir`` (controller output), ``force = gtau * vir`` (N), ``qg`` (reference
position, m), ``pulses`` (N, PULSES record only) and the scalars ``gtau``, ``kp``, ``kv``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.io as sio

from cdam_core.record.realdata import real_record, repo_data_dir, shared_data_dir

NAMES = ("DATA_EMPS", "DATA_EMPS_PULSES")


def emps_path(name: str = "DATA_EMPS") -> Path:
    """Path of an EMPS record (``data/emps`` in the checkout, else the shared folder)."""
    if name not in NAMES:
        raise ValueError(f"name: unknown EMPS record {name!r}; known: {', '.join(NAMES)}")
    return real_record(f"emps/{name}.mat")


# the EMPS axis is prismatic: force gtau * vir in N, position qm in m (its weight is the
# constant offset; no gravity terms: residual.analyse's ``units``)
EMPS_UNITS = {"tau": "N", "q": "m"}


def load_emps(name: str = "DATA_EMPS", path=None) -> dict:
    """Load an EMPS record (``path`` overrides the shared-data location)."""
    p = Path(path) if path is not None else emps_path(name)
    if not p.is_file():
        if path is not None:
            raise FileNotFoundError(f"path: EMPS record not found: {p}")
        raise FileNotFoundError(
            f"EMPS record {name}.mat not found in {repo_data_dir() / 'emps'} nor in "
            f"{shared_data_dir() / 'emps'} (run from the checkout, or set CDAM_SHARED_DATA to "
            "the folder that holds emps/)")
    try:
        m = sio.loadmat(str(p))
    except Exception as exc:  # scipy raises several types on corrupt files
        raise ValueError(f"path: cannot read {p} as a MATLAB file ({exc})") from None
    need = ("t", "qm", "vir", "gtau")
    missing = [k for k in need if k not in m]
    if missing:
        raise ValueError(f"path: {p.name} lacks variable(s) {', '.join(missing)}")
    out = {}
    for k in ("t", "qm", "vir", "qg"):
        if k in m:
            out[k] = np.asarray(m[k], dtype=float).ravel()
    if "pulses_N" in m:
        out["pulses"] = np.asarray(m["pulses_N"], dtype=float).ravel()
    for k in ("gtau", "kp", "kv"):
        if k in m:
            out[k] = float(np.asarray(m[k]).ravel()[0])
    n = out["t"].size
    for k, v in out.items():
        if isinstance(v, np.ndarray):
            if v.size != n:
                raise ValueError(f"path: {p.name}: {k} has {v.size} samples, t has {n}")
            if not np.all(np.isfinite(v)):
                raise ValueError(f"path: {p.name}: {k} contains NaN or Inf")
    if np.any(np.diff(out["t"]) <= 0):
        raise ValueError(f"path: {p.name}: t is not strictly increasing")
    out["force"] = out["gtau"] * out["vir"]
    return out
