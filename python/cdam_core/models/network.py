"""The BP network as a scikit-learn-style estimator: scaling, initial weights, training, NARX.

`BPNetwork` runs on the C++ core and follows the model protocol (:mod:`.protocol`); the tests
check it against ``cdam_core.reference.BPNetwork``, an estimator written on the numpy twin.
"""
from __future__ import annotations

import math

import numpy as np

from cdam_core import _core
from cdam_core.base.checks import as_2d, finite_float, positive_int, same_rows
from cdam_core.base.orders import parse_orders
from cdam_core.models.protocol import Model, segment_bounds
from cdam_core.models.schema import field_array
from cdam_core.preprocess import MinMaxScaler

__all__ = ["BPNetwork", "hidden_node_candidates", "mean_network"]


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


class BPNetwork(Model):
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

    kind = "bp_network"

    def __init__(self, hidden=20, activation="tansig", trainer="lm", *, epochs=1000, goal=0.0,
                 mu=1e-3, mu_dec=0.1, mu_inc=10.0, mu_max=1e10, min_grad=1e-7, max_fail=6,
                 lr=0.01, validation_fraction=0.0, narx=None, seed=0, threads=2):
        # stored as given (scikit-learn's clone and set_params rely on it), checked here and
        # normalised where used (_settings)
        self.hidden = hidden
        self.activation = activation
        self.trainer = trainer
        self.epochs, self.goal, self.mu, self.mu_dec = epochs, goal, mu, mu_dec
        self.mu_inc, self.mu_max, self.min_grad, self.max_fail = mu_inc, mu_max, min_grad, max_fail
        self.lr, self.validation_fraction = lr, validation_fraction
        self.narx = narx
        self.seed, self.threads = seed, threads
        self._settings()

    def _settings(self) -> dict:
        """The parameters checked and as plain Python numbers (ValueError naming a bad one)."""
        if self.activation not in ("tansig", "logsig"):
            raise ValueError(f"activation: unknown {self.activation!r}; use 'tansig' or 'logsig'")
        if self.trainer not in ("lm", "gd"):
            raise ValueError(f"trainer: unknown {self.trainer!r}; use 'lm' or 'gd'")
        s = {"hidden": "auto" if isinstance(self.hidden, str) and self.hidden == "auto"
             else positive_int(self.hidden, "hidden"),
             "epochs": positive_int(self.epochs, "epochs", minimum=0),
             "goal": finite_float(self.goal, "goal", minimum=0.0),
             "mu": finite_float(self.mu, "mu", minimum=0.0, strict=True),
             "mu_dec": finite_float(self.mu_dec, "mu_dec", minimum=0.0, strict=True),
             "mu_inc": finite_float(self.mu_inc, "mu_inc", minimum=1.0, strict=True),
             "mu_max": finite_float(self.mu_max, "mu_max", minimum=0.0, strict=True),
             "min_grad": finite_float(self.min_grad, "min_grad", minimum=0.0),
             "max_fail": positive_int(self.max_fail, "max_fail"),
             "lr": finite_float(self.lr, "lr", minimum=0.0, strict=True),
             "validation_fraction": finite_float(self.validation_fraction,
                                                 "validation_fraction", minimum=0.0),
             "narx": tuple(parse_orders(self.narx)) if self.narx is not None else None,
             "seed": positive_int(self.seed, "seed", minimum=0),
             "threads": positive_int(self.threads, "threads")}
        if s["validation_fraction"] >= 1.0:
            raise ValueError("validation_fraction: must be < 1")
        return s

    # ---- helpers ----
    @property
    def t0(self) -> int:
        return 0 if self.narx is None else parse_orders(self.narx).t0

    def _orders(self) -> tuple:
        return tuple(parse_orders(self.narx))

    def _start_outputs(self) -> np.ndarray:
        """The middle of the training output range (0 in the network's scaled units)."""
        return 0.5 * (self.scaler_y_.data_min_ + self.scaler_y_.data_max_)

    @property
    def dynamic(self) -> bool:
        return self.narx is not None

    def _design(self, Us, Ys):
        """Network inputs and targets from scaled signals (NARX regressors when narx is set)."""
        if self.narx is None:
            return Us, Ys
        na, nb, nk = self._orders()
        if Us.shape[0] <= self.t0:
            raise ValueError(f"U: {Us.shape[0]} samples, NARX needs more than t0 = {self.t0}")
        return _core.narx_regressors(Us, Ys, na, nb, nk), Ys[self.t0:]

    def _initial_theta(self, n_in, h, n_out, dtype):
        D = n_in * h + h + h * n_out + n_out
        return np.asarray(_core.Rng(int(self.seed)).uniform_array(D, -1.0, 1.0), dtype=dtype)

    # ---- estimator API ----
    fits_segments = True

    def fit(self, U, Y, theta0=None, validation=None, callback=None, segments=None,
            stride=1) -> "BPNetwork":
        """Train on inputs U (N, i) and outputs Y (N, m).

        ``validation=(U_val, Y_val)`` early-stops LM (max_fail) and returns the best-validation
        weights; ``callback(epoch, mse)`` is called each epoch (return False to stop).
        ``segments`` (lengths or (start, stop) ranges, as for ``predict``): records laid end to
        end; no NARX regressor crosses a seam (a segment of no more than t0 rows gives none).
        ``stride``: train on every ``stride``-th row of the design (regressors and targets,
        all segments together; the scalers still see every row): the cost of an LM epoch grows
        with the rows, so long records can be thinned.
        """
        cfg = self._settings()                    # set_params or attribute edits since __init__
        U = as_2d(U, "U")
        if Y is None:
            raise ValueError("Y: the measured outputs are required (requires y to be passed, "
                             "but the target y is None)")
        Y1 = Y
        Y = as_2d(Y, "Y", dtype=U.dtype)
        same_rows(U, Y, "U, Y")
        bounds = segment_bounds(segments, U.shape[0])
        stride = positive_int(stride, "stride")
        val = None
        if len(bounds) > 1 and validation is None and cfg["validation_fraction"] > 0:
            raise ValueError("validation_fraction: not with several segments; give validation")
        if validation is not None:
            if len(validation) != 2:
                raise ValueError("validation: expected (U_val, Y_val)")
            Uv = as_2d(validation[0], "U_val", dtype=U.dtype)
            Yv = as_2d(validation[1], "Y_val", dtype=U.dtype)
            same_rows(Uv, Yv, "U_val, Y_val")
            if Uv.shape[1] != U.shape[1] or Yv.shape[1] != Y.shape[1]:
                raise ValueError("validation: channel counts differ from U, Y")
            val = (Uv, Yv)
        elif cfg["validation_fraction"] > 0:
            n_val = int(round(U.shape[0] * cfg["validation_fraction"]))
            if n_val < 1 or U.shape[0] - n_val < 1:
                raise ValueError("validation_fraction: leaves no training or no validation samples")
            val = (U[-n_val:], Y[-n_val:])
            U, Y = U[:-n_val], Y[:-n_val]
        self.n_inputs_, self.n_outputs_ = U.shape[1], Y.shape[1]
        self.scaler_x_ = MinMaxScaler().fit(U)
        self.scaler_y_ = MinMaxScaler().fit(Y)
        Us, Ys = self.scaler_x_.transform(U), self.scaler_y_.transform(Y)
        parts = [self._design(Us[a:b], Ys[a:b]) for a, b in bounds if b - a > self.t0]
        if not parts:
            raise ValueError(f"segments: none has more than t0 = {self.t0} samples")
        X, T = (np.ascontiguousarray(np.vstack([p[j] for p in parts])[::stride])
                for j in (0, 1))
        Xv = Tv = None
        if val is not None:
            Xv, Tv = self._design(self.scaler_x_.transform(val[0]), self.scaler_y_.transform(val[1]))
        candidates = (hidden_node_candidates(X.shape[1], T.shape[1]) if cfg["hidden"] == "auto"
                      else [cfg["hidden"]])
        best = None
        for h in candidates:
            if theta0 is not None and len(candidates) == 1:
                th0 = as_2d(np.ravel(theta0), "theta0", dtype=U.dtype)[:, 0]
                D = X.shape[1] * h + h + h * T.shape[1] + T.shape[1]
                if th0.shape[0] != D:
                    raise ValueError(f"theta0: expected length {D}, got {th0.shape[0]}")
            else:
                th0 = self._initial_theta(X.shape[1], h, T.shape[1], U.dtype)
            theta, hist = self._train(cfg, th0, X, T, h, Xv, Tv, callback)
            final = hist["mse"][-1]
            if best is None or final < best[0]:
                best = (final, h, theta, hist)
        _, self.hidden_, self.theta_, self.history_ = best
        self._note_target(Y1)
        return self

    def _train(self, cfg, theta0, X, T, h, Xv, Tv, callback):
        k = _core
        extra = {"threads": cfg["threads"], "callback": callback}
        if self.trainer == "gd":
            return k.train_gd(theta0, X, T, h, self.activation, lr=cfg["lr"],
                              epochs=cfg["epochs"], goal=cfg["goal"], **extra)
        return k.train_lm(theta0, X, T, h, self.activation, epochs=cfg["epochs"], goal=cfg["goal"],
                          mu=cfg["mu"], mu_dec=cfg["mu_dec"], mu_inc=cfg["mu_inc"],
                          mu_max=cfg["mu_max"], min_grad=cfg["min_grad"],
                          max_fail=cfg["max_fail"], X_val=Xv, T_val=Tv, **extra)

    def _fit(self, U, Y):
        self.fit(U, Y)

    def is_fitted(self) -> bool:
        return getattr(self, "theta_", None) is not None

    # ---- the protocol's prediction kernels (rows t0.. of one segment, physical units) ----
    def _static(self, U):
        U = U.astype(self.theta_.dtype, copy=False)
        Ys = _core.mlp_forward(self.theta_, self.scaler_x_.transform(U), self.hidden_,
                               self.n_outputs_, self.activation)
        return self.scaler_y_.inverse_transform(Ys)

    def _one_step(self, U, Y):
        dt = self.theta_.dtype
        X = _core.narx_regressors(self.scaler_x_.transform(U.astype(dt, copy=False)),
                                  self.scaler_y_.transform(Y.astype(dt, copy=False)),
                                  *self._orders())
        Ys = _core.mlp_forward(self.theta_, X, self.hidden_, self.n_outputs_, self.activation)
        return self.scaler_y_.inverse_transform(Ys)

    def _free_run(self, U, Y0):
        dt, t0 = self.theta_.dtype, self.t0
        Ys0 = (self.scaler_y_.transform(Y0.astype(dt, copy=False)) if t0
               else np.zeros((0, self.n_outputs_), dt))
        Ys = _core.narx_simulate(self.theta_, self.scaler_x_.transform(U.astype(dt, copy=False)),
                                 Ys0, self.hidden_, self.activation, *self._orders())
        return self.scaler_y_.inverse_transform(Ys)[t0:]

    # ---- model file section ----
    def to_dict(self) -> dict:
        self._check_fitted()
        return {"hidden": int(self.hidden_), "activation": self.activation,
                "narx": list(self._orders()) if self.narx is not None else None,
                "n_inputs": int(self.n_inputs_), "n_outputs": int(self.n_outputs_),
                "theta": [float(v) for v in np.asarray(self.theta_, dtype=np.float64)],
                "x_min": [float(v) for v in self.scaler_x_.data_min_],
                "x_max": [float(v) for v in self.scaler_x_.data_max_],
                "y_min": [float(v) for v in self.scaler_y_.data_min_],
                "y_max": [float(v) for v in self.scaler_y_.data_max_]}

    @classmethod
    def from_dict(cls, d: dict) -> "BPNetwork":
        i, m, h = int(d["n_inputs"]), int(d["n_outputs"]), int(d["hidden"])
        narx = parse_orders(d["narx"], "model.narx") if d["narx"] is not None else None
        net = cls(hidden=h, activation=d["activation"], narx=narx)
        n_in = i if narx is None else narx.n_regressors(i, m)
        D = _core.mlp_num_params(n_in, h, m)
        net.theta_ = field_array(d["theta"], "model.theta", (D,))
        sx, sy = MinMaxScaler(), MinMaxScaler()
        sx.data_min_ = field_array(d["x_min"], "model.x_min", (i,))
        sx.data_max_ = field_array(d["x_max"], "model.x_max", (i,))
        sy.data_min_ = field_array(d["y_min"], "model.y_min", (m,))
        sy.data_max_ = field_array(d["y_max"], "model.y_max", (m,))
        for name, s in (("x", sx), ("y", sy)):
            if np.any(s.data_max_ < s.data_min_):
                raise ValueError(f"model.{name}_max: below {name}_min")
        net.hidden_, net.n_inputs_, net.n_outputs_ = h, i, m
        net.scaler_x_, net.scaler_y_ = sx, sy
        net.history_ = None
        return net

    def parameters(self) -> dict:
        self._check_fitted()
        return {f"theta[{k}]": (float(v), None) for k, v in enumerate(self.theta_)}


