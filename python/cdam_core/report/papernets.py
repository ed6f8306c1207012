"""Renders the paper's pipelines beside the baselines on real flights (issue [flights] item 6):
one table over both records, the per-horizon tables, the AR.Drone free-run figure
(computes nothing; the numbers come from ``evaluate.crossfold`` and ``evaluate.papernets``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cdam_core.base.jsonio import atomic_target
from cdam_core.report.horizons import GROUP_UNITS

__all__ = ["standing_table", "ardrone_table", "selection_md", "write_ardrone_figure",
           "NANO_TO_ARDRONE", "AR_UNITS"]

#: a nano-drone predictor's name -> its AR.Drone row (the physics model has one row there)
NANO_TO_ARDRONE = {"physics": "quad_physics", "physics_hold": "quad_physics"}

AR_UNITS = {"phi": "rad", "theta": "rad", "psi": "rad", "X": "m", "Y": "m", "Z": "m"}


def _cell(v, fmt="{:.3f}"):
    return "-" if v is None or not np.isfinite(v) else fmt.format(v)


def standing_table(mean=None, ardrone_rows=(), at=(1, 50)) -> str:
    """Markdown: one row per predictor (every model of either record, in order of first
    appearance), nano-drone RMSE per group at the horizons ``at`` (mean over the folds, cells
    'h1 / h50'), and the AR.Drone free-run mean r and mean NRMSE; '-' where a model did not run
    on a record. ``mean``: ``HorizonScores`` (or None); ``ardrone_rows``: ``ArdroneRow``s."""
    ar = {r.name: r for r in ardrone_rows}
    names = list(mean.group_rmse) if mean is not None else []
    for r in ardrone_rows:
        if r.name not in names and r.name not in NANO_TO_ARDRONE.values():
            names.append(r.name)
    groups = [g.name for g in mean.groups] if mean is not None else []
    at = [h for h in at if mean is None or h in mean.horizons]
    hs = " / ".join(f"h={h}" for h in at)
    head = ["predictor"] + [f"nano-drone {g} RMSE [{GROUP_UNITS.get(g, '')}] {hs}"
                            for g in groups] + ["AR.Drone free-run mean r",
                                                "AR.Drone mean NRMSE"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name in names:
        cells = [name]
        for j, _ in enumerate(groups):
            if name in mean.group_rmse:
                cells.append(" / ".join(_cell(mean.group_rmse[name][mean.horizons.index(h), j])
                                        for h in at))
            else:
                cells.append("-")
        row = ar.get(NANO_TO_ARDRONE.get(name, name))
        if row is None or row.metrics is None:
            cells += ["-", "-"]
        else:
            nr = [v["nrmse"] for v in row.metrics.values()]
            cells += [_cell(row.mean_r), _cell(float(np.mean(nr)))]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def ardrone_table(rows) -> str:
    """Markdown: the AR.Drone rows with per-output r, the rate and what was chosen."""
    outs = next((list(r.metrics) for r in rows if r.metrics), [])
    head = ["model", "mean r"] + [f"r {o}" for o in outs] + ["rate [Hz]", "time [s]", "note"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        rs = [(r.metrics[o]["r"] if r.metrics else None) for o in outs]
        lines.append("| " + " | ".join([r.name, _cell(r.mean_r)] + [_cell(v) for v in rs] +
                                      [_cell(r.rate, "{:g}"), _cell(r.seconds, "{:.1f}"),
                                       r.note]) + " |")
    return "\n".join(lines)


def write_ardrone_figure(path, rows, outputs, names=None) -> Path:
    """The AR.Drone test part in free run: measured and each model of ``names`` (default: every
    row with a trace), one panel per output, time from the start of the test part [s]."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = [r for r in rows if r.trace is not None and (names is None or r.name in names)]
    if not rows:
        raise ValueError("rows: none has a free run to plot")
    fig, axes = plt.subplots(len(outputs), 1, figsize=(7.5, 1.7 * len(outputs) + 0.6),
                             squeeze=False, sharex=True)
    ref = max(rows, key=lambda r: len(r.trace[0]))
    for j, (ax, o) in enumerate(zip(axes[:, 0], outputs)):
        ax.plot(ref.trace[0], ref.trace[1][:, j], color="k", lw=1.0, label="measured")
        for r in rows:
            ax.plot(r.trace[0], r.trace[2][:, j], lw=0.8, label=f"{r.name} (r {r.mean_r:.2f})")
        ax.set_ylabel(f"{o} [{AR_UNITS.get(o, 'output units')}]")
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(loc="upper left", fontsize=7, ncol=2)
    axes[-1, 0].set_xlabel("time from the start of the test part [s]")
    fig.tight_layout()
    path = Path(path)
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return path


def selection_md(details: dict, top: int = 8) -> list[str]:
    """Markdown lines: what the selected hybrid chose on the training part (its
    ``HybridSelection.to_json()`` with each network candidate's test r added)."""
    c = sorted(details["structure_candidates"], key=lambda x: -x["blocked_r"])[:top]
    lines = [f"Preprocessing and structure (blocked validation on the training part, "
             f"{len(details['structure_candidates'])} candidates; the best {len(c)}):", "",
             "| decimation | smoothing passes | orders na,nb,nk | features | blocked mean r |",
             "|---|---|---|---|---|"]
    lines += [f"| {x['decimation']} | {x['smoothing_passes']} | "
              f"{','.join(map(str, x['narx']))} | {x['features']} | {_cell(x['blocked_r'])} |"
              for x in c]
    lines += ["", "Single networks on the ARX residual (each seed alone; validation: the same "
              "blocks, the hybrid fitted on the rest; the test r is reported, never used to "
              "choose; the candidates are the seeds' means below):", "",
              "| training | hidden | seed | blocked mean r with network | "
              "blocked mean r ARX alone | test r with network |", "|---|---|---|---|---|---|"]
    lines += [f"| {x.get('training', 'one_step')} | {x['hidden']} | {x['seed']} | "
              f"{_cell(x['validation_r_network'])} | "
              f"{_cell(x['validation_r_arx'])} | {_cell(x.get('test_r_network'))} |"
              for x in details["network_candidates"]]
    ens = details.get("ensemble_candidates") or []
    if ens:
        arx = details["validation_r"]["arx"]
        lines += ["", f"The candidates: hybrid = ARX + weight x (mean of the seeds' networks), "
                  f"on the same blocks; the best is kept only if above the ARX alone "
                  f"(blocked mean r {_cell(arx)}; network "
                  f"{'kept' if details['network_kept'] else 'switched off'}):", "",
                  "| training | hidden | networks | weight | blocked mean r | test r | chosen |",
                  "|---|---|---|---|---|---|---|"]
        lines += [f"| {x['training']} | {x['hidden']} | {x['members']} | {x['weight']:g} | "
                  f"{_cell(x['validation_r'])} | {_cell(x.get('test_r'))} | "
                  f"{('yes' if details['network_kept'] else 'best, not kept') if x.get('chosen') else ''} |"
                  for x in ens]
    return lines
