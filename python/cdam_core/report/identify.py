"""The identification report: Markdown and HTML with PNG figures (matplotlib, Agg backend),
units on every axis (the dataset format's SI units, or ``units``), a caption under each figure.

Tables 2/3-style per output and algorithm (mean and std of Pearson r, RMSE and NRMSE over seeds,
per evaluation record and mode), final fitness (adaptation value 1 / (1 + MSE)) and run times,
the rank-sum verdicts, convergence curves (the paper's Fig. 11: adaptation value of the best
individual per iteration, mean over seeds with a min-max band) and predicted against measured
time series of the best-fitness model of each algorithm (Figs. 12-15) and their residuals
(measured minus predicted) against time.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cdam_core.base.metrics import adaptation_value
from cdam_core.base.jsonio import atomic_target
from cdam_core.preprocess import smooth_pair
from cdam_core.record.dataset import STANDARD_UNITS
from cdam_core.report.page import figure, write_page

__all__ = ["write_report", "headline"]

_LABEL = {"iboa": "IBOA-BP", "boa": "BOA-BP", "cabc": "CABC-BP", "bp": "BP"}


def _fmt(a, digits=4):
    if a["mean"] is None:
        return "n/a"
    return f"{a['mean']:.{digits}f} ± {a['std']:.{digits}f}"


def _mean_over_outputs(per_output: dict, key: str):
    vals = []
    for m in per_output.values():
        v = m[key]["mean"] if isinstance(m[key], dict) else m[key]
        if v is None or not np.isfinite(v):
            return None
        vals.append(v)
    return float(np.mean(vals)) if vals else None


def _cell(r, nrmse) -> str:
    return (f"r {'  n/a' if r is None else format(r, '5.3f')}  "
            f"NRMSE {'n/a' if nrmse is None else format(nrmse, '.3f')}")


def _verdict(models: list, baselines: list) -> list[str]:
    """One line: whether each model's mean NRMSE over the outputs is below the best of the
    baselines' (naive, ARX) on this record and mode; nothing without a finite baseline."""
    base = [(label, _mean_over_outputs(m, "nrmse")) for label, m, _ in baselines if m is not None]
    base = [(label, v) for label, v in base if v is not None]
    if not base:
        return []
    bl, bv = min(base, key=lambda b: b[1])
    out = []
    for label, m, _ in models:
        v = None if m is None else _mean_over_outputs(m, "nrmse")
        out.append(f"{label} {'n/a' if v is None else ('below' if v < bv else 'NOT below')}")
    return [f"  -> mean NRMSE against the best baseline ({bl}, {bv:.3f}): " + ", ".join(out)]


def headline(result: dict) -> list[str]:
    """The lines ``cdam identify`` leads with: on the validation record (else the test record),
    each algorithm's mean r and NRMSE over outputs in free run (one step for a static map)
    beside the naive and least-squares ARX baselines (``result["baselines"]``, see
    ``evaluate.baselines.naive_and_arx``) and whether each is below the best of them, then one
    step, then the training fitness."""
    summary, base = result["summary"], result.get("baselines") or {}
    first = next(iter(summary.values()))["records"]
    rec = "validation" if "validation" in first else "test"
    modes = ["free_run", "one_step"] if "free_run" in first[rec] else ["one_step"]
    seeds = len(result["seeds"])
    arx_label = "ARX({}, {}, {})".format(*base["arx_orders"]) if base else "ARX"
    lines = []
    for mode in modes:
        what = "free run" if mode == "free_run" else "one step"
        lines.append(f"{rec} record, {what}, mean over {len(result['outputs'])} output(s)"
                     + (f" and {seeds} seeds" if seeds > 1 else "") + ":")
        rows = [(_LABEL[algo], s["records"][rec][mode], "") for algo, s in summary.items()]
        if rec in base:
            rows.append(("naive", base[rec]["naive"][mode],
                         "y(t-1)" if mode == "one_step" else "training mean"))
            ax = base[rec]["arx"]
            rows.append((arx_label, None if "error" in ax else ax.get(mode, ax["one_step"]),
                         ax.get("error", "least squares")))
        for label, m, why in rows:
            cell = "n/a" if m is None else _cell(_mean_over_outputs(m, "r"),
                                                  _mean_over_outputs(m, "nrmse"))
            lines.append(f"  {label:<14} {cell}" + (f"   ({why})" if why else ""))
        lines += _verdict(rows[:len(summary)], rows[len(summary):])
    lines.append("training fitness 1/(1+MSE), normalised units (not a validation score): "
                 + ", ".join(f"{_LABEL[a]} {_fmt(s['fitness'])}" for a, s in summary.items()))
    lines.append("time per run: " + ", ".join(f"{_LABEL[a]} {_fmt(s['seconds'], 2)} s"
                                               for a, s in summary.items()))
    return lines


