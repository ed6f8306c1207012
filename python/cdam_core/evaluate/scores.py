"""Scoring a fitted model on a record: per-output metrics one-step, k-step and free run."""
from __future__ import annotations

import numpy as np

from cdam_core.base.metrics import output_metrics
from cdam_core.models.protocol import Model, segment_bounds
from cdam_core.preprocess import smooth_pair

__all__ = ["evaluate"]


def evaluate(model: Model, U, Y, names=None, *, smoothing_passes: int = 0, k: int | None = None,
             segments=None) -> dict:
    """Per-output metrics of a fitted model of any kind on a record (U, Y).

    The record is smoothed like the training data (``smoothing_passes``, each segment on its
    own), and the metrics
    compare the back-normalised predictions with these preprocessed measurements (as the
    paper does). Returns {"one_step": {name: {r, rmse, nrmse, fit_percent}}}, and for dynamic
    models "free_run" and, with ``k``, "k_step"; the measured rows every segment starts from
    (t0, and t0 + k - 1 for k-step) are left out of the scores.
    """
    bounds = segment_bounds(segments, len(Y))
    parts = [smooth_pair(U[a:b], Y[a:b], smoothing_passes) for a, b in bounds]  # per segment
    U, Y = np.vstack([u for u, _ in parts]), np.vstack([y for _, y in parts])
    t0 = model.t0
    modes = [("one_step", 1)]
    if model.dynamic:
        modes.append(("free_run", 1))
        if k is not None:
            modes.append(("k_step", int(k)))
    out = {}
    for mode, kk in modes:
        P = model.predict(U, Y, mode=mode, k=kk, segments=segments)
        if not np.all(np.isfinite(P)):
            raise ValueError(f"model: the {mode} prediction diverged (NaN or Inf)")
        skip = t0 + (kk - 1 if mode == "k_step" else 0)
        keep = np.zeros(len(Y), bool)
        for a, b in bounds:
            keep[a + skip:b] = True
        out[mode] = output_metrics(Y[keep], P[keep], names)
    return out
