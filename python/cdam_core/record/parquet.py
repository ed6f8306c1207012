"""Tables in and out of Parquet (pyarrow) and pandas DataFrames, as (names, float64 array).

The dataset format in Parquet: one column per channel, ``t`` (or PlotJuggler's ``__time``)
first or anywhere (it is moved first), numbers (floats, integers, booleans as 0/1); the
metadata lives in the same JSON sidecar as for CSV (``FILE.json``). A column that is not numeric
(text, timestamps) is refused, naming it, unless ``drop_other`` (then it is left out and named
in the returned list). Writes are atomic (``base.jsonio.atomic_target``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cdam_core.base.jsonio import atomic_target

__all__ = ["frame_table", "read_parquet_frame", "read_parquet_table", "write_parquet_table"]

TIME_NAMES = ("t", "__time")


def frame_table(df, where: str = "dataframe", drop_other: bool = False):
    """(names with ``t`` first, (N, C) float64 array, names of non-numeric columns left out)
    from a pandas DataFrame. The time column is ``t`` or ``__time`` (or the index, when it is
    named so); any other index is ignored."""
    import pandas as pd

    if not isinstance(df, pd.DataFrame):
        raise ValueError(f"{where}: expected a pandas DataFrame, got {type(df).__name__}")
    if df.index.name in TIME_NAMES and not any(c in df.columns for c in TIME_NAMES):
        df = df.reset_index()
    names = [str(c) for c in df.columns]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ValueError(f"{where}: duplicate column name {dup!r}")
    tcol = [c for c in TIME_NAMES if c in names]
    if not tcol:
        raise ValueError(f"{where}: no time column 't' (or '__time'); columns: "
                         f"{', '.join(names[:12])}{' ...' if len(names) > 12 else ''}")
    if len(tcol) > 1:
        raise ValueError(f"{where}: both 't' and '__time' present; keep one")
    order = [tcol[0]] + [n for n in names if n != tcol[0]]
    cols, other = [], []
    for n in order:
        s = df[df.columns[names.index(n)]]
        if pd.api.types.is_bool_dtype(s) or pd.api.types.is_numeric_dtype(s):
            cols.append(n)
        elif n == tcol[0] or not drop_other:
            raise ValueError(f"{where}: column {n!r} is not numeric (dtype {s.dtype})")
        else:
            other.append(n)
    arr = np.empty((len(df), len(cols)), dtype=np.float64)
    for j, n in enumerate(cols):
        s = df[df.columns[names.index(n)]]
        arr[:, j] = s.to_numpy(dtype=np.float64, na_value=np.nan)
    return ["t"] + cols[1:], arr, other


def read_parquet_frame(path):
    """A Parquet file as a pandas DataFrame; ValueError naming the file when it is not a
    readable Parquet file or has no rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        df = pq.read_table(path).to_pandas()
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise ValueError(f"{path}: corrupt or unreadable Parquet file ({exc})") from None
    if len(df) == 0:
        raise ValueError(f"{path}: row 0: no data rows")
    return df


def read_parquet_table(path, drop_other: bool = True):
    """(names, array, non-numeric columns left out) of a Parquet file (see
    :func:`frame_table`); ValueError naming the file when it is not a readable Parquet file or
    has no rows."""
    path = Path(path)
    return frame_table(read_parquet_frame(path), str(path), drop_other=drop_other)


def write_parquet_table(path, names: list[str], arr: np.ndarray) -> None:
    """Write columns ``names`` of (N, C) ``arr`` to ``path`` (float64, no index), atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({n: pa.array(arr[:, j], type=pa.float64()) for j, n in enumerate(names)})
    with atomic_target(path) as tmp:
        pq.write_table(table, tmp)
