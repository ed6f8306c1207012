"""The dataset format: a table with ``t`` first (CSV or Parquet), and an optional JSON sidecar.

Format (issue "identification", section "The dataset format"):

- ``FILE.csv``: a header row of column names, then one row per sample; the first column is ``t``
  (seconds, strictly increasing); every cell a decimal number. Standard channel names
  for the aerial manipulator: inputs ``T, tau_phi, tau_theta, tau_psi, tau_m1, tau_m2``; outputs
  ``phi, theta, psi, X, Y, Z, q1, q2``; optional ``theta_m1, theta_m2`` (motor-side angle after
  the gearbox, rad) and any other named columns. SI units (N, N m, rad, m; a declared unit of a
  standard column is checked: :mod:`cdam_core.record.units`). pandas' default
  CSV (an unnamed index column first) and PlotJuggler's (``__time`` first) are read too.
- ``FILE.parquet``: the same columns in Parquet (:mod:`cdam_core.record.parquet`); a pandas
  DataFrame in and out: ``Dataset.from_dataframe`` / ``Dataset.to_dataframe``.
- ``FILE.json`` (optional, beside the table): metadata, e.g. ``rate`` (Hz), ``units`` (column ->
  unit), ``source``, ``model`` (declared model), ``inputs``/``outputs`` (default selection),
  ``segments`` (row ranges a model never predicts across), declared gaps (``gapless_rows``,
  ``gaps``: rows inside a gap are left out on reading and the record is cut there; see
  :mod:`cdam_core.record.columns`) and anything else a producer wants to keep (clock offsets,
  interpolation per column).

Missing values: an error by default (``nan="error"``), or the record cut into segments around
them (``nan="split"``); a column map renames the record's columns for a model (``mapping=``,
``--map``). Both: :mod:`cdam_core.record.columns`.

Every error is a ValueError naming the file and, for the CSV, the line number (the header is
line 1), for Parquet and DataFrames the row. Writing is atomic: a temporary file in the same
folder, flushed, then renamed.
"""
from __future__ import annotations

import csv
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from cdam_core.base.jsonio import plain, write_text_atomic
from cdam_core.record.columns import (NAN_POLICIES, apply_column_map, check_segments,
                                      gap_cuts, kept_segments, parse_column_map, split_missing)
from cdam_core.record.parquet import frame_table, read_parquet_table, write_parquet_table
from cdam_core.record.units import STANDARD_UNITS, check_standard_units

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
        units = self.meta.get("units")
        if units is not None and not (isinstance(units, dict) and
                                      all(isinstance(u, str) for u in units.values())):
            raise ValueError("meta.units: expected a dict of column -> unit text")
        check_standard_units(units or {}, self.columns, "meta")
        if self.meta.get("segments") is not None:
            check_segments(self.meta["segments"], t.size, "meta.segments")
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

    # -- pandas ---------------------------------------------------------------------------
    @classmethod
    def from_dataframe(cls, df, inputs=None, outputs=None, *, meta: dict | None = None,
                       mapping=None, nan: str = "error") -> "Dataset":
        """A Dataset from a pandas DataFrame: time column ``t`` or ``__time`` (or the index so
        named), numeric columns (booleans as 0/1); ``inputs``, ``outputs``, ``mapping`` and
        ``nan`` as for :func:`read_dataset` (errors name the row). A non-numeric column is an
        error unless ``nan="split"`` (then it is dropped and listed in
        ``meta["dropped_columns"]``)."""
        mapping = _prepare(nan, mapping)
        names, arr, other = frame_table(df, "dataframe", drop_other=(nan == "split"))
        meta = dict(meta or {})
        if other:
            meta["dropped_columns"] = other
        return _assemble("dataframe", names, arr, meta, inputs, outputs, mapping, nan,
                         "row {}".format, None)

    def to_dataframe(self):
        """pandas DataFrame with ``t`` first and every column (the metadata in ``.attrs``)."""
        import pandas as pd
        df = pd.DataFrame(self.data, columns=self.columns)
        df.insert(0, "t", self.t)
        df.attrs.update(plain(self.meta))
        return df

    def without_rows(self, drop) -> "Dataset":
        """A copy without the rows where ``drop`` (bool (N,)) is True, cut into segments there
        (the existing seams kept): nothing is interpolated across the rows left out."""
        drop = np.asarray(drop, bool)
        if drop.shape != self.t.shape:
            raise ValueError(f"drop: expected shape {self.t.shape}, got {drop.shape}")
        if drop.all():
            raise ValueError("drop: every row would be left out")
        segments = kept_segments(~drop, self.segments)
        meta = {k: v for k, v in self.meta.items() if k != "segments"}
        if len(segments) > 1:
            meta["segments"] = segments
        return Dataset(t=self.t[~drop], columns=list(self.columns), data=self.data[~drop],
                       meta=meta, input_names=self.inputs, output_names=self.outputs)

    @property
    def segments(self) -> list[tuple[int, int]]:
        """(start, stop) row ranges of the record's segments (``meta["segments"]``; one segment
        when none is declared): a model never predicts across a seam."""
        seg = self.meta.get("segments")
        return check_segments(seg, len(self)) if seg else [(0, len(self))]

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
    terms = model.get("terms") if isinstance(model, dict) else None
    if terms is not None and not _names(terms):
        bad("model.terms", f"expected a list of parameter names, got {json.dumps(terms)[:60]}")


