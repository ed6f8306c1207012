"""The dataset format: CSV with a header row, ``t`` first, and an optional JSON sidecar.

Format (issue "identification", section "The dataset format"):

- ``FILE.csv``: a header row of column names, then one row per sample; the first column is ``t``
  (seconds, strictly increasing); every cell a finite decimal number. Standard channel names
  for the aerial manipulator: inputs ``T, tau_phi, tau_theta, tau_psi, tau_m1, tau_m2``; outputs
  ``phi, theta, psi, X, Y, Z, q1, q2``; optional ``theta_m1, theta_m2`` (motor-side angle after
  the gearbox, rad) and any other named columns. SI units (N, N m, rad, m).
- ``FILE.json`` (optional, beside the CSV): metadata, e.g. ``rate`` (Hz), ``units`` (column ->
  unit), ``source``, ``model`` (declared model), ``inputs``/``outputs`` (default selection) and
  anything else a producer wants to keep (gaps, clock offsets, interpolation per column).

Every error is a ValueError naming the file and, for the CSV, the line number (the header is
line 1). Writing is atomic: a temporary file in the same folder, flushed, then renamed.
"""
from __future__ import annotations

import csv
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from cdam_core.base.jsonio import plain, write_text_atomic

__all__ = [
    "Dataset",
    "read_dataset",
    "write_dataset",
    "sidecar_path",
    "STANDARD_INPUTS",
    "STANDARD_OUTPUTS",
    "STANDARD_UNITS",
]

STANDARD_INPUTS = ("T", "tau_phi", "tau_theta", "tau_psi", "tau_m1", "tau_m2")
STANDARD_OUTPUTS = ("phi", "theta", "psi", "X", "Y", "Z", "q1", "q2")
STANDARD_UNITS = {
    "t": "s",
    "T": "N",
    "tau_phi": "N m",
    "tau_theta": "N m",
    "tau_psi": "N m",
    "tau_m1": "N m",
    "tau_m2": "N m",
    "phi": "rad",
    "theta": "rad",
    "psi": "rad",
    "X": "m",
    "Y": "m",
    "Z": "m",
    "q1": "rad",
    "q2": "rad",
    "theta_m1": "rad",
    "theta_m2": "rad",
}


def sidecar_path(path: str | os.PathLike) -> Path:
    """The JSON sidecar beside a CSV file: ``FILE.csv`` -> ``FILE.json``."""
    return Path(path).with_suffix(".json")


def _check_names(names: Sequence[str], where: str) -> list[str]:
    names = [str(n) for n in names]
    seen: set[str] = set()
    for n in names:
        if not n or n != n.strip():
            raise ValueError(f"{where}: empty column name or name with surrounding spaces: {n!r}")
        if any(c in n for c in ',"\r\n'):
            raise ValueError(f"{where}: column name {n!r} contains a comma, quote or newline")
        if n in seen:
            raise ValueError(f"{where}: duplicate column name {n!r}")
        seen.add(n)
    return names


