"""The experiment runner of ``cdam paper``: identification sections (static map, NARX network,
hybrid ARX + network) over algorithms x seeds on the simulated flights, evaluated segment by
segment.

Training is :func:`cdam_core.evaluate.compare` (one call per algorithm and seed, so every
seed's model can be kept to save its predictions); summaries and rank-sum tests are
:func:`cdam_core.identify.summarise` and :func:`cdam_core.identify.rank_sum`. Evaluation is
done here because the test and validation records consist of two experiments: a NARX model
restarts at each segment (see :mod:`.records`). Metrics are
:func:`cdam_core.identify.output_metrics` on the pooled segments after dropping each segment's
first t0 samples (the given NARX initial outputs; t0 = 0 for a static map), or t0 + k - 1
samples for a k-step-ahead prediction (:mod:`.kstep`).

The hybrid section (:class:`cdam_core.models.hybrid.HybridNarx`: linear ARX by least squares
plus the algorithm's network on its residual) chooses its orders and delay with
:func:`cdam_core.models.hybrid.select_structure` on the training record only (free-run r on
its last 20 %); the residual network uses the hybrid's own small default (:data:`HYBRID_NET`),
and each run keeps the network only if it improves the free run on that training tail.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np

from cdam_core.base.metrics import output_metrics
from cdam_core.evaluate.compare import compare, rank_sum, summarise
from cdam_core.identify import IdentifyConfig
from cdam_core.evaluate.kstep import horizon_steps, k_step_predict

__all__ = ["PaperConfig", "run_section", "run_seed", "section_setup", "evaluate_segments",
           "HYBRID_NET", "HYBRID_SEARCH"]

# The hybrid's residual network: HybridNarx's own default size (identify/hybrid.py), not tuned.
HYBRID_NET = {"hidden": 5, "iterations": 20, "lm_epochs": 30}
# Structures select_structure tries on the training record (inputs are already thrust and
# torques, so the "physics" features of four motor commands do not apply: raw features only).
HYBRID_SEARCH = {"orders": (1, 2, 3, 4), "delays": (0, 1), "features": ("raw",)}


def _mode_name(horizon_s: float) -> str:
    return f"k_step_{float(horizon_s):g}s"


@dataclass
class PaperConfig:
    """Settings of ``cdam paper`` (defaults: the paper's Table 1, 200 Hz training data)."""

    seeds: int = 4
    flight_seed: int = 0
    duration: float = 20.0
    rate: float = 200.0
    smoothing: int = 5
    hidden: int = 20
    population: int = 20
    iterations: int = 50
    switch_probability: float = 0.8
    cabc_limit: int = 20
    lm_epochs: int = 50
    lm_goal: float = 0.003
    narx: tuple | None = (2, 2, 1)
    hybrid: bool = True
    horizons: tuple = (0.1,)
    algos: tuple = ("iboa", "boa", "cabc")
    threads: int = 2
    effects: list = field(default_factory=list)

    def __post_init__(self):
        if isinstance(self.seeds, bool) or not isinstance(self.seeds, (int, np.integer)) \
                or self.seeds < 1:
            raise ValueError(f"seeds: must be an integer >= 1, got {self.seeds!r}")
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"duration: must be positive and finite, got {self.duration!r}")
        if not self.algos:
            raise ValueError("algos: no algorithm given")
        self.algos = tuple(self.algos)
        self.narx = tuple(int(v) for v in self.narx) if self.narx else None
        self.horizons = tuple(float(h) for h in (self.horizons or ()))
        for h in self.horizons:
            horizon_steps(h, self.rate)   # ValueError for a non-positive or sub-sample horizon
        if isinstance(self.smoothing, bool) or not isinstance(self.smoothing, (int, np.integer)) \
                or self.smoothing < 0:
            raise ValueError(f"smoothing: must be an integer >= 0, got {self.smoothing!r}")
        from cdam_core.paper.records import decimation_factor
        decimation_factor(1000.0, self.rate)
        self.identify_config(None)  # validates the rest

    def identify_config(self, narx, model: str = "bp") -> IdentifyConfig:
        """The pipeline settings for one section (smoothing already done: 0 passes here);
        ``model="hybrid"``: the residual network of :data:`HYBRID_NET` size."""
        size = ({"hidden": self.hidden, "iterations": self.iterations,
                 "lm_epochs": self.lm_epochs} if model == "bp"
                else {k: min(v, getattr(self, k)) for k, v in HYBRID_NET.items()})
        return IdentifyConfig(narx=narx, smoothing_passes=0, population=self.population,
                              switch_probability=self.switch_probability,
                              cabc_limit=self.cabc_limit, lm_goal=self.lm_goal,
                              threads=self.threads, model=model, **size)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["narx"] = list(self.narx) if self.narx else None
        d["horizons"] = list(self.horizons)
        d["algos"] = list(self.algos)
        return d


def _predict(model, U, Y, mode):
    if model.narx is None:
        return model.predict(U)
    return model.predict(U, Y, mode=mode)


