"""The BP network as a scikit-learn-style estimator: scaling, initial weights, training, NARX.

`BPNetwork` runs on the C++ core; `cdam_core.reference.BPNetwork` is the same estimator on the
numpy twin (the kernels are the only difference), so tests can swap implementations.
"""
from __future__ import annotations

import math

import numpy as np

from cdam_core._validate import as_2d, finite_float, positive_int, same_rows

__all__ = ["BPNetwork", "hidden_node_candidates"]


def hidden_node_candidates(n_inputs: int, n_outputs: int, a_values=range(1, 11)) -> list[int]:
    """Hidden-node rule h = sqrt(i + m) + a, rounded half up, for each a (the paper's section 3.1)."""
    n_inputs = positive_int(n_inputs, "n_inputs")
    n_outputs = positive_int(n_outputs, "n_outputs")
    out = []
    for a in a_values:
        h = int(math.floor(math.sqrt(n_inputs + n_outputs) + a + 0.5))
        if h >= 1 and h not in out:
            out.append(h)
    if not out:
        raise ValueError("a_values: gives no hidden-node count >= 1")
    return out


class BPNetwork:
    """One-hidden-layer BP network (tansig or logsig hidden, linear output) on scaled data.

    Parameters follow MATLAB's trainlm (``epochs``, ``goal``, ``mu``, ``mu_dec``, ``mu_inc``,
    ``mu_max``, ``min_grad``, ``max_fail``); ``trainer="gd"`` is plain gradient-descent BP with
    learning rate ``lr``. ``hidden="auto"`` searches the rule h = sqrt(i + m) + a, a = 1..10, and
    keeps the lowest training MSE. ``narx=(na, nb, nk)`` makes a NARX model (lagged outputs and
    inputs as regressors). Inputs and outputs are min-max scaled to [-1, 1] on the training data;
    the MSE the trainers report is in those normalised units. Initial weights, when ``theta0`` is
    not given to ``fit``, are uniform in [-1, 1] drawn in flat order from ``Rng(seed)``. With
    ``validation_fraction`` > 0 the last part of the training record stops LM early (max_fail).
    """

    _backend = "core"

    def __init__(self, hidden=20, activation="tansig", trainer="lm", *, epochs=1000, goal=0.0,
                 mu=1e-3, mu_dec=0.1, mu_inc=10.0, mu_max=1e10, min_grad=1e-7, max_fail=6,
                 lr=0.01, validation_fraction=0.0, narx=None, seed=0, threads=2):
        if activation not in ("tansig", "logsig"):
            raise ValueError(f"activation: unknown {activation!r}; use 'tansig' or 'logsig'")
        if trainer not in ("lm", "gd"):
            raise ValueError(f"trainer: unknown {trainer!r}; use 'lm' or 'gd'")
        if hidden != "auto":
            hidden = positive_int(hidden, "hidden")
        self.hidden = hidden
        self.activation = activation
        self.trainer = trainer
        self.epochs = positive_int(epochs, "epochs", minimum=0)
        self.goal = finite_float(goal, "goal", minimum=0.0)
        self.mu = finite_float(mu, "mu", minimum=0.0, strict=True)
        self.mu_dec = finite_float(mu_dec, "mu_dec", minimum=0.0, strict=True)
        self.mu_inc = finite_float(mu_inc, "mu_inc", minimum=1.0, strict=True)
        self.mu_max = finite_float(mu_max, "mu_max", minimum=0.0, strict=True)
        self.min_grad = finite_float(min_grad, "min_grad", minimum=0.0)
        self.max_fail = positive_int(max_fail, "max_fail")
        self.lr = finite_float(lr, "lr", minimum=0.0, strict=True)
        self.validation_fraction = finite_float(validation_fraction, "validation_fraction", minimum=0.0)
        if self.validation_fraction >= 1.0:
            raise ValueError("validation_fraction: must be < 1")
        if narx is not None:
            if len(narx) != 3:
                raise ValueError(f"narx: expected (na, nb, nk), got {narx!r}")
            na, nb, nk = (positive_int(v, n, minimum=0) for v, n in zip(narx, ("na", "nb", "nk")))
            if na + nb < 1:
                raise ValueError("narx: na + nb must be >= 1")
            narx = (na, nb, nk)
        self.narx = narx
        self.seed = positive_int(seed, "seed", minimum=0)
        self.threads = positive_int(threads, "threads")

    # ---- the backend: the C++ core here, the numpy twin in cdam_core.reference ----
    @staticmethod
    def _kernels():
        from cdam_core import _core
        return _core

    @staticmethod
    def _scaler():
        from cdam_core.preprocess import MinMaxScaler
        return MinMaxScaler()

    def _train_kwargs(self, callback):
        return {"threads": self.threads, "callback": callback}

    # ---- helpers ----
    @property
    def t0(self) -> int:
        if self.narx is None:
            return 0
        na, nb, nk = self.narx
        return max(na, nk + nb - 1)

    def _design(self, Us, Ys):
        """Network inputs and targets from scaled signals (NARX regressors when narx is set)."""
        if self.narx is None:
            return Us, Ys
        na, nb, nk = self.narx
        if Us.shape[0] <= self.t0:
            raise ValueError(f"U: {Us.shape[0]} samples, NARX needs more than t0 = {self.t0}")
        return self._kernels().narx_regressors(Us, Ys, na, nb, nk), Ys[self.t0:]

    def _initial_theta(self, n_in, h, n_out, dtype):
        D = n_in * h + h + h * n_out + n_out
        return np.asarray(self._kernels().Rng(self.seed).uniform_array(D, -1.0, 1.0), dtype=dtype)

    # ---- estimator API ----
    def fit(self, U, Y, theta0=None, validation=None, callback=None) -> "BPNetwork":
        """Train on inputs U (N, i) and outputs Y (N, m).

        ``validation=(U_val, Y_val)`` early-stops LM (max_fail) and returns the best-validation
        weights; ``callback(epoch, mse)`` is called each epoch (return False to stop).
        """
        U = as_2d(U, "U")
        Y = as_2d(Y, "Y", dtype=U.dtype)
        same_rows(U, Y, "U, Y")
        val = None
        if validation is not None:
            if len(validation) != 2:
                raise ValueError("validation: expected (U_val, Y_val)")
            Uv = as_2d(validation[0], "U_val", dtype=U.dtype)
            Yv = as_2d(validation[1], "Y_val", dtype=U.dtype)
            same_rows(Uv, Yv, "U_val, Y_val")
            if Uv.shape[1] != U.shape[1] or Yv.shape[1] != Y.shape[1]:
                raise ValueError("validation: channel counts differ from U, Y")
            val = (Uv, Yv)
        elif self.validation_fraction > 0:
            n_val = int(round(U.shape[0] * self.validation_fraction))
            if n_val < 1 or U.shape[0] - n_val < 1:
                raise ValueError("validation_fraction: leaves no training or no validation samples")
            val = (U[-n_val:], Y[-n_val:])
            U, Y = U[:-n_val], Y[:-n_val]
        self.n_inputs_, self.n_outputs_ = U.shape[1], Y.shape[1]
        self.scaler_x_ = self._scaler().fit(U)
        self.scaler_y_ = self._scaler().fit(Y)
        X, T = self._design(self.scaler_x_.transform(U), self.scaler_y_.transform(Y))
        Xv = Tv = None
        if val is not None:
            Xv, Tv = self._design(self.scaler_x_.transform(val[0]), self.scaler_y_.transform(val[1]))
        candidates = (hidden_node_candidates(X.shape[1], T.shape[1]) if self.hidden == "auto"
                      else [self.hidden])
        best = None
        for h in candidates:
            if theta0 is not None and len(candidates) == 1:
                th0 = as_2d(np.ravel(theta0), "theta0", dtype=U.dtype)[:, 0]
                D = X.shape[1] * h + h + h * T.shape[1] + T.shape[1]
                if th0.shape[0] != D:
                    raise ValueError(f"theta0: expected length {D}, got {th0.shape[0]}")
            else:
                th0 = self._initial_theta(X.shape[1], h, T.shape[1], U.dtype)
            theta, hist = self._train(th0, X, T, h, Xv, Tv, callback)
            final = hist["mse"][-1]
            if best is None or final < best[0]:
                best = (final, h, theta, hist)
        _, self.hidden_, self.theta_, self.history_ = best
        return self

    def _train(self, theta0, X, T, h, Xv, Tv, callback):
        k = self._kernels()
        extra = self._train_kwargs(callback)
        if self.trainer == "gd":
            return k.train_gd(theta0, X, T, h, self.activation, lr=self.lr, epochs=self.epochs,
                              goal=self.goal, **extra)
        return k.train_lm(theta0, X, T, h, self.activation, epochs=self.epochs, goal=self.goal,
                          mu=self.mu, mu_dec=self.mu_dec, mu_inc=self.mu_inc, mu_max=self.mu_max,
                          min_grad=self.min_grad, max_fail=self.max_fail, X_val=Xv, T_val=Tv,
                          **extra)

    def _check_fitted(self):
        if getattr(self, "theta_", None) is None:
            raise ValueError("BPNetwork: not fitted; call fit(U, Y) first")

    def predict(self, U, Y=None, mode="one_step") -> np.ndarray:
        """Outputs (N, m) for inputs U (N, i), back-normalised.

        Static network: ``Y`` is ignored. NARX: ``mode="one_step"`` uses the measured past
        outputs ``Y`` (N, m); ``mode="free_run"`` feeds predictions back and needs only
        ``Y[:t0]``. In both NARX modes the first t0 rows are the measured ``Y[:t0]``.
        """
        self._check_fitted()
        U = as_2d(U, "U", dtype=self.theta_.dtype)
        if U.shape[1] != self.n_inputs_:
            raise ValueError(f"U: expected {self.n_inputs_} columns, got {U.shape[1]}")
        k = self._kernels()
        Us = self.scaler_x_.transform(U)
        if self.narx is None:
            Ys = k.mlp_forward(self.theta_, Us, self.hidden_, self.n_outputs_, self.activation)
            return self.scaler_y_.inverse_transform(Ys)
        if mode not in ("one_step", "free_run"):
            raise ValueError(f"mode: unknown {mode!r}; use 'one_step' or 'free_run'")
        if Y is None:
            raise ValueError("Y: a NARX model needs the measured outputs (at least the first t0 rows)")
        Y = as_2d(Y, "Y", dtype=self.theta_.dtype)
        if Y.shape[1] != self.n_outputs_:
            raise ValueError(f"Y: expected {self.n_outputs_} columns, got {Y.shape[1]}")
        na, nb, nk = self.narx
        t0 = self.t0
        if U.shape[0] <= t0:
            raise ValueError(f"U: {U.shape[0]} samples, NARX needs more than t0 = {t0}")
        if mode == "free_run":
            if Y.shape[0] < t0:
                raise ValueError(f"Y: free run needs the first t0 = {t0} rows, got {Y.shape[0]}")
            Ys0 = self.scaler_y_.transform(Y[:t0]) if t0 else np.zeros((0, self.n_outputs_), U.dtype)
            Ys = k.narx_simulate(self.theta_, Us, Ys0, self.hidden_, self.activation, na, nb, nk)
            out = self.scaler_y_.inverse_transform(Ys)
        else:
            same_rows(U, Y, "U, Y")
            X = k.narx_regressors(Us, self.scaler_y_.transform(Y), na, nb, nk)
            Ys = k.mlp_forward(self.theta_, X, self.hidden_, self.n_outputs_, self.activation)
            out = np.vstack([Y[:t0], self.scaler_y_.inverse_transform(Ys)])
        out[:t0] = Y[:t0]
        return out

    def score(self, U, Y, mode="one_step") -> float:
        """Coefficient of determination R^2, averaged over outputs (as scikit-learn)."""
        Y = as_2d(Y, "Y")
        P = self.predict(U, Y, mode=mode)[self.t0:]
        Yt = Y[self.t0:]
        ss_res = np.sum((Yt - P) ** 2, axis=0)
        ss_tot = np.sum((Yt - Yt.mean(axis=0)) ** 2, axis=0)
        r2 = np.where(ss_tot > 0, 1.0 - ss_res / np.where(ss_tot > 0, ss_tot, 1.0), 0.0)
        return float(np.mean(r2))
