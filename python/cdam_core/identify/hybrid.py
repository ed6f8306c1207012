"""Hybrid NARX: a linear ARX part plus a BP network on its residual, and physics features.

Why: on the AR.Drone 2.0 flight the paper's static network and a plain NARX network lose to a
linear ARX model in free run (the network's feedback drifts; a static map cannot follow the
pose). The hybrid keeps the linear dynamics and lets a network (seeded by IBOA, BOA, CABC or
plain BP) add a bounded nonlinear term of the inputs only, so it cannot destabilise the free
run:

    y(t) = A [y(t-1); ...; y(t-na)] + B [f(t-nk); ...; f(t-nk-nb+1)] + c
           + alpha * N([f(t-nk); ...; f(t-nk-nb+1)])

f = features of the inputs (``"raw"``: the inputs; ``"physics"``: for four motor commands in
X-mixer order (1 front-left, 2 front-right, 3 rear-right, 4 rear-left; the AR.Drone's) the
commands scaled by their training maximum, plus thrust ~ sum u_i^2 and the roll, pitch and yaw
torque combinations of u_i^2). A, B, c: least squares on the training record (one-step).
N: the BP network trained on the one-step residual with the chosen algorithm, on the first
``1 - validation_fraction`` of the training record; alpha in {0, 1} is chosen by the free-run
mean Pearson r on the last ``validation_fraction`` of the training record (test data is never
seen). ``residual_weight_`` says which was chosen: 0 means the network did not help.

:func:`select_structure` chooses decimation, orders, delay and features by the same
validation on the training record only.
"""
from __future__ import annotations

import numpy as np

__all__ = ["HybridNarx", "physics_features", "select_structure", "arx_design"]

FEATURES = ("raw", "physics")


def _check_2d(a, name):
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{name}: expected a non-empty (N, C) array, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or Inf")
    return a


def physics_features(U, scale=None):
    """Physics features of four motor commands U (N, 4) in X-mixer order (see module doc).

    Returns (F (N, 8), scale): [u / scale (4), T, tau_roll, tau_pitch, tau_yaw] with
    f_i = (u_i / scale_i)^2, T = sum f_i, tau_roll = f1 + f4 - f2 - f3,
    tau_pitch = f1 + f2 - f3 - f4, tau_yaw = f1 - f2 + f3 - f4. ``scale`` (4,) defaults to the
    per-command maximum of |U| (1 where that is 0); pass the training scale for other records.
    """
    U = _check_2d(U, "U")
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


def _lags(A, order, first, t0):
    """[A(t - first); ...; A(t - first - order + 1)] for t = t0 .. N-1, as rows."""
    n = A.shape[0]
    return np.hstack([A[t0 - first - j:n - first - j] for j in range(order)]) if order else \
        np.zeros((n - t0, 0))


def arx_design(F, Y, na, nb, nk):
    """ARX regressors [y(t-1..t-na), f(t-nk..t-nk-nb+1)] for t = t0..N-1 and t0."""
    t0 = max(na, nk + nb - 1)
    return np.hstack([_lags(Y, na, 1, t0), _lags(F, nb, nk, t0)]), t0


def _pearson_mean(Y, P):
    r = []
    for k in range(Y.shape[1]):
        a, b = Y[:, k] - Y[:, k].mean(), P[:, k] - P[:, k].mean()
        d = np.sqrt((a @ a) * (b @ b))
        r.append(a @ b / d if d > 0 else 0.0)
    return float(np.mean(r))


