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
prediction).

Step 1 may have regressors of its own (``first``): for each listed set of outputs, a one-step
ARX (orders and features of their own, least squares on the same rows) predicts those outputs
at step 1 in place of the ARX above. The ARX of ``narx`` chosen for the multi-step error need
not be the best one-step predictor: on the nano-drone flights the one-step body rates are
better predicted from the newest rotor speed (delay 1) than by the delay-2 ARX chosen for the
multi-step error. Only step 1 changes: steps 2..``horizon`` are fitted from the measured rows
and the recursion beyond continues from them, the free run is the ARX of ``narx``.

``first_mix`` = (narx, features, window): step 1 of the ``first`` outputs is instead a mix,
row by row, of their own ARX's prediction p1 and that of a second one-step ARX p2 (e.g. the
multi-step ARX): lambda p1 + (1 - lambda) p2, lambda in [0, 1] the least-squares weight of
the two predictors' one-step errors e1, e2 over the ``window`` rows before the predicted one
in its segment (lambda = sum (e2 - e1) . e2 / sum |e1 - e2|^2 over the part's outputs, 0 with
no past row): measured rows only, so the k-step protocol's causality holds. Why: on the
nano-drone flights the rotor speeds' alignment against the body rates moves by 10-20 ms from
flight to flight, so which delay predicts the rates best one step ahead is a property of the
flight; the mix follows it from the flight's own recent past. Regressor channels are centred and scaled by their training mean and standard
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

    def __init__(self, narx=(2, 2, 1), features: str = "raw", horizon: int = 50, first=None,
                 first_mix=None):
        self.horizon = horizon
        self.first = first
        self.first_mix = first_mix
        super().__init__(narx, features)

    def _check_params(self) -> None:
        super()._check_params()
        positive_int(self.horizon, "horizon")
        self._first_parts()
        self._mix_spec()

    def _mix_spec(self):
        """``first_mix`` checked: None or (narx, features, window >= 1), with ``first``."""
        if self.first_mix is None:
            return None
        try:
            narx, feat, window = self.first_mix
        except (TypeError, ValueError):
            raise ValueError("first_mix: expected (narx, features, window)") from None
        if self.first is None:
            raise ValueError("first_mix: needs first (the outputs it mixes)")
        ArxModel(narx, feat)
        return narx, feat, positive_int(window, "first_mix window")

    def _first_parts(self):
        """``first`` checked: a list of (outputs (indices), narx, features), the outputs of
        different entries disjoint (None: step 1 is the ARX's)."""
        if self.first is None:
            return []
        try:
            items = list(self.first)
        except TypeError:
            raise ValueError("first: expected a list of (outputs, narx, features)") from None
        parts, seen = [], set()
        for j, item in enumerate(items):
            if isinstance(item, dict):
                item = (item.get("outputs"), item.get("narx"), item.get("features", "raw"))
            try:
                outs, narx, feat = item
                outs = [int(o) for o in outs]
            except (TypeError, ValueError):
                raise ValueError(f"first[{j}]: expected (outputs, narx, features)") from None
            if not outs or any(o < 0 for o in outs) or len(set(outs)) != len(outs):
                raise ValueError(f"first[{j}]: outputs must be distinct indices >= 0")
            if seen & set(outs):
                raise ValueError(f"first[{j}]: outputs {sorted(seen & set(outs))} already "
                                 f"listed")
            seen |= set(outs)
            ArxModel(narx, feat)                       # checks the orders and features
            parts.append((outs, narx, feat))
        return parts

    @property
    def t0(self) -> int:
        t0 = self.orders.t0
        for m in self.first_ + ([self.mix_] if self.mix_ is not None else []):
            t0 = max(t0, m.t0)
        return t0

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

    first_: list = []              # the ``first`` outputs' ARXs (fitted), their outputs
    first_outputs_: list = []
    mix_ = None                    # the second one-step ARX of ``first_mix`` (fitted)

    def _fit(self, U, Y, bounds=None):
        self.first_, self.first_outputs_, self.mix_ = [], [], None
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
        self.first_, self.first_outputs_ = [], []
        for j, (outs, narx, feat) in enumerate(self._first_parts()):
            if max(outs) >= m:
                self.n_outputs_ = None
                raise ValueError(f"first[{j}]: output {max(outs)} of {m}")
            self.first_.append(ArxModel(narx, feat).fit(U, Y, segments=bounds))
            self.first_outputs_.append(outs)
        spec = self._mix_spec()
        if spec is not None:
            self.mix_ = ArxModel(spec[0], spec[1]).fit(U, Y, segments=bounds)
            self.mix_window_ = spec[2]

    # -- prediction -------------------------------------------------------------------------
    def _one_step(self, U, Y):
        """Step 1 (rows t0..): the ARX's, the outputs of ``first`` from their own ARXs (mixed
        with ``first_mix``'s ARX row by row when given)."""
        t0 = self.t0
        P = super()._one_step(U, Y)                   # rows t0.. (t0 covers every part)
        if self.mix_ is None:
            for outs, m in zip(self.first_outputs_, self.first_):
                P[:, outs] = m._one_step(U, Y)[t0 - m.t0:, outs]
            return P
        p2 = self.mix_._one_step(U, Y)[t0 - self.mix_.t0:]
        e2 = Y[t0:] - p2
        W = self.mix_window_
        for outs, m in zip(self.first_outputs_, self.first_):
            p1 = m._one_step(U, Y)[t0 - m.t0:, outs]
            e1 = e2[:, outs] + p2[:, outs] - p1
            d = e1 - e2[:, outs]
            a = np.concatenate([[0.0], np.cumsum(np.sum(-d * e2[:, outs], axis=1))])
            q = np.concatenate([[0.0], np.cumsum(np.sum(d * d, axis=1))])
            r = np.arange(len(p1))
            lo = np.maximum(r - W, 0)
            A, B = a[r] - a[lo], q[r] - q[lo]     # the rows before each one, in the window
            lam = np.clip(np.divide(A, B, out=np.zeros_like(A), where=B > 0), 0.0, 1.0)
            P[:, outs] = lam[:, None] * p1 + (1.0 - lam[:, None]) * p2[:, outs]
        return P

    def rollout(self, U, Y, horizon: int, segments=None, first: int = 1, chunk=None):
        """``Model.rollout``; with ``first_mix`` step 1 of the ``first`` outputs from each
        segment's ``_one_step`` (the mix needs the segment's past rows)."""
        if self.mix_ is None:
            yield from super().rollout(U, Y, horizon, segments, first, chunk)
            return
        from cdam_core.models.protocol import segment_bounds
        U, Y = np.asarray(U, float), np.asarray(Y, float)
        S1 = np.zeros_like(Y)
        for a, b in segment_bounds(segments, U.shape[0]):
            if b - a > self.t0:
                S1[a + self.t0:b] = self._one_step(U[a:b], Y[a:b])
        outs = [o for part in self.first_outputs_ for o in part]
        for k, rows, P in super().rollout(U, Y, horizon, segments, first, chunk):
            if k == 1:
                P[:, outs] = S1[rows][:, outs]
            yield k, rows, P

    def _rollout_step(self, k, origins, Ub, Zb, U, Y):
        """``Model.rollout``'s step k: steps 2..``horizon`` the direct predictions from the
        measured rows (which the ARX's recursion beyond continues from), else the ARX's
        one-step prediction."""
        if not 2 <= k <= int(self.horizon):
            P = super()._rollout_step(k, origins, Ub, Zb, U, Y)
            if k == 1 and self.first_:
                t0, W = self.t0, len(origins)
                u = np.ascontiguousarray(Ub[:, :t0 + 1].reshape(W * (t0 + 1), -1))
                z = np.ascontiguousarray(Zb[:, :t0 + 1].reshape(W * (t0 + 1), -1))
                for outs, m in zip(self.first_outputs_, self.first_):
                    P[:, outs] = m._windows_one_step(u, z, W, t0)[:, outs]
            return P
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
        if self.first_:
            d["first"] = [{"outputs": [int(o) for o in outs], "arx": m.to_dict()}
                          for outs, m in zip(self.first_outputs_, self.first_)]
        if self.mix_ is not None:
            d["first_mix"] = {"arx": self.mix_.to_dict(), "window": int(self.mix_window_)}
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ArxDirect":
        first = d.get("first") or []
        if not isinstance(first, list) or not all(isinstance(f, dict) and
                                                  isinstance(f.get("arx"), dict)
                                                  for f in first):
            raise ValueError("model.first: expected a list of {outputs, arx}")
        mix = d.get("first_mix")
        if mix is not None and not (isinstance(mix, dict) and isinstance(mix.get("arx"), dict)):
            raise ValueError("model.first_mix: expected {arx, window}")
        m = cls(d["narx"], d["features"], d["horizon"],
                [(f["outputs"], f["arx"].get("narx"), f["arx"].get("features"))
                 for f in first] or None,
                None if mix is None else (mix["arx"].get("narx"), mix["arx"].get("features"),
                                          mix.get("window")))
        m._load_arx(d)
        m.first_, m.first_outputs_ = [], []
        for j, f in enumerate(first):
            part = ArxModel.from_dict(f["arx"])
            if (part.n_inputs_, part.n_outputs_) != (m.n_inputs_, m.n_outputs_) or \
                    max(f["outputs"]) >= m.n_outputs_:
                raise ValueError(f"model.first[{j}]: other inputs or outputs than the model")
            m.first_.append(part)
            m.first_outputs_.append([int(o) for o in f["outputs"]])
        if mix is not None:
            m.mix_ = ArxModel.from_dict(mix["arx"])
            if (m.mix_.n_inputs_, m.mix_.n_outputs_) != (m.n_inputs_, m.n_outputs_):
                raise ValueError("model.first_mix: other inputs or outputs than the model")
            m.mix_window_ = int(mix["window"])
        mo, nf = m.n_outputs_, m.n_features
        for name, size in (("y_mean", mo), ("y_scale", mo), ("f_mean", nf), ("f_scale", nf)):
            setattr(m, name + "_", field_array(d[name], f"model.{name}", (size,)))
        steps = d["steps"]
        if not isinstance(steps, list) or len(steps) != int(m.horizon) - 1:
            raise ValueError(f"model.steps: expected {int(m.horizon) - 1} matrices")
        m.coefs_ = [field_array(c, f"model.steps[{k}]", (m._columns(k + 2).size, mo))
                    for k, c in enumerate(steps)]
        return m
