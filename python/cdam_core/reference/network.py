"""A BP network estimator written on the numpy twin alone (no C++, no package estimator).

It is what a numpy user would write around the twin kernels: min-max scaling fitted on the
training data, initial weights ``Rng(seed).uniform_array(D, -1, 1)``, Levenberg-Marquardt
(``train_lm``), NARX regressors for ``narx=(na, nb, nk)``; ``predict`` back-normalises. The
tests compare it with ``cdam_core.models.network.BPNetwork``; it shares no code with it.
"""
from __future__ import annotations

import math

import numpy as np

from cdam_core.reference.levenberg_marquardt import train_lm
from cdam_core.reference.mlp import mlp_forward
from cdam_core.reference.narx import narx_regressors, narx_simulate
from cdam_core.reference.rng import Rng
from cdam_core.reference.scaling import MinMaxScaler

__all__ = ["BPNetwork", "hidden_node_candidates"]


def hidden_node_candidates(n_inputs, n_outputs, a_values=range(1, 11)):
    """h = round-half-up(sqrt(i + m) + a) for each a, without repeats (the paper's rule)."""
    out = []
    for a in a_values:
        h = int(math.floor(math.sqrt(n_inputs + n_outputs) + a + 0.5))
        if h >= 1 and h not in out:
            out.append(h)
    return out


class BPNetwork:
    """One hidden layer, linear output, trained by LM on [-1, 1]-scaled data (numpy only)."""

    def __init__(self, hidden=20, activation="tansig", *, epochs=1000, goal=0.0, mu=1e-3,
                 max_fail=6, narx=None, seed=0):
        self.hidden, self.activation, self.epochs, self.goal = int(hidden), activation, epochs, goal
        self.mu, self.max_fail, self.seed = mu, max_fail, int(seed)
        self.narx = None if narx is None else tuple(int(v) for v in narx)

    @property
    def t0(self) -> int:
        if self.narx is None:
            return 0
        na, nb, nk = self.narx
        return max(na, nk + nb - 1)

    def fit(self, U, Y, theta0=None):
        U, Y = np.asarray(U, float), np.asarray(Y, float)
        if U.ndim == 1:
            U = U[:, None]
        if Y.ndim == 1:
            Y = Y[:, None]
        self.scaler_x_, self.scaler_y_ = MinMaxScaler().fit(U), MinMaxScaler().fit(Y)
        Us, Ys = self.scaler_x_.transform(U), self.scaler_y_.transform(Y)
        if self.narx is None:
            X, T = Us, Ys
        else:
            X, T = narx_regressors(Us, Ys, *self.narx), Ys[self.t0:]
        h, m = self.hidden, T.shape[1]
        D = X.shape[1] * h + h + h * m + m
        th0 = Rng(self.seed).uniform_array(D, -1.0, 1.0) if theta0 is None else np.asarray(theta0, float)
        self.theta_, self.history_ = train_lm(th0, X, T, h, self.activation, epochs=self.epochs,
                                              goal=self.goal, mu=self.mu, max_fail=self.max_fail)
        self.n_outputs_ = m
        return self

    def predict(self, U, Y=None, mode="one_step"):
        U = np.asarray(U, float)
        if U.ndim == 1:
            U = U[:, None]
        Us = self.scaler_x_.transform(U)
        if self.narx is None:
            Ys = mlp_forward(self.theta_, Us, self.hidden, self.n_outputs_, self.activation)
            return self.scaler_y_.inverse_transform(Ys)
        Y = np.asarray(Y, float)
        if Y.ndim == 1:
            Y = Y[:, None]
        t0 = self.t0
        if mode == "free_run":
            Ys0 = self.scaler_y_.transform(Y[:t0]) if t0 else np.zeros((0, self.n_outputs_))
            out = self.scaler_y_.inverse_transform(
                narx_simulate(self.theta_, Us, Ys0, self.hidden, self.activation, *self.narx))
        else:
            X = narx_regressors(Us, self.scaler_y_.transform(Y), *self.narx)
            Ys = mlp_forward(self.theta_, X, self.hidden, self.n_outputs_, self.activation)
            out = np.vstack([Y[:t0], self.scaler_y_.inverse_transform(Ys)])
        out[:t0] = Y[:t0]
        return out

    def score(self, U, Y, mode="one_step"):
        """Mean R^2 over outputs after the first t0 rows."""
        Y = np.asarray(Y, float)
        if Y.ndim == 1:
            Y = Y[:, None]
        P = self.predict(U, Y, mode=mode)[self.t0:]
        Yt = Y[self.t0:]
        ss_res = ((Yt - P) ** 2).sum(0)
        ss_tot = ((Yt - Yt.mean(0)) ** 2).sum(0)
        return float(np.mean(np.where(ss_tot > 0, 1 - ss_res / np.where(ss_tot > 0, ss_tot, 1), 0)))
