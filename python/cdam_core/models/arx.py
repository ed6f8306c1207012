"""Linear ARX models on raw or physics features of the inputs (least squares).

    y(t) = A [y(t-1); ...; y(t-na)] + B [f(t-nk); ...; f(t-nk-nb+1)] + c

f = features of the inputs: ``"raw"`` (the inputs) or ``"physics"``: for four motor commands in
X-mixer order (1 front-left, 2 front-right, 3 rear-right, 4 rear-left) the commands scaled by
their training maximum, plus thrust ~ sum u_i^2 and the roll, pitch and yaw torque combinations
of u_i^2. A, B, c by least squares on the one-step equation; their standard deviations from the
residual variance and (R'R)^-1 (ordinary least squares, white-noise assumption: stated, not
checked). ``parameters()`` names them ``A[out,lag,channel]``, ``B[out,lag,feature]``, ``c[out]``.
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.checks import as_2d
from cdam_core.base.orders import Orders, parse_orders
from cdam_core.models.protocol import Model
from cdam_core.models.schema import field_array

__all__ = ["ArxModel", "FEATURES", "physics_features", "arx_design", "lagged"]

FEATURES = ("raw", "physics")
N_PHYSICS = 8   # physics features of four motor commands (see physics_features)


def physics_features(U, scale=None):
    """Physics features of four motor commands U (N, 4) in X-mixer order (see module doc).

    Returns (F (N, 8), scale): [u / scale (4), T, tau_roll, tau_pitch, tau_yaw] with
    f_i = (u_i / scale_i)^2, T = sum f_i, tau_roll = f1 + f4 - f2 - f3,
    tau_pitch = f1 + f2 - f3 - f4, tau_yaw = f1 - f2 + f3 - f4. ``scale`` (4,) defaults to the
    per-command maximum of |U| (1 where that is 0); pass the training scale for other records.
    """
    U = as_2d(U, "U")
    if U.shape[1] != 4:
        raise ValueError(f"U: physics features need 4 motor commands, got {U.shape[1]} columns")
    if scale is None:
        scale = np.max(np.abs(U), axis=0)
        scale = np.where(scale > 0, scale, 1.0)
    scale = np.asarray(scale, dtype=np.float64)
    u = U / scale
    f = u * u
    F = np.column_stack([u, f.sum(axis=1), f[:, 0] + f[:, 3] - f[:, 1] - f[:, 2],
                         f[:, 0] + f[:, 1] - f[:, 2] - f[:, 3], f[:, 0] - f[:, 1] + f[:, 2] - f[:, 3]])
    return F, scale


def lagged(A, order: int, first: int, t0: int) -> np.ndarray:
    """[A(t - first); ...; A(t - first - order + 1)] for t = t0 .. N-1, as rows."""
    n = A.shape[0]
    if not order:
        return np.zeros((n - t0, 0))
    return np.hstack([A[t0 - first - j:n - first - j] for j in range(order)])


def arx_design(F, Y, orders: Orders):
    """ARX regressors [y(t-1..t-na), f(t-nk..t-nk-nb+1)] for t = t0..N-1."""
    na, nb, nk = orders
    return np.hstack([lagged(Y, na, 1, orders.t0), lagged(F, nb, nk, orders.t0)])


class ArxModel(Model):
    """Linear ARX (see the module doc): ``ArxModel(narx=(na, nb, nk), features="raw")``."""

    kind = "arx"
    fits_segments = True

    def __init__(self, narx=(3, 3, 0), features: str = "raw"):
        self.narx = narx                   # as given (scikit-learn's clone relies on it)
        self.features = features
        self._check_params()

    def _check_params(self) -> None:
        parse_orders(self.narx)
        if self.features not in FEATURES:
            raise ValueError(f"features: unknown {self.features!r}; use 'raw' or 'physics'")

    @property
    def orders(self) -> Orders:
        """The checked orders of ``narx`` (parsed again when ``narx`` changes)."""
        cached = getattr(self, "_orders_cache", None)
        if cached is None or cached[0] is not self.narx:
            cached = (self.narx, parse_orders(self.narx))
            self._orders_cache = cached
        return cached[1]

    @property
    def t0(self) -> int:
        return self.orders.t0

    @property
    def n_features(self) -> int:
        """Columns of f: the inputs (raw) or the physics features."""
        return self.n_inputs_ if self.features == "raw" else N_PHYSICS

    def _features(self, U):
        return U if self.features == "raw" else physics_features(U, self.feature_scale_)[0]

    def _check_length(self, n):
        if n < 4 * (self.t0 + 1) + 10:
            raise ValueError(f"U: {n} samples are too few for orders {tuple(self.orders)}")

    def _fit(self, U, Y, bounds=None, feature_scale=None):
        """Least squares on (U, Y); ``feature_scale``: the physics features' scale to use
        (HybridNarx passes its whole record's to a fit on part of it), default U's own."""
        self._check_params()
        self._check_length(U.shape[0])
        self.y_start_ = Y.mean(axis=0)     # where predict(U) alone starts a free run
        self.n_inputs_, self.n_outputs_ = U.shape[1], Y.shape[1]
        self.feature_scale_ = None
        if self.features == "physics":
            self.feature_scale_ = (physics_features(U)[1] if feature_scale is None
                                   else feature_scale)
        F = self._features(U)
        # one design per segment (records laid end to end): no regressor crosses a seam
        parts = [(a, b) for a, b in (bounds or [(0, U.shape[0])]) if b - a > self.t0]
        if not parts:
            raise ValueError(f"segments: none is longer than t0 = {self.t0} samples")
        R = np.vstack([arx_design(F[a:b], Y[a:b], self.orders) for a, b in parts])
        T = np.vstack([Y[a + self.t0:b] for a, b in parts])
        A = np.c_[R, np.ones(len(R))]
        with np.errstate(over="ignore", invalid="ignore"):
            G = A.T @ A        # products of the data: beyond float64 for values near 1e155
        if not np.all(np.isfinite(G)) or not np.all(np.isfinite(A.T @ T)):
            self.n_outputs_ = None                    # not fitted
            raise ValueError("U, Y: values too large for a least-squares fit in float64 (their "
                             "products overflow); scale the data")
        self.coef_, *_ = np.linalg.lstsq(A, T, rcond=None)
        dof = max(len(A) - A.shape[1], 1)
        sigma2 = np.sum((T - A @ self.coef_) ** 2, axis=0) / dof
        cov = np.linalg.pinv(G)
        self.coef_std_ = np.sqrt(np.outer(np.clip(np.diag(cov), 0, None), sigma2))

    # the input part (B f + c) for rows t0.. of a segment; HybridNarx adds its network here
    def _input_term(self, F):
        na, nb, nk = self.orders
        Wu = self.coef_[na * self.n_outputs_:]
        return np.c_[lagged(F, nb, nk, self.t0), np.ones(F.shape[0] - self.t0)] @ Wu

    def _one_step(self, U, Y):
        na = self.orders.na
        return lagged(Y, na, 1, self.t0) @ self.coef_[:na * self.n_outputs_] + \
            self._input_term(self._features(U))

    def _windows_one_step(self, u, z, W, t0):
        """The last row of each of W stacked windows of t0 + 1 rows, from that row's regressor
        alone (the protocol's default computes every row of every window)."""
        if type(self)._input_term is not ArxModel._input_term:   # HybridNarx adds a network
            return super()._windows_one_step(u, z, W, t0)
        na, nb, nk = self.orders
        z3 = z.reshape(W, t0 + 1, -1)
        f3 = self._features(u).reshape(W, t0 + 1, -1)
        R = np.hstack([z3[:, t0 - 1 - j] for j in range(na)] +
                      [f3[:, t0 - nk - j] for j in range(nb)] + [np.ones((W, 1))])
        return R @ self.coef_

    def _free_run(self, U, Y0):
        na, t0, m = self.orders.na, self.t0, self.n_outputs_
        term = self._input_term(self._features(U))
        Wy = self.coef_[:na * m]
        P = np.zeros((U.shape[0], m))
        P[:t0] = Y0
        for t in range(t0, U.shape[0]):
            past = P[t - na:t][::-1].ravel() if na else np.zeros(0)
            P[t] = past @ Wy + term[t - t0]
            if not np.all(np.isfinite(P[t])):
                raise ValueError("model: the free-run simulation diverged (NaN or Inf)")
        return P[t0:]

    def _coef_names(self):
        na, nb, _ = self.orders
        m = self.n_outputs_
        rows = [f"A[{{o}},{j + 1},{c}]" for j in range(na) for c in range(m)]
        rows += [f"B[{{o}},{j},{c}]" for j in range(nb) for c in range(self.n_features)]
        rows += ["c[{o}]"]
        return rows

    def parameters(self) -> dict:
        self._check_fitted()
        out = {}
        for r, pattern in enumerate(self._coef_names()):
            for o in range(self.n_outputs_):
                out[pattern.format(o=o)] = (float(self.coef_[r, o]), float(self.coef_std_[r, o]))
        return out

    def to_dict(self) -> dict:
        self._check_fitted()
        return {"narx": list(self.orders), "features": self.features,
                "n_inputs": int(self.n_inputs_), "n_outputs": int(self.n_outputs_),
                "feature_scale": None if self.feature_scale_ is None else
                [float(v) for v in self.feature_scale_],
                "coef": [[float(v) for v in row] for row in self.coef_],
                "coef_std": [[float(v) for v in row] for row in self.coef_std_],
                "y_start": None if getattr(self, "y_start_", None) is None else
                [float(v) for v in self.y_start_]}

    @classmethod
    def from_dict(cls, d: dict) -> "ArxModel":
        m = cls(d["narx"], d["features"])
        m._load_arx(d)
        return m

    def _load_arx(self, d: dict):
        self.n_inputs_, self.n_outputs_ = int(d["n_inputs"]), int(d["n_outputs"])
        if self.features == "physics":
            if self.n_inputs_ != 4:
                raise ValueError("model.n_inputs: physics features need 4 inputs")
            self.feature_scale_ = field_array(d["feature_scale"], "model.feature_scale", (4,))
        else:
            if d.get("feature_scale") is not None:
                raise ValueError("model.feature_scale: must be null for raw features")
            self.feature_scale_ = None
        rows = self.orders.na * self.n_outputs_ + self.orders.nb * self.n_features + 1
        self.coef_ = field_array(d["coef"], "model.coef", (rows, self.n_outputs_))
        self.coef_std_ = field_array(d["coef_std"], "model.coef_std", (rows, self.n_outputs_))
        # where predict(U) alone starts a free run (the training mean; absent in older files)
        if d.get("y_start") is not None:
            self.y_start_ = field_array(d["y_start"], "model.y_start", (self.n_outputs_,))
