"""Physics + network flight model trained on the k-step error: kind ``quad_hybrid``.

The quadrotor of ``physics.QuadPhysics`` (the 13 states on the four rotor speeds) with a
network on the residual of its rotational dynamics, used recurrently and trained for what it is
used for: the Levenberg-Marquardt of the core (``_core.kstep_train_lm``,
cpp/include/cdam/host/kstep.hpp) on the K-step simulation error of the body rates, its Jacobian
by forward sensitivities through the rollout.

Per sample (dt, inputs held), with w the body rates::

    w(t+1) = w(t) + d(t) + r o (W2 tanh(W1 x(t) + b1) + b2),  x(t) = [(w(t) - m) / c, phi(t)]

- d(t) the physics increment of the rates: ``prior="dynamic"``: dt (b o tau(f(t - d_rot)) + e)
  of a ``QuadPhysics`` fitted on the same records without the rigid-body coupling and rate
  damping (its rates then depend on the inputs alone); ``prior="hold"``: 0 (the benchmark's
  physics model holds the rates; the network supplies every change);
- phi(t) the roll, pitch and yaw combinations of the squared rotor speeds (delayed like the
  physics' rotation, lagged 0..``lags``-1 samples), each divided by its training std;
- m, c the training mean and std of the rates, r the std of the physics' one-step rate residual
  (the network's output scale); the error of each rate is divided by its training std.

Position, velocity and attitude follow the physics: the translational equations of
``QuadPhysics`` (kT/m, drag) and the quaternion kinematics, one RK4 step per sample with the
rates moving linearly from w(t) to w(t+1) over the step (exact for that path).

Training: windows of ``horizon`` steps from the measured rates (each step's error weighted alike,
or by one over the naive predictor's error at that step: ``weighting``), one every ``stride`` samples
(default: the horizon, so every sample is in one window), inside each record; the network starts
from small weights (uniform +-0.1 from ``seed``, so the model starts as the physics) and runs
``epochs`` LM epochs at most (trainlm's rules). The structure (hidden units, horizon, lags,
prior) is chosen on validation flights outside (``evaluate.crossfold.hybrid_fold``).

What it does not model: the loss sees the rates only; attitude, velocity and position errors
follow from them through the physics.
"""
from __future__ import annotations

import numpy as np

from cdam_core import _core
from cdam_core.base.checks import finite_float, positive_int
from cdam_core.models.flight.physics import (STATES, QuadPhysics, rk4_step,
                                             torque_combinations)
from cdam_core.models.protocol import Model
from cdam_core.models.schema import field_array

__all__ = ["QuadHybrid", "PRIORS", "WEIGHTINGS"]

PRIORS = ("dynamic", "hold")
WEIGHTINGS = ("flat", "naive")
RATES = slice(10, 13)


