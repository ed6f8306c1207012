"""[speed] item 5: one LM epoch on the 50-step rollout error of the physics + network flight
model (kind quad_hybrid) over the nano-drone flights (about 60,000 samples: every flight but the
multisine ones, windows of 50 steps, one every 50 samples, so every sample is in one window).

Core: ``_core.kstep_train_lm`` (cdam/host/kstep.hpp) on 1 and 2 threads, a run of 3 epochs / 3
(each epoch: the sensitivities and J'J, the solves, the trial passes; the run's last evaluation
is a gradient only). Fairest numpy reference (same process, BLAS pinned to the same thread
count): the sensitivities carried forward vectorised over a chunk of windows (100 at a time, so
J stays in cache-sized pieces), J'J by one BLAS SYRK per chunk (scipy dsyrk), J'e by GEMV,
Cholesky by LAPACK; trainlm's loop. Bound: the J'J's FLOPs (rows x D x (D + 1): the lower
triangle with the diagonal, a multiply-add counted as 2) at numpy's DGEMM rate measured in this
run (1 core; 2 cores for the 2-thread figure).

Measured here (AMD EPYC, AVX2 kernels, 2 cores shared, load 9-12; the chosen structure: 8 units,
6 lags, 203 weights): 0.38 s per epoch on 1 thread (CPU time) against 0.72 s for the numpy
reference (1.9x), 2.6x the bound of 0.145 s (7.2 GFLOP at 49.6 GFLOP/s); 2 threads 1.64 s wall
at load 10-12 (each thread got a fraction of a core); the same bits at 1 and 2 threads.

``kstep_anchored_epoch``: the same on the ARX-anchored model (models.arx_kstep.ArxKStep: 13
states, a linear part of 2 lags, 357 weights) over all 17 flights (88,099 samples, 863 windows
of 50 steps): 2.49 s per epoch on 1 thread (numpy 6.34 s, 2.5x; 1.86x the bound of 1.34 s),
1.24 s on 2 threads (session 21, load 1.5). Before the sensitivity products were tiled
(kstep_kernels.hpp) 3.84 s (1.8x numpy, 2.83x the bound): the plain loops of G (I + A)^T took
46 % of an epoch, the J'J 38 %."""
from __future__ import annotations

import glob

import numpy as np
import scipy.linalg
from scipy.linalg.blas import dsyrk


def _problem():
    from cdam_core.models.flight.hybrid import QuadHybrid
    from cdam_core.record.realdata import shared_data_dir
    from cdam_core.record.realdata.nanodrone import load_nanodrone, trajectory_type
    from cdam_core.record.stack import stack_records

    files = sorted(glob.glob(str(shared_data_dir() / "nanodrone" / "*.parquet")))
    st = stack_records([load_nanodrone(f) for f in files if trajectory_type(f) != "multisine"])
    K = 50
    m = QuadHybrid(horizon=K, epochs=0).fit(st.U, st.Y, segments=st.lengths)
    bounds = np.cumsum([0] + list(st.lengths))
    t0 = m.t0
    rows = np.concatenate([np.arange(a + t0 - 1, b - 1) for a, b in zip(bounds[:-1], bounds[1:])])
    starts = np.concatenate([np.arange(a + t0 - 1, b - 1 - K, K)
                             for a, b in zip(bounds[:-1], bounds[1:])]).astype(np.int64)
    E, Dr = np.zeros((len(st.U), 3 * m.lags)), np.zeros((len(st.U), 3))
    E[rows], Dr[rows] = m._features(st.U, rows), m._drift(st.U, rows)
    S = np.ascontiguousarray(st.Y[:, 10:13])
    theta = np.random.default_rng(0).uniform(-0.3, 0.3, m.theta_.size)
    args = (S, E, Dr, starts, K, int(m.hidden), m.in_mean_, m.in_scale_, m.out_scale_,
            m.err_scale_)
    return theta, args, len(st.U)


def _normal_numpy(theta, args, chunk=100, lin=None):
    """(J'J lower, J'e, sse) by the vectorised sensitivities, a chunk of windows at a time."""
    from cdam_core.reference.kstep import kstep_jacobian
    S, E, Dr, starts = args[:4]
    D = theta.size
    jtj, jte, sse = np.zeros((D, D), order="F"), np.zeros(D), 0.0
    for c in range(0, starts.size, chunk):
        e, J = kstep_jacobian(theta, S, E, Dr, starts[c:c + chunk], *args[4:], lin=lin)
        jtj = dsyrk(1.0, J, beta=1.0, c=jtj, trans=1, lower=1, overwrite_c=1)
        jte += J.T @ e
        sse += float(e @ e)
    return jtj, jte, sse


def _mse_numpy(theta, args, lin=None):
    from cdam_core.reference.kstep import kstep_residuals
    e = kstep_residuals(theta, *args, lin=lin)
    return float(e @ e / e.size)