@dataclass
class Dataset:
    """One record in the dataset format.

    Attributes:
        t: (N,) sample times in seconds, strictly increasing, finite.
        columns: the C column names other than ``t``, in file order.
        data: (N, C) float64 samples.
        meta: the sidecar's metadata (``rate``, ``units``, ``source``, ``model``, ...).
        input_names / output_names: the selected inputs and outputs. When not given they come
            from ``meta["inputs"]``/``meta["outputs"]``, else the standard names present.
    """

    t: np.ndarray
    columns: list[str]
    data: np.ndarray
    meta: dict = field(default_factory=dict)
    input_names: list[str] | None = None
    output_names: list[str] | None = None

    def __post_init__(self) -> None:
        self.columns = _check_names(self.columns, "columns")
        if "t" in self.columns:
            raise ValueError("columns: 't' is the time vector, not a data column")
        t = np.asarray(self.t, dtype=np.float64)
        if t.ndim != 1 or t.size == 0:
            raise ValueError(f"t: expected a non-empty 1-D array, got shape {t.shape}")
        if not np.all(np.isfinite(t)):
            raise ValueError("t: contains NaN or Inf")
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise ValueError(f"t: not strictly increasing at sample {i} ({t[i - 1]!r} -> {t[i]!r})")
        data = np.asarray(self.data, dtype=np.float64)
        if data.ndim == 1 and len(self.columns) == 1:
            data = data[:, None]
        if data.ndim != 2 or data.shape != (t.size, len(self.columns)):
            raise ValueError(
                f"data: expected shape ({t.size}, {len(self.columns)}), got {data.shape}")
        if not np.all(np.isfinite(data)):
            r, c = np.argwhere(~np.isfinite(data))[0]
            raise ValueError(f"data: NaN or Inf at sample {r}, column {self.columns[c]!r}")
        if not isinstance(self.meta, dict):
            raise ValueError("meta: expected a dict")
        self.t = t
        self.data = np.ascontiguousarray(data)
        self.input_names = self._resolve(self.input_names, "inputs", STANDARD_INPUTS)
        self.output_names = self._resolve(self.output_names, "outputs", STANDARD_OUTPUTS)

    def _resolve(self, given, key: str, standard: Sequence[str]) -> list[str]:
        if given is None:
            given = self.meta.get(key)
        if given is None:
            return [n for n in standard if n in self.columns]
        if isinstance(given, str):
            given = [s for s in given.split(",") if s.strip()]
        names = [str(n).strip() for n in given]
        for n in names:
            if n not in self.columns:
                raise ValueError(
                    f"{key}: unknown column {n!r} (columns: {', '.join(self.columns)})")
        return names

    # -- access -------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.t.size)

    def column(self, name: str) -> np.ndarray:
        """One column by name (``"t"`` gives the time vector); ValueError if unknown."""
        if name == "t":
            return self.t
        try:
            return self.data[:, self.columns.index(name)]
        except ValueError:
            raise ValueError(
                f"name: unknown column {name!r} (columns: {', '.join(self.columns)})") from None

    def select(self, names: Iterable[str]) -> np.ndarray:
        """(N, k) array of the named columns, in the order given."""
        names = list(names)
        if not names:
            raise ValueError("names: no column selected")
        return np.column_stack([self.column(n) for n in names])

    @property
    def inputs(self) -> list[str]:
        """Names of the input columns."""
        return list(self.input_names or [])

    @property
    def outputs(self) -> list[str]:
        """Names of the output columns."""
        return list(self.output_names or [])

    @property
    def rate(self) -> float:
        """Sample rate in Hz: ``meta["rate"]`` if declared, else 1 / median sample step."""
        r = self.meta.get("rate")
        if r is not None:
            return float(r)
        if self.t.size < 2:
            raise ValueError("rate: a single sample has no rate and the sidecar declares none")
        return float(1.0 / np.median(np.diff(self.t)))

    @property
    def units(self) -> dict[str, str]:
        """Unit per column: the sidecar's ``units`` over the standard units."""
        u = {k: v for k, v in STANDARD_UNITS.items() if k == "t" or k in self.columns}
        u.update(self.meta.get("units") or {})
        return u


# -- reading --------------------------------------------------------------------------------
def _read_sidecar(path: Path) -> dict:
    side = sidecar_path(path)
    if not side.is_file():
        return {}
    text = side.read_text(encoding="utf-8")
    try:
        meta = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{side}: line {exc.lineno}: corrupt JSON sidecar: {exc.msg}") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{side}: line 1: the sidecar must hold a JSON object")
    return meta


# A declared rate is the writer's grid rate or a logger's nominal rate; a real clock (crystal
# error, jitter) is within a fraction of a percent of it, so 5 % separates a nominal rate from a
# wrong one (10 Hz declared on 1 kHz data) with room to spare.
RATE_TOLERANCE = 0.05
_INTERP = ("linear", "hold", "angle")


