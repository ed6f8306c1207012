"""Several algorithms x several seeds on one training record, evaluated on test/validation
records, summarised (mean and std over seeds) with a rank-sum test of IBOA against the others.

The rank-sum test is ``scipy.stats.mannwhitneyu(iboa, other, alternative="greater")`` (the
Wilcoxon rank-sum test) on two per-seed scores: the final adaptation value 1 / (1 + MSE) and the
mean Pearson r over outputs on the first evaluation record. "IBOA beats X" means p < 0.05.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from cdam_core.base.metrics import adaptation_value
from cdam_core.evaluate.scores import evaluate
from cdam_core.identify.pipelines import ALGORITHMS, IdentifyConfig, identify, preprocess
from cdam_core.models.protocol import Model, segment_bounds

__all__ = ["Comparison", "compare", "summarise", "rank_sum"]


@dataclass
class Comparison:
    """What :func:`compare` hands on: the JSON-able ``result`` ({"config", "outputs", "seeds",
    "algorithms": {algo: {"runs", "best_seed"}}, "summary", "rank_sum"}) and ``models``
    ({algo: its best-training-fitness fitted model})."""

    result: dict
    models: dict[str, Model] = field(default_factory=dict)


def _progress(total, enabled, desc):
    if not enabled:
        return None
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit="run", file=__import__("sys").stderr, leave=False)


def compare(algos, U, Y, *, records: dict | None = None, seeds=range(10), config=None,
            names=None, progress: bool = False, segments=None,
            record_segments: dict | None = None) -> Comparison:
    """Run every algorithm with every seed; evaluate on each record.

    Args:
        algos: subset of ('iboa', 'boa', 'cabc', 'bp').
        U, Y: training inputs (N, i) and outputs (N, m).
        records: {"test": (U, Y), "validation": (U, Y), ...} evaluation records.
        seeds: the seeds (at least 1).
        names: output names for the metric tables.
        progress: show a tqdm bar on stderr.
        segments: the training rows as records laid end to end (lengths or ranges): each is
            smoothed on its own; the paper's network (static or NARX: no regressor crosses a
            seam) trains across them, a hybrid model does not.
        record_segments: {record name: segments} of the evaluation records cut into segments.

    Returns a :class:`Comparison`.
    """
    algos = list(algos)
    if not algos:
        raise ValueError("algos: no algorithm given")
    for a in algos:
        if a not in ALGORITHMS:
            raise ValueError(f"algos: unknown {a!r}; use {', '.join(ALGORITHMS)}")
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds: need at least one seed")
    cfg = config or IdentifyConfig()
    bounds = segment_bounds(segments, len(U))
    if len(bounds) > 1 and cfg.model != "bp":
        raise ValueError(f"segments: {len(bounds)} training segments; a hybrid network "
                         f"trains on one contiguous record (the paper's network, static or "
                         f"NARX, and an arx model train across them, no regressor crossing a "
                         f"seam)")
    parts = [preprocess(U[a:b], Y[a:b], cfg.smoothing_passes) for a, b in bounds]
    Us, Ys = np.vstack([u for u, _ in parts]), np.vstack([y for _, y in parts])
    names = list(names) if names is not None else [f"y{k}" for k in range(Ys.shape[1])]
    records = dict(records or {})
    bar = _progress(len(algos) * len(seeds), progress, "identify")
    out = {"config": cfg.to_dict(), "outputs": names, "seeds": seeds, "algorithms": {}}
    models = {}
    for algo in algos:
        runs, best = [], None
        for seed in seeds:
            run = identify(algo, Us, Ys, seed=seed, config=cfg, preprocessed=True,
                           segments=bounds if cfg.model == "bp" else None)
            metrics = {name: evaluate(run.model, Ur, Yr, names,
                                      smoothing_passes=cfg.smoothing_passes,
                                      segments=(record_segments or {}).get(name))
                       for name, (Ur, Yr) in records.items()}
            runs.append({
                "seed": seed, "fitness": run.fitness, "final_mse": run.final_mse,
                "optimiser_mse": run.optimiser_mse,
                "optimiser_fitness": (adaptation_value(run.optimiser_mse)
                                      if run.optimiser_mse is not None else None),
                "curve_mse": run.curve.tolist() if run.curve is not None else None,
                "lm_mse": run.lm_mse.tolist(), "evaluations": run.evaluations,
                "seconds": run.seconds, "metrics": metrics})
            if best is None or run.fitness > best[0]:
                best = (run.fitness, run.model, seed)
            if bar is not None:
                bar.set_postfix_str(f"{algo} seed {seed} fitness {run.fitness:.4f}")
                bar.update()
        out["algorithms"][algo] = {"runs": runs, "best_seed": best[2]}
        models[algo] = best[1]
    if bar is not None:
        bar.close()
    out["summary"] = summarise(out)
    out["rank_sum"] = rank_sum(out)
    return Comparison(result=out, models=models)


def _agg(values):
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        return {"mean": None, "std": None}
    return {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else 0.0}


def summarise(result: dict) -> dict:
    """Mean and std over seeds: fitness, run time, and each metric per record, mode, output."""
    summary = {}
    for algo, data in result["algorithms"].items():
        runs = data["runs"]
        s = {"fitness": _agg([r["fitness"] for r in runs]),
             "optimiser_fitness": _agg([r["optimiser_fitness"] for r in runs]),
             "seconds": _agg([r["seconds"]["total"] for r in runs]),
             "optimise_seconds": _agg([r["seconds"]["optimise"] for r in runs]),
             "records": {}}
        for rec in runs[0]["metrics"]:
            s["records"][rec] = {}
            for mode in runs[0]["metrics"][rec]:
                s["records"][rec][mode] = {
                    out: {k: _agg([r["metrics"][rec][mode][out][k] for r in runs])
                          for k in ("r", "rmse", "nrmse")}
                    for out in result["outputs"]}
        summary[algo] = s
    return summary


def _mean_r(run, rec):
    if rec is None:
        return None
    m = run["metrics"][rec]
    mode = "free_run" if "free_run" in m else "one_step"
    return float(np.nanmean([v["r"] for v in m[mode].values()]))


def rank_sum(result: dict) -> dict:
    """Mann-Whitney U (rank-sum) tests: does IBOA score higher than each other algorithm?"""
    algs = result["algorithms"]
    if "iboa" not in algs:
        return {}
    runs0 = algs["iboa"]["runs"]
    rec = next(iter(runs0[0]["metrics"]), None)
    tests = {}
    for other in algs:
        if other == "iboa":
            continue
        entry = {}
        for score, get in (("fitness", lambda r: r["fitness"]),
                           (f"mean_r_{rec}", lambda r: _mean_r(r, rec))):
            a = [get(r) for r in runs0]
            b = [get(r) for r in algs[other]["runs"]]
            if any(v is None or not np.isfinite(v) for v in a + b) or len(a) < 2 or len(b) < 2:
                continue
            if np.ptp(a + b) == 0:
                entry[score] = {"p_value": 1.0, "iboa_better": False}
                continue
            p = float(stats.mannwhitneyu(a, b, alternative="greater").pvalue)
            entry[score] = {"p_value": p, "iboa_better": bool(p < 0.05),
                            "iboa_median": float(np.median(a)), "other_median": float(np.median(b))}
        tests[other] = entry
    return tests
