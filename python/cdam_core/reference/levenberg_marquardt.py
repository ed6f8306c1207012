"""Levenberg-Marquardt training with MATLAB trainlm's semantics, numpy reference.

Each epoch forms J'J and J'e (e = T - Y) at theta, then solves (J'J + mu I) d = J'e by
Cholesky for growing mu until the training MSE falls (ALGORITHMS.md, "trainlm"). The exact
sequence below is shared with the C++ core so both produce the same per-epoch history::

    theta = theta0; mse = MSE(theta)
    if val: vbest = MSE_val(theta); best = theta; fails = 0; best_epoch = 0
    for epoch in 0, 1, 2, ...:
        JtJ, Jte at theta; gnorm = ||Jte||_2; record mse, mu, gnorm, val_mse
        stop in this order: mse <= goal; epoch == epochs; gnorm <= min_grad; mu >= mu_max;
                            val and fails >= max_fail; callback(epoch, mse) is False
        while mu <= mu_max:
            solve (JtJ + mu I) d = Jte (failed Cholesky = no improvement); mse2 = MSE(theta + d)
            if mse2 < mse: accept; mu = max(mu * mu_dec, 1e-20); break
            mu *= mu_inc
        if val: v = MSE_val(theta); v < vbest -> new best, fails = 0; v > vbest -> fails += 1
    return best if val else theta
"""
from __future__ import annotations

import numpy as np
import scipy.linalg

from cdam_core.reference._checks import common_dtype, float_array, integer, real, same_rows
from cdam_core.reference.mlp import _forward, _jacobian, _prepare

MU_FLOOR = 1e-20


def _mse(th, x, t, h, m, activation) -> float:
    e = t - _forward(th, x, h, m, activation)[0]
    return float(np.sum(e * e) / e.size)


def _cancelled(callback, epoch: int, mse: float) -> bool:
    """True when ``callback(epoch, mse)`` returns a false value other than None."""
    r = callback(epoch, mse)
    return r is not None and not bool(r)


def _solve(JtJ, Jte, mu):
    """Solve (JtJ + mu I) d = Jte by Cholesky; None when the factorisation fails."""
    A = JtJ + np.asarray(mu, dtype=JtJ.dtype) * np.eye(JtJ.shape[0], dtype=JtJ.dtype)
    try:
        c = scipy.linalg.cho_factor(A, lower=True, check_finite=True)
    except (np.linalg.LinAlgError, ValueError):
        return None
    d = scipy.linalg.cho_solve(c, Jte, check_finite=False)
    return d if np.all(np.isfinite(d)) else None


def _validation_set(X_val, T_val, x, t, dtype):
    if (X_val is None) != (T_val is None):
        missing = "T_val" if T_val is None else "X_val"
        raise ValueError(f"{missing}: X_val and T_val must be given together")
    if X_val is None:
        return None, None
    xv = float_array(X_val, "X_val", 2)
    tv = float_array(T_val, "T_val", 2)
    same_rows(xv, tv, "X_val", "T_val")
    if xv.shape[1] != x.shape[1]:
        raise ValueError(f"X_val: has {xv.shape[1]} columns, X has {x.shape[1]}")
    if tv.shape[1] != t.shape[1]:
        raise ValueError(f"T_val: has {tv.shape[1]} columns, T has {t.shape[1]}")
    dtype = common_dtype(np.empty(0, dtype), xv, tv)
    return xv.astype(dtype, copy=False), tv.astype(dtype, copy=False)