def _locate_bad_row(path: Path, lines: list[str], ncol: int, columns: list[str],
                    rows=None, nan: str = "error", skip: int = 0) -> None:
    """Slow path: check the data lines (all, or the 0-based data ``rows`` given) cell by cell
    and raise at the first bad one (cell count, non-numeric, or a missing value when ``nan`` is
    "error"). ``skip`` leading cells (a pandas index) are not numbers."""
    todo = range(len(lines) - 1) if rows is None else rows
    for r in todo:
        k, line = int(r) + 2, lines[int(r) + 1]
        cells = next(csv.reader([line]))
        if len(cells) != ncol:
            raise ValueError(f"{path}: line {k}: expected {ncol} cells, found {len(cells)}")
        for j, cell in enumerate(cells[skip:], start=skip):
            if not cell.strip():
                if nan == "error":
                    raise ValueError(f"{path}: line {k}: column {columns[j]!r}: non-numeric cell "
                                     f"{cell!r} (an empty cell is a missing value: read with "
                                     f"nan='split' to cut the record there)")
                continue
            try:
                v = float(cell)
            except ValueError:
                raise ValueError(f"{path}: line {k}: column {columns[j]!r}: "
                                 f"non-numeric cell {cell!r}") from None
            if nan == "error" and not np.isfinite(v):
                raise ValueError(f"{path}: line {k}: column {columns[j]!r}: "
                                 f"NaN or Inf cell {cell.strip()!r}")
    if rows is None:
        raise ValueError(f"{path}: could not parse the numeric rows")  # pragma: no cover


def _read_csv(path: Path, nan: str):
    """(header with ``t`` first, (N, C) float64 array) of a CSV file. pandas' default output
    (an unnamed index column first) and PlotJuggler's ``__time`` first column are accepted: the
    index column is dropped, ``__time`` read as ``t``. Numbers are parsed by pandas (exact
    round trip of float64); every error names the line."""
    import pandas as pd

    text = path.read_text(encoding="utf-8-sig")
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise ValueError(f"{path}: line 1: empty file (expected a header row starting with 't')")
    header = [c.strip() for c in next(csv.reader([lines[0]]))]
    skip = 1 if len(header) > 1 and header[0] in ("", "Unnamed: 0") else 0
    names = header[skip:]
    if names[:1] == ["__time"]:
        names[0] = "t"
    if not names or names[0] != "t":
        raise ValueError(f"{path}: line 1: the first column must be 't', found {names[:1]}")
    try:
        _check_names(names, f"{path}: line 1")
    except ValueError as exc:
        raise ValueError(str(exc)) from None
    for k, line in enumerate(lines[1:], start=2):
        if not line.strip():
            raise ValueError(f"{path}: line {k}: empty line inside the data")
    if len(lines) < 2:
        raise ValueError(f"{path}: line 2: no data rows after the header")
    full = header[:skip] + names
    try:
        arr = pd.read_csv(io.StringIO("\n".join(lines[1:])), header=None,
                          dtype={j: np.float64 for j in range(skip, len(full))},
                          skip_blank_lines=False).to_numpy()
    except (ValueError, pd.errors.ParserError):
        _locate_bad_row(path, lines, len(full), full, nan=nan, skip=skip)
        raise  # pragma: no cover
    if arr.shape != (len(lines) - 1, len(full)):
        _locate_bad_row(path, lines, len(full), full, nan=nan, skip=skip)
        raise ValueError(f"{path}: could not parse the numeric rows")  # pragma: no cover
    arr = np.ascontiguousarray(arr[:, skip:], dtype=np.float64)
    bad_rows = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad_rows.size:   # short rows read as NaN; a NaN is an error unless nan="split"
        _locate_bad_row(path, lines, len(full), full, rows=bad_rows, nan=nan, skip=skip)
    return names, arr


