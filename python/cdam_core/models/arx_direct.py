"""A direct multi-step linear predictor: one least-squares fit per prediction step (kind
``arx_direct``).

For an ARX's orders (na, nb, nk) and features f of the inputs (``models.arx``: raw or physics),
the k-step prediction from the origin t (the last measured row) is, for k = 1..``horizon``::

    y(t + k) = sum_{j<na} A_kj y(t - j) + sum_{s = 1 - nk - nb + 1}^{k - nk} B_ks f(t + s) + c_k

i.e. the regressors of the ARX iterated k times (the measured outputs of its first step and
every input feature its k steps use), each step's (A_k, B_k, c_k) fitted by least squares on
that step's error over every origin of the training segments whose target t + k lies in the
segment (nothing crosses a seam). Step 1 is the ARX itself (``ArxModel``'s fit on the same rows).
Steps beyond ``horizon`` and the free run continue with that ARX (iterated one-step
prediction). Regressor channels are centred and scaled by their training mean and standard
deviation before the normal equations are formed (conditioning; the fit is the same least
squares). The sums are formed once: the Gram matrix of every origin's whole window and its
cross products with every step's target, plus the origins near each segment's end whose window
is cut (their missing entries are zeros in columns their steps never use).
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.checks import positive_int
from cdam_core.models.arx import ArxModel
from cdam_core.models.schema import field_array

__all__ = ["ArxDirect"]


class ArxDirect(ArxModel):
    """Direct k-step least squares (module doc): ``ArxDirect(narx, features, horizon)``."""

    kind = "arx_direct"

    def __init__(self, narx=(2, 2, 1), features: str = "raw", horizon: int = 50):
        self.horizon = horizon
        super().__init__(narx, features)

    def _check_params(self) -> None:
        super()._check_params()
        positive_int(self.horizon, "horizon")

    # -- regressors -------------------------------------------------------------------------
    def _window(self, U, Y, o, K):
        """Regressors (len(o), na m + (K + nb - 1) nf + 1) of origins ``o`` for steps up to
        K: [y(o), .., y(o - na + 1), f(o + 1 - nk - nb + 1), .., f(o + K - nk), 1] of the
        scaled channels; rows past the data are zeros."""
        na, nb, nk = self.orders
        n = Y.shape[0]
        cols = [(Y[o - j] - self.y_mean_) / self.y_scale_ for j in range(na)]
        if nb:
            s = np.arange(2 - nk - nb, K - nk + 1)
            idx = o[:, None] + s[None, :]                        # (origins, window rows)
            F = (self._features(U[np.minimum(idx, n - 1).ravel()]) - self.f_mean_) / \
                self.f_scale_
            F = np.where((idx < n).ravel()[:, None], F, 0.0)
            cols.append(F.reshape(len(o), -1))
        cols.append(np.ones((len(o), 1)))
        return np.hstack(cols)

    def _columns(self, k):
        """Column indices of step k's regressors in a window of ``horizon`` steps."""
        na, nb, _ = self.orders
        m, nf, K = self.n_outputs_, self.n_features, int(self.horizon)
        ny = na * m
        nfk = (k + nb - 1) * nf if nb else 0
        nft = (K + nb - 1) * nf if nb else 0
        return np.r_[np.arange(ny), ny + np.arange(nfk), ny + nft]

    def _fit(self, U, Y, bounds=None):
        super()._fit(U, Y, bounds)                     # step 1, free run, sizes, feature scale
        K = int(self.horizon)
        F = self._features(U)
        self.y_mean_, self.f_mean_ = Y.mean(axis=0), F.mean(axis=0)
        sy, sf = Y.std(axis=0), F.std(axis=0)
        self.y_scale_ = np.where(sy > 0, sy, 1.0)
        self.f_scale_ = np.where(sf > 0, sf, 1.0)
        t0, m = self.t0, Y.shape[1]
        full, cut, cut_end = [], [], []
        for a, b in bounds or [(0, U.shape[0])]:
            o = np.arange(a + t0 - 1, b - 1)
            if o.size:
                full.append(o[o + K < b])
                cut.append(o[o + K >= b])
                cut_end.append(np.full(int(np.sum(o + K >= b)), b))
        full = np.concatenate(full) if full else np.zeros(0, int)
        cut, cut_end = np.concatenate(cut), np.concatenate(cut_end)
        p = self._columns(K).size
        G, B = np.zeros((p, p)), np.zeros((p, K * m))
        for c in range(0, full.size, 4096):
            o = full[c:c + 4096]
            X = self._window(U, Y, o, K)
            T = Y[o[:, None] + np.arange(1, K + 1)[None, :]].reshape(len(o), K * m)
            G += X.T @ X
            B += X.T @ T
        # the windows cut by a segment's end (none when K = 1: every origin reaches step 1)
        Xc = self._window(U, Y, cut, K) if cut.size else None
        self.coefs_ = []
        for k in range(2, K + 1):
            cols = self._columns(k)
            live = cut + k < cut_end                   # cut windows that reach step k
            Xk = Xc[np.ix_(live, cols)]
            Tk = Y[cut[live] + k]
            Gk = G[np.ix_(cols, cols)] + Xk.T @ Xk
            bk = B[cols, (k - 1) * m:k * m] + Xk.T @ Tk
            if not (np.all(np.isfinite(Gk)) and np.all(np.isfinite(bk))):
                self.n_outputs_ = None
                raise ValueError("U, Y: values too large for a least-squares fit in float64")
            self.coefs_.append(np.linalg.lstsq(Gk, bk, rcond=None)[0])
        self.n_inputs_, self.n_outputs_ = U.shape[1], m

    # -- prediction -------------------------------------------------------------------------
    def _rollout_step(self, k, origins, Ub, Zb, U, Y):
        """``Model.rollout``'s step k: steps 2..``horizon`` the direct predictions from the
        measured rows (which the ARX's recursion beyond continues from), else the ARX's
        one-step prediction."""
        if not 2 <= k <= int(self.horizon):
            return super()._rollout_step(k, origins, Ub, Zb, U, Y)
        return self._window(U, Y, origins, k) @ self.coefs_[k - 2]   # step k's columns

    def _k_step(self, U, Y, k):
        P = np.array(Y, dtype=float, copy=True)
        for j, rows, Pj in self.rollout(U, Y, k):
            if j == k:
                P[rows] = Pj
        return P

    # -- file -------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        d = super().to_dict()
        d["horizon"] = int(self.horizon)
        for name in ("y_mean_", "y_scale_", "f_mean_", "f_scale_"):
            d[name.rstrip("_")] = [float(v) for v in getattr(self, name)]
        d["steps"] = [[[float(v) for v in row] for row in c] for c in self.coefs_]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ArxDirect":
        m = cls(d["narx"], d["features"], d["horizon"])
        m._load_arx(d)
        mo, nf = m.n_outputs_, m.n_features
        for name, size in (("y_mean", mo), ("y_scale", mo), ("f_mean", nf), ("f_scale", nf)):
            setattr(m, name + "_", field_array(d[name], f"model.{name}", (size,)))
        steps = d["steps"]
        if not isinstance(steps, list) or len(steps) != int(m.horizon) - 1:
            raise ValueError(f"model.steps: expected {int(m.horizon) - 1} matrices")
        m.coefs_ = [field_array(c, f"model.steps[{k}]", (m._columns(k + 2).size, mo))
                    for k, c in enumerate(steps)]
        return m