def train_lm(theta0, X, T, hidden: int, activation: str = "tansig", *, epochs: int = 1000,
             goal: float = 0.0, mu: float = 1e-3, mu_dec: float = 0.1, mu_inc: float = 10.0,
             mu_max: float = 1e10, min_grad: float = 1e-7, max_fail: int = 6,
             X_val=None, T_val=None, callback=None):
    """Train the network by Levenberg-Marquardt (trainlm semantics); returns (theta, history).

    Parameters follow MATLAB's trainlm defaults. With a validation set (X_val, T_val) the
    returned theta is the best-validation one; without it, the last one. ``callback(epoch, mse)``
    is called after the stop tests of each recorded epoch; returning False (not None) stops with
    "cancelled".

    history : dict
        "mse", "mu", "grad_norm", "val_mse" : float64 arrays, one entry per recorded epoch
        (val_mse is NaN without validation); "stop" : one of "goal", "epochs", "min_grad",
        "mu_max", "max_fail", "cancelled"; "best_epoch" : epoch of the returned weights (the
        last recorded epoch index without validation).
    """
    th, x, t, h, m = _prepare(theta0, X, T=T, hidden=hidden, outputs=None,
                              activation=activation)
    epochs = integer(epochs, "epochs", minimum=0)
    goal = real(goal, "goal", minimum=0.0)
    mu = real(mu, "mu", minimum=0.0, strict_min=True)
    mu_dec = real(mu_dec, "mu_dec", minimum=0.0, maximum=1.0, strict_min=True, strict_max=True)
    mu_inc = real(mu_inc, "mu_inc", minimum=1.0, strict_min=True)
    mu_max = real(mu_max, "mu_max", minimum=0.0, strict_min=True)
    min_grad = real(min_grad, "min_grad", minimum=0.0)
    max_fail = integer(max_fail, "max_fail", minimum=1)
    if callback is not None and not callable(callback):
        raise ValueError(f"callback: must be callable, got {callback!r}")
    xv, tv = _validation_set(X_val, T_val, x, t, th.dtype)
    val = xv is not None
    if val and xv.dtype != th.dtype:   # a float64 validation set promotes the whole run
        th, x, t = (a.astype(np.float64) for a in (th, x, t))

    theta = th.copy()
    mse = _mse(theta, x, t, h, m, activation)
    vbest = np.nan
    best, fails, best_epoch = theta, 0, 0
    if val:
        vbest = _mse(theta, xv, tv, h, m, activation)
    hist = {"mse": [], "mu": [], "grad_norm": [], "val_mse": []}
    v = vbest
    epoch = 0
    while True:
        J, Y = _jacobian(theta, x, h, m, activation)
        e = (t - Y).reshape(-1)
        JtJ, Jte = J.T @ J, J.T @ e
        del J
        gnorm = float(np.linalg.norm(Jte))
        hist["mse"].append(mse)
        hist["mu"].append(mu)
        hist["grad_norm"].append(gnorm)
        hist["val_mse"].append(v if val else np.nan)
        if mse <= goal:
            stop = "goal"
        elif epoch == epochs:
            stop = "epochs"
        elif gnorm <= min_grad:
            stop = "min_grad"
        elif mu >= mu_max:
            stop = "mu_max"
        elif val and fails >= max_fail:
            stop = "max_fail"
        elif callback is not None and _cancelled(callback, epoch, mse):
            stop = "cancelled"
        else:
            stop = None
        if stop is not None:
            break
        while mu <= mu_max:
            d = _solve(JtJ, Jte, mu)
            if d is not None:
                trial = theta + d
                mse2 = _mse(trial, x, t, h, m, activation)
                if mse2 < mse:
                    theta, mse = trial, mse2
                    mu = max(mu * mu_dec, MU_FLOOR)
                    break
            mu = mu * mu_inc
        if val:
            v = _mse(theta, xv, tv, h, m, activation)
            if v < vbest:
                vbest, best, fails, best_epoch = v, theta, 0, epoch + 1
            elif v > vbest:
                fails += 1
        epoch += 1

    history = {k: np.asarray(vals, dtype=np.float64) for k, vals in hist.items()}
    history["stop"] = stop
    history["best_epoch"] = best_epoch if val else epoch
    return (best.copy() if val else theta), history
