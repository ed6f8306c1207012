"""Free runs of an IDIM fit: the residual loop's simulations, through the grey-box model kind.

There is one integrator of the grey-box equations, :class:`~cdam_core.models.greybox.augmented.
GreyBox`'s (semi-implicit Euler, substeps per sample, every window at once); a fit is simulated
by turning it into that model (:meth:`GreyBox.from_fit`).
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.signals import as_signal, as_time
from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.models.greybox.estimation import Fit, apply_effects

__all__ = ["simulate", "free_run_error"]


def simulate(fitted: Fit, t, inputs: dict, x0=None, v0=None, extra: dict | None = None,
             substeps: int | None = None, precomputed: dict | None = None) -> dict:
    """Free-run the fitted model from ``inputs`` alone; returns ``{position: array}``.

    ``x0`` and ``v0`` are the initial positions and velocities (default: first input-record
    values given in ``inputs`` for positions, zero velocity). ``precomputed`` maps an effect
    key to ``{parameter: column}`` over the same samples, for effects whose columns need the
    whole record (``arm_coupling``: evaluated from the measured signals). ``substeps``: per
    sample (default: the model's, from its fastest linearised mode).
    """
    model = fitted.model
    t = as_time(t)
    n = t.size
    if n < 2:
        raise ValueError("t: need at least 2 samples to simulate")
    cols = []
    for name in model.inputs:
        if name not in inputs:
            raise ValueError(f"inputs: missing {name!r}")
        cols.append(as_signal(inputs[name], f"inputs[{name}]", n))
    extra = dict(extra or {})
    for k, v in extra.items():
        cols.append(as_signal(v, f"extra[{k}]", n))
    npos = len(model.positions)
    if x0 is None:
        x0 = [float(as_signal(inputs[p], p)[0]) if p in inputs else 0.0 for p in model.positions]
    x = np.array(x0, dtype=float).reshape(1, npos)
    v = np.zeros((1, npos)) if v0 is None else np.array(v0, dtype=float).reshape(1, npos)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
        raise ValueError("x0/v0: not finite")
    dt = float(np.mean(np.diff(t)))
    g = GreyBox.from_fit(fitted, dt, extra_columns=tuple(extra))
    if substeps is not None:
        if int(substeps) < 1:
            raise ValueError("substeps: must be >= 1")
        g.substeps_ = int(substeps)
    U = np.column_stack(cols)
    Y = np.zeros((n, npos))
    Y[0] = x[0]
    pre = {key: {c: np.asarray(col, dtype=float) for c, col in d.items()}
           for key, d in (precomputed or {}).items()}
    path = g._rollout(U, Y, np.array([0]), n - 1, True, x, v, pre=pre, t_start=float(t[0]))
    out = np.vstack([x, path[:, 0, :]])
    return {p: out[:, i] for i, p in enumerate(model.positions)}


def free_run_error(fitted: Fit, sig: dict, substeps: int | None = None) -> tuple[dict, dict]:
    """Simulate over the record of ``sig`` and compare with the measured positions.

    The simulation starts at sample ``fitted.keep.start`` (after the derivative filter's edge).
    Models with a ``free_run_window`` (s) (the flight models: a quadrotor is a chain of
    integrators flown in closed loop, so a 10 s open-loop run only drifts) are simulated in
    consecutive windows of that length, each started from the filtered measured state.
    Returns (``{position: {"rmse", "nrmse"}}`` with nrmse = rmse / std(measured), simulated).
    """
    model = fitted.model
    n = sig["t"].size
    keep = fitted.keep
    k0 = min(keep.start if isinstance(keep, slice) else int(keep[0]), n - 3)
    s_eff = apply_effects(model, sig, fitted.effects)
    pre_all = {e.key: e.columns(s_eff) for e in fitted.effects if hasattr(e, "columns")}
    window = getattr(model, "free_run_window", None)
    step = n - k0 if window is None else max(3, int(round(window / sig["dt"])))
    sim = {p: np.empty(n - k0) for p in model.positions}
    for a in range(k0, n, step):
        b = min(a + step, n)
        if b - a < 3:   # a tail too short to simulate keeps the measured value
            for p in model.positions:
                sim[p][a - k0:] = sig[p][a:b]
            break
        x0 = [sig[p][a] for p in model.positions]
        v0 = [sig[p + "_d"][a] for p in model.positions]
        part = simulate(fitted, sig["t"][a:b], {u: sig[u][a:b] for u in model.inputs}, x0=x0,
                        v0=v0, extra={k: v[a:b] for k, v in sig.get("extra", {}).items()},
                        substeps=substeps,
                        precomputed={key: {c: col[a:b] for c, col in cols.items()}
                                     for key, cols in pre_all.items()})
        for p in model.positions:
            sim[p][a - k0:b - k0] = part[p]
    out = {}
    for p in model.positions:
        e = sim[p] - sig[p + "_raw"][k0:]
        sd = float(np.std(sig[p + "_raw"][k0:]))
        rmse = float(np.sqrt(np.mean(e ** 2)))
        out[p] = {"rmse": rmse, "nrmse": rmse / sd if sd > 0 else float("nan")}
    return out, sim