def mean_network(nets) -> BPNetwork:
    """One static :class:`BPNetwork` whose output is the mean of ``nets``' outputs (an
    ensemble, e.g. the same network trained from several seeds), exactly: members fitted on the
    same data share their min-max scalers, so the mean of their outputs is the back-scaling of
    the mean of their scaled outputs, a network with the members' hidden units side by side
    (K h units in all), output weights W2_k / K and output bias mean(b2_k). The result is a plain
    network (model file, firmware, monitor take it as any other). ``nets``: fitted static
    networks with the same activation, inputs, outputs and scalers (ValueError naming the
    mismatch otherwise)."""
    nets = list(nets)
    if not nets:
        raise ValueError("nets: need at least one fitted network")
    first = nets[0]
    for k, n in enumerate(nets):
        if not isinstance(n, BPNetwork) or not n.is_fitted() or n.narx is not None:
            raise ValueError(f"nets[{k}]: must be a fitted static BPNetwork")
        if n.activation != first.activation:
            raise ValueError(f"nets[{k}]: activation {n.activation!r} differs from "
                             f"{first.activation!r}")
        if (n.n_inputs_, n.n_outputs_) != (first.n_inputs_, first.n_outputs_):
            raise ValueError(f"nets[{k}]: {n.n_inputs_} inputs, {n.n_outputs_} outputs differ "
                             f"from {first.n_inputs_}, {first.n_outputs_}")
        for name in ("scaler_x_", "scaler_y_"):
            a, b = getattr(n, name), getattr(first, name)
            if not (np.array_equal(a.data_min_, b.data_min_)
                    and np.array_equal(a.data_max_, b.data_max_)):
                raise ValueError(f"nets[{k}]: {name[:-1]} differs from nets[0]'s (members must "
                                 "be fitted on the same data)")
    if len(nets) == 1:
        return first
    i, m, K = int(first.n_inputs_), int(first.n_outputs_), len(nets)
    dt = np.result_type(*(n.theta_.dtype for n in nets))
    W1, b1, W2, b2 = [], [], [], []
    for n in nets:
        h = int(n.hidden_)
        th = np.asarray(n.theta_, dt)
        W1.append(th[:i * h].reshape(h, i, order="F"))
        b1.append(th[i * h:i * h + h])
        W2.append(th[i * h + h:i * h + h + h * m].reshape(m, h, order="F") / K)
        b2.append(th[i * h + h + h * m:])
    H = sum(int(n.hidden_) for n in nets)
    out = BPNetwork(hidden=H, activation=first.activation, seed=first.seed)
    out.theta_ = np.concatenate([np.vstack(W1).ravel(order="F"), np.concatenate(b1),
                                 np.hstack(W2).ravel(order="F"), np.mean(b2, axis=0)]).astype(dt)
    out.hidden_, out.n_inputs_, out.n_outputs_ = H, i, m
    out.scaler_x_, out.scaler_y_ = first.scaler_x_, first.scaler_y_
    out.history_ = None
    out._target_1d = getattr(first, "_target_1d", False)
    return out
