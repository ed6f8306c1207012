"""Hybrid NARX: a linear ARX part plus a BP network on its residual.

Why: on the AR.Drone 2.0 flight the paper's static network and a plain NARX network lose to a
linear ARX model in free run (the network's feedback drifts; a static map cannot follow the
pose). The hybrid keeps the linear dynamics and lets a network add a bounded nonlinear term of
the inputs only, so it cannot destabilise the free run:

    y(t) = A [y(t-1); ...; y(t-na)] + B [f(t-nk); ...; f(t-nk-nb+1)] + c
           + alpha * N([f(t-nk); ...; f(t-nk-nb+1)])

A, B, c: least squares on the training record (:class:`.arx.ArxModel`). N: a static
:class:`.network.BPNetwork` fitted on the one-step residual of the first
``1 - validation_fraction`` of the training record by ``fit_residual(X, R)`` (the identify
stage passes one that seeds it with IBOA, BOA or CABC; the default is plain LM from Rng(seed)
weights); alpha in {0, 1} is chosen by the free-run mean Pearson r on the last
``validation_fraction`` of the training record (test data is never seen).
``residual_weight_`` says which was chosen: 0 means the network did not help.
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.checks import finite_float, positive_int
from cdam_core.base.metrics import mean_pearson
from cdam_core.models.arx import ArxModel, lagged
from cdam_core.models.network import BPNetwork

__all__ = ["HybridNarx"]


def _default_residual_fitter(seed: int):
    def fit_residual(X, R):
        return BPNetwork(hidden=5, epochs=30, goal=0.003, seed=seed).fit(X, R)
    return fit_residual


class HybridNarx(ArxModel):
    """Linear ARX + BP network on the residual (see the module doc).

    Args:
        narx: (na, nb, nk) orders of the linear part and the network's input lags.
        features: "raw" or "physics" (four motor commands).
        fit_residual: callable (X, R) -> fitted static BPNetwork; None: plain LM (hidden 5,
            30 epochs) from ``Rng(seed)`` weights.
        seed: seed of the default residual fit.
        validation_fraction: tail of the training record that chooses alpha.
    """

    kind = "hybrid"
    fits_segments = False   # the residual network is trained on one record

    def __init__(self, narx=(3, 3, 0), features="raw", fit_residual=None, seed=0,
                 validation_fraction=0.2):
        self.seed = seed                   # all stored as given (scikit-learn's clone)
        self.fit_residual = fit_residual
        self.validation_fraction = validation_fraction
        super().__init__(narx, features)

    def _check_params(self) -> None:
        super()._check_params()
        positive_int(self.seed, "seed", minimum=0)
        f = finite_float(self.validation_fraction, "validation_fraction")
        if not 0.0 < f < 1.0:
            raise ValueError("validation_fraction: must be in (0, 1)")
        if self.fit_residual is not None and not callable(self.fit_residual):
            raise ValueError("fit_residual: must be callable (X, R) -> fitted BPNetwork")

    def _fit(self, U, Y):
        super()._fit(U, Y)
        nb, nk, t0 = self.orders.nb, self.orders.nk, self.t0
        self.net_, self.residual_weight_, self.validation_r_ = None, 0.0, {}
        F = self._features(U)
        resid = Y[t0:] - ArxModel._one_step(self, U, Y)
        Xn = lagged(F, nb, nk, t0)
        n_fit = int(round(len(Xn) * (1 - float(self.validation_fraction))))
        fitter = self.fit_residual or _default_residual_fitter(int(self.seed))
        net = fitter(Xn[:n_fit], resid[:n_fit])
        if not isinstance(net, BPNetwork) or net.narx is not None:
            raise ValueError("fit_residual: must return a fitted static BPNetwork")
        self.net_ = net
        v0 = n_fit                    # validation rows t0 + n_fit.., with t0 rows of history
        Uv, Yv = U[v0:], Y[v0:]
        for w in (0.0, 1.0):
            self.residual_weight_ = w
            P = self._free_run(Uv, Yv[:t0])
            self.validation_r_[w] = mean_pearson(Yv[t0:], P)
        self.residual_weight_ = 1.0 if self.validation_r_[1.0] > self.validation_r_[0.0] else 0.0
        P = self._one_step(U, Y)
        lo, hi = Y.min(axis=0), Y.max(axis=0)
        span = np.where(hi > lo, hi - lo, 1.0)
        self.train_mse_ = float(np.mean(((P - Y[t0:]) * 2.0 / span) ** 2))

    def _input_term(self, F):
        term = super()._input_term(F)
        if self.net_ is not None and self.residual_weight_ != 0.0:
            Xn = lagged(F, self.orders.nb, self.orders.nk, self.t0)
            term = term + self.residual_weight_ * self.net_.predict(Xn)
        return term

    def to_dict(self) -> dict:
        d = super().to_dict()
        d["residual_weight"] = float(self.residual_weight_)
        d["network"] = self.net_.to_dict() if self.net_ is not None else None
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "HybridNarx":
        m = cls(d["narx"], d["features"])
        m._load_arx(d)
        w = d["residual_weight"]
        if w not in (0.0, 1.0):
            raise ValueError("model.residual_weight: must be 0 or 1")
        m.residual_weight_ = float(w)
        m.net_ = None
        if d["network"] is not None:
            try:
                m.net_ = BPNetwork.from_dict(d["network"])
            except ValueError as exc:
                raise ValueError(str(exc).replace("model.", "model.network.", 1)) from None
            if m.net_.n_inputs_ != m.orders.nb * m.n_features or m.net_.n_outputs_ != m.n_outputs_:
                raise ValueError("model.network: sizes do not match the ARX part")
        return m
