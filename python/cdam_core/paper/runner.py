"""The experiment runner of ``cdam paper``: identification sections (static map, NARX) over
algorithms x seeds on the simulated flights, evaluated segment by segment.

Training is :func:`cdam_core.identify.compare` (one call per algorithm and seed, so every
seed's model can be kept to save its predictions); summaries and rank-sum tests are
:func:`cdam_core.identify.summarise` and :func:`cdam_core.identify.rank_sum`. Evaluation is
done here because the test and validation records consist of two experiments: a NARX model
restarts at each segment (see :mod:`.records`). Metrics are
:func:`cdam_core.identify.output_metrics` on the pooled segments after dropping each segment's
first t0 samples (the given NARX initial outputs; t0 = 0 for a static map).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ..identify import IdentifyConfig, compare, output_metrics, rank_sum, summarise

__all__ = ["PaperConfig", "run_section", "evaluate_segments"]


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
        if isinstance(self.smoothing, bool) or not isinstance(self.smoothing, (int, np.integer)) \
                or self.smoothing < 0:
            raise ValueError(f"smoothing: must be an integer >= 0, got {self.smoothing!r}")
        from .records import decimation_factor
        decimation_factor(1000.0, self.rate)
        self.identify_config(None)  # validates the rest

    def identify_config(self, narx) -> IdentifyConfig:
        """The pipeline settings for one section (smoothing already done: 0 passes here)."""
        return IdentifyConfig(hidden=self.hidden, narx=narx, smoothing_passes=0,
                              population=self.population, iterations=self.iterations,
                              switch_probability=self.switch_probability,
                              cabc_limit=self.cabc_limit, lm_epochs=self.lm_epochs,
                              lm_goal=self.lm_goal, threads=self.threads)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["narx"] = list(self.narx) if self.narx else None
        d["algos"] = list(self.algos)
        return d


def _predict(model, U, Y, mode):
    if model.narx is None:
        return model.predict(U)
    return model.predict(U, Y, mode=mode)


def evaluate_segments(model, segments, names) -> tuple[dict, dict]:
    """Metrics of ``model`` on a segmented record and the arrays they were computed on.

    Returns ({mode: {output: {r, rmse, nrmse, fit_percent}}}, {mode: (measured, predicted)})
    with modes "one_step" and, for NARX models, "free_run". Each segment's first t0 rows are
    dropped before pooling. A prediction with NaN or Inf (a diverged free run) gets NaN
    metrics marked ``"diverged": True`` instead of stopping the study.
    """
    t0 = getattr(model, "t0", 0) if model.narx is not None else 0
    modes = ["one_step"] + (["free_run"] if model.narx is not None else [])
    metrics, arrays = {}, {}
    for mode in modes:
        meas, pred = [], []
        for seg in segments:
            P = _predict(model, seg.U, seg.Y, mode)
            meas.append(seg.Y[t0:])
            pred.append(P[t0:])
        Ym, Pm = np.vstack(meas), np.vstack(pred)
        if np.all(np.isfinite(Pm)):
            metrics[mode] = output_metrics(Ym, Pm, names)
        else:  # a diverged free run: no metric (null in JSON, skipped by the summaries)
            metrics[mode] = {n: {"r": float("nan"), "rmse": float("nan"),
                                 "nrmse": float("nan"), "fit_percent": float("nan"),
                                 "diverged": True} for n in names}
        arrays[mode] = (Ym, Pm)
    return metrics, arrays


def run_section(data, cfg: PaperConfig, narx, *, bar=None, label="static"):
    """Identify with every algorithm and seed; evaluate on test and validation.

    Returns (result, predictions, best_models): ``result`` is JSON-able (config, per-run
    records, summary, rank_sum, seconds); ``predictions`` maps "label/record/mode/measured" and
    "label/record/mode/algo/seedS" to arrays; ``best_models`` holds each algorithm's
    best-training-fitness model.
    """
    icfg = cfg.identify_config(narx)
    U, Y = data.train_arrays()
    names = data.outputs
    records = {"test": data.test, "validation": data.validation}
    result = {"config": icfg.to_dict(), "outputs": list(names), "seeds": list(range(cfg.seeds)),
              "algorithms": {}}
    preds, best = {}, {}
    t_start = time.perf_counter()
    for algo in cfg.algos:
        runs, top = [], None
        for seed in range(cfg.seeds):
            one = compare([algo], U, Y, seeds=[seed], config=icfg, names=names)
            run = one["algorithms"][algo]["runs"][0]
            model = one["_models"][algo]
            run["metrics"] = {}
            for rec, segs in records.items():
                m, arr = evaluate_segments(model, segs, names)
                run["metrics"][rec] = m
                for mode, (Ym, Pm) in arr.items():
                    preds[f"{label}/{rec}/{mode}/measured"] = Ym
                    preds[f"{label}/{rec}/{mode}/{algo}/seed{seed}"] = Pm
            runs.append(run)
            if top is None or run["fitness"] > top[0]:
                top = (run["fitness"], model, seed)
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