def _convergence_figure(result, path):
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for algo, data in result["algorithms"].items():
        curves = [r["curve_mse"] for r in data["runs"] if r["curve_mse"] is not None]
        if not curves:
            continue
        fit = adaptation_value(np.asarray(curves))
        it = np.arange(fit.shape[1])
        ax.plot(it, fit.mean(axis=0), label=_LABEL[algo])
        ax.fill_between(it, fit.min(axis=0), fit.max(axis=0), alpha=0.2)
    ax.set_xlabel("iteration [-]")
    ax.set_ylabel("adaptation value 1 / (1 + MSE) [-]")
    ax.set_title("Convergence of the initial-weight search (mean, min-max over seeds)")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def _label(name: str, units: dict) -> str:
    return f"{name} [{units.get(name) or 'output units'}]"


def _predictions(models, record, passes):
    """The smoothed measured outputs and each algorithm's prediction (free run for a dynamic
    model, the static map otherwise)."""
    U, Y = smooth_pair(record[0], record[1], passes)
    return Y, {algo: (model.predict(U, Y, mode="free_run") if model.narx is not None
                      else model.predict(U)) for algo, model in models.items()}


def _series_figure(x, series: dict, names, units, path, title, xlabel, ylabel_prefix=""):
    """One panel per output, one line per entry of ``series`` ({label: (N, m) array})."""
    import matplotlib.pyplot as plt
    m = len(names)
    fig, axes = plt.subplots(m, 1, figsize=(8, 1.8 * m + 0.6), sharex=True, squeeze=False)
    for i, (label, A) in enumerate(series.items()):
        for k in range(m):
            style = dict(color="k", lw=1.2) if label == "measured" else dict(lw=0.9)
            axes[k, 0].plot(x, A[:, k], label=label, **style)
    for k in range(m):
        axes[k, 0].set_ylabel(ylabel_prefix + _label(names[k], units), fontsize=8)
        axes[k, 0].grid(True, alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=len(series))
    axes[-1, 0].set_xlabel(xlabel)
    fig.suptitle(title)
    fig.tight_layout()
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def _prediction_figures(models, record, names, passes, t, units, d, rec) -> list[str]:
    """Predicted against measured, and the residuals, of record ``rec``: the Markdown lines."""
    Y, P = _predictions(models, record, passes)
    x = t if t is not None and len(t) == len(Y) else np.arange(len(Y))
    xlabel = "time [s]" if x is t else "sample [-]"
    mode = "free run" if any(m.narx is not None for m in models.values()) else "static map"
    pred = {"measured": Y, **{_LABEL[a]: p for a, p in P.items()}}
    res = {_LABEL[a]: Y - p for a, p in P.items()}
    f1, f2 = f"predicted_{rec}.png", f"residual_{rec}.png"
    _series_figure(x, pred, names, units, d / f1,
                   f"{rec}: measured and predicted (best seed per algorithm)", xlabel)
    _series_figure(x, res, names, units, d / f2,
                   f"{rec}: residual, measured minus predicted", xlabel, "residual ")
    return (figure(f1, f"{rec} predicted", f"Predicted ({mode}, best seed of each algorithm) "
                   f"against measured outputs of the {rec} record, one panel per output, "
                   "after the same smoothing as in training.")
            + figure(f2, f"{rec} residual", f"Residual (measured minus predicted, {mode}) of "
                     f"the {rec} record, one panel per output: a model that captured the "
                     "dynamics leaves a small residual without trend or periodic pattern."))