def _names(v) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


def check_sidecar(meta: dict, t: np.ndarray, header: list[str], where) -> None:
    """The sidecar's known fields against their types and the data (ValueError naming the
    field): ``rate`` a positive number within RATE_TOLERANCE of 1 / median step of ``t``;
    ``units`` and ``interpolation`` maps of column -> text; ``columns`` the CSV header;
    ``inputs``/``outputs`` a list of names or one comma-separated text; ``effects`` a list of names (or
    name -> parameters), ``model.effects`` a list of names; ``model`` a name or an object."""
    def bad(field, msg):
        raise ValueError(f"{where}: sidecar field {field!r}: {msg}")

    rate = meta.get("rate")
    if rate is not None:
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or \
                not (np.isfinite(rate) and rate > 0):
            bad("rate", f"expected a positive number of Hz, got {rate!r}")
        if t.size >= 2:
            measured = 1.0 / float(np.median(np.diff(t)))
            if abs(rate / measured - 1.0) > RATE_TOLERANCE:
                bad("rate", f"declares {rate:g} Hz but the time column's median step gives "
                            f"{measured:.6g} Hz (tolerance {RATE_TOLERANCE:.0%})")
    for key in ("units", "interpolation"):
        v = meta.get(key)
        if v is not None and not (isinstance(v, dict) and
                                  all(isinstance(x, str) for x in v.values())):
            bad(key, f"expected an object of column -> text, got {type(v).__name__}")
    for col, kind in (meta.get("interpolation") or {}).items():
        if kind not in _INTERP:
            bad("interpolation", f"{col}: expected one of {', '.join(_INTERP)}, got {kind!r}")
    cols = meta.get("columns")
    if cols is not None and cols != header:
        bad("columns", f"{cols!r} disagrees with the CSV header {header!r}")
    for key in ("inputs", "outputs"):
        v = meta.get(key)
        if v is not None and not (isinstance(v, str) or _names(v)):
            bad(key, f"expected a list of column names, got {type(v).__name__}")
    model = meta.get("model")
    if model is not None and not isinstance(model, (dict, str)):
        bad("model", f"expected a name or an object, got {type(model).__name__}")
    eff = meta.get("effects")
    if eff is not None and not (_names(eff) or isinstance(eff, dict)):
        bad("effects", f"expected a list of effect names or an object of name -> parameters, "
                       f"got {json.dumps(eff)[:60]}")
    eff = model.get("effects") if isinstance(model, dict) else None
    if eff is not None and not _names(eff):
        bad("model.effects", f"expected a list of effect names, got {json.dumps(eff)[:60]}")


def _locate_bad_row(path: Path, lines: list[str], ncol: int, columns: list[str]) -> None:
    """Slow path after the fast parser failed: find the first bad line and raise."""
    for k, line in enumerate(lines[1:], start=2):
        cells = next(csv.reader([line]))
        if len(cells) != ncol:
            raise ValueError(f"{path}: line {k}: expected {ncol} cells, found {len(cells)}")
        for j, cell in enumerate(cells):
            try:
                float(cell)
            except ValueError:
                raise ValueError(f"{path}: line {k}: column {columns[j]!r}: "
                                 f"non-numeric cell {cell!r}") from None
    raise ValueError(f"{path}: could not parse the numeric rows")  # pragma: no cover