def _assemble(where: str, names: list[str], arr: np.ndarray, meta: dict, inputs, outputs,
              mapping: dict, nan: str, row_name, side: Path | None) -> "Dataset":
    """A Dataset from a table (``t`` first): time checks, sidecar checks, the column map, the
    missing-value policy (cdam_core.record.columns); ``row_name(r)`` names data row r."""
    t = arr[:, 0]
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ValueError(f"{where}: {row_name(int(bad[0]))}: t is NaN or Inf")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        r = int(bad[0]) + 1
        raise ValueError(f"{where}: {row_name(r)}: t not strictly increasing "
                         f"({float(t[r - 1])!r} -> {float(t[r])!r})")
    if side is not None:
        check_sidecar(meta, t, names, side)
    meta = dict(meta)
    if meta.get("gapless_rows") is not None or meta.get("gaps") is not None:
        keep, segments = gap_cuts(meta, t, str(side or where))
        if not keep.any():
            raise ValueError(f"{where}: every row lies inside a declared gap")
        arr, t = arr[keep], t[keep]
        meta.pop("gapless_rows", None)      # row numbers before the gap rows were left out
        meta.pop("segments", None)
        if len(segments) > 1:
            meta["segments"] = segments
        if not keep.all():
            meta["gap_rows_left_out"] = int((~keep).sum())
    columns, data = apply_column_map(names[1:], arr[:, 1:], mapping, where)
    if mapping:
        units = dict(meta.get("units") or {})
        # a mapped name carries its source column's unit when the map does not scale it;
        # a scaled one (a unit conversion) is in the unit the name stands for
        meta["units"] = {**{k: v for k, v in units.items() if k in columns and k not in mapping},
                         **{n: units[c] for n, (c, f) in mapping.items() if c in units and f == 1}}
        meta["map"] = {n: c if f == 1 else f"{c}*{f!r}" for n, (c, f) in mapping.items()}
    check_standard_units(meta.get("units") or {}, columns, str(side or where))
    if nan == "error":
        finite = np.isfinite(data)
        if not finite.all():
            r, c = np.argwhere(~finite)[0]
            raise ValueError(f"{where}: {row_name(int(r))}: column {columns[c]!r}: NaN or Inf "
                             f"(read with nan='split' to cut the record there)")
    else:
        probe = Dataset.__new__(Dataset)
        probe.columns, probe.meta = columns, meta
        try:
            sel = probe._resolve(inputs, "inputs", STANDARD_INPUTS) + \
                probe._resolve(outputs, "outputs", STANDARD_OUTPUTS)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
        rows, keep, dropped = split_missing(data, columns, sel)
        if not rows.any():
            raise ValueError(f"{where}: no row has finite values in every selected column "
                             f"({', '.join(sel) or 'all columns'})")
        seams = meta.get("segments")
        seams = check_segments(seams, len(t), f"{where}: segments") if seams else [(0, len(t))]
        segments = kept_segments(rows, seams)
        t, data = t[rows], data[rows][:, keep]
        columns = [columns[j] for j in keep]
        meta.pop("segments", None)
        if len(segments) > 1:
            meta["segments"] = segments
        if not rows.all():
            meta["dropped_rows"] = int((~rows).sum())
        if dropped:
            meta["dropped_columns"] = dropped
        meta.pop("columns", None)
    try:
        return Dataset(t=t.copy(), columns=columns, data=data, meta=meta,
                       input_names=inputs, output_names=outputs)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def _prepare(nan, mapping):
    if nan not in NAN_POLICIES:
        raise ValueError(f"nan: expected one of {', '.join(NAN_POLICIES)}, got {nan!r}")
    return parse_column_map(mapping, "map")


