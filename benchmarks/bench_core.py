"""Benchmarks of issue 2: one LM epoch, LM memory at 1e6 samples, smoothing."""
from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np


def _paper_problem(n=10_000, i=6, h=20, m=8, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, (n, i))
    T = np.tanh(X @ rng.uniform(-1, 1, (i, m))) + 0.1 * rng.standard_normal((n, m))
    theta = rng.uniform(-1, 1, i * h + h + h * m + m)
    return X, T, theta, h


def _best_of(fn, repeats=3):
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def _matmul_gflops(n=1500):
    a = np.random.default_rng(1).standard_normal((n, n))
    a @ a
    t = _best_of(lambda: a @ a, 3)
    return 2.0 * n**3 / t / 1e9


def lm_epoch() -> dict:
    from cdam_core import _core, reference

    X, T, theta, h = _paper_problem()
    n, i = X.shape
    m = T.shape[1]
    D = theta.size
    epochs = 3
    kw = dict(epochs=epochs, goal=0.0, mu=1e-3)
    t_core = _best_of(lambda: _core.train_lm(theta, X, T, h, "tansig", threads=2, **kw))
    t_ref = _best_of(lambda: reference.train_lm(theta, X, T, h, "tansig", **kw), 2)
    t_jtj = _best_of(lambda: _core.mlp_jtj(theta, X, T, h, "tansig", 2))
    # multiply-adds of one J'J: structured against forming J'J from J (n m D^2 / 2 with symmetry)
    ph = h * (i + 1)
    mac_structured = n * (ph * (ph + 1) / 2 + (h + 1) * ph + (h + 1) * (h + 2) / 2)
    mac_dense = n * m * D * (D + 1) / 2
    return {
        "ratio": t_ref / t_core,
        "seconds": t_core / (epochs + 1),
        "reference_seconds": t_ref / (epochs + 1),
        "epochs_timed": epochs,
        "jtj_seconds": t_jtj,
        "jtj_gflop": 2 * mac_structured / 1e9,
        "dense_jtj_gflop": 2 * mac_dense / 1e9,
        "jtj_gflops_achieved": 2 * mac_structured / t_jtj / 1e9,
        "machine_matmul_gflops": _matmul_gflops(),
    }


_MEM_CHILD = r"""
import json, resource, sys, numpy as np
from cdam_core import _core
n = int(sys.argv[1]); i, h, m = 6, 20, 8
rng = np.random.default_rng(0)
X = rng.uniform(-1, 1, (n, i)); T = np.empty((n, m))
W = rng.uniform(-1, 1, (i, m))
for k in range(0, n, 100000):
    T[k:k + 100000] = np.tanh(X[k:k + 100000] @ W)
theta = rng.uniform(-1, 1, i * h + h + h * m + m)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
import time; t = time.perf_counter()
_core.train_lm(theta, X, T, h, "tansig", epochs=1, threads=2)
secs = time.perf_counter() - t
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"peak_kib": after, "before_kib": before, "data_bytes": X.nbytes + T.nbytes, "seconds": secs}))
"""


def lm_memory() -> dict:
    n = 1_000_000
    out = subprocess.run([sys.executable, "-c", _MEM_CHILD, str(n)], capture_output=True, text=True, check=True)
    r = json.loads(out.stdout)
    extra = (r["peak_kib"] - r["before_kib"]) * 1024
    dense_j = n * 8 * 308 * 8
    return {
        # memory an explicit J would need, over the whole process's peak (data, Python included)
        "ratio": dense_j / (r["peak_kib"] * 1024),
        "seconds": r["seconds"],
        "samples": n,
        "peak_rss_mib": r["peak_kib"] / 1024,
        "data_mib": r["data_bytes"] / 2**20,
        "lm_extra_mib": extra / 2**20,
        "explicit_jacobian_mib": dense_j / 2**20,
    }


def smoothing() -> dict:
    from cdam_core import _core, reference
    from scipy.signal import savgol_filter

    y = np.random.default_rng(0).standard_normal((20_000, 14))
    passes = 10
    t_core = _best_of(lambda: _core.five_point_cubic_smooth(y, passes))
    t_ref = _best_of(lambda: reference.five_point_cubic_smooth(y, passes))

    def sg():
        z = y
        for _ in range(passes):
            z = savgol_filter(z, 5, 3, mode="interp", axis=0)
        return z

    t_sg = _best_of(sg)
    return {"ratio": t_ref / t_core, "seconds": t_core, "reference_seconds": t_ref,
            "savgol_seconds": t_sg, "ratio_vs_savgol": t_sg / t_core, "shape": list(y.shape),
            "passes": passes}


BENCHMARKS = {"lm_epoch": lm_epoch, "lm_memory": lm_memory, "smoothing": smoothing}
