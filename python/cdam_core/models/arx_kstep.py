"""A least-squares ARX with a recurrent network on the residual of its k-step rollout, trained by
the core's Levenberg-Marquardt on the multi-step error of every output: kind ``arx_kstep``.

The base is ``ArxModel`` (orders and features as given, least squares on the one-step
equation); the network adds to its one-step prediction, recurrently::

    y(t+1) = A_1 y(t) + .. + A_na y(t-na+1) + B f(..) + c + r o (W2 tanh(W1 x(t) + b1) + b2)
    x(t) = [(y(t) - m) / s, phi(t+1-nk), .., phi(t+1-nk-lags+1)]

phi: the inputs (``net_features="raw"``) or the physics features of four rotor speeds
(``"physics"``, ``arx.physics_features``), each less its training mean over its training std; nk the ARX's delay
(the network sees no input the ARX may not); m, s the outputs' training mean and std; r the std
of the ARX's one-step training residual per output (the network's output scale).

Training (``_core.kstep_train_lm`` with the ARX as its linear part, cpp/include/cdam/host/
kstep.hpp): windows of ``horizon`` steps from the measured outputs, one every ``stride`` samples
(default: the horizon), inside each record. The error of output i at step j is divided by the
RMS of the ARX's own k-step error on the training windows over the outputs of i's group
(``groups``: a group label per output, e.g. position, velocity, attitude, rates; default: each
output its own group): with ``weighting="base"`` at step j (so every horizon of every group
counts relative to the ARX there, as the target scores it); ``"flat"``: pooled over the steps
(every step alike). Nothing
is hand-picked: every scale comes from the training records.

The network's output layer starts at zero (W2 = 0, b2 = 0; W1, b1 uniform +-1/sqrt(inputs) from
``seed``), so the model starts exactly as the ARX and LM, which only accepts steps that lower
the training k-step error, can only lower it (``history_["mse"][0]`` is the ARX's).
"""
from __future__ import annotations

import numpy as np

from cdam_core import _core
from cdam_core.base.checks import finite_float, positive_int
from cdam_core.models.arx import FEATURES, ArxModel, physics_features
from cdam_core.models.protocol import Model
from cdam_core.models.schema import field_array

__all__ = ["ArxKStep", "WEIGHTINGS", "base_rollout_errors"]

WEIGHTINGS = ("flat", "base")
#: input scale of an output the network does not see (``blind``): its input is ~1e-12 of its
#: range, nothing the tanh layer can use (the core's network reads every state)
BLIND_SCALE = 1e12


def base_rollout_errors(S, Dr, lin, starts, K):
    """Errors (W, K, ns) of the linear recursion y(t+1) = y(t) + Dr(t) + sum_l L_l y(t-l) run K
    steps from the measured outputs at each start (the ARX's k-step error on the windows)."""
    ns = S.shape[1]
    na = lin.shape[1] // ns
    Ls = [lin[:, l * ns:(l + 1) * ns] for l in range(na)]
    hist = [S[starts - l] for l in range(na)][::-1]     # oldest first, the start last
    err = np.empty((starts.size, K, ns))
    for j in range(K):
        t = starts + j
        nxt = hist[-1] + Dr[t]
        for l in range(na):
            nxt = nxt + hist[-1 - l] @ Ls[l].T
        hist = hist[1:] + [nxt]
        err[:, j] = S[t + 1] - nxt
    return err


