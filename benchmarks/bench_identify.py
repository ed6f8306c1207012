"""IBOA-BP at the paper's size and the BP fitness throughput, core against the numpy reference.

iboa_bp: 10,000 samples, 6-20-8, g = 20, Tmax = 50, LM at most 50 epochs (goal 0, so all 50
run): wall time of the C++ pipeline and of the numpy reference pipeline (reference optimiser +
reference LM) in the same run. The reference LM forms the full 80,000 x 308 Jacobian per epoch,
so the reference pipeline runs LM for `REF_LM_EPOCHS` epochs and its LM time is scaled linearly
to 50 epochs (stated in the result).
fitness_eval: BP fitness evaluations per second (20 individuals per batch, 2 and 1 threads)
against the numpy forward pass; iboa_bp also reports the optimiser's own rate (which includes
BOA's one-individual-at-a-time evaluations).
Every figure carries the 1-minute load average when it was taken (the machine is shared) and,
for the core, the process CPU seconds next to the wall seconds.
"""
from __future__ import annotations

import os
import time
from types import SimpleNamespace

import numpy as np

REF_LM_EPOCHS = 3


def _data(n=10_000, seed=0):
    g = np.random.default_rng(seed)
    U = g.uniform(-1, 1, (n, 6))
    W = g.normal(size=(6, 8))
    Y = np.tanh(U @ W) + 0.1 * np.sin(np.cumsum(U, axis=0) * 0.01) @ g.normal(size=(6, 8)) * 0.1
    return U, Y


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def iboa_bp() -> dict:
    from cdam_core.identify import IdentifyConfig, identify
    U, Y = _data()
    cfg = IdentifyConfig(hidden=20, iterations=50, population=20, lm_epochs=50, lm_goal=0.0,
                         smoothing_passes=5)
    load = _load()
    c0 = time.process_time()
    run = identify("iboa", U, Y, seed=0, config=cfg)
    cpu = time.process_time() - c0
    ref_cfg = IdentifyConfig(hidden=20, iterations=50, population=20, lm_epochs=REF_LM_EPOCHS,
                             lm_goal=0.0, smoothing_passes=5)
    from cdam_core.reference.pipeline import identify_reference
    r = identify_reference("iboa", U, Y, seed=0, hidden=20, smoothing_passes=5,
                           options=ref_cfg.options("iboa"), lm_epochs=REF_LM_EPOCHS, lm_goal=0.0)
    ref = SimpleNamespace(seconds=r["seconds"], lm_mse=r["lm_mse"], curve=r["curve"])
    lm_epochs = max(1, len(run.lm_mse) - 1)
    ref_lm_50 = ref.seconds["lm"] / max(1, len(ref.lm_mse) - 1) * lm_epochs
    ref_total = ref.seconds["total"] - ref.seconds["lm"] + ref_lm_50
    return {"seconds": run.seconds["total"], "optimise_seconds": run.seconds["optimise"],
            "lm_seconds": run.seconds["lm"], "lm_epochs": lm_epochs, "cpu_seconds": cpu,
            "load_average": load, "evaluations": run.evaluations,
            "optimiser_evals_per_second": run.evaluations / run.seconds["optimise"],
            "reference_seconds_estimated": ref_total,
            "reference_optimise_seconds": ref.seconds["optimise"],
            "reference_lm_seconds_per_epoch": ref.seconds["lm"] / max(1, len(ref.lm_mse) - 1),
            "ratio": ref_total / run.seconds["total"],
            "optimiser_ratio": ref.seconds["optimise"] / run.seconds["optimise"],
            "same_curve": bool(np.allclose(run.curve, ref.curve, rtol=1e-9)),
            "paper_iboa_seconds": 2.4,
            "optimiser_faster_than_paper": run.seconds["optimise"] < 2.4}


def fitness_eval() -> dict:
    from cdam_core import _core
    from cdam_core.reference.optimisers import BpObjective
    U, Y = _data()
    g = np.random.default_rng(1)
    th = g.uniform(-1, 1, (20, 6 * 20 + 20 + 20 * 8 + 8))
    reps = 10
    load = _load()
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(reps):
        _core.bp_fitness(th, U, Y, 20, threads=2)
    core, core_cpu = time.perf_counter() - t0, time.process_time() - c0
    t1 = time.perf_counter()
    for _ in range(reps):
        _core.bp_fitness(th, U, Y, 20, threads=1)
    core1 = time.perf_counter() - t1
    f = BpObjective(U, Y, 20)
    t0 = time.perf_counter()
    for x in th:
        f(x)
    refs = time.perf_counter() - t0
    return {"seconds": core, "evals_per_second": reps * 20 / core,
            "cpu_ms_per_eval": core_cpu / (reps * 20) * 1e3, "load_average": load,
            "evals_per_second_1_thread": reps * 20 / core1,
            "reference_evals_per_second": 20 / refs, "ratio": (reps * 20 / core) / (20 / refs)}


BENCHMARKS = {"iboa_bp": iboa_bp, "fitness_eval": fitness_eval}

if __name__ == "__main__":
    for name, fn in BENCHMARKS.items():
        print(name, fn())