class QuadHybrid(Model):
    """Quadrotor physics with a recurrent network on its rate residual (module doc).

    Args:
        dt: sample time (s).
        hidden: tanh units of the network.
        horizon: K, the steps of each training window.
        lags: rotor-speed lags (samples) the network sees.
        prior: "dynamic" (the physics' rate increment) or "hold" (none).
        epochs: LM epochs at most.
        stride: samples between window starts (None: the horizon).
        seed: of the initial weights.
        threads: of the core's LM (the result does not depend on it).
        weighting: "flat" (every step's error alike) or "naive" (each step's error divided by
            the naive predictor's RMS error at that step on the training windows, so that every
            horizon counts relative to holding the state, as the benchmark scores it).
    """

    kind = "quad_hybrid"
    unit_quaternion = (6, 7, 8, 9)   # qx, qy, qz, qw among the outputs (evaluate.monitor)
    fits_segments = True

    def __init__(self, dt: float = 0.01, hidden: int = 8, horizon: int = 50, lags: int = 6,
                 prior: str = "dynamic", epochs: int = 15, stride=None, seed: int = 0,
                 threads: int = 2, weighting: str = "naive"):
        self.dt = dt
        self.hidden = hidden
        self.horizon = horizon
        self.lags = lags
        self.prior = prior
        self.epochs = epochs
        self.stride = stride
        self.seed = seed
        self.threads = threads
        self.weighting = weighting
        self._check_params()

    def _check_params(self) -> None:
        finite_float(self.dt, "dt", minimum=0.0, strict=True)
        positive_int(self.hidden, "hidden")
        positive_int(self.horizon, "horizon")
        positive_int(self.lags, "lags")
        positive_int(self.epochs, "epochs", minimum=0)
        positive_int(self.seed, "seed", minimum=0)
        positive_int(self.threads, "threads")
        if self.stride is not None:
            positive_int(self.stride, "stride")
        if self.prior not in PRIORS:
            raise ValueError(f"prior: unknown {self.prior!r}; use 'dynamic' or 'hold'")
        if self.weighting not in WEIGHTINGS:
            raise ValueError(f"weighting: unknown {self.weighting!r}; use 'flat' or 'naive'")

    # -- the parts ---------------------------------------------------------------------------
    @property
    def t0(self) -> int:
        if not hasattr(self, "physics_"):
            return 1 + self.lags
        return self.physics_.t0 + int(self.lags) - 1

    def _features(self, U, idx):
        """phi (len(idx), 3 lags): the torque combinations at the rotation's delay, lagged."""
        p = self.physics_
        cols = [torque_combinations(p._drive(U, idx - j, p.delays_[1])[0])
                for j in range(int(self.lags))]
        return np.concatenate(cols, axis=1) / self.feature_scale_

    def _drift(self, U, idx):
        """d (len(idx), 3): the physics' rate increment over one step."""
        if self.prior == "hold":
            return np.zeros((len(idx), 3))
        p = self.physics_
        f, _ = p._drive(U, idx, p.delays_[1])
        return float(self.dt) * (p.rot_[0:3] * torque_combinations(f) + p.rot_[6:9])

    def _unpack(self):
        H, ni = int(self.hidden), 3 + 3 * int(self.lags)
        th = self.theta_
        W1 = th[:H * ni].reshape(ni, H).T
        b1 = th[H * ni:H * ni + H]
        o = H * ni + H
        return W1, b1, th[o:o + 3 * H].reshape(H, 3).T, th[o + 3 * H:]

    def _rates_next(self, w, U, idx):
        W1, b1, W2, b2 = self._unpack()
        x = np.concatenate([(w - self.in_mean_) / self.in_scale_, self._features(U, idx)], axis=1)
        out = self.out_scale_ * (np.tanh(x @ W1.T + b1) @ W2.T + b2)
        return w + self._drift(U, idx) + out

    def _scales(self, U, Y, rows):
        """Feature, rate and residual scales from the training rows."""
        p = self.physics_
        tau = torque_combinations(p._drive(U, rows, p.delays_[1])[0])
        self.feature_scale_ = np.tile(np.where(tau.std(axis=0) > 0, tau.std(axis=0), 1.0),
                                      int(self.lags))
        w = Y[rows, RATES]
        sd = w.std(axis=0)
        if not np.all(sd > 0):
            raise ValueError("Y: a body rate is constant over the training records")
        self.in_mean_, self.in_scale_ = w.mean(axis=0), sd
        res = Y[rows + 1, RATES] - w - self._drift(U, rows)
        r = res.std(axis=0)
        self.out_scale_ = np.where(r > 0, r, sd)
        self.err_scale_ = sd.copy()

    # -- fit -----------------------------------------------------------------------------------
    def _fit(self, U, Y, bounds=None):
        self._check_params()
        if U.shape[1] != 4 or Y.shape[1] != len(STATES):
            raise ValueError(f"U, Y: the quad_hybrid model takes the 4 rotor speeds and the 13 "
                             f"states {' '.join(STATES)} (got {U.shape[1]} and {Y.shape[1]} "
                             f"columns)")
        bounds = bounds or [(0, U.shape[0])]
        self.physics_ = QuadPhysics(dt=self.dt, rates="dynamic", gyro=False).fit(
            U, Y, segments=[b - a for a, b in bounds])
        K, t0 = int(self.horizon), self.t0
        stride = int(self.stride or K)
        rows = np.concatenate([np.arange(a + t0 - 1, b - 1) for a, b in bounds
                               if b - 1 > a + t0 - 1] or [np.zeros(0, int)])
        starts = np.concatenate([np.arange(a + t0 - 1, b - 1 - K, stride) for a, b in bounds
                                 if b - 1 - K > a + t0 - 1] or [np.zeros(0, int)])
        if starts.size < 2:
            raise ValueError(f"U: too few samples for windows of {K} steps (horizon) after the "
                             f"first {t0} rows of each record")
        self._scales(U, Y, rows)
        S = np.ascontiguousarray(Y[:, RATES], dtype=np.float64)
        E = np.zeros((U.shape[0], 3 * int(self.lags)))
        Dr = np.zeros((U.shape[0], 3))
        E[rows], Dr[rows] = self._features(U, rows), self._drift(U, rows)
        H = int(self.hidden)
        D = _core.kstep_num_params(3, E.shape[1], H)
        theta0 = np.asarray(_core.Rng(int(self.seed)).uniform_array(D, -0.1, 0.1), float)
        weight = None
        if self.weighting == "naive":
            # each step's error over the naive predictor's RMS at that step (training windows)
            naive = S[starts[:, None] + np.arange(1, K + 1)] - S[starts][:, None, :]
            rms = np.sqrt(np.mean((naive / self.err_scale_) ** 2, axis=(0, 2)))
            weight = 1.0 / np.maximum(rms, 1e-3 * rms.max())
            weight /= np.sqrt(np.mean(weight ** 2))
        self.theta_, hist = _core.kstep_train_lm(
            theta0, S, E, Dr, starts.astype(np.int64), K, H, self.in_mean_, self.in_scale_,
            self.out_scale_, self.err_scale_, epochs=int(self.epochs), step_weight=weight,
            threads=int(self.threads))
        self.history_ = {"mse": [float(v) for v in hist["mse"]], "stop": hist["stop"]}
        self.n_inputs_, self.n_outputs_ = 4, len(STATES)
        self.y_start_ = self.physics_.y_start_

    # -- prediction ----------------------------------------------------------------------------
    def _step(self, X, U, idx):
        p = self.physics_
        X = X.astype(np.float64, copy=True)
        X[:, 6:10] /= np.linalg.norm(X[:, 6:10], axis=1, keepdims=True)
        w_next = self._rates_next(X[:, RATES], U, idx)
        thrust = p.trans_[0] * np.sum(p._drive(U, idx, p.delays_[0])[0], axis=1)
        acc = (w_next - X[:, RATES]) / float(self.dt)
        out = rk4_step(X, thrust, acc, p.trans_, np.zeros(9), float(self.dt),
                       float(p.gravity))
        out[:, RATES] = w_next
        return out

    # one-step, stacked windows and free run: the physics model's, on this model's _step
    _one_step = QuadPhysics._one_step
    _windows_one_step = QuadPhysics._windows_one_step
    _free_run = QuadPhysics._free_run

    def parameters(self) -> dict:
        """The physics' parameters (``QuadPhysics.parameters``) and the network's size."""
        self._check_fitted()
        out = dict(self.physics_.parameters())
        out["network_weights"] = (int(self.theta_.size), None)
        return out

    # -- file ------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        self._check_fitted()
        vec = lambda a: [float(v) for v in a]  # noqa: E731
        return {"dt": float(self.dt), "hidden": int(self.hidden), "horizon": int(self.horizon),
                "lags": int(self.lags), "prior": self.prior, "epochs": int(self.epochs),
                "stride": None if self.stride is None else int(self.stride),
                "seed": int(self.seed), "weighting": self.weighting,
                "physics": self.physics_.to_dict(),
                "theta": vec(self.theta_), "in_mean": vec(self.in_mean_),
                "in_scale": vec(self.in_scale_), "out_scale": vec(self.out_scale_),
                "err_scale": vec(self.err_scale_), "feature_scale": vec(self.feature_scale_)}

    @classmethod
    def from_dict(cls, d: dict) -> "QuadHybrid":
        try:
            m = cls(dt=d["dt"], hidden=d["hidden"], horizon=d["horizon"], lags=d["lags"],
                    prior=d["prior"], epochs=d["epochs"], stride=d["stride"], seed=d["seed"],
                    weighting=d["weighting"])
        except ValueError as exc:
            raise ValueError(f"model.{exc}") from None
        try:
            m.physics_ = QuadPhysics.from_dict(d["physics"])
        except ValueError as exc:
            raise ValueError(str(exc).replace("model.", "model.physics.", 1)) from None
        D = _core.kstep_num_params(3, 3 * m.lags, m.hidden)
        m.theta_ = field_array(d["theta"], "model.theta", (D,))
        for name in ("in_mean", "in_scale", "out_scale", "err_scale"):
            setattr(m, name + "_", field_array(d[name], f"model.{name}", (3,)))
        m.feature_scale_ = field_array(d["feature_scale"], "model.feature_scale",
                                       (3 * m.lags,))
        for name in ("in_scale", "out_scale", "err_scale", "feature_scale"):
            if not np.all(getattr(m, name + "_") > 0):
                raise ValueError(f"model.{name}: every scale must be > 0")
        m.n_inputs_, m.n_outputs_ = 4, len(STATES)
        m.y_start_ = m.physics_.y_start_
        return m