def read_dataset(path: str | os.PathLike, inputs: Sequence[str] | str | None = None,
                 outputs: Sequence[str] | str | None = None) -> Dataset:
    """Read ``FILE.csv`` (and ``FILE.json`` if present) into a Dataset.

    Args:
        path: the CSV file.
        inputs, outputs: column names to select (a list or a comma-separated string); default
            the sidecar's ``inputs``/``outputs``, else the standard names present.

    Raises:
        ValueError naming the file and line: empty file, missing ``t`` (must be first),
        duplicate or empty column name, wrong number of cells, non-numeric, NaN or Inf cell,
        non-increasing ``t``, unknown requested column, corrupt sidecar or one that disagrees
        with the data (``check_sidecar``).
        FileNotFoundError if the file does not exist.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    text = path.read_text(encoding="utf-8-sig")
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise ValueError(f"{path}: line 1: empty file (expected a header row starting with 't')")
    header = [c.strip() for c in next(csv.reader([lines[0]]))]
    if not header or header[0] != "t":
        raise ValueError(f"{path}: line 1: the first column must be 't', found {header[:1]}")
    try:
        _check_names(header, f"{path}: line 1")
    except ValueError as exc:
        raise ValueError(str(exc)) from None
    columns = header[1:]
    for k, line in enumerate(lines[1:], start=2):
        if not line.strip():
            raise ValueError(f"{path}: line {k}: empty line inside the data")
    if len(lines) < 2:
        raise ValueError(f"{path}: line 2: no data rows after the header")
    try:
        arr = np.loadtxt(lines[1:], delimiter=",", ndmin=2, dtype=np.float64, comments=None)
        if arr.shape[1] != len(header):
            raise ValueError("cell count")
    except ValueError:
        _locate_bad_row(path, lines, len(header), header)
        raise  # pragma: no cover
    finite = np.isfinite(arr)
    if not finite.all():
        r, c = np.argwhere(~finite)[0]
        raise ValueError(f"{path}: line {r + 2}: column {header[c]!r}: "
                         f"NaN or Inf cell {lines[r + 1].split(',')[c].strip()!r}")
    t = arr[:, 0]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        r = int(bad[0]) + 1
        raise ValueError(f"{path}: line {r + 2}: t not strictly increasing "
                         f"({t[r - 1]!r} -> {t[r]!r})")
    meta = _read_sidecar(path)
    check_sidecar(meta, t, header, sidecar_path(path))
    try:
        return Dataset(t=t.copy(), columns=columns, data=arr[:, 1:], meta=meta,
                       input_names=inputs, output_names=outputs)
    except ValueError as exc:
        raise ValueError(f"{path}: line 1: {exc}") from None


# -- writing --------------------------------------------------------------------------------
# atomic writes and JSON cleaning: cdam_core.base.jsonio (shared with reports and model files)


def write_dataset(path: str | os.PathLike, dataset: Dataset, *, sidecar: bool = True) -> None:
    """Write ``dataset`` to ``FILE.csv`` and its metadata to ``FILE.json`` (both atomically).

    Numbers are written with Python's shortest round-trip representation, so reading back
    gives bit-identical float64 values. The sidecar holds the dataset's ``meta`` plus
    ``rate`` (declared or measured), ``units`` (standard units for standard names, overridden
    by ``meta["units"]``), ``columns``, ``inputs`` and ``outputs``.
    """
    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset: expected a Dataset, got {type(dataset).__name__}")
    path = Path(path)
    if path.suffix.lower() != ".csv":
        raise ValueError(f"path: expected a .csv file name, got {path.name!r}")
    if not path.parent.is_dir():
        raise ValueError(f"path: folder {str(path.parent)!r} does not exist")
    buf = io.StringIO()
    buf.write(",".join(["t"] + dataset.columns) + "\n")
    full = np.column_stack([dataset.t, dataset.data])
    rep = float.__repr__
    for row in full.tolist():
        buf.write(",".join(map(rep, row)))
        buf.write("\n")
    if sidecar:
        meta = dict(dataset.meta)
        if len(dataset) >= 2 or "rate" in meta:
            meta["rate"] = dataset.rate
        meta["units"] = dataset.units
        meta["columns"] = ["t"] + dataset.columns
        meta["inputs"] = dataset.inputs
        meta["outputs"] = dataset.outputs
        write_text_atomic(sidecar_path(path),
                           json.dumps(plain(meta), indent=2, sort_keys=False) + "\n")
    write_text_atomic(path, buf.getvalue())
