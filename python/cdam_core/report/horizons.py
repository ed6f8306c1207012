"""Renders :class:`~cdam_core.evaluate.horizons.HorizonScores`: a Markdown table and the plot
of error against horizon (computes nothing)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cdam_core.base.jsonio import atomic_target
from cdam_core.record.dataset import STANDARD_UNITS
from cdam_core.report.page import write_page

__all__ = ["horizon_table", "group_table", "write_horizon_report"]

GROUP_UNITS = {"position": "m", "velocity": "m/s", "attitude": "rad", "rates": "rad/s"}


def horizon_table(scores, at=None) -> str:
    """Markdown table: RMSE of each output for each predictor at the horizons ``at``."""
    hs = scores.horizons
    at = [h for h in (at or sorted({hs[0], hs[len(hs) // 2], hs[-1]})) if h in hs]
    head = "| predictor | h | " + " | ".join(scores.outputs) + " |"
    lines = [head, "|" + "---|" * (len(scores.outputs) + 2)]
    for name, R in scores.rmse.items():
        for h in at:
            row = R[hs.index(h)]
            lines.append(f"| {name} | {h} | " + " | ".join(f"{v:.4g}" for v in row) + " |")
    return "\n".join(lines)


def group_table(scores, at=(1, 10, 25, 50)) -> str:
    """Markdown table per group: RMSE and MAE of each predictor at the horizons ``at`` (those
    scored) and the MAE summed over h = 1..50 (the nano-drone benchmark's metrics)."""
    hs = scores.horizons
    at = [h for h in at if h in hs] or [hs[-1]]
    names = [g.name for g in scores.groups]
    head = ("| predictor | group | " + " | ".join(f"RMSE h={h}" for h in at) + " | " +
            " | ".join(f"MAE h={h}" for h in at) + " | MAE sum 1..50 |")
    lines = [head, "|" + "---|" * (2 * len(at) + 3)]
    for name in scores.group_rmse:
        total = scores.group_mae_sum(name)
        for g, gname in enumerate(names):
            r = [scores.group_rmse[name][hs.index(h), g] for h in at]
            a = [scores.group_mae[name][hs.index(h), g] for h in at]
            lines.append(f"| {name} | {gname} [{_unit(scores.groups[g])}] | " +
                         " | ".join(f"{v:.4g}" for v in r + a) + " | " +
                         ("-" if total is None else f"{total[g]:.4g}") + " |")
    return "\n".join(lines)


def write_horizon_report(scores, folder, title: str, dt: float | None = None,
                         units: dict | None = None, logy: bool = False,
                         published: bool = False, intro: str | None = None) -> Path:
    """``index.md``, ``index.html`` and ``rmse_vs_horizon.png`` (one panel per output) in
    ``folder``; ``logy``: logarithmic error axes (predictors that differ by decades);
    ``published``: the groups are the nano-drone benchmark's: its published table on the page
    and its models' MAE at h = 50 marked on the per-group plot; ``intro``: a paragraph under
    the title."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    units = {**STANDARD_UNITS, **(units or {})}      # the dataset format's, else given
    x = np.asarray(scores.horizons, dtype=float) * (dt if dt else 1.0)
    _panels(folder / "rmse_vs_horizon.png", x, dt, scores.rmse,
            [f"RMSE {o} [{units.get(o, 'output units')}]" for o in scores.outputs], logy)
    md = [f"# {title}", "", *([intro, ""] if intro else []), horizon_table(scores), "",
          "![RMSE against horizon](rmse_vs_horizon.png)", "",
          "*Figure: root-mean-square error of each output against the prediction horizon, for "
          "the model, the naive predictor y(t) = y(t - h)"
          + (" and the other predictors of the comparison" if len(scores.rmse) > 2 else "")
          + ", on the same rows.*", ""]
    if scores.groups:
        marks = _published_marks(scores, 50 * (dt if dt else 1.0)) if published else None
        _panels(folder / "group_mae_vs_horizon.png", x, dt, scores.group_mae,
                [f"MAE {g.name} [{_unit(g)}]" for g in scores.groups], logy, marks=marks)
        md += ["## Per group (the nano-drone benchmark's metrics)", "", group_table(scores), "",
               "![MAE per group against horizon](group_mae_vs_horizon.png)", "",
               "*Figure: mean error per group against the prediction horizon (Euclidean norm of "
               "the group's error vector; attitude as the quaternion geodesic angle), for every "
               "predictor of the comparison, on the same rows"
               + ("; the markers at h = 50: the published models' MAE on the benchmark's own "
                  "test trajectory type (not these records; table below)" if marks else "")
               + ".*", ""]
        if published:
            md += ["## Published", "", published_table(), ""]
    return write_page(folder / "index.md", md, title)


def _unit(group) -> str:
    return "rad" if group.kind != "vector" else GROUP_UNITS.get(group.name, "output units")


def _published_marks(scores, x50) -> dict:
    """{published model: (x, [MAE at h = 50 per group of ``scores``])} (evaluate.published)."""
    from cdam_core.evaluate.published import NANODRONE_PUBLISHED
    return {f"{name} (published)": (x50, [row[g.name][0] for g in scores.groups])
            for name, row in NANODRONE_PUBLISHED.items()}


def _panels(path, x, dt, series: dict, ylabels: list[str], logy: bool = False,
            marks: dict | None = None) -> None:
    """One panel per column of the (H, k) arrays of ``series`` (predictor -> array); more
    than 10 predictors get distinct colours (tab20's ten dark ones, then its light ones) and the
    legend goes beside the panels. ``marks``: {name: (x, [value per panel])}, single points
    drawn as grey markers (e.g. published figures at one horizon)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    k = len(ylabels)
    many = len(series) > 10
    beside = many or bool(marks)
    tab = plt.get_cmap("tab20").colors
    colours = list(tab[0::2]) + list(tab[1::2]) if many else [None] * len(series)
    fig, axes = plt.subplots(k, 1, figsize=(8.4 if beside else 6.4, 2.2 * k + 0.6),
                             squeeze=False, sharex=True)
    for j, (ax, label) in enumerate(zip(axes[:, 0], ylabels)):
        for c, (name, A) in enumerate(series.items()):
            ax.plot(x, A[:, j], marker="." if len(x) < 60 else None, label=name,
                    color=colours[c % len(colours)])
        for c, (name, (xm, values)) in enumerate((marks or {}).items()):
            ax.plot([xm], [values[j]], linestyle="none", marker="os^vDP*X"[c % 8],
                    color="0.45", markerfacecolor="none", label=name)
        ax.set_ylabel(label)
        if logy:
            ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
    if beside:
        axes[0, 0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    else:
        axes[0, 0].legend(loc="upper left", fontsize=8)
    axes[-1, 0].set_xlabel("horizon [s]" if dt else "horizon [samples]")
    fig.tight_layout()
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=110, **({"bbox_inches": "tight"} if beside else {}))
    plt.close(fig)


def published_table() -> str:
    """Markdown: the nano-drone benchmark's published MAE table and the quoted RMSE re-run
    (``evaluate.published``), for printing beside ours."""
    from cdam_core.evaluate.published import (GROUPS, NANODRONE_PUBLISHED,
                                              NANODRONE_RERUN_RMSE_H50, NANODRONE_SOURCE)
    units = [GROUP_UNITS[g] for g in GROUPS]
    lines = [f"Published (benchmark test type, not among our flights; {NANODRONE_SOURCE}): MAE "
             f"at h = 50 (sum over h = 1..50)", "",
             "| model | " + " | ".join(f"{g} [{u}]" for g, u in zip(GROUPS, units)) + " |",
             "|" + "---|" * (len(GROUPS) + 1)]
    for name, row in NANODRONE_PUBLISHED.items():
        lines.append(f"| {name} | " + " | ".join(f"{row[g][0]:.3f} ({row[g][1]:.2f})"
                                                for g in GROUPS) + " |")
    lines += ["", "RMSE at h = 50 on that test type, as quoted in issue [flights] (re-run of the "
              "published weights, and a least-squares ARX(1) on the 17 flights):", "",
              "| model | " + " | ".join(GROUPS) + " |", "|" + "---|" * (len(GROUPS) + 1)]
    for name, row in NANODRONE_RERUN_RMSE_H50.items():
        cells = [f"{v[0]:.3f}-{v[1]:.3f}" if isinstance(v, tuple) else f"{v:.3f}"
                 for v in (row[g] for g in GROUPS)]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
