"""The persistence baseline of ``cdam paper``: predict y(t) by the last measured y(t - k).

A model-free reference for the dynamic sections: one-step (k = 1) and k-step (k = the horizon
in samples) predictions are only informative where they beat persistence, since at a high
sampling rate consecutive samples of a smooth signal are almost perfectly correlated. Scored
like the models: per segment, the first k rows dropped (no earlier sample), segments pooled.
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.metrics import output_metrics
from cdam_core.evaluate.kstep import horizon_steps

__all__ = ["persistence"]


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
