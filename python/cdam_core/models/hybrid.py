"""Hybrid NARX: a linear ARX part plus a BP network on its residual.

Why: on the AR.Drone 2.0 flight the paper's static network and a plain NARX network lose to a
linear ARX model in free run (the network's feedback drifts; a static map cannot follow the
pose). The hybrid keeps the linear dynamics and lets a network add a bounded nonlinear term of
the inputs only, so it cannot destabilise the free run:

    y(t) = A [y(t-1); ...; y(t-na)] + B [f(t-nk); ...; f(t-nk-nb+1)] + c
           + alpha * N([f(t-nk); ...; f(t-nk-nb+1)])

alpha in ``weights`` (default {0, 1}; always with 0) is chosen held out: the ARX (A, B, c by least squares,
:class:`.arx.ArxModel`) and a static :class:`.network.BPNetwork` N on its one-step residual
(``fit_residual(X, R)``: the identify stage passes one that seeds it with IBOA, BOA or CABC;
the default is plain LM from Rng(seed) weights) are fitted on the first
``1 - validation_fraction`` of the training record, and both the ARX alone and ARX + N run
free on the last ``validation_fraction`` (which neither saw; test data is never seen); alpha
is the weight with the highest mean Pearson r there, kept only where it beats alpha 0 (the ARX
alone). Then the model is refitted on the whole training record: the ARX, and N on its
residual when kept (not kept: the held-out N stays beside it with alpha 0). ``validation_r_``
{alpha: r} holds the held-out scores, ``residual_weight_`` alpha (0: the network did not help).
The physics features are scaled by the whole record's command maxima in both fits.

Why a weight below 1 and an ensemble: on the AR.Drone flight the residual network's free-run
contribution varies with its seed as much as it helps (test r 0.48-0.64 across 12 networks,
the ARX alone 0.625). ``ensemble=K`` trains K networks on the same residual (seeds seed ..
seed + K - 1) and uses their mean (:func:`.network.mean_network`: one network with the K
members' hidden units side by side, so the model file and the firmware take it as any
network): the seed-to-seed variance of the correction falls as 1 / K. ``weights`` between 0
and 1 shrink the correction towards the ARX.
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.checks import as_2d, finite_float, positive_int
from cdam_core.base.metrics import mean_pearson
from cdam_core.models.arx import ArxModel, lagged, physics_features
from cdam_core.models.network import BPNetwork, mean_network
from cdam_core.models.protocol import segment_bounds

__all__ = ["HybridNarx", "TRAINING", "free_run_error", "refine_free_run"]

#: how the residual networks are trained: on the ARX's one-step residual, or that fit refined
#: on the free-run error of the hybrid (:func:`refine_free_run`)
TRAINING = ("one_step", "free_run")


def _default_residual_fitter(seed: int):
    def fit_residual(X, R, member=0):
        return BPNetwork(hidden=5, epochs=30, goal=0.003, seed=seed + member).fit(X, R)
    return fit_residual


def _check_weight(w, name="weight") -> float:
    if isinstance(w, bool):
        raise ValueError(f"{name}: must be a number in [0, 1], got {w!r}")
    w = finite_float(w, name)
    if not 0.0 <= w <= 1.0:
        raise ValueError(f"{name}: must be in [0, 1], got {w!r}")
    return w


def _filter_ar(X, Wy, na):
    """Z (N, ...) with Z(t) = sum_j Wy_j' Z(t-1-j) + X(t), Z = 0 before row 0: the ARX's
    output recursion (``ArxModel._free_run``) driven by X; Wy (na m, m), Wy_j its rows
    j m .. (j + 1) m; X (N, m) or (N, m, D) (a Jacobian, filtered column by column)."""
    m = Wy.shape[1]
    Ws = [Wy[j * m:(j + 1) * m].T for j in range(na)]
    Z = np.zeros_like(X)
    for t in range(X.shape[0]):
        z = X[t].copy()
        for j in range(min(na, t)):
            z += Ws[j] @ Z[t - 1 - j]
        Z[t] = z
    return Z


def refine_free_run(net, Wy, na, parts, epochs: int = 10, mu: float = 1e-3):
    """A copy of the static network ``net`` refined by Levenberg-Marquardt on the free-run
    error of the model it corrects: ``parts`` [(X, E)], per record the network's inputs
    (rows t0..) and E the ARX's free-run error there (measured minus the ARX run free from
    the record's first t0 measured rows); the network's term N(X) reaches the free run through
    the ARX's output recursion (:func:`_filter_ar`, coefficients Wy of ``na`` lags), so the
    cost is sum ||(E - G N(X)) / s||^2, s the std of E per output over all records (every
    output weighs alike, as in the mean r). The Jacobian is the network's
    (``_core.mlp_jacobian``) through the same recursion. Steps that do not lower the cost are
    refused (mu x 10), so the refined network is never worse than ``net`` on this cost.
    ``history_["mse"]``: the cost per accepted step, over the rows and outputs."""
    from copy import deepcopy
    out = deepcopy(net)
    s = np.std(np.vstack([E for _, E in parts]), axis=0)
    s = np.where(s > 0, s, 1.0)

    def cost_jac(theta, jac):
        return free_run_error(net, theta, Wy, na, parts, s, jac)

    theta = np.asarray(out.theta_, np.float64).copy()
    e, J = cost_jac(theta, True)
    hist = [float(e @ e / e.size)]
    for _ in range(int(epochs)):
        g, H = J.T @ e, J.T @ J
        step_ok = False
        while mu < 1e10:
            try:
                d = np.linalg.solve(H + mu * np.eye(len(theta)), g)
            except np.linalg.LinAlgError:
                mu *= 10
                continue
            e2, _ = cost_jac(theta + d, False)
            if np.all(np.isfinite(e2)) and e2 @ e2 < e @ e:
                theta, mu, step_ok = theta + d, mu * 0.1, True
                break
            mu *= 10
        if not step_ok:
            break
        e, J = cost_jac(theta, True)
        hist.append(float(e @ e / e.size))
    out.theta_ = theta.astype(np.asarray(net.theta_).dtype)
    out.history_ = {"mse": hist}
    return out


def free_run_error(net, theta, Wy, na, parts, s, jac: bool = True):
    """(e, J) of :func:`refine_free_run`'s cost at weights ``theta`` of ``net``'s structure
    (its scalers, hidden size, activation): e the stacked errors (E - G N(X)) / s, row-major
    per record (rows, outputs); J (e.size, theta.size) their derivative with the sign of
    G N, i.e. d(G N / s) / d theta (None when not ``jac``)."""
    from cdam_core import _core
    m, h = int(net.n_outputs_), int(net.hidden_)
    span = (net.scaler_y_.data_max_ - net.scaler_y_.data_min_) / 2.0
    errs, jacs = [], []
    for X, E in parts:
        Xk = net.scaler_x_.transform(X)
        N = net.scaler_y_.inverse_transform(_core.mlp_forward(theta, Xk, h, m, net.activation))
        errs.append(((E - _filter_ar(N, Wy, na)) / s).ravel())
        if jac:
            J = _core.mlp_jacobian(theta, Xk, h, m, net.activation).reshape(len(Xk), m, -1)
            J *= span[None, :, None]
            jacs.append((_filter_ar(J, Wy, na) / s[None, :, None]).reshape(len(Xk) * m, -1))
    return np.concatenate(errs), (np.vstack(jacs) if jac else None)


class HybridNarx(ArxModel):
    """Linear ARX + BP network on the residual (see the module doc).

    Args:
        narx: (na, nb, nk) orders of the linear part and the network's input lags.
        features: "raw" or "physics" (four motor commands).
        fit_residual: callable (X, R) -> fitted static BPNetwork; with ``ensemble`` > 1 it
            is called as (X, R, member) for member 0 .. K-1 (each should differ, e.g. by its
            seed); None: plain LM (hidden 5, 30 epochs) from ``Rng(seed + member)`` weights.
        seed: seed of the default residual fit.
        validation_fraction: tail of the training record that chooses alpha (held out of
            both fits that choose it).
        validation_blocks: 0: choose alpha on that tail; B >= 2: on B contiguous blocks
            instead, each held out in turn (the ARX and the network(s) fitted on the rest),
            the score the mean over blocks of the free-run mean r (one window's luck
            averages out; ``evaluate.papernets.select_hybrid``'s rule).
        ensemble: K, the number of residual networks averaged (module doc).
        weights: the candidate weights alpha of the network's correction, in [0, 1]; 0 (the
            ARX alone) is always a candidate.
        training: "one_step" (each network fitted on the ARX's one-step residual) or
            "free_run" (that fit then refined by LM on the hybrid's free-run error over the
            rows it is fitted on, ``refine_epochs`` epochs: :func:`refine_free_run`).
    """

    kind = "hybrid"
    fits_segments = False   # the residual network is trained on one record

    def __init__(self, narx=(3, 3, 0), features="raw", fit_residual=None, seed=0,
                 validation_fraction=0.2, ensemble=1, weights=(0.0, 1.0), validation_blocks=0,
                 training="one_step", refine_epochs=10):
        self.seed = seed                   # all stored as given (scikit-learn's clone)
        self.fit_residual = fit_residual
        self.validation_fraction = validation_fraction
        self.ensemble = ensemble
        self.weights = weights
        self.validation_blocks = validation_blocks
        self.training = training
        self.refine_epochs = refine_epochs
        super().__init__(narx, features)

    def _check_params(self) -> None:
        super()._check_params()
        positive_int(self.seed, "seed", minimum=0)
        f = finite_float(self.validation_fraction, "validation_fraction")
        if not 0.0 < f < 1.0:
            raise ValueError("validation_fraction: must be in (0, 1)")
        if self.fit_residual is not None and not callable(self.fit_residual):
            raise ValueError("fit_residual: must be callable (X, R) -> fitted BPNetwork")
        positive_int(self.ensemble, "ensemble")
        if self.training not in TRAINING:
            raise ValueError(f"training: unknown {self.training!r}; use 'one_step' or 'free_run'")
        positive_int(self.refine_epochs, "refine_epochs", minimum=0)
        if positive_int(self.validation_blocks, "validation_blocks", minimum=0) == 1:
            raise ValueError("validation_blocks: must be 0 (the tail) or >= 2")
        self._weights()

    def _weights(self) -> tuple:
        """The candidate weights, checked, with 0 first and no repeat."""
        try:
            ws = [_check_weight(w, "weights") for w in self.weights]
        except TypeError:
            raise ValueError(f"weights: must be a sequence of numbers in [0, 1], "
                             f"got {self.weights!r}") from None
        return tuple(sorted(set([0.0] + ws)))

    def _fit(self, U, Y):
        t0 = self.t0
        n_fit = int(round((U.shape[0] - t0) * (1 - float(self.validation_fraction))))
        e = t0 + n_fit          # first validation target; rows n_fit..e-1 are its history
        self._check_length(U.shape[0])
        if e < 4 * (t0 + 1) + 10 or U.shape[0] - e < 2:
            raise ValueError(f"U: {U.shape[0]} samples leave {e} before the validation tail "
                             f"(validation_fraction {self.validation_fraction}) and "
                             f"{U.shape[0] - e} in it: too few for orders {tuple(self.orders)}")
        fitter = self.fit_residual or _default_residual_fitter(int(self.seed))
        scale = physics_features(U)[1] if self.features == "physics" else None
        B = int(self.validation_blocks)
        if B:
            self._blocked_scores(U, Y, scale, fitter, B)
        else:
            # held out: the ARX and its residual network fitted on rows < e only, both scored
            # in free run on the rows from e, which neither saw
            self._fit_parts(U[:e], Y[:e], scale, fitter)
            self.validation_r_ = {}
            Uv, Yv = U[n_fit:], Y[n_fit:]
            for w in self._weights():
                self.residual_weight_ = w
                self.validation_r_[w] = mean_pearson(Yv[t0:], self._free_run(Uv, Yv[:t0]))
        best = max(self.validation_r_, key=lambda w: (self.validation_r_[w], -w))
        kept = best > 0.0 and self.validation_r_[best] > self.validation_r_[0.0]
        # the model: the ARX refitted on the whole record, and the network too when kept
        # (not kept: the held-out network stays beside it with weight 0, unused)
        if kept:
            self._fit_parts(U, Y, scale, fitter)
        else:
            net, members = self.net_, self.members_
            super()._fit(U, Y, feature_scale=scale)
            self.net_, self.members_ = net, members
        self.residual_weight_ = best if kept else 0.0
        self._train_mse(U, Y, [(0, U.shape[0])])

    def _blocked_scores(self, U, Y, scale, fitter, B) -> None:
        """``validation_r_`` {alpha: mean over B contiguous blocks of the free-run mean r on
        the block}, the ARX and its network(s) fitted on the rest (two records, no regressor
        across the gap) for each block; leaves the last block's parts in place."""
        n, t0 = U.shape[0], self.t0
        if n // B < t0 + 3 or n - n // B < 4 * (t0 + 1) + 10:
            raise ValueError(f"U: {n} samples in {B} validation blocks: too few for orders "
                             f"{tuple(self.orders)}")
        rs = {w: [] for w in self._weights()}
        for k in range(B):
            a, b = n * k // B, n * (k + 1) // B
            keep = np.r_[0:a, b:n]
            bounds = [(0, a), (a, n - (b - a))] if 0 < a and b < n else [(0, n - (b - a))]
            self._fit_parts(U[keep], Y[keep], scale, fitter, bounds)
            for w in rs:
                self.residual_weight_ = w
                rs[w].append(mean_pearson(Y[a + t0:b], self._free_run(U[a:b], Y[a:a + t0])))
        self.validation_r_ = {w: float(np.mean(v)) for w, v in rs.items()}

    def fit_with_weight(self, U, Y, weight, segments=None) -> "HybridNarx":
        """The ARX and its residual network(s) all fitted on all of (U, Y), the network's
        weight ``weight`` (in [0, 1]) given, not chosen: for a caller that chooses it on
        validation of its own (``evaluate.papernets.select_hybrid``: blocked). ``segments``:
        records laid end to end (no regressor crosses a seam). ``validation_r_`` is empty."""
        Y1 = Y
        U, Y = as_2d(U, "U"), as_2d(Y, "Y")
        if U.shape[0] != Y.shape[0]:
            raise ValueError(f"U, Y: mismatched sample counts ({U.shape[0]} and {Y.shape[0]})")
        weight = _check_weight(weight)
        self._check_params()
        bounds = segment_bounds(segments, U.shape[0])
        scale = physics_features(U)[1] if self.features == "physics" else None
        self._fit_parts(U, Y, scale, self.fit_residual or
                        _default_residual_fitter(int(self.seed)), bounds)
        self.residual_weight_, self.validation_r_ = float(weight), {}
        self._train_mse(U, Y, bounds)
        self._note_target(Y1)
        return self

    def _train_mse(self, U, Y, bounds) -> None:
        """One-step MSE in min-max units (-1..1) over the segments' predicted rows."""
        lo, hi = Y.min(axis=0), Y.max(axis=0)
        span = np.where(hi > lo, hi - lo, 1.0)
        t0 = self.t0
        E = [(self._one_step(U[a:b], Y[a:b]) - Y[a + t0:b]) * 2.0 / span
             for a, b in bounds if b - a > t0]
        self.train_mse_ = float(np.mean(np.vstack(E) ** 2))

    def _fit_parts(self, U, Y, scale, fitter, bounds=None) -> None:
        """The ARX on (U, Y) by least squares (physics features scaled by ``scale``; records
        ``bounds``), then ``fitter`` on its one-step residual (each record's rows from its
        own t0), ``ensemble`` times; sets ``members_`` and ``net_`` (their mean)."""
        self.net_, self.members_ = None, []
        bounds = bounds or [(0, U.shape[0])]
        super()._fit(U, Y, bounds, feature_scale=scale)
        nb, nk, t0 = self.orders.nb, self.orders.nk, self.t0
        parts = [(lagged(self._features(U[a:b]), nb, nk, t0),
                  Y[a + t0:b] - ArxModel._one_step(self, U[a:b], Y[a:b]))
                 for a, b in bounds if b - a > t0]
        X, R = np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])
        K = int(self.ensemble)
        members = [fitter(X, R) if K == 1 else fitter(X, R, k) for k in range(K)]
        for net in members:
            if not isinstance(net, BPNetwork) or net.narx is not None:
                raise ValueError("fit_residual: must return a fitted static BPNetwork")
        if self.training == "free_run":
            na, m = self.orders.na, self.n_outputs_
            runs = [(p[0], Y[a + t0:b] - ArxModel._free_run(self, U[a:b], Y[a:a + t0]))
                    for p, (a, b) in zip(parts, [x for x in bounds if x[1] - x[0] > t0])]
            members = [refine_free_run(n, self.coef_[:na * m], na, runs,
                                       int(self.refine_epochs)) for n in members]
        self.members_ = members
        self.net_ = mean_network(members)

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
        m.residual_weight_ = _check_weight(d["residual_weight"], "model.residual_weight")
        m.net_, m.members_ = None, []
        if d["network"] is not None:
            try:
                m.net_ = BPNetwork.from_dict(d["network"])
            except ValueError as exc:
                raise ValueError(str(exc).replace("model.", "model.network.", 1)) from None
            if m.net_.n_inputs_ != m.orders.nb * m.n_features or m.net_.n_outputs_ != m.n_outputs_:
                raise ValueError("model.network: sizes do not match the ARX part")
        return m
