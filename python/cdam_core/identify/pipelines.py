"""The identification pipelines: IBOA-BP, BOA-BP, CABC-BP and plain BP.

One run (``identify``):
1. preprocess: five-point cubic smoothing (``smoothing_passes`` passes) of the training inputs
   and outputs; min-max scaling to [-1, 1] fitted on the training data only (inside
   :class:`cdam_core.BPNetwork`);
2. optimise the initial weights and thresholds with BOA / IBOA / CABC on the BP fitness (the
   training MSE in normalised units of the network given by the individual, evaluated entirely
   in C++); plain BP starts from uniform [-1, 1] weights drawn from ``Rng(seed)``;
3. refine with Levenberg-Marquardt (trainlm semantics; Table 1: at most 50 epochs, goal 0.003);
4. back-normalise the predictions (``BPNetwork.predict``) and evaluate per output
   (:func:`evaluate`): Pearson r, RMSE, NRMSE, one-step and, for NARX models, free-run.
The reported "fitness" is the adaptation value 1 / (1 + MSE) of the final training MSE.

``IdentifyConfig(model="hybrid", narx=(na, nb, nk), features="raw"|"physics")`` identifies a
linear ARX part by least squares and trains the algorithm's network on its residual
(identify/hybrid.py); its final MSE is the combined model's one-step training MSE in min-max
normalised units.

The numpy twins compose the same pipeline in benchmarks/bench_identify.py (the baseline).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np

from cdam_core import _core
from cdam_core.base.metrics import adaptation_value
from cdam_core.base.orders import parse_orders
from cdam_core.models.hybrid import HybridNarx
from cdam_core.models.network import BPNetwork
from cdam_core.models.protocol import segment_bounds
from cdam_core.preprocess import MinMaxScaler, smooth_pair

__all__ = ["ALGORITHMS", "IdentifyConfig", "IdentifyRun", "identify", "preprocess"]

ALGORITHMS = ("iboa", "boa", "cabc", "bp")


@dataclass
class IdentifyConfig:
    """Settings of a pipeline run (defaults: the paper's Table 1 where it is readable).

    ``boa_c`` and ``boa_a`` default to the BOA author's 0.01 and 0.1: Table 1's "c = 2" (with its
    unexplained "rid" and "r") is not used by default. ``optimiser_options`` adds or overrides
    any option of the C++ optimisers (see cdam_core.reference.optimisers).
    """

    hidden: int = 20
    activation: str = "tansig"
    narx: tuple | None = None
    smoothing_passes: int = 5
    population: int = 20          # g (BOA/IBOA butterflies) and Np (CABC colony)
    iterations: int = 50          # Tmax
    switch_probability: float = 0.8
    boa_c: float = 0.01
    boa_a: float = 0.1
    boa_form: str = "author"
    cabc_limit: int = 20
    bounds: tuple = (-1.0, 1.0)
    lm_epochs: int = 50
    lm_goal: float = 0.003
    threads: int = 2
    fitness_precision: str = "float64"  # the swarm's BP fitness: "float64" or "float32"
    optimiser_options: dict = field(default_factory=dict)
    model: str = "bp"             # "bp": the paper's network; "hybrid": ARX + residual network
    features: str = "raw"         # "raw" or "physics" (hybrid only; identify/hybrid.py)
    max_rows: int | None = None   # bp: the optimiser and LM see at most this many evenly
                                  # spaced training rows (every ceil(rows / max_rows)-th)
    ensemble: int = 1             # hybrid: residual networks averaged (seeds seed .. seed+K-1)
    residual_weights: tuple = (0.0, 1.0)   # hybrid: candidate weights of the network's term
    validation_blocks: int = 0    # hybrid: 0: choose the weight on the last 20 %; B: B blocks
    residual_training: str = "one_step"   # hybrid: "one_step" or "free_run" (HybridNarx)

    def __post_init__(self):
        if self.hidden != "auto" and (not isinstance(self.hidden, (int, np.integer))
                                      or self.hidden < 1):
            raise ValueError(f"hidden: must be a positive integer, got {self.hidden!r}")
        if not isinstance(self.smoothing_passes, (int, np.integer)) or self.smoothing_passes < 0:
            raise ValueError("smoothing_passes: must be an integer >= 0")
        for name in ("population", "iterations", "lm_epochs", "threads"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < (0 if name != "population" and
                                                           name != "threads" else 1):
                raise ValueError(f"{name}: must be a non-negative integer, got {v!r}")
        if self.narx is not None:
            narx = tuple(int(v) for v in self.narx)
            if len(narx) != 3 or min(narx) < 0 or narx[0] + narx[1] < 1:
                raise ValueError(f"narx: expected (na, nb, nk) >= 0 with na + nb >= 1, "
                                 f"got {self.narx!r}")
            self.narx = narx
        if self.max_rows is not None and (isinstance(self.max_rows, bool) or not isinstance(
                self.max_rows, (int, np.integer)) or self.max_rows < 1):
            raise ValueError(f"max_rows: must be a positive integer or None, got {self.max_rows!r}")
        if self.fitness_precision not in ("float64", "float32"):
            raise ValueError(f"fitness_precision: unknown {self.fitness_precision!r}; "
                             "use 'float64' or 'float32'")
        if self.model not in ("bp", "hybrid"):
            raise ValueError(f"model: unknown {self.model!r}; use 'bp' or 'hybrid'")
        if self.features not in ("raw", "physics"):
            raise ValueError(f"features: unknown {self.features!r}; use 'raw' or 'physics'")
        if self.model == "bp" and self.features != "raw":
            raise ValueError("features: 'physics' needs model='hybrid'")
        if self.model == "hybrid" and self.narx is None:
            raise ValueError("narx: model='hybrid' needs orders (na, nb, nk)")
        if self.model == "hybrid":
            from cdam_core.models.hybrid import HybridNarx
            HybridNarx(self.narx, self.features, ensemble=self.ensemble,
                       weights=self.residual_weights,
                       validation_blocks=self.validation_blocks,
                       training=self.residual_training)._check_params()
            self.residual_weights = tuple(float(w) for w in self.residual_weights)
        lb, ub = (float(b) for b in self.bounds)
        if not (np.isfinite(lb) and np.isfinite(ub) and lb < ub):
            raise ValueError(f"bounds: expected finite (lb, ub) with lb < ub, got {self.bounds!r}")
        self.bounds = (lb, ub)

    def options(self, algo: str) -> dict:
        """The optimiser options dict for ``algo`` ('boa', 'iboa', 'cabc')."""
        o = {"n": int(self.population), "iterations": int(self.iterations),
             "lb": self.bounds[0], "ub": self.bounds[1]}
        if algo in ("boa", "iboa"):
            o.update(p=self.switch_probability, c=self.boa_c, a=self.boa_a, form=self.boa_form)
        else:
            o.update(limit=int(self.cabc_limit))
        extra = {k: v for k, v in self.optimiser_options.items()
                 if algo == "iboa" or k not in ("clusters", "kmeans_iters", "phi",
                                                "chaos_candidates", "chaos_form", "chaos_scale")}
        if algo == "cabc":
            extra = {k: v for k, v in extra.items() if k not in ("p", "c", "a", "form")}
        else:
            extra = {k: v for k, v in extra.items()
                     if k not in ("limit", "scout_candidates", "scout_radius")}
        o.update(extra)
        return o

    def to_dict(self) -> dict:
        d = asdict(self)
        d["bounds"] = list(self.bounds)
        d["narx"] = list(self.narx) if self.narx else None
        d["residual_weights"] = list(self.residual_weights)
        return d


@dataclass
class IdentifyRun:
    """The result of one pipeline run."""

    algo: str
    seed: int
    model: object                   # fitted cdam_core.BPNetwork (or its reference twin)
    curve: np.ndarray | None        # optimiser best MSE per iteration (Tmax + 1), None for bp
    optimiser_mse: float | None     # best individual's training MSE before LM
    evaluations: int
    lm_mse: np.ndarray              # LM training MSE per epoch
    final_mse: float
    seconds: dict                   # optimise, lm, total

    @property
    def fitness(self) -> float:
        """Adaptation value 1 / (1 + final training MSE)."""
        return adaptation_value(self.final_mse)


preprocess = smooth_pair   # the pipeline's step 1 (cdam_core.preprocess.smooth_pair)


def identify(algo: str, U, Y, *, seed: int = 0, config: IdentifyConfig | None = None,
             preprocessed: bool = False, segments=None) -> IdentifyRun:
    """Run one pipeline (``algo`` in 'iboa', 'boa', 'cabc', 'bp') on training inputs U (N, i)
    and outputs Y (N, m). ``preprocessed=True`` skips the smoothing (already done).
    ``segments`` (bp model only): records laid end to end (lengths or (start, stop) ranges),
    each smoothed on its own (one of fewer than 5 rows is left as measured), no NARX
    regressor crossing a seam."""
    if algo not in ALGORITHMS:
        raise ValueError(f"algo: unknown {algo!r}; use one of {', '.join(ALGORITHMS)}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise ValueError(f"seed: must be an integer in 0 .. 2**32 - 1, got {seed!r}")
    cfg = config or IdentifyConfig()
    U = np.asarray(U, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    if U.ndim != 2 or Y.ndim != 2 or U.shape[0] != Y.shape[0] or U.size == 0 or Y.size == 0:
        raise ValueError(f"U, Y: expected non-empty (N, i) and (N, m) arrays with the same N, "
                         f"got {U.shape} and {Y.shape}")
    if not (np.all(np.isfinite(U)) and np.all(np.isfinite(Y))):
        raise ValueError("U, Y: contain NaN or Inf")
    t_start = time.perf_counter()
    bounds = segment_bounds(segments, U.shape[0])
    if len(bounds) > 1 and cfg.model != "bp":
        raise ValueError("segments: a hybrid model is fitted on one record")
    if not preprocessed:
        # a segment too short for the five-point smoother (< 5 rows) stays as measured
        parts = [preprocess(U[a:b], Y[a:b], cfg.smoothing_passes) if b - a >= 5 or len(bounds) == 1
                 else (U[a:b], Y[a:b]) for a, b in bounds]
        U, Y = (np.vstack([p[j] for p in parts]) for j in (0, 1))
    if cfg.model == "hybrid":
        return _identify_hybrid(algo, U, Y, int(seed), cfg, t_start)
    net = BPNetwork(hidden=cfg.hidden, activation=cfg.activation, epochs=cfg.lm_epochs,
              goal=cfg.lm_goal, narx=cfg.narx, seed=int(seed), threads=cfg.threads)
    theta0, curve, opt_mse, evals = None, None, None, 0
    t_opt = 0.0
    t0_rows = 0 if cfg.narx is None else parse_orders(cfg.narx).t0
    rows = sum(b - a - t0_rows for a, b in bounds if b - a > t0_rows)
    stride = 1 if cfg.max_rows is None else max(1, -(-rows // int(cfg.max_rows)))
    if algo != "bp":
        Us = MinMaxScaler().fit(U).transform(U)
        Ys = MinMaxScaler().fit(Y).transform(Y)
        if cfg.narx is None:
            X, T = Us, Ys
        else:
            orders = parse_orders(cfg.narx)
            parts = [(_core.narx_regressors(Us[a:b], Ys[a:b], *orders), Ys[a + orders.t0:b])
                     for a, b in bounds if b - a > orders.t0]
            if not parts:
                raise ValueError(f"U, Y: no segment has more than t0 = {orders.t0} samples")
            X, T = (np.vstack([p[j] for p in parts]) for j in (0, 1))
        X, T = (np.ascontiguousarray(A[::stride]) for A in (X, T))
        t0 = time.perf_counter()
        res = _core.optimise(algo, "bp", X=X, T=T, hidden=cfg.hidden, activation=cfg.activation,
                             seed=int(seed), options=cfg.options(algo), threads=cfg.threads,
                             precision=cfg.fitness_precision)
        t_opt = time.perf_counter() - t0
        theta0, curve = res["best"], np.asarray(res["curve"])
        opt_mse, evals = float(res["best_fitness"]), int(res["evaluations"])
    t0 = time.perf_counter()
    net.fit(U, Y, theta0=theta0, segments=bounds, stride=stride)
    t_lm = time.perf_counter() - t0
    lm_mse = np.asarray(net.history_["mse"], dtype=np.float64)
    return IdentifyRun(algo=algo, seed=int(seed), model=net, curve=curve, optimiser_mse=opt_mse,
                       evaluations=evals, lm_mse=lm_mse, final_mse=float(lm_mse[-1]),
                       seconds={"optimise": t_opt, "lm": t_lm,
                                "total": time.perf_counter() - t_start})


def _identify_hybrid(algo, U, Y, seed, cfg, t_start) -> IdentifyRun:
    """Linear ARX + ``algo``-BP network on its residual (:class:`cdam_core.models.HybridNarx`)."""
    net_cfg = IdentifyConfig(**{**cfg.to_dict(), "narx": None, "smoothing_passes": 0,
                                "bounds": tuple(cfg.bounds), "model": "bp", "features": "raw",
                                "residual_weights": (0.0, 1.0), "ensemble": 1,
                                "validation_blocks": 0, "residual_training": "one_step"})
    runs = []

    def fit_residual(X, R, member=0):
        runs.append(identify(algo, X, R, seed=seed + member, config=net_cfg, preprocessed=True))
        return runs[-1].model

    model = HybridNarx(cfg.narx, cfg.features, fit_residual=fit_residual, seed=seed,
                       ensemble=cfg.ensemble, weights=cfg.residual_weights,
                       validation_blocks=cfg.validation_blocks,
                       training=cfg.residual_training).fit(U, Y)
    run = runs[-1]        # the model's (last) network: refitted on the whole record when kept
    total = time.perf_counter() - t_start
    return IdentifyRun(algo=algo, seed=seed, model=model, curve=run.curve,
                       optimiser_mse=run.optimiser_mse, evaluations=run.evaluations,
                       lm_mse=run.lm_mse, final_mse=model.train_mse_,
                       seconds={"optimise": sum(r.seconds["optimise"] for r in runs),
                                "lm": sum(r.seconds["lm"] for r in runs), "total": total})
