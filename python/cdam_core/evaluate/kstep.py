"""k-step-ahead prediction of a dynamic (NARX-type) model, from its one-step predictor only.

The k-step-ahead prediction of y(t) uses the measured outputs up to t - k and the inputs up to
t (the logged inputs are known); the model's own predictions fill the outputs t-k+1 .. t-1. It
lies between one-step prediction (k = 1, every lag measured) and free-run simulation (k = the
record length), and is the standard compromise for marginally stable plants such as a
quadrotor's attitude and position, which integrate torque and thrust.

:func:`k_step_predict` is the protocol's ``predict(U, Y, mode="k_step", k=k)``
(:mod:`cdam_core.models.protocol`: every target sample t gets its own window of t0 + k rows,
and the k steps of all windows run together, one vectorised one-step call per step).
"""
from __future__ import annotations

import numpy as np

__all__ = ["k_step_predict", "horizon_steps"]


def horizon_steps(horizon_s: float, rate: float) -> int:
    """Steps k of a horizon in seconds at ``rate`` Hz (rounded; ValueError below one step)."""
    h, r = float(horizon_s), float(rate)
    if not (np.isfinite(h) and h > 0):
        raise ValueError(f"horizon_s: must be positive and finite, got {horizon_s!r}")
    if not (np.isfinite(r) and r > 0):
        raise ValueError(f"rate: must be positive and finite, got {rate!r}")
    k = int(round(h * r))
    if k < 1:
        raise ValueError(f"horizon_s: {h:g} s is less than one sample at {r:g} Hz")
    return k


def k_step_predict(model, U, Y, k: int) -> np.ndarray:
    """k-step-ahead predictions (N, m) of ``model`` on inputs U (N, i) and outputs Y (N, m).

    Rows t < t0 + k - 1 (too little history for a k-step prediction) are the measured Y, as
    the first t0 rows are in one-step and free-run predictions; drop them before scoring.
    k = 1 equals the model's one-step prediction.
    """
    # shapes, NaN and k are checked by the protocol's predict
    if not getattr(model, "dynamic", False):
        raise ValueError("model: k-step prediction needs a dynamic (NARX-type) model")
    return model.predict(U, Y, mode="k_step", k=k)
