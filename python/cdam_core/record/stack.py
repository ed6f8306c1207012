"""Several records in one call, laid end to end as segments (no prediction crosses a seam).

Each record is read with the one dataset path (``read_dataset``: CSV or Parquet, column map,
missing-value policy) or, for the nano-drone benchmark's flights, ``load_nanodrone``; each of
its segments (``Dataset.segments``: pieces left between excluded or missing rows) becomes one
segment of the stack, so a model's ``fit``/``predict(..., segments=stack.lengths)`` never
joins two records or two pieces of one.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cdam_core.record.dataset import Dataset, read_dataset

__all__ = ["Stack", "stack_records", "LOADERS"]

LOADERS = ("dataset", "nanodrone")


@dataclass
class Stack:
    """Records end to end: ``U`` (N, i), ``Y`` (N, m), ``t`` (N,), ``lengths`` (segment
    lengths, summing to N), ``record`` (N,) index into ``names``, ``row`` (N,) row within its
    record as loaded, and the ``datasets`` themselves."""

    names: list[str]
    inputs: list[str]
    outputs: list[str]
    U: np.ndarray
    Y: np.ndarray
    t: np.ndarray
    lengths: list[int]
    record: np.ndarray
    row: np.ndarray
    datasets: list[Dataset] = field(default_factory=list)

    def pieces(self):
        """(start, stop) row ranges of the segments in the stack."""
        stops = np.cumsum(self.lengths)
        return list(zip((stops - self.lengths).tolist(), stops.tolist()))


def _load(path, inputs, outputs, mapping, nan, loader) -> Dataset:
    if loader == "nanodrone":
        from cdam_core.record.realdata.nanodrone import load_nanodrone
        if mapping:
            raise ValueError("map: the nanodrone loader maps its columns itself")
        return load_nanodrone(path)
    if loader != "dataset":
        raise ValueError(f"loader: unknown {loader!r}; use one of {', '.join(LOADERS)}")
    return read_dataset(path, inputs=inputs, outputs=outputs, mapping=mapping, nan=nan)


def stack_records(paths, inputs=None, outputs=None, *, mapping=None, nan: str = "error",
                  loader: str = "dataset") -> Stack:
    """Read every record of ``paths`` and stack them (module doc). ``inputs``/``outputs``:
    the columns (after the map); default the first record's selection, which every other
    record must then have. An item of ``paths`` may be a Dataset already loaded (named by its
    ``meta["path"]``). ValueError naming the record on any problem."""
    paths = [p if isinstance(p, Dataset) else Path(p) for p in paths]
    if not paths:
        raise ValueError("paths: no record given")
    sets, names = [], []
    for k, p in enumerate(paths):
        if isinstance(p, Dataset):
            ds, p = p, p.meta.get("path", f"record {k}")
        else:
            ds = _load(p, inputs, outputs, mapping, nan, loader)
        if k == 0:     # the first record's selection (names, or text resolved by it)
            inputs = ds.inputs if inputs is None or isinstance(inputs, str) else list(inputs)
            outputs = ds.outputs if outputs is None or isinstance(outputs, str) else list(outputs)
        if not inputs or not outputs:
            raise ValueError(f"{p}: no input or output columns selected")
        for c in list(inputs) + list(outputs):
            if c not in ds.columns:
                raise ValueError(f"{p}: no column {c!r} (columns: {', '.join(ds.columns)})")
        sets.append(ds)
        names.append(str(p))
    inputs, outputs = list(inputs), list(outputs)
    lengths, rec, row = [], [], []
    for k, ds in enumerate(sets):
        lengths += [b - a for a, b in ds.segments]
        rec.append(np.full(len(ds), k))
        row.append(np.arange(len(ds)))
    return Stack(names=names, inputs=inputs, outputs=outputs,
                 U=np.vstack([ds.select(inputs) for ds in sets]),
                 Y=np.vstack([ds.select(outputs) for ds in sets]),
                 t=np.concatenate([ds.t for ds in sets]), lengths=lengths,
                 record=np.concatenate(rec), row=np.concatenate(row), datasets=sets)
