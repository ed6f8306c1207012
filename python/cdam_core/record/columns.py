"""Column maps, the missing-value policy and the segments of a record (arrays only).

**Column map** (``--map`` on the command line, ``mapping=`` in Python): the names a model uses
-> the record's own columns, so a flight log reaches a model without a converter. Text
``"u1=m1_erpm,u2=m2_erpm*0.01745"`` (``name=column`` or ``name=column*factor``, the factor a
plain number, e.g. a unit conversion), a JSON file holding an object of the same
``{"name": "column"}`` / ``{"name": "column*factor"}`` pairs, or a dict. Each mapped name becomes
a column holding the record's column (times the factor); a record column used by the map and not
itself a mapped name is dropped (it was renamed); the other columns stay.

**Missing values** (``nan=``): ``"error"`` (default): every cell must be finite; the first NaN,
Inf or empty cell is an error naming the file, line (CSV) or row (Parquet, DataFrame) and
column. ``"split"``: only the selected columns (inputs and outputs, after the map; every column
when none is selected) must be finite: a row where one of them is not is dropped and the record
is cut there into segments (``meta["segments"]``: [start, stop) ranges of the kept rows that
tile them; ``meta["dropped_rows"]``: how many); another column holding a non-finite value is
dropped (``meta["dropped_columns"]``). Rows are never filled in or interpolated.

**Segments**: a record's rows may be split into segments (``meta["segments"]``); a model never
predicts across a seam (:mod:`cdam_core.models.protocol`, ``segments=``).

**Declared gaps** (:func:`gap_cuts`): a producer that saw its source stop (``cdam merge``,
``cdam import-can``, ``cdam import-ulog``, the real-data loaders) says so in the sidecar:
``gapless_rows`` (row ranges without a gap) and/or ``gaps`` (time intervals ``{"start", "end"}``
in the record's time, a list or an object of lists per source). Reading such a record leaves
out the rows inside a gap (their values were interpolated over it, not measured) and cuts the
record at every gap, so no regressor or prediction crosses one.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["parse_column_map", "apply_column_map", "split_missing", "kept_segments",
           "check_segments", "gap_cuts", "NAN_POLICIES"]

NAN_POLICIES = ("error", "split")


def _entry(name, spec, where) -> tuple[str, float]:
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"{where}: empty name in {name!r}={spec!r}")
    if isinstance(spec, tuple) and len(spec) == 2:      # already parsed: (column, factor)
        spec = spec[0] if spec[1] == 1 else f"{spec[0]}*{spec[1]!r}"
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"{where}: {name}: expected a column name, got {spec!r}")
    col, star, factor = spec.partition("*")
    col = col.strip()
    if not col:
        raise ValueError(f"{where}: {name}: empty column in {spec!r}")
    if not star:
        return col, 1.0
    try:
        f = float(factor)
    except ValueError:
        raise ValueError(f"{where}: {name}: factor {factor.strip()!r} is not a number") from None
    if not np.isfinite(f) or f == 0:
        raise ValueError(f"{where}: {name}: factor must be finite and non-zero, got {f!r}")
    return col, f


def parse_column_map(spec, where: str = "map") -> dict[str, tuple[str, float]]:
    """``{name: (column, factor)}`` from text, a JSON file's path or a dict (module doc);
    None or "" gives {}. ValueError naming ``where`` and the bad item."""
    if spec is None or (isinstance(spec, str) and not spec.strip()):
        return {}
    if isinstance(spec, (str, Path)) and str(spec).lower().endswith(".json"):
        path = Path(spec)
        if not path.is_file():
            raise ValueError(f"{where}: no such JSON file {str(path)!r}")
        try:
            spec = json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{where}: {path}: corrupt JSON ({exc})") from None
        if not isinstance(spec, dict):
            raise ValueError(f"{where}: {path}: expected a JSON object of name -> column")
        where = f"{where}: {path}"
    if isinstance(spec, dict):
        items = list(spec.items())
    elif isinstance(spec, str):
        items = []
        for item in (s.strip() for s in spec.split(",")):
            if not item:
                continue
            if "=" not in item:
                raise ValueError(f"{where}: expected name=column, got {item!r}")
            k, v = item.split("=", 1)
            items.append((k.strip(), v.strip()))
    else:
        raise ValueError(f"{where}: expected text, a .json path or a dict, got "
                         f"{type(spec).__name__}")
    out = {}
    for k, v in items:
        if k in out:
            raise ValueError(f"{where}: {k!r} mapped twice")
        out[k] = _entry(k, v, where)
    return out


def apply_column_map(columns: list[str], data: np.ndarray, mapping: dict, where: str):
    """(columns, data) with the map applied (module doc). ``mapping`` from
    :func:`parse_column_map`; ValueError naming a column the record lacks."""
    if not mapping:
        return list(columns), data
    index = {c: j for j, c in enumerate(columns)}
    for name, (col, _) in mapping.items():
        if col not in index:
            raise ValueError(f"{where}: map: column {col!r} (for {name}) not in the record; "
                             f"columns: {', '.join(columns)}")
    used = {col for col, _ in mapping.values()}
    keep = [c for c in columns if c not in used and c not in mapping]
    new_cols = list(mapping) + keep
    parts = [data[:, index[col]] * f if f != 1.0 else data[:, index[col]]
             for col, f in mapping.values()]
    parts += [data[:, index[c]] for c in keep]
    return new_cols, np.column_stack(parts) if parts else data[:, :0]


def split_missing(data: np.ndarray, columns: list[str], protected: list[str]):
    """The ``nan="split"`` policy on (N, C) ``data``: (rows kept, bool (N,); indices of the
    columns kept; names of the columns dropped). ``protected``: the selected columns (all when
    empty)."""
    finite = np.isfinite(data)
    prot = [columns.index(c) for c in protected] if protected else list(range(len(columns)))
    pset = set(prot)
    keep_cols = [j for j in range(len(columns)) if j in pset or finite[:, j].all()]
    dropped = [columns[j] for j in range(len(columns)) if j not in keep_cols]
    rows = finite[:, prot].all(axis=1) if prot else np.ones(len(data), bool)
    return rows, keep_cols, dropped


def kept_segments(rows: np.ndarray, seams) -> list[list[int]]:
    """[start, stop) ranges, over the kept rows only, of the runs of kept rows (``rows`` bool
    (N,)) that neither a dropped row nor a seam of ``seams`` ((start, stop) ranges tiling 0..N)
    interrupts."""
    rows = np.asarray(rows, bool)
    brk = np.zeros(rows.size, bool)
    for a, _ in seams:
        brk[a] = True
    out, pos, start, prev_ok = [], 0, None, False
    for i, ok in enumerate(rows):
        if ok and (start is None or brk[i] or not prev_ok):
            if start is not None:
                out.append([start, pos])
            start = pos
        if ok:
            pos += 1
        prev_ok = bool(ok)
    if start is not None:
        out.append([start, pos])
    return out


def check_segments(segments, n: int, where: str = "segments") -> list[tuple[int, int]]:
    """[start, stop) row ranges that tile 0..n (ValueError naming the first bad one)."""
    if not isinstance(segments, (list, tuple)) or not segments:
        raise ValueError(f"{where}: expected a non-empty list of [start, stop] row ranges")
    out, pos = [], 0
    for k, s in enumerate(segments):
        if not (isinstance(s, (list, tuple)) and len(s) == 2 and
                all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in s)):
            raise ValueError(f"{where}[{k}]: expected [start, stop] integers, got {s!r}")
        a, b = int(s[0]), int(s[1])
        if a != pos or b <= a:
            raise ValueError(f"{where}[{k}]: [{a}, {b}] does not continue the tiling at row {pos}")
        out.append((a, b))
        pos = b
    if pos != n:
        raise ValueError(f"{where}: cover {pos} rows, the record has {n}")
    return out


def _gap_intervals(gaps, where: str) -> list[tuple[float, float]]:
    """(start, end) of every declared gap: a list of {"start", "end"} objects, or an object of
    such lists (per source or column)."""
    if isinstance(gaps, dict):
        groups = list(gaps.items())
    elif isinstance(gaps, list):
        groups = [(None, gaps)]
    else:
        raise ValueError(f"{where}: sidecar field 'gaps': expected a list of {{start, end}} "
                         f"objects or an object of such lists, got {type(gaps).__name__}")
    out = []
    for key, items in groups:
        name = "gaps" if key is None else f"gaps.{key}"
        if not isinstance(items, list):
            raise ValueError(f"{where}: sidecar field {name!r}: expected a list, got "
                             f"{type(items).__name__}")
        for k, g in enumerate(items):
            s = g.get("start") if isinstance(g, dict) else None
            e = g.get("end") if isinstance(g, dict) else None
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
                       for v in (s, e)) or not e > s:
                raise ValueError(f"{where}: sidecar field '{name}[{k}]': expected "
                                 f"{{\"start\": s, \"end\": s}} with finite start < end, "
                                 f"got {g!r}"[:300])
            out.append((float(s), float(e)))
    return out


def gap_cuts(meta: dict, t: np.ndarray, where: str):
    """The declared gaps of a record (module doc) on its times ``t`` (N,): (rows kept, bool
    (N,); [start, stop) ranges, over the kept rows, of the pieces between seams, gaps and the
    existing ``meta["segments"]``). ValueError naming the field when the sidecar's
    ``gapless_rows`` or ``gaps`` is malformed."""
    t = np.asarray(t, np.float64)
    n = t.size
    keep = np.ones(n, bool)
    cut = np.zeros(n + 1, bool)
    cut[0] = True
    seg = meta.get("segments")
    if seg:
        for a, _ in check_segments(seg, n, f"{where}: sidecar field 'segments'"):
            cut[a] = True
    rows = meta.get("gapless_rows")
    if rows is not None:
        if not isinstance(rows, list):
            raise ValueError(f"{where}: sidecar field 'gapless_rows': expected a list of "
                             f"[start, stop] row ranges, got {type(rows).__name__}")
        covered, pos = np.zeros(n, bool), 0
        for k, r in enumerate(rows):
            if not (isinstance(r, list) and len(r) == 2 and
                    all(isinstance(v, int) and not isinstance(v, bool) for v in r)
                    and pos <= r[0] < r[1] <= n):
                raise ValueError(f"{where}: sidecar field 'gapless_rows[{k}]': expected "
                                 f"[start, stop] rows in increasing order within 0..{n}, "
                                 f"got {r!r}"[:300])
            covered[r[0]:r[1]] = True
            cut[r[0]] = True
            pos = r[1]
        keep &= covered
    if meta.get("gaps") is not None:
        for s, e in _gap_intervals(meta["gaps"], where):
            keep &= ~((t > s) & (t < e))
            j = int(np.searchsorted(t, e, side="left"))     # first row at or after the end
            if 0 < j < n:
                cut[j] = True
    seams = np.flatnonzero(cut[:n])
    bounds = list(zip(seams.tolist(), np.r_[seams[1:], n].tolist()))
    return keep, kept_segments(keep, bounds)