def read_dataset(path: str | os.PathLike, inputs: Sequence[str] | str | None = None,
                 outputs: Sequence[str] | str | None = None, *, mapping=None,
                 nan: str = "error") -> Dataset:
    """Read a record: ``FILE.csv`` or ``FILE.parquet`` (and ``FILE.json`` if present).

    Args:
        path: the CSV or Parquet file (chosen by the suffix; anything but ``.parquet`` is CSV).
        inputs, outputs: column names to select (a list or a comma-separated string), after the
            map; default the sidecar's ``inputs``/``outputs``, else the standard names present.
        mapping: a column map (text, a JSON file or a dict; :mod:`cdam_core.record.columns`).
        nan: "error" (every cell finite) or "split" (rows with a missing value in a selected
            column dropped and the record cut there into segments; see
            :mod:`cdam_core.record.columns`).

    Raises:
        ValueError naming the file and line (CSV) or row (Parquet): empty file, missing ``t``
        (must be first), duplicate or empty column name, wrong number of cells, non-numeric,
        NaN or Inf cell (``nan="error"``), non-increasing ``t``, unknown requested or mapped
        column, corrupt Parquet file, corrupt sidecar or one that disagrees with the data
        (``check_sidecar``).
        FileNotFoundError if the file does not exist.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    mapping = _prepare(nan, mapping)
    if path.suffix.lower() == ".parquet":
        names, arr, other = read_parquet_table(path)
        row_name = "row {}".format
    else:
        (names, arr), other = _read_csv(path, nan), []
        row_name = lambda r: f"line {r + 2}"   # noqa: E731  (header is line 1)
    meta = _read_sidecar(path)
    if other:
        meta["dropped_columns"] = other
    return _assemble(str(path), names, arr, meta, inputs, outputs, mapping, nan, row_name,
                     sidecar_path(path))


# -- writing --------------------------------------------------------------------------------
# atomic writes and JSON cleaning: cdam_core.base.jsonio (shared with reports and model files)


def write_dataset(path: str | os.PathLike, dataset: Dataset, *, sidecar: bool = True) -> None:
    """Write ``dataset`` to ``FILE.csv`` or ``FILE.parquet`` and its metadata to ``FILE.json``
    (each atomically).

    CSV numbers are written with Python's shortest round-trip representation and Parquet holds
    float64, so reading back gives bit-identical values. The sidecar holds the dataset's
    ``meta`` (segments included) plus ``rate`` (declared or measured), ``units`` (standard units
    for standard names, overridden by ``meta["units"]``), ``columns``, ``inputs`` and
    ``outputs``.
    """
    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset: expected a Dataset, got {type(dataset).__name__}")
    path = Path(path)
    kind = path.suffix.lower()
    if kind not in (".csv", ".parquet"):
        raise ValueError(f"path: expected a .csv or .parquet file name, got {path.name!r}")
    if not path.parent.is_dir():
        raise ValueError(f"path: folder {str(path.parent)!r} does not exist")
    full = np.column_stack([dataset.t, dataset.data])
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
    if kind == ".parquet":
        write_parquet_table(path, ["t"] + dataset.columns, full)
        return
    buf = io.StringIO()
    buf.write(",".join(["t"] + dataset.columns) + "\n")
    rep = float.__repr__
    for row in full.tolist():
        buf.write(",".join(map(rep, row)))
        buf.write("\n")
    write_text_atomic(path, buf.getvalue())