def _lm_numpy(theta0, args, epochs, mu=1e-3, lin=None, chunk=100):
    """trainlm's loop (no validation) on _normal_numpy; the last evaluation a gradient only."""
    theta = theta0.copy()
    mse = _mse_numpy(theta, args, lin)
    for epoch in range(epochs + 1):
        if epoch == epochs:
            break
        jtj, jte, _ = _normal_numpy(theta, args, chunk, lin)
        while mu <= 1e10:
            try:
                c = scipy.linalg.cho_factor(jtj + mu * np.eye(theta.size), lower=True)
                d = scipy.linalg.cho_solve(c, jte)
                mse2 = _mse_numpy(theta + d, args, lin)
            except np.linalg.LinAlgError:
                mse2 = np.inf
            if mse2 < mse:
                theta, mse, mu = theta + d, mse2, max(mu * 0.1, 1e-20)
                break
            mu *= 10.0
    return theta


def _anchored_problem():
    """The ARX-anchored k-step model (models.arx_kstep.ArxKStep) on all 17 nano-drone flights
    (88,099 samples) with the structure the cross-trajectory folds choose (8 units, 2 lags, 50
    steps, windows every 100 samples, the ARX (2, 3, 2) on physics features as the linear part):
    13 states, 357 weights."""
    from cdam_core.evaluate.crossfold import ANCHORED_BLIND, AnchoredFitter
    from cdam_core.models.arx_kstep import ArxKStep
    from cdam_core.record.realdata import shared_data_dir
    from cdam_core.record.realdata.nanodrone import load_nanodrone
    from cdam_core.record.stack import stack_records

    files = sorted(glob.glob(str(shared_data_dir() / "nanodrone" / "*.parquet")))
    st = stack_records([load_nanodrone(f) for f in files])
    outs = list(st.outputs)
    m = ArxKStep(narx=(2, 3, 2), features="physics", hidden=8, lags=2, horizon=50, epochs=0,
                 net_features="physics", weighting="base", stride=100,
                 groups=AnchoredFitter()._labels(outs),
                 blind=[outs.index(c) for c in ANCHORED_BLIND])
    m.fit(st.U, st.Y, segments=st.lengths)
    bounds = np.cumsum([0] + list(st.lengths))
    S, E, Dr, _, starts = m._windows(st.U, st.Y, list(zip(bounds[:-1], bounds[1:])))
    theta = np.random.default_rng(0).uniform(-0.3, 0.3, m.theta_.size)
    args = (S, E, Dr, starts, int(m.horizon), int(m.hidden), m.in_mean_, m.in_scale_,
            m.out_scale_, m.err_scale_)
    return theta, args, len(st.U), m._lin()


def _epoch(theta, args, n, lin=None, chunk=100, epochs=3) -> dict:
    """One LM epoch of the core (1 and 2 threads) against the numpy reference, and the bound."""
    from cdam_core import _core
    from timing import best_of, blas_threads, clock_for, dgemm_gflops

    K, D, ns = args[4], theta.size, args[0].shape[1]
    W = args[3].size
    rows = W * K * ns
    out = {}
    for t in (1, 2):
        clk = clock_for(t)
        core = best_of(lambda: _core.kstep_train_lm(theta, *args, epochs=epochs, threads=t,
                                                    lin=lin), 3, clk) / epochs
        with blas_threads(t):
            ref = best_of(lambda: _lm_numpy(theta, args, epochs, lin=lin, chunk=chunk), 1,
                          clk) / epochs
        out[t] = (core, ref)
    th1, h1 = _core.kstep_train_lm(theta, *args, epochs=epochs, threads=1, lin=lin)
    th2, h2 = _core.kstep_train_lm(theta, *args, epochs=epochs, threads=2, lin=lin)
    gf1, gf2 = dgemm_gflops(1), dgemm_gflops(2)
    flops = rows * D * (D + 1)
    return {
        "seconds": out[1][0], "reference": "numpy: vectorised sensitivities + dsyrk per chunk",
        "reference_seconds": out[1][1], "ratio": out[1][1] / out[1][0],
        "seconds_2_threads": out[2][0], "reference_seconds_2_threads": out[2][1],
        "ratio_2_threads": out[2][1] / out[2][0],
        "bound": "J'J FLOPs at DGEMM rate", "bound_seconds": flops / gf1 / 1e9,
        "over_bound": out[1][0] / (flops / gf1 / 1e9),
        "bound_seconds_2_threads": flops / gf2 / 1e9,
        "over_bound_2_threads": out[2][0] / (flops / gf2 / 1e9),
        "jtj_gflop_per_epoch": flops / 1e9, "samples": n, "windows": W, "horizon": K,
        "states": ns, "params": D, "residual_rows": rows, "dgemm_gflops_1_thread": gf1,
        "dgemm_gflops_2_threads": gf2,
        "same_bits_1_and_2_threads": bool(np.array_equal(th1, th2)
                                          and np.array_equal(h1["mse"], h2["mse"])),
    }


def kstep_epoch() -> dict:
    theta, args, n = _problem()
    return {**_epoch(theta, args, n), "target_2_threads_seconds": 1.0}


def kstep_anchored_epoch() -> dict:
    theta, args, n, lin = _anchored_problem()
    return _epoch(theta, args, n, lin=lin, chunk=20)


BENCHMARKS = {"kstep_epoch": kstep_epoch, "kstep_anchored_epoch": kstep_anchored_epoch}