class ArxKStep(Model):
    """ARX + recurrent residual network trained on the k-step error (module doc).

    Args:
        narx: the ARX's (na, nb, nk), nk >= 1.
        features: the ARX's input features ("raw" or "physics").
        hidden: tanh units of the network.
        lags: input-feature lags the network sees.
        horizon: K, the steps of each training window.
        epochs: LM epochs at most.
        net_features: the network's input features ("raw" or "physics").
        weighting: "base" (each step's error over the ARX's at that step) or "flat".
        groups: a group label per output for the error scales (None: each output alone).
        blind: indices of outputs the network does not see (e.g. a flight's position: the
            dynamics do not depend on where the vehicle is, and a position outside the
            training range would only mislead the network); None: it sees every output.
        stride: samples between window starts (None: the horizon).
        seed: of the initial weights.
        threads: of the core's LM (the result does not depend on it).
        mu: LM's initial damping (large: short first steps from the ARX).
    """

    kind = "arx_kstep"
    fits_segments = True

    def __init__(self, narx=(2, 2, 1), features: str = "raw", hidden: int = 8, lags: int = 2,
                 horizon: int = 50, epochs: int = 10, net_features: str = "raw",
                 weighting: str = "base", groups=None, stride=None, seed: int = 0,
                 threads: int = 2, blind=None, mu: float = 1e-3):
        self.narx = narx
        self.features = features
        self.hidden = hidden
        self.lags = lags
        self.horizon = horizon
        self.epochs = epochs
        self.net_features = net_features
        self.weighting = weighting
        self.groups = groups
        self.stride = stride
        self.seed = seed
        self.threads = threads
        self.blind = blind
        self.mu = mu
        self._check_params()

    def _check_params(self) -> None:
        na, nb, nk = ArxModel(self.narx, self.features).orders
        if nk < 1:
            raise ValueError(f"narx: the delay nk must be >= 1 (got {nk}): the network's "
                             f"state enters one step later")
        positive_int(self.hidden, "hidden")
        positive_int(self.lags, "lags")
        positive_int(self.horizon, "horizon")
        positive_int(self.epochs, "epochs", minimum=0)
        positive_int(self.seed, "seed", minimum=0)
        positive_int(self.threads, "threads")
        if self.stride is not None:
            positive_int(self.stride, "stride")
        finite_float(self.mu, "mu", minimum=0.0, strict=True)
        if self.net_features not in FEATURES:
            raise ValueError(f"net_features: unknown {self.net_features!r}; use 'raw' or "
                             f"'physics'")
        if self.weighting not in WEIGHTINGS:
            raise ValueError(f"weighting: unknown {self.weighting!r}; use 'flat' or 'base'")
        if self.groups is not None and (np.ndim(self.groups) != 1 or len(self.groups) == 0):
            raise ValueError("groups: expected one group label per output")
        if self.blind is not None and np.ndim(self.blind) != 1:
            raise ValueError("blind: expected a list of output indices")

    # -- the parts -----------------------------------------------------------------------------
    @property
    def t0(self) -> int:
        na, nb, nk = ArxModel(self.narx).orders
        return max(ArxModel(self.narx).t0, nk + int(self.lags) - 1, 1)

    def _phi(self, U):
        """The network's input features (N, n), unscaled."""
        if self.net_features == "raw":
            return np.asarray(U, float)
        return physics_features(U, self.phi_input_scale_)[0]

    def _exo(self, Phi, rows):
        """E rows (len(rows), n lags): the features phi(t+1-nk-j), j = 0..lags-1, less their
        training mean, over their training std."""
        nk = ArxModel(self.narx).orders.nk
        return (np.concatenate([Phi[rows + 1 - nk - j] for j in range(int(self.lags))], axis=1)
                - self.feature_mean_) / self.feature_scale_

    def _unpack(self):
        H, ns = int(self.hidden), self.n_outputs_
        ni = ns + self.feature_scale_.size
        th = self.theta_
        W1 = th[:H * ni].reshape(ni, H).T
        b1 = th[H * ni:H * ni + H]
        o = H * ni + H
        return W1, b1, th[o:o + ns * H].reshape(H, ns).T, th[o + ns * H:]

    def _net(self, Yprev, E):
        W1, b1, W2, b2 = self._unpack()
        x = np.concatenate([(Yprev - self.in_mean_) / self.in_scale_, E], axis=1)
        return self.out_scale_ * (np.tanh(x @ W1.T + b1) @ W2.T + b2)

    def _lin(self):
        """L = [A_1 - I, A_2, ..]: the ARX's state dependence as the core's linear part."""
        na, m = self.arx_.orders.na, self.n_outputs_
        L = self.arx_.coef_[:na * m].T.copy()       # L[i, l m + k] = coef[l m + k, i]
        L[:, :m] -= np.eye(m)
        return np.ascontiguousarray(L)

    def _group_labels(self, m):
        if self.groups is None:
            return np.arange(m)
        g = np.asarray(self.groups)
        if g.size != m:
            raise ValueError(f"groups: {g.size} labels for {m} outputs")
        return np.unique(g, return_inverse=True)[1]

    # -- fit -----------------------------------------------------------------------------------
    def fit(self, U, Y, segments=None, validation=None):
        """``Model.fit``; ``validation`` = (U, Y, segments) of records held out of training:
        their k-step error is tracked by LM and the weights of the best validation epoch are
        kept (``history_["best_epoch"]``); None: every epoch's weights, the last kept."""
        self._validation = validation
        try:
            return super().fit(U, Y, segments)
        finally:
            self._validation = None

    def _windows(self, U, Y, bounds):
        """(S, E, Dr, rows, starts) of records laid end to end: outputs, the network's features
        (row t: for the step t -> t + 1), the ARX's input term B f + c (for the target t + 1,
        at row t), the rows with every regressor inside their record and the window starts."""
        m, K, t0, at0 = Y.shape[1], int(self.horizon), self.t0, self.arx_.t0
        stride = int(self.stride or K)
        rows = np.concatenate([np.arange(a + t0 - 1, b - 1) for a, b in bounds
                               if b - 1 > a + t0 - 1] or [np.zeros(0, int)])
        starts = np.concatenate([np.arange(a + t0 - 1, b - 1 - K, stride) for a, b in bounds
                                 if b - 1 - K > a + t0 - 1] or [np.zeros(0, int)])
        Phi = self._phi(U)
        if not hasattr(self, "feature_scale_"):
            sd = np.std(Phi[rows], axis=0)
            self.feature_scale_ = np.tile(np.where(sd > 0, sd, 1.0), int(self.lags))
            self.feature_mean_ = np.tile(np.mean(Phi[rows], axis=0), int(self.lags))
        E = np.zeros((U.shape[0], self.feature_scale_.size))
        E[rows] = self._exo(Phi, rows)
        Dr = np.zeros((U.shape[0], m))
        F = self.arx_._features(U)
        for a, b in bounds:
            if b - a > at0:
                Dr[a + at0 - 1:b - 1] = self.arx_._input_term(F[a:b])
        return np.ascontiguousarray(Y, dtype=np.float64), E, Dr, rows, starts.astype(np.int64)

    def _fit(self, U, Y, bounds=None):
        self._check_params()
        for name in ("feature_scale_", "feature_mean_", "theta_"):
            if hasattr(self, name):
                delattr(self, name)
        bounds = bounds or [(0, U.shape[0])]
        self.arx_ = ArxModel(self.narx, self.features).fit(U, Y, segments=bounds)
        self.n_inputs_, self.n_outputs_ = U.shape[1], Y.shape[1]
        m, K, t0 = Y.shape[1], int(self.horizon), self.t0
        self.phi_input_scale_ = physics_features(U)[1] if self.net_features == "physics" \
            else None
        S, E, Dr, rows, starts = self._windows(U, Y, bounds)
        if starts.size < 2:
            raise ValueError(f"U: too few samples for windows of {K} steps (horizon) after the "
                             f"first {t0} rows of each record")
        lin = self._lin()
        ysd = Y[rows].std(axis=0)
        self.in_mean_, self.in_scale_ = Y[rows].mean(axis=0), np.where(ysd > 0, ysd, 1.0)
        blind = [] if self.blind is None else [int(i) for i in self.blind]
        if any(i < 0 or i >= m for i in blind):
            raise ValueError(f"blind: output indices must be in 0..{m - 1}")
        self.in_scale_[blind] = BLIND_SCALE       # the network does not see these outputs
        res = (Y[rows + 1] - Y[rows] - Dr[rows]
               - np.concatenate([Y[rows - l] for l in range(lin.shape[1] // m)], axis=1)
               @ lin.T)
        r = res.std(axis=0)
        self.out_scale_ = np.where(r > 0, r, self.in_scale_)
        # the ARX's own k-step error on the training windows: the error scales
        err = base_rollout_errors(S, Dr, lin, starts, K)
        lab = self._group_labels(m)
        ms = np.mean(err ** 2, axis=0)                           # (K, m)
        per_group = np.stack([ms[:, lab == g].mean(axis=1) for g in range(lab.max() + 1)], 1)
        if self.weighting == "base":     # each step and group over the ARX's error there
            qk = np.sqrt(per_group)                               # (K, groups)
            qk = np.maximum(qk, 1e-3 * qk.max(axis=0))
            qk = np.where(qk > 0, qk, 1.0)
            self.err_scale_ = np.ascontiguousarray(qk[:, lab])   # (K, m)
        else:                            # pooled over the steps
            q = np.sqrt(per_group.mean(axis=0))
            self.err_scale_ = np.where(q > 0, q, 1.0)[lab]
        val = None
        if self._validation is not None:
            Uv, Yv, segv = self._validation
            from cdam_core.models.protocol import segment_bounds
            Sv, Ev, Dv, _, sv = self._windows(np.asarray(Uv, float), np.asarray(Yv, float),
                                              segment_bounds(segv, len(Uv)))
            if sv.size:
                val = (Sv, Ev, Dv, sv)
        H = int(self.hidden)
        ni = m + E.shape[1]
        D = _core.kstep_num_params(m, E.shape[1], H)
        theta0 = np.zeros(D)
        lim = 1.0 / np.sqrt(ni)
        theta0[:H * ni + H] = np.asarray(
            _core.Rng(int(self.seed)).uniform_array(H * ni + H, -lim, lim), float)
        self.theta_, hist = _core.kstep_train_lm(
            theta0, S, E, Dr, starts, K, H, self.in_mean_, self.in_scale_, self.out_scale_,
            self.err_scale_, epochs=int(self.epochs), threads=int(self.threads), lin=lin,
            val=val, max_fail=max(int(self.epochs), 1), mu=float(self.mu))
        self.history_ = {"mse": [float(v) for v in hist["mse"]], "stop": hist["stop"],
                         "val_mse": [float(v) for v in hist["val_mse"]] if val else None,
                         "best_epoch": int(hist["best_epoch"]) if val else None}
        self.y_start_ = self.arx_.y_start_

    # -- prediction ----------------------------------------------------------------------------
    def _one_step(self, U, Y):
        t0 = self.t0
        base = self.arx_._one_step(U, Y)[t0 - self.arx_.t0:]
        prev = np.arange(t0 - 1, U.shape[0] - 1)
        return base + self._net(Y[prev], self._exo(self._phi(U), prev))

    def _windows_one_step(self, u, z, W, t0):
        base = self.arx_._windows_one_step(u, z, W, t0)
        prev = np.arange(W) * (t0 + 1) + t0 - 1
        return base + self._net(z[prev], self._exo(self._phi(u), prev))

    def _free_run(self, U, Y0):
        t0, n = self.t0, U.shape[0]
        P = np.zeros((n, self.n_outputs_))
        P[:t0] = Y0
        for t in range(t0, n):
            P[t] = self._windows_one_step(U[t - t0:t + 1], P[t - t0:t + 1], 1, t0)[0]
            if not np.all(np.isfinite(P[t])):
                raise ValueError("model: the free-run simulation diverged (NaN or Inf)")
        return P[t0:]

    def parameters(self) -> dict:
        """The ARX's coefficients (``ArxModel.parameters``) and the network's size."""
        self._check_fitted()
        out = dict(self.arx_.parameters())
        out["network_weights"] = (int(self.theta_.size), None)
        return out

    # -- file ------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        self._check_fitted()
        vec = lambda a: [float(v) for v in a]  # noqa: E731
        return {"narx": [int(v) for v in self.arx_.orders], "features": self.features,
                "hidden": int(self.hidden), "lags": int(self.lags),
                "horizon": int(self.horizon), "epochs": int(self.epochs),
                "net_features": self.net_features, "weighting": self.weighting,
                "groups": None if self.groups is None else [int(g) for g in
                                                            self._group_labels(
                                                                self.n_outputs_)],
                "stride": None if self.stride is None else int(self.stride),
                "seed": int(self.seed), "mu": float(self.mu),
                "blind": None if self.blind is None else [int(i) for i in self.blind],
                "arx": self.arx_.to_dict(),
                "phi_input_scale": None if self.phi_input_scale_ is None else
                vec(self.phi_input_scale_),
                "theta": vec(self.theta_), "in_mean": vec(self.in_mean_),
                "in_scale": vec(self.in_scale_), "out_scale": vec(self.out_scale_),
                "err_scale": [float(v) for v in np.ravel(self.err_scale_)],
                "feature_mean": vec(self.feature_mean_), "feature_scale": vec(self.feature_scale_)}

    @classmethod
    def from_dict(cls, d: dict) -> "ArxKStep":
        try:
            m = cls(narx=d["narx"], features=d["features"], hidden=d["hidden"],
                    lags=d["lags"], horizon=d["horizon"], epochs=d["epochs"],
                    net_features=d["net_features"], weighting=d["weighting"],
                    groups=d["groups"], stride=d["stride"], seed=d["seed"], blind=d["blind"],
                    mu=d["mu"])
        except ValueError as exc:
            raise ValueError(f"model.{exc}") from None
        try:
            m.arx_ = ArxModel.from_dict(d["arx"])
        except ValueError as exc:
            raise ValueError(str(exc).replace("model.", "model.arx.", 1)) from None
        if tuple(m.arx_.orders) != tuple(ArxModel(m.narx).orders) or \
                m.arx_.features != m.features:
            raise ValueError("model.arx: orders or features differ from the model's")
        m.n_inputs_, m.n_outputs_ = m.arx_.n_inputs_, m.arx_.n_outputs_
        if m.net_features == "physics":
            if m.n_inputs_ != 4:
                raise ValueError("model.net_features: physics features need 4 inputs")
            m.phi_input_scale_ = field_array(d["phi_input_scale"], "model.phi_input_scale",
                                             (4,))
        else:
            m.phi_input_scale_ = None
        nphi = m.n_inputs_ if m.net_features == "raw" else 8
        ne = nphi * int(m.lags)
        D = _core.kstep_num_params(m.n_outputs_, ne, int(m.hidden))
        m.theta_ = field_array(d["theta"], "model.theta", (D,))
        for name in ("in_mean", "in_scale", "out_scale"):
            setattr(m, name + "_", field_array(d[name], f"model.{name}", (m.n_outputs_,)))
        rows = int(m.horizon) if m.weighting == "base" else 1
        m.err_scale_ = field_array(d["err_scale"], "model.err_scale",
                                   (rows * m.n_outputs_,)).reshape(rows, m.n_outputs_)
        if m.weighting != "base":
            m.err_scale_ = m.err_scale_[0]
        m.feature_scale_ = field_array(d["feature_scale"], "model.feature_scale", (ne,))
        m.feature_mean_ = field_array(d["feature_mean"], "model.feature_mean", (ne,))
        for name in ("in_scale", "out_scale", "err_scale", "feature_scale"):
            if not np.all(getattr(m, name + "_") > 0):
                raise ValueError(f"model.{name}: every scale must be > 0")
        m.y_start_ = getattr(m.arx_, "y_start_", None)
        return m
