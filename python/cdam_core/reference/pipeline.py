"""The paper's pipeline (smooth, scale, optimise initial weights, LM) on the numpy twin alone.

What a numpy user would compose from the twin: five-point smoothing of U and Y, min-max
scaling, BOA / IBOA / CABC on the BP fitness (:mod:`.optimisers`), then the twin's BPNetwork
trained by LM from the optimiser's best weights. Tests compare ``cdam_core.identify.identify``
with it; benchmarks/bench_identify.py times it as the reference.
"""
from __future__ import annotations

import time

import numpy as np

from cdam_core.reference import optimisers as opt
from cdam_core.reference.narx import narx_regressors
from cdam_core.reference.network import BPNetwork
from cdam_core.reference.scaling import MinMaxScaler
from cdam_core.reference.smoothing import five_point_cubic_smooth

__all__ = ["identify_reference"]


def identify_reference(algo, U, Y, *, seed=0, hidden=20, activation="tansig", narx=None,
                       smoothing_passes=5, options=None, lm_epochs=50, lm_goal=0.003) -> dict:
    """{"model", "curve", "lm_mse", "seconds": {"optimise", "lm", "total"}} of one run."""
    t_start = time.perf_counter()
    U, Y = np.asarray(U, float), np.asarray(Y, float)
    if smoothing_passes:
        U = five_point_cubic_smooth(U, smoothing_passes)
        Y = five_point_cubic_smooth(Y, smoothing_passes)
    theta0, curve, t_opt = None, None, 0.0
    if algo != "bp":
        Us, Ys = MinMaxScaler().fit(U).transform(U), MinMaxScaler().fit(Y).transform(Y)
        if narx is None:
            X, T = Us, Ys
        else:
            na, nb, nk = narx
            X, T = narx_regressors(Us, Ys, na, nb, nk), Ys[max(na, nk + nb - 1):]
        t0 = time.perf_counter()
        f = opt.BpObjective(X, T, hidden, activation)
        res = getattr(opt, algo)(f, f.dim, seed=seed, options=options)
        t_opt = time.perf_counter() - t0
        theta0, curve = res["best"], np.asarray(res["curve"])
    t0 = time.perf_counter()
    net = BPNetwork(hidden=hidden, activation=activation, epochs=lm_epochs, goal=lm_goal,
                    narx=narx, seed=seed).fit(U, Y, theta0=theta0)
    t_lm = time.perf_counter() - t0
    return {"model": net, "curve": curve, "lm_mse": np.asarray(net.history_["mse"]),
            "seconds": {"optimise": t_opt, "lm": t_lm, "total": time.perf_counter() - t_start}}