def _times_figure(result, path):
    import matplotlib.pyplot as plt
    s = result["summary"]
    algos = list(s)
    fig, ax = plt.subplots(figsize=(5, 3))
    ax.bar([_LABEL[a] for a in algos], [s[a]["seconds"]["mean"] for a in algos],
           yerr=[s[a]["seconds"]["std"] for a in algos], capsize=4)
    ax.set_ylabel("run time per seed [s]")
    ax.set_xlabel("algorithm")
    fig.tight_layout()
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def write_report(comparison, directory, *, records: dict | None = None,
                 times: dict | None = None, title: str = "System identification report",
                 units: dict | None = None) -> Path:
    """Write ``report.md``, ``report.html`` and the PNG figures into ``directory``; returns the
    Markdown path.

    ``comparison``: a :class:`cdam_core.evaluate.Comparison`. ``records`` ({name: (U, Y)})
    draws predicted-against-measured and residual figures with the best model of each
    algorithm (``comparison.models``); ``times`` ({name: t}) gives their time axes; ``units``
    ({output: unit}) the outputs' units (default: the dataset format's SI units).
    """
    units = {**STANDARD_UNITS, **(units or {})}
    result = comparison.result
    import matplotlib
    matplotlib.use("Agg")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    cfg, names, summary = result["config"], result["outputs"], result["summary"]
    lines = [f"# {title}", "",
             f"Seeds per algorithm: {len(result['seeds'])}. Network: {cfg['hidden']} hidden "
             f"({cfg['activation']}), NARX orders {cfg['narx'] or 'none (static map)'}; "
             f"smoothing passes {cfg['smoothing_passes']}; population {cfg['population']}, "
             f"Tmax {cfg['iterations']}, SP {cfg['switch_probability']}, CABC limit "
             f"{cfg['cabc_limit']}; LM at most {cfg['lm_epochs']} epochs, goal {cfg['lm_goal']}."
             + (f" Model: hybrid (linear ARX + the algorithm's network on its residual), "
                f"{cfg.get('features', 'raw')} features." if cfg.get("model") == "hybrid" else ""),
             "", "Fitness = adaptation value 1 / (1 + MSE), MSE the final training error in "
             "normalised units. Metrics compare back-normalised predictions with the "
             "preprocessed (smoothed) measurements; NRMSE = RMSE / std(measured).", "",
             "## Headline", "", "```", *headline(result), "```", "",
             "## Fitness and run time (mean ± std over seeds)", "",
             "| algorithm | fitness after LM | fitness of the optimiser's best | run time (s) | "
             "optimiser time (s) |", "|---|---|---|---|---|"]
    for algo, s in summary.items():
        lines.append(f"| {_LABEL[algo]} | {_fmt(s['fitness'])} | {_fmt(s['optimiser_fitness'])}"
                     f" | {_fmt(s['seconds'], 3)} | {_fmt(s['optimise_seconds'], 3)} |")
    algos = list(summary)
    first = next(iter(summary.values()))
    for rec, modes in first["records"].items():
        for mode in modes:
            for metric in ("r", "rmse", "nrmse"):
                lines += ["", f"## {rec}, {mode.replace('_', '-')}: {metric} per output", "",
                          "| output | " + " | ".join(_LABEL[a] for a in algos) + " |",
                          "|---" * (len(algos) + 1) + "|"]
                for out in names:
                    label = _label(out, units) if metric == "rmse" else f"{out} [-]"
                    lines.append(f"| {label} | " + " | ".join(
                        _fmt(summary[a]["records"][rec][mode][out][metric]) for a in algos) + " |")
    if result.get("rank_sum"):
        lines += ["", "## Does IBOA beat the others? (one-sided Mann-Whitney rank-sum, p < 0.05)",
                  "", "| against | score | p-value | IBOA better |", "|---|---|---|---|"]
        for other, entry in result["rank_sum"].items():
            for score, v in entry.items():
                lines.append(f"| {_LABEL[other]} | {score} | {v['p_value']:.3g} | "
                             f"{'yes' if v['iboa_better'] else 'no'} |")
    lines += ["", "## Figures", ""]
    if any(r["curve_mse"] for a in result["algorithms"].values() for r in a["runs"]):
        _convergence_figure(result, d / "convergence.png")
        lines += figure("convergence.png", "convergence",
                        "Convergence of the initial-weight search: adaptation value of the "
                        "best individual per iteration, mean over seeds with the min-max band "
                        "(the paper's Fig. 11).")
    _times_figure(result, d / "run_times.png")
    lines += figure("run_times.png", "run times",
                    "Run time per seed of each algorithm (mean, error bar one standard "
                    "deviation over seeds), optimiser and Levenberg-Marquardt together.")
    models = comparison.models
    for rec, data in (records or {}).items():
        if not models:
            break
        lines += _prediction_figures(models, data, names, cfg["smoothing_passes"],
                                     (times or {}).get(rec), units, d, rec)
    return write_page(d / "report.md", lines, title)
