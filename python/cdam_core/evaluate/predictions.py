"""Every k-step prediction in long format (``cdam evaluate --predictions FILE.parquet``), so
anyone can score them with their own code.

One row per (record, start, horizon): ``record`` (the path as given), ``start`` (the row of the
last measured state within the record as loaded, i.e. after left-out rows), ``t_start`` (its
time, s), ``horizon`` (samples), ``t`` (the predicted sample's time), then the predicted outputs
under the record's own column names and units (the model's names, or, where ``--map`` renamed
a column, the record's column with the map's factor undone).
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.jsonio import atomic_target

__all__ = ["predictions_table", "write_predictions"]


def predictions_table(stack, collected, mapping=None):
    """A pyarrow Table from ``collected`` [(h, stacked target rows, predictions)]; ``mapping``
    the column map the records were read with ({name: (column, factor)})."""
    import pyarrow as pa

    mapping = mapping or {}
    names = [mapping[o][0] if o in mapping else o for o in stack.outputs]
    factors = [mapping[o][1] if o in mapping else 1.0 for o in stack.outputs]
    if not collected:
        raise ValueError("collected: no prediction to write")
    rec = np.concatenate([stack.record[idx] for _, idx, _ in collected])
    start = np.concatenate([idx - h for h, idx, _ in collected])
    hor = np.concatenate([np.full(idx.size, h, np.int32) for h, idx, _ in collected])
    tgt = np.concatenate([idx for _, idx, _ in collected])
    P = np.vstack([P for _, _, P in collected])
    order = np.lexsort((hor, start, rec))
    labels = pa.array(np.asarray(stack.names, dtype=object)[rec[order]].tolist(), pa.string())
    cols = {"record": labels, "start": pa.array(stack.row[start[order]], pa.int64()),
            "t_start": pa.array(stack.t[start[order]], pa.float64()),
            "horizon": pa.array(hor[order], pa.int32()),
            "t": pa.array(stack.t[tgt[order]], pa.float64())}
    for j, n in enumerate(names):
        cols[n] = pa.array(P[order, j] / factors[j], pa.float64())
    return pa.table(cols)


def write_predictions(path, stack, collected, mapping=None) -> None:
    """Write :func:`predictions_table` to ``path`` (Parquet), atomically."""
    import pyarrow.parquet as pq

    table = predictions_table(stack, collected, mapping)
    with atomic_target(path) as tmp:
        pq.write_table(table, tmp)