def evaluate_segments(model, segments, names, *, horizons=(), rate=None) -> tuple[dict, dict]:
    """Metrics of ``model`` on a segmented record and the arrays they were computed on.

    Returns ({mode: {output: {r, rmse, nrmse, fit_percent}}}, {mode: (measured, predicted)})
    with modes "one_step" and, for NARX-type models, "k_step_<h>s" for each horizon h (s) of
    ``horizons`` (``rate`` Hz gives the steps) and "free_run". Each segment's first t0 rows
    (t0 + k - 1 for a k-step prediction) are dropped before pooling. A prediction with NaN or
    Inf (a diverged free run) gets NaN metrics marked ``"diverged": True`` instead of stopping
    the study.
    """
    dynamic = model.narx is not None
    t0 = int(getattr(model, "t0", 0)) if dynamic else 0
    modes = {"one_step": (None, t0)}
    if dynamic:
        if horizons and rate is None:
            raise ValueError("rate: needed for k-step horizons")
        for h in horizons:
            k = horizon_steps(h, rate)
            modes[_mode_name(h)] = (k, t0 + k - 1)
        modes["free_run"] = (None, t0)
    metrics, arrays = {}, {}
    for mode, (k, skip) in modes.items():
        meas, pred = [], []
        for seg in segments:
            P = (k_step_predict(model, seg.U, seg.Y, k) if k is not None
                 else _predict(model, seg.U, seg.Y, mode))
            meas.append(seg.Y[skip:])
            pred.append(P[skip:])
        Ym, Pm = np.vstack(meas), np.vstack(pred)
        if np.all(np.isfinite(Pm)):
            metrics[mode] = output_metrics(Ym, Pm, names)
        else:  # a diverged free run: no metric (null in JSON, skipped by the summaries)
            metrics[mode] = {n: {"r": float("nan"), "rmse": float("nan"),
                                 "nrmse": float("nan"), "fit_percent": float("nan"),
                                 "diverged": True} for n in names}
        arrays[mode] = (Ym, Pm)
    return metrics, arrays


def _hybrid_structure(U, Y) -> dict:
    """select_structure on the training record (its last 20 % validates); JSON-able."""
    from cdam_core.identify.structure import select_structure
    sel = select_structure(U, Y, **HYBRID_SEARCH)
    return {"narx": list(sel["narx"]), "features": sel["features"],
            "training_tail_free_run_r": sel["validation_r"],
            "candidates": [{"narx": list(n), "features": f, "training_tail_free_run_r": r}
                           for r, _, n, f in sel["table"]]}


def section_setup(data, cfg: PaperConfig, narx, model="bp"):
    """(identify config, structure) of one section: the hybrid's orders chosen on the training
    record (``narx`` ignored, ``structure`` JSON-able), else ``narx`` as given (structure None).
    Deterministic: ``cdam batch`` calls it on each worker and gets the serial section's."""
    structure = None
    if model == "hybrid":
        U, Y = data.train_arrays()
        structure = _hybrid_structure(U, Y)
        narx = tuple(structure["narx"])
    return cfg.identify_config(narx, model), structure


def run_seed(data, cfg: PaperConfig, icfg, algo: str, seed: int, *, label="static",
             model="bp"):
    """One algorithm and seed of a section: identify on the training data, evaluate on test and
    validation. Returns (run, fitted model, predictions): ``run`` is the JSON-able record of
    :func:`run_section` (fitness, seconds, metrics per record, mode, output); ``predictions``
    maps "label/record/mode/measured" and "label/record/mode/algo/seedS" to arrays. The one
    code path of ``cdam paper`` and of ``cdam batch``'s paper tasks."""
    U, Y = data.train_arrays()
    names = data.outputs
    one = compare([algo], U, Y, seeds=[seed], config=icfg, names=names)
    run = one.result["algorithms"][algo]["runs"][0]
    fitted = one.models[algo]
    if model == "hybrid":
        run["residual_weight"] = float(fitted.residual_weight_)
        run["training_tail_free_run_r"] = {str(w): float(v) for w, v
                                           in fitted.validation_r_.items()}
    run["metrics"] = {}
    preds = {}
    for rec, segs in (("test", data.test), ("validation", data.validation)):
        m, arr = evaluate_segments(fitted, segs, names, horizons=cfg.horizons, rate=data.rate)
        run["metrics"][rec] = m
        for mode, (Ym, Pm) in arr.items():
            preds[f"{label}/{rec}/{mode}/measured"] = Ym
            preds[f"{label}/{rec}/{mode}/{algo}/seed{seed}"] = Pm
    return run, fitted, preds


def run_section(data, cfg: PaperConfig, narx, *, bar=None, label="static", model="bp"):
    """Identify with every algorithm and seed; evaluate on test and validation.

    ``model="hybrid"``: the hybrid ARX + network model, orders chosen on the training record
    (``narx`` is ignored). Returns (result, predictions, best_models): ``result`` is JSON-able
    (config, per-run records, summary, rank_sum, seconds); ``predictions`` maps
    "label/record/mode/measured" and "label/record/mode/algo/seedS" to arrays; ``best_models``
    holds each algorithm's best-training-fitness model.
    """
    t_start = time.perf_counter()
    icfg, structure = section_setup(data, cfg, narx, model)
    narx = icfg.narx
    result = {"config": icfg.to_dict(), "outputs": list(data.outputs),
              "seeds": list(range(cfg.seeds)), "model": model, "algorithms": {}}
    if structure is not None:
        result["structure"] = structure
    preds, best = {}, {}
    for algo in cfg.algos:
        runs, top = [], None
        for seed in range(cfg.seeds):
            run, fitted, p = run_seed(data, cfg, icfg, algo, seed, label=label, model=model)
            preds.update(p)
            runs.append(run)
            if top is None or run["fitness"] > top[0]:
                top = (run["fitness"], fitted, seed)
            if bar is not None:
                bar.set_postfix_str(f"{label} {algo} seed {seed} fitness {run['fitness']:.4f}")
                bar.update()
        result["algorithms"][algo] = {"runs": runs, "best_seed": top[2]}
        best[algo] = top[1]
    result["t0"] = int(getattr(best[cfg.algos[0]], "t0", 0)) if narx is not None else 0
    result["summary"] = summarise(result)
    result["rank_sum"] = rank_sum(result)
    result["seconds"] = time.perf_counter() - t_start
    return result, preds, best
