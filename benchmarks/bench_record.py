"""Reading a dataset CSV (30,000 rows x 15 columns, the size of a 30 s, 1 kHz record):
record.dataset.read_dataset (checks, sidecar, segments) against pandas.read_csv of the same
file, the fairest reference (the reader most users would otherwise write), in the same run.
Formerly a 1 s limit inside a behaviour test (tests/record/test_dataset.py), where a loaded
machine made it fail: the speed lives here, the round trip stays a test."""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np


def read_csv() -> dict:
    import pandas as pd

    from cdam_core.record.dataset import Dataset, read_dataset, write_dataset
    rng = np.random.default_rng(0)
    n = 30_000
    ds = Dataset(t=np.arange(n) * 1e-3, columns=[f"c{i}" for i in range(14)],
                 data=rng.standard_normal((n, 14)))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "big.csv"
        write_dataset(p, ds)
        best, ref = float("inf"), float("inf")
        for _ in range(5):
            t0 = time.perf_counter()
            read_dataset(p)
            best = min(best, time.perf_counter() - t0)
            t0 = time.perf_counter()
            pd.read_csv(p).to_numpy(dtype=float)
            ref = min(ref, time.perf_counter() - t0)
    return {"seconds": best, "reference_seconds": ref, "ratio": ref / best,
            "reference": "pandas.read_csv(...).to_numpy() of the same file",
            "rows": n, "columns": 15}


BENCHMARKS = {"read_csv": read_csv}

if __name__ == "__main__":
    print(read_csv())
