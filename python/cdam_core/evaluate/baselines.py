"""Baselines: what a model's scores must beat to mean anything.

``persistence`` (``cdam paper``): predict y(t) by the last measured y(t - k). A model-free
reference for the dynamic sections: one-step (k = 1) and k-step (k = the horizon
in samples) predictions are only informative where they beat persistence, since at a high
sampling rate consecutive samples of a smooth signal are almost perfectly correlated. Scored
like the models: per segment, the first k rows dropped (no earlier sample), segments pooled.
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.metrics import output_metrics
from cdam_core.evaluate.kstep import horizon_steps
from cdam_core.evaluate.scores import evaluate
from cdam_core.models.arx import ArxModel
from cdam_core.preprocess import smooth_pair

__all__ = ["persistence", "naive_and_arx"]


def persistence(segments, names, rate: float, horizons=()) -> tuple[dict, dict]:
    """Persistence r etc. on a segmented record: ({mode: {output: metrics}},
    {mode: (measured, predicted)}) with modes "one_step" and "k_step_<h>s" per horizon h (s)."""
    if not segments:
        raise ValueError("segments: no segment given")
    steps = {"one_step": 1}
    for h in horizons:
        steps[f"k_step_{float(h):g}s"] = horizon_steps(h, rate)
    metrics, arrays = {}, {}
    for mode, k in steps.items():
        short = [s.name for s in segments if len(s.Y) <= k]
        if short:
            raise ValueError(f"segments: {', '.join(short)} have no more than {k} samples")
        Ym = np.vstack([s.Y[k:] for s in segments])
        Pm = np.vstack([s.Y[:-k] for s in segments])
        metrics[mode] = output_metrics(Ym, Pm, names)
        arrays[mode] = (Ym, Pm)
    return metrics, arrays


def naive_and_arx(U, Y, records: dict, names, *, narx=None, smoothing_passes: int = 0,
                  features: str = "raw") -> dict:
    """The references ``cdam identify`` prints beside a model's scores on each record, with the
    model's preprocessing (records smoothed ``smoothing_passes`` times):

    - ``naive``: one step, the last measured output y(t-1); free run, the training mean (no
      measured output is seen after the start, so its r is undefined: None);
    - ``arx``: a least-squares ``ArxModel`` fitted on the training record (U, Y) with the
      model's NARX orders (a static map: y(t) = B u(t) + c, orders (0, 1, 0)) and ``features``,
      scored by :func:`~cdam_core.evaluate.scores.evaluate` like the model.

    Returns {"arx_orders": [na, nb, nk], record: {"naive": {mode: metrics}, "arx": {mode:
    metrics}}} with modes "one_step" and "free_run" (``arx`` is {"error": why} when its free
    run diverges).
    """
    orders = tuple(narx) if narx is not None else (0, 1, 0)
    Us, Ys = smooth_pair(U, Y, smoothing_passes)
    arx = ArxModel(orders, features=features).fit(Us, Ys)
    mean = Ys.mean(axis=0)
    out = {"arx_orders": list(orders)}
    for name, (Ur, Yr) in records.items():
        _, Yp = smooth_pair(Ur, Yr, smoothing_passes)
        if len(Yp) < 3:
            raise ValueError(f"records: {name} has fewer than 3 samples")
        naive = {"one_step": output_metrics(Yp[1:], Yp[:-1], names),
                 "free_run": output_metrics(Yp, np.broadcast_to(mean, Yp.shape), names)}
        for m in naive["free_run"].values():
            m["r"] = None                                  # a constant: no correlation
        try:
            scores = evaluate(arx, Ur, Yr, names, smoothing_passes=smoothing_passes)
        except ValueError as exc:                  # a diverged free run: said, not scored
            scores = {"error": str(exc)}
        out[name] = {"naive": naive, "arx": scores}
    return out
