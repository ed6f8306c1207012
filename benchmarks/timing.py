"""Timing helpers shared by the benchmarks: best-of-N clocks, BLAS pinned to a thread count,
the machine's DGEMM rate, and what the machine is (CPU model, SIMD level, load)."""
from __future__ import annotations

import contextlib
import os
import time

import numpy as np


def best_of(fn, repeats=5, clock=time.perf_counter) -> float:
    """The least time of `repeats` calls of fn() on `clock` (perf_counter: wall; thread_time:
    CPU time of the calling thread, right for code that runs on that thread only)."""
    best = float("inf")
    for _ in range(repeats):
        t = clock()
        fn()
        best = min(best, clock() - t)
    return best


def clock_for(threads: int):
    """Thread CPU time on one thread (other jobs on the machine do not count), wall above."""
    return time.thread_time if threads == 1 else time.perf_counter


@contextlib.contextmanager
def blas_threads(n: int):
    """numpy's BLAS limited to n threads (threadpoolctl)."""
    from threadpoolctl import threadpool_limits
    with threadpool_limits(limits=n, user_api="blas"):
        yield


def dgemm_gflops(threads: int = 1, n: int = 1200, dtype=np.float64) -> float:
    """numpy's GEMM rate (GFLOP/s) on `threads` BLAS threads, measured now (dtype float32:
    the SGEMM rate)."""
    a = np.random.default_rng(1).standard_normal((n, n)).astype(dtype)
    b = a.T.copy()
    with blas_threads(threads):
        a @ b
        t = best_of(lambda: a @ b, 3, clock_for(threads))
    return 2.0 * n**3 / t / 1e9


def machine() -> dict:
    """CPU model, SIMD level (from /proc/cpuinfo's flags), cores and the load averages."""
    model, flags = "unknown", set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, val = line.partition(":")
                if key.strip() == "model name" and model == "unknown":
                    model = val.strip()
                elif key.strip() == "flags" and not flags:
                    flags = set(val.split())
    except OSError:
        pass
    simd = ("AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else
            "AVX" if "avx" in flags else "SSE2" if "sse2" in flags else "unknown")
    return {"cpu": model, "simd": simd, "fma": "fma" in flags, "cores": os.cpu_count(),
            "load_average": [round(x, 2) for x in os.getloadavg()]}
