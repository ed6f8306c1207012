"""Plain batch gradient-descent backpropagation (the baseline trainer), numpy reference.

For epoch 0, 1, ...: record the MSE; stop if mse <= goal ("goal"), epoch == epochs ("epochs")
or callback(epoch, mse) returns False ("cancelled"); otherwise theta -= lr * d MSE / d theta.
"""
from __future__ import annotations

import numpy as np

from cdam_core.reference._checks import integer, real
from cdam_core.reference.levenberg_marquardt import _cancelled
from cdam_core.reference.mlp import _prepare, mlp_mse_gradient


def train_gd(theta0, X, T, hidden: int, activation: str = "tansig", *, lr: float = 0.01,
             epochs: int = 1000, goal: float = 0.0, callback=None):
    """Train by batch gradient descent on the MSE; returns (theta, history).

    history : dict shaped like :func:`train_lm`'s: "mse" (float64, one entry per recorded
    epoch); "mu", "grad_norm", "val_mse" empty float64 arrays (not used by this trainer);
    "stop" ("goal", "epochs" or "cancelled"); "best_epoch" (the last recorded epoch index).
    ``callback(epoch, mse)`` is called after the stop tests; returning False stops.
    """
    th, x, t, h, _ = _prepare(theta0, X, T=T, hidden=hidden, outputs=None,
                              activation=activation)
    lr = real(lr, "lr", minimum=0.0, strict_min=True)
    epochs = integer(epochs, "epochs", minimum=0)
    goal = real(goal, "goal", minimum=0.0)
    if callback is not None and not callable(callback):
        raise ValueError(f"callback: must be callable, got {callback!r}")
    theta = th.copy()
    mses = []
    epoch = 0
    while True:
        mse, grad = mlp_mse_gradient(theta, x, t, h, activation)
        mses.append(mse)
        if mse <= goal:
            stop = "goal"
            break
        if epoch == epochs:
            stop = "epochs"
            break
        if callback is not None and _cancelled(callback, epoch, mse):
            stop = "cancelled"
            break
        theta = theta - np.asarray(lr, dtype=theta.dtype) * grad
        epoch += 1
    empty = np.empty(0, dtype=np.float64)
    history = {"mse": np.asarray(mses, dtype=np.float64), "mu": empty.copy(),
               "grad_norm": empty.copy(), "val_mse": empty.copy(),
               "stop": stop, "best_epoch": epoch}
    return theta, history