class HybridNarx:
    """Linear ARX + BP network on the residual (see the module doc).

    Args:
        narx: (na, nb, nk) orders of the linear part and the network's input lags.
        features: "raw" or "physics" (four motor commands).
        algo: "iboa", "boa", "cabc" or "bp" for the residual network; None: linear only.
        config: IdentifyConfig of the residual network run (hidden, iterations, LM...).
        seed: seed of the residual network run.
        validation_fraction: tail of the training record that chooses alpha.
    """

    def __init__(self, narx=(3, 3, 0), features="raw", algo="iboa", config=None, seed=0,
                 validation_fraction=0.2):
        if len(tuple(narx)) != 3 or min(int(v) for v in narx) < 0 or int(narx[0]) + int(narx[1]) < 1:
            raise ValueError(f"narx: expected (na, nb, nk) >= 0 with na + nb >= 1, got {narx!r}")
        if features not in FEATURES:
            raise ValueError(f"features: unknown {features!r}; use 'raw' or 'physics'")
        if algo is not None and algo not in ("iboa", "boa", "cabc", "bp"):
            raise ValueError(f"algo: unknown {algo!r}")
        if not 0.0 < float(validation_fraction) < 1.0:
            raise ValueError("validation_fraction: must be in (0, 1)")
        self.narx = tuple(int(v) for v in narx)
        self.features = features
        self.algo = algo
        self.config = config
        self.seed = int(seed)
        self.validation_fraction = float(validation_fraction)

    @property
    def t0(self) -> int:
        na, nb, nk = self.narx
        return max(na, nk + nb - 1)

    def _features(self, U):
        if self.features == "raw":
            return U
        return physics_features(U, self.feature_scale_)[0]

    def fit(self, U, Y) -> "HybridNarx":
        """Fit on inputs U (N, i) and outputs Y (N, m) (one record, in time order)."""
        from .pipelines import IdentifyConfig, identify
        U = _check_2d(U, "U")
        Y = _check_2d(Y, "Y")
        if U.shape[0] != Y.shape[0]:
            raise ValueError(f"U, Y: {U.shape[0]} and {Y.shape[0]} samples")
        na, nb, nk = self.narx
        if U.shape[0] < 4 * (self.t0 + 1) + 10:
            raise ValueError(f"U: {U.shape[0]} samples are too few for orders {self.narx}")
        self.n_inputs_, self.n_outputs_ = U.shape[1], Y.shape[1]
        self.feature_scale_ = physics_features(U)[1] if self.features == "physics" else None
        F = self._features(U)
        R, t0 = arx_design(F, Y, na, nb, nk)
        A = np.c_[R, np.ones(len(R))]
        self.coef_ = np.linalg.lstsq(A, Y[t0:], rcond=None)[0]
        self.net_, self.residual_weight_, self.run_ = None, 0.0, None
        self.validation_r_ = {}
        if self.algo is not None:
            cfg = self.config or IdentifyConfig(hidden=5, iterations=20, lm_epochs=30)
            cfg = IdentifyConfig(**{**cfg.to_dict(), "narx": None, "smoothing_passes": 0,
                                    "bounds": tuple(cfg.bounds), "model": "bp",
                                    "features": "raw"})
            resid = Y[t0:] - A @ self.coef_
            Xn = _lags(F, nb, nk, t0)
            n_fit = int(round(len(Xn) * (1 - self.validation_fraction)))
            self.run_ = identify(self.algo, Xn[:n_fit], resid[:n_fit], seed=self.seed, config=cfg)
            self.net_ = self.run_.model
            v0 = t0 + n_fit - self.t0  # validation record, with t0 samples of history
            Uv, Yv = U[v0:], Y[v0:]
            for w in (0.0, 1.0):
                self.residual_weight_ = w
                P = self.predict(Uv, Yv, mode="free_run")
                self.validation_r_[w] = _pearson_mean(Yv[self.t0:], P[self.t0:])
            self.residual_weight_ = 1.0 if self.validation_r_[1.0] > self.validation_r_[0.0] else 0.0
        P = self.predict(U, Y)
        lo, hi = Y.min(axis=0), Y.max(axis=0)
        span = np.where(hi > lo, hi - lo, 1.0)
        self.train_mse_ = float(np.mean(((P[t0:] - Y[t0:]) * 2.0 / span) ** 2))
        return self

    def _input_term(self, F):
        na, nb, nk = self.narx
        t0 = self.t0
        Xn = _lags(F, nb, nk, t0)
        Wu = self.coef_[na * self.n_outputs_:]
        term = np.c_[Xn, np.ones(len(Xn))] @ Wu
        if self.net_ is not None and self.residual_weight_ != 0.0:
            term = term + self.residual_weight_ * self.net_.predict(Xn)
        return term

    def predict(self, U, Y, mode="one_step") -> np.ndarray:
        """Outputs (N, m): ``one_step`` from measured past outputs Y, ``free_run`` from Y[:t0]
        only (the first t0 rows are the measured Y[:t0])."""
        if getattr(self, "coef_", None) is None:
            raise ValueError("HybridNarx: not fitted; call fit(U, Y) first")
        U = _check_2d(U, "U")
        Y = _check_2d(Y, "Y")
        if U.shape[1] != self.n_inputs_ or Y.shape[1] != self.n_outputs_ or len(U) != len(Y):
            raise ValueError(f"U, Y: expected (N, {self.n_inputs_}) and (N, {self.n_outputs_})")
        if mode not in ("one_step", "free_run"):
            raise ValueError(f"mode: unknown {mode!r}; use 'one_step' or 'free_run'")
        t0, m = self.t0, self.n_outputs_
        if len(U) <= t0:
            raise ValueError(f"U: needs more than t0 = {t0} samples")
        na = self.narx[0]
        term = self._input_term(self._features(U))
        Wy = self.coef_[:na * m]
        P = Y.copy()
        if mode == "one_step":
            P[t0:] = _lags(Y, na, 1, t0) @ Wy + term
            return P
        for t in range(t0, len(U)):
            past = P[t - na:t][::-1].ravel() if na else np.zeros(0)
            P[t] = past @ Wy + term[t - t0]
            if not np.all(np.isfinite(P[t])):
                raise ValueError("model: the free-run simulation diverged (NaN or Inf)")
        return P


def select_structure(U, Y, *, decimations=(1,), orders=(2, 3, 4), delays=(0, 1),
                     features=("raw", "physics"), validation_fraction=0.2) -> dict:
    """Choose (decimation, narx, features) of the linear part by free-run mean Pearson r on
    the last ``validation_fraction`` of the training record U, Y (never the test data).

    Each decimation d keeps every d-th sample of U, Y (1: the record's own rate; the caller
    decimates the test record the same way); na = nb = each of ``orders``, nk each of
    ``delays``. Returns {"decimation", "narx", "features", "validation_r",
    "table": [(r, decimation, narx, features), ...] best first}.
    """
    U = _check_2d(U, "U")
    Y = _check_2d(Y, "Y")
    table = []
    for d in decimations:
        if int(d) < 1:
            raise ValueError(f"decimations: must be >= 1, got {d!r}")
        Ud, Yd = U[::int(d)], Y[::int(d)]
        n_fit = int(round(len(Ud) * (1 - validation_fraction)))
        for feat in features:
            for o in orders:
                for nk in delays:
                    model = HybridNarx((o, o, nk), feat, algo=None)
                    try:
                        model.fit(Ud[:n_fit], Yd[:n_fit])
                        v0 = n_fit - model.t0
                        P = model.predict(Ud[v0:], Yd[v0:], mode="free_run")
                    except ValueError:
                        continue
                    r = _pearson_mean(Yd[n_fit:], P[model.t0:])
                    table.append((r, int(d), (o, o, nk), feat))
    if not table:
        raise ValueError("U, Y: no structure could be fitted (record too short?)")
    table.sort(key=lambda row: -row[0])
    r, d, narx, feat = table[0]
    return {"decimation": d, "narx": narx, "features": feat, "validation_r": r, "table": table}
